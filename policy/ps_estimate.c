/*
 * ps_estimate: trunk tilt, foot positions, contact, lumped CoM and CoP.
 *
 * CoM / CoP / base-of-support definitions follow the Push-and-Step seed paper
 * (seed 000_caaeae2d90dfe8b5.txt, "2. Stage 1: Encoding
 * Biomechanical Balance Principles into Rewards"): the CoM is compared with the
 * centre of the base of support (the contact feet) at resting height, the CoP
 * is the point where the vertical ground reaction acts. Details and limits in
 * docs/estimation.md.
 *
 * Frames. Pelvis: x forward, y left, z up, origin at the IMU. Ground: the
 * pelvis frame rotated by the trunk tilt (roll, pitch; yaw ignored, so it is
 * heading-aligned), origin on the ground under the midpoint of the two soles.
 * Positive angle = right-hand rotation about the positive axis.
 */
#include "ps_estimate.h"

#include <math.h>
#include <string.h>

#include "../rt/ps_err.h"

static const char *const LEG_NAMES[2][PS_LEG_N_JOINTS] = {
    {"l_hip_yaw", "l_hip_roll", "l_hip_pitch", "l_knee", "l_ankle_pitch", "l_ankle_roll"},
    {"r_hip_yaw", "r_hip_roll", "r_hip_pitch", "r_knee", "r_ankle_pitch", "r_ankle_roll"},
};

/* ---- small 3x3 helpers (row-major, float, no allocation) --------------- */

static void rot_x(float a, float r[3][3])
{
    const float c = cosf(a), s = sinf(a);
    const float m[3][3] = {{1.0f, 0.0f, 0.0f}, {0.0f, c, -s}, {0.0f, s, c}};
    memcpy(r, m, sizeof(m));
}

static void rot_y(float a, float r[3][3])
{
    const float c = cosf(a), s = sinf(a);
    const float m[3][3] = {{c, 0.0f, s}, {0.0f, 1.0f, 0.0f}, {-s, 0.0f, c}};
    memcpy(r, m, sizeof(m));
}

static void rot_z(float a, float r[3][3])
{
    const float c = cosf(a), s = sinf(a);
    const float m[3][3] = {{c, -s, 0.0f}, {s, c, 0.0f}, {0.0f, 0.0f, 1.0f}};
    memcpy(r, m, sizeof(m));
}

/* out = a * b; out may alias neither a nor b. */
static void mat_mul(const float a[3][3], const float b[3][3], float out[3][3])
{
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            out[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
}

/* r <- r * rot(axis, a): appends one joint rotation to a chain. */
static void chain_rot(float r[3][3], int axis, float a)
{
    float j[3][3], tmp[3][3];
    if (axis == 0)
        rot_x(a, j);
    else if (axis == 1)
        rot_y(a, j);
    else
        rot_z(a, j);
    mat_mul(r, j, tmp);
    memcpy(r, tmp, sizeof(tmp));
}

/* out = base + r * v */
static void add_rot_vec(const float base[3], const float r[3][3], const float v[3], float out[3])
{
    for (int i = 0; i < 3; i++)
        out[i] = base[i] + r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2];
}

static float clampf(float x, float lo, float hi)
{
    return x < lo ? lo : (x > hi ? hi : x);
}

/* ---- forward kinematics ------------------------------------------------ */

void ps_estimate_leg_fk_pose(const ps_kinematics_cfg_t *k, int side,
                             const float q_rad[PS_LEG_N_JOINTS], float out_sole_m[3],
                             float out_ankle_m[3], float out_rot[3][3])
{
    const float ysign = (side == 0) ? 1.0f : -1.0f;
    const float hip[3] = {0.0f, ysign * k->hip_offset_y_m, -k->hip_offset_z_m};
    const float thigh[3] = {0.0f, 0.0f, -k->thigh_m};
    const float shank[3] = {0.0f, 0.0f, -k->shank_m};
    const float sole[3] = {k->foot_offset_x_m, 0.0f, -k->ankle_height_m};
    float r[3][3] = {{1.0f, 0.0f, 0.0f}, {0.0f, 1.0f, 0.0f}, {0.0f, 0.0f, 1.0f}};
    float knee[3], ankle[3];

    /* Hip yaw (z), roll (x), pitch (y) all act at the hip centre. */
    chain_rot(r, 2, q_rad[PS_LEG_HIP_YAW]);
    chain_rot(r, 0, q_rad[PS_LEG_HIP_ROLL]);
    chain_rot(r, 1, q_rad[PS_LEG_HIP_PITCH]);
    add_rot_vec(hip, r, thigh, knee);
    /* Knee about +y: knee > 0 swings the shank backward (-x). */
    chain_rot(r, 1, q_rad[PS_LEG_KNEE]);
    add_rot_vec(knee, r, shank, ankle);
    /* Ankle pitch then roll, both through the ankle centre. */
    chain_rot(r, 1, q_rad[PS_LEG_ANKLE_PITCH]);
    chain_rot(r, 0, q_rad[PS_LEG_ANKLE_ROLL]);
    add_rot_vec(ankle, r, sole, out_sole_m);

    if (out_ankle_m)
        memcpy(out_ankle_m, ankle, sizeof(ankle));
    if (out_rot)
        memcpy(out_rot, r, sizeof(r));
}

