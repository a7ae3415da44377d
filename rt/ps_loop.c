#include "ps_loop.h"

#include <math.h>
#include <string.h>

#include "../policy/ps_servo.h"
#include "ps_config.h"
#include "ps_err.h"
#include "ps_perception.h"

static const char *const STAGE_NAMES[PS_STAGE_COUNT] = {
    [PS_STAGE_WAKE] = "wake",
    [PS_STAGE_READ] = "read",
    [PS_STAGE_ESTIMATE] = "estimate",
    [PS_STAGE_POLICY] = "policy",
    [PS_STAGE_SERVO] = "servo",
    [PS_STAGE_WRITE] = "write",
    [PS_STAGE_TICK] = "tick",
    [PS_STAGE_TICK_PLAIN] = "tick_plain",
    [PS_STAGE_TICK_POLICY] = "tick_policy",
    [PS_STAGE_REACTION] = "reaction",
    [PS_STAGE_TAP] = "tap",
};
_Static_assert(sizeof(STAGE_NAMES) / sizeof(STAGE_NAMES[0]) == PS_STAGE_COUNT,
               "one name per stage");

/* A saturated gyro or a failed self-test makes the sample useless. A
 * saturated accelerometer (an impact) does not: the gyro still counts and the
 * estimator's gravity gate ignores an accelerometer far from 1 g. */
#define IMU_STATUS_REJECTED (PS_IMU_STATUS_SELFTEST_FAIL | PS_IMU_STATUS_GYRO_SAT)

/* DAMPING may end early on stillness only after this long, so that a robot
 * that is momentarily still at the instant damping starts is still braked. */
#define MIN_DAMPING_NS (200 * PS_NS_PER_MS)

const char *ps_loop_stage_name(ps_stage_t s)
{
    return (s >= 0 && s < PS_STAGE_COUNT) ? STAGE_NAMES[s] : "?";
}

/* Which joints' replies can arrive on each bus: a frame is offered to the
 * protocol of each joint on its bus until one matches. */
static void build_reply_table(ps_loop_t *loop)
{
    const ps_robot_cfg_t *r = loop->cfg.robot;
    memset(loop->n_bus_joints, 0, sizeof(loop->n_bus_joints));
    for (uint32_t j = 0; j < r->n_joints; j++) {
        const uint32_t b = r->act[j].bus_idx;
        loop->bus_joint[b][loop->n_bus_joints[b]++] = (uint8_t)j;
    }
}

/* The fastest speed a joint's reply may plausibly show (rt/ps_loop.h): the
 * factor times the largest of its command limit, its driver's wire range
 * and no-load speed (seen from the joint); the jump test's slack in LSB. */
static void init_reply_bounds(ps_loop_t *loop)
{
    const ps_robot_cfg_t *r = loop->cfg.robot;
    for (uint32_t j = 0; j < r->n_joints; j++) {
        const ps_act_cfg_t *a = &r->act[j];
        const ps_act_range_t *w = &r->servo[j].wire;
        float v = r->servo[j].lim.vel_max_rad_s;
        v = fmaxf(v, fmaxf(fabsf(w->v_min_rad_s), fabsf(w->v_max_rad_s)));
        v = fmaxf(v, a->motor.no_load_speed_rad_s / a->gear_ratio);
        loop->reply_max_vel_rad_s[j] = PS_LOOP_REPLY_VEL_FACTOR * v;
        float lsb[5];
        ps_act_joint_lsb(a, lsb);
        loop->reply_margin_rad[j] = PS_LOOP_REPLY_MARGIN_LSB * lsb[0];
    }
}

/* The config loader checks all of this too; the loop checks again because it
 * indexes its fixed tables with these values on every tick. */
static bool is_schedule_valid(const ps_board_cfg_t *b, const ps_robot_cfg_t *r)
{
    for (uint32_t j = 0; j < r->n_joints; j++) {
        const ps_act_cfg_t *a = &r->act[j];
        const ps_act_proto_t *p = ps_act_proto_get(a->protocol);
        if (a->bus_idx >= b->n_buses || a->rate_div == 0 || p == NULL ||
            p->n_cmd > PS_ACT_MAX_FRAMES || ps_act_check_cfg(a, NULL, 0) < 0)
            return false;
    }
    return r->imu.bus_idx < b->n_buses && r->imu.rate_div != 0 &&
           r->imu.base_id < PS_CAN_SFF_MASK && r->imu.protocol < PS_IMU_PROTO_COUNT;
}

int ps_loop_init(ps_loop_t *loop, const ps_loop_cfg_t *cfg)
{
    if (loop == NULL || cfg == NULL || cfg->robot == NULL || cfg->board == NULL ||
        cfg->plan == NULL || cfg->clock == NULL || cfg->policy.ops == NULL)
        return -EINVAL;
    const ps_control_cfg_t *c = &cfg->robot->control;
    if (c->servo_hz == 0 || c->policy_hz == 0 || c->servo_hz % c->policy_hz != 0 ||
        cfg->robot->n_joints == 0 || cfg->robot->n_joints > PS_MAX_JOINTS ||
        cfg->board->n_buses == 0 || cfg->board->n_buses > PS_MAX_BUSES)
        return -EINVAL;
    for (uint32_t b = 0; b < cfg->board->n_buses; b++)
        if (cfg->buses[b].ops == NULL)
            return -EINVAL;
    if (cfg->gpio.ops == NULL || !is_schedule_valid(cfg->board, cfg->robot) ||
        !(c->ramp_s > 0.0f) || !(c->damping_s > 0.0f))
        return -EINVAL;
    /* The derating band must have a width (torque_scale divides by it). */
    if (!(c->hot_margin_c >= 0.0f) || !(c->derate_band_c > c->hot_margin_c) ||
        !(c->derate_min > 0.0f) || !(c->derate_min <= 1.0f))
        return -EINVAL;
    if (cfg->neighbours != NULL && (!cfg->board->has_perception ||
                                     !(cfg->board->perception.max_age_s > 0)))
        return -EINVAL;

    memset(loop, 0, sizeof(*loop)); /* also touches every page of the struct */
    loop->cfg = *cfg;
    if (loop->cfg.perf_clock == NULL)
        loop->cfg.perf_clock = cfg->clock;
    if (loop->cfg.deadline_clock == NULL)
        loop->cfg.deadline_clock = cfg->clock;
    loop->period_ns = PS_NS_PER_S / c->servo_hz;
    loop->neighbours_max_age_ns =
        cfg->neighbours != NULL ? ps_s_to_ns((double)cfg->board->perception.max_age_s) : 0;
    loop->policy_div = c->servo_hz / c->policy_hz;
    loop->state = PS_SM_STANDBY;
    atomic_init(&loop->published_state, (int)PS_SM_STANDBY);
    loop->meas.n_joints = cfg->robot->n_joints;
    atomic_init(&loop->external_requests, 0u);
    atomic_init(&loop->n_stop_requests, 0u);
    int rc = ps_estimate_init(&loop->estimator, &cfg->robot->kin, cfg->robot->joint_name,
                              cfg->robot->n_joints, (float)loop->period_ns * 1e-9f);
    if (rc < 0)
        return rc;
    build_reply_table(loop);
    init_reply_bounds(loop);
    for (uint32_t j = 0; j < PS_MAX_JOINTS; j++)
        loop->fault_grace_until_ns[j] = INT64_MAX; /* drives not enabled yet */
    ps_imu_rx_init(&loop->imu_rx, &cfg->robot->imu);
    for (int s = 0; s < PS_STAGE_COUNT; s++)
        ps_perf_reset(&loop->perf[s]);
    rc = ps_perf_us_reset(&loop->wake_us, cfg->wake_hist_us ? cfg->wake_hist_us : 1000u);
    if (rc < 0)
        return rc;
    return ps_pacer_init(&loop->pacer, cfg->clock, loop->period_ns, 0);
}

