/*
 * Tests for policy/ps_servo: each state's command for a hand-built joint,
 * clamping at every limit, the torque-limited set-point, invalid targets,
 * the ramp blend, and a randomized property test (every output is inside
 * the joint's limits and wire range, whatever goes in).
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <float.h>
#include <math.h>
#include <string.h>

#include "../drivers/ps_actuator.h"
#include "../policy/ps_servo.h"
#include "../rt/ps_err.h"
#include "fakes/ps_test_wire.h"

#define TOL 1e-6f

typedef struct {
    ps_servo_joint_cfg_t j;
    ps_servo_cfg_t c;
    ps_targets_t t;
    float meas_q[PS_MAX_JOINTS];
    float from_q[PS_MAX_JOINTS];
    ps_servo_mode_t mode;
} fixture_t;

/* A joint whose configured limits are all tighter than its wire range. */
static ps_servo_joint_cfg_t make_joint(void)
{
    ps_servo_joint_cfg_t j;
    memset(&j, 0, sizeof j);
    j.wire = ps_test_wire_ak();
    j.lim.pos_min_rad = -1.0f;
    j.lim.pos_max_rad = 2.0f;
    j.lim.vel_max_rad_s = 10.0f;
    j.lim.torque_max_nm = 12.0f;
    j.kp_nm_rad = 80.0f;
    j.kd_nm_s_rad = 2.0f;
    j.lim.kp_max_nm_rad = 200.0f;
    j.lim.kd_max_nm_s_rad = 4.0f;
    j.stance_rad = 0.5f;
    return j;
}

static int setup(void **state)
{
    fixture_t *f = test_calloc(1, sizeof *f);
    if (f == NULL)
        return -1;
    f->j = make_joint();
    f->c.damping_kd_nm_s_rad = 3.0f;
    f->t.n_joints = 4;
    f->mode.kind = PS_SERVO_TRACK;
    f->mode.ramp_alpha = 1.0f;
    f->mode.ramp_from_q_rad = f->from_q;
    f->mode.meas_q_rad = f->meas_q;
    *state = f;
    return 0;
}

static int teardown(void **state)
{
    test_free(*state);
    return 0;
}

/* Joint 1 of the fixture: set measurement and target. */
static void set_joint1(fixture_t *f, float meas_q, float q, float qd, float tau)
{
    f->meas_q[1] = meas_q;
    f->t.q_rad[1] = q;
    f->t.qd_rad_s[1] = qd;
    f->t.tau_ff_nm[1] = tau;
}

static int run1(fixture_t *f, ps_servo_mode_kind_t s, ps_act_cmd_t *out)
{
    f->mode.kind = s;
    return ps_servo_command(&f->j, &f->c, &f->mode, 1u, &f->t, out);
}

static void assert_cmd(const ps_act_cmd_t *got, float p, float v, float kp, float kd, float tau)
{
    assert_float_equal(got->q_rad, p, TOL);
    assert_float_equal(got->qd_rad_s, v, TOL);
    assert_float_equal(got->kp_nm_rad, kp, TOL);
    assert_float_equal(got->kd_nm_s_rad, kd, TOL);
    assert_float_equal(got->tau_ff_nm, tau, TOL);
}

/* ---- per-state commands --------------------------------------------------- */

static void test_ps_servo_command_standby_limp_at_measured(void **state)
{
    fixture_t *f = *state;
    ps_act_cmd_t out;
    set_joint1(f, 0.7f, 1.5f, 3.0f, 5.0f);
    assert_int_equal(run1(f, PS_SERVO_LIMP, &out), 0);
    assert_cmd(&out, 0.7f, 0.0f, 0.0f, 0.0f, 0.0f);
    /* targets are not read: NULL is fine, garbage is fine */
    f->mode.kind = PS_SERVO_LIMP;
    assert_int_equal(ps_servo_command(&f->j, &f->c, &f->mode, 1u, NULL, &out), 0);
    assert_cmd(&out, 0.7f, 0.0f, 0.0f, 0.0f, 0.0f);
    f->t.q_rad[1] = NAN;
    assert_int_equal(run1(f, PS_SERVO_LIMP, &out), 0);
    assert_cmd(&out, 0.7f, 0.0f, 0.0f, 0.0f, 0.0f);
}

static void test_ps_servo_command_estop_limp_clamped_into_limits(void **state)
{
    fixture_t *f = *state;
    ps_act_cmd_t out;
    set_joint1(f, 3.0f, 0.0f, 0.0f, 0.0f); /* joint pushed past pos_max */
    assert_int_equal(run1(f, PS_SERVO_LIMP, &out), 0);
    assert_cmd(&out, 2.0f, 0.0f, 0.0f, 0.0f, 0.0f);
    f->meas_q[1] = -7.0f;
    assert_int_equal(run1(f, PS_SERVO_LIMP, &out), 0);
    assert_cmd(&out, -1.0f, 0.0f, 0.0f, 0.0f, 0.0f);
    /* unusable measurement: the stance, still limp */
    f->meas_q[1] = NAN;
    assert_int_equal(run1(f, PS_SERVO_LIMP, &out), 0);
    assert_cmd(&out, 0.5f, 0.0f, 0.0f, 0.0f, 0.0f);
}