void ps_estimate_leg_fk(const ps_kinematics_cfg_t *k, int side, const float q_rad[PS_LEG_N_JOINTS],
                        float out_sole_m[3])
{
    ps_estimate_leg_fk_pose(k, side, q_rad, out_sole_m, NULL, NULL);
}

/* ---- init ---------------------------------------------------------------- */

static int find_joint(const char (*names)[PS_NAME_LEN], uint32_t n, const char *name)
{
    for (uint32_t i = 0; i < n; i++) {
        if (strncmp(names[i], name, PS_NAME_LEN) == 0)
            return (int)i;
    }
    return -ENOENT;
}

int ps_estimate_init(ps_estimator_t *e, const ps_kinematics_cfg_t *kin,
                     const char (*joint_name)[PS_NAME_LEN], uint32_t n_joints, float dt_s)
{
    if (!e || !kin || !joint_name || n_joints > PS_MAX_JOINTS || !(dt_s > 0.0f) ||
        !(kin->mass_kg > 0.0f))
        return -EINVAL;
    int idx[2][PS_LEG_N_JOINTS];
    for (int s = 0; s < 2; s++) {
        for (int j = 0; j < PS_LEG_N_JOINTS; j++) {
            idx[s][j] = find_joint(joint_name, n_joints, LEG_NAMES[s][j]);
            if (idx[s][j] < 0)
                return -ENOENT;
        }
    }
    memset(e, 0, sizeof(*e));
    e->kin = *kin;
    memcpy(e->leg_idx, idx, sizeof(idx));
    e->dt_s = dt_s;
    e->filter_tau_s = PS_ESTIMATE_FILTER_TAU_S;
    return 0;
}

/* ---- tilt: complementary filter ----------------------------------------- */

float ps_estimate_wrap_pi(float a_rad)
{
    if (!isfinite(a_rad))
        return NAN; /* +-inf has no angle; NaN stays NaN */
    const float pi = 3.14159265f;
    if (a_rad >= -pi && a_rad <= pi)
        return a_rad; /* the usual case: exact, no rounding */
    /* One remainder instead of a loop: bounded time for any finite input
     * (a loop of -= 2 pi never ends once 2 pi is below the float's ulp). */
    const float r = remainderf(a_rad, 2.0f * pi);
    return r > pi ? r - 2.0f * pi : (r < -pi ? r + 2.0f * pi : r);
}

/* Tilt from the gravity direction. Trunk orientation R = Ry(pitch) Rx(roll)
 * (ZYX Euler without yaw). At rest the accelerometer reads the specific force
 * R^T (0, 0, g) = g (-sin p, sin r cos p, cos r cos p), hence the atan2s.
 * Returns false when |a| is too far from g (pushes, impacts, free fall): the
 * direction is then not gravity and must not pull the estimate. */
static bool accel_tilt(const float a[3], float *out_roll, float *out_pitch)
{
    const float n2 = a[0] * a[0] + a[1] * a[1] + a[2] * a[2];
    if (!isfinite(n2))
        return false;
    const float g = PS_ESTIMATE_G_M_S2;
    const float lo = (1.0f - PS_ESTIMATE_ACCEL_GATE) * g;
    const float hi = (1.0f + PS_ESTIMATE_ACCEL_GATE) * g;
    if (n2 < lo * lo || n2 > hi * hi)
        return false;
    *out_roll = atan2f(a[1], a[2]);
    *out_pitch = atan2f(-a[0], sqrtf(a[1] * a[1] + a[2] * a[2]));
    return true;
}

