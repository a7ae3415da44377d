#include "ps_capture.h"

#include <errno.h>
#include <math.h>
#include <string.h>

#include "../rt/ps_err.h"
#include "ps_legik.h"
#include "ps_stand.h"

#define VEL_TAU_S       0.03f /* CoM velocity low-pass time constant */
#define HEIGHT_RATE_M_S 0.1f  /* fastest change of the pelvis height target */

static const char *const LEG[2][PS_LEG_N_JOINTS] = {
    {"l_hip_yaw", "l_hip_roll", "l_hip_pitch", "l_knee", "l_ankle_pitch", "l_ankle_roll"},
    {"r_hip_yaw", "r_hip_roll", "r_hip_pitch", "r_knee", "r_ankle_pitch", "r_ankle_roll"},
};

const char *ps_capture_phase_name(ps_capture_phase_t p)
{
    return p == PS_CAPTURE_SWING ? "swing" : (p == PS_CAPTURE_SETTLE ? "settle" : "stand");
}

static float clampf(float x, float lo, float hi)
{
    return x < lo ? lo : (x > hi ? hi : x);
}

int ps_capture_init(ps_capture_t *c, uint32_t n_joints, const char (*joint_name)[PS_NAME_LEN],
                    const ps_servo_joint_cfg_t *joints, const ps_kinematics_cfg_t *kin,
                    float dt_s)
{
    if (c == NULL || joint_name == NULL || joints == NULL || kin == NULL || n_joints == 0 ||
        n_joints > PS_MAX_JOINTS || !(dt_s > 0.0f) || !ps_balance_has_mass_model(kin))
        return -EINVAL;
    int idx[2][PS_LEG_N_JOINTS];
    for (int s = 0; s < 2; s++)
        for (int j = 0; j < PS_LEG_N_JOINTS; j++) {
            idx[s][j] = -1;
            for (uint32_t i = 0; i < n_joints; i++)
                if (strncmp(joint_name[i], LEG[s][j], PS_NAME_LEN) == 0)
                    idx[s][j] = (int)i;
            if (idx[s][j] < 0)
                return -ENOENT;
        }
    memset(c, 0, sizeof(*c));
    c->n_joints = n_joints;
    c->joints = joints;
    c->kin = *kin;
    memcpy(c->leg_idx, idx, sizeof(idx));
    c->dt_s = dt_s;
    for (int s = 0; s < 2; s++) {
        float q[PS_LEG_N_JOINTS];
        for (int j = 0; j < PS_LEG_N_JOINTS; j++)
            q[j] = joints[idx[s][j]].stance_rad;
        ps_estimate_leg_fk(kin, s, q, c->stance_sole_m[s]);
    }
    c->height_m = -0.5f * (c->stance_sole_m[0][2] + c->stance_sole_m[1][2]);
    c->p = (ps_capture_params_t){
        .swing_s = 0.15f,
        .settle_s = 0.2f,
        .lift_m = 0.04f,
        .trigger_margin_m = 0.0f,
        .step_offset_m = 0.04f,
        .max_step_m = 0.30f,
        .min_width_m = 0.14f,
        .k_tilt = PS_STAND_K_TILT_DEFAULT,
        .k_vel = PS_STAND_K_VEL_DEFAULT,
        .k_com = 0.5f,
        .lookahead_s = 0.0f,
        .max_load_frac = 0.95f,
        .reach_frac = 0.92f,
        .swing_follows_trunk = true,
    };
    return 0;
}

/* Mass-model CoM in the trunk (pelvis) frame and the soles there (FK). */
static int trunk_frame(const ps_capture_t *c, const ps_meas_t *m, float out_com[3],
                       float out_soles[2][3], float out_rot[2][3][3])
{
    float q[2][PS_LEG_N_JOINTS];
    for (int s = 0; s < 2; s++)
        for (int j = 0; j < PS_LEG_N_JOINTS; j++) {
            const uint32_t i = (uint32_t)c->leg_idx[s][j];
            q[s][j] = i < m->n_joints ? m->joints[i].q_rad : NAN;
        }
    ps_balance_point_t p[PS_BALANCE_N_POINTS];
    if (ps_balance_points(&c->kin, (const float(*)[PS_LEG_N_JOINTS])q, p) < 0 ||
        ps_balance_com(p, PS_BALANCE_N_POINTS, out_com) != 0)
        return -EINVAL;
    for (int s = 0; s < 2; s++)
        ps_estimate_leg_fk_pose(&c->kin, s, q[s], out_soles[s], NULL, out_rot[s]);
    return isfinite(out_com[0]) && isfinite(out_com[1]) && isfinite(out_com[2]) ? 0 : -EINVAL;
}

