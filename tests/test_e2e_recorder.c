/*
 * End to end, the flight recorder: the shove scenario in lockstep with
 * continuous and triggered recording, the loop thread guarded (no
 * allocation, lock or page fault with the recorder on), the files read by
 * Foxglove's own readers (@mcap/core stream and indexed readers, the CDR
 * decoder and encoder of @foxglove/rosmsg2-serialization: tests/mcap/
 * check.mjs, installed by make test into $PUSHSTEP_NPM, default build/npm)
 * and compared with what the recorder says it wrote; then the command line:
 * a power cut (SIGKILL), a full disk, a file size limit reached mid-run, a
 * slow disk, SIGUSR1, paths that cannot be written, and `pushstep log`.
 *
 * Built twice, plain and with ASan and UBSan (build/tests/san/, which runs
 * the sanitized runtime and reports the loop thread's page faults rather
 * than asserting them: tests/fakes/ps_san.h); runs from the repository
 * root (the runtime: tests/fakes/ps_cli.h, $PUSHSTEP_BIN by default).
 */
#include <cjson/cJSON.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <setjmp.h>
#include <signal.h>
#include <spawn.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <cmocka.h>

#include "../rt/ps_app.h"
#include "../rt/ps_err.h"
#include "../rt/ps_guard.h"
#include "../rt/ps_mcap.h"
#include "../rt/ps_recorder.h"
#include "../rt/ps_rosmsg.h"
#include "../rt/ps_rtsetup.h"
#include "fakes/ps_cli.h"
#include "fakes/ps_san.h"

#define START_NS PS_NS_PER_S
#define OUT_MAX  (1u << 20)
/* Loop time of the in-process shove: the fall comes before 7 s (asserted), and
 * the fall dump wants 2 s after it. One number for the run and what
 * `pushstep log` must say of it. */
#define SHOVE_RUN_S 9
#define STR_(x)     #x
#define STR(x)      STR_(x)

extern char **environ;

static char dir[64];
static char out[OUT_MAX];

static const char *bin(void)
{
    return ps_cli_bin();
}

static const char *npm_dir(void)
{
    const char *d = getenv("PUSHSTEP_NPM");
    return d ? d : "build/npm";
}

/* Run a shell command with stdout and stderr into out; its exit status. */
static int sh(const char *fmt, ...)
{
    char cmd[2048];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(cmd, sizeof(cmd), fmt, ap);
    va_end(ap);
    char full[2100];
    snprintf(full, sizeof(full), "%s 2>&1", cmd);
    FILE *p = popen(full, "r");
    assert_non_null(p);
    size_t n = fread(out, 1, sizeof(out) - 1, p);
    out[n] = '\0';
    int status = pclose(p);
    ps_san_assert_no_report(out);
    assert_true(WIFEXITED(status));
    return WEXITSTATUS(status);
}

static cJSON *parse_out(void)
{
    cJSON *j = cJSON_Parse(out);
    if (j == NULL)
        fail_msg("not JSON:\n%.2000s", out);
    return j;
}

static cJSON *read_json(const char *path)
{
    FILE *f = fopen(path, "r");
    if (f == NULL)
        fail_msg("cannot open %s", path);
    size_t n = fread(out, 1, sizeof(out) - 1, f);
    out[n] = '\0';
    fclose(f);
    return parse_out();
}

static const cJSON *get(const cJSON *o, const char *key)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, key);
    if (v == NULL)
        fail_msg("JSON key \"%s\" missing", key);
    return v;
}

static double num(const cJSON *o, const char *key)
{
    const cJSON *v = get(o, key);
    if (!cJSON_IsNumber(v))
        fail_msg("JSON key \"%s\" not a number", key);
    return v->valuedouble;
}

/* Triggers a loaded machine adds to a lockstep run: overrun bursts and
 * watchdog stops (a late policy step), judged on the loop thread's CPU
 * time. The triggers are printed when there is more than the one the test
 * makes, whatever their kind. */
static double load_triggers(const cJSON *recorder)
{
    const cJSON *by = get(recorder, "triggers_by");
    if (num(recorder, "triggers") != 1) {
        char *txt = cJSON_PrintUnformatted(by);
        print_message("triggers: %s\n", txt);
        free(txt);
    }
    return num(by, "overrun") + num(by, "watchdog");
}

/* The flight summary's file whose causes include `trigger` (NULL when
 * none); *out_is_alone: it is the only cause. A trigger inside a dump being
 * written is noted in that dump ("overrun|button"), so on a loaded machine
 * an overrun near it may own the file. */
static const cJSON *flight_file_by_trigger(const cJSON *flight, const char *trigger,
                                           bool *out_is_alone)
{
    const cJSON *fi = NULL;
    cJSON_ArrayForEach(fi, get(flight, "files"))
    {
        const char *causes = cJSON_GetStringValue(get(fi, "trigger"));
        if (causes != NULL && strstr(causes, trigger) != NULL) {
            *out_is_alone = strcmp(causes, trigger) == 0;
            if (!*out_is_alone)
                print_message("the %s dump shares its file with: %s\n", trigger, causes);
            return fi;
        }
    }
    return NULL;
}