static void test_ps_servo_command_damping_kd_only(void **state)
{
    fixture_t *f = *state;
    ps_act_cmd_t out;
    set_joint1(f, -0.3f, 1.0f, 1.0f, 1.0f);
    assert_int_equal(run1(f, PS_SERVO_DAMP, &out), 0);
    assert_cmd(&out, -0.3f, 0.0f, 0.0f, 3.0f, 0.0f);
    /* damping kd above kd_max: clamped to kd_max */
    f->c.damping_kd_nm_s_rad = 10.0f;
    assert_int_equal(run1(f, PS_SERVO_DAMP, &out), 0);
    assert_cmd(&out, -0.3f, 0.0f, 0.0f, 4.0f, 0.0f);
    /* wire kd range tighter than kd_max: clamped to the wire */
    f->j.wire.kd_max_nm_s_rad = 3.5f;
    assert_int_equal(run1(f, PS_SERVO_DAMP, &out), 0);
    assert_cmd(&out, -0.3f, 0.0f, 0.0f, 3.5f, 0.0f);
    /* NaN damping kd (never passes ps_config): limp rather than garbage */
    f->c.damping_kd_nm_s_rad = NAN;
    assert_int_equal(run1(f, PS_SERVO_DAMP, &out), 0);
    assert_cmd(&out, -0.3f, 0.0f, 0.0f, 0.0f, 0.0f);
}

/* HOLD: the hold pose with the configured gains, v = tau = 0, targets not
 * read; the stance when no pose is given; torque-limited like TRACK. Joint:
 * kp 80, kd 2, torque_max 12, stance 0.5, limits [-1, 2]. */
static void test_ps_servo_command_hold_pose_stiff_torque_limited(void **state)
{
    fixture_t *f = *state;
    float hold[PS_MAX_JOINTS] = {0};
    hold[1] = 0.8f;
    f->mode.hold_q_rad = hold;
    ps_act_cmd_t out;
    set_joint1(f, 0.75f, NAN, NAN, NAN); /* garbage targets: not read in HOLD */
    assert_int_equal(run1(f, PS_SERVO_HOLD, &out), 0);
    assert_cmd(&out, 0.8f, 0.0f, 80.0f, 2.0f, 0.0f);
    assert_int_equal(ps_servo_command(&f->j, &f->c, &f->mode, 1u, NULL, &out), 0);
    assert_cmd(&out, 0.8f, 0.0f, 80.0f, 2.0f, 0.0f);
    /* far from the measurement: p pulled to q + 12 / 80 = 0.15 rad away */
    f->meas_q[1] = 0.0f;
    assert_int_equal(run1(f, PS_SERVO_HOLD, &out), 0);
    assert_cmd(&out, 0.15f, 0.0f, 80.0f, 2.0f, 0.0f);
    /* no pose, or a non-finite one: the stance */
    f->meas_q[1] = 0.5f;
    hold[1] = NAN;
    assert_int_equal(run1(f, PS_SERVO_HOLD, &out), 0);
    assert_cmd(&out, 0.5f, 0.0f, 80.0f, 2.0f, 0.0f);
    f->mode.hold_q_rad = NULL;
    assert_int_equal(run1(f, PS_SERVO_HOLD, &out), 0);
    assert_cmd(&out, 0.5f, 0.0f, 80.0f, 2.0f, 0.0f);
    /* a hold pose outside the limits is clamped into them */
    hold[1] = 5.0f;
    f->mode.hold_q_rad = hold;
    f->meas_q[1] = 1.95f;
    assert_int_equal(run1(f, PS_SERVO_HOLD, &out), 0);
    assert_cmd(&out, 2.0f, 0.0f, 80.0f, 2.0f, 0.0f);
    /* the measurement unusable: damping, and the error */
    f->meas_q[1] = NAN;
    assert_int_equal(run1(f, PS_SERVO_HOLD, &out), -PS_ERR_LIMIT);
    assert_cmd(&out, 0.5f, 0.0f, 0.0f, 3.0f, 0.0f);
    assert_string_equal(ps_servo_mode_name(PS_SERVO_HOLD), "hold");
    assert_string_equal(ps_servo_mode_name(PS_SERVO_MODE_COUNT), "?");
}

static void test_ps_servo_command_active_targets_and_gains(void **state)
{
    fixture_t *f = *state;
    ps_act_cmd_t out;
    /* window (12 - 1) / 80 = 0.1375 rad around q: target 0.1 away is kept */
    set_joint1(f, 0.2f, 0.3f, 0.5f, 1.0f);
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), 0);
    assert_cmd(&out, 0.3f, 0.5f, 80.0f, 2.0f, 1.0f);
    assert_true(ps_servo_is_within_limits(&f->j, &out));
}

/* ---- clamping at each limit ------------------------------------------------- */

