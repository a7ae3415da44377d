#include "ps_recorder.h"

#include <fcntl.h>
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "ps_config.h"
#include "ps_err.h"
#include "ps_logger.h"
#include "ps_rosmsg.h"
#include "ps_rtsetup.h"

#define IDLE_SLEEP_NS    (5 * PS_NS_PER_MS)
#define LOSSLESS_WAIT_NS (50 * PS_NS_PER_US) /* the loop's poll while the writer catches up */
#define RECORDS_PER_PASS 2048u /* per file, between looks at the other file and triggers */
#define DEFAULT_CHUNK    (256u * 1024u)
#define MSG_BUF          16384u
#define SCHEMA_BUF       8192u
#define GRAVITY_M_S2     9.81f

static const char *const TRIGGER_NAMES[PS_REC_TRIG_COUNT] = {
    "estop", "fall", "watchdog", "overrun", "button", "signal",
};

const char *ps_recorder_trigger_name(ps_rec_trigger_t bit)
{
    for (unsigned i = 0; i < PS_REC_TRIG_COUNT; i++)
        if (bit == (1u << i))
            return TRIGGER_NAMES[i];
    return "?";
}

/* ---- message definitions ------------------------------------------------- */

enum { CNT_JOINTS = 0, CNT_BUSES, CNT_CONTACTS, CNT_COUNT };

#define OFF(m) offsetof(ps_rec_tick_t, m)
#define SCALAR(n, t, m, doc)                                                                       \
    {                                                                                              \
        n, PS_ROSMSG_##t, PS_ROSMSG_SCALAR, 0, 1, OFF(m), doc                                      \
    }
#define ARRAY(n, t, m, k, doc)                                                                     \
    {                                                                                              \
        n, PS_ROSMSG_##t, PS_ROSMSG_ARRAY, 0, k, OFF(m), doc                                       \
    }
#define SEQ(n, t, m, c, cap, doc)                                                                  \
    {                                                                                              \
        n, PS_ROSMSG_##t, PS_ROSMSG_SEQUENCE, c, cap, OFF(m), doc                                  \
    }
#define JSEQ(n, t, m, doc) SEQ(n, t, m, CNT_JOINTS, PS_MAX_JOINTS, doc)
#define BSEQ(n, t, m, doc) SEQ(n, t, m, CNT_BUSES, PS_MAX_BUSES, doc)
#define CSEQ(n, t, m, doc) SEQ(n, t, m, CNT_CONTACTS, PS_REC_MAX_CONTACTS, doc)
#define STAMP                                                                                      \
    SCALAR("tick", UINT64, tick, "loop tick"),                                                     \
        SCALAR("t_ns", INT64, t_ns, "tick deadline, loop clock (the message log time)")

static const ps_rosmsg_field_t JOINTS[] = {
    STAMP,
    JSEQ("q_rad", FLOAT32, q_rad, "measured position, by joint (joint_names metadata)"),
    JSEQ("qd_rad_s", FLOAT32, qd_rad_s, NULL),
    JSEQ("tau_nm", FLOAT32, tau_nm, NULL),
    JSEQ("temp_c", FLOAT32, temp_c, NULL),
    JSEQ("fault_bits", UINT32, fault_bits, "ps_act_fault_t bits"),
    JSEQ("is_cmd_sent", BOOL, is_cmd_sent, "a command went out this tick"),
    JSEQ("cmd_q_rad", FLOAT32, cmd_q_rad, "last command per joint"),
    JSEQ("cmd_qd_rad_s", FLOAT32, cmd_qd_rad_s, NULL),
    JSEQ("cmd_kp_nm_rad", FLOAT32, cmd_kp_nm_rad, NULL),
    JSEQ("cmd_kd_nm_s_rad", FLOAT32, cmd_kd_nm_s_rad, NULL),
    JSEQ("cmd_tau_ff_nm", FLOAT32, cmd_tau_ff_nm, NULL),
};

static const ps_rosmsg_field_t IMU[] = {
    STAMP,
    ARRAY("gyro_body_rad_s", FLOAT32, gyro_body_rad_s, 3, NULL),
    ARRAY("accel_body_m_s2", FLOAT32, accel_body_m_s2, 3, NULL),
    SCALAR("sample_t_ns", INT64, imu_t_ns, "tick the sample was taken, 0: never"),
};

static const ps_rosmsg_field_t ESTIMATE[] = {
    STAMP,
    SCALAR("roll_rad", FLOAT32, roll_rad, NULL),
    SCALAR("pitch_rad", FLOAT32, pitch_rad, NULL),
    ARRAY("com_m", FLOAT32, com_m, 3, "ground frame: x forward, y left, z up"),
    ARRAY("com_vel_m_s", FLOAT32, com_vel_m_s, 3, NULL),
    ARRAY("cop_m", FLOAT32, cop_m, 2, NULL),
    ARRAY("capture_point_m", FLOAT32, capture_point_m, 2, "com + com_vel / sqrt(g / com_z)"),
    ARRAY("support_min_m", FLOAT32, support_min_m, 2, "box around the soles in contact"),
    ARRAY("support_max_m", FLOAT32, support_max_m, 2, NULL),
    ARRAY("foot_left_m", FLOAT32, foot_left_m, 3, NULL),
    ARRAY("foot_right_m", FLOAT32, foot_right_m, 3, NULL),
    SCALAR("is_contact_left", BOOL, is_contact_left, NULL),
    SCALAR("is_contact_right", BOOL, is_contact_right, NULL),
    SCALAR("is_fallen", BOOL, is_fallen, NULL),
};

static const ps_rosmsg_field_t STATE[] = {
    STAMP,
    SCALAR("state", UINT8, state,
           "0 STANDBY 1 RAMP 2 ACTIVE 3 DAMPING 4 ESTOP 5 HOLD (after this tick)"),
    SCALAR("state_before", UINT8, state_before, NULL),
    SCALAR("cond", UINT32, cond, "condition bits (rt/ps_sm.h)"),
    SCALAR("triggers", UINT32, triggers,
           "recorder triggers: 1 estop 2 fall 4 watchdog 8 overrun 16 button 32 signal"),
    SCALAR("is_estop_input", BOOL, is_estop_input, NULL),
    SCALAR("heartbeat", UINT8, heartbeat, "level written; 255: held still"),
    SCALAR("led", UINT8, led, NULL),
    SCALAR("is_button_pressed", BOOL, is_button_pressed, NULL),
};

