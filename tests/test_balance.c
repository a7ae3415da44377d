/*
 * Tests of policy/ps_balance.c on hand-made cases: gravity direction, the
 * point-mass model in a straight-leg pose, CoM, momentum of simple motions,
 * capture point, support polygon and its signed distance, CoP.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <math.h>
#include <string.h>

#include "../policy/ps_balance.h"

static void test_ps_balance_gravity_body_hand_cases(void **st)
{
    (void)st;
    float g[3];
    ps_balance_gravity_body(0.0f, 0.0f, g);
    assert_float_equal(g[0], 0.0f, 1e-7);
    assert_float_equal(g[1], 0.0f, 1e-7);
    assert_float_equal(g[2], -1.0f, 1e-7);
    /* leaning forward (pitch > 0): gravity points forward in the trunk frame */
    ps_balance_gravity_body(0.0f, 0.5f, g);
    assert_float_equal(g[0], sinf(0.5f), 1e-6);
    assert_float_equal(g[2], -cosf(0.5f), 1e-6);
    /* rolled right side down (roll > 0 tips the top toward -y): gravity toward -y */
    ps_balance_gravity_body(0.5f, 0.0f, g);
    assert_float_equal(g[1], -sinf(0.5f), 1e-6);
    assert_float_equal(g[0] * g[0] + g[1] * g[1] + g[2] * g[2], 1.0f, 1e-6);
}

static ps_kinematics_cfg_t kin(void)
{
    return (ps_kinematics_cfg_t){
        .mass_kg = 30.0f,
        .hip_offset_y_m = 0.1f,
        .hip_offset_z_m = 0.05f,
        .thigh_m = 0.3f,
        .shank_m = 0.3f,
        .ankle_height_m = 0.05f,
        .trunk_mass_kg = 20.0f,
        .trunk_com_z_m = 0.2f,
        .hip_mass_kg = 1.0f,
        .thigh_mass_kg = 2.0f,
        .thigh_com_m = 0.1f,
        .shank_mass_kg = 1.0f,
        .shank_com_m = 0.15f,
        .foot_mass_kg = 1.0f,
        .foot_com_x_m = 0.04f,
        .foot_com_z_m = -0.02f,
    };
}

/* Straight legs: every leg point straight below its hip. CoM z by hand:
 * (20 * 0.2 + 2 * (1 * -0.05 + 2 * -0.15 + 1 * -0.5 + 1 * -0.67)) / 30
 * = (4 - 3.04) / 30 = 0.032; x = 2 * 1 * 0.04 / 30; y = 0 by symmetry. */
static void test_ps_balance_points_straight_legs_by_hand(void **st)
{
    (void)st;
    const ps_kinematics_cfg_t k = kin();
    const float q[2][PS_LEG_N_JOINTS] = {{0}};
    ps_balance_point_t p[PS_BALANCE_N_POINTS];
    assert_int_equal(ps_balance_points(&k, q, p), (int)PS_BALANCE_N_POINTS);
    assert_float_equal(p[2].pos_m[2], -0.15f, 1e-6); /* left thigh */
    assert_float_equal(p[2].pos_m[1], 0.1f, 1e-6);
    assert_float_equal(p[7].pos_m[2], -0.5f, 1e-6);  /* right shank */
    assert_float_equal(p[8].pos_m[0], 0.04f, 1e-6);  /* right foot */
    assert_float_equal(p[8].pos_m[1], -0.1f, 1e-6);
    float c[3];
    assert_int_equal(ps_balance_com(p, PS_BALANCE_N_POINTS, c), 0);
    assert_float_equal(c[2], 0.032f, 1e-6);
    assert_float_equal(c[0], 0.08f / 30.0f, 1e-6);
    assert_float_equal(c[1], 0.0f, 1e-6);
    /* knee bent 90 deg: the shank points back (-x), its CoM 0.15 behind the knee */
    float qb[2][PS_LEG_N_JOINTS] = {{0}};
    qb[0][PS_LEG_KNEE] = 1.5707963f;
    assert_int_equal(ps_balance_points(&k, qb, p), (int)PS_BALANCE_N_POINTS);
    assert_float_equal(p[3].pos_m[0], -0.15f, 1e-5);
    assert_float_equal(p[3].pos_m[2], -0.35f, 1e-5);
    ps_kinematics_cfg_t none = k;
    none.trunk_mass_kg = 0.0f;
    assert_int_equal(ps_balance_points(&none, q, p), -EINVAL);
}

