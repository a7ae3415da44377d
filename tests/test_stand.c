/* Tests of policy/ps_stand: stance hold and the ankle strategy's sign,
 * magnitude, clamps and fall-backs.
 *
 * Restoring direction (derived in ps_stand.c): a forward lean (pitch > 0,
 * CoM ahead of the support centre) must RAISE the ankle pitch targets, so the
 * servo presses the toes down and the reaction on the shanks rotates the body
 * back. Roll > 0 (top toward -y) raises the ankle roll targets; a CoM left of
 * the support (+y) lowers them. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <string.h>

#include "../policy/ps_estimate.h"
#include "../policy/ps_stand.h"
#include "../rt/ps_err.h"

static const char *const NAMES[12] = {
    "l_hip_yaw", "l_hip_roll", "l_hip_pitch", "l_knee", "l_ankle_pitch", "l_ankle_roll",
    "r_hip_yaw", "r_hip_roll", "r_hip_pitch", "r_knee", "r_ankle_pitch", "r_ankle_roll",
};
/* A slightly crouched stance; distinct values so a swapped index shows. */
static const float STANCE[12] = {0.01f,  0.02f,  -0.2f,  0.4f,  -0.2f,  0.03f,
                                 -0.01f, -0.02f, -0.21f, 0.41f, -0.19f, -0.03f};
enum { L_AP = 4, L_AR = 5, R_AP = 10, R_AR = 11 };

#define TOL 1e-6f

/* What the standing controller is given: names, stance and limits. */
typedef struct {
    char name[PS_NAME_LEN];
    uint32_t n_joints;
    char joint_name[PS_MAX_JOINTS][PS_NAME_LEN];
    ps_servo_joint_cfg_t servo[PS_MAX_JOINTS];
    ps_kinematics_cfg_t kin;
} test_robot_t;

static int stand_init(ps_stand_t *st, const test_robot_t *r)
{
    return ps_stand_init(st, r ? r->n_joints : 0, r ? r->joint_name : NULL, r ? r->servo : NULL);
}

typedef struct {
    test_robot_t robot;
    ps_stand_t st;
    ps_policy_t pol;
    ps_estimate_t est;
    ps_meas_t meas;
    ps_targets_t out;
} fixture_t;

static int setup(void **state)
{
    static fixture_t f;
    memset(&f, 0, sizeof(f));
    test_robot_t *r = &f.robot;
    strcpy(r->name, "test");
    r->n_joints = 12;
    for (unsigned i = 0; i < 12; i++) {
        strcpy(r->joint_name[i], NAMES[i]);
        r->servo[i].stance_rad = STANCE[i];
        r->servo[i].lim.pos_min_rad = -2.0f;
        r->servo[i].lim.pos_max_rad = 2.0f;
    }
    r->kin = (ps_kinematics_cfg_t){.mass_kg = 32.0f,
                                   .hip_offset_y_m = 0.08f,
                                   .hip_offset_z_m = 0.08f,
                                   .thigh_m = 0.3f,
                                   .shank_m = 0.3f,
                                   .ankle_height_m = 0.05f,
                                   .foot_length_m = 0.22f,
                                   .foot_width_m = 0.1f,
                                   .foot_offset_x_m = 0.03f,
                                   .com_offset_z_m = 0.15f};
    assert_int_equal(stand_init(&f.st, r), 0);
    /* The arithmetic tests below use fixed gains, not the shipped defaults
     * (which are checked separately and tuned in simulation). */
    f.st.k_tilt = 0.5f;
    f.st.k_com = 1.0f;
    f.st.k_vel = 0.0f;
    ps_stand_as_policy(&f.st, &f.pol);
    /* Upright, both feet down at (0, +-0.08), CoM 0.85 m above their midpoint. */
    f.est.foot_m[0][1] = 0.08f;
    f.est.foot_m[1][1] = -0.08f;
    f.est.is_contact[0] = f.est.is_contact[1] = true;
    f.est.com_m[2] = 0.85f;
    *state = &f;
    return 0;
}

static int step(fixture_t *f)
{
    return f->pol.ops->step(f->pol.ctx, &f->meas, &f->est, &f->out);
}

/* Every joint at stance except the four ankles, which get the deltas. */
static void assert_targets(const fixture_t *f, float d_pitch, float d_roll)
{
    assert_int_equal(f->out.n_joints, 12);
    for (int i = 0; i < 12; i++) {
        float want = STANCE[i];
        if (i == L_AP || i == R_AP)
            want += d_pitch;
        if (i == L_AR || i == R_AR)
            want += d_roll;
        if (!(fabsf(f->out.q_rad[i] - want) <= TOL))
            fail_msg("%s: got %.7f want %.7f", NAMES[i], (double)f->out.q_rad[i], (double)want);
        assert_true(f->out.qd_rad_s[i] == 0.0f);
        assert_true(f->out.tau_ff_nm[i] == 0.0f);
    }
}