/* The independent readers on a file: its JSON report (see check.mjs). */
static cJSON *check_file(const char *path, int n_cuts)
{
    char cuts[32] = "";
    if (n_cuts > 0)
        snprintf(cuts, sizeof(cuts), "--cuts %d", n_cuts);
    int rc = sh("node %s/check.mjs %s %s", npm_dir(), path, cuts);
    if (rc != 0)
        fail_msg("node check.mjs %s failed (exit %d; make test installs the packages with "
                 "tools/npm-deps.sh):\n%.3000s",
                 path, rc, out);
    return parse_out();
}

/* What check.mjs read equals what the recorder says it wrote. */
static void expect_same_as_written(const cJSON *c, const ps_recorder_stats_t *s,
                                   const ps_rec_file_stats_t *f)
{
    assert_true(cJSON_IsTrue(get(c, "complete")));
    assert_int_equal((uint64_t)num(c, "messages"), f->n_messages);
    const cJSON *checks = get(c, "checks");
    assert_int_equal((uint64_t)num(checks, "decoded"), f->n_messages);
    if (num(checks, "stampMismatch") != 0 || num(checks, "reencodeMismatch") != 0)
        fail_msg("%s: %s", f->path, cJSON_Print(checks));
    const cJSON *st = get(c, "statistics");
    assert_int_equal((uint64_t)num(st, "messageCount"), f->n_messages);
    uint32_t n_present = 0;
    for (uint32_t k = 0; k < s->n_channels; k++)
        n_present += f->channel_n_messages[k] > 0;
    assert_int_equal((uint32_t)num(st, "channelCount"), n_present);
    assert_int_equal((uint32_t)num(st, "schemaCount"), n_present); /* one schema per channel */
    assert_int_equal(cJSON_GetArraySize(get(c, "schemas")), n_present);
    assert_int_equal((uint32_t)num(c, "indexedChannels"), n_present);
    assert_int_equal((uint32_t)num(c, "indexedSchemas"), n_present);
    const cJSON *chs = get(c, "channels");
    assert_int_equal(cJSON_GetArraySize(chs), n_present);
    const cJSON *ch;
    cJSON_ArrayForEach(ch, chs)
    {
        const char *topic = cJSON_GetStringValue(get(ch, "topic"));
        uint32_t k = 0;
        while (k < s->n_channels && strcmp(s->channel_topic[k], topic) != 0)
            k++;
        assert_true(k < s->n_channels);
        const double written = (double)f->channel_n_messages[k];
        if (num(ch, "messages") != written || num(ch, "indexedMessages") != written ||
            num(ch, "statisticsMessages") != written)
            fail_msg("%s %s: written %.0f, stream %.0f, indexed %.0f, statistics %.0f", f->path,
                     topic, written, num(ch, "messages"), num(ch, "indexedMessages"),
                     num(ch, "statisticsMessages"));
        assert_string_equal(cJSON_GetStringValue(get(ch, "messageEncoding")), "cdr");
        assert_string_equal(cJSON_GetStringValue(get(ch, "schemaEncoding")), "ros2msg");
        assert_non_null(strstr(cJSON_GetStringValue(get(ch, "schema")), "pushstep_msgs/msg/"));
    }
}

/* ---- reading fields back with the generic decoder --------------------------- */

typedef struct {
    const char *topic;
    const char *field;
    uint32_t elem;
    int ch;
    ps_rosmsg_parsed_t defs[PS_MCAP_MAX_SCHEMAS + 1];
    int field_idx;
    double t_s[20000];
    double v[20000];
    uint32_t n;
    char events[4096];
    int events_ch;
} series_t;

static series_t series;

static int se_schema(void *ctx, uint16_t id, const char *name, const char *enc, const uint8_t *d,
                     size_t len)
{
    series_t *s = ctx;
    (void)name;
    (void)enc;
    char err[128];
    assert_int_equal(ps_rosmsg_parse((const char *)d, len, &s->defs[id], err, sizeof(err)), 0);
    return 0;
}

static int se_channel(void *ctx, uint16_t id, uint16_t schema, const char *topic, const char *enc)
{
    series_t *s = ctx;
    (void)enc;
    if (strcmp(topic, s->topic) == 0) {
        s->ch = id;
        for (uint32_t i = 0; i < s->defs[schema].n_fields; i++)
            if (strcmp(s->defs[schema].fields[i].name, s->field) == 0)
                s->field_idx = (int)i;
        s->defs[0] = s->defs[schema];
    }
    if (strcmp(topic, "/events") == 0)
        s->events_ch = id;
    return 0;
}

static void se_value(void *ctx, const ps_rosmsg_value_t *v)
{
    series_t *s = ctx;
    if ((int)v->field_idx == s->field_idx && v->elem_idx == s->elem && s->n < 20000)
        s->v[s->n] = v->value;
}

