/*
 * rt/ps_recorder: the ring (overwrite, lapping, stamps), the triggers the
 * loop's state raises, flight windows (exact pre and post records, a
 * trigger during a dump, a second dump), and disk trouble: a full disk
 * (/dev/full), a path that cannot be created, a dump file that cannot be
 * created, a slow disk (PUSHSTEP_REC_IO_DELAY_NS). The loop side is driven
 * with a hand-made ps_loop_t, the writer thread is the real one.
 */
#include <errno.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmocka.h>

#include "../rt/ps_config.h"
#include "../rt/ps_mcap.h"
#include "../rt/ps_recorder.h"

static ps_board_cfg_t board;
static ps_loop_t loop; /* large: static */
static ps_recorder_t rec;
static char dir[64];
static const char JOINTS[2][PS_NAME_LEN] = {"a", "b"};

/* One tick of a loop that does nothing but what the test sets. */
static void tick(uint8_t state, uint32_t cond, bool is_button)
{
    loop.last.state_before = loop.state;
    loop.state = state;
    loop.last.cond = cond;
    loop.last.is_button_pressed = is_button;
    loop.t_deadline_ns += PS_NS_PER_MS;
    loop.counters.n_ticks++;
    loop.meas.joints[0].q_rad = (float)loop.counters.n_ticks;
    ps_recorder_on_tick(&rec, &loop);
}

static void ticks(uint32_t n)
{
    for (uint32_t i = 0; i < n; i++)
        tick(PS_SM_ACTIVE, 0, false);
}

static ps_recorder_cfg_t base_cfg(void)
{
    return (ps_recorder_cfg_t){.pre_s = 1.0,
                               .post_s = 0.5,
                               .servo_hz = 1000,
                               .compression = PS_MCAP_COMPRESS_ZSTD,
                               .cpu = -1,
                               .joint_name = JOINTS,
                               .n_joints = 2,
                               .board_name = "test",
                               .robot_name = "two joints"};
}

static void init_rec(ps_recorder_cfg_t cfg)
{
    char err[256] = "";
    int rc = ps_recorder_init(&rec, &cfg, err, sizeof(err));
    if (rc < 0)
        fail_msg("ps_recorder_init: %s", err);
}