/* ---- init ---------------------------------------------------------------- */

static void test_stand_init_null_or_no_joints_returns_einval(void **state)
{
    fixture_t *f = *state;
    ps_stand_t st;
    assert_int_equal(stand_init(NULL, &f->robot), -EINVAL);
    assert_int_equal(stand_init(&st, NULL), -EINVAL);
    f->robot.n_joints = 0;
    assert_int_equal(stand_init(&st, &f->robot), -EINVAL);
    f->robot.n_joints = PS_MAX_JOINTS + 1;
    assert_int_equal(stand_init(&st, &f->robot), -EINVAL);
}

static void test_stand_init_finds_ankles_by_name(void **state)
{
    fixture_t *f = *state;
    assert_int_equal(f->st.idx_ankle_pitch[0], L_AP);
    assert_int_equal(f->st.idx_ankle_roll[0], L_AR);
    assert_int_equal(f->st.idx_ankle_pitch[1], R_AP);
    assert_int_equal(f->st.idx_ankle_roll[1], R_AR);
    assert_string_equal(f->pol.ops->name, "stand");
    assert_ptr_equal(f->pol.ctx, &f->st);
}

/* The shipped gains by what they do, with the numbers docs/estimation.md
 * gives (k_tilt = 0.5, k_vel = 0.25 rad per m/s, k_com = 0), written here
 * independently of the header's macros: a CoM moving forward at 0.2 m/s
 * raises both ankle pitch targets by 0.05 rad; moving left at 0.2 m/s
 * lowers the roll targets by 0.05 rad; a trunk pitch of 0.1 rad adds
 * 0.05 rad; a CoM 3 cm ahead of the support does nothing. */
static void test_stand_step_default_gains_respond_as_documented(void **state)
{
    fixture_t *f = *state;
    ps_stand_t st;
    ps_policy_t pol;
    assert_int_equal(stand_init(&st, &f->robot), 0); /* defaults, not the fixture's */
    ps_stand_as_policy(&st, &pol);
    f->est.com_vel_m_s[0] = 0.2f;
    assert_int_equal(pol.ops->step(pol.ctx, &f->meas, &f->est, &f->out), 0);
    assert_targets(f, 0.05f, 0.0f);
    f->est.com_vel_m_s[0] = 0.0f;
    f->est.com_vel_m_s[1] = 0.2f;
    assert_int_equal(pol.ops->step(pol.ctx, &f->meas, &f->est, &f->out), 0);
    assert_targets(f, 0.0f, -0.05f);
    f->est.com_vel_m_s[1] = 0.0f;
    f->est.pitch_rad = 0.1f;
    assert_int_equal(pol.ops->step(pol.ctx, &f->meas, &f->est, &f->out), 0);
    assert_targets(f, 0.05f, 0.0f);
    f->est.pitch_rad = 0.0f;
    f->est.com_m[0] = 0.03f;
    assert_int_equal(pol.ops->step(pol.ctx, &f->meas, &f->est, &f->out), 0);
    assert_targets(f, 0.0f, 0.0f);
}

/* ---- step ---------------------------------------------------------------- */

static void test_stand_step_upright_outputs_stance(void **state)
{
    fixture_t *f = *state;
    memset(&f->out, 0x7f, sizeof(f->out)); /* garbage the step must overwrite */
    assert_int_equal(step(f), 0);
    assert_targets(f, 0.0f, 0.0f);
}

static void test_stand_step_forward_lean_raises_ankle_pitch(void **state)
{
    fixture_t *f = *state;
    /* pitch 0.05 rad, CoM 0.02 m ahead: 0.5 * 0.05 + 1.0 * 0.02 = +0.045. */
    f->est.pitch_rad = 0.05f;
    f->est.com_m[0] = 0.02f;
    assert_int_equal(step(f), 0);
    assert_true(f->out.q_rad[L_AP] > STANCE[L_AP]); /* restoring: up */
    assert_targets(f, 0.045f, 0.0f);
    /* Backward lean: the opposite. */
    f->est.pitch_rad = -0.05f;
    f->est.com_m[0] = -0.02f;
    assert_int_equal(step(f), 0);
    assert_targets(f, -0.045f, 0.0f);
}

static void test_stand_step_lateral_lean_moves_ankle_roll(void **state)
{
    fixture_t *f = *state;
    /* roll 0.04 (top toward -y), CoM 0.01 m right of centre (-y):
     * 0.5 * 0.04 - 1.0 * (-0.01) = +0.03. */
    f->est.roll_rad = 0.04f;
    f->est.com_m[1] = -0.01f;
    assert_int_equal(step(f), 0);
    assert_targets(f, 0.0f, 0.03f);
}

