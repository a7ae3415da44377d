/*
 * Tests of policy/ps_obs.c on hand-made states: straight legs (every mass
 * point known, tests/test_balance.c), a pelvis placed by hand in the ground
 * frame, two builds for velocities: field values, layout, normalisation and
 * clipping, the ground frame moving with the feet, errors.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <math.h>
#include <string.h>

#include "../policy/ps_obs.h"

#define N_J 12

static ps_obs_cfg_t cfg_all(void)
{
    ps_obs_cfg_t c;
    memset(&c, 0, sizeof(c));
    for (int f = 0; f < (int)PS_OBS_FIELD_COUNT; f++)
        c.fields[c.n_fields++] = (ps_obs_field_t)f;
    c.n_joints = N_J;
    c.n_act = N_J;
    for (int j = 0; j < N_J; j++) {
        c.joint_idx[j] = (uint32_t)j;
        c.joint_offset_rad[j] = 0.1f;
    }
    for (int s = 0; s < 2; s++)
        for (int j = 0; j < PS_LEG_N_JOINTS; j++)
            c.leg_idx[s][j] = 6 * s + j;
    for (int i = 0; i < (int)PS_OBS_MAX; i++)
        c.std[i] = 1.0f;
    c.clip = 100.0f;
    c.dt_s = 0.02f;
    c.kin = (ps_kinematics_cfg_t){
        .mass_kg = 30.0f, .hip_offset_y_m = 0.1f, .hip_offset_z_m = 0.05f,
        .thigh_m = 0.3f, .shank_m = 0.3f, .ankle_height_m = 0.05f,
        .foot_length_m = 0.2f, .foot_width_m = 0.1f,
        .trunk_mass_kg = 20.0f, .trunk_com_z_m = 0.2f, .hip_mass_kg = 1.0f,
        .thigh_mass_kg = 2.0f, .thigh_com_m = 0.1f, .shank_mass_kg = 1.0f,
        .shank_com_m = 0.15f, .foot_mass_kg = 1.0f, .foot_com_x_m = 0.04f,
        .foot_com_z_m = -0.02f,
    };
    return c;
}

/* Straight legs, pelvis upright at (px, 0, 0.7) over soles at (fx, +-0.1, 0). */
static void state(ps_meas_t *m, ps_estimate_t *e, float px, float fx)
{
    memset(m, 0, sizeof(*m));
    memset(e, 0, sizeof(*e));
    m->n_joints = N_J;
    for (int j = 0; j < N_J; j++)
        m->joints[j].qd_rad_s = 0.01f * (float)j;
    m->imu.gyro_body_rad_s[1] = 0.3f;
    for (int i = 0; i < 3; i++)
        e->pelvis_rot[i][i] = 1.0f;
    e->pelvis_m[0] = px;
    e->pelvis_m[2] = 0.7f;
    e->foot_m[0][0] = e->foot_m[1][0] = fx;
    e->foot_m[0][1] = 0.1f;
    e->foot_m[1][1] = -0.1f;
    e->is_contact[0] = e->is_contact[1] = true;
    e->cop_m[0] = fx + 0.01f;
}

/* Offset of each field in the all-fields layout. */
static uint32_t at(ps_obs_field_t f)
{
    uint32_t n = 0;
    for (int i = 0; i < (int)f; i++)
        n += ps_obs_field_size((ps_obs_field_t)i, N_J, N_J);
    return n;
}

