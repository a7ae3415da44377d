#include "ps_args.h"
#include "ps_reclog.h"

#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "ps_err.h"
#include "ps_limits.h"
#include "ps_mcap.h"
#include "ps_rosmsg.h"
#include "ps_sm.h"

#define MAX_CH      64u
#define MAX_SCHEMAS 64u
#define MAX_COLS    512u
#define MAX_JOINTS  64u
#define MAX_TIMING  16u
#define TEXT_CAP    16384u

static const char USAGE[] =
    "usage: pushstep log FILE.mcap [--events] [--csv OUT.csv] [--plot OUT.png]\n"
    "                              [--channels LIST] [--signals LIST] [--from S] [--to S]\n"
    "Reads a flight-recorder file (pushstep --record / --flight; any MCAP file of\n"
    "ros2msg/CDR messages with flat schemas).\n"
    "  (no option)       summary: closed or cut (and where), duration, channels and\n"
    "                    message counts, the run and the recorder (records lost),\n"
    "                    events (transitions, triggers), fault conditions seen,\n"
    "                    latency per stage (p50/p99/max from /timing); a long\n"
    "                    recording's events are listed up to a screenful\n"
    "  --events          every event (transitions, triggers) in time order, one per\n"
    "                    line, and nothing else\n"
    "  --csv OUT.csv     the chosen channels or signals as columns, one row per\n"
    "                    log time (t_s from the first message); a channel without a\n"
    "                    message at that time repeats its last value\n"
    "  --plot OUT.png    the chosen signals over time (gnuplot, Debian gnuplot-nox)\n"
    "  --channels LIST   channels to export, e.g. /estimate,/imu (all their fields)\n"
    "  --signals LIST    CHANNEL.FIELD, CHANNEL.FIELD[i] or CHANNEL.FIELD.JOINT,\n"
    "                    e.g. estimate.com_m[0],joints.q_rad.l_knee; or `balance`:\n"
    "                    CoM, capture point and support polygon along x and y, with\n"
    "                    the push force (a plot in two panels)\n"
    "  --from S, --to S  time window, seconds from the first message\n";

static const char BALANCE[] =
    "estimate.com_m[0],estimate.capture_point_m[0],estimate.support_min_m[0],"
    "estimate.support_max_m[0],estimate.com_m[1],estimate.capture_point_m[1],"
    "estimate.support_min_m[1],estimate.support_max_m[1],truth.push_force_n[0],"
    "truth.push_force_n[1]";

typedef struct {
    uint16_t id, schema;
    char topic[64];
    uint64_t n;
    uint32_t n_elems[PS_ROSMSG_MAX_FIELDS]; /**< elements of each field in the first message */
    bool has_first;
} chan_t;

typedef struct {
    uint16_t id;
    char name[96];
    ps_rosmsg_parsed_t def;
} schema_t;

typedef struct {
    uint16_t ch; /**< index into chans */
    uint32_t field, elem;
    char name[112];
} col_t;

typedef struct {
    double *v;
    size_t n, cap;
} series_t;

typedef struct {
    /* options */
    const char *path, *csv, *plot, *channels, *signals;
    double from_s, to_s;
    bool is_balance;
    /* what the file holds */
    schema_t *schemas;
    uint32_t n_schemas;
    chan_t chans[MAX_CH];
    uint32_t n_chans;
    uint64_t t0, t_last;
    bool has_t0;
    char joints[MAX_JOINTS][48];
    uint32_t n_joints;
    char meta[TEXT_CAP];
    char events[TEXT_CAP];
    uint32_t n_events, n_events_listed;
    bool is_events_only; /**< --events: print each event as read, no summary */
    double cond_first_s[32];
    uint64_t cond_ticks[32];
    series_t timing[MAX_TIMING];
    char timing_name[MAX_TIMING][PS_ROSMSG_NAME_LEN];
    uint32_t n_timing;
    /* decode scratch */
    int cur_ch;
    char kind[32], text[256];
    /* export */
    bool is_export;
    col_t cols[MAX_COLS];
    uint32_t n_cols;
    /** column of each element, by channel and field (NULL: none chosen; -1: element not
     *  chosen), so a decoded value finds its column at once */
    int32_t *col_of[MAX_CH][PS_ROSMSG_MAX_FIELDS];
    double row[MAX_COLS];
    double col_min[MAX_COLS], col_max[MAX_COLS]; /**< over the rows written */
    bool has_row;
    uint64_t row_t;
    FILE *out[2]; /* csv, plot data */
    uint64_t n_rows;
} log_t;

