#include "ps_can_replay.h"

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "../rt/ps_err.h"
#include "ps_candump.h"

#define FLAG_EXT 0x01u
#define FLAG_FD  0x02u
#define FLAG_BRS 0x04u

/* ---- classification --------------------------------------------------- */

ps_can_replay_role_t ps_can_replay_classify(const ps_can_replay_cfg_t *cfg, uint32_t bus_idx,
                                            const ps_can_frame_t *f, uint32_t *out_joint_idx)
{
    /* Replies first, over every joint, as the loop's reply table does: a
     * reply identifier that happens to be another drive's command
     * identifier is still a reply. */
    for (uint32_t j = 0; j < cfg->n_joints; j++) {
        const ps_act_cfg_t *a = &cfg->act[j];
        const ps_act_proto_t *p = ps_act_proto_get(a->protocol);
        if (a->bus_idx == bus_idx && p != NULL && p->match_reply(a, f)) {
            *out_joint_idx = j;
            return PS_CAN_REPLAY_FED;
        }
    }
    if (cfg->imu_bus_idx == bus_idx && !f->is_ext)
        for (uint32_t k = 0; k < cfg->n_imu_ids && k < PS_CAN_REPLAY_MAX_IMU_IDS; k++)
            if (f->id == cfg->imu_ids[k])
                return PS_CAN_REPLAY_FED;
    for (uint32_t j = 0; j < cfg->n_joints; j++) {
        const ps_act_cfg_t *a = &cfg->act[j];
        const ps_act_proto_t *p = ps_act_proto_get(a->protocol);
        if (a->bus_idx == bus_idx && p != NULL && p->is_for_drive(a, f)) {
            *out_joint_idx = j;
            return PS_CAN_REPLAY_EXPECTED;
        }
    }
    return PS_CAN_REPLAY_UNKNOWN;
}

/* ---- reading the log -------------------------------------------------- */

static int check_cfg(const ps_can_replay_cfg_t *cfg, char *err, size_t len)
{
    bool is_ok = cfg != NULL && cfg->path != NULL && cfg->n_buses >= 1u &&
                 cfg->n_buses <= PS_MAX_BUSES && cfg->n_joints <= PS_MAX_JOINTS &&
                 (cfg->n_joints == 0 || cfg->act != NULL) && cfg->period_ns > 0 &&
                 cfg->match_window_ns >= 0 && cfg->n_imu_ids <= PS_CAN_REPLAY_MAX_IMU_IDS;
    for (uint32_t b = 0; is_ok && b < cfg->n_buses; b++)
        is_ok = cfg->ifname[b] != NULL;
    if (!is_ok)
        ps_err_format(err, len,
                      "replay: no log path, no buses, a bus without a name, more "
                      "than the joints allowed or no period");
    return is_ok ? 0 : -EINVAL;
}

static int bus_of(const ps_can_replay_cfg_t *cfg, const char *ifname)
{
    for (uint32_t b = 0; b < cfg->n_buses; b++)
        if (strcmp(cfg->ifname[b], ifname) == 0)
            return (int)b;
    return -1;
}

static void not_a_bus(const ps_can_replay_cfg_t *cfg, unsigned long long lineno, const char *ifname,
                      char *err, size_t len)
{
    char names[PS_MAX_BUSES * (PS_NAME_LEN + 2u)] = "";
    size_t used = 0;
    for (uint32_t b = 0; b < cfg->n_buses && used < sizeof(names); b++) {
        const int n =
            snprintf(names + used, sizeof(names) - used, "%s%s", b ? ", " : "", cfg->ifname[b]);
        if (n < 0)
            break;
        used += (size_t)n;
    }
    ps_err_format(err, len, "%s:%llu: interface \"%s\" is not a bus of the board (its buses: %s)",
                  cfg->path, lineno, ifname, names);
}