static void test_ps_servo_command_active_velocity_clamped_both_sides(void **state)
{
    fixture_t *f = *state;
    ps_act_cmd_t out;
    set_joint1(f, 0.0f, 0.0f, 100.0f, 0.0f);
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), 0);
    assert_float_equal(out.qd_rad_s, 10.0f, TOL);
    f->t.qd_rad_s[1] = -100.0f;
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), 0);
    assert_float_equal(out.qd_rad_s, -10.0f, TOL);
    /* exactly at the limit: kept */
    f->t.qd_rad_s[1] = 10.0f;
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), 0);
    assert_float_equal(out.qd_rad_s, 10.0f, TOL);
    /* wire tighter than vel_max */
    f->j.wire.v_min_rad_s = -8.0f;
    f->j.wire.v_max_rad_s = 8.0f;
    f->t.qd_rad_s[1] = -9.0f;
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), 0);
    assert_float_equal(out.qd_rad_s, -8.0f, TOL);
}

static void test_ps_servo_command_active_gains_clamped_to_max(void **state)
{
    fixture_t *f = *state;
    ps_act_cmd_t out;
    set_joint1(f, 0.4f, 0.4f, 0.0f, 0.0f); /* on target: window irrelevant */
    f->j.kp_nm_rad = 300.0f;
    f->j.kd_nm_s_rad = 10.0f;
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), 0);
    assert_float_equal(out.kp_nm_rad, 200.0f, TOL);
    assert_float_equal(out.kd_nm_s_rad, 4.0f, TOL);
    /* wire kp tighter than kp_max */
    f->j.wire.kp_max_nm_rad = 150.0f;
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), 0);
    assert_float_equal(out.kp_nm_rad, 150.0f, TOL);
    /* negative configured gains never leave negative */
    f->j.kp_nm_rad = -5.0f;
    f->j.kd_nm_s_rad = -1.0f;
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), 0);
    assert_float_equal(out.kp_nm_rad, 0.0f, 0.0f);
    assert_float_equal(out.kd_nm_s_rad, 0.0f, 0.0f);
}

static void test_ps_servo_command_active_torque_ff_clamped_both_sides(void **state)
{
    fixture_t *f = *state;
    ps_act_cmd_t out;
    set_joint1(f, 0.0f, 0.0f, 0.0f, 50.0f);
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), 0);
    assert_float_equal(out.tau_ff_nm, 12.0f, TOL);
    f->t.tau_ff_nm[1] = -50.0f;
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), 0);
    assert_float_equal(out.tau_ff_nm, -12.0f, TOL);
    /* wire tighter than torque_max */
    f->j.wire.t_min_nm = -9.0f;
    f->j.wire.t_max_nm = 9.0f;
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), 0);
    assert_float_equal(out.tau_ff_nm, -9.0f, TOL);
}

static void test_ps_servo_command_active_position_limits_inclusive(void **state)
{
    fixture_t *f = *state;
    ps_act_cmd_t out;
    set_joint1(f, 2.0f, 2.0f, 0.0f, 0.0f);
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), 0);
    assert_float_equal(out.q_rad, 2.0f, 0.0f);
    set_joint1(f, -1.0f, -1.0f, 0.0f, 0.0f);
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), 0);
    assert_float_equal(out.q_rad, -1.0f, 0.0f);
    /* one float step beyond: refused */
    f->t.q_rad[1] = nextafterf(-1.0f, -2.0f);
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), -PS_ERR_LIMIT);
    f->t.q_rad[1] = nextafterf(2.0f, 3.0f);
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), -PS_ERR_LIMIT);
}

/* ---- torque-limited set-point ------------------------------------------------ */

static void test_ps_servo_command_active_far_target_torque_limited(void **state)
{
    fixture_t *f = *state;
    ps_act_cmd_t out;
    /* budget 12 - |4| = 8 Nm, kp 80: p within q +/- 0.1 rad */
    set_joint1(f, 0.0f, 1.0f, 0.0f, 4.0f);
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), 0);
    assert_cmd(&out, 0.1f, 0.0f, 80.0f, 2.0f, 4.0f);
    /* the sign of tau_ff does not matter, the direction of the error does */
    set_joint1(f, 0.0f, -0.9f, 0.0f, -4.0f);
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), 0);
    assert_cmd(&out, -0.1f, 0.0f, 80.0f, 2.0f, -4.0f);
    /* feed-forward uses the whole torque: no spring torque left, p = q */
    set_joint1(f, 0.3f, 1.0f, 0.0f, 12.0f);
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), 0);
    assert_cmd(&out, 0.3f, 0.0f, 80.0f, 2.0f, 12.0f);
    /* feed-forward clamped first (50 -> 12), budget computed after */
    set_joint1(f, 0.3f, 1.0f, 0.0f, 50.0f);
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), 0);
    assert_cmd(&out, 0.3f, 0.0f, 80.0f, 2.0f, 12.0f);
}