static void test_ps_obs_build_fields_by_hand(void **st)
{
    (void)st;
    const ps_obs_cfg_t c = cfg_all();
    ps_obs_t o;
    assert_int_equal(ps_obs_init(&o, &c), 0);
    assert_int_equal(o.n_obs, 3 + 3 + N_J + N_J + N_J + 3 + 3 + 2 + 2 + 1 + 6 + 2 + 6 + N_J);
    ps_meas_t m;
    ps_estimate_t e;
    float z[PS_OBS_MAX], raw[PS_OBS_MAX];
    state(&m, &e, 0.0f, 0.0f);
    assert_int_equal(ps_obs_build(&o, &m, &e, z, raw), (int)o.n_obs);
    /* upright: gravity straight down */
    assert_float_equal(raw[at(PS_OBS_GRAVITY_BODY) + 2], -1.0f, 1e-6);
    assert_float_equal(raw[at(PS_OBS_GYRO_BODY) + 1], 0.3f, 1e-6);
    assert_float_equal(raw[at(PS_OBS_JOINT_POS)], -0.1f, 1e-6); /* q 0 - offset 0.1 */
    assert_float_equal(raw[at(PS_OBS_JOINT_VEL) + 5], 0.05f, 1e-6);
    /* CoM: pelvis (0, 0, 0.7) + (0.08 / 30, 0, 0.032); BoS centre (0, 0) */
    assert_float_equal(raw[at(PS_OBS_COM_POS)], 0.08f / 30.0f, 1e-6);
    assert_float_equal(raw[at(PS_OBS_COM_POS) + 2], 0.732f, 1e-5);
    assert_float_equal(raw[at(PS_OBS_COM_VEL)], 0.0f, 0.0); /* first build */
    assert_float_equal(raw[at(PS_OBS_COP)], 0.01f, 1e-6);
    /* at rest the capture point is the CoM's ground point */
    assert_float_equal(raw[at(PS_OBS_CAPTURE_POINT)], 0.08f / 30.0f, 1e-6);
    /* BoS: 0.2 long, y from -0.15 to 0.15: margin = nearest edge (front/back) */
    assert_float_equal(raw[at(PS_OBS_BOS_MARGIN)], 0.1f - 0.08f / 30.0f, 1e-5);
    assert_float_equal(raw[at(PS_OBS_FEET) + 1], 0.1f, 1e-6);
    assert_float_equal(raw[at(PS_OBS_CONTACT) + 1], 1.0f, 0.0);

    /* 20 ms later the pelvis is 2 cm further forward: 1 m/s, capture point
     * 1 / sqrt(9.81 / 0.732) = 0.2732 m ahead of the CoM. */
    state(&m, &e, 0.02f, 0.0f);
    assert_int_equal(ps_obs_build(&o, &m, &e, z, raw), (int)o.n_obs);
    assert_float_equal(raw[at(PS_OBS_COM_VEL)], 1.0f, 1e-4);
    assert_float_equal(raw[at(PS_OBS_CAPTURE_POINT)],
                       0.02f + 0.08f / 30.0f + 1.0f / sqrtf(9.81f / 0.732f), 1e-4);
    assert_true(raw[at(PS_OBS_BOS_MARGIN)] < 0.0f); /* outside the feet */
    assert_float_equal(raw[at(PS_OBS_MOMENTUM)], 1.0f, 1e-4); /* p / M */
    assert_float_equal(raw[at(PS_OBS_MOMENTUM) + 4], 0.0f, 1e-4);

    /* the estimator's ground frame recentres between the soles: when the
     * pelvis and both soles shift by the same -5 cm in that frame, the robot
     * has not moved over the ground (velocity 0) */
    state(&m, &e, -0.03f, -0.05f);
    assert_int_equal(ps_obs_build(&o, &m, &e, z, raw), (int)o.n_obs);
    assert_float_equal(raw[at(PS_OBS_COM_VEL)], 0.0f, 1e-3);
}

static void test_ps_obs_build_normalises_and_clips(void **st)
{
    (void)st;
    ps_obs_cfg_t c = cfg_all();
    c.mean[at(PS_OBS_GYRO_BODY) + 1] = 0.1f;
    c.std[at(PS_OBS_GYRO_BODY) + 1] = 0.5f;
    c.clip = 0.5f;
    ps_obs_t o;
    assert_int_equal(ps_obs_init(&o, &c), 0);
    ps_meas_t m;
    ps_estimate_t e;
    state(&m, &e, 0.0f, 0.0f);
    float z[PS_OBS_MAX], raw[PS_OBS_MAX];
    assert_true(ps_obs_build(&o, &m, &e, z, raw) > 0);
    assert_float_equal(z[at(PS_OBS_GYRO_BODY) + 1], (0.3f - 0.1f) / 0.5f, 1e-6);
    assert_float_equal(z[at(PS_OBS_GRAVITY_BODY) + 2], -0.5f, 0.0); /* -1 clipped */
    /* prev_action carries what the policy applied */
    float a[N_J];
    for (int j = 0; j < N_J; j++)
        a[j] = 0.01f * (float)j;
    ps_obs_set_action(&o, a);
    assert_true(ps_obs_build(&o, &m, &e, z, raw) > 0);
    assert_float_equal(raw[at(PS_OBS_PREV_ACTION) + 3], 0.03f, 1e-7);
    /* base_action carries the residual's base, apart from prev_action */
    float b[N_J];
    for (int j = 0; j < N_J; j++)
        b[j] = -0.02f * (float)j;
    ps_obs_set_base_action(&o, b);
    assert_true(ps_obs_build(&o, &m, &e, z, raw) > 0);
    assert_float_equal(raw[at(PS_OBS_BASE_ACTION) + 3], -0.06f, 1e-7);
    assert_float_equal(raw[at(PS_OBS_PREV_ACTION) + 3], 0.03f, 1e-7);
    ps_obs_reset(&o);
    assert_true(ps_obs_build(&o, &m, &e, z, raw) > 0);
    assert_float_equal(raw[at(PS_OBS_PREV_ACTION) + 3], 0.0f, 0.0);
    assert_float_equal(raw[at(PS_OBS_BASE_ACTION) + 3], 0.0f, 0.0);
}