/* Append one frame to the storage and to its bus's list of its role. */
static int keep(ps_can_replay_t *r, uint32_t bus_idx, ps_can_replay_role_t role, uint32_t joint_idx,
                const ps_can_frame_t *f)
{
    /* indices and payload offsets are 32-bit: 4 G frames or bytes at most */
    if (r->n_entries >= r->max_entries || r->n_entries >= PS_CAN_REPLAY_NONE ||
        r->max_data - r->n_data < f->len || r->n_data + f->len > UINT32_MAX)
        return -ENOSPC;
    const uint32_t idx = (uint32_t)r->n_entries++;
    ps_can_replay_entry_t *e = &r->entries[idx];
    memset(e, 0, sizeof(*e));
    e->t_ns = f->t_ns;
    e->id = f->id;
    e->next_idx = PS_CAN_REPLAY_NONE;
    e->data_off = (uint32_t)r->n_data;
    e->len = f->len;
    e->flags = (uint8_t)((f->is_ext ? FLAG_EXT : 0u) | (f->is_fd ? FLAG_FD : 0u) |
                         (f->is_brs ? FLAG_BRS : 0u));
    e->bus_idx = (uint8_t)bus_idx;
    e->joint_idx = role == PS_CAN_REPLAY_EXPECTED ? (uint8_t)joint_idx : 0u;
    if (f->len > 0)
        memcpy(r->data + r->n_data, f->data, f->len);
    r->n_data += f->len;
    ps_can_replay_bus_t *bus = &r->bus[bus_idx];
    uint32_t *head = role == PS_CAN_REPLAY_FED ? &bus->fed_idx : &bus->exp_idx;
    uint32_t *tail = role == PS_CAN_REPLAY_FED ? &bus->fed_tail_idx : &bus->exp_tail_idx;
    if (*tail == PS_CAN_REPLAY_NONE)
        *head = idx;
    else
        r->entries[*tail].next_idx = idx;
    *tail = idx;
    return 0;
}

typedef struct {
    ps_can_replay_size_t size;
    uint64_t n_fed, n_expected, n_unknown;
    int64_t first_ns, last_ns;
} scan_result_t;

/* Read every line of the log: parse, find its bus, classify; with r, keep
 * the fed and expected frames in r's storage. Errors name file:line(:column). */
static int scan(const ps_can_replay_cfg_t *cfg, ps_can_replay_t *r, scan_result_t *out, char *err,
                size_t len)
{
    FILE *fp = fopen(cfg->path, "r");
    if (fp == NULL) {
        const int e = errno;
        ps_err_format(err, len, "%s: %s", cfg->path, strerror(e));
        return -e;
    }
    memset(out, 0, sizeof(*out));
    out->first_ns = INT64_MAX;
    out->last_ns = INT64_MIN;
    char line[PS_CANDUMP_LINE_MAX + 2];
    unsigned long long lineno = 0;
    int rc = 0;
    while (rc == 0 && fgets(line, sizeof(line), fp) != NULL) {
        lineno++;
        const size_t n = strlen(line);
        if (n + 1 == sizeof(line) && line[n - 1] != '\n') {
            ps_err_format(err, len, "%s:%llu: longer than a candump -L line (%u characters)",
                          cfg->path, lineno, PS_CANDUMP_LINE_MAX - 2u);
            rc = -PS_ERR_PROTOCOL;
            break;
        }
        ps_can_frame_t f;
        char ifname[PS_CANDUMP_IFNAME_MAX], why[PS_ERR_MSG_LEN];
        if (ps_candump_parse(line, &f, ifname, sizeof(ifname), why, sizeof(why)) < 0) {
            /* "column N: what" -> "file:line:N: what", as compilers name places */
            const char *at = strncmp(why, "column ", 7) == 0 ? why + 7 : why;
            ps_err_format(err, len, "%s:%llu:%s", cfg->path, lineno, at);
            rc = -PS_ERR_PROTOCOL;
            break;
        }
        const int b = bus_of(cfg, ifname);
        if (b < 0) {
            not_a_bus(cfg, lineno, ifname, err, len);
            rc = -PS_ERR_CONFIG;
            break;
        }
        out->first_ns = f.t_ns < out->first_ns ? f.t_ns : out->first_ns;
        out->last_ns = f.t_ns > out->last_ns ? f.t_ns : out->last_ns;
        uint32_t joint_idx = 0;
        const ps_can_replay_role_t role = ps_can_replay_classify(cfg, (uint32_t)b, &f, &joint_idx);
        if (role == PS_CAN_REPLAY_UNKNOWN) {
            out->n_unknown++;
            continue;
        }
        if (role == PS_CAN_REPLAY_FED)
            out->n_fed++;
        else
            out->n_expected++;
        out->size.n_entries++;
        out->size.n_data += f.len;
        if (r != NULL && keep(r, (uint32_t)b, role, joint_idx, &f) < 0) {
            ps_err_format(err, len,
                          "%s:%llu: the replay storage is full (the file grew since "
                          "it was measured?)",
                          cfg->path, lineno);
            rc = -ENOSPC;
        }
    }
    if (rc == 0 && ferror(fp)) {
        ps_err_format(err, len, "%s: read error after line %llu", cfg->path, lineno);
        rc = -EIO;
    }
    (void)fclose(fp); /* read-only: nothing to lose */
    if (rc == 0 && lineno == 0) {
        ps_err_format(err, len, "%s: the log holds no frames", cfg->path);
        rc = -PS_ERR_CONFIG;
    }
    out->size.n_lines = lineno;
    return rc;
}