static void to_ground(const ps_estimate_t *est, const float p[3], float out[3])
{
    for (int a = 0; a < 3; a++)
        out[a] = est->pelvis_m[a] + est->pelvis_rot[a][0] * p[0] + est->pelvis_rot[a][1] * p[1] +
                 est->pelvis_rot[a][2] * p[2];
}

/* CoM velocity over the ground by leg odometry against the soles in contact
 * at both ticks (ps_balance_com_velocity_odometry), low-passed. */
static void com_velocity(ps_capture_t *c, const ps_meas_t *m, const ps_estimate_t *est,
                         const float com_p[3], const float soles_p[2][3])
{
    float v[3] = {0, 0, 0};
    int n = 0;
    for (int s = 0; s < 2 && c->has_prev; s++) {
        if (!est->is_contact[s] || !c->prev_contact[s])
            continue;
        float vs[3];
        if (ps_balance_com_velocity_odometry(com_p, c->prev_com_m, soles_p[s],
                                             c->prev_feet_m[s], m->imu.gyro_body_rad_s,
                                             (const float(*)[3])est->pelvis_rot, c->dt_s,
                                             vs) != 0)
            continue;
        for (int a = 0; a < 3; a++)
            v[a] += vs[a];
        n++;
    }
    const float alpha = c->dt_s / (VEL_TAU_S + c->dt_s);
    for (int a = 0; a < 3 && n > 0; a++) {
        const float va = v[a] / (float)n;
        c->com_vel_m_s[a] = isfinite(va) ? c->com_vel_m_s[a] + alpha * (va - c->com_vel_m_s[a])
                                         : c->com_vel_m_s[a];
    }
    if (!c->has_prev)
        memset(c->com_vel_m_s, 0, sizeof(c->com_vel_m_s));
    memcpy(c->prev_com_m, com_p, 3 * sizeof(float));
    memcpy(c->prev_feet_m, soles_p, sizeof(c->prev_feet_m));
    c->prev_contact[0] = est->is_contact[0];
    c->prev_contact[1] = est->is_contact[1];
    c->has_prev = true;
}

/* (x, y) turned by angle a about z. */
static void rot2(float a, const float in[2], float out[2])
{
    const float ca = cosf(a), sa = sinf(a);
    const float x = ca * in[0] - sa * in[1], y = sa * in[0] + ca * in[1];
    out[0] = x;
    out[1] = y;
}

static float omega0(const ps_capture_t *c)
{
    const float z = c->com_m[2] > 0.2f ? c->com_m[2] : 0.2f;
    return sqrtf(PS_ESTIMATE_G_M_S2 / z);
}

/* Step target of the swing foot, from the stance sole (ground axes). */
static void plan_target(ps_capture_t *c, const ps_estimate_t *est)
{
    const int st = 1 - c->swing_side;
    const float t_left = fmaxf(c->p.swing_s - c->t_phase_s, 0.0f);
    const float grow = expf(omega0(c) * t_left);
    /* in the stance foot's frame (its heading): a turned body plans the same */
    const float d[2] = {c->xi_m[0] - est->foot_m[st][0], c->xi_m[1] - est->foot_m[st][1]};
    float local[2];
    rot2(-c->foot_yaw[st], d, local);
    float x = local[0] * grow;
    float y = local[1] * grow;
    const float n = sqrtf(x * x + y * y);
    if (n > 1e-6f) {
        x += c->p.step_offset_m * x / n;
        y += c->p.step_offset_m * y / n;
    }
    /* never across the stance foot: the swing foot keeps to its side */
    if (c->swing_side == 0)
        y = fmaxf(y, c->p.min_width_m);
    else
        y = fminf(y, -c->p.min_width_m);
    const float r = sqrtf(x * x + y * y);
    if (r > c->p.max_step_m) {
        x *= c->p.max_step_m / r;
        y *= c->p.max_step_m / r;
    }
    c->swing_to_m[0] = x;
    c->swing_to_m[1] = y;
    c->swing_to_m[2] = 0.0f;
}

/* Start a step; false when no foot can swing: the capture point went
 * sideways past a foot that already carries the CoM (lifting it would drop
 * the robot; the ankles must do it). */
