/*
 * ps_stand: stance hold plus an ankle strategy, in the policy slot.
 *
 * Sign of the ankle correction (axes in docs/estimation.md). Positive trunk
 * pitch is a right-hand rotation about +y, which tips the trunk's top toward
 * +x: a forward lean. For a body leaning rigidly forward by theta over a flat
 * foot, the ankle pitch angle is q = -theta (foot = shank * Ry(q) must stay
 * level). The servo applies tau = kp (q_target - q) to the foot; its reaction
 * on the shank is -tau about +y, i.e. it rotates the body backward when
 * tau > 0. So to push a forward-leaning body back the target must go UP:
 * correction_pitch = +k_tilt * pitch + k_com * (com_x - support_x). The same
 * argument about +x: positive roll tips the top toward -y, and a CoM left of
 * the support (+y) is the same situation as negative roll, hence
 * correction_roll = +k_tilt * roll - k_com * (com_y - support_y).
 * (A "-k_tilt * pitch" term would subtract from the servo's own restoring
 * stiffness: kp (1 - k_tilt) instead of kp (1 + k_tilt).)
 *
 * The support centre is the centre of the base of support, the mean of the
 * contact soles, as the Push-and-Step seed paper sets its CoM target
 * (seed 000_caaeae2d90dfe8b5.txt, "2. Stage 1: Encoding
 * Biomechanical Balance Principles into Rewards": "The target CoM is set at
 * the center of the BoS at a resting height").
 *
 * A CoM velocity term, k_vel * com_vel, damps the whole-body sway (period
 * about 2 s on ps1) that joint damping cannot reach; its sign follows the
 * position term's.
 *
 * Default gains, chosen by measurement in the lockstep simulation (ps1,
 * scenarios stand and push, plus 80 N pushes; the sweep is in
 * docs/estimation.md): k_tilt = 0.5, k_vel = 0.25 rad per m/s, k_com = 0.
 * The CoM position term is off by default because the lumped-CoM estimate
 * is biased on ps1 (4.8 cm behind the sole centres at the stance): with
 * k_com = 1 the robot leans on that bias and falls under pushes that it
 * survives without the term. Tilt and velocity carry no such bias.
 */
#include "ps_stand.h"

#include <math.h>
#include <string.h>

#include "../rt/ps_err.h"

static int find_joint(const char (*names)[PS_NAME_LEN], uint32_t n, const char *name)
{
    for (uint32_t i = 0; i < n; i++) {
        if (strncmp(names[i], name, PS_NAME_LEN) == 0)
            return (int)i;
    }
    return -1;
}

int ps_stand_init(ps_stand_t *st, uint32_t n_joints, const char (*joint_name)[PS_NAME_LEN],
                  const ps_servo_joint_cfg_t *joints)
{
    if (!st || !joint_name || !joints || n_joints == 0 || n_joints > PS_MAX_JOINTS)
        return -EINVAL;
    memset(st, 0, sizeof(*st));
    st->n_joints = n_joints;
    st->joints = joints;
    st->idx_ankle_pitch[0] = find_joint(joint_name, n_joints, "l_ankle_pitch");
    st->idx_ankle_pitch[1] = find_joint(joint_name, n_joints, "r_ankle_pitch");
    st->idx_ankle_roll[0] = find_joint(joint_name, n_joints, "l_ankle_roll");
    st->idx_ankle_roll[1] = find_joint(joint_name, n_joints, "r_ankle_roll");
    st->k_tilt = PS_STAND_K_TILT_DEFAULT;
    st->k_com = PS_STAND_K_COM_DEFAULT;
    st->k_vel = PS_STAND_K_VEL_DEFAULT;
    return 0;
}

static float clampf(float x, float lo, float hi)
{
    return x < lo ? lo : (x > hi ? hi : x);
}

/* Ankle corrections from the estimate; both zero when the estimate cannot be
 * trusted (missing, non-finite, fallen): then the stance is held as is. */
static void ankle_correction(const ps_stand_t *st, const ps_estimate_t *est, float *out_pitch_rad,
                             float *out_roll_rad)
{
    *out_pitch_rad = 0.0f;
    *out_roll_rad = 0.0f;
    if (!est || est->is_fallen)
        return;
    /* Support centre: mean of the contact soles (both if none reported). */
    float sx = 0.0f, sy = 0.0f;
    int n = 0;
    for (int s = 0; s < 2; s++) {
        if (est->is_contact[s]) {
            sx += est->foot_m[s][0];
            sy += est->foot_m[s][1];
            n++;
        }
    }
    if (n == 0) {
        sx = est->foot_m[0][0] + est->foot_m[1][0];
        sy = est->foot_m[0][1] + est->foot_m[1][1];
        n = 2;
    }
    sx /= (float)n;
    sy /= (float)n;
    const float cp = st->k_tilt * est->pitch_rad + st->k_com * (est->com_m[0] - sx) +
                     st->k_vel * est->com_vel_m_s[0];
    const float cr = st->k_tilt * est->roll_rad - st->k_com * (est->com_m[1] - sy) -
                     st->k_vel * est->com_vel_m_s[1];
    if (!isfinite(cp) || !isfinite(cr))
        return; /* NaN anywhere in the inputs or gains: fall back to stance */
    *out_pitch_rad = clampf(cp, -PS_STAND_CORR_MAX_RAD, PS_STAND_CORR_MAX_RAD);
    *out_roll_rad = clampf(cr, -PS_STAND_CORR_MAX_RAD, PS_STAND_CORR_MAX_RAD);
}

static void add_target(const ps_servo_joint_cfg_t *j, float *q, float delta_rad)
{
    float v = *q + delta_rad;
    if (j->lim.pos_min_rad < j->lim.pos_max_rad)
        v = clampf(v, j->lim.pos_min_rad, j->lim.pos_max_rad);
    *q = v;
}

static int stand_step(void *ctx, const ps_meas_t *meas, const ps_estimate_t *est, ps_targets_t *out)
{
    (void)meas; /* everything needed is in the estimate */
    const ps_stand_t *st = ctx;
    if (!st || !st->joints || !out)
        return -EINVAL;
    const uint32_t n = st->n_joints;
    if (n == 0 || n > PS_MAX_JOINTS)
        return -EINVAL;

    ps_targets_t t;
    memset(&t, 0, sizeof(t));
    t.n_joints = n;
    for (uint32_t i = 0; i < n; i++)
        t.q_rad[i] = st->joints[i].stance_rad;

    float cp = 0.0f, cr = 0.0f;
    ankle_correction(st, est, &cp, &cr);
    for (int s = 0; s < 2; s++) {
        const int ip = st->idx_ankle_pitch[s], ir = st->idx_ankle_roll[s];
        if (ip >= 0 && (uint32_t)ip < n)
            add_target(&st->joints[ip], &t.q_rad[ip], cp);
        if (ir >= 0 && (uint32_t)ir < n)
            add_target(&st->joints[ir], &t.q_rad[ir], cr);
    }

    for (uint32_t i = 0; i < t.n_joints; i++) {
        if (!isfinite(t.q_rad[i]))
            return -PS_ERR_LIMIT; /* only a non-finite stance_rad gets here */
    }
    *out = t;
    return 0;
}

static void stand_reset(void *ctx)
{
    (void)ctx; /* stateless: nothing filtered or integrated */
}

static const ps_policy_ops_t STAND_OPS = {
    .name = "stand",
    .step = stand_step,
    .reset = stand_reset,
};

void ps_stand_as_policy(ps_stand_t *st, ps_policy_t *out)
{
    out->ops = &STAND_OPS;
    out->ctx = st;
}