void ps_loop_deinit(ps_loop_t *loop)
{
    if (loop != NULL)
        memset(loop, 0, sizeof(*loop));
}

/* ---- READ ------------------------------------------------------------- */

/* Payload corruption that keeps the frame's length: a position no drive can
 * have reached since the last reply taken, or a velocity no drive makes
 * (rt/ps_loop.h). The time between the two replies is the larger of the
 * ticks that took them and their receive stamps (two replies may arrive in
 * one tick after a late batch), plus one servo period of slack. */
static bool is_reply_plausible(const ps_loop_t *loop, uint32_t j, const ps_act_meas_t *m,
                               int64_t rx_ns)
{
    const ps_act_meas_t *prev = &loop->meas.joints[j];
    const float v_max = loop->reply_max_vel_rad_s[j];
    if (!(fabsf(m->qd_rad_s) <= v_max))
        return false;
    if (prev->t_ns == 0)
        return true; /* nothing to compare with */
    int64_t dt_ns = loop->t_deadline_ns - prev->t_ns;
    if (rx_ns - loop->reply_rx_ns[j] > dt_ns)
        dt_ns = rx_ns - loop->reply_rx_ns[j];
    const float dt_s = (float)(dt_ns + loop->period_ns) * 1e-9f;
    return fabsf(m->q_rad - prev->q_rad) <= v_max * dt_s + loop->reply_margin_rad[j];
}

/* @return true if a joint on the bus claimed the frame (decoded or bad). */
static bool take_reply(ps_loop_t *loop, uint32_t bus_idx, const ps_can_frame_t *f)
{
    const ps_robot_cfg_t *r = loop->cfg.robot;
    for (uint32_t k = 0; k < loop->n_bus_joints[bus_idx]; k++) {
        const uint32_t j = loop->bus_joint[bus_idx][k];
        ps_act_meas_t m = {0};
        const int rc = ps_act_decode_reply(&r->act[j], f, &m);
        if (rc == -ENOENT) {
            /* Not a reply: perhaps the drive's own fault report. Its bits
             * stay until the drives are enabled again after ESTOP: the next
             * reply may not carry them (docs/safety.md). */
            uint32_t bits = 0;
            const int frc = ps_act_decode_fault(&r->act[j], f, &bits);
            if (frc == -ENOENT)
                continue;
            if (frc < 0)
                loop->counters.n_rx_bad++;
            else {
                loop->fault_report_bits[j] |= bits;
                loop->counters.n_fault_reports++;
            }
            return true;
        }
        if (rc < 0 || !isfinite(m.q_rad)) {
            loop->counters.n_rx_bad++;
            return true;
        }
        if (!is_reply_plausible(loop, j, &m, f->t_ns)) {
            loop->counters.n_reply_implausible++;
            loop->counters.n_rx_bad++;
            return true;
        }
        loop->reply_rx_ns[j] = f->t_ns;
        m.t_ns = loop->t_deadline_ns;
        loop->meas.joints[j] = m;
        if (f->t_ns > loop->newest_reply_rx_ns)
            loop->newest_reply_rx_ns = f->t_ns;
        return true;
    }
    return false;
}

static void take_frame(ps_loop_t *loop, uint32_t bus_idx, const ps_can_frame_t *f)
{
    loop->counters.n_rx_frames++;
    if (!ps_can_is_valid_frame(f)) {
        loop->counters.n_rx_bad++; /* an id beyond its width, or a length no frame has */
        return;
    }
    if (take_reply(loop, bus_idx, f))
        return;
    if (bus_idx != loop->cfg.robot->imu.bus_idx || f->is_ext) {
        loop->counters.n_rx_unknown++;
        return;
    }
    ps_imu_sample_t sample;
    int rc = ps_imu_rx_feed(&loop->imu_rx, f, &sample);
    if (rc == -ENOENT) {
        loop->counters.n_rx_unknown++;
    } else if (rc == -PS_ERR_STALE) {
        loop->counters.n_imu_frozen++; /* values frozen while the seq goes on: not fresh */
    } else if (rc < 0) {
        loop->counters.n_rx_bad++;
    } else if (rc == 1 && (sample.status & IMU_STATUS_REJECTED)) {
        loop->counters.n_imu_rejected++; /* saturated gyro or failed: not a measurement */
    } else if (rc == 1 && loop->has_imu_seq && sample.seq == loop->imu_seq) {
        loop->counters.n_imu_repeated++; /* a hung IMU repeating itself is not fresh */
    } else if (rc == 1) {
        loop->has_imu_seq = true;
        loop->imu_seq = sample.seq;
        ps_imu_meas_t *imu = &loop->meas.imu;
        memcpy(imu->gyro_body_rad_s, sample.gyro_body_rad_s, sizeof(imu->gyro_body_rad_s));
        memcpy(imu->accel_body_m_s2, sample.accel_body_m_s2, sizeof(imu->accel_body_m_s2));
        imu->t_ns = loop->t_deadline_ns;
    }
}