int ps_can_replay_measure(const ps_can_replay_cfg_t *cfg, ps_can_replay_size_t *out, char *err,
                          size_t err_len)
{
    int rc = check_cfg(cfg, err, err_len);
    scan_result_t res;
    if (rc == 0)
        rc = scan(cfg, NULL, &res, err, err_len);
    if (rc == 0)
        *out = res.size;
    return rc;
}

/* ---- the ports -------------------------------------------------------- */

static void entry_frame(const ps_can_replay_t *r, const ps_can_replay_entry_t *e,
                        ps_can_frame_t *out)
{
    *out = (ps_can_frame_t){
        .id = e->id,
        .len = e->len,
        .is_ext = (e->flags & FLAG_EXT) != 0,
        .is_fd = (e->flags & FLAG_FD) != 0,
        .is_brs = (e->flags & FLAG_BRS) != 0,
        .t_ns = e->t_ns,
    };
    if (e->len > 0)
        memcpy(out->data, r->data + e->data_off, e->len);
}

static int replay_recv(void *ctx, ps_can_frame_t *out, size_t max)
{
    ps_can_replay_bus_t *bus = ctx;
    const ps_can_replay_t *r = bus->owner;
    const int64_t now = atomic_load_explicit(&r->now_ns, memory_order_relaxed);
    if (max > INT_MAX)
        max = INT_MAX;
    size_t n = 0;
    uint32_t i = bus->fed_idx;
    while (n < max && i != PS_CAN_REPLAY_NONE && r->entries[i].t_ns <= now) {
        entry_frame(r, &r->entries[i], &out[n++]);
        i = r->entries[i].next_idx;
    }
    bus->fed_idx = i;
    bus->n_fed += n;
    return (int)n;
}

static void note_diff(ps_can_replay_stats_t *st, unsigned k, float diff, float lsb)
{
    if (diff > st->max_diff[k])
        st->max_diff[k] = diff;
    const float steps = lsb > 0.0f ? diff / lsb : 0.0f;
    if (steps > st->max_diff_lsb[k])
        st->max_diff_lsb[k] = steps;
}

/* A sent frame against the logged one it was paired with, through the
 * joint's protocol: requests by kind, commands field by field (joint side). */
static void compare_pair(ps_can_replay_t *r, const ps_can_replay_entry_t *e,
                         const ps_can_frame_t *sent)
{
    ps_can_replay_stats_t *st = &r->stats;
    const ps_act_cfg_t *a = &r->cfg.act[e->joint_idx];
    const ps_act_proto_t *p = ps_act_proto_get(a->protocol);
    ps_can_frame_t logged;
    entry_frame(r, e, &logged);
    const int req_sent = p->classify_request(a, sent);
    const int req_logged = p->classify_request(a, &logged);
    if (req_sent >= 0 || req_logged >= 0) {
        if (req_sent != req_logged)
            st->n_differ++;
        return;
    }
    ps_act_cmd_t m_sent, m_logged, j_sent, j_logged;
    if (p->decode_cmd(a, sent, &m_sent) < 0 || p->decode_cmd(a, &logged, &m_logged) < 0) {
        st->n_differ++;
        return;
    }
    ps_act_cmd_from_motor(a, &m_sent, &j_sent);
    ps_act_cmd_from_motor(a, &m_logged, &j_logged);
    float lsb[PS_CAN_REPLAY_N_FIELDS];
    ps_act_joint_lsb(a, lsb);
    note_diff(st, PS_CAN_REPLAY_Q, fabsf(j_sent.q_rad - j_logged.q_rad), lsb[0]);
    note_diff(st, PS_CAN_REPLAY_QD, fabsf(j_sent.qd_rad_s - j_logged.qd_rad_s), lsb[1]);
    note_diff(st, PS_CAN_REPLAY_KP, fabsf(j_sent.kp_nm_rad - j_logged.kp_nm_rad), lsb[2]);
    note_diff(st, PS_CAN_REPLAY_KD, fabsf(j_sent.kd_nm_s_rad - j_logged.kd_nm_s_rad), lsb[3]);
    note_diff(st, PS_CAN_REPLAY_TAU, fabsf(j_sent.tau_ff_nm - j_logged.tau_ff_nm), lsb[4]);
    st->n_cmd_compared++;
}

