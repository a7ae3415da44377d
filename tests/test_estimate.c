/* Tests of policy/ps_estimate: leg FK against hand-computed positions, the
 * complementary filter, contact, lumped CoM, CoP and the fallen flag.
 *
 * Fixture geometry (m): hip_offset y 0.08 z 0.08, thigh 0.3, shank 0.3,
 * ankle_height 0.05, foot_offset_x 0.03, foot 0.22 x 0.1, com_offset_z 0.15,
 * mass 32 kg. Zero pose: sole (0.03, +-0.08, -0.08-0.3-0.3-0.05 = -0.73).
 * Rotations (right-hand, positive axis): Rx(a) = [1 0 0; 0 c -s; 0 s c],
 * Ry(a) = [c 0 s; 0 1 0; -s 0 c], Rz(a) = [c -s 0; s c 0; 0 0 1]. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <string.h>
#include <unistd.h>

#include "../policy/ps_estimate.h"
#include "../rt/ps_err.h"

#define TOL_FK_M 1e-5f
#define G_M_S2   9.81f
#define DT_S     0.001f
#define DT_NS    1000000

static const char *const NAMES[12] = {
    "l_hip_yaw", "l_hip_roll", "l_hip_pitch", "l_knee", "l_ankle_pitch", "l_ankle_roll",
    "r_hip_yaw", "r_hip_roll", "r_hip_pitch", "r_knee", "r_ankle_pitch", "r_ankle_roll",
};

static const ps_kinematics_cfg_t KIN = {
    .mass_kg = 32.0f,
    .hip_offset_y_m = 0.08f,
    .hip_offset_z_m = 0.08f,
    .thigh_m = 0.3f,
    .shank_m = 0.3f,
    .ankle_height_m = 0.05f,
    .foot_length_m = 0.22f,
    .foot_width_m = 0.1f,
    .foot_offset_x_m = 0.03f,
    .com_offset_z_m = 0.15f,
    .fall_tilt_rad = 0.6f,
    .fall_com_height_m = 0.5f,
};

/* What the estimator is given: joint names and the kinematics. */
typedef struct {
    char name[PS_NAME_LEN];
    uint32_t n_joints;
    char joint_name[PS_MAX_JOINTS][PS_NAME_LEN];
    ps_kinematics_cfg_t kin;
} test_robot_t;

static int init_est(ps_estimator_t *e, const test_robot_t *r, float dt_s)
{
    return ps_estimate_init(e, r ? &r->kin : NULL, r ? r->joint_name : NULL, r ? r->n_joints : 0,
                            dt_s);
}

typedef struct {
    test_robot_t robot;
    ps_estimator_t est;
    ps_meas_t meas;
} fixture_t;

static void fill_robot(test_robot_t *r)
{
    memset(r, 0, sizeof(*r));
    strcpy(r->name, "test");
    r->n_joints = 12;
    for (unsigned i = 0; i < 12; i++)
        strcpy(r->joint_name[i], NAMES[i]);
    r->kin = KIN;
}

static int setup(void **state)
{
    static fixture_t f;
    memset(&f, 0, sizeof(f));
    fill_robot(&f.robot);
    assert_int_equal(init_est(&f.est, &f.robot, DT_S), 0);
    f.meas.n_joints = 12;
    for (unsigned i = 0; i < 12; i++)
        f.meas.joints[i].t_ns = 1;
    *state = &f;
    return 0;
}

static int find(const test_robot_t *r, const char *name)
{
    for (unsigned i = 0; i < r->n_joints; i++)
        if (strcmp(r->joint_name[i], name) == 0)
            return (int)i;
    fail_msg("no joint %s", name);
    return -1;
}

/* Sets one leg's six joints (chain order) by name. */
static void set_leg(fixture_t *f, int side, const float q[6])
{
    for (int j = 0; j < 6; j++)
        f->meas.joints[find(&f->robot, NAMES[side * 6 + j])].q_rad = q[j];
}

static void set_ankle_tau(fixture_t *f, int side, float pitch_nm, float roll_nm)
{
    f->meas.joints[find(&f->robot, NAMES[side * 6 + 4])].tau_nm = pitch_nm;
    f->meas.joints[find(&f->robot, NAMES[side * 6 + 5])].tau_nm = roll_nm;
}

/* The accelerometer of a resting trunk at orientation Ry(p) Rx(r) reads the
 * specific force R^T (0,0,g) = g (-sin p, sin r cos p, cos r cos p). */
static void set_imu(fixture_t *f, float roll, float pitch, const float gyro[3], int64_t t_ns)
{
    f->meas.imu.accel_body_m_s2[0] = -G_M_S2 * sinf(pitch);
    f->meas.imu.accel_body_m_s2[1] = G_M_S2 * sinf(roll) * cosf(pitch);
    f->meas.imu.accel_body_m_s2[2] = G_M_S2 * cosf(roll) * cosf(pitch);
    for (int i = 0; i < 3; i++)
        f->meas.imu.gyro_body_rad_s[i] = gyro ? gyro[i] : 0.0f;
    f->meas.imu.t_ns = t_ns;
}

