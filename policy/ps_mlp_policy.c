#include "ps_mlp_policy.h"

#include <errno.h>
#include <math.h>
#include <string.h>

static const char *const LEG[2][PS_LEG_N_JOINTS] = {
    {"l_hip_yaw", "l_hip_roll", "l_hip_pitch", "l_knee", "l_ankle_pitch", "l_ankle_roll"},
    {"r_hip_yaw", "r_hip_roll", "r_hip_pitch", "r_knee", "r_ankle_pitch", "r_ankle_roll"},
};

#define FALLBACK_HOLD_S 1.0f

int ps_mlp_policy_init(ps_mlp_policy_t *p, ps_weights_t *w, uint32_t n_joints,
                       const char (*joint_name)[PS_NAME_LEN], const ps_servo_joint_cfg_t *joints,
                       const ps_kinematics_cfg_t *kin, float dt_s, ps_policy_t fallback,
                       const ps_clock_t *clock, int64_t late_ns)
{
    if (p == NULL || w == NULL || joint_name == NULL || joints == NULL || kin == NULL ||
        fallback.ops == NULL || n_joints != w->contract.n_joints || !(dt_s > 0.0f))
        return -EINVAL;
    const ps_weights_contract_t *c = &w->contract;
    ps_obs_cfg_t oc;
    memset(&oc, 0, sizeof(oc));
    oc.n_fields = c->n_fields;
    memcpy(oc.fields, c->fields, sizeof(oc.fields));
    oc.n_joints = c->n_joints;
    oc.n_act = c->n_act;
    for (uint32_t j = 0; j < c->n_joints; j++) {
        oc.joint_idx[j] = j; /* checked: the contract's order is the robot's */
        oc.joint_offset_rad[j] = c->stance_rad[j];
    }
    memcpy(oc.mean, c->obs_mean, sizeof(oc.mean));
    memcpy(oc.std, c->obs_std, sizeof(oc.std));
    oc.clip = c->obs_clip;
    oc.kin = *kin;
    oc.dt_s = dt_s;
    for (int s = 0; s < 2; s++)
        for (int j = 0; j < PS_LEG_N_JOINTS; j++) {
            oc.leg_idx[s][j] = -1;
            for (uint32_t i = 0; i < n_joints; i++)
                if (strncmp(joint_name[i], LEG[s][j], PS_NAME_LEN) == 0)
                    oc.leg_idx[s][j] = (int)i;
            if (oc.leg_idx[s][j] < 0)
                return -ENOENT;
        }
    memset(p, 0, sizeof(*p));
    const int rc = ps_obs_init(&p->obs, &oc);
    if (rc != 0 || p->obs.n_obs != w->mlp.n_in)
        return -EINVAL;
    p->w = w;
    p->joints = joints;
    p->n_joints = n_joints;
    p->fallback = fallback;
    p->clock = clock;
    p->late_ns = late_ns;
    p->first_fallback_t_ns = -1;
    p->fallback_hold_s = FALLBACK_HOLD_S;
    p->dt_s = dt_s;
    return 0;
}

static float clampf(float x, float lo, float hi)
{
    return x < lo ? lo : (x > hi ? hi : x);
}

/* The action added to action a: 0, or for a residual policy the capture
 * controller's (base; NULL when it had none this step), in action units and
 * clipped, as training's environment adds it (tools/psenv). */
static float base_action(const ps_mlp_policy_t *p, const ps_targets_t *base, uint32_t a)
{
    const ps_weights_contract_t *c = &p->w->contract;
    if (c->act_base != PS_WEIGHTS_BASE_CAPTURE)
        return 0.0f;
    const uint32_t j = c->act_joint[a];
    return clampf((base->q_rad[j] - c->stance_rad[j]) / c->act_scale[a], -c->act_clip, c->act_clip);
}

/* The MLP's targets; the fault bits when it misbehaves (targets then unused).
 * base: the fallback's targets this step, NULL when it failed. */