static bool start_step(ps_capture_t *c, const ps_estimate_t *est, const float centre[2])
{
    const float dy = c->xi_m[1] - centre[1];
    int side;
    if (fabsf(dy) > 0.03f) {
        side = dy > 0.0f ? 0 : 1;
        const float sgn = side == 0 ? 1.0f : -1.0f;
        const float span = sgn * (est->foot_m[side][1] - est->foot_m[1 - side][1]);
        if (sgn * (c->com_m[1] - est->foot_m[1 - side][1]) > c->p.max_load_frac * span)
            return false;
    } else {
        float d[2];
        for (int s = 0; s < 2; s++)
            d[s] = hypotf(c->xi_m[0] - est->foot_m[s][0], c->xi_m[1] - est->foot_m[s][1]);
        side = d[0] > d[1] ? 0 : 1;
    }
    c->swing_side = side;
    c->phase = PS_CAPTURE_SWING;
    c->t_phase_s = 0.0f;
    const float d[2] = {est->foot_m[side][0] - est->foot_m[1 - side][0],
                        est->foot_m[side][1] - est->foot_m[1 - side][1]};
    rot2(-c->foot_yaw[1 - side], d, c->swing_from_m);
    c->swing_from_m[2] = 0.0f;
    plan_target(c, est);
    c->n_steps++;
    return true;
}

/* Minimum-jerk blend 0..1. */
static float min_jerk(float s)
{
    s = clampf(s, 0.0f, 1.0f);
    return s * s * s * (10.0f + s * (-15.0f + 6.0f * s));
}

/* Joint targets of both legs for soles at ground positions feet[s] (flat,
 * heading-aligned) under a level pelvis at pelvis_des (ground frame). */
static int legs_ik(const ps_capture_t *c, const float feet[2][3], const float yaw[2],
                   const float pelvis_des[3], float heading, ps_targets_t *t)
{
    for (int s = 0; s < 2; s++) {
        const float d[2] = {feet[s][0] - pelvis_des[0], feet[s][1] - pelvis_des[1]};
        float rel[3];
        rot2(-heading, d, rel);
        rel[2] = feet[s][2] - pelvis_des[2];
        float rot[3][3], q[PS_LEG_N_JOINTS];
        ps_legik_rot_rpy(0.0f, 0.0f, yaw[s] - heading, rot);
        if (ps_legik_solve(&c->kin, s, rel, (const float(*)[3])rot, q) < 0)
            return -EINVAL;
        for (int j = 0; j < PS_LEG_N_JOINTS; j++)
            t->q_rad[c->leg_idx[s][j]] = q[j];
    }
    return 0;
}

/* The swing leg's joints for its sole at ground-frame point sole, flat and
 * at heading yaw, solved from the trunk's estimated pose (tilt included)
 * rather than the level pelvis the stance leg is commanded to: the sole
 * follows its path over the ground however the trunk leans. Solved for a
 * level trunk, a trunk pitched back by 0.05-0.09 rad put the foot down at
 * 0.13 m instead of 0.25 m (docs/policy.md). An unreachable point gives the
 * best effort (ps_legik_solve); -EINVAL keeps the level-trunk solution. */
static int swing_leg_ik(const ps_capture_t *c, const ps_estimate_t *est, int side,
                        const float sole[3], float yaw, ps_targets_t *t)
{
    const float(*r)[3] = (const float(*)[3])est->pelvis_rot;
    const float d[3] = {sole[0] - est->pelvis_m[0], sole[1] - est->pelvis_m[1],
                        sole[2] - est->pelvis_m[2]};
    float rel[3], rz[3][3], rot[3][3], q[PS_LEG_N_JOINTS];
    for (int a = 0; a < 3; a++) /* into the trunk frame: R^T d */
        rel[a] = r[0][a] * d[0] + r[1][a] * d[1] + r[2][a] * d[2];
    ps_legik_rot_rpy(0.0f, 0.0f, yaw, rz);
    for (int i = 0; i < 3; i++) /* the flat sole's axes in the trunk frame: R^T Rz */
        for (int j = 0; j < 3; j++)
            rot[i][j] = r[0][i] * rz[0][j] + r[1][i] * rz[1][j] + r[2][i] * rz[2][j];
    if (ps_legik_solve(&c->kin, side, rel, (const float(*)[3])rot, q) < 0)
        return -EINVAL;
    for (int j = 0; j < PS_LEG_N_JOINTS; j++)
        t->q_rad[c->leg_idx[side][j]] = q[j];
    return 0;
}

static void stance_targets(const ps_capture_t *c, ps_targets_t *t)
{
    memset(t, 0, sizeof(*t));
    t->n_joints = c->n_joints;
    for (uint32_t i = 0; i < c->n_joints; i++)
        t->q_rad[i] = c->joints[i].stance_rad;
}