static const ps_rosmsg_field_t TIMING[] = {
    STAMP,
    SCALAR("wake_ns", INT64, stage_ns[0], "wake-up latency"),
    SCALAR("read_ns", INT64, stage_ns[1], NULL),
    SCALAR("estimate_ns", INT64, stage_ns[2], NULL),
    SCALAR("policy_ns", INT64, stage_ns[3], "-1: no policy step this tick"),
    SCALAR("servo_ns", INT64, stage_ns[4], "with the state machine"),
    SCALAR("write_ns", INT64, stage_ns[5], NULL),
    SCALAR("tick_ns", INT64, stage_ns[6], "read start to write end"),
    SCALAR("n_overruns", UINT64, n_overruns, NULL),
};

static const ps_rosmsg_field_t BUSES[] = {
    STAMP,
    BSEQ("mode", UINT8, bus_mode, "0 active 1 warning 2 passive 3 off, by bus"),
    BSEQ("tx_errors", UINT16, bus_tx_errors, NULL),
    BSEQ("rx_errors", UINT16, bus_rx_errors, NULL),
    BSEQ("n_rx", UINT16, bus_n_rx, "frames read this tick"),
    BSEQ("n_tx", UINT16, bus_n_tx, "frames sent this tick"),
    BSEQ("load", FLOAT32, bus_load, "observed load since start, 0..1"),
    SCALAR("n_rx_bad", UINT64, n_rx_bad, NULL),
    SCALAR("n_rx_unknown", UINT64, n_rx_unknown, NULL),
    SCALAR("n_tx_refused", UINT64, n_tx_refused, NULL),
    SCALAR("n_bus_errors", UINT64, n_bus_errors, NULL),
    SCALAR("n_gpio_errors", UINT64, n_gpio_errors, NULL),
};

static const ps_rosmsg_field_t POLICY[] = {
    STAMP,
    JSEQ("target_q_rad", FLOAT32, target_q_rad, "policy output, by joint"),
    JSEQ("target_qd_rad_s", FLOAT32, target_qd_rad_s, NULL),
    JSEQ("target_tau_ff_nm", FLOAT32, target_tau_ff_nm, NULL),
    SCALAR("compute_ns", INT64, policy_ns, NULL),
    SCALAR("is_late", BOOL, is_policy_late, NULL),
    SCALAR("is_target_invalid", BOOL, is_target_invalid, NULL),
};

#define TOFF(m) (offsetof(ps_rec_tick_t, truth) + offsetof(ps_rec_truth_t, m))
#define TSCALAR(n, t, m, doc)                                                                      \
    {                                                                                              \
        n, PS_ROSMSG_##t, PS_ROSMSG_SCALAR, 0, 1, TOFF(m), doc                                     \
    }
#define TARRAY(n, t, m, k, doc)                                                                    \
    {                                                                                              \
        n, PS_ROSMSG_##t, PS_ROSMSG_ARRAY, 0, k, TOFF(m), doc                                      \
    }
#define TCSEQ(n, t, m, doc)                                                                        \
    {                                                                                              \
        n, PS_ROSMSG_##t, PS_ROSMSG_SEQUENCE, CNT_CONTACTS, PS_REC_MAX_CONTACTS, TOFF(m), doc      \
    }

static const ps_rosmsg_field_t TRUTH[] = {
    STAMP,
    TSCALAR("sim_t_s", FLOAT32, t_s, "simulated time"),
    TARRAY("com_m", FLOAT32, com_m, 3, "world frame"),
    TARRAY("pelvis_m", FLOAT32, pelvis_m, 3, NULL),
    TSCALAR("head_height_m", FLOAT32, head_height_m, NULL),
    TARRAY("push_force_n", FLOAT32, push_force_n, 3, "scenario pushes acting now"),
    TSCALAR("tau_abs_sum_nm", FLOAT32, tau_abs_sum_nm, NULL),
    TSCALAR("is_fallen", BOOL, is_fallen, NULL),
    TSCALAR("is_drive_power_on", BOOL, is_drive_power_on, NULL),
    TCSEQ("contact_agent", UINT16, contact_agent, "crowd contacts"),
    TCSEQ("contact_fx_n", FLOAT32, contact_fx_n, NULL),
    TCSEQ("contact_fy_n", FLOAT32, contact_fy_n, NULL),
    TCSEQ("contact_fz_n", FLOAT32, contact_fz_n, NULL),
    TCSEQ("contact_x_m", FLOAT32, contact_x_m, NULL),
    TCSEQ("contact_y_m", FLOAT32, contact_y_m, NULL),
    TCSEQ("contact_z_m", FLOAT32, contact_z_m, NULL),
};

/* Events (state transitions, triggers): a struct of their own. */
typedef struct {
    uint64_t tick;
    int64_t t_ns;
    char kind[16];
    char text[200];
} rec_event_t;

static const ps_rosmsg_field_t EVENT[] = {
    {"tick", PS_ROSMSG_UINT64, PS_ROSMSG_SCALAR, 0, 1, offsetof(rec_event_t, tick), NULL},
    {"t_ns", PS_ROSMSG_INT64, PS_ROSMSG_SCALAR, 0, 1, offsetof(rec_event_t, t_ns), NULL},
    {"kind", PS_ROSMSG_STRING, PS_ROSMSG_SCALAR, 0, 16, offsetof(rec_event_t, kind),
     "transition | trigger"},
    {"text", PS_ROSMSG_STRING, PS_ROSMSG_SCALAR, 0, 200, offsetof(rec_event_t, text), NULL},
};

#define DEF(n, f)                                                                                  \
    {                                                                                              \
        n, f, sizeof(f) / sizeof(f[0])                                                             \
    }

enum {
    CH_JOINTS,
    CH_IMU,
    CH_ESTIMATE,
    CH_STATE,
    CH_TIMING,
    CH_BUSES,
    CH_POLICY,
    CH_TRUTH,
    CH_EVENTS,
    CH_COUNT
};

static const struct {
    const char *topic;
    ps_rosmsg_def_t def;
} CHANNELS[CH_COUNT] = {
    [CH_JOINTS] = {"/joints", DEF("pushstep_msgs/msg/Joints", JOINTS)},
    [CH_IMU] = {"/imu", DEF("pushstep_msgs/msg/Imu", IMU)},
    [CH_ESTIMATE] = {"/estimate", DEF("pushstep_msgs/msg/Estimate", ESTIMATE)},
    [CH_STATE] = {"/state", DEF("pushstep_msgs/msg/State", STATE)},
    [CH_TIMING] = {"/timing", DEF("pushstep_msgs/msg/Timing", TIMING)},
    [CH_BUSES] = {"/buses", DEF("pushstep_msgs/msg/Buses", BUSES)},
    [CH_POLICY] = {"/policy", DEF("pushstep_msgs/msg/Policy", POLICY)},
    [CH_TRUTH] = {"/truth", DEF("pushstep_msgs/msg/Truth", TRUTH)},
    [CH_EVENTS] = {"/events", DEF("pushstep_msgs/msg/Event", EVENT)},
};