static uint32_t run_mlp(ps_mlp_policy_t *p, const ps_meas_t *meas, const ps_estimate_t *est,
                        const ps_targets_t *base, ps_targets_t *t)
{
    const ps_weights_contract_t *c = &p->w->contract;
    const int64_t t0 = p->clock != NULL ? ps_clock_now_ns(p->clock) : 0;
    uint32_t faults = 0;
    /* a residual without its base (the capture controller found no support)
     * counts as no observation: the same condition stops the builder */
    const bool has_base = base != NULL || c->act_base != PS_WEIGHTS_BASE_CAPTURE;
    float base_act[PS_MAX_JOINTS] = {0}; /* this step's base, action units */
    for (uint32_t a = 0; has_base && a < c->n_act; a++)
        base_act[a] = base_action(p, base, a);
    /* known before the build: the observation's base_action field */
    ps_obs_set_base_action(&p->obs, base_act);
    if (!has_base || est == NULL || ps_obs_build(&p->obs, meas, est, p->in, NULL) < 0)
        faults |= PS_MLP_FAULT_OBS;
    if (faults == 0 && ps_mlp_forward(&p->w->mlp, p->in, NULL, p->act) != 0)
        faults |= PS_MLP_FAULT_NAN;
    for (uint32_t a = 0; faults == 0 && a < c->n_act; a++) {
        if (!isfinite(p->act[a]))
            faults |= PS_MLP_FAULT_NAN;
        else if (fabsf(p->act[a]) > c->act_clip)
            faults |= PS_MLP_FAULT_RANGE;
    }
    if (p->clock != NULL && ps_clock_now_ns(p->clock) - t0 > p->late_ns)
        faults |= PS_MLP_FAULT_LATE;
    if (faults != 0)
        return faults;
    memset(t, 0, sizeof(*t));
    t->n_joints = p->n_joints;
    for (uint32_t j = 0; j < p->n_joints; j++)
        t->q_rad[j] = p->joints[j].stance_rad;
    for (uint32_t a = 0; a < c->n_act; a++) {
        const uint32_t j = c->act_joint[a];
        const ps_act_limits_t *l = &p->joints[j].lim;
        /* the action applied, also the observation's previous action */
        p->applied[a] = clampf(base_act[a] + p->act[a], -c->act_clip, c->act_clip);
        t->q_rad[j] = clampf(c->stance_rad[j] + c->act_scale[a] * p->applied[a], l->pos_min_rad,
                             l->pos_max_rad);
    }
    ps_obs_set_action(&p->obs, p->applied);
    return 0;
}

static int mlp_step(void *ctx, const ps_meas_t *meas, const ps_estimate_t *est, ps_targets_t *out)
{
    ps_mlp_policy_t *p = ctx;
    if (p == NULL || meas == NULL || out == NULL)
        return -EINVAL;
    p->n_steps++;
    /* The fallback runs every step, so it is current when it takes over. */
    ps_targets_t fb;
    const int fb_rc = p->fallback.ops->step(p->fallback.ctx, meas, est, &fb);
    if (p->is_fallback) {
        p->fallback_left_s -= p->dt_s;
        if (p->fallback_left_s <= 0.0f) {
            p->is_fallback = false;
            ps_obs_reset(&p->obs);
        }
    }
    if (!p->is_fallback) {
        ps_targets_t t;
        const uint32_t faults = run_mlp(p, meas, est, fb_rc == 0 ? &fb : NULL, &t);
        p->last_faults = faults;
        if (faults == 0) {
            *out = t;
            return 0;
        }
        p->n_obs_faults += (faults & PS_MLP_FAULT_OBS) != 0;
        p->n_nan += (faults & PS_MLP_FAULT_NAN) != 0;
        p->n_range += (faults & PS_MLP_FAULT_RANGE) != 0;
        p->n_late += (faults & PS_MLP_FAULT_LATE) != 0;
        if (p->first_fallback_t_ns < 0)
            p->first_fallback_t_ns = meas->imu.t_ns;
        p->is_fallback = true;
        p->fallback_left_s = p->fallback_hold_s;
    }
    p->n_fallback_steps++;
    if (fb_rc == 0)
        *out = fb;
    return fb_rc;
}

static void mlp_reset(void *ctx)
{
    ps_mlp_policy_t *p = ctx;
    if (p == NULL)
        return;
    ps_obs_reset(&p->obs);
    p->is_fallback = false;
    p->fallback_left_s = 0.0f;
    p->fallback.ops->reset(p->fallback.ctx);
}

static const ps_policy_ops_t MLP_OPS = {
    .name = "mlp",
    .step = mlp_step,
    .reset = mlp_reset,
};

void ps_mlp_policy_as_policy(ps_mlp_policy_t *p, ps_policy_t *out)
{
    out->ops = &MLP_OPS;
    out->ctx = p;
}
