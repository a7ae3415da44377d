/*
 * ps_servo: joint targets -> MIT-mode commands, per safety state. See
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

static limits_t limits_of(const ps_joint_cfg_t *j)
{
    const limits_t l = {
        .p_lo = fmaxf(j->pos_min_rad, j->wire.p_min_rad),
        .p_hi = fminf(j->pos_max_rad, j->wire.p_max_rad),
        .v_lo = fmaxf(-j->vel_max_rad_s, j->wire.v_min_rad_s),
        .v_hi = fminf(j->vel_max_rad_s, j->wire.v_max_rad_s),
        .kp_hi = fminf(j->kp_max_nm_rad, j->wire.kp_max_nm_rad),
        .kd_hi = fminf(j->kd_max_nm_s_rad, j->wire.kd_max_nm_s_rad),
        .t_lo = fmaxf(-j->torque_max_nm, j->wire.t_min_nm),
        .t_hi = fminf(j->torque_max_nm, j->wire.t_max_nm),
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
static float rest_position(const ps_joint_cfg_t *j, const limits_t *l, float meas_q)
{
    const float p = isfinite(meas_q) ? meas_q : j->stance_rad;
    return clampf(p, l->p_lo, l->p_hi);
}

static ps_mit_cmd_t limp_cmd(const ps_joint_cfg_t *j, const limits_t *l, float meas_q)
{
    const ps_mit_cmd_t cmd = {
        .p_rad = rest_position(j, l, meas_q),
        .v_rad_s = clampf(0.0f, l->v_lo, l->v_hi),
        .kp_nm_rad = 0.0f,
        .kd_nm_s_rad = 0.0f,
        .t_ff_nm = clampf(0.0f, l->t_lo, l->t_hi),
    };
    return cmd;
}

static ps_mit_cmd_t damping_cmd(const ps_joint_cfg_t *j, const limits_t *l,
                                const ps_control_cfg_t *c, float meas_q)
{
    ps_mit_cmd_t cmd = limp_cmd(j, l, meas_q);
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

/* LSB of a field packed into `bits` over [lo, hi]. */
static float lsb(float lo, float hi, unsigned bits)
{
    return (hi - lo) / (float)((1u << bits) - 1u);
}

/* The MIT special frames (FF FF FF FF FF FF FF FC..FE) are p, v, kp and kd at
 * their packed maxima with t near its maximum: a set-point there would be read
 * as a mode change, and ps_mit_encode_cmd refuses it. Only a joint whose
 * limits reach the wire maxima can get there; if a command is within one LSB
 * of that corner (a conservative float test, ignoring t), step kd down two
 * LSB, which changes the damping by 0.05 % of its range. */
static void avoid_special_frame(const ps_mit_range_t *w, ps_mit_cmd_t *cmd)
{
    if (cmd->p_rad >= w->p_max_rad - lsb(w->p_min_rad, w->p_max_rad, PS_MIT_P_BITS) &&
        cmd->v_rad_s >= w->v_max_rad_s - lsb(w->v_min_rad_s, w->v_max_rad_s, PS_MIT_V_BITS) &&
        cmd->kp_nm_rad >= w->kp_max_nm_rad - lsb(0.0f, w->kp_max_nm_rad, PS_MIT_KP_BITS) &&
        cmd->kd_nm_s_rad >= w->kd_max_nm_s_rad - lsb(0.0f, w->kd_max_nm_s_rad, PS_MIT_KD_BITS))
        cmd->kd_nm_s_rad =
            w->kd_max_nm_s_rad - 2.0f * lsb(0.0f, w->kd_max_nm_s_rad, PS_MIT_KD_BITS);
}

int ps_servo_command(const ps_joint_cfg_t *j, const ps_control_cfg_t *c,
                     const ps_servo_mode_t *mode, unsigned joint_idx, const ps_targets_t *t,
                     ps_mit_cmd_t *out)
{
    if (j == NULL || out == NULL)
        return -EINVAL;
    const limits_t l = limits_of(j);
    if (mode == NULL || mode->meas_q_rad == NULL || joint_idx >= PS_MAX_JOINTS || c == NULL) {
        *out = limp_cmd(j, &l, NAN);
        return -EINVAL;
    }
    const float q = mode->meas_q_rad[joint_idx];

    switch (mode->state) {
    case PS_SM_STANDBY:
    case PS_SM_ESTOP:
        *out = limp_cmd(j, &l, q);
        return 0;
    case PS_SM_DAMPING:
        *out = damping_cmd(j, &l, c, q);
        return 0;
    case PS_SM_RAMP:
    case PS_SM_ACTIVE:
        break;
    default:
        *out = limp_cmd(j, &l, q); /* corrupted state: the state machine says ESTOP */
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

    float p = target_q;
    float v = target_qd;
    float tau = target_tau;
    float kp = j->kp_nm_rad;
    const float kd = j->kd_nm_s_rad; /* full damping in RAMP too: see header */
    if (mode->state == PS_SM_RAMP) {
        const float a = isfinite(mode->ramp_alpha) ? clampf(mode->ramp_alpha, 0.0f, 1.0f) : 0.0f;
        float from = q;
        if (mode->ramp_from_q_rad != NULL && isfinite(mode->ramp_from_q_rad[joint_idx]))
            from = mode->ramp_from_q_rad[joint_idx];
        p = from + a * (target_q - from);
        kp *= a;
        v *= a;
        tau *= a;
    }

    ps_mit_cmd_t cmd = {
        .p_rad = clampf(p, l.p_lo, l.p_hi),
        .v_rad_s = clampf(v, l.v_lo, l.v_hi),
        .kp_nm_rad = clampf(kp, 0.0f, l.kp_hi),
        .kd_nm_s_rad = clampf(kd, 0.0f, l.kd_hi),
        .t_ff_nm = clampf(tau, l.t_lo, l.t_hi),
    };
    float budget = j->torque_max_nm - fabsf(cmd.t_ff_nm);
    if (!(budget > 0.0f))
        budget = 0.0f;
    limit_spring_torque(&l, q, budget, &cmd.p_rad, &cmd.kp_nm_rad);
    avoid_special_frame(&j->wire, &cmd);
    *out = cmd;
    return 0;
}

bool ps_servo_is_within_limits(const ps_joint_cfg_t *j, const ps_mit_cmd_t *cmd)
{
    if (j == NULL || cmd == NULL)
        return false;
    if (!isfinite(cmd->p_rad) || !isfinite(cmd->v_rad_s) || !isfinite(cmd->kp_nm_rad) ||
        !isfinite(cmd->kd_nm_s_rad) || !isfinite(cmd->t_ff_nm))
        return false;
    const limits_t l = limits_of(j);
    return cmd->p_rad >= l.p_lo && cmd->p_rad <= l.p_hi && cmd->v_rad_s >= l.v_lo &&
           cmd->v_rad_s <= l.v_hi && cmd->kp_nm_rad >= 0.0f && cmd->kp_nm_rad <= l.kp_hi &&
           cmd->kd_nm_s_rad >= 0.0f && cmd->kd_nm_s_rad <= l.kd_hi && cmd->t_ff_nm >= l.t_lo &&
           cmd->t_ff_nm <= l.t_hi;
}
