/*
 * ps_servo: joint targets -> neutral joint commands, per servo mode. See
 * ps_servo.h for the contract and docs/safety.md for what each state sends.
 */
#include "ps_servo.h"

#include <math.h>
#include <stddef.h>

#include "../rt/ps_err.h"

/* The tighter of the joint's configured limits and the driver's wire range,
 * so a clamped command is both safe and encodable. */
typedef struct {
    float p_lo, p_hi;
    float v_lo, v_hi;
    float kp_hi, kd_hi;
    float t_lo, t_hi;
} limits_t;

static limits_t limits_of(const ps_servo_joint_cfg_t *j)
{
    const ps_act_limits_t *c = &j->lim;
    const limits_t l = {
        .p_lo = fmaxf(c->pos_min_rad, j->wire.p_min_rad),
        .p_hi = fminf(c->pos_max_rad, j->wire.p_max_rad),
        .v_lo = fmaxf(-c->vel_max_rad_s, j->wire.v_min_rad_s),
        .v_hi = fminf(c->vel_max_rad_s, j->wire.v_max_rad_s),
        .kp_hi = fminf(c->kp_max_nm_rad, j->wire.kp_max_nm_rad),
        .kd_hi = fminf(c->kd_max_nm_s_rad, j->wire.kd_max_nm_s_rad),
        .t_lo = fmaxf(-c->torque_max_nm, j->wire.t_min_nm),
        .t_hi = fminf(c->torque_max_nm, j->wire.t_max_nm),
    };
    return l;
}

/* Clamp into [lo, hi]; NaN maps to lo, so the result is always a number
 * inside the range (given a sane range). */
static float clampf(float x, float lo, float hi)
{
    if (!(x >= lo))
        return lo;
    if (x > hi)
        return hi;
    return x;
}

/* Set-point for commands with kp = 0: the driver ignores p then, but it
 * must still encode, so keep it where the joint is (or the stance when the
 * measurement is unusable), inside the limits. */
static float rest_position(const ps_servo_joint_cfg_t *j, const limits_t *l, float meas_q)
{
    const float p = isfinite(meas_q) ? meas_q : j->stance_rad;
    return clampf(p, l->p_lo, l->p_hi);
}

static ps_act_cmd_t limp_cmd(const ps_servo_joint_cfg_t *j, const limits_t *l, float meas_q)
{
    const ps_act_cmd_t cmd = {
        .q_rad = rest_position(j, l, meas_q),
        .qd_rad_s = clampf(0.0f, l->v_lo, l->v_hi),
        .kp_nm_rad = 0.0f,
        .kd_nm_s_rad = 0.0f,
        .tau_ff_nm = clampf(0.0f, l->t_lo, l->t_hi),
    };
    return cmd;
}

static ps_act_cmd_t damping_cmd(const ps_servo_joint_cfg_t *j, const limits_t *l,
                                const ps_servo_cfg_t *c, float meas_q)
{
    ps_act_cmd_t cmd = limp_cmd(j, l, meas_q);
    cmd.kd_nm_s_rad = clampf(c->damping_kd_nm_s_rad, 0.0f, l->kd_hi);
    return cmd;
}

/* Bound the spring torque kp * (p - q) by budget: first move p towards q
 * (within the position limits), and where that is not enough (q outside the
 * limits, or float rounding) lower kp. */
static void limit_spring_torque(const limits_t *l, float q, float budget, float *p, float *kp)
{
    if (!(*kp > 0.0f))
        return;
    const float window = budget / *kp;
    *p = clampf(*p, q - window, q + window);
    *p = clampf(*p, l->p_lo, l->p_hi);
    const float err = fabsf(*p - q);
    if (*kp * err > budget)
        *kp = budget / err; /* err > 0 here, since budget >= 0 */
}

/* The set-point for RAMP, TRACK and HOLD, before clamping. */
typedef struct {
    float p, v, tau, kp;
} setpoint_t;

static setpoint_t hold_setpoint(const ps_servo_joint_cfg_t *j, const ps_servo_mode_t *mode,
                                unsigned joint_idx)
{
    float p = j->stance_rad;
    if (mode->hold_q_rad != NULL && isfinite(mode->hold_q_rad[joint_idx]))
        p = mode->hold_q_rad[joint_idx];
    return (setpoint_t){.p = p, .v = 0.0f, .tau = 0.0f, .kp = j->kp_nm_rad};
}

static ps_act_cmd_t clamped_command(const ps_servo_joint_cfg_t *j, const limits_t *l, float q,
                                    const setpoint_t *sp)
{
    ps_act_cmd_t cmd = {
        .q_rad = clampf(sp->p, l->p_lo, l->p_hi),
        .qd_rad_s = clampf(sp->v, l->v_lo, l->v_hi),
        .kp_nm_rad = clampf(sp->kp, 0.0f, l->kp_hi),
        .kd_nm_s_rad = clampf(j->kd_nm_s_rad, 0.0f, l->kd_hi), /* full damping in RAMP too */
        .tau_ff_nm = clampf(sp->tau, l->t_lo, l->t_hi),
    };
    float budget = j->lim.torque_max_nm - fabsf(cmd.tau_ff_nm);
    if (!(budget > 0.0f))
        budget = 0.0f;
    limit_spring_torque(l, q, budget, &cmd.q_rad, &cmd.kp_nm_rad);
    return cmd;
}