static void test_ps_servo_command_measured_outside_limits_kp_lowered(void **state)
{
    fixture_t *f = *state;
    ps_act_cmd_t out;
    /* q = 2.5 is 0.5 rad past pos_max = 2.0; window q +/- 12/80 = [2.35, 2.65]
     * does not meet the limits, so p = 2.0 and kp = 12 / 0.5 = 24 */
    set_joint1(f, 2.5f, 1.9f, 0.0f, 0.0f);
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), 0);
    assert_cmd(&out, 2.0f, 0.0f, 24.0f, 2.0f, 0.0f);
    assert_true(out.kp_nm_rad * fabsf(out.q_rad - 2.5f) <= 12.0f * (1.0f + 1e-5f));
}

/* The command encoded by MIT mode on the joint's wire range (gear 1). */
static int encode_mit(const ps_servo_joint_cfg_t *j, const ps_act_cmd_t *cmd)
{
    const ps_act_cfg_t a = {.can_id = 1,
                            .reply_id = 2,
                            .protocol = PS_ACT_PROTO_MIT,
                            .wire = j->wire,
                            .gear_ratio = 1.0f,
                            .direction = 1.0f,
                            .kt_nm_a = 1.0f,
                            .temp_max_c = 80.0f,
                            .rate_div = 1};
    ps_can_frame_t frames[PS_ACT_MAX_FRAMES];
    return ps_act_encode_command(&a, cmd, frames, PS_ACT_MAX_FRAMES);
}

/* ---- encodability ------------------------------------------------------------------ */

/* A joint whose limits are its wire range, driven into the corner where
 * every field is at its maximum: in MIT mode that would pack into the
 * ENTER/EXIT/ZERO special frame. The servo layer knows no protocol: its
 * command is inside the limits, and the MIT encoder steps out of the corner
 * (tests/test_mit.c checks how). */
static void test_ps_servo_command_wire_corner_still_encodes(void **state)
{
    fixture_t *f = *state;
    ps_servo_joint_cfg_t *j = &f->j;
    j->lim.pos_min_rad = j->wire.p_min_rad;
    j->lim.pos_max_rad = j->wire.p_max_rad;
    j->lim.vel_max_rad_s = j->wire.v_max_rad_s;
    j->kp_nm_rad = j->lim.kp_max_nm_rad = j->wire.kp_max_nm_rad;
    j->kd_nm_s_rad = j->lim.kd_max_nm_s_rad = j->wire.kd_max_nm_s_rad;
    j->lim.torque_max_nm = j->wire.t_max_nm;
    const float taus[] = {17.99f, 17.98f, 17.974f}; /* packed 0xFFE, 0xFFD, 0xFFC */
    for (size_t i = 0; i < 3; i++) {
        set_joint1(f, 12.5f, 12.5f, 45.0f, taus[i]);
        ps_act_cmd_t out;
        assert_int_equal(run1(f, PS_SERVO_TRACK, &out), 0);
        assert_true(ps_servo_is_within_limits(j, &out));
        assert_float_equal(out.kd_nm_s_rad, j->wire.kd_max_nm_s_rad, 0.0f);
        /* the command still goes out as one set-point frame */
        assert_int_equal(encode_mit(j, &out), 1);
    }
}

/* ---- invalid targets ------------------------------------------------------------ */

static void test_ps_servo_command_invalid_target_limit_and_damping(void **state)
{
    fixture_t *f = *state;
    const float bad_q[] = {NAN, INFINITY, -INFINITY, -1.5f, 2.5f, 1e30f, -FLT_MAX};
    for (size_t i = 0; i < sizeof bad_q / sizeof bad_q[0]; i++) {
        for (int s = PS_SERVO_RAMP; s <= PS_SERVO_TRACK; s++) {
            ps_act_cmd_t out;
            memset(&out, 0xAB, sizeof out);
            set_joint1(f, 0.25f, bad_q[i], 0.0f, 0.0f);
            f->mode.ramp_alpha = 0.5f;
            f->from_q[1] = 0.0f;
            assert_int_equal(run1(f, (ps_servo_mode_kind_t)s, &out), -PS_ERR_LIMIT);
            assert_cmd(&out, 0.25f, 0.0f, 0.0f, 3.0f, 0.0f);
        }
    }
}

static void test_ps_servo_command_nonfinite_velocity_or_torque_limit(void **state)
{
    fixture_t *f = *state;
    ps_act_cmd_t out;
    set_joint1(f, 0.25f, 0.3f, NAN, 0.0f);
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), -PS_ERR_LIMIT);
    assert_cmd(&out, 0.25f, 0.0f, 0.0f, 3.0f, 0.0f);
    set_joint1(f, 0.25f, 0.3f, 0.0f, -INFINITY);
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), -PS_ERR_LIMIT);
    assert_cmd(&out, 0.25f, 0.0f, 0.0f, 3.0f, 0.0f);
}

static void test_ps_servo_command_joint_without_target_limit(void **state)
{
    fixture_t *f = *state;
    ps_act_cmd_t out;
    set_joint1(f, 0.25f, 0.3f, 0.0f, 0.0f);
    f->t.n_joints = 1; /* policy produced joint 0 only */
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), -PS_ERR_LIMIT);
    assert_cmd(&out, 0.25f, 0.0f, 0.0f, 3.0f, 0.0f);
}