/* Copies frames to the candump ring; a full ring drops and counts
 * (ps_ring_dropped), the tick never waits for the log. */
static void tap_frames(ps_loop_t *loop, uint32_t bus_idx, const ps_can_frame_t *f, size_t n,
                       bool is_tx)
{
    if (loop->cfg.frame_ring == NULL)
        return;
    for (size_t i = 0; i < n; i++) {
        ps_loop_frame_rec_t rec = {.frame = f[i], .bus_idx = (uint8_t)bus_idx, .is_tx = is_tx};
        if (is_tx)
            rec.frame.t_ns = loop->t_deadline_ns;
        (void)ps_ring_push(loop->cfg.frame_ring, &rec);
    }
}

static void read_bus(ps_loop_t *loop, uint32_t bus_idx)
{
    const ps_can_port_t *port = &loop->cfg.buses[bus_idx];
    const size_t cap = sizeof(loop->rx_buf) / sizeof(loop->rx_buf[0]);
    /* A healthy bus carries far less than a batch per tick; the cap keeps a
     * babbling node or a backlog after a stall from starving the tick. What
     * is left waits for the next tick. */
    for (unsigned batch = 0; batch < PS_LOOP_MAX_RX_BATCHES; batch++) {
        int n = ps_can_recv_batch(port, loop->rx_buf, cap);
        if (n < 0) {
            loop->counters.n_bus_errors++;
            return;
        }
        for (int i = 0; i < n; i++)
            take_frame(loop, bus_idx, &loop->rx_buf[i]);
        tap_frames(loop, bus_idx, loop->rx_buf, (size_t)n, false);
        loop->last.n_rx[bus_idx] = (uint16_t)(loop->last.n_rx[bus_idx] + (uint32_t)n);
        if ((size_t)n < cap)
            return;
    }
    loop->counters.n_rx_capped++;
}

static void read_bus_states(ps_loop_t *loop)
{
    loop->bus_off_mask = 0;
    for (uint32_t b = 0; b < loop->cfg.board->n_buses; b++) {
        ps_can_state_t st;
        if (ps_can_get_state(&loop->cfg.buses[b], &st) < 0) {
            loop->counters.n_bus_errors++;
            continue;
        }
        if (st.mode == PS_CAN_BUS_OFF)
            loop->bus_off_mask |= 1u << b;
        loop->last.bus[b] = st;
    }
}

/* The newest neighbour list from perception, aged at this tick's deadline. */
static void read_neighbours(ps_loop_t *loop)
{
    if (loop->cfg.neighbours == NULL)
        return;
    if (ps_perception_take(loop->cfg.neighbours, loop->t_deadline_ns, loop->neighbours_max_age_ns,
                           &loop->meas.neighbours))
        loop->counters.n_neighbour_lists++;
    if (!loop->meas.neighbours.is_valid)
        loop->counters.n_neighbour_stale++;
}

static void stage_read(ps_loop_t *loop)
{
    loop->newest_reply_rx_ns = 0;
    memset(loop->last.n_rx, 0, sizeof(loop->last.n_rx));
    for (uint32_t b = 0; b < loop->cfg.board->n_buses; b++)
        read_bus(loop, b);
    read_bus_states(loop);
    read_neighbours(loop);
}

/* ---- POLICY ----------------------------------------------------------- */

static bool is_target_valid(const ps_robot_cfg_t *r, const ps_targets_t *t)
{
    if (t->n_joints != r->n_joints)
        return false;
    for (uint32_t j = 0; j < r->n_joints; j++) {
        const ps_act_limits_t *lim = &r->servo[j].lim;
        float q = t->q_rad[j];
        if (!isfinite(q) || q < lim->pos_min_rad || q > lim->pos_max_rad ||
            !isfinite(t->qd_rad_s[j]) || !isfinite(t->tau_ff_nm[j]))
            return false;
    }
    return true;
}

static void stage_policy(ps_loop_t *loop, uint64_t tick)
{
    const bool is_reset = loop->is_policy_reset;
    loop->is_policy_reset = false;
    if (is_reset)
        loop->cfg.policy.ops->reset(loop->cfg.policy.ctx); /* before this tick's step */
    else if (tick % loop->policy_div != 0)
        return;
    /* Statistics on the perf clock; the deadline on the deadline clock (the
     * pacing clock on hardware, the thread's CPU time in lockstep, so that a
     * preempted policy is not late and the run stays deterministic). */
    const ps_clock_t *perf = loop->cfg.perf_clock, *dl = loop->cfg.deadline_clock;
    int64_t t0 = ps_clock_now_ns(perf), t0_dl = ps_clock_now_ns(dl);
    int rc = loop->cfg.policy.ops->step(loop->cfg.policy.ctx, &loop->meas, &loop->estimator.est,
                                        &loop->targets);
    int64_t dt = ps_clock_now_ns(perf) - t0, dt_dl = ps_clock_now_ns(dl) - t0_dl;
    ps_perf_record(&loop->perf[PS_STAGE_POLICY], dt);
    loop->last.is_policy_run = true;
    loop->last.policy_dt_ns = dt;
    loop->counters.n_policy_runs++;
    loop->has_policy_late = dt_dl > ps_s_to_ns(loop->cfg.robot->control.policy_deadline_s);
    if (loop->has_policy_late)
        loop->counters.n_policy_late++;
    loop->has_target_invalid = rc < 0 || !is_target_valid(loop->cfg.robot, &loop->targets);
    if (loop->has_target_invalid) {
        loop->counters.n_target_invalid++;
        return;
    }
    loop->has_targets = true;
    /* A late step's targets are tracked (the state machine reacts next tick)
     * but are not the pose HOLD falls back to. */
    if (!loop->has_policy_late)
        memcpy(loop->safe_q_rad, loop->targets.q_rad, sizeof(loop->safe_q_rad));
}

/* ---- state machine ---------------------------------------------------- */