int ps_servo_command(const ps_servo_joint_cfg_t *j, const ps_servo_cfg_t *c,
                     const ps_servo_mode_t *mode, unsigned joint_idx, const ps_targets_t *t,
                     ps_act_cmd_t *out)
{
    if (j == NULL || out == NULL)
        return -EINVAL;
    const limits_t l = limits_of(j);
    if (mode == NULL || mode->meas_q_rad == NULL || joint_idx >= PS_MAX_JOINTS || c == NULL) {
        *out = limp_cmd(j, &l, NAN);
        return -EINVAL;
    }
    const float q = mode->meas_q_rad[joint_idx];

    switch (mode->kind) {
    case PS_SERVO_LIMP:
        *out = limp_cmd(j, &l, q);
        return 0;
    case PS_SERVO_DAMP:
        *out = damping_cmd(j, &l, c, q);
        return 0;
    case PS_SERVO_HOLD:
        if (!isfinite(q)) {
            *out = damping_cmd(j, &l, c, q);
            return -PS_ERR_LIMIT;
        } else {
            const setpoint_t sp = hold_setpoint(j, mode, joint_idx);
            *out = clamped_command(j, &l, q, &sp);
        }
        return 0;
    case PS_SERVO_RAMP:
    case PS_SERVO_TRACK:
        break;
    default:
        *out = limp_cmd(j, &l, q); /* corrupted mode: the loop's state machine says ESTOP */
        return -EINVAL;
    }

    /* From here on every failure falls back to damping: the drives brake
     * the robot down while the state machine reacts to TARGET_INVALID. */
    if (t == NULL) {
        *out = damping_cmd(j, &l, c, q);
        return -EINVAL;
    }
    if (joint_idx >= t->n_joints || !isfinite(q)) {
        *out = damping_cmd(j, &l, c, q);
        return -PS_ERR_LIMIT;
    }
    const float target_q = t->q_rad[joint_idx];
    const float target_qd = t->qd_rad_s[joint_idx];
    const float target_tau = t->tau_ff_nm[joint_idx];
    if (!isfinite(target_q) || !isfinite(target_qd) || !isfinite(target_tau) || target_q < l.p_lo ||
        target_q > l.p_hi) {
        *out = damping_cmd(j, &l, c, q);
        return -PS_ERR_LIMIT;
    }

    setpoint_t sp = {.p = target_q, .v = target_qd, .tau = target_tau, .kp = j->kp_nm_rad};
    if (mode->kind == PS_SERVO_RAMP) {
        const float a = isfinite(mode->ramp_alpha) ? clampf(mode->ramp_alpha, 0.0f, 1.0f) : 0.0f;
        float from = q;
        if (mode->ramp_from_q_rad != NULL && isfinite(mode->ramp_from_q_rad[joint_idx]))
            from = mode->ramp_from_q_rad[joint_idx];
        sp.p = from + a * (target_q - from);
        sp.kp *= a;
        sp.v *= a;
        sp.tau *= a;
    }
    *out = clamped_command(j, &l, q, &sp);
    return 0;
}

bool ps_servo_is_within_limits(const ps_servo_joint_cfg_t *j, const ps_act_cmd_t *cmd)
{
    if (j == NULL || cmd == NULL)
        return false;
    if (!isfinite(cmd->q_rad) || !isfinite(cmd->qd_rad_s) || !isfinite(cmd->kp_nm_rad) ||
        !isfinite(cmd->kd_nm_s_rad) || !isfinite(cmd->tau_ff_nm))
        return false;
    const limits_t l = limits_of(j);
    return cmd->q_rad >= l.p_lo && cmd->q_rad <= l.p_hi && cmd->qd_rad_s >= l.v_lo &&
           cmd->qd_rad_s <= l.v_hi && cmd->kp_nm_rad >= 0.0f && cmd->kp_nm_rad <= l.kp_hi &&
           cmd->kd_nm_s_rad >= 0.0f && cmd->kd_nm_s_rad <= l.kd_hi && cmd->tau_ff_nm >= l.t_lo &&
           cmd->tau_ff_nm <= l.t_hi;
}

const char *ps_servo_mode_name(ps_servo_mode_kind_t kind)
{
    static const char *const NAMES[PS_SERVO_MODE_COUNT] = {
        [PS_SERVO_LIMP] = "limp",   [PS_SERVO_DAMP] = "damp", [PS_SERVO_RAMP] = "ramp",
        [PS_SERVO_TRACK] = "track", [PS_SERVO_HOLD] = "hold",
    };
    return ((unsigned)kind < PS_SERVO_MODE_COUNT) ? NAMES[kind] : "?";
}