static void assert_vec(const float got[3], float x, float y, float z, float tol)
{
    const float want[3] = {x, y, z};
    for (int i = 0; i < 3; i++) {
        if (!(fabsf(got[i] - want[i]) <= tol))
            fail_msg("[%d]: got %.7f want %.7f (tol %g)", i, (double)got[i], (double)want[i],
                     (double)tol);
    }
}

static void assert_near(float got, float want, float tol)
{
    if (!(fabsf(got - want) <= tol))
        fail_msg("got %.7f want %.7f (tol %g)", (double)got, (double)want, (double)tol);
}

/* ---- init ---------------------------------------------------------------- */

static void test_estimate_init_null_returns_einval(void **state)
{
    fixture_t *f = *state;
    ps_estimator_t e;
    assert_int_equal(init_est(NULL, &f->robot, DT_S), -EINVAL);
    assert_int_equal(init_est(&e, NULL, DT_S), -EINVAL);
}

static void test_estimate_init_bad_dt_or_mass_returns_einval(void **state)
{
    fixture_t *f = *state;
    ps_estimator_t e;
    assert_int_equal(init_est(&e, &f->robot, 0.0f), -EINVAL);
    assert_int_equal(init_est(&e, &f->robot, NAN), -EINVAL);
    f->robot.kin.mass_kg = 0.0f;
    assert_int_equal(init_est(&e, &f->robot, DT_S), -EINVAL);
}

static void test_estimate_init_missing_joint_returns_enoent(void **state)
{
    fixture_t *f = *state;
    ps_estimator_t e;
    strcpy(f->robot.joint_name[9], "r_knee_typo");
    assert_int_equal(init_est(&e, &f->robot, DT_S), -ENOENT);
}

static void test_estimate_init_any_order_finds_joints_by_name(void **state)
{
    fixture_t *f = *state;
    /* Reverse the joint table and add an unrelated joint in front. */
    test_robot_t *r = &f->robot;
    r->n_joints = 13;
    strcpy(r->joint_name[0], "waist");
    for (unsigned i = 0; i < 12; i++)
        strcpy(r->joint_name[1 + i], NAMES[11 - i]);
    assert_int_equal(init_est(&f->est, r, DT_S), 0);
    assert_int_equal(f->est.leg_idx[0][PS_LEG_HIP_YAW], 12);
    assert_int_equal(f->est.leg_idx[0][PS_LEG_KNEE], 9);
    assert_int_equal(f->est.leg_idx[1][PS_LEG_ANKLE_ROLL], 1);
    assert_int_equal(f->est.leg_idx[1][PS_LEG_HIP_YAW], 6);
    f->meas.n_joints = 13;
    /* Lift the left foot (hip pitch -a, knee 2a, ankle -a keeps it flat;
     * lift = 0.6 (1 - cos a) = 0.0485 m for a = 0.4): only the right one
     * stays in contact, which needs the left joints found correctly. */
    const float q[6] = {0.0f, 0.0f, -0.4f, 0.8f, -0.4f, 0.0f};
    set_leg(f, 0, q);
    ps_estimate_update(&f->est, &f->meas);
    assert_false(f->est.est.is_contact[0]);
    assert_true(f->est.est.is_contact[1]);
}

/* ---- forward kinematics ------------------------------------------------ */

static void test_leg_fk_zero_pose_legs_straight_down(void **state)
{
    (void)state;
    const float q[6] = {0};
    float s[3];
    ps_estimate_leg_fk(&KIN, 0, q, s);
    assert_vec(s, 0.03f, 0.08f, -0.73f, TOL_FK_M);
    ps_estimate_leg_fk(&KIN, 1, q, s);
    assert_vec(s, 0.03f, -0.08f, -0.73f, TOL_FK_M);
}

static void test_leg_fk_knee_90_shank_points_backward(void **state)
{
    (void)state;
    /* Knee (0, .08, -.38); shank Ry(90)(0,0,-.3) = (-.3, 0, 0) -> ankle
     * (-.3, .08, -.38); foot Ry(90)(.03, 0, -.05) = (-.05, 0, -.03). */
    const float q[6] = {0, 0, 0, (float)M_PI_2, 0, 0};
    float s[3];
    ps_estimate_leg_fk(&KIN, 0, q, s);
    assert_vec(s, -0.35f, 0.08f, -0.41f, TOL_FK_M);
}

static void test_leg_fk_hip_pitch_minus_90_knee_90_thigh_forward_shank_down(void **state)
{
    (void)state;
    /* Ry(-90)(0,0,-.3) = (.3, 0, 0): knee (.3, .08, -.08); total pitch 0:
     * ankle (.3, .08, -.38), sole (.33, .08, -.43). */
    const float q[6] = {0, 0, -(float)M_PI_2, (float)M_PI_2, 0, 0};
    float s[3];
    ps_estimate_leg_fk(&KIN, 0, q, s);
    assert_vec(s, 0.33f, 0.08f, -0.43f, TOL_FK_M);
}