/* ---- the ring (loop side) -------------------------------------------------- */

ps_rec_tick_t *ps_recorder_begin(ps_recorder_t *r)
{
    const uint64_t idx = atomic_load_explicit(&r->head, memory_order_relaxed);
    ps_rec_slot_t *s = &r->slots[idx & (r->n_slots - 1u)];
    atomic_store_explicit(&s->seq, UINT64_MAX, memory_order_relaxed);
    atomic_thread_fence(memory_order_release); /* the stamp before the new contents */
    return &s->rec;
}

void ps_recorder_commit(ps_recorder_t *r)
{
    const uint64_t idx = atomic_load_explicit(&r->head, memory_order_relaxed);
    ps_rec_slot_t *s = &r->slots[idx & (r->n_slots - 1u)];
    atomic_store_explicit(&s->seq, idx + 1u, memory_order_release);
    atomic_store_explicit(&r->head, idx + 1u, memory_order_release);
}

/* A seqlock read: the copy counts only if the stamp was idx + 1 before and
 * after it (the loop may overwrite the slot meanwhile). */
int ps_recorder_read(const ps_recorder_t *r, uint64_t idx, ps_rec_tick_t *out)
{
    if (idx >= atomic_load_explicit(&r->head, memory_order_acquire))
        return -EAGAIN;
    const ps_rec_slot_t *s = &r->slots[idx & (r->n_slots - 1u)];
    const uint64_t s1 = atomic_load_explicit(&s->seq, memory_order_acquire);
    if (s1 != idx + 1u)
        return -ESTALE;
    memcpy(out, &s->rec, sizeof(*out));
    atomic_thread_fence(memory_order_acquire);
    return atomic_load_explicit(&s->seq, memory_order_relaxed) == s1 ? 0 : -ESTALE;
}

void ps_recorder_trigger(ps_recorder_t *r, ps_rec_trigger_t cause)
{
    atomic_fetch_or_explicit(&r->ext_trigger, (uint32_t)cause, memory_order_relaxed);
}

static bool is_in_charge(uint8_t s)
{
    return s == PS_SM_RAMP || s == PS_SM_ACTIVE || s == PS_SM_HOLD;
}

static uint32_t find_triggers(ps_recorder_t *r, const ps_rec_tick_t *t, bool is_button)
{
    const uint32_t rose = t->cond & ~r->last_cond;
    uint32_t trig = 0;
    if (t->state == PS_SM_ESTOP && t->state_before != PS_SM_ESTOP)
        trig |= PS_REC_TRIG_ESTOP;
    if (rose & PS_SM_C_FALL)
        trig |= PS_REC_TRIG_FALL; /* the loop keeps FALL only while in charge */
    if (is_in_charge(t->state_before) &&
        (rose & (PS_SM_C_REPLY_STALE | PS_SM_C_IMU_STALE | PS_SM_C_POLICY_LATE)))
        trig |= PS_REC_TRIG_WATCHDOG;
    if (rose & PS_SM_C_OVERRUN)
        trig |= PS_REC_TRIG_OVERRUN;
    if (is_button)
        trig |= PS_REC_TRIG_BUTTON;
    trig |= atomic_exchange_explicit(&r->ext_trigger, 0u, memory_order_relaxed);
    return trig;
}

static void fill_estimate(const ps_recorder_t *r, const ps_estimate_t *e, ps_rec_tick_t *t)
{
    t->roll_rad = e->roll_rad;
    t->pitch_rad = e->pitch_rad;
    memcpy(t->com_m, e->com_m, sizeof(t->com_m));
    memcpy(t->com_vel_m_s, e->com_vel_m_s, sizeof(t->com_vel_m_s));
    memcpy(t->cop_m, e->cop_m, sizeof(t->cop_m));
    memcpy(t->foot_left_m, e->foot_m[0], sizeof(t->foot_left_m));
    memcpy(t->foot_right_m, e->foot_m[1], sizeof(t->foot_right_m));
    t->is_contact_left = e->is_contact[0];
    t->is_contact_right = e->is_contact[1];
    t->is_fallen = e->is_fallen;
    const float z = e->com_m[2];
    const float omega = z > 0.05f ? sqrtf(GRAVITY_M_S2 / z) : NAN;
    for (int k = 0; k < 2; k++)
        t->capture_point_m[k] = e->com_m[k] + e->com_vel_m_s[k] / omega;
    const float half[2] = {0.5f * r->cfg.foot_length_m, 0.5f * r->cfg.foot_width_m};
    for (int k = 0; k < 2; k++) {
        t->support_min_m[k] = NAN;
        t->support_max_m[k] = NAN;
    }
    for (int side = 0; side < 2; side++) {
        if (!e->is_contact[side])
            continue;
        for (int k = 0; k < 2; k++) {
            const float lo = e->foot_m[side][k] - half[k], hi = e->foot_m[side][k] + half[k];
            t->support_min_m[k] = isnan(t->support_min_m[k]) ? lo : fminf(t->support_min_m[k], lo);
            t->support_max_m[k] = isnan(t->support_max_m[k]) ? hi : fmaxf(t->support_max_m[k], hi);
        }
    }
}

static void fill_joints(const ps_loop_t *loop, ps_rec_tick_t *t)
{
    const uint32_t n = loop->meas.n_joints < PS_MAX_JOINTS ? loop->meas.n_joints : PS_MAX_JOINTS;
    t->n_joints = n;
    for (uint32_t j = 0; j < n; j++) {
        const ps_act_meas_t *m = &loop->meas.joints[j];
        const ps_act_cmd_t *c = &loop->last.cmd[j];
        t->q_rad[j] = m->q_rad;
        t->qd_rad_s[j] = m->qd_rad_s;
        t->tau_nm[j] = m->tau_nm;
        t->temp_c[j] = m->temp_c;
        t->fault_bits[j] = m->fault_bits;
        t->is_cmd_sent[j] = loop->last.is_cmd_sent[j];
        t->cmd_q_rad[j] = c->q_rad;
        t->cmd_qd_rad_s[j] = c->qd_rad_s;
        t->cmd_kp_nm_rad[j] = c->kp_nm_rad;
        t->cmd_kd_nm_s_rad[j] = c->kd_nm_s_rad;
        t->cmd_tau_ff_nm[j] = c->tau_ff_nm;
        t->target_q_rad[j] = loop->targets.q_rad[j];
        t->target_qd_rad_s[j] = loop->targets.qd_rad_s[j];
        t->target_tau_ff_nm[j] = loop->targets.tau_ff_nm[j];
    }
}