static int se_message(void *ctx, uint16_t ch, uint32_t seq, uint64_t t, const uint8_t *d,
                      size_t len)
{
    series_t *s = ctx;
    (void)seq;
    if (ch == s->events_ch && s->events_ch >= 0) {
        const size_t used = strlen(s->events);
        /* kind and text are the last two strings: keep the printable bytes */
        for (size_t i = 20; i < len && used + i < sizeof(s->events) - 2; i++)
            s->events[used + i - 20] = (d[i] >= 32 && d[i] < 127) ? (char)d[i] : ' ';
        strcat(s->events, "\n");
    }
    if ((int)ch != s->ch || s->n >= 20000)
        return 0;
    s->t_s[s->n] = ps_ns_to_s((int64_t)t - START_NS);
    assert_int_equal(ps_rosmsg_decode(&s->defs[0], d, len, se_value, s), 0);
    s->n++;
    return 0;
}

static void read_series(const char *path, const char *topic, const char *field, uint32_t elem)
{
    static const ps_mcap_read_ops_t OPS = {se_schema, se_channel, se_message, NULL};
    memset(&series, 0, sizeof(series));
    series.topic = topic;
    series.field = field;
    series.elem = elem;
    series.ch = series.field_idx = series.events_ch = -1;
    ps_mcap_read_info_t info;
    char err[256];
    assert_int_equal(ps_mcap_read_file(path, &OPS, &series, &info, err, sizeof(err)), 0);
    assert_true(series.field_idx >= 0);
}

/* ---- pushstep log ---------------------------------------------------------- */

static uint64_t count_lines(const char *path)
{
    FILE *f = fopen(path, "r");
    assert_non_null(f);
    uint64_t n = 0;
    for (int c; (c = fgetc(f)) != EOF;)
        n += c == '\n';
    fclose(f);
    return n;
}

/* Summary, CSV and plot of the shove's file; the same file cut short. */
static void check_log_command(const char *path, uint64_t n_ticks)
{
    assert_int_equal(sh("%s log %s", bin(), path), 0);
    static const char *const SUMMARY[] = {"closed (summary and index present)",
                                          "duration " STR(SHOVE_RUN_S) ".000 s",
                                          "/joints",
                                          "pushstep_msgs/msg/Estimate",
                                          "scenario=scenarios/shove.yaml",
                                          "records_lost_ring=0",
                                          "transition ACTIVE -> DAMPING (FALL)",
                                          "trigger    fall",
                                          "FALL ",
                                          "tick_ns",
                                          "latency (us)"};
    for (size_t i = 0; i < sizeof(SUMMARY) / sizeof(SUMMARY[0]); i++)
        if (strstr(out, SUMMARY[i]) == NULL)
            fail_msg("pushstep log summary lacks \"%s\":\n%s", SUMMARY[i], out);
    /* --events: every event the summary counts, one a line, nothing else */
    unsigned n_events = 0;
    assert_non_null(strstr(out, "events ("));
    assert_int_equal(sscanf(strstr(out, "events ("), "events (%u", &n_events), 1);
    assert_true(n_events >= 2);
    assert_int_equal(sh("%s log %s --events", bin(), path), 0);
    unsigned n_lines = 0;
    for (const char *p = out; (p = strchr(p, '\n')) != NULL; p++)
        n_lines++;
    assert_int_equal(n_lines, n_events);
    assert_non_null(strstr(out, "transition ACTIVE -> DAMPING (FALL)"));
    assert_null(strstr(out, "channels:"));
    char csv[128], png[128];
    snprintf(csv, sizeof(csv), "%s/e.csv", dir);
    snprintf(png, sizeof(png), "%s/balance.png", dir);
    assert_int_equal(sh("%s log %s --csv %s --channels /estimate --signals "
                        "joints.q_rad.l_knee,truth.push_force_n[0]",
                        bin(), path, csv),
                     0);
    assert_int_equal(count_lines(csv), 1 + n_ticks); /* a header and a row a tick */
    FILE *f = fopen(csv, "r");
    assert_non_null(f);
    static char line[8192];
    assert_non_null(fgets(line, sizeof(line), f));
    assert_true(strncmp(line, "t_s,estimate.tick,estimate.t_ns,", 32) == 0);
    assert_non_null(strstr(line, ",estimate.capture_point_m[0],"));
    assert_non_null(strstr(line, ",joints.q_rad.l_knee,truth.push_force_n[0]\n"));
    uint32_t n_push = 0, n_rows = 0;
    long long tick_before = -1, t_ns_before = -1;
    while (fgets(line, sizeof(line), f) != NULL) {
        const double t_s = atof(line);
        /* the tick and its time in ns as integers, in full: one tick, 1 ms */
        char *end = NULL;
        const long long tick = strtoll(strchr(line, ',') + 1, &end, 10);
        assert_true(*end == ',');
        const long long t_ns = strtoll(end + 1, &end, 10);
        assert_true(*end == ',');
        if (n_rows++ > 0) {
            assert_true(tick == tick_before + 1);
            assert_true(t_ns == t_ns_before + 1000000);
        }
        tick_before = tick;
        t_ns_before = t_ns;
        const char *last = strrchr(line, ',');
        if (atof(last + 1) > 299.0) {
            n_push++;
            assert_true(t_s >= 4.999 && t_s < 5.101);
        }
    }
    fclose(f);
    assert_true(n_push >= 99 && n_push <= 101); /* 0.1 s of 300 N */
    assert_int_equal(sh("%s log %s --plot %s --signals balance --from 4 --to 7", bin(), path, png),
                     0);
    f = fopen(png, "rb");
    assert_non_null(f);
    uint8_t magic[8];
    assert_int_equal(fread(magic, 1, 8, f), 8);
    fclose(f);
    assert_memory_equal(magic, "\x89PNG\r\n\x1a\n", 8);
    /* a cut copy: read up to its last complete chunk, and said so */
    char cut[128];
    snprintf(cut, sizeof(cut), "%s/cut.mcap", dir);
    assert_int_equal(sh("head -c 1000000 %s > %s", path, cut), 0);
    assert_int_equal(sh("%s log %s", bin(), cut), 0);
    assert_non_null(strstr(out, "NOT CLOSED"));
    assert_non_null(strstr(out, "cut: reading stopped at byte"));
    assert_int_equal(sh("%s log %s --signals balance", bin(), path), 2); /* no --csv/--plot */
    assert_int_equal(sh("%s log %s --csv %s --signals estimate.nope", bin(), path, csv), 2);
    assert_non_null(strstr(out, "/estimate has no field nope"));
    assert_int_equal(sh("%s log /nonexistent.mcap", bin()), 1);
}