static void test_ps_servo_command_measurement_nan_in_active_limit(void **state)
{
    fixture_t *f = *state;
    ps_act_cmd_t out;
    set_joint1(f, NAN, 0.3f, 0.0f, 0.0f);
    assert_int_equal(run1(f, PS_SERVO_TRACK, &out), -PS_ERR_LIMIT);
    assert_cmd(&out, 0.5f, 0.0f, 0.0f, 3.0f, 0.0f); /* p = stance */
    f->meas_q[1] = INFINITY;
    assert_int_equal(run1(f, PS_SERVO_RAMP, &out), -PS_ERR_LIMIT);
    assert_cmd(&out, 0.5f, 0.0f, 0.0f, 3.0f, 0.0f);
}

/* ---- ramp ------------------------------------------------------------------------- */

static void test_ps_servo_command_ramp_alpha_blends(void **state)
{
    fixture_t *f = *state;
    ps_act_cmd_t out;
    /* from 0.0 to 0.2, measured 0.1; at alpha 1 the window is
     * (12 - 2) / 80 = 0.125 around 0.1, so 0.2 is reachable */
    set_joint1(f, 0.1f, 0.2f, 0.4f, 2.0f);
    f->from_q[1] = 0.0f;

    f->mode.ramp_alpha = 0.0f;
    assert_int_equal(run1(f, PS_SERVO_RAMP, &out), 0);
    assert_cmd(&out, 0.0f, 0.0f, 0.0f, 2.0f, 0.0f); /* kd full from the start */

    f->mode.ramp_alpha = 0.5f;
    assert_int_equal(run1(f, PS_SERVO_RAMP, &out), 0);
    assert_cmd(&out, 0.1f, 0.2f, 40.0f, 2.0f, 1.0f);

    f->mode.ramp_alpha = 1.0f;
    assert_int_equal(run1(f, PS_SERVO_RAMP, &out), 0);
    assert_cmd(&out, 0.2f, 0.4f, 80.0f, 2.0f, 2.0f);

    /* alpha 1 equals ACTIVE */
    ps_act_cmd_t active;
    assert_int_equal(run1(f, PS_SERVO_TRACK, &active), 0);
    assert_memory_equal(&out, &active, sizeof out);
}

static void test_ps_servo_command_ramp_alpha_out_of_range_clamped(void **state)
{
    fixture_t *f = *state;
    ps_act_cmd_t out;
    set_joint1(f, 0.1f, 0.2f, 0.4f, 2.0f);
    f->from_q[1] = 0.0f;
    f->mode.ramp_alpha = 2.0f;
    assert_int_equal(run1(f, PS_SERVO_RAMP, &out), 0);
    assert_cmd(&out, 0.2f, 0.4f, 80.0f, 2.0f, 2.0f);
    f->mode.ramp_alpha = -1.0f;
    assert_int_equal(run1(f, PS_SERVO_RAMP, &out), 0);
    assert_cmd(&out, 0.0f, 0.0f, 0.0f, 2.0f, 0.0f);
    f->mode.ramp_alpha = NAN; /* counts as 0: stay where the ramp began */
    assert_int_equal(run1(f, PS_SERVO_RAMP, &out), 0);
    assert_cmd(&out, 0.0f, 0.0f, 0.0f, 2.0f, 0.0f);
}

static void test_ps_servo_command_ramp_from_missing_uses_measured(void **state)
{
    fixture_t *f = *state;
    ps_act_cmd_t out;
    set_joint1(f, 0.1f, 0.2f, 0.0f, 0.0f);
    f->mode.ramp_alpha = 0.5f;
    f->mode.ramp_from_q_rad = NULL;
    assert_int_equal(run1(f, PS_SERVO_RAMP, &out), 0);
    assert_float_equal(out.q_rad, 0.15f, TOL);
    f->mode.ramp_from_q_rad = f->from_q;
    f->from_q[1] = NAN;
    assert_int_equal(run1(f, PS_SERVO_RAMP, &out), 0);
    assert_float_equal(out.q_rad, 0.15f, TOL);
}

static void test_ps_servo_command_ramp_from_outside_limits_clamped(void **state)
{
    fixture_t *f = *state;
    ps_act_cmd_t out;
    /* ramp began with the joint past pos_min; the blend is clamped */
    set_joint1(f, -1.05f, 0.0f, 0.0f, 0.0f);
    f->from_q[1] = -1.2f;
    f->mode.ramp_alpha = 0.1f; /* -1.2 + 0.1 * 1.2 = -1.08 -> -1.0 */
    assert_int_equal(run1(f, PS_SERVO_RAMP, &out), 0);
    assert_float_equal(out.q_rad, -1.0f, TOL);
    assert_float_equal(out.kp_nm_rad, 8.0f, TOL);
}

/* ---- argument errors ------------------------------------------------------------------ */