static void fill_buses(const ps_loop_t *loop, ps_rec_tick_t *t)
{
    const uint32_t n = loop->cfg.board->n_buses;
    t->n_buses = n;
    for (uint32_t b = 0; b < n && b < PS_MAX_BUSES; b++) {
        const ps_can_state_t *s = &loop->last.bus[b];
        t->bus_mode[b] = (uint8_t)s->mode;
        t->bus_tx_errors[b] = s->tx_error_count;
        t->bus_rx_errors[b] = s->rx_error_count;
        t->bus_n_rx[b] = loop->last.n_rx[b];
        t->bus_n_tx[b] = loop->last.n_tx[b];
        t->bus_load[b] = (float)s->load;
    }
    t->n_rx_bad = loop->counters.n_rx_bad;
    t->n_rx_unknown = loop->counters.n_rx_unknown;
    t->n_tx_refused = loop->counters.n_tx_refused;
    t->n_bus_errors = loop->counters.n_bus_errors;
    t->n_gpio_errors = loop->counters.n_gpio_errors;
}

static void sleep_ns(int64_t ns);

/* Unpaced runs only: until the slot about to be filled holds nothing the
 * writer still needs (one slot spare for the writer's read in progress). */
static void wait_for_writer(ps_recorder_t *r)
{
    const uint64_t head = atomic_load_explicit(&r->head, memory_order_relaxed);
    bool has_waited = false;
    while (atomic_load_explicit(&r->is_writer_running, memory_order_acquire) &&
           head - atomic_load_explicit(&r->writer_needed, memory_order_acquire) + 1u >=
               r->n_slots) {
        has_waited = true;
        sleep_ns(LOSSLESS_WAIT_NS);
    }
    r->n_lossless_waits += has_waited;
}

void ps_recorder_on_tick(void *ctx, const ps_loop_t *loop)
{
    ps_recorder_t *r = ctx;
    if (r->cfg.is_lossless)
        wait_for_writer(r);
    const uint64_t idx = atomic_load_explicit(&r->head, memory_order_relaxed);
    ps_rec_tick_t *t = ps_recorder_begin(r);
    t->tick = loop->counters.n_ticks - 1u; /* the tick that just ran */
    t->t_ns = loop->t_deadline_ns;
    t->cond = loop->last.cond;
    t->state = (uint8_t)loop->state;
    t->state_before = (uint8_t)loop->last.state_before;
    t->is_policy_tick = loop->last.is_policy_run;
    fill_joints(loop, t);
    t->policy_ns = loop->last.is_policy_run ? loop->last.policy_dt_ns : -1;
    t->is_policy_late = loop->has_policy_late;
    t->is_target_invalid = loop->has_target_invalid;
    memcpy(t->gyro_body_rad_s, loop->meas.imu.gyro_body_rad_s, sizeof(t->gyro_body_rad_s));
    memcpy(t->accel_body_m_s2, loop->meas.imu.accel_body_m_s2, sizeof(t->accel_body_m_s2));
    t->imu_t_ns = loop->meas.imu.t_ns;
    fill_estimate(r, &loop->estimator.est, t);
    static const ps_stage_t STAGES[PS_REC_N_STAGES] = {
        PS_STAGE_WAKE,  PS_STAGE_READ,  PS_STAGE_ESTIMATE, PS_STAGE_POLICY,
        PS_STAGE_SERVO, PS_STAGE_WRITE, PS_STAGE_TICK,
    };
    for (unsigned k = 0; k < PS_REC_N_STAGES; k++)
        t->stage_ns[k] = loop->last.stage_ns[STAGES[k]];
    t->n_overruns = loop->pacer.n_overruns;
    fill_buses(loop, t);
    t->is_estop_input = loop->last.is_estop_input;
    t->heartbeat = loop->last.heartbeat < 0 ? 255u : (uint8_t)loop->last.heartbeat;
    t->led = loop->last.led;
    t->is_button_pressed = loop->last.is_button_pressed;
    t->has_truth = r->truth.read != NULL && r->truth.read(r->truth.ctx, &t->truth);
    if (!t->has_truth)
        memset(&t->truth, 0, sizeof(t->truth));
    t->triggers = find_triggers(r, t, loop->last.is_button_pressed && !r->was_button);
    r->was_button = loop->last.is_button_pressed;
    r->last_cond = t->cond;
    r->last_state = t->state;
    ps_recorder_commit(r);
    if (t->triggers != 0) {
        const ps_rec_trig_t tr = {.idx = idx, .bits = t->triggers};
        (void)ps_ring_push(&r->trig_ring, &tr); /* full: noted in the record only */
        atomic_fetch_add_explicit(&r->n_trig, 1u, memory_order_relaxed);
        for (unsigned i = 0; i < PS_REC_TRIG_COUNT; i++)
            if (t->triggers & (1u << i))
                atomic_fetch_add_explicit(&r->n_trig_by[i], 1u, memory_order_relaxed);
    }
}

/* ---- init ------------------------------------------------------------------ */

static uint32_t pow2_at_least(uint64_t n)
{
    uint32_t p = 2;
    while (p < n && p < (1u << 30))
        p <<= 1;
    return p;
}

static int check_dir(const char *dir, char *err, size_t len)
{
    struct stat st;
    if (stat(dir, &st) < 0) {
        const int e = errno;
        ps_err_format(err, len, "--flight %s: %s", dir, strerror(e));
        return -e;
    }
    if (!S_ISDIR(st.st_mode)) {
        ps_err_format(err, len, "--flight %s: not a folder", dir);
        return -ENOTDIR;
    }
    if (access(dir, W_OK | X_OK) < 0) {
        const int e = errno;
        ps_err_format(err, len, "--flight %s: not writable: %s", dir, strerror(e));
        return -e;
    }
    return 0;
}