/* ---- the shove, in process ---------------------------------------------------- */

static ps_app_t app; /* large: static */
static ps_recorder_t rec;

static void test_e2e_rec_lockstep_shove_guarded_files_match_foxglove_readers(void **state)
{
    (void)state;
    char err[PS_ERR_MSG_LEN] = "";
    /* The standing controller, as the scenario is written for: the shipped
     * MLP (the robot file's default) computed for 0.13-0.3 ms a step in the
     * ASan build before its kernel's checks became whole-range ones
     * (policy/ps_mlp.c), near its 0.5 ms deadline on the thread's CPU clock,
     * and a loaded CI host pushed it over once: ACTIVE -> HOLD and a second
     * dump (WATCHDOG) made the run depend on the host, not on the recorder. */
    ps_app_opts_t o = {.data_dir = ".",
                       .board = "sim",
                       .scenario = "scenarios/shove.yaml",
                       .is_lockstep = true,
                       .policy = "stand"};
    int rc = ps_app_init(&app, &o, err, sizeof(err));
    if (rc != 0)
        fail_msg("ps_app_init: %s", err);
    char path[128];
    snprintf(path, sizeof(path), "%s/run.mcap", dir);
    ps_recorder_cfg_t rc_cfg = {.path = path,
                                .dir = dir,
                                .pre_s = 5.0,
                                .post_s = 2.0,
                                .compression = PS_MCAP_COMPRESS_ZSTD,
                                .is_sync_chunks = true,
                                .cpu = -1};
    ps_app_recorder_cfg(&app, &rc_cfg);
    assert_int_equal(ps_recorder_init(&rec, &rc_cfg, err, sizeof(err)), 0);
    ps_app_attach_recorder(&app, &rec);
    assert_int_equal(ps_recorder_start(&rec), 0);
    assert_int_equal(ps_sim_start(app.sim, START_NS), 0);
    assert_int_equal(ps_loop_start(&app.loop, START_NS), 0);
    if (ps_rtsetup_lock_memory() < 0)
        (void)ps_rtsetup_prefault_maps();
    ps_rtsetup_prefault_stack(256 * 1024);

    ps_guard_arm();
    while (app.loop.t_deadline_ns < START_NS + SHOVE_RUN_S * PS_NS_PER_S)
        assert_int_equal(ps_loop_step(&app.loop), 0);
    ps_guard_counts_t counts;
    ps_guard_disarm(&counts);
    const uint64_t n_ticks = app.loop.counters.n_ticks;
    const uint64_t n_late = app.loop.counters.n_policy_late, n_overruns = app.loop.pacer.n_overruns;
    ps_recorder_stop(&rec);
    ps_app_deinit(&app);

    /* the recorder's tap on the loop thread: nothing allocated, locked or faulted */
    ps_san_assert_guard_clean(&counts, "shove 0.." STR(SHOVE_RUN_S) " s with the recorder");
    const ps_recorder_stats_t *s = &rec.stats;
    assert_int_equal(s->n_pushed, n_ticks);
    assert_int_equal(s->cont.n_records, n_ticks);
    assert_int_equal(s->cont.n_lost_ring + s->cont.n_lost_io, 0);
    assert_int_equal(s->cont.err, 0);
    if (s->n_dumps != 1) /* say why: each dump's triggers, the loop's CPU-time faults */
        fail_msg("%u dumps, want 1 (the fall's); triggers 0x%x, 0x%x; %llu late policy "
                 "steps, %llu overruns",
                 s->n_dumps, s->dump[0].triggers, s->n_dumps > 1 ? s->dump[1].triggers : 0u,
                 (unsigned long long)n_late, (unsigned long long)n_overruns);
    assert_true(s->dump[0].triggers & PS_REC_TRIG_FALL);
    assert_int_equal(s->dump[0].n_records, 7001); /* 5 s before the fall, 2 s after */
    assert_int_equal(s->dump[0].n_lost_ring + s->dump[0].n_lost_io, 0);

    cJSON *c = check_file(path, 2);
    expect_same_as_written(c, s, &s->cont);
    const cJSON *cut;
    uint32_t n_cuts = 0;
    cJSON_ArrayForEach(cut, get(c, "cuts"))
    {
        if (!cJSON_IsNull(get(cut, "error")) || num(cut, "got") != num(cut, "expected"))
            fail_msg("cut at %.0f: read %.0f messages, chunks before it hold %.0f (%s)",
                     num(cut, "cut"), num(cut, "got"), num(cut, "expected"),
                     cJSON_Print(get(cut, "error")));
        assert_false(cJSON_IsTrue(get(cut, "done")));
        n_cuts++;
    }
    assert_true(n_cuts >= 7);
    cJSON_Delete(c);
    c = check_file(s->dump[0].path, 0);
    expect_same_as_written(c, s, &s->dump[0]);
    cJSON_Delete(c);

    /* the file shows the push (300 N for 0.1 s at 5 s) and the fall */
    read_series(path, "/truth", "push_force_n", 0);
    double first_push = -1, last_push = -1;
    for (uint32_t i = 0; i < series.n; i++)
        if (series.v[i] > 299.0) {
            if (first_push < 0)
                first_push = series.t_s[i];
            last_push = series.t_s[i];
        }
    assert_true(fabs(first_push - 5.0) < 0.0025 && fabs(last_push - 5.1) < 0.0025);
    read_series(path, "/estimate", "is_fallen", 0);
    double fallen_at = -1;
    for (uint32_t i = 0; i < series.n && fallen_at < 0; i++)
        if (series.v[i] != 0)
            fallen_at = series.t_s[i];
    assert_true(fallen_at > 5.0 && fallen_at < 7.0);
    assert_non_null(strstr(series.events, "ACTIVE -> DAMPING (FALL)"));
    assert_non_null(strstr(series.events, "trigger"));
    assert_non_null(strstr(series.events, "fall"));
    check_log_command(path, n_ticks);
}

