/*
 * Tests of policy/ps_legik.c: the analytic leg IK inverts the estimator's
 * forward kinematics (ps_estimate_leg_fk_pose) over the joint ranges of ps1,
 * a hand-made pose, reach limits and argument errors.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../policy/ps_legik.h"

static const ps_kinematics_cfg_t KIN = {
    .mass_kg = 37.7f,
    .hip_offset_y_m = 0.08f,
    .hip_offset_z_m = 0.06f,
    .thigh_m = 0.28f,
    .shank_m = 0.28f,
    .ankle_height_m = 0.05f,
    .foot_length_m = 0.20f,
    .foot_width_m = 0.09f,
    .foot_offset_x_m = 0.03f,
};

/* ps1's leg ranges (robots/ps1.yaml), the knee kept bent enough to be unique. */
static const float Q_MIN[PS_LEG_N_JOINTS] = {-0.6f, -0.35f, -2.0f, 0.05f, -0.9f, -0.4f};
static const float Q_MAX[PS_LEG_N_JOINTS] = {0.6f, 0.35f, 0.8f, 2.4f, 0.6f, 0.4f};

static float urand(unsigned *seed, float lo, float hi)
{
    *seed = *seed * 1103515245u + 12345u;
    return lo + (hi - lo) * (float)((*seed >> 8) & 0xffffu) / 65535.0f;
}

/* FK, then IK of what FK gave: the same angles, and FK of those the same pose. */
static void test_ps_legik_solve_inverts_fk_both_legs(void **st)
{
    (void)st;
    unsigned seed = 7u;
    for (int side = 0; side < 2; side++) {
        for (int n = 0; n < 2000; n++) {
            float q[PS_LEG_N_JOINTS], q2[PS_LEG_N_JOINTS], sole[3], sole2[3], rot[3][3],
                rot2[3][3];
            for (int j = 0; j < PS_LEG_N_JOINTS; j++)
                q[j] = urand(&seed, Q_MIN[j], Q_MAX[j]);
            ps_estimate_leg_fk_pose(&KIN, side, q, sole, NULL, rot);
            assert_int_equal(ps_legik_solve(&KIN, side, sole, (const float(*)[3])rot, q2), 0);
            for (int j = 0; j < PS_LEG_N_JOINTS; j++)
                if (fabsf(q2[j] - q[j]) > 2e-3f)
                    fail_msg("side %d joint %d: %g, want %g", side, j, (double)q2[j], (double)q[j]);
            ps_estimate_leg_fk_pose(&KIN, side, q2, sole2, NULL, rot2);
            for (int i = 0; i < 3; i++) {
                assert_float_equal(sole2[i], sole[i], 1e-4);
                for (int k = 0; k < 3; k++)
                    assert_float_equal(rot2[i][k], rot[i][k], 1e-4);
            }
        }
    }
}

/* By hand: foot flat, sole straight under the hip, ankle 0.5 m below the hip
 * centre. Thigh = shank = 0.28, so cos(knee/2) = 0.25 / 0.28:
 * knee = 2 acos(0.25 / 0.28) = 0.93883 rad, hip pitch = -knee / 2,
 * ankle pitch = -knee / 2, the rest 0. */
static void test_ps_legik_solve_flat_foot_under_hip_by_hand(void **st)
{
    (void)st;
    const float eye[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    const float sole[3] = {0.03f, 0.08f, -0.06f - 0.5f - 0.05f};
    float q[PS_LEG_N_JOINTS];
    assert_int_equal(ps_legik_solve(&KIN, 0, sole, eye, q), 0);
    const float knee = 2.0f * acosf(0.25f / 0.28f);
    assert_float_equal(q[PS_LEG_KNEE], knee, 1e-5);
    assert_float_equal(q[PS_LEG_HIP_PITCH], -0.5f * knee, 1e-5);
    assert_float_equal(q[PS_LEG_ANKLE_PITCH], -0.5f * knee, 1e-5);
    assert_float_equal(q[PS_LEG_HIP_YAW], 0.0f, 1e-6);
    assert_float_equal(q[PS_LEG_HIP_ROLL], 0.0f, 1e-6);
    assert_float_equal(q[PS_LEG_ANKLE_ROLL], 0.0f, 1e-6);
}

/* A yawed foot: the hip yaw takes it, the rest as without yaw. */
static void test_ps_legik_solve_yawed_foot_hip_yaw(void **st)
{
    (void)st;
    float rot[3][3], q[PS_LEG_N_JOINTS], sole[3];
    const float q_in[PS_LEG_N_JOINTS] = {0.3f, 0.0f, -0.4f, 0.8f, -0.4f, 0.0f};
    ps_estimate_leg_fk_pose(&KIN, 1, q_in, sole, NULL, rot);
    float want[3][3];
    ps_legik_rot_rpy(0.0f, 0.0f, 0.3f, want);
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++)
            assert_float_equal(rot[i][k], want[i][k], 1e-5);
    assert_int_equal(ps_legik_solve(&KIN, 1, sole, (const float(*)[3])want, q), 0);
    for (int j = 0; j < PS_LEG_N_JOINTS; j++)
        assert_float_equal(q[j], q_in[j], 1e-4);
}

static void test_ps_legik_solve_out_of_reach_straight_leg(void **st)
{
    (void)st;
    const float eye[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    const float far[3] = {0.03f, 0.08f, -1.5f};
    float q[PS_LEG_N_JOINTS];
    assert_int_equal(ps_legik_solve(&KIN, 0, far, eye, q), 1);
    assert_float_equal(q[PS_LEG_KNEE], 0.0f, 1e-3);
    assert_float_equal(q[PS_LEG_HIP_PITCH], 0.0f, 1e-3);
    const float near[3] = {0.03f, 0.08f, -0.06f - 0.05f};
    assert_int_equal(ps_legik_solve(&KIN, 0, near, eye, q), 1);
    assert_true(q[PS_LEG_KNEE] > 3.0f); /* folded */
}

static void test_ps_legik_solve_bad_args_einval(void **st)
{
    (void)st;
    const float eye[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    const float sole[3] = {0.0f, 0.08f, -0.6f};
    const float bad[3] = {0.0f, NAN, -0.6f};
    float q[PS_LEG_N_JOINTS];
    assert_int_equal(ps_legik_solve(NULL, 0, sole, eye, q), -EINVAL);
    assert_int_equal(ps_legik_solve(&KIN, 2, sole, eye, q), -EINVAL);
    assert_int_equal(ps_legik_solve(&KIN, 0, bad, eye, q), -EINVAL);
    assert_int_equal(ps_legik_solve(&KIN, 0, sole, eye, NULL), -EINVAL);
    ps_kinematics_cfg_t k0 = KIN;
    k0.thigh_m = 0.0f;
    assert_int_equal(ps_legik_solve(&k0, 0, sole, eye, q), -EINVAL);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ps_legik_solve_inverts_fk_both_legs),
        cmocka_unit_test(test_ps_legik_solve_flat_foot_under_hip_by_hand),
        cmocka_unit_test(test_ps_legik_solve_yawed_foot_hip_yaw),
        cmocka_unit_test(test_ps_legik_solve_out_of_reach_straight_leg),
        cmocka_unit_test(test_ps_legik_solve_bad_args_einval),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