/* Pair a sent frame with the oldest unused logged host frame of its bus, of
 * the same identifier and kind, logged within the window of now. The walk
 * is bounded by the frames the log holds in the window. */
static void match_sent(ps_can_replay_bus_t *bus, const ps_can_frame_t *f, int64_t now)
{
    ps_can_replay_t *r = bus->owner;
    const int64_t w = r->cfg.match_window_ns > 0 ? r->cfg.match_window_ns : r->cfg.period_ns;
    uint32_t i = bus->exp_idx;
    while (i != PS_CAN_REPLAY_NONE && (r->entries[i].is_matched || r->entries[i].t_ns < now - w))
        i = r->entries[i].next_idx;
    bus->exp_idx = i; /* what is older than the window can match nothing any more */
    const uint8_t kind = (uint8_t)((f->is_ext ? FLAG_EXT : 0u) | (f->is_fd ? FLAG_FD : 0u));
    for (; i != PS_CAN_REPLAY_NONE && r->entries[i].t_ns <= now + w; i = r->entries[i].next_idx) {
        ps_can_replay_entry_t *e = &r->entries[i];
        if (e->is_matched || e->id != f->id || (e->flags & (FLAG_EXT | FLAG_FD)) != kind)
            continue;
        e->is_matched = 1;
        r->stats.n_matched++;
        compare_pair(r, e, f);
        return;
    }
    r->stats.n_unmatched++;
}

static int replay_send(void *ctx, const ps_can_frame_t *frames, size_t n)
{
    ps_can_replay_bus_t *bus = ctx;
    const int64_t now = atomic_load_explicit(&bus->owner->now_ns, memory_order_relaxed);
    if (n > INT_MAX)
        n = INT_MAX;
    for (size_t k = 0; k < n; k++)
        match_sent(bus, &frames[k], now);
    bus->n_sent += n;
    return (int)n;
}

static int replay_get_state(void *ctx, ps_can_state_t *out)
{
    const ps_can_replay_bus_t *bus = ctx;
    memset(out, 0, sizeof(*out));
    out->mode = PS_CAN_BUS_ERROR_ACTIVE;
    out->n_tx_frames = bus->n_sent;
    out->n_rx_frames = bus->n_fed;
    return 0;
}

static void replay_close(void *ctx)
{
    (void)ctx; /* the storage is the caller's */
}

static const ps_can_ops_t REPLAY_OPS = {
    .send_batch = replay_send,
    .recv_batch = replay_recv,
    .get_state = replay_get_state,
    .close = replay_close,
};

/* ---- the clock -------------------------------------------------------- */

static int64_t replay_now_ns(void *ctx)
{
    const ps_can_replay_t *r = ctx;
    return atomic_load_explicit(&r->now_ns, memory_order_relaxed);
}

/* No waiting: the loop's sleep is where replay time passes. */
static int replay_sleep_until_ns(void *ctx, int64_t deadline_ns)
{
    ps_can_replay_t *r = ctx;
    if (deadline_ns > atomic_load_explicit(&r->now_ns, memory_order_relaxed))
        atomic_store_explicit(&r->now_ns, deadline_ns, memory_order_relaxed);
    return 0;
}

/* ---- lifecycle -------------------------------------------------------- */