/* CoM moving forward (+x) and left (+y): the velocity term acts like the
 * position term, pitch up and roll the other way:
 * pitch 0.25 * 0.2 = +0.05, roll -0.25 * 0.1 = -0.025. */
static void test_stand_step_com_velocity_damps(void **state)
{
    fixture_t *f = *state;
    f->st.k_vel = 0.25f;
    f->est.com_vel_m_s[0] = 0.2f;
    f->est.com_vel_m_s[1] = 0.1f;
    assert_int_equal(step(f), 0);
    assert_targets(f, 0.05f, -0.025f);
}

static void test_stand_step_gains_scale_correction(void **state)
{
    fixture_t *f = *state;
    f->st.k_tilt = 0.2f;
    f->st.k_com = 3.0f;
    f->est.pitch_rad = 0.05f;
    f->est.com_m[0] = 0.01f;
    assert_int_equal(step(f), 0);
    assert_targets(f, 0.2f * 0.05f + 3.0f * 0.01f, 0.0f);
}

static void test_stand_step_support_centre_is_contact_feet(void **state)
{
    fixture_t *f = *state;
    /* Left foot lifted and 0.1 m ahead; support = right sole at x = -0.02.
     * CoM at x = 0: 0.02 m ahead of the support -> +0.02 pitch. In y the
     * CoM is 0.08 m left of the right sole -> roll -0.08. */
    f->est.is_contact[0] = false;
    f->est.foot_m[0][0] = 0.1f;
    f->est.foot_m[0][2] = 0.05f;
    f->est.foot_m[1][0] = -0.02f;
    assert_int_equal(step(f), 0);
    assert_targets(f, 0.02f, -0.08f);
}

static void test_stand_step_large_lean_correction_clamped(void **state)
{
    fixture_t *f = *state;
    f->est.pitch_rad = 0.4f;
    f->est.com_m[0] = 0.3f;
    f->est.roll_rad = -0.4f;
    assert_int_equal(step(f), 0);
    assert_targets(f, PS_STAND_CORR_MAX_RAD, -PS_STAND_CORR_MAX_RAD);
    f->est.pitch_rad = -0.4f;
    f->est.com_m[0] = -0.3f;
    f->est.roll_rad = 0.4f;
    assert_int_equal(step(f), 0);
    assert_targets(f, -PS_STAND_CORR_MAX_RAD, PS_STAND_CORR_MAX_RAD);
}

static void test_stand_step_target_clamped_to_joint_limit(void **state)
{
    fixture_t *f = *state;
    f->robot.servo[L_AP].lim.pos_max_rad = STANCE[L_AP] + 0.01f;
    f->est.pitch_rad = 0.1f;
    assert_int_equal(step(f), 0);
    assert_true(fabsf(f->out.q_rad[L_AP] - (STANCE[L_AP] + 0.01f)) <= TOL);
    assert_true(fabsf(f->out.q_rad[R_AP] - (STANCE[R_AP] + 0.05f)) <= TOL);
}

static void test_stand_step_missing_ankles_no_correction(void **state)
{
    fixture_t *f = *state;
    strcpy(f->robot.joint_name[L_AP], "l_foot_pitch");
    strcpy(f->robot.joint_name[R_AR], "r_foot_roll");
    assert_int_equal(stand_init(&f->st, &f->robot), 0);
    assert_int_equal(f->st.idx_ankle_pitch[0], -1);
    assert_int_equal(f->st.idx_ankle_roll[1], -1);
    f->est.pitch_rad = 0.05f;
    f->est.roll_rad = 0.05f;
    assert_int_equal(step(f), 0);
    for (int i = 0; i < 12; i++) {
        float want = STANCE[i];
        if (i == R_AP || i == L_AR) /* still present: corrected by 0.025 */
            want += 0.025f;
        assert_true(fabsf(f->out.q_rad[i] - want) <= TOL);
    }
}

static void test_stand_step_nan_estimate_falls_back_to_stance(void **state)
{
    fixture_t *f = *state;
    f->est.pitch_rad = NAN;
    f->est.com_m[1] = INFINITY;
    assert_int_equal(step(f), 0);
    assert_targets(f, 0.0f, 0.0f);
    f->est.pitch_rad = 0.0f;
    f->est.com_m[1] = 0.0f;
    f->est.foot_m[1][0] = NAN;
    assert_int_equal(step(f), 0);
    assert_targets(f, 0.0f, 0.0f);
}