static void test_ps_balance_com_weighted_and_errors(void **st)
{
    (void)st;
    const ps_balance_point_t p[2] = {{{0, 0, 0}, 1.0f}, {{4, 2, 0}, 3.0f}};
    float c[3];
    assert_int_equal(ps_balance_com(p, 2, c), 0);
    assert_float_equal(c[0], 3.0f, 1e-6);
    assert_float_equal(c[1], 1.5f, 1e-6);
    const ps_balance_point_t z[1] = {{{1, 1, 1}, 0.0f}};
    assert_int_equal(ps_balance_com(z, 1, c), -EINVAL);
    assert_int_equal(ps_balance_com(p, 0, c), -EINVAL);
}

/* Translation: p = M v, L = 0. Two 1 kg masses at x = +-1 moving -+v in y
 * (a spin about +z): p = 0, L_z = 2 * 1 * 1 * v. */
static void test_ps_balance_momentum_translation_and_spin(void **st)
{
    (void)st;
    const float dt = 0.01f, v = 0.5f;
    ps_balance_point_t a[2] = {{{1, 0, 0}, 1.0f}, {{-1, 0, 0}, 2.0f}}, b[2];
    memcpy(b, a, sizeof(a));
    for (int i = 0; i < 2; i++)
        a[i].pos_m[0] += v * dt;
    float p[3], l[3];
    assert_int_equal(ps_balance_momentum(a, b, 2, dt, p, l), 0);
    assert_float_equal(p[0], 3.0f * v, 1e-4);
    assert_float_equal(l[2], 0.0f, 1e-5);
    ps_balance_point_t s[2] = {{{1, 0, 0}, 1.0f}, {{-1, 0, 0}, 1.0f}}, s0[2];
    memcpy(s0, s, sizeof(s));
    s[0].pos_m[1] += v * dt;
    s[1].pos_m[1] -= v * dt;
    assert_int_equal(ps_balance_momentum(s, s0, 2, dt, p, l), 0);
    assert_float_equal(p[1], 0.0f, 1e-5);
    assert_float_equal(l[2], 2.0f * v, 1e-3);
    assert_int_equal(ps_balance_momentum(s, s0, 2, 0.0f, p, l), -EINVAL);
}

/* z = 0.981 m, g = 9.81: omega0 = sqrt(10); v = 1 m/s -> xi = c + 0.31623. */
static void test_ps_balance_capture_point_lipm(void **st)
{
    (void)st;
    const float c[3] = {0.1f, -0.05f, 0.981f}, v[3] = {1.0f, 0.0f, 0.0f};
    float xi[2];
    assert_int_equal(ps_balance_capture_point(c, v, 9.81f, xi), 0);
    assert_float_equal(xi[0], 0.1f + 0.316228f, 1e-5);
    assert_float_equal(xi[1], -0.05f, 1e-6);
    const float low[3] = {0, 0, 0};
    assert_int_equal(ps_balance_capture_point(low, v, 9.81f, xi), -EINVAL);
}

/* One sole 0.2 x 0.1 at the origin: 4 corners, distance 0.05 at the centre
 * (nearest long edge), -0.1 at (0.2, 0). Two parallel soles at y = +-0.1:
 * the hull is the outer rectangle (4 corners, collinear ones dropped), the
 * centre between them, 0.1 from each long side at the midpoint... */