static int setup(void **state)
{
    (void)state;
    memset(&loop, 0, sizeof(loop));
    memset(&board, 0, sizeof(board));
    board.n_buses = 1;
    loop.cfg.board = &board;
    loop.meas.n_joints = 2;
    loop.state = PS_SM_STANDBY;
    loop.t_deadline_ns = PS_NS_PER_S;
    snprintf(dir, sizeof(dir), "/tmp/test_recorder_XXXXXX");
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

/* ---- reading a file back --------------------------------------------------- */

typedef struct {
    int state_ch, events_ch;
    uint64_t n_state, first_tick, last_tick;
    uint32_t n_trigger_events;
    char meta_lost_ring[24], meta_written[24], meta_trigger[64];
} file_t;

static int on_channel(void *ctx, uint16_t id, uint16_t schema, const char *topic, const char *enc)
{
    file_t *f = ctx;
    (void)schema;
    (void)enc;
    if (strcmp(topic, "/state") == 0)
        f->state_ch = id;
    if (strcmp(topic, "/events") == 0)
        f->events_ch = id;
    return 0;
}

static int on_message(void *ctx, uint16_t ch, uint32_t seq, uint64_t t, const uint8_t *data,
                      size_t len)
{
    file_t *f = ctx;
    (void)seq;
    (void)t;
    if (ch == f->state_ch && len >= 12) {
        uint64_t tk;
        memcpy(&tk, data + 4, 8); /* first field, right after the CDR header */
        if (f->n_state == 0)
            f->first_tick = tk;
        f->last_tick = tk;
        f->n_state++;
    }
    if (ch == f->events_ch && len > 30 && memmem(data, len, "trigger", 7) != NULL)
        f->n_trigger_events++;
    return 0;
}

static int on_meta(void *ctx, const char *name, const ps_mcap_kv_t *kv, size_t n)
{
    file_t *f = ctx;
    for (size_t i = 0; i < n; i++) {
        if (strcmp(name, "pushstep.recorder") == 0 && strcmp(kv[i].key, "records_lost_ring") == 0)
            snprintf(f->meta_lost_ring, sizeof(f->meta_lost_ring), "%s", kv[i].value);
        if (strcmp(name, "pushstep.recorder") == 0 && strcmp(kv[i].key, "records_written") == 0)
            snprintf(f->meta_written, sizeof(f->meta_written), "%s", kv[i].value);
        if (strcmp(kv[i].key, "trigger") == 0)
            snprintf(f->meta_trigger, sizeof(f->meta_trigger), "%s", kv[i].value);
    }
    return 0;
}

static void read_file(const char *path, file_t *f, ps_mcap_read_info_t *info)
{
    static const ps_mcap_read_ops_t OPS = {NULL, on_channel, on_message, on_meta};
    memset(f, 0, sizeof(*f));
    f->state_ch = f->events_ch = -1;
    char err[256];
    int rc = ps_mcap_read_file(path, &OPS, f, info, err, sizeof(err));
    if (rc < 0)
        fail_msg("%s", err);
}

/* ---- the ring ------------------------------------------------------------ */

static void test_ring_overwrites_oldest_and_reader_sees_lost(void **state)
{
    (void)state;
    ps_recorder_cfg_t cfg = base_cfg();
    cfg.path = NULL;
    cfg.dir = dir;
    cfg.pre_s = 0.5;
    cfg.post_s = 0.2;
    init_rec(cfg);
    assert_int_equal(rec.n_slots, 2048); /* 2 s at least, rounded to a power of two */
    ps_rec_tick_t t;
    assert_int_equal(ps_recorder_read(&rec, 0, &t), -EAGAIN);
    ticks(3000);
    assert_int_equal(ps_recorder_read(&rec, 3000, &t), -EAGAIN);
    assert_int_equal(ps_recorder_read(&rec, 0, &t), -ESTALE); /* overwritten */
    assert_int_equal(ps_recorder_read(&rec, 3000 - 2049, &t), -ESTALE);
    assert_int_equal(ps_recorder_read(&rec, 3000 - 2048, &t), 0); /* the oldest kept */
    assert_int_equal(t.tick, 3000 - 2048);
    assert_int_equal(ps_recorder_read(&rec, 2999, &t), 0);
    assert_int_equal(t.tick, 2999);
    assert_true(t.q_rad[0] == 3000.0f);
    assert_int_equal(t.n_joints, 2);
    assert_int_equal(t.n_buses, 1);
}

static void test_init_refuses_bad_paths_and_windows(void **state)
{
    (void)state;
    char err[256];
    ps_recorder_cfg_t cfg = base_cfg();
    assert_int_equal(ps_recorder_init(&rec, &cfg, err, sizeof(err)), -EINVAL); /* no output */
    cfg.path = "/nonexistent-dir/run.mcap";
    assert_int_equal(ps_recorder_init(&rec, &cfg, err, sizeof(err)), -ENOENT);
    assert_non_null(strstr(err, "/nonexistent-dir/run.mcap"));
    cfg.path = NULL;
    cfg.dir = "/etc/passwd";
    assert_int_equal(ps_recorder_init(&rec, &cfg, err, sizeof(err)), -ENOTDIR);
    assert_non_null(strstr(err, "not a folder"));
    cfg.dir = dir;
    cfg.pre_s = 601;
    assert_int_equal(ps_recorder_init(&rec, &cfg, err, sizeof(err)), -EINVAL);
}

/* ---- triggers ------------------------------------------------------------ */

static uint32_t last_triggers(void)
{
    ps_rec_tick_t t;
    assert_int_equal(ps_recorder_read(&rec, atomic_load(&rec.head) - 1u, &t), 0);
    return t.triggers;
}

static void test_triggers_from_state_conditions_button_and_signal(void **state)
{
    (void)state;
    ps_recorder_cfg_t cfg = base_cfg();
    cfg.dir = dir;
    init_rec(cfg);
    /* stale replies while standing by at start-up: no trigger */
    tick(PS_SM_STANDBY, PS_SM_C_REPLY_STALE, false);
    assert_int_equal(last_triggers(), 0);
    tick(PS_SM_STANDBY, 0, false);
    tick(PS_SM_ACTIVE, 0, false);
    tick(PS_SM_HOLD, PS_SM_C_REPLY_STALE, false); /* a watchdog while in charge */
    assert_int_equal(last_triggers(), PS_REC_TRIG_WATCHDOG);
    tick(PS_SM_HOLD, PS_SM_C_REPLY_STALE, false); /* still stale: no new trigger */
    assert_int_equal(last_triggers(), 0);
    tick(PS_SM_DAMPING, PS_SM_C_REPLY_STALE | PS_SM_C_FALL, false);
    assert_int_equal(last_triggers(), PS_REC_TRIG_FALL);
    tick(PS_SM_DAMPING, PS_SM_C_OVERRUN, false);
    assert_int_equal(last_triggers(), PS_REC_TRIG_OVERRUN);
    tick(PS_SM_ESTOP, PS_SM_C_ESTOP_INPUT, false);
    assert_int_equal(last_triggers(), PS_REC_TRIG_ESTOP);
    tick(PS_SM_ESTOP, PS_SM_C_ESTOP_INPUT, false); /* still in ESTOP: no new trigger */
    assert_int_equal(last_triggers(), 0);
    tick(PS_SM_ESTOP, 0, true);
    assert_int_equal(last_triggers(), PS_REC_TRIG_BUTTON);
    ps_recorder_trigger(&rec, PS_REC_TRIG_SIGNAL);
    tick(PS_SM_ESTOP, 0, false);
    assert_int_equal(last_triggers(), PS_REC_TRIG_SIGNAL);
    tick(PS_SM_ESTOP, 0, false);
    assert_int_equal(last_triggers(), 0);
    assert_int_equal(atomic_load(&rec.n_trig), 6);
    assert_int_equal(atomic_load(&rec.n_trig_by[0]), 1); /* estop */
    assert_string_equal(ps_recorder_trigger_name(PS_REC_TRIG_WATCHDOG), "watchdog");
}

/* ---- flight windows ----------------------------------------------------- */

static void test_flight_dumps_pre_and_post_exactly_then_a_second_dump(void **state)
{
    (void)state;
    ps_recorder_cfg_t cfg = base_cfg();
    cfg.dir = dir;
    cfg.ring_s = 4.0; /* holds the whole test: nothing depends on the writer's timing */
    init_rec(cfg);
    assert_int_equal(ps_recorder_start(&rec), 0);
    ticks(1500); /* records 0..1499 */
    ps_recorder_trigger(&rec, PS_REC_TRIG_SIGNAL);
    ticks(1); /* record 1500 carries the trigger */
    ticks(199);
    tick(PS_SM_ESTOP, 0, false); /* record 1700: a trigger during the dump */
    ticks(899);                  /* up to 2599 */
    ps_recorder_trigger(&rec, PS_REC_TRIG_SIGNAL);
    ticks(1); /* record 2600: after the first dump: a second */
    ticks(700);
    ps_recorder_stop(&rec);
    const ps_recorder_stats_t *s = &rec.stats;
    assert_int_equal(s->n_pushed, 3301);
    assert_int_equal(s->n_triggers, 3);
    assert_int_equal(s->n_dumps, 2);
    assert_int_equal(s->n_dumps_failed, 0);
    assert_int_equal(s->dump[0].n_records, 1501); /* 1 s before, the trigger, 0.5 s after */
    assert_int_equal(s->dump[0].n_lost_ring + s->dump[0].n_lost_io, 0);
    assert_int_equal(s->dump[0].triggers, PS_REC_TRIG_SIGNAL | PS_REC_TRIG_ESTOP);
    assert_int_equal(s->dump[0].trigger_tick, 1500);
    assert_int_equal(s->dump[1].n_records, 1501);
    file_t f;
    ps_mcap_read_info_t info;
    read_file(s->dump[0].path, &f, &info);
    assert_true(info.has_footer);
    assert_int_equal(f.n_state, 1501);
    assert_int_equal(f.first_tick, 500);
    assert_int_equal(f.last_tick, 2000);
    assert_int_equal(f.n_trigger_events, 2); /* the signal and the e-stop */
    assert_string_equal(f.meta_trigger, "estop|signal");
    assert_string_equal(f.meta_written, "1501");
    read_file(s->dump[1].path, &f, &info);
    assert_int_equal(f.first_tick, 1600);
    assert_int_equal(f.last_tick, 3100);
    assert_non_null(strstr(s->dump[1].path, "flight-0002.mcap"));
}

/* The run ends inside the post window: the dump keeps what there was. */
static void test_flight_run_ending_in_post_window_closes_dump(void **state)
{
    (void)state;
    ps_recorder_cfg_t cfg = base_cfg();
    cfg.dir = dir;
    init_rec(cfg);
    assert_int_equal(ps_recorder_start(&rec), 0);
    ticks(300);
    tick(PS_SM_ESTOP, 0, false); /* record 300 */
    ticks(100);
    ps_recorder_stop(&rec);
    assert_int_equal(rec.stats.n_dumps, 1);
    assert_int_equal(rec.stats.dump[0].n_records, 401); /* all there was: 0..400 */
    file_t f;
    ps_mcap_read_info_t info;
    read_file(rec.stats.dump[0].path, &f, &info);
    assert_true(info.has_footer);
    assert_int_equal(f.n_state, 401);
}

/* ---- the largest record fits every message ---------------------------------- */

static bool full_truth(void *ctx, ps_rec_truth_t *out)
{
    (void)ctx;
    memset(out, 0, sizeof(*out));
    out->n_contacts = PS_REC_MAX_CONTACTS;
    out->push_force_n[0] = 300.0f;
    return true;
}

typedef struct {
    char topic[PS_MCAP_MAX_CHANNELS][32];
    uint64_t n[PS_MCAP_MAX_CHANNELS];
    size_t max_len;
} per_channel_t;

static int pc_channel(void *ctx, uint16_t id, uint16_t schema, const char *topic, const char *enc)
{
    per_channel_t *p = ctx;
    (void)schema;
    (void)enc;
    snprintf(p->topic[id], sizeof(p->topic[id]), "%s", topic);
    return 0;
}

static int pc_message(void *ctx, uint16_t ch, uint32_t seq, uint64_t t, const uint8_t *data,
                      size_t len)
{
    per_channel_t *p = ctx;
    (void)seq;
    (void)t;
    (void)data;
    p->n[ch]++;
    if (len > p->max_len)
        p->max_len = len;
    return 0;
}

/* Every joint, bus and contact the compile-time maxima allow, on a policy
 * tick in simulation: every channel's message is encoded and written. */
static void test_largest_record_every_channel_written(void **state)
{
    (void)state;
    static char names[PS_MAX_JOINTS][PS_NAME_LEN];
    for (unsigned j = 0; j < PS_MAX_JOINTS; j++)
        snprintf(names[j], sizeof(names[j]), "joint_with_a_long_name_%02u", j);
    char path[128];
    snprintf(path, sizeof(path), "%s/max.mcap", dir);
    ps_recorder_cfg_t cfg = base_cfg();
    cfg.path = path;
    cfg.joint_name = (const char(*)[PS_NAME_LEN])names;
    cfg.n_joints = PS_MAX_JOINTS;
    init_rec(cfg);
    ps_recorder_set_truth(&rec, (ps_rec_truth_src_t){.read = full_truth});
    board.n_buses = PS_MAX_BUSES;
    loop.meas.n_joints = PS_MAX_JOINTS;
    loop.last.is_policy_run = true;
    assert_int_equal(ps_recorder_start(&rec), 0);
    tick(PS_SM_ACTIVE, 0, false);
    tick(PS_SM_ESTOP, PS_SM_C_ESTOP_INPUT | PS_SM_C_REQ_ESTOP | PS_SM_C_BUS_OFF, false);
    ps_recorder_stop(&rec);
    assert_int_equal(rec.stats.cont.n_records, 2);
    per_channel_t p;
    memset(&p, 0, sizeof(p));
    const ps_mcap_read_ops_t ops = {NULL, pc_channel, pc_message, NULL};
    ps_mcap_read_info_t info;
    char err[256];
    assert_int_equal(ps_mcap_read_file(path, &ops, &p, &info, err, sizeof(err)), 0);
    assert_true(info.has_footer);
    static const char *const PER_TICK[] = {"/joints", "/imu",   "/estimate", "/state",
                                           "/timing", "/buses", "/policy",   "/truth"};
    for (size_t k = 0; k < sizeof(PER_TICK) / sizeof(PER_TICK[0]); k++) {
        uint64_t n = 0;
        for (unsigned c = 0; c < PS_MCAP_MAX_CHANNELS; c++)
            if (strcmp(p.topic[c], PER_TICK[k]) == 0)
                n = p.n[c];
        if (n != 2)
            fail_msg("%s: %llu messages, want 2", PER_TICK[k], (unsigned long long)n);
    }
    print_message("largest message: %zu bytes\n", p.max_len);
}

/* ---- disk trouble -------------------------------------------------------- */

static void test_disk_full_counts_every_record_lost_io(void **state)
{
    (void)state;
    ps_recorder_cfg_t cfg = base_cfg();
    cfg.path = "/dev/full";
    init_rec(cfg);
    assert_int_equal(ps_recorder_start(&rec), 0);
    ticks(1000);
    ps_recorder_stop(&rec);
    const ps_rec_file_stats_t *c = &rec.stats.cont;
    assert_int_equal(c->err, -ENOSPC);
    assert_int_equal(c->n_records, 0);
    assert_int_equal(c->n_lost_io + c->n_lost_ring, 1000);
}

static void test_dump_that_cannot_be_created_is_counted_failed(void **state)
{
    (void)state;
    char blocker[128];
    snprintf(blocker, sizeof(blocker), "%s/flight-0001.mcap", dir);
    assert_int_equal(mkdir(blocker, 0755), 0); /* a folder where the file should go */
    ps_recorder_cfg_t cfg = base_cfg();
    cfg.dir = dir;
    init_rec(cfg);
    assert_int_equal(ps_recorder_start(&rec), 0);
    ticks(200);
    ps_recorder_trigger(&rec, PS_REC_TRIG_SIGNAL);
    ticks(800);
    ps_recorder_stop(&rec);
    assert_int_equal(rec.stats.n_dumps, 1);
    assert_int_equal(rec.stats.n_dumps_failed, 1);
    assert_int_equal(rec.stats.dump[0].err, -EISDIR);
    assert_int_equal(rec.stats.dump[0].n_records, 0);
    assert_int_equal(rec.stats.dump[0].n_lost_io, 201 + 500); /* what it would have held */
}

/* A disk that takes 0.3 s per write: the loop's pushes never wait, the
 * writer falls behind the ring and says how many records it lost, in the
 * stats and in the file. */
static void test_slow_disk_loses_records_counted_in_stats_and_file(void **state)
{
    (void)state;
    char path[128];
    snprintf(path, sizeof(path), "%s/slow.mcap", dir);
    setenv("PUSHSTEP_REC_IO_DELAY_NS", "300000000", 1);
    ps_recorder_cfg_t cfg = base_cfg();
    cfg.path = path;
    cfg.ring_s = 2.0;
    cfg.chunk_size = 8u << 20; /* few writes: the test stays short */
    init_rec(cfg);
    unsetenv("PUSHSTEP_REC_IO_DELAY_NS");
    assert_int_equal(rec.io_delay_ns, 300000000);
    assert_int_equal(ps_recorder_start(&rec), 0);
    ticks(8000); /* far faster than the writer's first two writes take */
    ps_recorder_stop(&rec);
    const ps_rec_file_stats_t *c = &rec.stats.cont;
    assert_int_equal(c->err, 0);
    assert_true(c->n_lost_ring > 0);
    assert_int_equal(c->n_records + c->n_lost_ring + c->n_lost_io, 8000);
    file_t f;
    ps_mcap_read_info_t info;
    read_file(path, &f, &info);
    assert_true(info.has_footer);
    assert_int_equal(f.n_state, c->n_records);
    char lost[24];
    snprintf(lost, sizeof(lost), "%llu", (unsigned long long)c->n_lost_ring);
    assert_string_equal(f.meta_lost_ring, lost);
}

/* The same slow disk in an unpaced run (lockstep, replay): the loop waits
 * for the writer, so the continuous file and both flight dumps hold every
 * record, the dumps their whole windows; the loop noted that it waited. */
static void test_lossless_slow_disk_loses_nothing_in_file_or_dumps(void **state)
{
    (void)state;
    char path[128];
    snprintf(path, sizeof(path), "%s/lossless.mcap", dir);
    setenv("PUSHSTEP_REC_IO_DELAY_NS", "20000000", 1);
    ps_recorder_cfg_t cfg = base_cfg();
    cfg.path = path;
    cfg.dir = dir;
    cfg.ring_s = 2.0; /* 2048 slots: the 1.5 s dump window fits, little more */
    cfg.chunk_size = 64u << 10;
    cfg.is_lossless = true;
    init_rec(cfg);
    unsetenv("PUSHSTEP_REC_IO_DELAY_NS");
    assert_int_equal(ps_recorder_start(&rec), 0);
    ticks(2500);
    ps_recorder_trigger(&rec, PS_REC_TRIG_SIGNAL);
    ticks(1); /* record 2500 */
    ticks(1999);
    ps_recorder_trigger(&rec, PS_REC_TRIG_SIGNAL);
    ticks(1); /* record 4500 */
    ticks(1499);
    ps_recorder_stop(&rec);
    const ps_recorder_stats_t *s = &rec.stats;
    const ps_rec_file_stats_t *c = &s->cont;
    print_message("lossless: the loop waited on %llu ticks\n",
                  (unsigned long long)rec.n_lossless_waits);
    assert_true(rec.n_lossless_waits > 0); /* the disk was slower than the loop */
    assert_int_equal(c->err, 0);
    assert_int_equal(c->n_records, 6000);
    assert_int_equal(c->n_lost_ring + c->n_lost_io, 0);
    assert_int_equal(s->n_dumps, 2);
    for (unsigned i = 0; i < 2; i++) {
        assert_int_equal(s->dump[i].n_records, 1501);
        assert_int_equal(s->dump[i].n_lost_ring + s->dump[i].n_lost_io, 0);
    }
    file_t f;
    ps_mcap_read_info_t info;
    read_file(path, &f, &info);
    assert_true(info.has_footer);
    assert_int_equal(f.n_state, 6000);
    read_file(s->dump[1].path, &f, &info);
    assert_int_equal(f.first_tick, 3500);
    assert_int_equal(f.last_tick, 5000);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_ring_overwrites_oldest_and_reader_sees_lost, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_init_refuses_bad_paths_and_windows, setup, teardown),
        cmocka_unit_test_setup_teardown(test_triggers_from_state_conditions_button_and_signal,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_flight_dumps_pre_and_post_exactly_then_a_second_dump,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_flight_run_ending_in_post_window_closes_dump, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_largest_record_every_channel_written, setup, teardown),
        cmocka_unit_test_setup_teardown(test_disk_full_counts_every_record_lost_io, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_lossless_slow_disk_loses_nothing_in_file_or_dumps,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_dump_that_cannot_be_created_is_counted_failed, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_slow_disk_loses_records_counted_in_stats_and_file,
                                        setup, teardown),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