static void test_leg_fk_hip_roll_30_swings_leg_to_plus_y(void **state)
{
    (void)state;
    /* Hip to sole at zero pose is (.03, 0, -.65); Rx(30 deg) of it:
     * (.03, .65 sin30, -.65 cos30) = (.03, .325, -.5629165). */
    const float q[6] = {0, (float)(M_PI / 6.0), 0, 0, 0, 0};
    float s[3];
    ps_estimate_leg_fk(&KIN, 0, q, s);
    assert_vec(s, 0.03f, 0.405f, -0.6429165f, TOL_FK_M);
    /* Right leg: same hip-to-sole vector from (0, -.08, -.08). */
    ps_estimate_leg_fk(&KIN, 1, q, s);
    assert_vec(s, 0.03f, 0.245f, -0.6429165f, TOL_FK_M);
}

static void test_leg_fk_hip_yaw_30_with_knee_90_rotates_about_z(void **state)
{
    (void)state;
    /* Hip to sole with knee 90 is (-.35, 0, -.33); Rz(30):
     * (-.35 cos30, -.35 sin30, -.33) = (-.3031089, -.175, -.33). */
    const float q[6] = {(float)(M_PI / 6.0), 0, 0, (float)M_PI_2, 0, 0};
    float s[3];
    ps_estimate_leg_fk(&KIN, 0, q, s);
    assert_vec(s, -0.3031089f, -0.095f, -0.41f, TOL_FK_M);
}

static void test_leg_fk_hip_order_yaw_roll_pitch(void **state)
{
    (void)state;
    float s[3];
    /* Yaw 90, pitch -90, rest 0. Hip to sole (.03, 0, -.65); Ry(-90) maps
     * (x,y,z) to (-z, y, x): (.65, 0, .03); Rz(90) maps to (-y, x, z):
     * (0, .65, .03). Pitch-then-yaw would give (.65, .03, 0) instead. */
    const float qyp[6] = {(float)M_PI_2, 0, -(float)M_PI_2, 0, 0, 0};
    ps_estimate_leg_fk(&KIN, 0, qyp, s);
    assert_vec(s, 0.0f, 0.73f, -0.05f, TOL_FK_M);
    /* Roll 90, pitch -90: Ry(-90) -> (.65, 0, .03); Rx(90) maps (x,y,z) to
     * (x, -z, y): (.65, -.03, 0). Pitch-then-roll would give (0, .65, .03). */
    const float qrp[6] = {0, (float)M_PI_2, -(float)M_PI_2, 0, 0, 0};
    ps_estimate_leg_fk(&KIN, 0, qrp, s);
    assert_vec(s, 0.65f, 0.05f, -0.08f, TOL_FK_M);
}

static void test_leg_fk_ankle_angles_move_sole_about_ankle(void **state)
{
    (void)state;
    float s[3];
    /* Ankle centre (0, .08, -.68). Pitch 90: Ry(90)(.03,0,-.05) = (-.05,0,-.03). */
    const float qp[6] = {0, 0, 0, 0, (float)M_PI_2, 0};
    ps_estimate_leg_fk(&KIN, 0, qp, s);
    assert_vec(s, -0.05f, 0.08f, -0.71f, TOL_FK_M);
    /* Roll 90: Rx(90)(.03,0,-.05) = (.03, .05, 0). */
    const float qr[6] = {0, 0, 0, 0, 0, (float)M_PI_2};
    ps_estimate_leg_fk(&KIN, 0, qr, s);
    assert_vec(s, 0.03f, 0.13f, -0.68f, TOL_FK_M);
    /* Pitch then roll: Ry(90) Rx(90)(.03,0,-.05) = Ry(90)(.03,.05,0) = (0,.05,-.03). */
    const float qpr[6] = {0, 0, 0, 0, (float)M_PI_2, (float)M_PI_2};
    ps_estimate_leg_fk(&KIN, 0, qpr, s);
    assert_vec(s, 0.0f, 0.13f, -0.71f, TOL_FK_M);
}

static void test_leg_fk_pose_returns_ankle_and_foot_axes(void **state)
{
    (void)state;
    const float q[6] = {0, 0, 0, 0, 0.3f, 0};
    float s[3], a[3], r[3][3];
    ps_estimate_leg_fk_pose(&KIN, 1, q, s, a, r);
    assert_vec(a, 0.0f, -0.08f, -0.68f, TOL_FK_M);
    /* Foot axes = Ry(0.3): x axis (cos .3, 0, -sin .3). */
    assert_vec((float[3]){r[0][0], r[1][0], r[2][0]}, 0.9553365f, 0.0f, -0.2955202f, 1e-6f);
    assert_vec((float[3]){r[0][1], r[1][1], r[2][1]}, 0.0f, 1.0f, 0.0f, 1e-6f);
}

static void test_leg_fk_mirrored_pose_gives_mirrored_sole(void **state)
{
    (void)state;
    /* Mirroring in y flips the sign of yaw and roll joints, keeps pitch joints. */
    const float ql[6] = {0.2f, 0.15f, -0.4f, 0.7f, -0.25f, 0.1f};
    const float qr[6] = {-0.2f, -0.15f, -0.4f, 0.7f, -0.25f, -0.1f};
    float sl[3], sr[3];
    ps_estimate_leg_fk(&KIN, 0, ql, sl);
    ps_estimate_leg_fk(&KIN, 1, qr, sr);
    assert_vec(sr, sl[0], -sl[1], sl[2], 1e-6f);
    assert_true(sl[1] > 0.0f); /* not trivially symmetric about y = 0 */
}