/* ---- the command line --------------------------------------------------------- */

static void test_e2e_rec_cli_help_and_unwritable_paths(void **state)
{
    (void)state;
    assert_int_equal(sh("%s --help", bin()), 0);
    static const char *const OPTIONS[] = {
        "--record FILE.mcap",   "--flight DIR",    "--flight-pre S", "--flight-post S",
        "--record-compression", "--record-ring S", "pushstep log"};
    for (size_t i = 0; i < sizeof(OPTIONS) / sizeof(OPTIONS[0]); i++)
        if (strstr(out, OPTIONS[i]) == NULL)
            fail_msg("--help does not mention %s", OPTIONS[i]);
    assert_int_equal(sh("%s --lockstep --duration 1 --record /nonexistent-dir/x.mcap", bin()), 2);
    assert_non_null(strstr(out, "--record /nonexistent-dir/x.mcap: No such file or directory"));
    assert_int_equal(sh("%s --lockstep --duration 1 --flight /etc/hostname", bin()), 2);
    assert_non_null(strstr(out, "--flight /etc/hostname: not a folder"));
    assert_int_equal(sh("%s --lockstep --duration 1 --flight %s --flight-pre 700", bin(), dir), 2);
    assert_int_equal(sh("%s --lockstep --record %s/x.mcap --record-compression gz", bin(), dir), 2);
    assert_non_null(strstr(out, "not one of zstd, lz4, none"));
}

/* The disk is full from the first byte: the run goes on to its end, the
 * recorder counts every record lost and the exit status says the
 * recording failed. */
static void test_e2e_rec_cli_disk_full_loop_runs_on_records_counted(void **state)
{
    (void)state;
    char sum[128];
    snprintf(sum, sizeof(sum), "%s/s.json", dir);
    assert_int_equal(
        sh("%s --lockstep --duration 3 --quiet --record /dev/full --summary %s", bin(), sum), 1);
    assert_non_null(strstr(out, "No space left on device"));
    assert_non_null(strstr(out, "LOST"));
    cJSON *j = read_json(sum);
    const double ticks = num(j, "ticks");
    assert_true(ticks >= 3000);
    assert_int_equal(num(get(j, "after_init"), "mallocs"), 0);
    const cJSON *cont = get(get(j, "recorder"), "continuous");
    assert_string_equal(cJSON_GetStringValue(get(cont, "error")), "No space left on device");
    assert_int_equal(num(cont, "records"), 0);
    assert_true(num(cont, "records_lost_io") + num(cont, "records_lost_ring") == ticks);
    cJSON_Delete(j);
}

/* The file may not grow past 300 kB (RLIMIT_FSIZE, as a small full disk):
 * the write that crosses it fails mid-run; Foxglove's reader reads exactly
 * the messages the recorder says reached the file. */