static chan_t *chan_by_id(log_t *lg, uint16_t id, int *out_idx)
{
    for (uint32_t i = 0; i < lg->n_chans; i++)
        if (lg->chans[i].id == id) {
            if (out_idx)
                *out_idx = (int)i;
            return &lg->chans[i];
        }
    return NULL;
}

static const ps_rosmsg_parsed_t *def_of(const log_t *lg, uint16_t schema)
{
    for (uint32_t i = 0; i < lg->n_schemas; i++)
        if (lg->schemas[i].id == schema)
            return &lg->schemas[i].def;
    return NULL;
}

static int on_schema(void *ctx, uint16_t id, const char *name, const char *enc, const uint8_t *data,
                     size_t len)
{
    log_t *lg = ctx;
    if (lg->n_schemas >= MAX_SCHEMAS || strcmp(enc, "ros2msg") != 0)
        return 0; /* not ours to decode: its channel is listed, not decoded */
    schema_t *s = &lg->schemas[lg->n_schemas];
    char err[160];
    if (ps_rosmsg_parse((const char *)data, len, &s->def, err, sizeof(err)) < 0)
        return 0;
    s->id = id;
    snprintf(s->name, sizeof(s->name), "%s", name);
    lg->n_schemas++;
    return 0;
}

static int on_channel(void *ctx, uint16_t id, uint16_t schema, const char *topic, const char *enc)
{
    log_t *lg = ctx;
    (void)enc;
    if (lg->n_chans >= MAX_CH)
        return 0;
    chan_t *c = &lg->chans[lg->n_chans++];
    memset(c, 0, sizeof(*c));
    c->id = id;
    c->schema = schema;
    snprintf(c->topic, sizeof(c->topic), "%s", topic);
    return 0;
}

static void split_joints(log_t *lg, const char *list)
{
    lg->n_joints = 0;
    const char *p = list;
    while (*p && lg->n_joints < MAX_JOINTS) {
        const char *comma = strchr(p, ',');
        size_t n = comma ? (size_t)(comma - p) : strlen(p);
        snprintf(lg->joints[lg->n_joints++], sizeof(lg->joints[0]), "%.*s", (int)n, p);
        p += n + (comma ? 1 : 0);
    }
}

static int on_metadata(void *ctx, const char *name, const ps_mcap_kv_t *kv, size_t n)
{
    log_t *lg = ctx;
    size_t used = strlen(lg->meta);
    used += (size_t)snprintf(lg->meta + used, TEXT_CAP - used, "  %s:", name);
    for (size_t i = 0; i < n && used < TEXT_CAP; i++) {
        if (strcmp(kv[i].key, "joint_names") == 0) {
            split_joints(lg, kv[i].value);
            continue; /* long; the joints are the CSV's column names */
        }
        used +=
            (size_t)snprintf(lg->meta + used, TEXT_CAP - used, " %s=%s", kv[i].key, kv[i].value);
    }
    if (used < TEXT_CAP - 1)
        strcat(lg->meta, "\n");
    return 0;
}

/* ---- pass 1: the summary's figures ------------------------------------------ */

static void series_add(series_t *s, double v)
{
    if (s->n == s->cap) {
        size_t cap = s->cap ? s->cap * 2 : 4096;
        double *p = realloc(s->v, cap * sizeof(double));
        if (p == NULL)
            return;
        s->v = p;
        s->cap = cap;
    }
    s->v[s->n++] = v;
}

/* A schema with a sequence: its length varies, so every message is read
 * for the longest (the columns a CSV gets). */
static bool has_sequence(const ps_rosmsg_parsed_t *def)
{
    for (uint32_t f = 0; def != NULL && f < def->n_fields; f++)
        if (def->fields[f].kind == PS_ROSMSG_SEQUENCE)
            return true;
    return false;
}