static void push_record(ps_loop_t *loop, const ps_loop_rec_t *rec)
{
    if (loop->cfg.ring != NULL && ps_ring_push(loop->cfg.ring, rec) < 0)
        loop->counters.n_ring_dropped++;
}

static void fill_record(const ps_loop_t *loop, ps_rec_kind_t kind, ps_loop_rec_t *rec)
{
    memset(rec, 0, sizeof(*rec));
    rec->kind = (uint8_t)kind;
    rec->state = (uint8_t)loop->state;
    rec->tick = loop->counters.n_ticks;
    rec->t_ns = loop->t_deadline_ns;
    rec->n_overruns = loop->pacer.n_overruns;
    rec->n_policy_runs = loop->counters.n_policy_runs;
    rec->com_height_m = loop->estimator.est.com_m[2];
    float roll = loop->estimator.est.roll_rad, pitch = loop->estimator.est.pitch_rad;
    rec->tilt_rad = sqrtf(roll * roll + pitch * pitch);
}

static bool is_stale(int64_t t_ns, int64_t now_ns, int64_t timeout_ns)
{
    return t_ns == 0 || now_ns - t_ns > timeout_ns;
}

/* OVERRUN: the last overrun_limit overruns all fell within overrun_window_s
 * before this tick. */
static bool is_overrunning(const ps_loop_t *loop)
{
    const ps_control_cfg_t *c = &loop->cfg.robot->control;
    const uint32_t limit = c->overrun_limit;
    if (limit == 0 || limit > PS_LOOP_MAX_OVERRUN_LIMIT || loop->n_overrun_times < limit)
        return false;
    const uint32_t oldest = (loop->n_overrun_times - limit) % PS_LOOP_MAX_OVERRUN_LIMIT;
    return loop->t_deadline_ns - loop->overrun_t_ns[oldest] <= ps_s_to_ns(c->overrun_window_s);
}

static void note_overrun(ps_loop_t *loop, int64_t t_ns)
{
    loop->overrun_t_ns[loop->n_overrun_times % PS_LOOP_MAX_OVERRUN_LIMIT] = t_ns;
    loop->n_overrun_times++;
}

static uint32_t watchdog_conditions(const ps_loop_t *loop)
{
    const ps_robot_cfg_t *r = loop->cfg.robot;
    const int64_t now = loop->t_deadline_ns;
    const int64_t reply_timeout = ps_s_to_ns(r->control.reply_timeout_s);
    uint32_t cond = 0;
    for (uint32_t j = 0; j < r->n_joints; j++) {
        const ps_act_meas_t *m = &loop->meas.joints[j];
        const ps_act_cfg_t *a = &r->act[j];
        if (is_stale(m->t_ns, now, reply_timeout + (int64_t)a->rate_div * loop->period_ns))
            cond |= PS_SM_C_REPLY_STALE;
        else if (now >= loop->fault_grace_until_ns[j] &&
                 ((m->fault_bits | loop->fault_report_bits[j]) != 0u || m->temp_c > a->temp_max_c))
            cond |= PS_SM_C_DRIVE_FAULT;
        else if (m->temp_c >= a->temp_max_c - r->control.hot_margin_c)
            cond |= PS_SM_C_DRIVE_HOT; /* damp before its own protection trips */
    }
    if (is_stale(loop->meas.imu.t_ns, now,
                 ps_s_to_ns(r->control.imu_timeout_s) + (int64_t)r->imu.rate_div * loop->period_ns))
        cond |= PS_SM_C_IMU_STALE;
    if (loop->has_policy_late)
        cond |= PS_SM_C_POLICY_LATE;
    if (loop->has_target_invalid || loop->has_cmd_fault)
        cond |= PS_SM_C_TARGET_INVALID;
    if (loop->bus_off_mask != 0)
        cond |= PS_SM_C_BUS_OFF;
    if (loop->has_tx_refused)
        cond |= PS_SM_C_TX_REFUSED;
    if (loop->has_heartbeat_fault)
        cond |= PS_SM_C_ESTOP_INPUT; /* the relay is cutting the drives' power */
    if (is_overrunning(loop))
        cond |= PS_SM_C_OVERRUN;
    if (loop->estimator.est.is_fallen)
        cond |= PS_SM_C_FALL;
    return cond;
}

static bool is_still(const ps_loop_t *loop)
{
    const float still = loop->cfg.robot->control.still_vel_rad_s;
    for (uint32_t j = 0; j < loop->meas.n_joints; j++)
        if (fabsf(loop->meas.joints[j].qd_rad_s) >= still)
            return false;
    return true;
}

static uint32_t timer_conditions(const ps_loop_t *loop)
{
    const ps_control_cfg_t *c = &loop->cfg.robot->control;
    const int64_t in_state = loop->t_deadline_ns - loop->state_since_ns;
    if (loop->state == PS_SM_RAMP && in_state >= ps_s_to_ns(c->ramp_s))
        return PS_SM_C_RAMP_DONE;
    if (loop->state == PS_SM_DAMPING &&
        (in_state >= ps_s_to_ns(c->damping_s) || (in_state >= MIN_DAMPING_NS && is_still(loop))))
        return PS_SM_C_DAMP_DONE;
    if (loop->state == PS_SM_HOLD && in_state >= ps_s_to_ns(c->hold_s))
        return PS_SM_C_HOLD_DONE;
    return 0;
}

/* Stopping: after an operator's stop request or the end of the run. */
static bool is_stopping(const ps_loop_t *loop)
{
    return loop->is_ending || loop->n_stops_handled > 0;
}

/* Operator requests are checked one by one so that each refusal is logged
 * with its reason; accepted ones join the conditions of this tick. */
static uint32_t take_requests(ps_loop_t *loop, uint32_t cond)
{
    uint32_t req = atomic_exchange(&loop->external_requests, 0u);
    if (loop->cfg.op.take != NULL)
        req |= loop->cfg.op.take(loop->cfg.op.ctx) & PS_SM_C_REQUESTS;
    if (is_stopping(loop))
        req &= ~(uint32_t)PS_SM_C_REQ_START; /* stopping: no new start */
    uint32_t accepted = 0;
    for (uint32_t bit = 1; bit != 0 && bit <= PS_SM_C_REQUESTS; bit <<= 1) {
        if ((req & bit) == 0)
            continue;
        const char *reason = NULL;
        if (ps_sm_check_request(loop->state, bit, cond, &reason) == 0) {
            accepted |= bit;
            continue;
        }
        ps_loop_rec_t rec;
        fill_record(loop, PS_REC_REFUSED, &rec);
        rec.cond = bit;
        rec.reason = reason;
        push_record(loop, &rec);
        loop->counters.n_refused++;
    }
    return accepted;
}