static void update_tilt(ps_estimator_t *e, const ps_imu_meas_t *imu)
{
    if (imu->t_ns == 0)
        return; /* never received */
    float acc_roll = 0.0f, acc_pitch = 0.0f;
    const bool is_acc_ok = accel_tilt(imu->accel_body_m_s2, &acc_roll, &acc_pitch);
    const int64_t gap_ns = imu->t_ns - e->last_imu_t_ns;
    const bool is_reinit =
        !e->has_tilt || e->last_imu_t_ns == 0 || gap_ns > (int64_t)(PS_ESTIMATE_IMU_GAP_S * 1e9f);

    if (is_reinit) {
        /* First sample or a long gap: the integrated state is meaningless,
         * start from the gravity direction (if this sample has one). */
        if (is_acc_ok) {
            e->est.roll_rad = acc_roll;
            e->est.pitch_rad = acc_pitch;
            e->has_tilt = true;
            e->last_imu_t_ns = imu->t_ns;
        }
        return;
    }
    if (gap_ns <= 0)
        return; /* same sample again (IMU slower than the loop) or reordered */

    const float dt = (float)gap_ns * 1e-9f;
    const float *w = imu->gyro_body_rad_s;
    if (!isfinite(w[0]) || !isfinite(w[1]) || !isfinite(w[2]))
        return;
    float r = e->est.roll_rad, p = e->est.pitch_rad;
    /* ZYX Euler rates from body rates; tan(p) is bounded because |p| near
     * pi/2 means the robot is on the floor anyway. */
    const float cr = cosf(r), sr = sinf(r);
    const float tp = tanf(clampf(p, -1.4f, 1.4f));
    r += (w[0] + tp * (sr * w[1] + cr * w[2])) * dt;
    p += (cr * w[1] - sr * w[2]) * dt;
    if (is_acc_ok) {
        /* First-order complementary filter: gyro high-passed, accel
         * low-passed, both with time constant tau. */
        const float tau = e->filter_tau_s > 0.0f ? e->filter_tau_s : PS_ESTIMATE_FILTER_TAU_S;
        const float beta = dt / (tau + dt);
        r += beta * ps_estimate_wrap_pi(acc_roll - r);
        p += beta * (acc_pitch - p);
    }
    e->est.roll_rad = ps_estimate_wrap_pi(r);
    e->est.pitch_rad = p;
    e->last_imu_t_ns = imu->t_ns;
}

/* ---- update --------------------------------------------------------------- */

static float joint_val(const ps_meas_t *m, int idx, bool is_tau)
{
    if (idx < 0 || (uint32_t)idx >= m->n_joints || (uint32_t)idx >= PS_MAX_JOINTS)
        return 0.0f;
    const float v = is_tau ? m->joints[idx].tau_nm : m->joints[idx].q_rad;
    return isfinite(v) ? v : 0.0f;
}