static void summary_value(void *ctx, const ps_rosmsg_value_t *v)
{
    log_t *lg = ctx;
    chan_t *c = &lg->chans[lg->cur_ch];
    const ps_rosmsg_parsed_t *def = def_of(lg, c->schema);
    const char *field = def->fields[v->field_idx].name;
    /* every message: a sequence (the crowd's contacts) varies in length */
    if (v->elem_idx + 1u > c->n_elems[v->field_idx])
        c->n_elems[v->field_idx] = v->elem_idx + 1u;
    if (strcmp(c->topic, "/events") == 0 && v->is_string) {
        char *dst = strcmp(field, "kind") == 0 ? lg->kind : lg->text;
        const size_t cap = strcmp(field, "kind") == 0 ? sizeof(lg->kind) : sizeof(lg->text);
        snprintf(dst, cap, "%.*s", (int)v->text_len, v->text);
    }
    if (strcmp(c->topic, "/state") == 0 && strcmp(field, "cond") == 0) {
        const uint32_t cond = (uint32_t)v->value;
        const double t_s = (double)(lg->t_last - lg->t0) * 1e-9;
        for (unsigned b = 0; b < 32; b++)
            if (cond & (1u << b)) {
                if (lg->cond_ticks[b]++ == 0)
                    lg->cond_first_s[b] = t_s;
            }
    }
    if (strcmp(c->topic, "/timing") == 0 && !v->is_string && v->value >= 0) {
        const size_t n = strlen(field);
        if (n < 4 || strcmp(field + n - 3, "_ns") != 0 || strcmp(field, "t_ns") == 0)
            return;
        uint32_t k = 0;
        while (k < lg->n_timing && strcmp(lg->timing_name[k], field) != 0)
            k++;
        if (k == lg->n_timing && lg->n_timing < MAX_TIMING)
            snprintf(lg->timing_name[lg->n_timing++], PS_ROSMSG_NAME_LEN, "%s", field);
        if (k < lg->n_timing)
            series_add(&lg->timing[k], v->value);
    }
}

static int on_message_summary(void *ctx, uint16_t id, uint32_t seq, uint64_t t, const uint8_t *data,
                              size_t len)
{
    log_t *lg = ctx;
    (void)seq;
    int idx;
    chan_t *c = chan_by_id(lg, id, &idx);
    if (c == NULL)
        return 0;
    if (!lg->has_t0 || t < lg->t0)
        lg->t0 = t;
    lg->has_t0 = true;
    if (t > lg->t_last)
        lg->t_last = t;
    c->n++;
    const ps_rosmsg_parsed_t *def = def_of(lg, c->schema);
    const bool is_wanted = !c->has_first || strcmp(c->topic, "/events") == 0 ||
                           strcmp(c->topic, "/state") == 0 || strcmp(c->topic, "/timing") == 0 ||
                           has_sequence(def);
    if (def == NULL || !is_wanted)
        return 0;
    lg->cur_ch = idx;
    lg->kind[0] = lg->text[0] = '\0';
    if (ps_rosmsg_decode(def, data, len, summary_value, lg) < 0)
        return 0; /* a message its schema does not describe: counted, not decoded */
    c->has_first = true;
    if (strcmp(c->topic, "/events") == 0) {
        char line[320];
        const int n = snprintf(line, sizeof(line), "  t=%8.3fs %-10s %s\n",
                               (double)(t - lg->t0) * 1e-9, lg->kind, lg->text);
        const size_t used = strlen(lg->events);
        lg->n_events++;
        if (lg->is_events_only)
            fputs(line, stdout);
        else if (n > 0 && used + (size_t)n < TEXT_CAP) { /* whole lines only */
            memcpy(lg->events + used, line, (size_t)n + 1u);
            lg->n_events_listed++;
        }
    }
    return 0;
}