/* ---- tilt filter --------------------------------------------------------- */

static void test_estimate_update_first_imu_sample_initialises_tilt(void **state)
{
    fixture_t *f = *state;
    set_imu(f, 0.1f, -0.2f, NULL, DT_NS);
    ps_estimate_update(&f->est, &f->meas);
    assert_true(f->est.has_tilt);
    assert_near(f->est.est.roll_rad, 0.1f, 1e-6f);
    assert_near(f->est.est.pitch_rad, -0.2f, 1e-6f);
}

static void test_estimate_update_static_tilt_converges_with_tau(void **state)
{
    fixture_t *f = *state;
    set_imu(f, 0.0f, 0.0f, NULL, DT_NS);
    ps_estimate_update(&f->est, &f->meas);
    int64_t t = DT_NS;
    for (int i = 0; i < 500; i++) { /* one time constant */
        t += DT_NS;
        set_imu(f, 0.0f, 0.2f, NULL, t);
        ps_estimate_update(&f->est, &f->meas);
    }
    assert_near(f->est.est.pitch_rad, 0.2f * (1.0f - expf(-1.0f)), 1e-3f);
    for (int i = 0; i < 4500; i++) { /* ten time constants in all */
        t += DT_NS;
        set_imu(f, 0.0f, 0.2f, NULL, t);
        ps_estimate_update(&f->est, &f->meas);
    }
    assert_near(f->est.est.pitch_rad, 0.2f, 1e-4f);
    assert_near(f->est.est.roll_rad, 0.0f, 1e-6f);
}

static void test_estimate_update_constant_gyro_rate_tracked_without_lag(void **state)
{
    fixture_t *f = *state;
    /* True pitch 0.1 rad/s * t, gyro and accel consistent. Without gyro
     * integration the filter would lag by rate * tau = 0.05 rad. */
    const float w[3] = {0.0f, 0.1f, 0.0f};
    set_imu(f, 0.0f, 0.0f, w, DT_NS);
    ps_estimate_update(&f->est, &f->meas);
    for (int i = 1; i <= 2000; i++) {
        set_imu(f, 0.0f, 0.1f * (float)i * DT_S, w, (int64_t)(i + 1) * DT_NS);
        ps_estimate_update(&f->est, &f->meas);
    }
    assert_near(f->est.est.pitch_rad, 0.2f, 1e-4f);
}

static void test_estimate_update_gated_accel_integrates_gyro_only(void **state)
{
    fixture_t *f = *state;
    set_imu(f, 0.0f, 0.0f, NULL, DT_NS);
    ps_estimate_update(&f->est, &f->meas);
    /* |a| = 0 (free fall) and then 2 g pointing "tilted": both outside the
     * 20 % gate, so only the gyro counts: roll rate -0.2 rad/s for 1 s. */
    const float w[3] = {-0.2f, 0.0f, 0.0f};
    for (int i = 1; i <= 1000; i++) {
        set_imu(f, 0.0f, 0.0f, w, (int64_t)(i + 1) * DT_NS);
        const float k = (i % 2) ? 0.0f : 2.0f;
        f->meas.imu.accel_body_m_s2[0] = k * G_M_S2 * 0.6f;
        f->meas.imu.accel_body_m_s2[1] = 0.0f;
        f->meas.imu.accel_body_m_s2[2] = k * G_M_S2 * 0.8f;
        ps_estimate_update(&f->est, &f->meas);
    }
    assert_near(f->est.est.roll_rad, -0.2f, 1e-4f);
    assert_near(f->est.est.pitch_rad, 0.0f, 1e-6f);
}

static void test_estimate_update_imu_t_zero_ignored(void **state)
{
    fixture_t *f = *state;
    set_imu(f, 0.3f, 0.3f, NULL, 0); /* never received: zeros would do too */
    ps_estimate_update(&f->est, &f->meas);
    assert_near(f->est.est.pitch_rad, 0.0f, 0.0f);
    assert_near(f->est.est.roll_rad, 0.0f, 0.0f);
    /* Nor did it start the filter: the first real sample below sets the
     * tilt from its accelerometer at once, not a filter step towards it. */
    set_imu(f, 0.0f, 0.1f, NULL, DT_NS);
    ps_estimate_update(&f->est, &f->meas);
    const float w[3] = {5.0f, 5.0f, 5.0f};
    set_imu(f, 0.4f, -0.4f, w, 0);
    ps_estimate_update(&f->est, &f->meas);
    assert_near(f->est.est.pitch_rad, 0.1f, 1e-6f);
    assert_near(f->est.est.roll_rad, 0.0f, 1e-6f);
}