static void test_ps_balance_support_polygon_and_distance(void **st)
{
    (void)st;
    const float soles[2][2] = {{0, 0.1f}, {0, -0.1f}};
    const float yaw[2] = {0, 0};
    const bool one[2] = {true, false}, both[2] = {true, true}, none[2] = {false, false};
    float poly[PS_BALANCE_MAX_POLY][2];
    int n = ps_balance_support_polygon(soles, yaw, one, 0.2f, 0.1f, poly);
    assert_int_equal(n, 4);
    const float at_c[2] = {0, 0.1f}, out[2] = {0.2f, 0.1f}, mid[2] = {0, 0};
    assert_float_equal(ps_balance_polygon_distance((const float(*)[2])poly, n, at_c), 0.05f, 1e-6);
    assert_float_equal(ps_balance_polygon_distance((const float(*)[2])poly, n, out), -0.1f, 1e-6);
    assert_true(ps_balance_polygon_distance((const float(*)[2])poly, n, mid) < 0.0f);
    n = ps_balance_support_polygon(soles, yaw, both, 0.2f, 0.1f, poly);
    assert_int_equal(n, 4);
    assert_float_equal(ps_balance_polygon_distance((const float(*)[2])poly, n, mid), 0.1f, 1e-6);
    float c[2];
    assert_int_equal(ps_balance_polygon_centre((const float(*)[2])poly, n, c), 0);
    assert_float_equal(c[0], 0.0f, 1e-6);
    assert_float_equal(c[1], 0.0f, 1e-6);
    /* counter-clockwise: positive cross product of consecutive edges */
    for (int i = 0; i < n; i++) {
        const float *a = poly[i], *b = poly[(i + 1) % n], *d = poly[(i + 2) % n];
        assert_true((b[0] - a[0]) * (d[1] - a[1]) - (b[1] - a[1]) * (d[0] - a[0]) > 0.0f);
    }
    /* a turned foot (yaw 90 deg) at (0.3, 0): 8-corner hulls stay convex */
    const float soles2[2][2] = {{0, 0.1f}, {0.3f, -0.1f}};
    const float yaw2[2] = {0, 1.5707963f};
    n = ps_balance_support_polygon(soles2, yaw2, both, 0.2f, 0.1f, poly);
    assert_true(n >= 5 && n <= 8);
    const float between[2] = {0.15f, 0.0f};
    assert_true(ps_balance_polygon_distance((const float(*)[2])poly, n, between) > 0.0f);
    assert_int_equal(ps_balance_support_polygon(soles, yaw, none, 0.2f, 0.1f, poly), 0);
    assert_int_equal(ps_balance_support_polygon(soles, yaw, both, 0.0f, 0.1f, poly), -EINVAL);
    assert_true(isinf(ps_balance_polygon_distance(NULL, 0, mid)));
}

static void test_ps_balance_cop_weighted(void **st)
{
    (void)st;
    const float pts[2][2] = {{0, 0.1f}, {0.2f, -0.1f}};
    const float f[2] = {300.0f, 100.0f};
    float cop[2];
    assert_int_equal(ps_balance_cop(pts, f, 2, cop), 0);
    assert_float_equal(cop[0], 0.05f, 1e-6);
    assert_float_equal(cop[1], 0.05f, 1e-6);
    const float f0[2] = {0, 0};
    assert_int_equal(ps_balance_cop(pts, f0, 2, cop), -EINVAL);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ps_balance_gravity_body_hand_cases),
        cmocka_unit_test(test_ps_balance_points_straight_legs_by_hand),
        cmocka_unit_test(test_ps_balance_com_weighted_and_errors),
        cmocka_unit_test(test_ps_balance_momentum_translation_and_spin),
        cmocka_unit_test(test_ps_balance_capture_point_lipm),
        cmocka_unit_test(test_ps_balance_support_polygon_and_distance),
        cmocka_unit_test(test_ps_balance_cop_weighted),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