static void enter_state(ps_loop_t *loop, ps_sm_state_t to)
{
    if (loop->state == PS_SM_ESTOP && to == PS_SM_STANDBY) {
        /* Only replies after the drives' new enable count (docs/safety.md). */
        for (uint32_t j = 0; j < loop->meas.n_joints; j++) {
            loop->meas.joints[j].fault_bits = 0u;
            loop->fault_report_bits[j] = 0u;
            loop->meas.joints[j].t_ns = 0;
            loop->fault_grace_until_ns[j] = INT64_MAX; /* until its enable is sent */
        }
    }
    loop->state = to;
    atomic_store_explicit(&loop->published_state, (int)to, memory_order_relaxed);
    loop->state_since_ns = loop->t_deadline_ns;
    if (to == PS_SM_RAMP) {
        for (uint32_t j = 0; j < loop->meas.n_joints; j++)
            loop->ramp_from_q_rad[j] = loop->meas.joints[j].q_rad;
        loop->is_policy_reset = true; /* stage_policy resets, then steps this tick */
    }
    if (to == PS_SM_HOLD) {
        /* The last safe pose: the targets of the last valid policy step, or
         * where the robot is when there was none. */
        for (uint32_t j = 0; j < loop->meas.n_joints; j++)
            loop->hold_q_rad[j] =
                loop->has_targets ? loop->safe_q_rad[j] : loop->meas.joints[j].q_rad;
    }
}

static void stage_state_machine(ps_loop_t *loop)
{
    uint32_t cond = watchdog_conditions(loop) | timer_conditions(loop);
    bool is_estop_pressed = true; /* a GPIO we cannot read counts as pressed */
    if (ps_gpio_read_estop(&loop->cfg.gpio, &is_estop_pressed) < 0)
        loop->counters.n_gpio_errors++;
    if (is_estop_pressed)
        cond |= PS_SM_C_ESTOP_INPUT;
    cond |= take_requests(loop, cond);
    if (loop->state != PS_SM_RAMP && loop->state != PS_SM_ACTIVE && loop->state != PS_SM_HOLD)
        cond &= ~(uint32_t)PS_SM_C_FALL; /* a limp robot on the floor is not news */
    else if (cond & PS_SM_C_FALL)
        loop->counters.has_fallen = true;
    loop->last.cond = cond;
    loop->last.is_estop_input = is_estop_pressed;
    bool is_button = false;
    if (ps_gpio_read_button(&loop->cfg.gpio, &is_button) < 0)
        loop->counters.n_gpio_errors++;
    loop->last.is_button_pressed = is_button;

    ps_sm_state_t next = ps_sm_next(loop->state, cond);
    if (next == loop->state)
        return;
    ps_loop_rec_t rec;
    fill_record(loop, PS_REC_TRANSITION, &rec);
    rec.from_state = (uint8_t)loop->state;
    rec.state = (uint8_t)next;
    rec.cond = cond;
    push_record(loop, &rec);
    loop->counters.n_transitions++;
    ps_trace_mark(loop->cfg.trace, "state", "from", loop->state, "to", next);
    enter_state(loop, next);
}

/* ---- SERVO and WRITE -------------------------------------------------- */

/* mode_joint: the joint whose enable/disable these frames are, or -1 for a
 * command; stage_write puts is_entered back to prev_entered when a bus
 * refused any frame of the request (once per request, however many frames
 * it had). n == 0 (a protocol that needs no frame for it) is done. The tx
 * buffer holds every joint's command frames (PS_LOOP_MAX_TX); a protocol
 * error that leaves no room is counted, never overflows. */
static bool queue_frames(ps_loop_t *loop, uint32_t bus_idx, const ps_can_frame_t *f, int n,
                         int mode_joint, bool prev_entered)
{
    if (n < 0 || loop->n_tx[bus_idx] + (uint32_t)n > PS_LOOP_MAX_TX)
        return false;
    for (int k = 0; k < n; k++) {
        const uint32_t i = loop->n_tx[bus_idx]++;
        loop->tx_buf[bus_idx][i] = f[k];
        loop->tx_mode_joint[bus_idx][i] = (int8_t)mode_joint;
        loop->tx_mode_prev[bus_idx][i] = prev_entered;
    }
    return true;
}

/* A drive reports a latched fault until it is enabled again; replies already
 * on their way when the enable goes out still carry it. So a joint's fault is
 * believed only from one reply period after its enable (at start and after an
 * e-stop reset alike); until then it cannot e-stop the robot, and START
 * waits for fresh replies anyway. */
static int64_t fault_grace_end_ns(const ps_loop_t *loop, const ps_act_cfg_t *a)
{
    return loop->t_deadline_ns + ps_s_to_ns(loop->cfg.robot->control.reply_timeout_s) +
           (int64_t)a->rate_div * loop->period_ns;
}

/* Drives need ENABLE before they obey commands and get DISABLE when the robot
 * is e-stopped, so that a reset starts from a known, disabled drive state. */
static bool queue_mode_change(ps_loop_t *loop, uint32_t j)
{
    const ps_act_cfg_t *a = &loop->cfg.robot->act[j];
    const bool want_entered = loop->state != PS_SM_ESTOP;
    if (loop->is_entered[j] == want_entered)
        return false;
    ps_can_frame_t f[PS_ACT_MAX_FRAMES];
    const int n = ps_act_encode_request(a, want_entered ? PS_ACT_REQ_ENABLE : PS_ACT_REQ_DISABLE, f,
                                        PS_ACT_MAX_FRAMES);
    if (!queue_frames(loop, a->bus_idx, f, n, (int)j, loop->is_entered[j])) {
        loop->counters.n_cmd_replaced++; /* cannot be expressed: the config check forbids it */
        return false;
    }
    loop->is_entered[j] = want_entered;
    if (want_entered)
        loop->fault_grace_until_ns[j] = fault_grace_end_ns(loop, a);
    return true;
}