static void test_ps_servo_command_bad_arguments_einval(void **state)
{
    fixture_t *f = *state;
    ps_act_cmd_t out;
    set_joint1(f, 0.7f, 0.3f, 0.0f, 0.0f);
    f->mode.kind = PS_SERVO_TRACK;
    assert_int_equal(ps_servo_command(NULL, &f->c, &f->mode, 1u, &f->t, &out), -EINVAL);
    assert_int_equal(ps_servo_command(&f->j, &f->c, &f->mode, 1u, &f->t, NULL), -EINVAL);

    /* limp when there is nothing to build a damping command from */
    memset(&out, 0xAB, sizeof out);
    assert_int_equal(ps_servo_command(&f->j, NULL, &f->mode, 1u, &f->t, &out), -EINVAL);
    assert_cmd(&out, 0.5f, 0.0f, 0.0f, 0.0f, 0.0f);
    memset(&out, 0xAB, sizeof out);
    assert_int_equal(ps_servo_command(&f->j, &f->c, NULL, 1u, &f->t, &out), -EINVAL);
    assert_cmd(&out, 0.5f, 0.0f, 0.0f, 0.0f, 0.0f);
    memset(&out, 0xAB, sizeof out);
    assert_int_equal(ps_servo_command(&f->j, &f->c, &f->mode, PS_MAX_JOINTS, &f->t, &out), -EINVAL);
    assert_cmd(&out, 0.5f, 0.0f, 0.0f, 0.0f, 0.0f);
    f->mode.meas_q_rad = NULL;
    memset(&out, 0xAB, sizeof out);
    assert_int_equal(ps_servo_command(&f->j, &f->c, &f->mode, 1u, &f->t, &out), -EINVAL);
    assert_cmd(&out, 0.5f, 0.0f, 0.0f, 0.0f, 0.0f);
    f->mode.meas_q_rad = f->meas_q;

    /* targets missing where they are needed: damping */
    memset(&out, 0xAB, sizeof out);
    assert_int_equal(ps_servo_command(&f->j, &f->c, &f->mode, 1u, NULL, &out), -EINVAL);
    assert_cmd(&out, 0.7f, 0.0f, 0.0f, 3.0f, 0.0f);

    /* corrupted state: limp */
    memset(&out, 0xAB, sizeof out);
    assert_int_equal(run1(f, PS_SERVO_MODE_COUNT, &out), -EINVAL);
    assert_cmd(&out, 0.7f, 0.0f, 0.0f, 0.0f, 0.0f);
}

/* ---- ps_servo_is_within_limits -------------------------------------------------------- */

static void test_ps_servo_is_within_limits_boundaries(void **state)
{
    fixture_t *f = *state;
    const ps_act_cmd_t ok = {.q_rad = 2.0f,
                             .qd_rad_s = -10.0f,
                             .kp_nm_rad = 200.0f,
                             .kd_nm_s_rad = 4.0f,
                             .tau_ff_nm = -12.0f};
    assert_true(ps_servo_is_within_limits(&f->j, &ok));
    const ps_act_cmd_t zero = {.q_rad = -1.0f};
    assert_true(ps_servo_is_within_limits(&f->j, &zero));

    ps_act_cmd_t c;
    c = ok, c.q_rad = nextafterf(2.0f, 3.0f);
    assert_false(ps_servo_is_within_limits(&f->j, &c));
    c = ok, c.q_rad = nextafterf(-1.0f, -2.0f);
    assert_false(ps_servo_is_within_limits(&f->j, &c));
    c = ok, c.qd_rad_s = -10.001f;
    assert_false(ps_servo_is_within_limits(&f->j, &c));
    c = ok, c.qd_rad_s = 10.001f;
    assert_false(ps_servo_is_within_limits(&f->j, &c));
    c = ok, c.kp_nm_rad = 200.01f;
    assert_false(ps_servo_is_within_limits(&f->j, &c));
    c = ok, c.kp_nm_rad = -0.001f;
    assert_false(ps_servo_is_within_limits(&f->j, &c));
    c = ok, c.kd_nm_s_rad = 4.001f;
    assert_false(ps_servo_is_within_limits(&f->j, &c));
    c = ok, c.kd_nm_s_rad = -0.001f;
    assert_false(ps_servo_is_within_limits(&f->j, &c));
    c = ok, c.tau_ff_nm = 12.001f;
    assert_false(ps_servo_is_within_limits(&f->j, &c));
    c = ok, c.tau_ff_nm = -12.001f;
    assert_false(ps_servo_is_within_limits(&f->j, &c));
    assert_false(ps_servo_is_within_limits(NULL, &ok));
    assert_false(ps_servo_is_within_limits(&f->j, NULL));
}

static void test_ps_servo_is_within_limits_nonfinite_false(void **state)
{
    fixture_t *f = *state;
    const float bad[] = {NAN, INFINITY, -INFINITY};
    for (size_t i = 0; i < 3; i++) {
        for (int field = 0; field < 5; field++) {
            ps_act_cmd_t c = {.q_rad = 0.0f};
            float *fp[] = {&c.q_rad, &c.qd_rad_s, &c.kp_nm_rad, &c.kd_nm_s_rad, &c.tau_ff_nm};
            *fp[field] = bad[i];
            assert_false(ps_servo_is_within_limits(&f->j, &c));
        }
    }
}