/* A subset in another order: the layout follows the list. */
static void test_ps_obs_layout_follows_field_list(void **st)
{
    (void)st;
    ps_obs_cfg_t c = cfg_all();
    c.n_fields = 2;
    c.fields[0] = PS_OBS_CONTACT;
    c.fields[1] = PS_OBS_GRAVITY_BODY;
    ps_obs_t o;
    assert_int_equal(ps_obs_init(&o, &c), 0);
    assert_int_equal(o.n_obs, 5);
    ps_meas_t m;
    ps_estimate_t e;
    state(&m, &e, 0.0f, 0.0f);
    e.is_contact[1] = false;
    float z[PS_OBS_MAX];
    assert_int_equal(ps_obs_build(&o, &m, &e, z, NULL), 5);
    assert_float_equal(z[0], 1.0f, 0.0);
    assert_float_equal(z[1], 0.0f, 0.0);
    assert_float_equal(z[4], -1.0f, 1e-6);
    assert_int_equal(ps_obs_field_find("capture_point"), PS_OBS_CAPTURE_POINT);
    assert_int_equal(ps_obs_field_find("nope"), -ENOENT);
    assert_string_equal(ps_obs_field_name(PS_OBS_MOMENTUM), "momentum");
    assert_int_equal(ps_obs_field_find("base_action"), PS_OBS_BASE_ACTION);
}

static void test_ps_obs_errors(void **st)
{
    (void)st;
    ps_obs_cfg_t c = cfg_all();
    ps_obs_t o;
    ps_obs_cfg_t bad = c;
    bad.std[3] = 0.0f;
    assert_int_equal(ps_obs_init(&o, &bad), -EINVAL);
    bad = c;
    bad.kin.trunk_mass_kg = 0.0f;
    assert_int_equal(ps_obs_init(&o, &bad), -EINVAL);
    bad = c;
    bad.fields[0] = PS_OBS_FIELD_COUNT;
    assert_int_equal(ps_obs_init(&o, &bad), -EINVAL);
    bad = c;
    bad.clip = 0.0f;
    assert_int_equal(ps_obs_init(&o, &bad), -EINVAL);
    assert_int_equal(ps_obs_init(&o, &c), 0);
    ps_meas_t m;
    ps_estimate_t e;
    state(&m, &e, 0.0f, 0.0f);
    float z[PS_OBS_MAX];
    m.joints[3].q_rad = NAN; /* a leg joint: the geometry fails */
    assert_int_equal(ps_obs_build(&o, &m, &e, z, NULL), -ERANGE);
    for (uint32_t i = 0; i < o.n_obs; i++)
        assert_true(isfinite(z[i])); /* never NaN into a network */
    state(&m, &e, 0.0f, 0.0f);
    e.is_contact[0] = e.is_contact[1] = false; /* no base of support */
    assert_int_equal(ps_obs_build(&o, &m, &e, z, NULL), -ERANGE);
    assert_int_equal(ps_obs_build(NULL, &m, &e, z, NULL), -EINVAL);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ps_obs_build_fields_by_hand),
        cmocka_unit_test(test_ps_obs_build_normalises_and_clips),
        cmocka_unit_test(test_ps_obs_layout_follows_field_list),
        cmocka_unit_test(test_ps_obs_errors),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