static void test_estimate_update_repeated_or_older_imu_sample_not_integrated(void **state)
{
    fixture_t *f = *state;
    set_imu(f, 0.0f, 0.0f, NULL, DT_NS);
    ps_estimate_update(&f->est, &f->meas);
    const float w[3] = {0.0f, 1.0f, 0.0f};
    set_imu(f, 0.0f, 0.0f, w, 2 * DT_NS);
    ps_estimate_update(&f->est, &f->meas);
    const float p1 = f->est.est.pitch_rad;
    assert_true(p1 > 0.0005f); /* the new sample did integrate */
    for (int i = 0; i < 10; i++)
        ps_estimate_update(&f->est, &f->meas); /* loop ticks, same IMU sample */
    assert_near(f->est.est.pitch_rad, p1, 0.0f);
    /* An older sample (reordered) is not integrated backwards either. */
    set_imu(f, 0.0f, 0.0f, w, DT_NS / 2);
    ps_estimate_update(&f->est, &f->meas);
    assert_near(f->est.est.pitch_rad, p1, 0.0f);
}

static void test_estimate_update_long_imu_gap_reinitialises_from_accel(void **state)
{
    fixture_t *f = *state;
    set_imu(f, 0.0f, 0.0f, NULL, DT_NS);
    ps_estimate_update(&f->est, &f->meas);
    set_imu(f, -0.25f, 0.15f, NULL, DT_NS + 1000000000); /* 1 s later */
    ps_estimate_update(&f->est, &f->meas);
    assert_near(f->est.est.roll_rad, -0.25f, 1e-6f);
    assert_near(f->est.est.pitch_rad, 0.15f, 1e-6f);
}

/* ---- contact, CoM -------------------------------------------------------- */

/* Bend a leg keeping the foot flat: hip pitch -a, knee 2a, ankle -a. The
 * sole rises by 0.6 (1 - cos a); a for a given lift is acos(1 - lift/0.6). */
static void bend_leg(fixture_t *f, int side, float a)
{
    const float q[6] = {0.0f, 0.0f, -a, 2.0f * a, -a, 0.0f};
    set_leg(f, side, q);
}

static void test_estimate_update_lifted_foot_not_in_contact(void **state)
{
    fixture_t *f = *state;
    bend_leg(f, 0, acosf(1.0f - 0.021f / 0.6f)); /* 2.1 cm: out */
    ps_estimate_update(&f->est, &f->meas);
    assert_false(f->est.est.is_contact[0]);
    assert_true(f->est.est.is_contact[1]);
    assert_near(f->est.est.foot_m[0][2], 0.021f, 1e-5f);
    assert_near(f->est.est.foot_m[1][2], 0.0f, 1e-6f);
    bend_leg(f, 0, acosf(1.0f - 0.019f / 0.6f)); /* 1.9 cm: still in */
    ps_estimate_update(&f->est, &f->meas);
    assert_true(f->est.est.is_contact[0]);
    assert_true(f->est.est.is_contact[1]);
}

static void test_estimate_update_stance_com_above_ground(void **state)
{
    fixture_t *f = *state;
    set_imu(f, 0.0f, 0.0f, NULL, DT_NS);
    ps_estimate_update(&f->est, &f->meas);
    const ps_estimate_t *e = &f->est.est;
    /* Origin under the soles (0.03, 0, -0.73): CoM (0, 0, .15) - origin. */
    assert_vec(e->com_m, -0.03f, 0.0f, 0.88f, 1e-5f);
    assert_vec(e->foot_m[0], 0.0f, 0.08f, 0.0f, 1e-5f);
    assert_vec(e->foot_m[1], 0.0f, -0.08f, 0.0f, 1e-5f);
    assert_true(e->is_contact[0] && e->is_contact[1]);
    assert_false(e->is_fallen);
}

static void test_estimate_update_pitched_trunk_moves_com_forward(void **state)
{
    fixture_t *f = *state;
    /* Pitch p = 0.1, zero pose. Ry(p) maps (x, y, z) to (cx + sz, y, -sx + cz).
     * Soles (.03, +-.08, -.73) -> origin (.03c - .73s, 0, -.03s - .73c); CoM
     * offset (.15s, 0, .15c). com - origin = (.88s - .03c, 0, .88c + .03s)
     * = (.0580033, 0, .8785988) with s = .0998334, c = .9950042. */
    set_imu(f, 0.0f, 0.1f, NULL, DT_NS);
    ps_estimate_update(&f->est, &f->meas);
    assert_vec(f->est.est.com_m, 0.0580033f, 0.0f, 0.8785988f, 1e-5f);
}

static void test_estimate_update_squat_gives_com_velocity(void **state)
{
    fixture_t *f = *state;
    /* Both legs bend with a = 0.3 + 0.5 t: CoM height 0.28 + 0.6 cos a, so
     * dz/dt = -0.3 sin a. The backward difference lags dt/2 and the low-pass
     * a further tau (ramp response), so compare with a(t - tau - dt/2). */
    const int n = 300;
    for (int i = 0; i <= n; i++) {
        const float a = 0.3f + 0.5f * (float)i * DT_S;
        bend_leg(f, 0, a);
        bend_leg(f, 1, a);
        ps_estimate_update(&f->est, &f->meas);
    }
    const float t_end = (float)n * DT_S;
    const float a_lag = 0.3f + 0.5f * (t_end - PS_ESTIMATE_VEL_TAU_S - 0.5f * DT_S);
    assert_near(f->est.est.com_vel_m_s[2], -0.3f * sinf(a_lag), 5e-4f);
    assert_near(f->est.est.com_vel_m_s[0], 0.0f, 1e-4f);
    assert_near(f->est.est.com_m[2], 0.28f + 0.6f * cosf(0.3f + 0.5f * t_end), 1e-5f);
}