int ps_recorder_init(ps_recorder_t *r, const ps_recorder_cfg_t *cfg, char *err, size_t err_len)
{
    memset(r, 0, sizeof(*r));
    if (cfg == NULL || (cfg->path == NULL && cfg->dir == NULL) || cfg->servo_hz == 0 ||
        !(cfg->pre_s >= 0 && cfg->pre_s <= 600) || !(cfg->post_s >= 0 && cfg->post_s <= 600)) {
        ps_err_format(err, err_len, "recorder: no file or folder, or pre/post outside 0..600 s");
        return -EINVAL;
    }
    r->cfg = *cfg;
    if (cfg->path != NULL) {
        snprintf(r->path, sizeof(r->path), "%s", cfg->path);
        r->cfg.path = r->path;
        const int fd = open(r->path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
        if (fd < 0) {
            const int e = errno;
            ps_err_format(err, err_len, "--record %s: %s", r->path, strerror(e));
            return -e;
        }
        close(fd); /* the writer opens it again: created now so a bad path fails at start */
    }
    if (cfg->dir != NULL) {
        snprintf(r->dir, sizeof(r->dir), "%s", cfg->dir);
        r->cfg.dir = r->dir;
        int rc = check_dir(r->dir, err, err_len);
        if (rc < 0)
            return rc;
    }
    double ring_s = cfg->pre_s + cfg->post_s + 1.0;
    if (ring_s < 2.0)
        ring_s = 2.0;
    if (cfg->ring_s > 0)
        ring_s = cfg->ring_s < 0.1 ? 0.1 : cfg->ring_s;
    r->n_slots = pow2_at_least((uint64_t)ceil(ring_s * cfg->servo_hz));
    const size_t bytes = (size_t)r->n_slots * sizeof(ps_rec_slot_t);
    r->slots = malloc(bytes);
    if (r->slots == NULL) {
        ps_err_format(err, err_len, "recorder: no memory for a ring of %u records (%zu MB)",
                      r->n_slots, bytes >> 20);
        return -ENOMEM;
    }
    memset(r->slots, 0, bytes); /* touched now: the loop's first laps fault nothing in */
    for (uint32_t i = 0; i < r->n_slots; i++)
        atomic_init(&r->slots[i].seq, 0u);
    atomic_init(&r->head, 0u);
    atomic_init(&r->ext_trigger, 0u);
    if (ps_ring_init(&r->trig_ring, r->trig_storage, PS_REC_TRIG_QUEUE,
                     sizeof(r->trig_storage[0])) < 0)
        return -EINVAL; /* cannot happen: a power of two */
    atomic_init(&r->n_trig, 0u);
    for (unsigned i = 0; i < PS_REC_TRIG_COUNT; i++)
        atomic_init(&r->n_trig_by[i], 0u);
    atomic_init(&r->should_stop, false);
    r->last_state = PS_SM_STANDBY;
    const char *delay = getenv("PUSHSTEP_REC_IO_DELAY_NS");
    r->io_delay_ns = delay != NULL ? strtoll(delay, NULL, 10) : 0;
    if (r->io_delay_ns < 0 || r->io_delay_ns > PS_NS_PER_S)
        r->io_delay_ns = 0;
    return 0;
}

void ps_recorder_set_truth(ps_recorder_t *r, ps_rec_truth_src_t src)
{
    r->truth = src;
}

void ps_recorder_deinit(ps_recorder_t *r)
{
    if (r == NULL)
        return;
    ps_recorder_stop(r);
    free(r->slots);
    r->slots = NULL;
    r->n_slots = 0;
}

/* ---- writer thread ---------------------------------------------------------- */

typedef struct {
    ps_recorder_t *r;
    int fd;
    ps_mcap_writer_t mcap;
    bool is_open;
    int ch[CH_COUNT]; /**< channel ids */
    uint32_t seq[CH_COUNT];
    uint64_t n_appended; /**< messages handed to the MCAP writer */
    uint64_t *rec_end;   /**< per pending record: n_appended after its last message */
    size_t n_pend, pend_head, pend_cap; /**< records not yet known to be in the file */
    ps_rec_file_stats_t *st;
} rec_file_t;

typedef struct {
    rec_file_t cont;
    uint64_t cont_next;
    rec_file_t dump;
    ps_rec_file_stats_t dump_stats; /**< the dump in progress */
    bool is_dumping;
    uint64_t dump_next, dump_end, dump_trig_idx;
    ps_rec_trig_t pending[PS_REC_TRIG_QUEUE]; /**< taken from the ring, not yet handled */
    uint32_t n_pending;
    uint32_t n_dumps;
    char schema[CH_COUNT][SCHEMA_BUF];
    int schema_len[CH_COUNT];
    uint8_t msg[MSG_BUF];
    ps_rec_tick_t rec;
    char joint_list[PS_MAX_JOINTS * (PS_NAME_LEN + 1)];
    char bus_list[PS_MAX_BUSES * (PS_NAME_LEN + 1)];
} writer_t;

static void sleep_ns(int64_t ns)
{
    const struct timespec ts = {(time_t)(ns / PS_NS_PER_S), (long)(ns % PS_NS_PER_S)};
    nanosleep(&ts, NULL);
}

static int io_write(void *ctx, const void *buf, size_t len)
{
    rec_file_t *f = ctx;
    if (f->r->io_delay_ns > 0)
        sleep_ns(f->r->io_delay_ns); /* test knob: a slow disk */
    const uint8_t *p = buf;
    while (len > 0) {
        ssize_t n = write(f->fd, p, len);
        if (n < 0 && errno == EINTR)
            continue;
        if (n < 0)
            return -errno;
        if (n == 0)
            return -EIO;
        p += n;
        len -= (size_t)n;
    }
    return 0;
}

static int io_sync(void *ctx)
{
    rec_file_t *f = ctx;
    if (fdatasync(f->fd) == 0 || errno == EINVAL || errno == EROFS)
        return 0; /* EINVAL: a file that cannot be synced (a pipe, /dev/null) */
    return -errno;
}

static void list_names(const char (*names)[PS_NAME_LEN], uint32_t n, char *out, size_t cap)
{
    size_t used = 0;
    out[0] = '\0';
    for (uint32_t i = 0; names != NULL && i < n && used + 1 < cap; i++) {
        int k = snprintf(out + used, cap - used, "%s%s", i ? "," : "", names[i]);
        if (k < 0)
            break;
        used += (size_t)k < cap - used ? (size_t)k : cap - used - 1;
    }
}

/* Open a file and declare every channel (those without messages do not
 * appear in it: MCAP writes a channel with its first message). */
static int file_open(writer_t *w, rec_file_t *f, const char *path, ps_rec_file_stats_t *st)
{
    ps_recorder_t *r = f->r;
    memset(st, 0, sizeof(*st));
    snprintf(st->path, sizeof(st->path), "%s", path);
    f->st = st;
    f->fd = open(path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (f->fd < 0) {
        st->err = -errno;
        return st->err;
    }
    const ps_mcap_cfg_t mc = {
        .io = {.write = io_write, .sync = io_sync},
        .io_ctx = f,
        .compression = r->cfg.compression,
        .chunk_size = r->cfg.chunk_size ? r->cfg.chunk_size : DEFAULT_CHUNK,
        .is_sync_chunks = r->cfg.is_sync_chunks,
        .profile = "ros2",
        .library = "pushstep flight recorder",
    };
    int rc = ps_mcap_open(&f->mcap, &mc);
    f->is_open = true;
    memset(f->seq, 0, sizeof(f->seq));
    f->n_appended = 0;
    f->n_pend = f->pend_head = 0;
    for (int c = 0; c < CH_COUNT && rc == 0; c++) {
        rc = ps_mcap_add_schema(&f->mcap, CHANNELS[c].def.name, "ros2msg", w->schema[c],
                                (size_t)w->schema_len[c]);
        const ps_mcap_kv_t joints_meta[] = {{"offered_qos_profiles", ""},
                                            {"joint_names", w->joint_list}};
        const ps_mcap_kv_t buses_meta[] = {{"offered_qos_profiles", ""},
                                           {"bus_names", w->bus_list}};
        const ps_mcap_kv_t *meta = joints_meta;
        size_t n_meta = 1;
        if (c == CH_JOINTS || c == CH_POLICY)
            n_meta = 2;
        if (c == CH_BUSES) {
            meta = buses_meta;
            n_meta = 2;
        }
        if (rc > 0)
            rc =
                ps_mcap_add_channel(&f->mcap, (uint16_t)rc, CHANNELS[c].topic, "cdr", meta, n_meta);
        if (rc >= 0) {
            f->ch[c] = rc;
            rc = 0;
        }
    }
    char hz[16], slots[16], when[32] = "";
    snprintf(hz, sizeof(hz), "%u", r->cfg.servo_hz);
    snprintf(slots, sizeof(slots), "%u", r->n_slots);
    const time_t now = time(NULL);
    struct tm utc;
    if (gmtime_r(&now, &utc) != NULL)
        (void)strftime(when, sizeof(when), "%Y-%m-%dT%H:%M:%SZ", &utc); /* fits */
    const ps_mcap_kv_t run[] = {
        {"board", r->cfg.board_name ? r->cfg.board_name : ""},
        {"robot", r->cfg.robot_name ? r->cfg.robot_name : ""},
        {"scenario", r->cfg.scenario_path ? r->cfg.scenario_path : ""},
        {"servo_hz", hz},
        {"joint_names", w->joint_list},
        {"bus_names", w->bus_list},
        {"clock", r->cfg.clock_name ? r->cfg.clock_name : ""},
        {"ring_slots", slots},
        {"file_opened_utc", when},
    };
    if (rc == 0)
        rc = ps_mcap_write_metadata(&f->mcap, "pushstep.run", run, sizeof(run) / sizeof(run[0]));
    if (rc < 0)
        st->err = rc;
    return rc;
}

static void put_message(rec_file_t *f, writer_t *w, int c, const void *src, const uint32_t *counts,
                        int64_t t_ns)
{
    const int n = ps_rosmsg_encode(&CHANNELS[c].def, src, counts, w->msg, sizeof(w->msg));
    if (n < 0)
        return; /* cannot happen: MSG_BUF holds the largest message (test_recorder's
                   test_largest_record_every_channel_written) */
    const uint64_t t = t_ns > 0 ? (uint64_t)t_ns : 0u;
    (void)ps_mcap_write_message(&f->mcap, (uint16_t)f->ch[c], f->seq[c]++, t, t, w->msg,
                                (size_t)n); /* an error fails the writer: seen below */
    f->n_appended++;
}

static void put_events(rec_file_t *f, writer_t *w, const ps_rec_tick_t *t)
{
    rec_event_t ev = {.tick = t->tick, .t_ns = t->t_ns};
    if (t->state != t->state_before) {
        char conds[160];
        ps_logger_format_cond(t->cond, conds, sizeof(conds));
        snprintf(ev.kind, sizeof(ev.kind), "transition");
        snprintf(ev.text, sizeof(ev.text), "%s -> %s (%s)",
                 ps_sm_state_name((ps_sm_state_t)t->state_before),
                 ps_sm_state_name((ps_sm_state_t)t->state), conds[0] ? conds : "-");
        put_message(f, w, CH_EVENTS, &ev, NULL, t->t_ns);
    }
    if (t->triggers != 0) {
        size_t used = 0;
        ev.text[0] = '\0';
        for (unsigned i = 0; i < PS_REC_TRIG_COUNT; i++)
            if (t->triggers & (1u << i)) {
                int k = snprintf(ev.text + used, sizeof(ev.text) - used, "%s%s", used ? "|" : "",
                                 TRIGGER_NAMES[i]);
                used += k > 0 ? (size_t)k : 0u;
            }
        snprintf(ev.kind, sizeof(ev.kind), "trigger");
        put_message(f, w, CH_EVENTS, &ev, NULL, t->t_ns);
    }
}

/* A record is in the file once the chunk holding its last message is:
 * the writer's message count (messages in written chunks) says how far. A
 * failed writer loses what was pending. */
static void settle(rec_file_t *f)
{
    while (f->n_pend > 0 && f->rec_end[f->pend_head] <= f->mcap.n_messages) {
        f->st->n_records++;
        f->pend_head++;
        f->n_pend--;
    }
    if (ps_mcap_error(&f->mcap) != 0) {
        f->st->n_lost_io += f->n_pend;
        f->n_pend = 0;
    }
    if (f->n_pend == 0)
        f->pend_head = 0;
}

/* One record as messages; a file whose writer failed counts it lost. */
static void file_put(rec_file_t *f, writer_t *w, const ps_rec_tick_t *t)
{
    if (!f->is_open || ps_mcap_error(&f->mcap) != 0) {
        f->st->n_lost_io++;
        return;
    }
    const uint32_t counts[CNT_COUNT] = {t->n_joints, t->n_buses, t->truth.n_contacts};
    put_message(f, w, CH_JOINTS, t, counts, t->t_ns);
    put_message(f, w, CH_IMU, t, counts, t->t_ns);
    put_message(f, w, CH_ESTIMATE, t, counts, t->t_ns);
    put_message(f, w, CH_STATE, t, counts, t->t_ns);
    put_message(f, w, CH_TIMING, t, counts, t->t_ns);
    put_message(f, w, CH_BUSES, t, counts, t->t_ns);
    if (t->is_policy_tick)
        put_message(f, w, CH_POLICY, t, counts, t->t_ns);
    if (t->has_truth)
        put_message(f, w, CH_TRUTH, t, counts, t->t_ns);
    put_events(f, w, t);
    if (f->n_pend + f->pend_head == f->pend_cap) { /* grow (compacting first) */
        if (f->pend_head > 0)
            memmove(f->rec_end, f->rec_end + f->pend_head, f->n_pend * sizeof(uint64_t));
        f->pend_head = 0;
        if (f->n_pend == f->pend_cap) {
            size_t cap = f->pend_cap ? f->pend_cap * 2 : 4096;
            uint64_t *p = realloc(f->rec_end, cap * sizeof(uint64_t));
            if (p == NULL) {
                f->st->n_lost_io++; /* cannot track it: count it lost rather than lie */
                return;
            }
            f->rec_end = p;
            f->pend_cap = cap;
        }
    }
    f->rec_end[f->pend_head + f->n_pend++] = f->n_appended;
    settle(f);
}

static void file_close(rec_file_t *f, const ps_mcap_kv_t *extra, size_t n_extra)
{
    if (!f->is_open)
        return;
    ps_rec_file_stats_t *st = f->st;
    (void)ps_mcap_flush(&f->mcap); /* an error: settle counts the pending records lost */
    settle(f);
    char written[24], lost_ring[24], lost_io[24];
    snprintf(written, sizeof(written), "%llu", (unsigned long long)st->n_records);
    snprintf(lost_ring, sizeof(lost_ring), "%llu", (unsigned long long)st->n_lost_ring);
    snprintf(lost_io, sizeof(lost_io), "%llu", (unsigned long long)st->n_lost_io);
    ps_mcap_kv_t kv[12] = {
        {"records_written", written},
        {"records_lost_ring", lost_ring},
        {"records_lost_io", lost_io},
    };
    size_t n = 3;
    for (size_t i = 0; i < n_extra && n < 12; i++)
        kv[n++] = extra[i];
    if (ps_mcap_error(&f->mcap) == 0)
        (void)ps_mcap_write_metadata(&f->mcap, "pushstep.recorder", kv, n); /* seen in close */
    st->n_index_bytes = (uint64_t)f->mcap.chunks_cap * sizeof(ps_mcap_chunk_entry_t);
    int rc = ps_mcap_close(&f->mcap);
    if (close(f->fd) < 0 && rc == 0)
        rc = -errno;
    if (rc < 0 && st->err == 0)
        st->err = rc;
    st->n_messages = f->mcap.n_messages;
    st->n_bytes = f->mcap.pos;
    memcpy(st->channel_n_messages, f->mcap.channel_n_messages, sizeof(st->channel_n_messages));
    f->is_open = false;
    f->fd = -1;
    free(f->rec_end);
    f->rec_end = NULL;
    f->n_pend = f->pend_head = f->pend_cap = 0;
}

/* Records before the ring's oldest are gone: count them and skip ahead. */
static uint64_t skip_lost(const ps_recorder_t *r, uint64_t next, uint64_t head,
                          ps_rec_file_stats_t *st)
{
    if (head > r->n_slots && next < head - r->n_slots) {
        st->n_lost_ring += head - r->n_slots - next;
        next = head - r->n_slots;
    }
    return next;
}

/* @return records handled */
static uint32_t drain_file(writer_t *w, rec_file_t *f, uint64_t *next, uint64_t end)
{
    ps_recorder_t *r = w->cont.r;
    uint32_t k = 0;
    uint64_t head = atomic_load_explicit(&r->head, memory_order_acquire);
    if (end > head)
        end = head;
    *next = skip_lost(r, *next, head, f->st);
    for (; *next < end && k < RECORDS_PER_PASS; k++) {
        const int rc = ps_recorder_read(r, *next, &w->rec);
        (*next)++;
        if (rc == -ESTALE) {
            f->st->n_lost_ring++;
            continue;
        }
        if (rc < 0)
            break;
        file_put(f, w, &w->rec);
    }
    return k;
}

static uint64_t ticks_of(const ps_recorder_t *r, double s)
{
    return (uint64_t)llround(s * r->cfg.servo_hz);
}

static void dump_begin(writer_t *w, uint64_t trig_idx, uint32_t bits)
{
    ps_recorder_t *r = w->cont.r;
    const uint64_t head = atomic_load_explicit(&r->head, memory_order_acquire);
    const uint64_t pre = ticks_of(r, r->cfg.pre_s);
    uint64_t from = trig_idx > pre ? trig_idx - pre : 0u;
    const uint64_t oldest = head > r->n_slots ? head - r->n_slots : 0u;
    w->dump_next = from;
    w->dump_end = trig_idx + ticks_of(r, r->cfg.post_s) + 1u;
    w->dump_trig_idx = trig_idx;
    w->is_dumping = true;
    char path[PS_PATH_LEN + 32];
    w->n_dumps++;
    snprintf(path, sizeof(path), "%s/flight-%04u.mcap", r->dir, w->n_dumps);
    w->dump.r = r;
    w->dump.fd = -1;
    (void)file_open(w, &w->dump, path, &w->dump_stats); /* a failure: err in dump_stats */
    w->dump_stats.triggers = bits;
    if (from < oldest) { /* the ring is shorter than pre_s: what it held */
        w->dump_stats.n_lost_ring += oldest - from;
        w->dump_next = oldest;
    }
    if (w->dump_stats.err != 0) { /* cannot be written: every record of it is lost */
        w->dump_stats.n_lost_io += w->dump_end - w->dump_next;
        w->dump_next = w->dump_end;
    }
}

static void dump_end(writer_t *w)
{
    ps_recorder_t *r = w->cont.r;
    char tick[24], causes[64] = "", pre[24], post[24], last[24];
    for (unsigned i = 0, used = 0; i < PS_REC_TRIG_COUNT; i++)
        if (w->dump_stats.triggers & (1u << i)) {
            int k = snprintf(causes + used, sizeof(causes) - used, "%s%s", used ? "|" : "",
                             TRIGGER_NAMES[i]);
            used += k > 0 ? (unsigned)k : 0u;
        }
    snprintf(tick, sizeof(tick), "%llu", (unsigned long long)w->dump_trig_idx);
    snprintf(pre, sizeof(pre), "%.3f", r->cfg.pre_s);
    snprintf(post, sizeof(post), "%.3f", r->cfg.post_s);
    snprintf(last, sizeof(last), "%llu", (unsigned long long)(w->dump_next - 1u));
    const ps_mcap_kv_t kv[] = {
        {"trigger", causes}, {"trigger_record", tick}, {"pre_s", pre},
        {"post_s", post},    {"last_record", last},
    };
    w->dump_stats.trigger_tick = w->dump_trig_idx;
    file_close(&w->dump, kv, sizeof(kv) / sizeof(kv[0]));
    ps_recorder_stats_t *s = &r->stats;
    if (w->dump_stats.err != 0)
        s->n_dumps_failed++;
    if (s->n_dumps < PS_REC_MAX_DUMP_STATS)
        s->dump[s->n_dumps] = w->dump_stats;
    s->n_dumps++;
    s->bytes_total += w->dump_stats.n_bytes;
    w->is_dumping = false;
}

/* The oldest record this writer may still read: its continuous file's
 * next, the dump in progress's next, a pending trigger's pre window, and
 * with flight dumps on the pre window of a trigger still to come. For the
 * loop's wait in unpaced runs (cfg.is_lossless). */
static void publish_needed(writer_t *w, uint64_t head_at_pop)
{
    ps_recorder_t *r = w->cont.r;
    /* A trigger the pass did not pop has an index of at least head_at_pop
     * less one (the loop pushes it just after committing its record): its
     * pre window starts no later than that. */
    uint64_t need = head_at_pop > 0u ? head_at_pop - 1u : 0u;
    /* A ring shorter than a dump's window (--record-ring below pre + post)
     * loses part of each dump however long the loop waits: the pre window
     * is then not held, or a pending dump would wait on itself. */
    const uint64_t pre_ticks = ticks_of(r, r->cfg.pre_s);
    const bool is_pre_held =
        r->cfg.dir != NULL && pre_ticks + ticks_of(r, r->cfg.post_s) + 2u < r->n_slots;
    const uint64_t pre = is_pre_held ? pre_ticks : 0u;
    need = need > pre ? need - pre : 0u;
    if (r->cfg.path != NULL && w->cont_next < need)
        need = w->cont_next;
    if (w->is_dumping && w->dump_next < need)
        need = w->dump_next;
    if (w->n_pending > 0 && is_pre_held) {
        const uint64_t from = w->pending[0].idx > pre ? w->pending[0].idx - pre : 0u;
        if (from < need)
            need = from;
    }
    atomic_store_explicit(&r->writer_needed, need, memory_order_release);
}

/* @return records handled in this pass */
static uint32_t pass(writer_t *w, bool is_final)
{
    ps_recorder_t *r = w->cont.r;
    uint32_t k = 0;
    const uint64_t head_at_pop = atomic_load_explicit(&r->head, memory_order_acquire);
    while (w->n_pending < PS_REC_TRIG_QUEUE &&
           ps_ring_pop(&r->trig_ring, &w->pending[w->n_pending]) == 0)
        w->n_pending++;
    /* In order: one inside the dump being written is noted in it (its
     * /events too); one after it waits for it to end, then starts the next. */
    while (w->n_pending > 0 && r->cfg.dir != NULL) {
        const ps_rec_trig_t tr = w->pending[0];
        if (!w->is_dumping)
            dump_begin(w, tr.idx, tr.bits);
        else if (tr.idx < w->dump_end)
            w->dump_stats.triggers |= tr.bits;
        else
            break;
        memmove(w->pending, w->pending + 1, (w->n_pending - 1u) * sizeof(w->pending[0]));
        w->n_pending--;
    }
    if (r->cfg.path != NULL)
        k += drain_file(w, &w->cont, &w->cont_next, UINT64_MAX);
    if (w->is_dumping) {
        if (w->dump.is_open)
            k += drain_file(w, &w->dump, &w->dump_next, w->dump_end);
        const uint64_t head = atomic_load_explicit(&r->head, memory_order_acquire);
        if (w->dump_next >= w->dump_end || (is_final && w->dump_next >= head)) {
            if (w->dump_next < w->dump_end && w->dump_stats.err == 0)
                w->dump_end = w->dump_next; /* the run ended inside the post window */
            dump_end(w);
        }
    }
    publish_needed(w, head_at_pop);
    return k;
}

static void *writer_main(void *arg)
{
    ps_recorder_t *r = arg;
    writer_t *w = r->w;
    if (r->cfg.cpu >= 0)
        (void)ps_rtsetup_thread_best_effort(0, r->cfg.cpu); /* not real-time */
    while (!atomic_load(&r->should_stop)) {
        if (pass(w, false) == 0)
            sleep_ns(IDLE_SLEEP_NS);
    }
    while (pass(w, true) != 0 || w->is_dumping || (w->n_pending > 0 && r->cfg.dir != NULL)) {
    }
    char slots[16];
    snprintf(slots, sizeof(slots), "%u", r->n_slots);
    const ps_mcap_kv_t kv[] = {{"ring_slots", slots}};
    file_close(&w->cont, kv, 1);
    return NULL;
}

int ps_recorder_start(ps_recorder_t *r)
{
    writer_t *w = calloc(1, sizeof(*w));
    if (w == NULL)
        return -ENOMEM;
    r->w = w;
    for (int c = 0; c < CH_COUNT; c++) {
        w->schema_len[c] = ps_rosmsg_schema_text(&CHANNELS[c].def, w->schema[c], SCHEMA_BUF);
        if (w->schema_len[c] < 0)
            return w->schema_len[c];
        snprintf(r->stats.channel_topic[c], sizeof(r->stats.channel_topic[c]), "%s",
                 CHANNELS[c].topic);
    }
    r->stats.n_channels = CH_COUNT;
    list_names(r->cfg.bus_name, r->cfg.n_buses, w->bus_list, sizeof(w->bus_list));
    list_names(r->cfg.joint_name, r->cfg.n_joints, w->joint_list, sizeof(w->joint_list));
    w->cont.r = r;
    w->dump.r = r;
    w->cont.fd = w->dump.fd = -1;
    w->cont.st = &r->stats.cont;
    if (r->cfg.path != NULL)
        (void)file_open(w, &w->cont, r->path, &r->stats.cont); /* err in stats.cont */
    atomic_store(&r->writer_needed, atomic_load(&r->head));
    atomic_store(&r->is_writer_running, true);
    int rc = pthread_create(&r->thread, NULL, writer_main, r);
    if (rc != 0) {
        atomic_store(&r->is_writer_running, false);
        return -rc;
    }
    r->has_thread = true;
    return 0;
}

void ps_recorder_stop(ps_recorder_t *r)
{
    if (!r->has_thread) {
        free(r->w);
        r->w = NULL;
        return;
    }
    atomic_store(&r->should_stop, true);
    (void)pthread_join(r->thread, NULL); /* the writer cannot fail to end */
    r->has_thread = false;
    ps_recorder_stats_t *s = &r->stats;
    s->n_slots = r->n_slots;
    s->n_pushed = atomic_load(&r->head);
    s->n_triggers = atomic_load(&r->n_trig);
    for (unsigned i = 0; i < PS_REC_TRIG_COUNT; i++)
        s->n_triggers_by[i] = atomic_load(&r->n_trig_by[i]);
    s->bytes_total += s->cont.n_bytes;
    free(r->w);
    r->w = NULL;
}