/* Damping for one joint: always inside its limits (the config keeps
 * damping_kd under kd_max), the command of last resort. */
static void damping_command(const ps_servo_joint_cfg_t *sj, const ps_servo_cfg_t *c, float q_rad,
                            ps_act_cmd_t *out)
{
    memset(out, 0, sizeof(*out));
    out->q_rad = fminf(fmaxf(q_rad, sj->lim.pos_min_rad), sj->lim.pos_max_rad);
    out->kd_nm_s_rad = fminf(c->damping_kd_nm_s_rad, sj->lim.kd_max_nm_s_rad);
}

static void disable_joint(ps_loop_t *loop, uint32_t j)
{
    const ps_act_cfg_t *a = &loop->cfg.robot->act[j];
    ps_can_frame_t f[PS_ACT_MAX_FRAMES];
    const int n = ps_act_encode_request(a, PS_ACT_REQ_DISABLE, f, PS_ACT_MAX_FRAMES);
    if (queue_frames(loop, a->bus_idx, f, n, (int)j, loop->is_entered[j]))
        loop->is_entered[j] = false;
}

float ps_loop_torque_scale(const ps_control_cfg_t *c, float temp_c, float temp_max_c)
{
    const float start_c = temp_max_c - c->derate_band_c;
    const float end_c = temp_max_c - c->hot_margin_c;
    if (!(temp_c > start_c)) /* NaN too */
        return 1.0f;
    if (temp_c >= end_c)
        return c->derate_min;
    return 1.0f - (1.0f - c->derate_min) * (temp_c - start_c) / (end_c - start_c);
}

static void servo_joint(ps_loop_t *loop, uint32_t j, const ps_servo_mode_t *mode)
{
    const ps_robot_cfg_t *r = loop->cfg.robot;
    const ps_act_cfg_t *a = &r->act[j];
    /* A hot drive gets a smaller torque budget: the servo layer clamps the
     * feed-forward and the spring's reach into it (docs/safety.md). */
    ps_servo_joint_cfg_t derated = r->servo[j];
    derated.lim.torque_max_nm *=
        ps_loop_torque_scale(&r->control, loop->meas.joints[j].temp_c, a->temp_max_c);
    const ps_servo_joint_cfg_t *sj = &derated;
    ps_act_cmd_t cmd;
    if (ps_servo_command(sj, &r->servo_common, mode, j, &loop->targets, &cmd) < 0)
        loop->counters.n_target_invalid++;
    ps_can_frame_t f[PS_ACT_MAX_FRAMES];
    int n = ps_servo_is_within_limits(sj, &cmd)
                ? ps_act_encode_command(a, &cmd, f, PS_ACT_MAX_FRAMES)
                : -PS_ERR_LIMIT;
    if (n < 0) {
        /* Defence in depth: the servo layer already clamps. Brake this joint
         * and let the state machine damp the robot. */
        loop->counters.n_cmd_replaced++;
        loop->has_cmd_fault = true;
        damping_command(sj, &r->servo_common, loop->meas.joints[j].q_rad, &cmd);
        n = ps_act_encode_command(a, &cmd, f, PS_ACT_MAX_FRAMES);
        if (n < 0) {
            disable_joint(loop, j); /* cannot even damp: disable */
            return;
        }
    }
    (void)queue_frames(loop, a->bus_idx, f, n, -1, false); /* room for every joint */
    loop->last.cmd[j] = cmd;
    loop->last.is_cmd_sent[j] = true;
}

/* The servo mode of each safety state (the servo layer knows no states). */
static ps_servo_mode_kind_t servo_mode_of(const ps_loop_t *loop)
{
    switch (loop->state) {
    case PS_SM_RAMP:
        return loop->has_targets ? PS_SERVO_RAMP : PS_SERVO_DAMP;
    case PS_SM_ACTIVE:
        return loop->has_targets ? PS_SERVO_TRACK : PS_SERVO_DAMP;
    case PS_SM_HOLD:
        return PS_SERVO_HOLD;
    case PS_SM_DAMPING:
        return PS_SERVO_DAMP;
    case PS_SM_STANDBY:
    case PS_SM_ESTOP:
        return PS_SERVO_LIMP;
    default:
        return PS_SERVO_LIMP;
    }
}

static void stage_servo(ps_loop_t *loop, uint64_t tick)
{
    const ps_robot_cfg_t *r = loop->cfg.robot;
    float meas_q[PS_MAX_JOINTS];
    for (uint32_t j = 0; j < r->n_joints; j++)
        meas_q[j] = loop->meas.joints[j].q_rad;
    ps_servo_mode_t mode = {
        .kind = servo_mode_of(loop),
        .ramp_alpha = 0.0f,
        .ramp_from_q_rad = loop->ramp_from_q_rad,
        .meas_q_rad = meas_q,
        .hold_q_rad = loop->hold_q_rad,
    };
    if (loop->state == PS_SM_RAMP) {
        float alpha = (float)(loop->t_deadline_ns - loop->state_since_ns) /
                      (float)ps_s_to_ns(r->control.ramp_s);
        mode.ramp_alpha = fminf(fmaxf(alpha, 0.0f), 1.0f);
    }
    for (uint32_t b = 0; b < loop->cfg.board->n_buses; b++)
        loop->n_tx[b] = 0;
    loop->has_cmd_fault = false; /* the state machine saw last tick's */
    memset(loop->last.is_cmd_sent, 0, sizeof(loop->last.is_cmd_sent));
    for (uint32_t j = 0; j < r->n_joints; j++) {
        if (!ps_canbus_is_due(tick, r->act[j].rate_div, loop->cfg.plan->phase[j]))
            continue;
        if (!queue_mode_change(loop, j))
            servo_joint(loop, j, &mode);
    }
}