/* ---- CoP ----------------------------------------------------------------- */

static void test_estimate_update_zero_ankle_torque_cop_under_ankles(void **state)
{
    fixture_t *f = *state;
    /* Zero ankle torque: the ground force passes through the ankle axis, so
     * the CoP is under the ankles (x = 0 in the pelvis), not the sole centres
     * 3 cm ahead: (0 - 0.03, 0) in the ground frame. */
    ps_estimate_update(&f->est, &f->meas);
    assert_near(f->est.est.cop_m[0], -0.03f, 1e-6f);
    assert_near(f->est.est.cop_m[1], 0.0f, 1e-6f);
}

static void test_estimate_update_known_ankle_torques_give_known_cop(void **state)
{
    fixture_t *f = *state;
    /* Static foot, ground force F = (0, 0, Fz) at r = (px, py, -h) from the
     * ankle; Fz = 32 * 9.81 / 2 = 156.96 N per foot. Moment balance on the
     * foot: tau + r x F = 0, r x F = (py Fz, -px Fz, 0). To put the CoP at
     * px = +0.05 the actuator must press the toe down: tau_pitch = +7.848 Nm.
     * To put it at py = -0.02 (toward the right edge) tau_roll = +3.1392 Nm. */
    set_ankle_tau(f, 0, 7.848f, 3.1392f);
    set_ankle_tau(f, 1, 7.848f, 3.1392f);
    ps_estimate_update(&f->est, &f->meas);
    assert_near(f->est.est.cop_m[0], -0.03f + 0.05f, 1e-5f);
    assert_near(f->est.est.cop_m[1], -0.02f, 1e-5f);
    /* Opposite torques on the two feet: x offsets 0.05 and -0.05 cancel. */
    set_ankle_tau(f, 1, -7.848f, -3.1392f);
    ps_estimate_update(&f->est, &f->meas);
    assert_near(f->est.est.cop_m[0], -0.03f, 1e-5f);
    assert_near(f->est.est.cop_m[1], 0.0f, 1e-5f);
}

static void test_estimate_update_large_torque_cop_clamped_to_foot(void **state)
{
    fixture_t *f = *state;
    /* Sole spans x in [0.03 - 0.11, 0.03 + 0.11] = [-0.08, 0.14] from the
     * ankle and y in [-0.05, 0.05]. 100 Nm / 156.96 N = 0.64 m: clamped. */
    set_ankle_tau(f, 0, 100.0f, 100.0f);
    set_ankle_tau(f, 1, 100.0f, 100.0f);
    ps_estimate_update(&f->est, &f->meas);
    assert_near(f->est.est.cop_m[0], -0.03f + 0.14f, 1e-5f);
    assert_near(f->est.est.cop_m[1], -0.05f, 1e-5f);
    set_ankle_tau(f, 0, -100.0f, -100.0f);
    set_ankle_tau(f, 1, -100.0f, -100.0f);
    ps_estimate_update(&f->est, &f->meas);
    assert_near(f->est.est.cop_m[0], -0.03f - 0.08f, 1e-5f);
    assert_near(f->est.est.cop_m[1], 0.05f, 1e-5f);
}

static void test_estimate_update_single_support_cop_on_stance_foot(void **state)
{
    fixture_t *f = *state;
    /* Left foot lifted 5 cm (sole x stays 0.03, origin x 0.03); all 313.92 N
     * on the right: tau_pitch 10 Nm -> px = 0.0318552 m. The swing foot's
     * torque must not count. */
    bend_leg(f, 0, acosf(1.0f - 0.05f / 0.6f));
    set_ankle_tau(f, 0, 50.0f, 50.0f);
    set_ankle_tau(f, 1, 10.0f, 0.0f);
    ps_estimate_update(&f->est, &f->meas);
    assert_false(f->est.est.is_contact[0]);
    assert_near(f->est.est.cop_m[0], -0.03f + 0.0318552f, 1e-5f);
    assert_near(f->est.est.cop_m[1], -0.08f, 1e-5f);
}

/* ---- fallen -------------------------------------------------------------- */

static void test_estimate_update_tilt_past_threshold_fallen(void **state)
{
    fixture_t *f = *state;
    set_imu(f, 0.0f, 0.59f, NULL, DT_NS); /* threshold 0.6 rad */
    ps_estimate_update(&f->est, &f->meas);
    assert_false(f->est.est.is_fallen);
    assert_int_equal(init_est(&f->est, &f->robot, DT_S), 0);
    set_imu(f, 0.0f, -0.61f, NULL, DT_NS);
    ps_estimate_update(&f->est, &f->meas);
    assert_true(f->est.est.is_fallen);
    assert_int_equal(init_est(&f->est, &f->robot, DT_S), 0);
    set_imu(f, 0.61f, 0.0f, NULL, DT_NS);
    ps_estimate_update(&f->est, &f->meas);
    assert_true(f->est.est.is_fallen);
}