static int cmp_double(const void *a, const void *b)
{
    const double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static double quantile(const series_t *s, double q)
{
    if (s->n == 0)
        return NAN;
    size_t i = (size_t)ceil(q * (double)s->n);
    return s->v[i > 0 ? (i > s->n ? s->n - 1 : i - 1) : 0];
}

static void print_summary(log_t *lg, const ps_mcap_read_info_t *info)
{
    printf("%s: %s, %llu bytes, %u chunks, %llu messages\n", lg->path,
           info->has_footer ? "closed (summary and index present)" : "NOT CLOSED",
           (unsigned long long)info->file_bytes, info->n_chunks,
           (unsigned long long)info->n_messages);
    if (!info->has_footer)
        printf("  cut: reading stopped %s; everything before it was read\n", info->stop_reason);
    const double dur = lg->has_t0 ? (double)(lg->t_last - lg->t0) * 1e-9 : 0.0;
    printf("duration %.3f s (log times %.3f .. %.3f s of the recording clock)\n", dur,
           (double)lg->t0 * 1e-9, (double)lg->t_last * 1e-9);
    printf("channels:\n");
    for (uint32_t i = 0; i < lg->n_chans; i++) {
        const chan_t *c = &lg->chans[i];
        const char *schema = "?";
        for (uint32_t k = 0; k < lg->n_schemas; k++)
            if (lg->schemas[k].id == c->schema)
                schema = lg->schemas[k].name;
        printf("  %-10s %8llu messages  %s\n", c->topic, (unsigned long long)c->n, schema);
    }
    printf("metadata:\n%s", lg->meta[0] ? lg->meta : "  none\n");
    if (lg->n_events_listed < lg->n_events)
        printf("events (%u; the first %u listed, --events lists all):\n%s", lg->n_events,
               lg->n_events_listed, lg->events);
    else
        printf("events (%u):\n%s", lg->n_events, lg->events[0] ? lg->events : "  none\n");
    printf("conditions seen (first time, ticks):\n");
    bool any = false;
    for (unsigned b = 0; b < 32; b++) {
        if (lg->cond_ticks[b] == 0)
            continue;
        printf("  %-15s t=%8.3fs %8llu ticks\n", ps_sm_cond_name(1u << b), lg->cond_first_s[b],
               (unsigned long long)lg->cond_ticks[b]);
        any = true;
    }
    if (!any)
        printf("  none\n");
    if (lg->n_timing > 0) {
        printf("latency (us):        n       p50       p99       max\n");
        for (uint32_t k = 0; k < lg->n_timing; k++) {
            series_t *s = &lg->timing[k];
            qsort(s->v, s->n, sizeof(double), cmp_double);
            printf("  %-12s %9zu %9.1f %9.1f %9.1f\n", lg->timing_name[k], s->n,
                   quantile(s, 0.5) * 1e-3, quantile(s, 0.99) * 1e-3,
                   s->n ? s->v[s->n - 1] * 1e-3 : NAN);
        }
    }
}

/* ---- export ----------------------------------------------------------------- */

static chan_t *chan_by_name(log_t *lg, const char *name, size_t len, int *out_idx)
{
    for (uint32_t i = 0; i < lg->n_chans; i++) {
        const char *t = lg->chans[i].topic;
        if (t[0] == '/')
            t++;
        const char *n = name[0] == '/' ? name + 1 : name;
        const size_t nl = name[0] == '/' ? len - 1 : len;
        if (strlen(t) == nl && strncmp(t, n, nl) == 0) {
            *out_idx = (int)i;
            return &lg->chans[i];
        }
    }
    return NULL;
}

static bool is_by_joint(const log_t *lg, const chan_t *c, uint32_t n_elems)
{
    return lg->n_joints > 0 && n_elems == lg->n_joints &&
           (strcmp(c->topic, "/joints") == 0 || strcmp(c->topic, "/policy") == 0);
}

static int add_col(log_t *lg, int ch, uint32_t field, uint32_t elem)
{
    if (lg->n_cols >= MAX_COLS)
        return -E2BIG;
    const chan_t *c = &lg->chans[ch];
    const ps_rosmsg_pfield_t *f = &def_of(lg, c->schema)->fields[field];
    col_t col = {.ch = (uint16_t)ch, .field = field, .elem = elem};
    const char *topic = c->topic[0] == '/' ? c->topic + 1 : c->topic;
    if (f->kind == PS_ROSMSG_SCALAR)
        snprintf(col.name, sizeof(col.name), "%s.%s", topic, f->name);
    else if (is_by_joint(lg, c, c->n_elems[field]))
        snprintf(col.name, sizeof(col.name), "%s.%s.%s", topic, f->name, lg->joints[elem]);
    else
        snprintf(col.name, sizeof(col.name), "%s.%s[%u]", topic, f->name, elem);
    int32_t **map = &lg->col_of[ch][field];
    const uint32_t n_elems = c->n_elems[field] > 0 ? c->n_elems[field] : 1u;
    if (*map == NULL) {
        *map = malloc(n_elems * sizeof(int32_t));
        if (*map == NULL)
            return -ENOMEM;
        for (uint32_t e = 0; e < n_elems; e++)
            (*map)[e] = -1;
    }
    if (elem < n_elems)
        (*map)[elem] = (int32_t)lg->n_cols;
    lg->cols[lg->n_cols++] = col;
    return 0;
}

static int add_field_cols(log_t *lg, int ch, uint32_t field)
{
    const chan_t *c = &lg->chans[ch];
    const ps_rosmsg_pfield_t *f = &def_of(lg, c->schema)->fields[field];
    if (f->type == PS_ROSMSG_STRING)
        return 0; /* text does not go into number columns */
    for (uint32_t e = 0; e < c->n_elems[field]; e++) {
        int rc = add_col(lg, ch, field, e);
        if (rc < 0)
            return rc;
    }
    return 0;
}

/* One signal: CHANNEL.FIELD, CHANNEL.FIELD[i], CHANNEL.FIELD.JOINT */
static int add_signal(log_t *lg, const char *sig, bool is_optional)
{
    const char *dot = strchr(sig + 1, '.');
    int ch = -1;
    chan_t *c = NULL;
    while (dot != NULL && (c = chan_by_name(lg, sig, (size_t)(dot - sig), &ch)) == NULL)
        dot = strchr(dot + 1, '.');
    const ps_rosmsg_parsed_t *def = c ? def_of(lg, c->schema) : NULL;
    if (c == NULL || def == NULL) {
        if (is_optional)
            return 0;
        fprintf(stderr, "pushstep log: %s: no channel (with a ros2msg schema) by that name\n", sig);
        return -ENOENT;
    }
    char field[PS_ROSMSG_NAME_LEN] = "", rest[64] = "";
    const char *fs = dot + 1;
    size_t fl = strcspn(fs, ".[");
    snprintf(field, sizeof(field), "%.*s", (int)fl, fs);
    snprintf(rest, sizeof(rest), "%s", fs + fl);
    uint32_t fi = 0;
    while (fi < def->n_fields && strcmp(def->fields[fi].name, field) != 0)
        fi++;
    if (fi == def->n_fields) {
        fprintf(stderr, "pushstep log: %s: %s has no field %s\n", sig, c->topic, field);
        return -ENOENT;
    }
    if (rest[0] == '\0')
        return add_field_cols(lg, ch, fi);
    long elem = -1;
    if (rest[0] == '[') {
        char *end = NULL;
        elem = strtol(rest + 1, &end, 10);
        if (end == rest + 1 || *end != ']' || end[1] != '\0')
            elem = -1;
    } else {
        for (uint32_t j = 0; j < lg->n_joints; j++)
            if (strcmp(rest + 1, lg->joints[j]) == 0 && is_by_joint(lg, c, c->n_elems[fi]))
                elem = j;
    }
    if (elem < 0 || (uint32_t)elem >= c->n_elems[fi]) {
        fprintf(stderr, "pushstep log: %s: no element %s (the field has %u)\n", sig, rest,
                c->n_elems[fi]);
        return -ENOENT;
    }
    return add_col(lg, ch, fi, (uint32_t)elem);
}

static int select_cols(log_t *lg)
{
    char buf[2048];
    if (lg->channels != NULL) {
        snprintf(buf, sizeof(buf), "%s", lg->channels);
        for (char *tok = strtok(buf, ","); tok; tok = strtok(NULL, ",")) {
            int ch;
            chan_t *c = chan_by_name(lg, tok, strlen(tok), &ch);
            const ps_rosmsg_parsed_t *def = c ? def_of(lg, c->schema) : NULL;
            if (def == NULL) {
                fprintf(stderr, "pushstep log: --channels: no channel %s in %s\n", tok, lg->path);
                return -ENOENT;
            }
            for (uint32_t f = 0; f < def->n_fields; f++)
                if (add_field_cols(lg, ch, f) < 0)
                    return -E2BIG;
        }
    }
    if (lg->signals != NULL) {
        snprintf(buf, sizeof(buf), "%s", lg->is_balance ? BALANCE : lg->signals);
        char *save = NULL;
        for (char *tok = strtok_r(buf, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
            /* the balance preset's push force is there only in simulation */
            int rc = add_signal(lg, tok, lg->is_balance && strncmp(tok, "truth.", 6) == 0);
            if (rc < 0)
                return rc;
        }
    }
    if (lg->n_cols == 0) {
        fprintf(stderr, "pushstep log: nothing to export: give --channels or --signals\n");
        return -EINVAL;
    }
    return 0;
}

/* Integral values (ticks, times in ns, counters, flags) in full, as integers:
 * %.9g would write a time of 4,493,000,000 ns as 4.493e+09. Up to 2^53 a
 * double holds every integer exactly. */
static void write_value(FILE *f, char sep, double v)
{
    if (v == trunc(v) && fabs(v) < 9007199254740992.0)
        fprintf(f, "%c%.0f", sep, v);
    else
        fprintf(f, "%c%.9g", sep, v);
}

static void emit_row(log_t *lg)
{
    const double t_s = (double)(lg->row_t - lg->t0) * 1e-9;
    if (!lg->has_row || t_s < lg->from_s || t_s > lg->to_s)
        return;
    for (uint32_t i = 0; i < lg->n_cols; i++) {
        lg->col_min[i] = fmin(lg->col_min[i], lg->row[i]); /* fmin skips NaN */
        lg->col_max[i] = fmax(lg->col_max[i], lg->row[i]);
    }
    for (int k = 0; k < 2; k++) {
        FILE *f = lg->out[k];
        if (f == NULL)
            continue;
        fprintf(f, "%.6f", t_s);
        for (uint32_t i = 0; i < lg->n_cols; i++)
            if (isnan(lg->row[i])) /* no value: empty in CSV, gnuplot's missing */
                fputs(k == 0 ? "," : "\tNaN", f);
            else
                write_value(f, k == 0 ? ',' : '\t', lg->row[i]);
        fputc('\n', f);
    }
    lg->n_rows++;
}

static void export_value(void *ctx, const ps_rosmsg_value_t *v)
{
    log_t *lg = ctx;
    const int32_t *map = lg->col_of[lg->cur_ch][v->field_idx];
    const uint32_t n = lg->chans[lg->cur_ch].n_elems[v->field_idx];
    if (map != NULL && v->elem_idx < (n > 0 ? n : 1u) && map[v->elem_idx] >= 0)
        lg->row[map[v->elem_idx]] = v->value;
}

static int on_message_export(void *ctx, uint16_t id, uint32_t seq, uint64_t t, const uint8_t *data,
                             size_t len)
{
    log_t *lg = ctx;
    (void)seq;
    int idx;
    chan_t *c = chan_by_id(lg, id, &idx);
    bool is_used = false;
    for (uint32_t f = 0; c != NULL && f < PS_ROSMSG_MAX_FIELDS && !is_used; f++)
        is_used = lg->col_of[idx][f] != NULL;
    if (!is_used)
        return 0;
    if (lg->has_row && t != lg->row_t)
        emit_row(lg);
    lg->row_t = t;
    lg->has_row = true;
    lg->cur_ch = idx;
    /* a sequence's elements past this message's length are empty, not the
     * last value of a longer one */
    for (uint32_t i = 0; i < lg->n_cols; i++)
        if (lg->cols[i].ch == idx &&
            def_of(lg, c->schema)->fields[lg->cols[i].field].kind == PS_ROSMSG_SEQUENCE)
            lg->row[i] = NAN;
    (void)ps_rosmsg_decode(def_of(lg, c->schema), data, len, export_value, lg);
    return 0;
}

/* gnuplot script: one panel of every signal, or the balance preset's two
 * (x and y: CoM, capture point, support polygon band; push force on y2). */
static int plot(log_t *lg, const char *data_path)
{
    if (system("command -v gnuplot >/dev/null 2>&1") != 0) {
        fprintf(stderr, "pushstep log: --plot needs gnuplot: apt-get install gnuplot-nox\n");
        return -ENOENT;
    }
    char cmd[64];
    snprintf(cmd, sizeof(cmd), "gnuplot");
    FILE *g = popen(cmd, "w");
    if (g == NULL)
        return -errno;
    fprintf(g, "set terminal pngcairo size 1200,%d noenhanced font \",10\"\n",
            lg->is_balance ? 900 : 600);
    fprintf(g, "set output \"%s\"\nset grid\nset xlabel \"t (s)\"\nset key outside right\n",
            lg->plot);
    if (lg->is_balance) {
        const bool has_push = lg->n_cols >= 10;
        fprintf(g, "set multiplot layout 2,1 title \"%s: balance\"\n", lg->path);
        for (int axis = 0; axis < 2; axis++) {
            const int b = 2 + axis * 4; /* data columns: t, then 4 per axis */
            fprintf(g, "set ylabel \"%s (m)\"\n", axis == 0 ? "x, forward" : "y, left");
            if (has_push) {
                /* a range around the force (all zero sideways: still a range) */
                const double lo = fmin(lg->col_min[8 + axis], 0.0) - 10.0;
                const double hi = fmax(lg->col_max[8 + axis], 0.0) + 10.0;
                fprintf(g, "set y2label \"push (N)\"\nset y2tics\nset y2range [%g:%g]\n",
                        isfinite(lo) ? lo : -10.0, isfinite(hi) ? hi : 10.0);
            }
            fprintf(g,
                    "plot \"%s\" using 1:%d:%d with filledcurves fs transparent solid 0.25 "
                    "title \"support polygon\", \"\" using 1:%d with lines lw 2 title \"CoM\", "
                    "\"\" using 1:%d with lines lw 2 title \"capture point\"",
                    data_path, b + 2, b + 3, b, b + 1);
            if (has_push)
                fprintf(g, ", \"\" using 1:%d axes x1y2 with lines dt 2 title \"push %s\"",
                        10 + axis, axis == 0 ? "x" : "y");
            fprintf(g, "\n");
        }
        fprintf(g, "unset multiplot\n");
    } else {
        fprintf(g, "set title \"%s\"\nplot ", lg->path);
        for (uint32_t i = 0; i < lg->n_cols; i++)
            fprintf(g, "%s\"%s\" using 1:%u with lines title \"%s\"", i ? ", " : "", data_path,
                    i + 2, lg->cols[i].name);
        fprintf(g, "\n");
    }
    const int status = pclose(g);
    if (status != 0) {
        fprintf(stderr, "pushstep log: gnuplot failed writing %s\n", lg->plot);
        return -EIO;
    }
    return 0;
}

static int run_export(log_t *lg)
{
    int rc = select_cols(lg);
    if (rc < 0)
        return 2;
    char data_path[64] = "";
    if (lg->csv != NULL && (lg->out[0] = fopen(lg->csv, "w")) == NULL) {
        fprintf(stderr, "pushstep log: %s: %s\n", lg->csv, strerror(errno));
        return 1;
    }
    if (lg->plot != NULL) {
        snprintf(data_path, sizeof(data_path), "/tmp/pushstep_log_XXXXXX");
        const int fd = mkstemp(data_path);
        lg->out[1] = fd >= 0 ? fdopen(fd, "w") : NULL;
        if (lg->out[1] == NULL) {
            fprintf(stderr, "pushstep log: no temporary file for the plot's data\n");
            return 1;
        }
    }
    if (lg->out[0] != NULL) {
        fprintf(lg->out[0], "t_s");
        for (uint32_t i = 0; i < lg->n_cols; i++)
            fprintf(lg->out[0], ",%s", lg->cols[i].name);
        fputc('\n', lg->out[0]);
    }
    for (uint32_t i = 0; i < lg->n_cols; i++) {
        lg->row[i] = NAN;
        lg->col_min[i] = INFINITY;
        lg->col_max[i] = -INFINITY;
    }
    const ps_mcap_read_ops_t ops = {NULL, NULL, on_message_export, NULL};
    ps_mcap_read_info_t info;
    char err[PS_ERR_MSG_LEN];
    rc = ps_mcap_read_file(lg->path, &ops, lg, &info, err, sizeof(err));
    emit_row(lg);
    int status = rc < 0 ? 1 : 0;
    if (lg->out[0] != NULL && fclose(lg->out[0]) != 0)
        status = 1;
    if (lg->out[0] != NULL)
        printf("csv: %llu rows of %u columns to %s\n", (unsigned long long)lg->n_rows, lg->n_cols,
               lg->csv);
    if (lg->out[1] != NULL) {
        fclose(lg->out[1]);
        if (status == 0 && plot(lg, data_path) < 0)
            status = 1;
        else if (status == 0)
            printf("plot: %u signals to %s\n", lg->n_cols, lg->plot);
        unlink(data_path);
    }
    return status;
}

static int parse_args(int argc, char **argv, log_t *lg)
{
    static const struct option LONG[] = {
        {"csv", required_argument, NULL, 'c'},
        {"plot", required_argument, NULL, 'p'},
        {"channels", required_argument, NULL, 'C'},
        {"signals", required_argument, NULL, 's'},
        {"from", required_argument, NULL, 'f'},
        {"to", required_argument, NULL, 't'},
        {"events", no_argument, NULL, 'e'},
        {"help", no_argument, NULL, 'h'},
        {NULL, 0, NULL, 0},
    };
    lg->from_s = -INFINITY;
    lg->to_s = INFINITY;
    optind = 1;
    int c;
    while ((c = getopt_long(argc, argv, "h", LONG, NULL)) != -1) {
        switch (c) {
        case 'c':
            lg->csv = optarg;
            break;
        case 'p':
            lg->plot = optarg;
            break;
        case 'e':
            lg->is_events_only = true;
            break;
        case 'C':
            lg->channels = optarg;
            break;
        case 's':
            lg->signals = optarg;
            lg->is_balance = strcmp(optarg, "balance") == 0;
            break;
        case 'f':
        case 't':
            if (ps_args_seconds(optarg, 0.0, 1e9, false, c == 'f' ? &lg->from_s : &lg->to_s) < 0) {
                fprintf(stderr, "pushstep log: --%s: \"%s\" is not a number of seconds >= 0\n",
                        c == 'f' ? "from" : "to", optarg);
                return -EINVAL;
            }
            break;
        case 'h':
            fputs(USAGE, stdout);
            exit(0);
        default:
            fputs(USAGE, stderr);
            return -EINVAL;
        }
    }
    if (optind != argc - 1) {
        fputs(USAGE, stderr);
        return -EINVAL;
    }
    lg->path = argv[optind];
    if (lg->plot != NULL && lg->signals == NULL) {
        fprintf(stderr, "pushstep log: --plot draws --signals (e.g. --signals balance)\n");
        return -EINVAL;
    }
    lg->is_export = lg->csv != NULL || lg->plot != NULL;
    if (lg->is_events_only && lg->is_export) {
        fprintf(stderr,
                "pushstep log: --events lists the events alone, not with --csv or --plot\n");
        return -EINVAL;
    }
    if (!lg->is_export && (lg->channels != NULL || lg->signals != NULL)) {
        fprintf(stderr, "pushstep log: --channels and --signals go with --csv or --plot\n");
        return -EINVAL;
    }
    return 0;
}

int ps_reclog_main(int argc, char **argv)
{
    log_t *lg = calloc(1, sizeof(*lg));
    schema_t *schemas = calloc(MAX_SCHEMAS, sizeof(*schemas));
    if (lg == NULL || schemas == NULL) {
        free(lg);
        free(schemas);
        return 1;
    }
    lg->schemas = schemas;
    int status = parse_args(argc, argv, lg) < 0 ? 2 : 0;
    ps_mcap_read_info_t info;
    char err[PS_ERR_MSG_LEN];
    if (status == 0) {
        const ps_mcap_read_ops_t ops = {on_schema, on_channel, on_message_summary, on_metadata};
        if (ps_mcap_read_file(lg->path, &ops, lg, &info, err, sizeof(err)) < 0) {
            fprintf(stderr, "pushstep log: %s\n", err);
            status = 1;
        }
    }
    if (status == 0 && lg->is_events_only) {
        if (!info.has_footer) /* the events were printed as read: say so after them */
            printf("%s: not closed, read up to its last complete chunk (%s)\n", lg->path,
                   info.stop_reason);
    } else if (status == 0 && !lg->is_export)
        print_summary(lg, &info);
    else if (status == 0) {
        if (!info.has_footer)
            printf("%s: not closed, read up to its last complete chunk (%s)\n", lg->path,
                   info.stop_reason);
        status = run_export(lg);
    }
    for (uint32_t k = 0; k < MAX_TIMING; k++)
        free(lg->timing[k].v);
    for (uint32_t ch = 0; ch < MAX_CH; ch++)
        for (uint32_t f = 0; f < PS_ROSMSG_MAX_FIELDS; f++)
            free(lg->col_of[ch][f]);
    free(schemas);
    free(lg);
    return status;
}