static void test_stand_step_null_or_fallen_estimate_holds_stance(void **state)
{
    fixture_t *f = *state;
    f->est.pitch_rad = 0.05f;
    assert_int_equal(f->pol.ops->step(f->pol.ctx, NULL, NULL, &f->out), 0);
    assert_targets(f, 0.0f, 0.0f);
    f->est.is_fallen = true;
    assert_int_equal(step(f), 0);
    assert_targets(f, 0.0f, 0.0f);
}

static void test_stand_step_null_ctx_or_out_returns_einval(void **state)
{
    fixture_t *f = *state;
    assert_int_equal(f->pol.ops->step(NULL, &f->meas, &f->est, &f->out), -EINVAL);
    assert_int_equal(f->pol.ops->step(f->pol.ctx, &f->meas, &f->est, NULL), -EINVAL);
    f->st.n_joints = 0; /* a corrupted controller, not a config: init refuses 0 */
    assert_int_equal(step(f), -EINVAL);
}

static void test_stand_step_nan_stance_returns_limit_out_untouched(void **state)
{
    fixture_t *f = *state;
    f->robot.servo[3].stance_rad = NAN;
    memset(&f->out, 0, sizeof(f->out));
    assert_int_equal(step(f), -PS_ERR_LIMIT);
    assert_int_equal(f->out.n_joints, 0);
    assert_true(f->out.q_rad[0] == 0.0f);
}

/* ps_stand keeps no state between steps (nothing filtered or integrated),
 * so reset has nothing to clear; what it must not do is lose the user's
 * gains or the joint map. After many steps on varied inputs (anything a
 * stateful controller would accumulate), reset, then the same input gives
 * exactly what a freshly initialised controller with the same gains gives,
 * and both match the correction computed by hand. */
static void test_stand_reset_after_varied_steps_matches_fresh_controller(void **state)
{
    fixture_t *f = *state;
    f->st.k_tilt = 0.3f;
    f->st.k_com = 0.7f;
    f->st.k_vel = 0.1f;
    for (int i = 0; i < 200; i++) {
        f->est.pitch_rad = 0.002f * (float)(i % 37);
        f->est.roll_rad = -0.001f * (float)(i % 23);
        f->est.com_vel_m_s[0] = 0.01f * (float)(i % 11);
        assert_int_equal(step(f), 0);
    }
    f->pol.ops->reset(f->pol.ctx);
    f->est.pitch_rad = 0.04f;
    f->est.roll_rad = 0.0f;
    f->est.com_m[0] = 0.01f;
    f->est.com_vel_m_s[0] = 0.2f;
    assert_int_equal(step(f), 0);
    const ps_targets_t after_reset = f->out;
    assert_targets(f, 0.3f * 0.04f + 0.7f * 0.01f + 0.1f * 0.2f, 0.0f);

    ps_stand_t fresh;
    ps_policy_t pol;
    assert_int_equal(stand_init(&fresh, &f->robot), 0);
    fresh.k_tilt = 0.3f;
    fresh.k_com = 0.7f;
    fresh.k_vel = 0.1f;
    ps_stand_as_policy(&fresh, &pol);
    assert_int_equal(pol.ops->step(pol.ctx, &f->meas, &f->est, &f->out), 0);
    assert_memory_equal(&f->out, &after_reset, sizeof(after_reset));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup(test_stand_init_null_or_no_joints_returns_einval, setup),
        cmocka_unit_test_setup(test_stand_init_finds_ankles_by_name, setup),
        cmocka_unit_test_setup(test_stand_step_default_gains_respond_as_documented, setup),
        cmocka_unit_test_setup(test_stand_step_upright_outputs_stance, setup),
        cmocka_unit_test_setup(test_stand_step_forward_lean_raises_ankle_pitch, setup),
        cmocka_unit_test_setup(test_stand_step_lateral_lean_moves_ankle_roll, setup),
        cmocka_unit_test_setup(test_stand_step_com_velocity_damps, setup),
        cmocka_unit_test_setup(test_stand_step_gains_scale_correction, setup),
        cmocka_unit_test_setup(test_stand_step_support_centre_is_contact_feet, setup),
        cmocka_unit_test_setup(test_stand_step_large_lean_correction_clamped, setup),
        cmocka_unit_test_setup(test_stand_step_target_clamped_to_joint_limit, setup),
        cmocka_unit_test_setup(test_stand_step_missing_ankles_no_correction, setup),
        cmocka_unit_test_setup(test_stand_step_nan_estimate_falls_back_to_stance, setup),
        cmocka_unit_test_setup(test_stand_step_null_or_fallen_estimate_holds_stance, setup),
        cmocka_unit_test_setup(test_stand_step_null_ctx_or_out_returns_einval, setup),
        cmocka_unit_test_setup(test_stand_step_nan_stance_returns_limit_out_untouched, setup),
        cmocka_unit_test_setup(test_stand_reset_after_varied_steps_matches_fresh_controller, setup),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