static void test_estimate_update_low_com_fallen_only_with_tilt(void **state)
{
    fixture_t *f = *state;
    /* Squat: CoM height 0.28 + 0.6 cos a; threshold 0.5 m. */
    bend_leg(f, 0, acosf((0.51f - 0.28f) / 0.6f));
    bend_leg(f, 1, acosf((0.51f - 0.28f) / 0.6f));
    set_imu(f, 0.0f, 0.0f, NULL, DT_NS);
    ps_estimate_update(&f->est, &f->meas);
    assert_near(f->est.est.com_m[2], 0.51f, 1e-5f);
    assert_false(f->est.est.is_fallen);
    bend_leg(f, 0, acosf((0.49f - 0.28f) / 0.6f));
    bend_leg(f, 1, acosf((0.49f - 0.28f) / 0.6f));
    ps_estimate_update(&f->est, &f->meas);
    assert_true(f->est.est.is_fallen);
    /* Same pose before any IMU sample: no tilt estimate, no verdict. */
    assert_int_equal(init_est(&f->est, &f->robot, DT_S), 0);
    f->meas.imu.t_ns = 0;
    ps_estimate_update(&f->est, &f->meas);
    assert_near(f->est.est.com_m[2], 0.49f, 1e-5f);
    assert_false(f->est.est.is_fallen);
}

/* NULL arguments are a no-op: an estimate built up by earlier updates (a
 * tilt, a CoM velocity, a CoP) is left exactly as it was, and the next real
 * update carries on from it. */
static void test_estimate_update_null_args_estimate_unchanged(void **state)
{
    fixture_t *f = *state;
    set_imu(f, 0.1f, 0.2f, NULL, DT_NS);
    bend_leg(f, 0, 0.2f);
    bend_leg(f, 1, 0.2f);
    set_ankle_tau(f, 1, 5.0f, 1.0f);
    ps_estimate_update(&f->est, &f->meas);
    bend_leg(f, 0, 0.25f); /* a CoM velocity from the squat */
    bend_leg(f, 1, 0.25f);
    ps_estimate_update(&f->est, &f->meas);
    static ps_estimator_t before;
    memcpy(&before, &f->est, sizeof(before));
    assert_true(before.est.com_vel_m_s[2] != 0.0f);
    ps_estimate_update(NULL, &f->meas);
    ps_estimate_update(&f->est, NULL);
    assert_memory_equal(&f->est, &before, sizeof(before));
}

/* ---- bounds: CoP without load, angle wrap -------------------------------- */

/* No load to average (mass 0 after init: every foot's share is 0 N): the
 * CoP is the midpoint of the soles, the ground origin, not 0/0 = NaN. */
static void test_estimate_update_zero_load_cop_midpoint_not_nan(void **state)
{
    fixture_t *f = *state;
    set_ankle_tau(f, 0, 7.848f, 3.1392f);
    set_ankle_tau(f, 1, 0.0f, 0.0f);
    f->est.kin.mass_kg = 0.0f; /* init checked it; poke the estimator's copy */
    ps_estimate_update(&f->est, &f->meas);
    assert_true(isfinite(f->est.est.cop_m[0]) && isfinite(f->est.est.cop_m[1]));
    assert_near(f->est.est.cop_m[0], 0.0f, 0.0f);
    assert_near(f->est.est.cop_m[1], 0.0f, 0.0f);
    f->est.kin.mass_kg = NAN;
    ps_estimate_update(&f->est, &f->meas);
    assert_near(f->est.est.cop_m[0], 0.0f, 0.0f);
    assert_near(f->est.est.cop_m[1], 0.0f, 0.0f);
    /* With the mass back, the load-weighted CoP is back. */
    f->est.kin.mass_kg = 32.0f;
    ps_estimate_update(&f->est, &f->meas);
    assert_near(f->est.est.cop_m[0], -0.03f + 0.025f, 1e-5f);
}

static void test_ps_estimate_wrap_pi_non_finite_returns_nan(void **state)
{
    (void)state;
    alarm(5); /* a wrap that loops forever ends the test binary, a failure */
    assert_true(isnan(ps_estimate_wrap_pi(INFINITY)));
    assert_true(isnan(ps_estimate_wrap_pi(-INFINITY)));
    assert_true(isnan(ps_estimate_wrap_pi(NAN)));
    alarm(0);
}