static void test_ps_servo_is_within_limits_wire_tighter_false(void **state)
{
    fixture_t *f = *state;
    f->j.wire.v_min_rad_s = -8.0f;
    f->j.wire.v_max_rad_s = 8.0f;
    ps_act_cmd_t c = {.q_rad = 0.0f, .qd_rad_s = 9.0f}; /* inside vel_max, outside wire */
    assert_false(ps_servo_is_within_limits(&f->j, &c));
    c.qd_rad_s = 8.0f;
    assert_true(ps_servo_is_within_limits(&f->j, &c));
    f->j.wire.p_max_rad = 1.5f; /* a misconfigured joint: limit beyond the wire */
    c.q_rad = 1.75f;
    assert_false(ps_servo_is_within_limits(&f->j, &c));
}

/* ---- randomized property test ------------------------------------------------------------- */

static uint64_t rng_state;

static uint64_t rng_next(void)
{
    /* splitmix64: fixed seed, same sequence on every host */
    uint64_t z = (rng_state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

static float rng_uniform(float lo, float hi)
{
    return lo + (hi - lo) * (float)((double)(rng_next() >> 11) / 9007199254740992.0);
}

/* Mostly plausible values around the limits, often the nasty ones. */
static float rng_value(float lo, float hi)
{
    static const float nasty[] = {NAN,    INFINITY, -INFINITY, FLT_MAX, -FLT_MAX, 1e30f,
                                  -1e30f, 1e-40f,   -1e-40f,   0.0f,    -0.0f,    FLT_MIN};
    const uint64_t pick = rng_next() % 10u;
    if (pick == 0u)
        return nasty[rng_next() % (sizeof nasty / sizeof nasty[0])];
    if (pick == 1u)
        return (rng_next() & 1u) ? lo : hi;
    const float span = hi - lo;
    return rng_uniform(lo - 0.5f * span, hi + 0.5f * span);
}

/* The limits written out field by field, independent of ps_servo's own
 * helper, so a bug shared by the command and ps_servo_is_within_limits
 * cannot hide. */
static bool independent_within(const ps_servo_joint_cfg_t *j, const ps_act_cmd_t *c)
{
    const ps_act_range_t *w = &j->wire;
    return isfinite(c->q_rad) && isfinite(c->qd_rad_s) && isfinite(c->kp_nm_rad) &&
           isfinite(c->kd_nm_s_rad) && isfinite(c->tau_ff_nm) && c->q_rad >= j->lim.pos_min_rad &&
           c->q_rad <= j->lim.pos_max_rad && c->q_rad >= w->p_min_rad && c->q_rad <= w->p_max_rad &&
           fabsf(c->qd_rad_s) <= j->lim.vel_max_rad_s && c->qd_rad_s >= w->v_min_rad_s &&
           c->qd_rad_s <= w->v_max_rad_s && c->kp_nm_rad >= 0.0f &&
           c->kp_nm_rad <= j->lim.kp_max_nm_rad && c->kp_nm_rad <= w->kp_max_nm_rad &&
           c->kd_nm_s_rad >= 0.0f && c->kd_nm_s_rad <= j->lim.kd_max_nm_s_rad &&
           c->kd_nm_s_rad <= w->kd_max_nm_s_rad && fabsf(c->tau_ff_nm) <= j->lim.torque_max_nm &&
           c->tau_ff_nm >= w->t_min_nm && c->tau_ff_nm <= w->t_max_nm;
}

static void test_ps_servo_command_random_inputs_always_within_limits(void **state)
{
    fixture_t *f = *state;
    /* second joint: wire tighter than the joint limits on v, kd and torque */
    ps_servo_joint_cfg_t joints[2] = {f->j, f->j};
    joints[1].wire.v_min_rad_s = -6.0f;
    joints[1].wire.v_max_rad_s = 7.0f;
    joints[1].wire.kd_max_nm_s_rad = 1.5f;
    joints[1].wire.t_min_nm = -10.0f;
    joints[1].wire.t_max_nm = 9.0f;
    joints[1].kp_nm_rad = 250.0f; /* above kp_max: always clamped */

    rng_state = 0x5EED5EEDull;
    unsigned n_ok = 0, n_limit = 0, n_inval = 0, n_torque_limited = 0;
    const unsigned n_iter = 100000u;
    for (unsigned it = 0; it < n_iter; it++) {
        const ps_servo_joint_cfg_t *j = &joints[it & 1u];
        const unsigned idx = (unsigned)(rng_next() % 4u);
        const uint64_t s_pick = rng_next() % 11u; /* 0..4 states, 5: invalid, rest active/ramp */
        f->mode.kind = s_pick < 5u ? (ps_servo_mode_kind_t)s_pick
                       : s_pick == 5u
                           ? (ps_servo_mode_kind_t)(PS_SERVO_MODE_COUNT + (rng_next() % 3u))
                       : (s_pick & 1u) ? PS_SERVO_TRACK
                                       : PS_SERVO_RAMP;
        f->mode.ramp_alpha = rng_value(0.0f, 1.0f);
        f->meas_q[idx] = rng_value(j->lim.pos_min_rad, j->lim.pos_max_rad);
        f->from_q[idx] = rng_value(j->lim.pos_min_rad, j->lim.pos_max_rad);
        f->t.q_rad[idx] = rng_value(j->lim.pos_min_rad, j->lim.pos_max_rad);
        f->t.qd_rad_s[idx] = rng_value(-j->lim.vel_max_rad_s, j->lim.vel_max_rad_s);
        f->t.tau_ff_nm[idx] = rng_value(-j->lim.torque_max_nm, j->lim.torque_max_nm);
        f->c.damping_kd_nm_s_rad = rng_value(0.0f, 5.0f);

        ps_act_cmd_t out;
        memset(&out, 0xAB, sizeof out);
        const int rc = ps_servo_command(j, &f->c, &f->mode, idx, &f->t, &out);
        if (!ps_servo_is_within_limits(j, &out) || !independent_within(j, &out) ||
            encode_mit(j, &out) != 1)
            fail_msg("iter %u: state %d rc %d out p=%g v=%g kp=%g kd=%g t=%g", it,
                     (int)f->mode.kind, rc, (double)out.q_rad, (double)out.qd_rad_s,
                     (double)out.kp_nm_rad, (double)out.kd_nm_s_rad, (double)out.tau_ff_nm);

        const bool drives = f->mode.kind == PS_SERVO_TRACK || f->mode.kind == PS_SERVO_RAMP;
        const bool is_hold = f->mode.kind == PS_SERVO_HOLD;
        if (rc == 0) {
            n_ok++;
            if (is_hold) {
                /* stiff at the stance (no hold pose given), spring bounded */
                const float spring = out.kp_nm_rad * fabsf(out.q_rad - f->meas_q[idx]);
                assert_true(spring <= j->lim.torque_max_nm * (1.0f + 1e-5f) + 1e-6f);
                assert_float_equal(out.tau_ff_nm, 0.0f, 0.0f);
            } else if (drives) {
                /* spring torque fits beside the feed-forward */
                const float budget = fmaxf(0.0f, j->lim.torque_max_nm - fabsf(out.tau_ff_nm));
                const float spring = out.kp_nm_rad * fabsf(out.q_rad - f->meas_q[idx]);
                if (!(spring <= budget * (1.0f + 1e-5f) + 1e-6f))
                    fail_msg("iter %u: spring %g Nm > budget %g Nm", it, (double)spring,
                             (double)budget);
                /* only valid targets are accepted */
                assert_true(isfinite(f->t.q_rad[idx]));
                assert_true(f->t.q_rad[idx] >= j->lim.pos_min_rad &&
                            f->t.q_rad[idx] <= j->lim.pos_max_rad);
                if (out.kp_nm_rad > 0.0f && fabsf(out.q_rad - f->meas_q[idx]) > 0.0f &&
                    spring >= budget * 0.999f)
                    n_torque_limited++;
            } else {
                assert_float_equal(out.kp_nm_rad, 0.0f, 0.0f);
            }
        } else if (rc == -PS_ERR_LIMIT) {
            n_limit++;
            assert_true(drives || is_hold);
            assert_float_equal(out.kp_nm_rad, 0.0f, 0.0f);
            assert_float_equal(out.tau_ff_nm, 0.0f, 0.0f);
        } else if (rc == -EINVAL) {
            n_inval++;
            assert_false(drives || is_hold);
            assert_float_equal(out.kp_nm_rad, 0.0f, 0.0f);
            assert_float_equal(out.kd_nm_s_rad, 0.0f, 0.0f);
        } else {
            fail_msg("iter %u: unexpected rc %d", it, rc);
        }
    }
    /* every branch was exercised, or the property says little */
    assert_int_equal(n_ok + n_limit + n_inval, n_iter);
    assert_true(n_ok > n_iter / 4u);
    assert_true(n_limit > n_iter / 20u);
    assert_true(n_inval > n_iter / 50u);
    assert_true(n_torque_limited > n_iter / 100u);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_ps_servo_command_standby_limp_at_measured, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_command_estop_limp_clamped_into_limits, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_command_damping_kd_only, setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_command_hold_pose_stiff_torque_limited, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_command_active_targets_and_gains, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_command_active_velocity_clamped_both_sides,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_command_active_gains_clamped_to_max, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_command_active_torque_ff_clamped_both_sides,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_command_active_position_limits_inclusive,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_command_active_far_target_torque_limited,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_command_measured_outside_limits_kp_lowered,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_command_wire_corner_still_encodes, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_command_invalid_target_limit_and_damping,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_command_nonfinite_velocity_or_torque_limit,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_command_joint_without_target_limit, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_command_measurement_nan_in_active_limit,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_command_ramp_alpha_blends, setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_command_ramp_alpha_out_of_range_clamped,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_command_ramp_from_missing_uses_measured,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_command_ramp_from_outside_limits_clamped,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_command_bad_arguments_einval, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_is_within_limits_boundaries, setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_is_within_limits_nonfinite_false, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_is_within_limits_wire_tighter_false, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_ps_servo_command_random_inputs_always_within_limits,
                                        setup, teardown),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