static void test_e2e_rec_cli_size_limit_mid_run_file_keeps_whole_chunks(void **state)
{
    (void)state;
    char sum[128], path[128];
    snprintf(sum, sizeof(sum), "%s/s.json", dir);
    snprintf(path, sizeof(path), "%s/limited.mcap", dir);
    assert_int_equal(sh("prlimit --fsize=300000 %s --lockstep --duration 5 --quiet --record %s "
                        "--summary %s",
                        bin(), path, sum),
                     1);
    cJSON *j = read_json(sum);
    const cJSON *cont = get(get(j, "recorder"), "continuous");
    assert_string_equal(cJSON_GetStringValue(get(cont, "error")), "File too large");
    const double written = num(cont, "messages");
    assert_true(num(cont, "records") > 0 && num(cont, "records_lost_io") > 0);
    assert_true(num(cont, "records") + num(cont, "records_lost_io") +
                    num(cont, "records_lost_ring") ==
                num(j, "ticks"));
    cJSON_Delete(j);
    struct stat st;
    assert_int_equal(stat(path, &st), 0);
    assert_true(st.st_size <= 300000);
    cJSON *c = check_file(path, 0);
    assert_false(cJSON_IsTrue(get(c, "complete")));
    assert_true(num(c, "messages") == written && written > 0);
    assert_int_equal(num(get(c, "checks"), "decoded"), written);
    cJSON_Delete(c);
}

/* A disk that takes 0.2 s per write and a ring of half a second: the loop runs on, the writer falls
 * behind the ring and says how many records it lost, in the summary and
 * in the file. */
static void test_e2e_rec_cli_slow_disk_reports_lost_records(void **state)
{
    (void)state;
    char sum[128], path[128];
    snprintf(sum, sizeof(sum), "%s/s.json", dir);
    snprintf(path, sizeof(path), "%s/slow.mcap", dir);
    /* in real time: the loop never waits for the writer */
    assert_int_equal(sh("PUSHSTEP_REC_IO_DELAY_NS=200000000 %s --duration 2 --quiet "
                        "--record %s --record-ring 0.1 --summary %s",
                        bin(), path, sum),
                     0);
    assert_non_null(strstr(out, "LOST"));
    cJSON *j = read_json(sum);
    assert_int_equal(num(get(j, "after_init"), "mallocs"), 0);
    const cJSON *cont = get(get(j, "recorder"), "continuous");
    const double lost = num(cont, "records_lost_ring");
    assert_true(lost > 0);
    assert_true(cJSON_IsNull(get(cont, "error")));
    assert_true(num(cont, "records") + lost == num(j, "ticks"));
    assert_true(num(get(j, "recorder"), "records_lost") == lost);
    const double written = num(cont, "messages");
    cJSON_Delete(j);
    cJSON *c = check_file(path, 0);
    assert_true(cJSON_IsTrue(get(c, "complete")));
    assert_true(num(c, "messages") == written);
    const cJSON *m;
    bool has_meta = false;
    cJSON_ArrayForEach(m, get(c, "metadata"))
    {
        if (strcmp(cJSON_GetStringValue(get(m, "name")), "pushstep.recorder") != 0)
            continue;
        const char *v = cJSON_GetStringValue(get(get(m, "metadata"), "records_lost_ring"));
        assert_true(v != NULL && atof(v) == lost);
        has_meta = true;
    }
    assert_true(has_meta);
    cJSON_Delete(c);
}

/* The same slow disk in lockstep: no deadline, so the loop waits for the
 * writer and the file holds every tick's record. */
static void test_e2e_rec_cli_lockstep_slow_disk_loses_nothing(void **state)
{
    (void)state;
    char sum[128], path[128];
    snprintf(sum, sizeof(sum), "%s/s.json", dir);
    snprintf(path, sizeof(path), "%s/slow.mcap", dir);
    assert_int_equal(sh("PUSHSTEP_REC_IO_DELAY_NS=200000000 %s --lockstep --duration 2 --quiet "
                        "--record %s --record-ring 0.1 --summary %s",
                        bin(), path, sum),
                     0);
    assert_null(strstr(out, "LOST"));
    cJSON *j = read_json(sum);
    assert_int_equal(num(get(j, "after_init"), "mallocs"), 0);
    const cJSON *cont = get(get(j, "recorder"), "continuous");
    assert_true(num(cont, "records_lost_ring") == 0);
    assert_true(num(cont, "records") == num(j, "ticks"));
    const double written = num(cont, "messages");
    cJSON_Delete(j);
    cJSON *c = check_file(path, 0);
    assert_true(cJSON_IsTrue(get(c, "complete")));
    assert_true(num(c, "messages") == written);
    cJSON_Delete(c);
}

/* Start argv in the background, stdout and stderr to log (or /dev/null). */
static pid_t spawn_bg(char *const argv[], const char *log)
{
    pid_t pid;
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    const char *to = log != NULL ? log : "/dev/null";
    posix_spawn_file_actions_addopen(&fa, 1, to, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&fa, 1, 2);
    assert_int_equal(posix_spawn(&pid, argv[0], &fa, NULL, argv, environ), 0);
    posix_spawn_file_actions_destroy(&fa);
    return pid;
}

static void sleep_s(double s)
{
    struct timespec ts = {(time_t)s, (long)((s - (double)(time_t)s) * 1e9)};
    nanosleep(&ts, NULL);
}

/* A power cut: the process is killed mid-run. The file has no summary or
 * footer; both readers take every message of its complete chunks. */