void ps_estimate_update(ps_estimator_t *e, const ps_meas_t *m)
{
    if (!e || !m || !(e->dt_s > 0.0f))
        return;
    const ps_kinematics_cfg_t *k = &e->kin;
    ps_estimate_t *est = &e->est;

    update_tilt(e, &m->imu);

    /* Tilt rotation; identity until the first accelerometer sample. */
    float r_tilt[3][3];
    rot_y(est->pitch_rad, r_tilt);
    chain_rot(r_tilt, 0, est->roll_rad); /* Ry(pitch) Rx(roll) */

    /* Feet in the heading-aligned frame at the pelvis origin. */
    const float zero[3] = {0.0f, 0.0f, 0.0f};
    float sole_h[2][3], ankle_h[2][3], rot_h[2][3][3];
    for (int s = 0; s < 2; s++) {
        float q[PS_LEG_N_JOINTS], sole_p[3], ankle_p[3], rot_p[3][3];
        for (int j = 0; j < PS_LEG_N_JOINTS; j++)
            q[j] = joint_val(m, e->leg_idx[s][j], false);
        ps_estimate_leg_fk_pose(k, s, q, sole_p, ankle_p, rot_p);
        add_rot_vec(zero, r_tilt, sole_p, sole_h[s]);
        add_rot_vec(zero, r_tilt, ankle_p, ankle_h[s]);
        mat_mul(r_tilt, rot_p, rot_h[s]);
    }

    /* Contact: kinematic only. The lowest sole is always "in contact"; the
     * estimator cannot tell flight (harness) from standing. */
    const float z_ground = fminf(sole_h[0][2], sole_h[1][2]);
    int n_contacts = 0;
    for (int s = 0; s < 2; s++) {
        est->is_contact[s] = sole_h[s][2] <= z_ground + PS_ESTIMATE_CONTACT_M;
        n_contacts += est->is_contact[s] ? 1 : 0;
    }

    const float origin[3] = {0.5f * (sole_h[0][0] + sole_h[1][0]),
                             0.5f * (sole_h[0][1] + sole_h[1][1]), z_ground};
    for (int i = 0; i < 3; i++)
        est->pelvis_m[i] = -origin[i];
    memcpy(est->pelvis_rot, r_tilt, sizeof(r_tilt));
    for (int s = 0; s < 2; s++)
        for (int i = 0; i < 3; i++)
            est->foot_m[s][i] = sole_h[s][i] - origin[i];

    /* Lumped CoM: com_offset_z_m along the trunk axis above the pelvis. */
    const float com_t[3] = {0.0f, 0.0f, k->com_offset_z_m};
    float com_h[3];
    add_rot_vec(zero, r_tilt, com_t, com_h);
    float com[3];
    for (int i = 0; i < 3; i++)
        com[i] = com_h[i] - origin[i];

    /* CoM velocity: finite difference, first-order low-pass. Encoder
     * quantisation over a 0.6 m leg makes the raw 1 kHz difference noisy by
     * ~0.2 m/s, hence the 20 ms smoothing. A support change (the origin jumps
     * with the feet) shows as a velocity spike; acceptable for standing. */
    if (e->has_prev_com) {
        const float a = e->dt_s / (PS_ESTIMATE_VEL_TAU_S + e->dt_s);
        for (int i = 0; i < 3; i++) {
            const float v = (com[i] - e->prev_com_m[i]) / e->dt_s;
            est->com_vel_m_s[i] += a * (v - est->com_vel_m_s[i]);
        }
    } else {
        for (int i = 0; i < 3; i++)
            est->com_vel_m_s[i] = 0.0f;
    }
    memcpy(est->com_m, com, sizeof(com));
    memcpy(e->prev_com_m, com, sizeof(com));
    e->has_prev_com = true;

    /* CoP. Per foot in contact, vertical load F_z = m g / n_contacts (the
     * joint torques could give each foot's load through the leg Jacobian;
     * not done, see docs/estimation.md). With a flat, massless foot the
     * moments about the ankle balance: tau_joint + r x F = 0, r = (px, py, -h)
     * from the ankle to the CoP, F = (0, 0, F_z). tau_joint is the actuator
     * torque ON THE FOOT about +axis (the drive's reply / MuJoCo qfrc_actuator sign).
     *   y: tau_pitch + (r_z F_x - r_x F_z) = tau_pitch - px F_z = 0
     *      -> px = +tau_pitch / F_z  (toe pressed down = positive pitch torque)
     *   x: tau_roll + (r_y F_z - r_z F_y) = tau_roll + py F_z = 0
     *      -> py = -tau_roll / F_z   (positive roll torque presses the right edge)
     * (The opposite signs hold for the reaction torque on the shank.) Checked
     * in MuJoCo 2.2.2, see docs/estimation.md. The offset is clamped to
     * the sole rectangle, placed with the foot's orientation, then the feet
     * are averaged weighted by load. Below PS_ESTIMATE_COP_MIN_FORCE_N of
     * total load (no contact foot, a zero or non-finite mass) the average
     * means nothing (0/0): the CoP is then the ground origin, the midpoint
     * of the two soles. */
    const float f_z = k->mass_kg * PS_ESTIMATE_G_M_S2 / (float)(n_contacts > 0 ? n_contacts : 1);
    const float half_l = 0.5f * k->foot_length_m, half_w = 0.5f * k->foot_width_m;
    float cop_sum[2] = {0.0f, 0.0f}, f_sum = 0.0f;
    for (int s = 0; s < 2; s++) {
        if (!est->is_contact[s])
            continue;
        const float tau_p = joint_val(m, e->leg_idx[s][PS_LEG_ANKLE_PITCH], true);
        const float tau_r = joint_val(m, e->leg_idx[s][PS_LEG_ANKLE_ROLL], true);
        const float off[3] = {
            clampf(tau_p / f_z, k->foot_offset_x_m - half_l, k->foot_offset_x_m + half_l),
            clampf(-tau_r / f_z, -half_w, half_w), -k->ankle_height_m};
        float cop_h[3];
        add_rot_vec(ankle_h[s], rot_h[s], off, cop_h);
        cop_sum[0] += f_z * (cop_h[0] - origin[0]);
        cop_sum[1] += f_z * (cop_h[1] - origin[1]);
        f_sum += f_z;
    }
    if (f_sum >= PS_ESTIMATE_COP_MIN_FORCE_N) {
        est->cop_m[0] = cop_sum[0] / f_sum;
        est->cop_m[1] = cop_sum[1] / f_sum;
    } else {
        est->cop_m[0] = 0.0f; /* the midpoint of the soles */
        est->cop_m[1] = 0.0f;
    }

    /* Fallen: trunk z axis (sp cr, -sr, cp cr) more than fall_tilt_rad from
     * vertical, or CoM too low. Only with a tilt estimate: before the first
     * IMU sample the geometry is computed as if upright and proves nothing. */
    if (e->has_tilt) {
        const float cos_tilt = cosf(est->roll_rad) * cosf(est->pitch_rad);
        est->is_fallen = cos_tilt < cosf(k->fall_tilt_rad) || com[2] < k->fall_com_height_m ||
                         !isfinite(cos_tilt);
    } else {
        est->is_fallen = false;
    }
}