static void stage_write(ps_loop_t *loop)
{
    bool has_refused = false;
    memset(loop->last.n_tx, 0, sizeof(loop->last.n_tx));
    for (uint32_t b = 0; b < loop->cfg.board->n_buses; b++) {
        if (loop->n_tx[b] == 0)
            continue;
        int n = ps_can_send_batch(&loop->cfg.buses[b], loop->tx_buf[b], loop->n_tx[b]);
        if (n < 0) {
            loop->counters.n_bus_errors++;
            n = 0;
        }
        tap_frames(loop, b, loop->tx_buf[b], (size_t)n, true);
        loop->last.n_tx[b] = (uint16_t)n;
        loop->counters.n_tx_frames += (uint64_t)n;
        loop->counters.n_tx_refused += loop->n_tx[b] - (uint32_t)n;
        if ((uint32_t)n < loop->n_tx[b])
            has_refused = true;
        /* A refused enable/disable did not happen: send it again on the joint's
         * next due tick instead of believing the drive changed mode. */
        for (uint32_t i = (uint32_t)n; i < loop->n_tx[b]; i++) {
            int j = loop->tx_mode_joint[b][i];
            if (j >= 0)
                loop->is_entered[j] = loop->tx_mode_prev[b][i];
        }
    }
    loop->has_tx_refused = has_refused; /* TX_REFUSED for the next tick's state machine */
    /* LED: on when the controller is in charge, blinking at 2 Hz in RAMP and
     * DAMPING, 4 Hz in HOLD, 8 Hz in ESTOP, off in STANDBY. */
    static const int64_t BLINK_HALF_PERIOD_NS[PS_SM_STATE_COUNT] = {
        [PS_SM_RAMP] = 250 * PS_NS_PER_MS,
        [PS_SM_DAMPING] = 250 * PS_NS_PER_MS,
        [PS_SM_HOLD] = 125 * PS_NS_PER_MS,
        [PS_SM_ESTOP] = 62 * PS_NS_PER_MS,
    };
    ps_gpio_led_t led = loop->state == PS_SM_ACTIVE ? PS_GPIO_LED_ON : PS_GPIO_LED_OFF;
    int64_t half = BLINK_HALF_PERIOD_NS[loop->state];
    if (half > 0)
        led = ((loop->t_deadline_ns / half) & 1) ? PS_GPIO_LED_ON : PS_GPIO_LED_OFF;
    /* Heartbeat to the power relay: a new level every tick; held still in
     * ESTOP so the relay drops the drives' power (drivers/ps_gpio.h). */
    int hb_rc = loop->state == PS_SM_ESTOP
                    ? 0
                    : ps_gpio_set_heartbeat(&loop->cfg.gpio, (loop->counters.n_ticks & 1u) != 0);
    loop->last.heartbeat = loop->state == PS_SM_ESTOP ? -1 : (int8_t)(loop->counters.n_ticks & 1u);
    loop->last.led = (uint8_t)led;
    loop->has_heartbeat_fault = hb_rc < 0; /* ESTOP_INPUT for the next tick */
    if (hb_rc < 0 || ps_gpio_set_led(&loop->cfg.gpio, led) < 0)
        loop->counters.n_gpio_errors++;
}

/* ---- the tick --------------------------------------------------------- */

void ps_loop_tick(ps_loop_t *loop, int64_t deadline_ns)
{
    const ps_clock_t *clk = loop->cfg.perf_clock;
    const uint64_t tick = loop->counters.n_ticks;
    loop->t_deadline_ns = deadline_ns;
    loop->last.state_before = loop->state;
    loop->last.is_policy_run = false;

    int64_t t0 = ps_clock_now_ns(clk);
    stage_read(loop);
    int64_t t1 = ps_clock_now_ns(clk);
    ps_estimate_update(&loop->estimator, &loop->meas);
    int64_t t2 = ps_clock_now_ns(clk);
    stage_state_machine(loop);
    int64_t t2b = ps_clock_now_ns(clk);
    stage_policy(loop, tick);
    int64_t t3 = ps_clock_now_ns(clk);
    stage_servo(loop, tick);
    int64_t t4 = ps_clock_now_ns(clk);
    const uint64_t n_sent_before = loop->counters.n_tx_frames;
    stage_write(loop);
    int64_t t5 = ps_clock_now_ns(clk);
    /* Reply in to commands out, on the clock the receive stamps are on (the
     * kernel's CLOCK_MONOTONIC on SocketCAN, simulated time on the sim); only
     * on ticks that sent something. */
    if (loop->newest_reply_rx_ns > 0 && loop->counters.n_tx_frames > n_sent_before)
        ps_perf_record(&loop->perf[PS_STAGE_REACTION],
                       ps_clock_now_ns(loop->cfg.clock) - loop->newest_reply_rx_ns);

    ps_perf_record(&loop->perf[PS_STAGE_READ], t1 - t0);
    ps_perf_record(&loop->perf[PS_STAGE_ESTIMATE], t2 - t1);
    ps_perf_record(&loop->perf[PS_STAGE_SERVO], (t4 - t3) + (t2b - t2)); /* with the SM */
    ps_perf_record(&loop->perf[PS_STAGE_WRITE], t5 - t4);
    ps_perf_record(&loop->perf[PS_STAGE_TICK], t5 - t0);
    bool is_policy_tick = tick % loop->policy_div == 0;
    ps_perf_record(&loop->perf[is_policy_tick ? PS_STAGE_TICK_POLICY : PS_STAGE_TICK_PLAIN],
                   t5 - t0);
    ps_trace_mark(loop->cfg.trace, "end", "n", (int64_t)tick, "work_ns", t5 - t0);
    int64_t *st = loop->last.stage_ns;
    st[PS_STAGE_READ] = t1 - t0;
    st[PS_STAGE_ESTIMATE] = t2 - t1;
    st[PS_STAGE_POLICY] = loop->last.is_policy_run ? t3 - t2b : -1;
    st[PS_STAGE_SERVO] = (t4 - t3) + (t2b - t2);
    st[PS_STAGE_WRITE] = t5 - t4;
    st[PS_STAGE_TICK] = t5 - t0;
    loop->counters.n_ticks++;
    if (loop->cfg.status_every != 0 && tick % loop->cfg.status_every == 0) {
        ps_loop_rec_t rec;
        fill_record(loop, PS_REC_STATUS, &rec);
        push_record(loop, &rec);
    }
    if (loop->cfg.tap.on_tick != NULL) {
        const int64_t t6 = ps_clock_now_ns(clk);
        loop->cfg.tap.on_tick(loop->cfg.tap.ctx, loop);
        ps_perf_record(&loop->perf[PS_STAGE_TAP], ps_clock_now_ns(clk) - t6);
    }
}