static void test_e2e_rec_cli_power_cut_file_readable_up_to_last_chunk(void **state)
{
    (void)state;
    char path[128];
    snprintf(path, sizeof(path), "%s/cut.mcap", dir);
    char *const argv[] = {(char *)bin(), "--duration", "30", "--quiet", "--record", path, NULL};
    pid_t pid = spawn_bg(argv, NULL);
    struct stat st = {0};
    for (int i = 0; i < 400 && (stat(path, &st) != 0 || st.st_size < 150000); i++)
        sleep_s(0.05);
    kill(pid, SIGKILL);
    int status;
    assert_int_equal(waitpid(pid, &status, 0), pid);
    assert_true(WIFSIGNALED(status));
    assert_true(st.st_size >= 150000);
    cJSON *c = check_file(path, 0);
    assert_false(cJSON_IsTrue(get(c, "complete")));
    const double n = num(c, "messages");
    assert_true(n > 0);
    assert_int_equal(num(get(c, "checks"), "decoded"), n);
    assert_int_equal(num(get(c, "checks"), "reencodeMismatch"), 0);
    cJSON_Delete(c);
    ps_mcap_read_info_t info;
    char err[256];
    assert_int_equal(
        ps_mcap_read_file(path, &(ps_mcap_read_ops_t){0}, NULL, &info, err, sizeof(err)), 0);
    assert_int_equal((double)info.n_messages, n);
    assert_false(info.has_footer);
    assert_true(info.n_chunks > 0);
}

/* SIGUSR1: a dump of 1 s before and 0.5 s after. In lockstep (until
 * SIGTERM) so that no overrun or watchdog of a loaded machine starts a dump
 * of its own; lockstep runs several times faster than real time, so the
 * post window is long over when SIGTERM comes. */
static void test_e2e_rec_cli_sigusr1_dumps_the_window_around_it(void **state)
{
    (void)state;
    char sum[128];
    snprintf(sum, sizeof(sum), "%s/s.json", dir);
    /* no crowd (board sim's default scenario): lockstep then runs many
     * times faster than the wall clock, so the sleeps below hold well over
     * the 1 s before and 0.5 s after the signal even on a loaded machine */
    char *const argv[] = {(char *)bin(), "--lockstep",
                          "--scenario",  "scenarios/stand.yaml",
                          "--duration",  "0",
                          "--quiet",     "--flight",
                          dir,           "--flight-pre",
                          "1",           "--flight-post",
                          "0.5",         "--summary",
                          sum,           NULL};
    char log[128];
    snprintf(log, sizeof(log), "%s/run.log", dir);
    pid_t pid = spawn_bg(argv, log);
    /* the pre window's 1 s of loop time has passed once RAMP -> ACTIVE
     * (t = 1.2 s) is printed */
    for (int i = 0; i < 1500 && sh("grep -q 'RAMP -> ACTIVE' %s", log) != 0; i++)
        sleep_s(0.02);
    kill(pid, SIGUSR1);
    sleep_s(1.5);
    kill(pid, SIGTERM);
    int status;
    assert_int_equal(waitpid(pid, &status, 0), pid);
    assert_true(WIFEXITED(status));
    assert_int_equal(WEXITSTATUS(status), 0);
    cJSON *j = read_json(sum);
    const cJSON *r = get(j, "recorder");
    assert_int_equal(num(get(r, "triggers_by"), "signal"), 1);
    /* lockstep judges overruns and late steps on the loop thread's CPU
     * time, which a loaded VM inflates: they may add dumps of their own, or
     * hold the signal in one (flight_file_by_trigger); each is counted */
    const cJSON *fl = get(r, "flight");
    const double n_load = load_triggers(r);
    assert_true(num(fl, "dumps") >= 1 && num(fl, "dumps") <= 1 + n_load);
    bool is_alone = false;
    const cJSON *f = flight_file_by_trigger(fl, "signal", &is_alone);
    assert_non_null(f);
    if (is_alone)
        assert_int_equal(num(f, "records"), 1501);
    char path[256];
    snprintf(path, sizeof(path), "%s", cJSON_GetStringValue(get(f, "path")));
    const double written = num(f, "messages");
    cJSON_Delete(j);
    cJSON *c = check_file(path, 0);
    assert_true(cJSON_IsTrue(get(c, "complete")));
    assert_true(num(c, "messages") == written);
    cJSON_Delete(c);
}

/* The GPIO record button (a scenario event on the simulated line) starts
 * a dump, in lockstep: 1 s before the press, 0.5 s after. */