static int capture_step(void *ctx, const ps_meas_t *meas, const ps_estimate_t *est,
                        ps_targets_t *out)
{
    ps_capture_t *c = ctx;
    if (c == NULL || c->joints == NULL || out == NULL || meas == NULL)
        return -EINVAL;
    ps_targets_t t;
    stance_targets(c, &t);
    float com[3], com_p[3], soles_p[2][3], rot_p[2][3][3];
    const bool is_usable = est != NULL && !est->is_fallen &&
                           (est->is_contact[0] || est->is_contact[1]) &&
                           trunk_frame(c, meas, com_p, soles_p, rot_p) == 0;
    if (!is_usable) {
        c->phase = PS_CAPTURE_STAND;
        c->has_prev = false;
    } else {
        to_ground(est, com_p, com);
        /* Each sole's heading in the ground frame (which follows the trunk's). */
        for (int s = 0; s < 2; s++) {
            float fx[2] = {0, 0};
            for (int a = 0; a < 2; a++)
                fx[a] = est->pelvis_rot[a][0] * rot_p[s][0][0] +
                        est->pelvis_rot[a][1] * rot_p[s][1][0] +
                        est->pelvis_rot[a][2] * rot_p[s][2][0];
            c->foot_yaw[s] = atan2f(fx[1], fx[0]);
        }
        memcpy(c->com_m, com, sizeof(com));
        com_velocity(c, meas, est, com_p, (const float(*)[3])soles_p);
        const float w0 = omega0(c);
        c->xi_m[0] = com[0] + c->com_vel_m_s[0] / w0;
        c->xi_m[1] = com[1] + c->com_vel_m_s[1] / w0;

        /* Base of support of the feet in contact (heading-aligned soles). */
        float soles[2][2], poly[PS_BALANCE_MAX_POLY][2], centre[2] = {0, 0};
        const float *yaw = c->foot_yaw;
        for (int s = 0; s < 2; s++) {
            soles[s][0] = est->foot_m[s][0];
            soles[s][1] = est->foot_m[s][1];
        }
        const int n = ps_balance_support_polygon((const float(*)[2])soles, yaw, est->is_contact,
                                                 c->kin.foot_length_m, c->kin.foot_width_m, poly);
        /* xi diverges from the CoP: xi(t) = p + (xi - p) e^{omega0 t} */
        const float grow = expf(w0 * c->p.lookahead_s);
        const float xi_ahead[2] = {est->cop_m[0] + (c->xi_m[0] - est->cop_m[0]) * grow,
                                   est->cop_m[1] + (c->xi_m[1] - est->cop_m[1]) * grow};
        c->bos_margin_m = ps_balance_polygon_distance((const float(*)[2])poly, n, xi_ahead);
        (void)ps_balance_polygon_centre((const float(*)[2])poly, n, centre);

        c->t_phase_s += c->dt_s;
        const bool was_out = c->was_out;
        c->was_out = c->bos_margin_m < c->p.trigger_margin_m;
        const bool is_double = est->is_contact[0] && est->is_contact[1];
        /* two ticks in a row outside: one noisy tick does not start a step */
        const bool is_out = c->bos_margin_m < c->p.trigger_margin_m;
        if (c->phase == PS_CAPTURE_STAND && is_double && is_out && was_out)
            (void)start_step(c, est, centre); /* false: the ankles keep the slot */
        else if (c->phase == PS_CAPTURE_SWING) {
            if (c->t_phase_s < 0.5f * c->p.swing_s)
                plan_target(c, est);
            if (c->t_phase_s >= c->p.swing_s) {
                c->phase = PS_CAPTURE_SETTLE;
                c->t_phase_s = 0.0f;
            }
        } else if (c->phase == PS_CAPTURE_SETTLE && c->t_phase_s >= c->p.settle_s) {
            c->phase = PS_CAPTURE_STAND;
            c->t_phase_s = 0.0f;
        }

        /* Feet and pelvis targets, ground frame. */
        float feet[2][3], pelvis[3];
        for (int s = 0; s < 2; s++) {
            feet[s][0] = est->foot_m[s][0];
            feet[s][1] = est->foot_m[s][1];
            feet[s][2] = 0.0f;
        }
        pelvis[0] = est->pelvis_m[0];
        pelvis[1] = est->pelvis_m[1];
        pelvis[2] = c->height_m;
        /* The trunk turns back to the feet's heading: the soles stay as they
         * are on the floor, the swing sole parallel to the stance sole. */
        float fyaw[2] = {c->foot_yaw[0], c->foot_yaw[1]};
        float heading = 0.5f * (fyaw[0] + fyaw[1]);
        if (c->phase == PS_CAPTURE_SWING) {
            const int sw = c->swing_side, st = 1 - sw;
            const float s = min_jerk(c->t_phase_s / c->p.swing_s);
            float local[2], d[2];
            for (int a = 0; a < 2; a++)
                local[a] = c->swing_from_m[a] + s * (c->swing_to_m[a] - c->swing_from_m[a]);
            rot2(c->foot_yaw[st], local, d);
            for (int a = 0; a < 2; a++)
                feet[sw][a] = est->foot_m[st][a] + d[a];
            fyaw[sw] = c->foot_yaw[st];
            heading = c->foot_yaw[st];
            feet[sw][2] = c->p.lift_m * sinf(3.14159265f * clampf(c->t_phase_s / c->p.swing_s,
                                                                   0.0f, 1.0f));
        } else {
            /* the CoM back over the centre of the base of support */
            pelvis[0] += c->p.k_com * (centre[0] - com[0]);
            pelvis[1] += c->p.k_com * (centre[1] - com[1]);
        }
        /* Low enough that both legs reach their soles with the knees bent:
         * reach_frac of the leg's length from hip to ankle (a crouch below
         * the stance: measured, a bent knee takes pushes better). */
        const float reach = c->p.reach_frac * (c->kin.thigh_m + c->kin.shank_m);
        for (int s = 0; s < 2; s++) {
            const float hy = (s == 0 ? 1.0f : -1.0f) * c->kin.hip_offset_y_m;
            const float dx = feet[s][0] - c->kin.foot_offset_x_m - pelvis[0];
            const float dy = feet[s][1] - (pelvis[1] + hy);
            const float d2 = dx * dx + dy * dy;
            const float h_max = d2 < reach * reach ? sqrtf(reach * reach - d2) : 0.0f;
            const float z_max =
                feet[s][2] + c->kin.ankle_height_m + h_max + c->kin.hip_offset_z_m;
            pelvis[2] = fminf(pelvis[2], z_max);
        }
        /* The height moves toward its target at most HEIGHT_RATE_M_S (no
         * jump from the stance to the crouch, which would itself step). */
        if (!(c->height_cmd_m > 0.0f))
            c->height_cmd_m = est->pelvis_m[2];
        const float dh = HEIGHT_RATE_M_S * c->dt_s;
        c->height_cmd_m += clampf(pelvis[2] - c->height_cmd_m, -dh, dh);
        pelvis[2] = c->height_cmd_m;
        if (legs_ik(c, (const float(*)[3])feet, fyaw, pelvis, heading, &t) != 0)
            stance_targets(c, &t);
        else if (c->phase == PS_CAPTURE_SWING && c->p.swing_follows_trunk)
            (void)swing_leg_ik(c, est, c->swing_side, feet[c->swing_side], fyaw[c->swing_side], &t);
        /* Ankle strategy (ps_stand's signs) on the feet that carry weight. */
        const float cp = clampf(c->p.k_tilt * est->pitch_rad + c->p.k_vel * c->com_vel_m_s[0],
                                -PS_STAND_CORR_MAX_RAD, PS_STAND_CORR_MAX_RAD);
        const float cr = clampf(c->p.k_tilt * est->roll_rad - c->p.k_vel * c->com_vel_m_s[1],
                                -PS_STAND_CORR_MAX_RAD, PS_STAND_CORR_MAX_RAD);
        for (int s = 0; s < 2; s++) {
            if (c->phase == PS_CAPTURE_SWING && s == c->swing_side)
                continue;
            if (isfinite(cp) && isfinite(cr)) {
                t.q_rad[c->leg_idx[s][PS_LEG_ANKLE_PITCH]] += cp;
                t.q_rad[c->leg_idx[s][PS_LEG_ANKLE_ROLL]] += cr;
            }
        }
    }
    for (uint32_t i = 0; i < t.n_joints; i++) {
        const ps_act_limits_t *l = &c->joints[i].lim;
        if (!isfinite(t.q_rad[i]))
            return -PS_ERR_LIMIT;
        t.q_rad[i] = clampf(t.q_rad[i], l->pos_min_rad, l->pos_max_rad);
    }
    *out = t;
    return 0;
}

static void capture_reset(void *ctx)
{
    ps_capture_t *c = ctx;
    if (c == NULL)
        return;
    c->phase = PS_CAPTURE_STAND;
    c->t_phase_s = 0.0f;
    c->has_prev = false;
    c->height_cmd_m = 0.0f; /* from the measured height at the next step */
}

static const ps_policy_ops_t CAPTURE_OPS = {
    .name = "capture",
    .step = capture_step,
    .reset = capture_reset,
};

void ps_capture_as_policy(ps_capture_t *c, ps_policy_t *out)
{
    out->ops = &CAPTURE_OPS;
    out->ctx = c;
}