void ps_loop_request(ps_loop_t *loop, uint32_t request_bits)
{
    atomic_fetch_or(&loop->external_requests, request_bits & PS_SM_C_REQUESTS);
}

void ps_loop_request_stop(ps_loop_t *loop)
{
    atomic_fetch_add(&loop->n_stop_requests, 1u);
}

/* Stopping (Ctrl-C, SIGTERM, end of run) is a mode, not a one-off request:
 * from the first stop on, START is refused and STOP is asked on every tick
 * the robot is in RAMP or ACTIVE, so a START accepted in the same tick as
 * the stop cannot outlive it. A stop request that arrives in a later tick
 * than the operator's first one (a second Ctrl-C while braking) asks for
 * e-stop; the end of the run is not an operator request, so one Ctrl-C
 * during its braking only confirms the stop. */
static void handle_stop_requests(ps_loop_t *loop)
{
    uint32_t n = atomic_load(&loop->n_stop_requests);
    if (n != loop->n_stops_handled) {
        bool is_second = loop->n_stops_handled > 0;
        loop->n_stops_handled = n;
        if (is_second) {
            ps_loop_request(loop, PS_SM_C_REQ_ESTOP);
            return;
        }
    }
    if (is_stopping(loop) &&
        (loop->state == PS_SM_RAMP || loop->state == PS_SM_ACTIVE || loop->state == PS_SM_HOLD))
        ps_loop_request(loop, PS_SM_C_REQ_STOP);
}

static bool is_at_rest(const ps_loop_t *loop)
{
    return loop->state == PS_SM_STANDBY || loop->state == PS_SM_ESTOP;
}

int ps_loop_start(ps_loop_t *loop, int64_t start_ns)
{
    loop->state_since_ns = start_ns;
    return ps_pacer_init(&loop->pacer, loop->cfg.clock, loop->period_ns, start_ns);
}

int ps_loop_step(ps_loop_t *loop)
{
    int64_t wake = ps_pacer_wait(&loop->pacer);
    if (wake < 0)
        return (int)wake;
    ps_perf_record(&loop->perf[PS_STAGE_WAKE], wake);
    loop->last.stage_ns[PS_STAGE_WAKE] = wake;
    ps_perf_us_record(&loop->wake_us, wake, loop->counters.n_ticks);
    ps_trace_mark(loop->cfg.trace, "tick", "n", (int64_t)loop->counters.n_ticks, "wake_ns", wake);
    handle_stop_requests(loop);
    /* With a deadline clock of its own (lockstep: the thread's CPU time) the
     * pacing clock cannot overrun; a tick that computes for a period or more
     * on the deadline clock counts as an overrun all the same. */
    const ps_clock_t *dl = loop->cfg.deadline_clock;
    const int64_t dl0_ns = dl != loop->cfg.clock ? ps_clock_now_ns(dl) : 0;
    ps_loop_tick(loop, loop->pacer.next_ns - loop->period_ns); /* this tick's deadline */
    const uint64_t n_overruns_before = loop->pacer.n_overruns;
    uint64_t missed = ps_pacer_end_tick(&loop->pacer); /* the pacer counts overruns itself */
    if (missed == 0 && dl != loop->cfg.clock && ps_clock_now_ns(dl) - dl0_ns >= loop->period_ns)
        loop->pacer.n_overruns++; /* no deadline was skipped: n_missed stays */
    if (loop->pacer.n_overruns != n_overruns_before)
        note_overrun(loop, loop->t_deadline_ns); /* for OVERRUN from the next tick on */
    if (missed != 0)
        ps_trace_mark(loop->cfg.trace, "overrun", "n", (int64_t)loop->counters.n_ticks - 1,
                      "missed", (int64_t)missed);
    return 0;
}

bool ps_loop_is_stopped(const ps_loop_t *loop)
{
    return is_stopping(loop) && is_at_rest(loop);
}

void ps_loop_release_drives(ps_loop_t *loop)
{
    const ps_robot_cfg_t *r = loop->cfg.robot;
    for (uint32_t b = 0; b < loop->cfg.board->n_buses; b++)
        loop->n_tx[b] = 0;
    for (uint32_t j = 0; j < r->n_joints; j++) {
        ps_can_frame_t f[PS_ACT_MAX_FRAMES];
        const int n = ps_act_encode_request(&r->act[j], PS_ACT_REQ_DISABLE, f, PS_ACT_MAX_FRAMES);
        if (!queue_frames(loop, r->act[j].bus_idx, f, n, -1, false))
            loop->counters.n_tx_refused++;
    }
    for (uint32_t b = 0; b < loop->cfg.board->n_buses; b++) {
        int n = ps_can_send_batch(&loop->cfg.buses[b], loop->tx_buf[b], loop->n_tx[b]);
        if (n < 0 || (uint32_t)n < loop->n_tx[b])
            loop->counters.n_tx_refused += loop->n_tx[b] - (uint32_t)(n < 0 ? 0 : n);
        if (n > 0)
            tap_frames(loop, b, loop->tx_buf[b], (size_t)n, true);
    }
    for (uint32_t j = 0; j < r->n_joints; j++)
        loop->is_entered[j] = false;
    /* The heartbeat is not written again: held still, the relay cuts power. */
    if (ps_gpio_set_led(&loop->cfg.gpio, PS_GPIO_LED_OFF) < 0)
        loop->counters.n_gpio_errors++;
}

int ps_loop_run(ps_loop_t *loop, int64_t start_ns, int64_t end_ns)
{
    int rc = ps_loop_start(loop, start_ns);
    while (rc == 0 && !ps_loop_is_stopped(loop)) {
        if (end_ns > 0 && loop->pacer.next_ns >= end_ns)
            loop->is_ending = true;
        rc = ps_loop_step(loop);
    }
    if (rc < 0) {
        /* The clock failed: no more paced ticks. One last tick, now, in
         * e-stop, so the drives are disabled and the heartbeat stops. */
        ps_loop_request(loop, PS_SM_C_REQ_ESTOP);
        ps_loop_tick(loop, ps_clock_now_ns(loop->cfg.clock));
    }
    ps_loop_release_drives(loop);
    return rc;
}

ps_sm_state_t ps_loop_get_state(const ps_loop_t *loop)
{
    return (ps_sm_state_t)atomic_load_explicit(&loop->published_state, memory_order_relaxed);
}