static void test_ps_estimate_wrap_pi_finite_wrapped_into_pi_range(void **state)
{
    (void)state;
    const float pi = 3.14159265f;
    alarm(5);
    assert_near(ps_estimate_wrap_pi(0.5f), 0.5f, 0.0f);
    assert_near(ps_estimate_wrap_pi(-3.0f), -3.0f, 0.0f);
    assert_near(ps_estimate_wrap_pi(0.5f + 2.0f * pi), 0.5f, 1e-5f);
    assert_near(ps_estimate_wrap_pi(-0.5f - 6.0f * pi), -0.5f, 1e-5f);
    assert_near(fabsf(ps_estimate_wrap_pi(3.0f * pi)), pi, 1e-5f);
    /* Far beyond 2 pi / ulp: "-= 2 pi" no longer changes the value. */
    static const float HUGE_RAD[] = {1e30f, -1e30f, 3.4e38f, -3.4e38f, 1e8f};
    for (size_t i = 0; i < sizeof(HUGE_RAD) / sizeof(HUGE_RAD[0]); i++) {
        const float w = ps_estimate_wrap_pi(HUGE_RAD[i]);
        if (!(w >= -pi && w <= pi))
            fail_msg("wrap(%g) = %g", (double)HUGE_RAD[i], (double)w);
    }
    alarm(0);
}

/* A finite but absurd gyro rate (a corrupt frame that passed the checks)
 * must not hang the tick in the wrap: the update returns, roll in range. */
static void test_estimate_update_huge_gyro_rate_returns_bounded_roll(void **state)
{
    fixture_t *f = *state;
    set_imu(f, 0.0f, 0.0f, NULL, DT_NS);
    ps_estimate_update(&f->est, &f->meas);
    const float w[3] = {3e38f, 0.0f, 0.0f};
    set_imu(f, 0.0f, 0.0f, w, 2 * DT_NS);
    alarm(5);
    ps_estimate_update(&f->est, &f->meas);
    alarm(0);
    const float r = f->est.est.roll_rad;
    assert_true(isnan(r) || (r >= -3.1416f && r <= 3.1416f));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup(test_estimate_init_null_returns_einval, setup),
        cmocka_unit_test_setup(test_estimate_init_bad_dt_or_mass_returns_einval, setup),
        cmocka_unit_test_setup(test_estimate_init_missing_joint_returns_enoent, setup),
        cmocka_unit_test_setup(test_estimate_init_any_order_finds_joints_by_name, setup),
        cmocka_unit_test(test_leg_fk_zero_pose_legs_straight_down),
        cmocka_unit_test(test_leg_fk_knee_90_shank_points_backward),
        cmocka_unit_test(test_leg_fk_hip_pitch_minus_90_knee_90_thigh_forward_shank_down),
        cmocka_unit_test(test_leg_fk_hip_roll_30_swings_leg_to_plus_y),
        cmocka_unit_test(test_leg_fk_hip_yaw_30_with_knee_90_rotates_about_z),
        cmocka_unit_test(test_leg_fk_hip_order_yaw_roll_pitch),
        cmocka_unit_test(test_leg_fk_ankle_angles_move_sole_about_ankle),
        cmocka_unit_test(test_leg_fk_pose_returns_ankle_and_foot_axes),
        cmocka_unit_test(test_leg_fk_mirrored_pose_gives_mirrored_sole),
        cmocka_unit_test_setup(test_estimate_update_first_imu_sample_initialises_tilt, setup),
        cmocka_unit_test_setup(test_estimate_update_static_tilt_converges_with_tau, setup),
        cmocka_unit_test_setup(test_estimate_update_constant_gyro_rate_tracked_without_lag, setup),
        cmocka_unit_test_setup(test_estimate_update_gated_accel_integrates_gyro_only, setup),
        cmocka_unit_test_setup(test_estimate_update_imu_t_zero_ignored, setup),
        cmocka_unit_test_setup(test_estimate_update_repeated_or_older_imu_sample_not_integrated,
                               setup),
        cmocka_unit_test_setup(test_estimate_update_long_imu_gap_reinitialises_from_accel, setup),
        cmocka_unit_test_setup(test_estimate_update_lifted_foot_not_in_contact, setup),
        cmocka_unit_test_setup(test_estimate_update_stance_com_above_ground, setup),
        cmocka_unit_test_setup(test_estimate_update_pitched_trunk_moves_com_forward, setup),
        cmocka_unit_test_setup(test_estimate_update_squat_gives_com_velocity, setup),
        cmocka_unit_test_setup(test_estimate_update_zero_ankle_torque_cop_under_ankles, setup),
        cmocka_unit_test_setup(test_estimate_update_known_ankle_torques_give_known_cop, setup),
        cmocka_unit_test_setup(test_estimate_update_large_torque_cop_clamped_to_foot, setup),
        cmocka_unit_test_setup(test_estimate_update_single_support_cop_on_stance_foot, setup),
        cmocka_unit_test_setup(test_estimate_update_tilt_past_threshold_fallen, setup),
        cmocka_unit_test_setup(test_estimate_update_low_com_fallen_only_with_tilt, setup),
        cmocka_unit_test_setup(test_estimate_update_null_args_estimate_unchanged, setup),
        cmocka_unit_test_setup(test_estimate_update_zero_load_cop_midpoint_not_nan, setup),
        cmocka_unit_test(test_ps_estimate_wrap_pi_non_finite_returns_nan),
        cmocka_unit_test(test_ps_estimate_wrap_pi_finite_wrapped_into_pi_range),
        cmocka_unit_test_setup(test_estimate_update_huge_gyro_rate_returns_bounded_roll, setup),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