static void test_e2e_rec_cli_gpio_button_dumps_the_window(void **state)
{
    (void)state;
    char scen[128], sum[128];
    snprintf(scen, sizeof(scen), "%s/button.yaml", dir);
    snprintf(sum, sizeof(sum), "%s/s.json", dir);
    FILE *f = fopen(scen, "w");
    assert_non_null(f);
    fputs("name: button\nduration_s: 4\nseed: 1\nevents:\n  - {t_s: 0.2, kind: start}\n"
          "  - {t_s: 2.0, kind: harness_release}\n  - {t_s: 2.5, kind: record_button}\n",
          f);
    fclose(f);
    assert_int_equal(sh("%s --lockstep --quiet --scenario %s --flight %s --flight-pre 1 "
                        "--flight-post 0.5 --summary %s",
                        bin(), scen, dir, sum),
                     0);
    cJSON *j = read_json(sum);
    const cJSON *r = get(j, "recorder");
    /* as above: a loaded machine (CI's sanitized build) may add triggers
     * of its own (one on the press's tick is one trigger with both
     * causes); the button's window is asserted when its dump is its own */
    const double n_load = load_triggers(r);
    assert_true(num(r, "triggers") >= 1 && num(r, "triggers") <= 1 + n_load);
    assert_int_equal(num(get(r, "triggers_by"), "button"), 1);
    bool is_alone = false;
    const cJSON *file = flight_file_by_trigger(get(r, "flight"), "button", &is_alone);
    assert_non_null(file);
    if (is_alone) {
        assert_int_equal(num(file, "records"), 1501);
        /* the press at 2.5 s is read by the loop's next tick */
        assert_true(num(file, "trigger_record") >= 2500 && num(file, "trigger_record") <= 2502);
    }
    cJSON_Delete(j);
}

static int setup(void **state)
{
    (void)state;
    snprintf(dir, sizeof(dir), "/tmp/ps_e2e_rec_XXXXXX");
    return mkdtemp(dir) != NULL ? 0 : -1;
}

static int teardown(void **state)
{
    (void)state;
    ps_recorder_deinit(&rec);
    char cmd[128];
    snprintf(cmd, sizeof(cmd), "rm -rf %s", dir);
    return system(cmd) == 0 ? 0 : -1;
}

/* In a crowd: /truth lists the crowd's contacts on the robot (agent, force,
 * point), each agent one of the scene's, each force no larger than the
 * run's largest total crowd force on the robot, and there is contact while
 * the crowd presses (the default scenario, board sim). */
static void test_e2e_rec_cli_crowd_contacts_in_truth(void **state)
{
    (void)state;
    char mcap[128], csv[128], sum[128];
    snprintf(mcap, sizeof(mcap), "%s/crowd.mcap", dir);
    snprintf(csv, sizeof(csv), "%s/contacts.csv", dir);
    snprintf(sum, sizeof(sum), "%s/summary.json", dir);
    assert_int_equal(sh("%s --board sim --lockstep --duration 3 --quiet --record %s --summary %s",
                        bin(), mcap, sum),
                     0);
    cJSON *j = read_json(sum);
    const cJSON *crowd = get(j, "crowd");
    const double n_agents = num(crowd, "agents");
    const double force_max_n = num(crowd, "robot_force_max_n");
    cJSON_Delete(j);
    assert_true(n_agents >= 1 && force_max_n > 10.0);
    assert_int_equal(sh("%s log %s --csv %s --signals truth.contact_agent[0],truth.contact_fx_n[0],"
                        "truth.contact_fy_n[0],truth.contact_fz_n[0],truth.contact_z_m[0]",
                        bin(), mcap, csv),
                     0);
    FILE *f = fopen(csv, "r");
    assert_non_null(f);
    static char line[1024];
    assert_non_null(fgets(line, sizeof(line), f)); /* header */
    uint32_t n_rows = 0, n_touching = 0;
    while (fgets(line, sizeof(line), f) != NULL) {
        n_rows++;
        double t_s, agent, fx, fy, fz, z;
        if (sscanf(line, "%lf,%lf,%lf,%lf,%lf,%lf", &t_s, &agent, &fx, &fy, &fz, &z) != 6)
            continue; /* no contact this tick: empty columns */
        n_touching++;
        if (!(agent == 65535.0 || (agent >= 0.0 && agent < n_agents)))
            fail_msg("t=%.3f: contact with agent %g of %g", t_s, agent, n_agents);
        const double fn = sqrt(fx * fx + fy * fy + fz * fz);
        if (!(fn <= force_max_n * 1.001 && z > 0.0 && z < 2.0))
            fail_msg("t=%.3f: contact force %.1f N (run's max %.1f N) at z %.3f m", t_s, fn,
                     force_max_n, z);
    }
    fclose(f);
    printf("crowd contacts in /truth: %u of %u ticks\n", n_touching, n_rows);
    assert_true(n_rows >= 3000); /* 3 s, then the stop ramp */
    assert_true(n_touching > 300);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(
            test_e2e_rec_lockstep_shove_guarded_files_match_foxglove_readers, setup, teardown),
        cmocka_unit_test_setup_teardown(test_e2e_rec_cli_help_and_unwritable_paths, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_e2e_rec_cli_disk_full_loop_runs_on_records_counted,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_e2e_rec_cli_size_limit_mid_run_file_keeps_whole_chunks,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_e2e_rec_cli_slow_disk_reports_lost_records, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_e2e_rec_cli_lockstep_slow_disk_loses_nothing, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_e2e_rec_cli_power_cut_file_readable_up_to_last_chunk,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_e2e_rec_cli_sigusr1_dumps_the_window_around_it, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_e2e_rec_cli_gpio_button_dumps_the_window, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_e2e_rec_cli_crowd_contacts_in_truth, setup, teardown),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