int ps_can_replay_init(ps_can_replay_t *r, const ps_can_replay_cfg_t *cfg,
                       ps_can_replay_entry_t *entries, size_t max_entries, uint8_t *data,
                       size_t max_data, char *err, size_t err_len)
{
    memset(r, 0, sizeof(*r));
    int rc = check_cfg(cfg, err, err_len);
    if (rc < 0)
        return rc;
    if ((entries == NULL && max_entries > 0) || (data == NULL && max_data > 0)) {
        ps_err_format(err, err_len, "replay: storage NULL with a size");
        return -EINVAL;
    }
    r->cfg = *cfg;
    r->entries = entries;
    r->max_entries = max_entries;
    r->data = data;
    r->max_data = max_data;
    for (uint32_t b = 0; b < PS_MAX_BUSES; b++)
        r->bus[b] = (ps_can_replay_bus_t){
            .owner = r,
            .bus_idx = b,
            .fed_idx = PS_CAN_REPLAY_NONE,
            .fed_tail_idx = PS_CAN_REPLAY_NONE,
            .exp_idx = PS_CAN_REPLAY_NONE,
            .exp_tail_idx = PS_CAN_REPLAY_NONE,
        };
    scan_result_t res;
    rc = scan(cfg, r, &res, err, err_len);
    if (rc < 0) {
        ps_can_replay_deinit(r);
        return rc;
    }
    r->stats.n_lines = res.size.n_lines;
    r->stats.n_fed_logged = res.n_fed;
    r->stats.n_expected = res.n_expected;
    r->stats.n_unknown = res.n_unknown;
    r->stats.first_ns = res.first_ns;
    r->stats.last_ns = res.last_ns;
    /* Down to a tick, so that the loop's deadlines fall where the recorded
     * loop's did (a pushstep log's sent frames carry their tick's deadline);
     * at least one tick, as a measurement time of 0 means "never". */
    const int64_t p = cfg->period_ns;
    r->start_ns = res.first_ns >= 0 ? res.first_ns / p * p : 0;
    if (r->start_ns < p)
        r->start_ns = p;
    atomic_init(&r->now_ns, r->start_ns);
    r->clock =
        (ps_clock_t){.now_ns = replay_now_ns, .sleep_until_ns = replay_sleep_until_ns, .ctx = r};
    return 0;
}

ps_can_port_t ps_can_replay_port(ps_can_replay_t *r, uint32_t bus_idx)
{
    return (ps_can_port_t){
        .ops = &REPLAY_OPS, .ctx = &r->bus[bus_idx], .name = r->cfg.ifname[bus_idx]};
}

const ps_clock_t *ps_can_replay_clock(ps_can_replay_t *r)
{
    return &r->clock;
}

int64_t ps_can_replay_start_ns(const ps_can_replay_t *r)
{
    return r->start_ns;
}

int64_t ps_can_replay_last_ns(const ps_can_replay_t *r)
{
    return r->stats.last_ns;
}

void ps_can_replay_get_stats(const ps_can_replay_t *r, ps_can_replay_stats_t *out)
{
    *out = r->stats;
    out->n_fed = 0;
    out->n_sent = 0;
    out->n_buses_fed = 0;
    for (uint32_t b = 0; b < r->cfg.n_buses; b++) {
        out->n_fed += r->bus[b].n_fed;
        out->n_sent += r->bus[b].n_sent;
        out->n_buses_fed += r->bus[b].n_fed > 0;
    }
}

static int no_estop(void *ctx, bool *out_pressed_since_last_read)
{
    (void)ctx;
    *out_pressed_since_last_read = false;
    return 0;
}

static int no_heartbeat(void *ctx, bool level)
{
    (void)ctx;
    (void)level;
    return 0;
}

static int no_led(void *ctx, ps_gpio_led_t led)
{
    (void)ctx;
    (void)led;
    return 0;
}

static const ps_gpio_ops_t NO_GPIO_OPS = {
    .read_estop = no_estop,
    .set_heartbeat = no_heartbeat,
    .set_led = no_led,
    .close = NULL,
};

ps_gpio_port_t ps_can_replay_gpio_port(void)
{
    return (ps_gpio_port_t){.ops = &NO_GPIO_OPS, .ctx = NULL};
}

void ps_can_replay_deinit(ps_can_replay_t *r)
{
    memset(r, 0, sizeof(*r));
}
