/* Tests of sim/ps_devices: the emulated MIT actuator and CAN IMU, driven with
 * plain joint states (no plant). */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <string.h>

#include "../drivers/ps_imu_msg.h"
#include "../drivers/ps_mit.h"
#include "../rt/ps_clock.h"
#include "../rt/ps_err.h"
#include "fakes/ps_test_wire.h"
#include "../sim/ps_devices.h"

/* AK-style wire ranges; joint limits tighter than the wire, as in a robot file.
 * Gear 1, direction +1, no zero offset: motor and joint units coincide, so
 * the MIT frames below are hand-checkable in joint units. */
static ps_act_cfg_t joint_cfg(void)
{
    ps_act_cfg_t j;
    memset(&j, 0, sizeof j);
    j.protocol = PS_ACT_PROTO_MIT;
    j.can_id = 0x13;
    j.reply_id = 0x113;
    j.wire = ps_test_wire_ak();
    j.gear_ratio = 1.0f;
    j.direction = 1.0f;
    j.kt_nm_a = 0.5f;
    j.temp_max_c = 80.0f;
    j.rate_div = 1;
    return j;
}

static ps_act_limits_t joint_limits(void)
{
    return (ps_act_limits_t){
        .pos_min_rad = -1.0f,
        .pos_max_rad = 2.0f,
        .vel_max_rad_s = 20.0f,
        .torque_max_nm = 12.0f,
        .kp_max_nm_rad = 200.0f,
        .kd_max_nm_s_rad = 4.0f,
    };
}

static ps_sim_devices_cfg_t sim_cfg(void)
{
    return (ps_sim_devices_cfg_t){
        .gyro_noise_rad_s = 0.02f,
        .gyro_bias_rad_s = 0.01f,
        .accel_noise_m_s2 = 0.05f,
        .accel_bias_m_s2 = 0.1f,
        .reply_latency_s = 50e-6f,
        .thermal_r_c_w = 2.0f,
        .thermal_tau_s = 30.0f,
        .winding_r_ohm = 0.2f,
        .ambient_c = 25.0f,
    };
}

typedef struct {
    ps_act_cfg_t j;
    ps_act_limits_t lim;
    ps_sim_devices_cfg_t sim;
    ps_devices_actuator_t a;
} fixture_t;

static int setup(void **state)
{
    static fixture_t fx;
    fx.j = joint_cfg();
    fx.lim = joint_limits();
    fx.sim = sim_cfg();
    ps_devices_init_actuator(&fx.a, &fx.j, &fx.lim, &fx.sim);
    *state = &fx;
    return 0;
}

static ps_can_frame_t special_frame(uint32_t id, ps_mit_special_t which, int64_t t_ns)
{
    ps_can_frame_t f;
    memset(&f, 0, sizeof f);
    f.id = id;
    f.len = PS_MIT_FRAME_LEN;
    ps_mit_encode_special(which, f.data);
    f.t_ns = t_ns;
    return f;
}

static ps_can_frame_t cmd_frame(const ps_act_cfg_t *j, const ps_mit_cmd_t *c, int64_t t_ns)
{
    ps_can_frame_t f;
    memset(&f, 0, sizeof f);
    f.id = j->can_id;
    f.len = PS_MIT_FRAME_LEN;
    assert_int_equal(ps_mit_encode_cmd(&j->wire, c, f.data), 0);
    f.t_ns = t_ns;
    return f;
}

static void enter(fixture_t *fx, int64_t t_ns)
{
    ps_can_frame_t rep;
    const ps_can_frame_t f = special_frame(fx->j.can_id, PS_MIT_SPECIAL_ENTER, t_ns);
    assert_int_equal(ps_devices_handle_frame(&fx->a, &f, 0.0, 0.0, &rep), 1);
    assert_true(fx->a.is_motor_mode);
}

static void send_cmd(fixture_t *fx, const ps_mit_cmd_t *c, double q, double qd, int64_t t_ns,
                     ps_can_frame_t *rep)
{
    const ps_can_frame_t f = cmd_frame(&fx->j, c, t_ns);
    assert_int_equal(ps_devices_handle_frame(&fx->a, &f, q, qd, rep), 1);
}

/* ---- motor mode ------------------------------------------------------ */

static void test_handle_frame_cmd_before_enter_ignored_but_replied(void **state)
{
    fixture_t *fx = *state;
    const ps_mit_cmd_t c = {.p_rad = 0.5f, .kp_nm_rad = 50.0f, .kd_nm_s_rad = 1.0f};
    ps_can_frame_t rep;
    send_cmd(fx, &c, 0.0, 0.0, 1000, &rep);
    assert_int_equal(rep.id, fx->j.reply_id);
    assert_false(fx->a.is_motor_mode);
    assert_int_equal(fx->a.n_cmd_frames, 1);
    assert_int_equal(fx->a.n_cmd_ignored, 1);
    assert_true(ps_devices_step_actuator(&fx->a, 0.0, 0.0, 2000, 1e-3) == 0.0);

    /* The same command after ENTER is obeyed. */
    enter(fx, 3000);
    send_cmd(fx, &c, 0.0, 0.0, 4000, &rep);
    assert_true(ps_devices_step_actuator(&fx->a, 0.0, 0.0, 5000, 1e-3) > 1.0);
    assert_int_equal(fx->a.n_cmd_ignored, 1);
}

static void test_handle_frame_exit_goes_limp(void **state)
{
    fixture_t *fx = *state;
    enter(fx, 0);
    const ps_mit_cmd_t c = {.p_rad = 0.5f, .kp_nm_rad = 50.0f};
    ps_can_frame_t rep;
    send_cmd(fx, &c, 0.0, 0.0, 1000, &rep);
    assert_true(ps_devices_step_actuator(&fx->a, 0.0, 0.0, 2000, 1e-3) > 1.0);
    const ps_can_frame_t f = special_frame(fx->j.can_id, PS_MIT_SPECIAL_EXIT, 3000);
    assert_int_equal(ps_devices_handle_frame(&fx->a, &f, 0.0, 0.0, &rep), 1);
    assert_false(fx->a.is_motor_mode);
    assert_true(ps_devices_step_actuator(&fx->a, 0.0, 0.0, 4000, 1e-3) == 0.0);
}

/* ---- PD -------------------------------------------------------------- */

static void test_step_actuator_pd_equals_quantised_command(void **state)
{
    fixture_t *fx = *state;
    enter(fx, 0);
    /* Values chosen off the quantisation grid, so decoding visibly moves them. */
    const ps_mit_cmd_t c = {.p_rad = 0.3141f,
                            .v_rad_s = 0.777f,
                            .kp_nm_rad = 37.3f,
                            .kd_nm_s_rad = 1.234f,
                            .t_ff_nm = 0.567f};
    ps_can_frame_t rep;
    const double q = 0.2, qd = -0.4;
    send_cmd(fx, &c, q, qd, 1000, &rep);

    ps_mit_cmd_t d;
    const ps_can_frame_t f = cmd_frame(&fx->j, &c, 0);
    assert_int_equal(ps_mit_decode_cmd(&fx->j.wire, f.data, f.len, &d), 0);
    const double want = (double)d.kp_nm_rad * ((double)d.p_rad - q) +
                        (double)d.kd_nm_s_rad * ((double)d.v_rad_s - qd) + (double)d.t_ff_nm;
    const double raw = (double)c.kp_nm_rad * ((double)c.p_rad - q) +
                       (double)c.kd_nm_s_rad * ((double)c.v_rad_s - qd) + (double)c.t_ff_nm;
    /* The quantised and the raw torque differ, so equality below proves decoding. */
    assert_true(fabs(want - raw) > 1e-5);
    const double tau = ps_devices_step_actuator(&fx->a, q, qd, 2000, 1e-3);
    assert_true(fabs(tau - want) < 1e-9);
    assert_true(fx->a.tau_nm == tau);
}

static void test_step_actuator_large_error_saturates_at_torque_max(void **state)
{
    fixture_t *fx = *state;
    enter(fx, 0);
    const ps_mit_cmd_t c = {.p_rad = 1.5f, .kp_nm_rad = 200.0f};
    ps_can_frame_t rep;
    send_cmd(fx, &c, 0.0, 0.0, 1000, &rep);
    /* 200 * 1.5 = 300 Nm asked; joint limit 12 Nm (wire allows 18). */
    assert_true(ps_devices_step_actuator(&fx->a, 0.0, 0.0, 2000, 1e-3) == 12.0);
    assert_true(ps_devices_step_actuator(&fx->a, 3.0, 0.0, 3000, 1e-3) == -12.0);
}

static void test_step_actuator_joint_above_wire_saturates_at_wire_t(void **state)
{
    fixture_t *fx = *state;
    fx->lim.torque_max_nm = 30.0f; /* beyond the wire's +-18 */
    ps_devices_init_actuator(&fx->a, &fx->j, &fx->lim, &fx->sim);
    enter(fx, 0);
    const ps_mit_cmd_t c = {.p_rad = 1.5f, .kp_nm_rad = 200.0f};
    ps_can_frame_t rep;
    send_cmd(fx, &c, 0.0, 0.0, 1000, &rep);
    assert_true(ps_devices_step_actuator(&fx->a, 0.0, 0.0, 2000, 1e-3) == 18.0);
}

/* ---- reply ----------------------------------------------------------- */

static void test_handle_frame_reply_content_ids_and_latency(void **state)
{
    fixture_t *fx = *state;
    enter(fx, 0);
    const ps_mit_cmd_t c = {.p_rad = 0.5f, .kp_nm_rad = 10.0f, .t_ff_nm = 0.5f};
    ps_can_frame_t rep;
    const double q = 0.1, qd = 1.5;
    const int64_t t_arr = 123456789;
    send_cmd(fx, &c, q, qd, t_arr, &rep);
    assert_int_equal(rep.id, 0x113);
    assert_int_equal(rep.len, 8);
    assert_int_equal(rep.is_ext, 0);
    assert_int_equal(rep.t_ns, t_arr + 50000);

    ps_mit_reply_t r;
    assert_int_equal(ps_mit_decode_reply(&fx->j.wire, rep.data, rep.len, &r), 0);
    assert_int_equal(r.motor_id, 0x3);
    assert_int_equal(r.fault, PS_MIT_FAULT_NONE);
    const double p_lsb = 25.0 / 65535.0, v_lsb = 90.0 / 4095.0, i_lsb = 80.0 / 4095.0;
    assert_true(fabs(r.p_rad - q) <= p_lsb);
    assert_true(fabs(r.v_rad_s - qd) <= v_lsb);
    /* Current = the torque the driver applies for its (decoded) command / kt. */
    const double tau = (double)fx->a.cmd.kp_nm_rad * ((double)fx->a.cmd.q_rad - q) +
                       (double)fx->a.cmd.kd_nm_s_rad * (0.0 - qd) + (double)fx->a.cmd.tau_ff_nm;
    assert_true(fabs(tau) > 1.0);
    assert_true(fabs(r.i_a - tau / 0.5) <= i_lsb);
    assert_int_equal(r.temp_rotor_c, 25);
    assert_int_equal(r.temp_mos_c, 25);
    assert_int_equal(fx->a.n_replies, 2); /* ENTER and the command */
}

static void test_handle_frame_zero_offsets_position(void **state)
{
    fixture_t *fx = *state;
    ps_can_frame_t rep;
    const ps_can_frame_t z = special_frame(fx->j.can_id, PS_MIT_SPECIAL_ZERO, 0);
    assert_int_equal(ps_devices_handle_frame(&fx->a, &z, 0.3, 0.0, &rep), 1);
    ps_mit_reply_t r;
    assert_int_equal(ps_mit_decode_reply(&fx->j.wire, rep.data, rep.len, &r), 0);
    assert_true(fabs(r.p_rad) <= 25.0 / 65535.0);

    /* Later readings and set-points are relative to the new zero. */
    enter(fx, 1000);
    const ps_mit_cmd_t c = {.p_rad = 0.0f, .kp_nm_rad = 20.0f};
    send_cmd(fx, &c, 0.4, 0.0, 2000, &rep);
    assert_int_equal(ps_mit_decode_reply(&fx->j.wire, rep.data, rep.len, &r), 0);
    assert_true(fabs(r.p_rad - 0.1) <= 25.0 / 65535.0);
    const double tau = ps_devices_step_actuator(&fx->a, 0.4, 0.0, 3000, 1e-3);
    /* p_des and t_ff 0 decode to half an LSB above 0 (0x8000 / 0x800). */
    const double want = (double)fx->a.cmd.kp_nm_rad * ((double)fx->a.cmd.q_rad - (0.4 - 0.3)) +
                        (double)fx->a.cmd.tau_ff_nm;
    assert_true(fabs(tau - want) < 1e-9);
    assert_true(fabs(tau - (-2.0)) < 0.01);
}

static void test_handle_frame_drop_knob_suppresses_reply_obeys_cmd(void **state)
{
    fixture_t *fx = *state;
    enter(fx, 0);
    fx->a.drop_replies_until_ns = 10000;
    const ps_mit_cmd_t c = {.p_rad = 0.5f, .kp_nm_rad = 50.0f};
    ps_can_frame_t f = cmd_frame(&fx->j, &c, 5000), rep;
    assert_int_equal(ps_devices_handle_frame(&fx->a, &f, 0.0, 0.0, &rep), 0);
    assert_int_equal(fx->a.n_replies_dropped, 1);
    assert_true(ps_devices_step_actuator(&fx->a, 0.0, 0.0, 6000, 1e-3) > 1.0);
    f.t_ns = 10000;
    assert_int_equal(ps_devices_handle_frame(&fx->a, &f, 0.0, 0.0, &rep), 1);
}

static void test_handle_frame_other_id_enoent_not_counted(void **state)
{
    fixture_t *fx = *state;
    ps_can_frame_t f = special_frame(0x14, PS_MIT_SPECIAL_ENTER, 0), rep;
    assert_int_equal(ps_devices_handle_frame(&fx->a, &f, 0.0, 0.0, &rep), -ENOENT);
    assert_false(fx->a.is_motor_mode);
    assert_int_equal(fx->a.n_bad_frames, 0);
}

/* A short frame or an FD frame on the drive's id is malformed for MIT mode; a
 * 29-bit frame with the same number is another identifier, not for it. */
static void test_handle_frame_bad_len_or_fd_protocol_counted(void **state)
{
    fixture_t *fx = *state;
    ps_can_frame_t f = special_frame(fx->j.can_id, PS_MIT_SPECIAL_ENTER, 0), rep;
    f.len = 7;
    assert_int_equal(ps_devices_handle_frame(&fx->a, &f, 0.0, 0.0, &rep), -PS_ERR_PROTOCOL);
    f.len = 8;
    f.is_fd = 1;
    assert_int_equal(ps_devices_handle_frame(&fx->a, &f, 0.0, 0.0, &rep), -PS_ERR_PROTOCOL);
    f.is_fd = 0;
    f.is_ext = 1;
    assert_int_equal(ps_devices_handle_frame(&fx->a, &f, 0.0, 0.0, &rep), -ENOENT);
    assert_int_equal(fx->a.n_bad_frames, 2);
    assert_false(fx->a.is_motor_mode);
    assert_int_equal(fx->a.n_replies, 0);
}

/* ---- comms loss ------------------------------------------------------ */

static void test_step_actuator_no_cmd_100ms_limp_comms_lost(void **state)
{
    fixture_t *fx = *state;
    enter(fx, 0);
    const ps_mit_cmd_t c = {.p_rad = 0.5f, .kp_nm_rad = 50.0f};
    ps_can_frame_t rep;
    const int64_t t_cmd = PS_NS_PER_MS;
    send_cmd(fx, &c, 0.0, 0.0, t_cmd, &rep);
    assert_true(ps_devices_step_actuator(&fx->a, 0.0, 0.0, t_cmd + PS_DEVICES_COMMS_TIMEOUT_NS,
                                         1e-3) > 1.0);
    assert_true(ps_devices_step_actuator(&fx->a, 0.0, 0.0,
                                         t_cmd + PS_DEVICES_COMMS_TIMEOUT_NS + 1000, 1e-3) == 0.0);
    assert_false(fx->a.is_motor_mode);

    /* The fault shows in the next reply; commands are ignored until ENTER. */
    const int64_t t2 = t_cmd + 2 * PS_DEVICES_COMMS_TIMEOUT_NS;
    send_cmd(fx, &c, 0.0, 0.0, t2, &rep);
    ps_mit_reply_t r;
    assert_int_equal(ps_mit_decode_reply(&fx->j.wire, rep.data, rep.len, &r), 0);
    assert_int_equal(r.fault, PS_MIT_FAULT_COMMS_LOST);
    assert_true(ps_devices_step_actuator(&fx->a, 0.0, 0.0, t2 + 1000, 1e-3) == 0.0);
    enter(fx, t2 + 2000);
    assert_int_equal(fx->a.fault_bits, 0u);
}

/* ---- limits ---------------------------------------------------------- */

static void test_handle_frame_out_of_limit_fields_counted(void **state)
{
    fixture_t *fx = *state;
    ps_can_frame_t rep;
    /* Exactly at every limit: not counted (quantisation slack). */
    const ps_mit_cmd_t at = {.p_rad = 2.0f,
                             .v_rad_s = -20.0f,
                             .kp_nm_rad = 200.0f,
                             .kd_nm_s_rad = 4.0f,
                             .t_ff_nm = -12.0f};
    send_cmd(fx, &at, 0.0, 0.0, 0, &rep);
    const ps_mit_cmd_t at_lo = {.p_rad = -1.0f, .v_rad_s = 20.0f, .t_ff_nm = 12.0f};
    send_cmd(fx, &at_lo, 0.0, 0.0, 0, &rep);
    assert_int_equal(fx->a.n_cmd_out_of_limits, 0);

    /* Each field beyond its limit by clearly more than one LSB, inside the wire. */
    const ps_mit_cmd_t bad[] = {
        {.p_rad = 2.01f},   {.p_rad = -1.01f},     {.v_rad_s = 20.1f}, {.v_rad_s = -20.1f},
        {.kp_nm_rad = 201}, {.kd_nm_s_rad = 4.1f}, {.t_ff_nm = 12.1f}, {.t_ff_nm = -12.1f},
    };
    for (unsigned i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        send_cmd(fx, &bad[i], 0.0, 0.0, 0, &rep);
        assert_int_equal(fx->a.n_cmd_out_of_limits, i + 1u);
    }
    assert_int_equal(fx->a.n_cmd_frames, 2u + sizeof bad / sizeof bad[0]);
}

/* ---- thermal --------------------------------------------------------- */

static void test_step_actuator_temp_follows_first_order_model(void **state)
{
    fixture_t *fx = *state;
    enter(fx, 0);
    /* Constant 6 Nm feed-forward: i = 12 A, P = 144 * 0.2 = 28.8 W,
     * rise at steady state 57.6 degC (82.6 degC: would fault). */
    const ps_mit_cmd_t c = {.t_ff_nm = 6.0f};
    ps_can_frame_t rep;
    int64_t t = 0;
    double tau = 0.0;
    for (int k = 0; k < 10000; k++) { /* 10 s at 1 ms, commands every step */
        send_cmd(fx, &c, 0.0, 0.0, t, &rep);
        tau = ps_devices_step_actuator(&fx->a, 0.0, 0.0, t, 1e-3);
        t += PS_NS_PER_MS;
    }
    const double i = tau / 0.5;
    const double rise = i * i * 0.2 * 2.0 * (1.0 - exp(-10.0 / 30.0));
    assert_true(fabs(fx->a.temp_c - (25.0 + rise)) < 1e-6 * rise + 1e-9);
    assert_true(fx->a.temp_c > 35.0);
    ps_mit_reply_t r;
    assert_int_equal(ps_mit_decode_reply(&fx->j.wire, rep.data, rep.len, &r), 0);
    assert_true(r.temp_rotor_c > 35);
}

static void test_step_actuator_above_temp_max_faults_and_refuses_enter(void **state)
{
    fixture_t *fx = *state;
    fx->sim.thermal_tau_s = 1.0f; /* fast, to cross 80 degC in a few seconds */
    ps_devices_init_actuator(&fx->a, &fx->j, &fx->lim, &fx->sim);
    enter(fx, 0);
    const ps_mit_cmd_t c = {.t_ff_nm = 6.0f};
    ps_can_frame_t rep;
    int64_t t = 0;
    int k_fault = -1;
    for (int k = 0; k < 10000 && k_fault < 0; k++) {
        send_cmd(fx, &c, 0.0, 0.0, t, &rep);
        (void)ps_devices_step_actuator(&fx->a, 0.0, 0.0, t, 1e-3);
        if ((fx->a.fault_bits & PS_ACT_FAULT_MOTOR_OVERTEMP))
            k_fault = k;
        t += PS_NS_PER_MS;
    }
    assert_true(k_fault > 0);
    assert_true(fx->a.temp_c > 80.0);
    assert_false(fx->a.is_motor_mode);
    assert_true(ps_devices_step_actuator(&fx->a, 0.0, 0.0, t, 1e-3) == 0.0);
    /* Still hot: ENTER is answered but refused. */
    const ps_can_frame_t f = special_frame(fx->j.can_id, PS_MIT_SPECIAL_ENTER, t);
    assert_int_equal(ps_devices_handle_frame(&fx->a, &f, 0.0, 0.0, &rep), 1);
    assert_false(fx->a.is_motor_mode);
    ps_mit_reply_t r;
    assert_int_equal(ps_mit_decode_reply(&fx->j.wire, rep.data, rep.len, &r), 0);
    assert_int_equal(r.fault, PS_MIT_FAULT_ROTOR_OVERTEMP);
    /* Cooled down (no current): ENTER works again. */
    for (int k = 0; k < 10000; k++)
        (void)ps_devices_step_actuator(&fx->a, 0.0, 0.0, t, 1e-3);
    assert_true(fx->a.temp_c < 75.0);
    enter(fx, t);
}

/* ---- IMU ------------------------------------------------------------- */

static ps_imu_cfg_t imu_cfg(uint32_t rate_div)
{
    return (ps_imu_cfg_t){.bus_idx = 0, .base_id = 0x50, .rate_div = rate_div};
}

static void test_tick_imu_rate_div_frames_ids_and_seq(void **state)
{
    (void)state;
    const ps_imu_cfg_t cfg = imu_cfg(3);
    const ps_sim_devices_cfg_t sim = sim_cfg();
    ps_devices_imu_t imu;
    ps_devices_init_imu(&imu, &cfg, &sim, 7);
    const double g[3] = {0.1, -0.2, 0.3}, a[3] = {0.0, 0.0, 9.81};
    ps_can_frame_t out[PS_IMU_MAX_FRAMES];
    unsigned n = 0;
    for (uint64_t tick = 0; tick < 30; tick++) {
        const int r = ps_devices_tick_imu(&imu, tick, g, a, (int64_t)tick * 1000, out);
        if (tick % 3 != 0) {
            assert_int_equal(r, 0);
            continue;
        }
        assert_int_equal(r, 2);
        assert_int_equal(out[0].id, 0x50);
        assert_int_equal(out[1].id, 0x51);
        assert_int_equal(out[0].t_ns, (int64_t)tick * 1000);
        ps_imu_msg_rx_t rx;
        ps_imu_sample_t s;
        ps_imu_msg_rx_init(&rx, 0x50);
        assert_int_equal(ps_imu_msg_rx_feed(&rx, &out[0], &s), 0);
        assert_int_equal(ps_imu_msg_rx_feed(&rx, &out[1], &s), 1);
        assert_int_equal(s.seq, (uint8_t)n);
        /* Ideal + bias + noise: within 6 sigma + bias of the ideal. */
        assert_true(fabsf(s.accel_body_m_s2[2] - 9.81f) < 0.1f + 6 * 0.05f + 0.002f);
        n++;
    }
    assert_int_equal(n, 10);
    assert_int_equal(imu.n_samples, 10);
}

typedef struct {
    double mean_gyro[3], std_gyro[3], mean_accel[3], std_accel[3];
} imu_stats_t;

static void run_imu(uint64_t seed, unsigned n, imu_stats_t *st, ps_devices_imu_t *out_imu,
                    uint64_t *out_hash)
{
    const ps_imu_cfg_t cfg = imu_cfg(1);
    const ps_sim_devices_cfg_t sim = sim_cfg();
    ps_devices_init_imu(out_imu, &cfg, &sim, seed);
    const double g[3] = {0.0, 0.0, 0.0}, a[3] = {0.0, 0.0, 9.81};
    double sg[3] = {0}, sgg[3] = {0}, sa[3] = {0}, saa[3] = {0};
    uint64_t h = 1469598103934665603ull; /* FNV-1a over every frame byte */
    ps_imu_msg_rx_t rx;
    ps_imu_msg_rx_init(&rx, cfg.base_id);
    for (unsigned k = 0; k < n; k++) {
        ps_can_frame_t out[PS_IMU_MAX_FRAMES];
        assert_int_equal(ps_devices_tick_imu(out_imu, k, g, a, 0, out), 2);
        for (unsigned f = 0; f < 2; f++)
            for (unsigned b = 0; b < 8; b++)
                h = (h ^ out[f].data[b]) * 1099511628211ull;
        ps_imu_sample_t s;
        assert_int_equal(ps_imu_msg_rx_feed(&rx, &out[0], &s), 0);
        assert_int_equal(ps_imu_msg_rx_feed(&rx, &out[1], &s), 1);
        for (unsigned ax = 0; ax < 3; ax++) {
            sg[ax] += s.gyro_body_rad_s[ax];
            sgg[ax] += (double)s.gyro_body_rad_s[ax] * s.gyro_body_rad_s[ax];
            sa[ax] += s.accel_body_m_s2[ax] - a[ax];
            saa[ax] += ((double)s.accel_body_m_s2[ax] - a[ax]) * (s.accel_body_m_s2[ax] - a[ax]);
        }
    }
    for (unsigned ax = 0; ax < 3; ax++) {
        st->mean_gyro[ax] = sg[ax] / n;
        st->std_gyro[ax] = sqrt(sgg[ax] / n - st->mean_gyro[ax] * st->mean_gyro[ax]);
        st->mean_accel[ax] = sa[ax] / n;
        st->std_accel[ax] = sqrt(saa[ax] / n - st->mean_accel[ax] * st->mean_accel[ax]);
    }
    *out_hash = h;
}

static void test_tick_imu_noise_statistics_match_sigma_and_bias(void **state)
{
    (void)state;
    const unsigned n = 40000;
    imu_stats_t st;
    ps_devices_imu_t imu;
    uint64_t h;
    run_imu(42, n, &st, &imu, &h);
    for (unsigned ax = 0; ax < 3; ax++) {
        /* Bias drawn in [-b, b]; the sample mean is the bias within 5 standard
         * errors plus half an LSB of quantisation. */
        assert_true(fabs(imu.gyro_bias_rad_s[ax]) <= 0.01);
        assert_true(fabs(imu.accel_bias_m_s2[ax]) <= 0.1);
        assert_true(fabs(st.mean_gyro[ax] - imu.gyro_bias_rad_s[ax]) < 5 * 0.02 / sqrt(n) + 0.0005);
        assert_true(fabs(st.mean_accel[ax] - imu.accel_bias_m_s2[ax]) < 5 * 0.05 / sqrt(n) + 0.001);
        /* Standard deviation within 3 % of sigma (its standard error is 0.35 %). */
        assert_true(fabs(st.std_gyro[ax] / 0.02 - 1.0) < 0.03);
        assert_true(fabs(st.std_accel[ax] / 0.05 - 1.0) < 0.03);
    }
    /* Biases are not all zero (they were drawn). */
    assert_true(fabs(imu.gyro_bias_rad_s[0]) + fabs(imu.gyro_bias_rad_s[1]) > 1e-6);
}

static void test_tick_imu_same_seed_identical_other_seed_differs(void **state)
{
    (void)state;
    imu_stats_t st;
    ps_devices_imu_t i1, i2, i3;
    uint64_t h1, h2, h3;
    run_imu(1234, 500, &st, &i1, &h1);
    run_imu(1234, 500, &st, &i2, &h2);
    run_imu(1235, 500, &st, &i3, &h3);
    assert_true(h1 == h2);
    assert_true(memcmp(i1.gyro_bias_rad_s, i2.gyro_bias_rad_s, sizeof i1.gyro_bias_rad_s) == 0);
    assert_true(h1 != h3);
    assert_true(i1.gyro_bias_rad_s[0] != i3.gyro_bias_rad_s[0]);
}

/* A geared, reversed joint: the host encodes joint units through the actuator
 * port, the emulated drive decodes motor units and acts in joint units, and
 * its reply reads back as the joint's position and torque. */
static void test_handle_frame_geared_reversed_joint_obeys_joint_units(void **state)
{
    fixture_t *fx = *state;
    fx->j.gear_ratio = 2.0f;
    fx->j.direction = -1.0f;
    fx->j.zero_offset_rad = 0.1f;
    ps_devices_init_actuator(&fx->a, &fx->j, &fx->lim, &fx->sim);
    enter(fx, 0);
    const ps_act_cmd_t joint_cmd = {.q_rad = 0.5f, .kp_nm_rad = 40.0f};
    ps_can_frame_t f[PS_ACT_MAX_FRAMES], rep;
    assert_int_equal(ps_act_encode_command(&fx->j, &joint_cmd, f, PS_ACT_MAX_FRAMES), 1);
    f[0].t_ns = 1000;
    assert_int_equal(ps_devices_handle_frame(&fx->a, &f[0], 0.4, 0.0, &rep), 1);
    /* decoded back to joint units within one quantisation step */
    assert_float_equal(fx->a.cmd.q_rad, 0.5f, 25.0f / 65535.0f);
    assert_float_equal(fx->a.cmd.kp_nm_rad, 40.0f, 4.0f * 500.0f / 4095.0f);
    const double tau = ps_devices_step_actuator(&fx->a, 0.4, 0.0, 2000, 1e-3);
    /* tau_ff is the mid code of +-18 Nm motor side: 0.0044 Nm, -0.0088 at the joint */
    assert_float_equal(fx->a.cmd.tau_ff_nm, -2.0f * 18.0f / 4095.0f, 1e-5f);
    assert_float_equal(tau,
                       (double)fx->a.cmd.kp_nm_rad * ((double)fx->a.cmd.q_rad - 0.4) +
                           (double)fx->a.cmd.tau_ff_nm,
                       1e-4);
    assert_true(tau > 3.8 && tau < 4.2); /* 40 Nm/rad x 0.1 rad, joint side */
    /* the reply, decoded by the host's port, gives the joint's angle and torque */
    ps_act_meas_t m = {0};
    assert_int_equal(ps_act_decode_reply(&fx->j, &rep, &m), 0);
    assert_float_equal(m.q_rad, 0.4f, 2.0f * 25.0f / 65535.0f);
    assert_float_equal(m.tau_nm, (float)tau, 2.0f * 80.0f / 4095.0f * 0.5f * 2.0f);
}

/* Set zero on a drive whose joint has a configured zero offset: from then on
 * the motor reads 0 where the joint is, so the host (which adds the offset)
 * sees the joint at zero_offset_rad there, like a real drive. */
static void test_handle_frame_set_zero_with_zero_offset_reads_offset(void **state)
{
    fixture_t *fx = *state;
    fx->j.gear_ratio = 2.0f;
    fx->j.direction = -1.0f;
    fx->j.zero_offset_rad = 0.1f;
    ps_devices_init_actuator(&fx->a, &fx->j, &fx->lim, &fx->sim);
    ps_can_frame_t f[PS_ACT_MAX_FRAMES], rep;
    assert_int_equal(ps_act_encode_request(&fx->j, PS_ACT_REQ_SET_ZERO, f, PS_ACT_MAX_FRAMES), 1);
    assert_int_equal(ps_devices_handle_frame(&fx->a, &f[0], 0.4, 0.0, &rep), 1);
    ps_act_meas_t m = {0};
    assert_int_equal(ps_act_decode_reply(&fx->j, &rep, &m), 0);
    assert_float_equal(m.q_rad, 0.1f, 2.0f * 25.0f / 65535.0f);
    /* and the motor-side zero moved with the joint: 0.1 rad further reads 0.2 */
    assert_int_equal(ps_devices_handle_frame(&fx->a, &f[0], 0.4, 0.0, &rep), 1); /* idempotent */
    const ps_act_cmd_t none = {.q_rad = 0.1f};
    assert_int_equal(ps_act_encode_command(&fx->j, &none, f, PS_ACT_MAX_FRAMES), 1);
    assert_int_equal(ps_devices_handle_frame(&fx->a, &f[0], 0.5, 0.0, &rep), 1);
    assert_int_equal(ps_act_decode_reply(&fx->j, &rep, &m), 0);
    assert_float_equal(m.q_rad, 0.2f, 2.0f * 25.0f / 65535.0f);
}

/* The winding loss follows the motor's current, joint torque / (N kt): with
 * gear ratio 2 the same joint torque needs half the motor current, a quarter
 * of the copper loss (kp is quantised on the motor side, so each run's own
 * torque is used). */
static void test_step_actuator_geared_copper_loss_quarter(void **state)
{
    fixture_t *fx = *state;
    double rise[2], tau[2];
    for (int k = 0; k < 2; k++) {
        fx->j.gear_ratio = k == 0 ? 1.0f : 2.0f;
        ps_devices_init_actuator(&fx->a, &fx->j, &fx->lim, &fx->sim);
        enter(fx, 0);
        /* kp 10 Nm/rad, 0.5 rad off: about 5 Nm at the joint */
        const ps_act_cmd_t c = {.q_rad = 0.5f, .kp_nm_rad = 10.0f};
        ps_can_frame_t f[PS_ACT_MAX_FRAMES], rep;
        assert_int_equal(ps_act_encode_command(&fx->j, &c, f, PS_ACT_MAX_FRAMES), 1);
        f[0].t_ns = 1000;
        assert_int_equal(ps_devices_handle_frame(&fx->a, &f[0], 0.0, 0.0, &rep), 1);
        const double t0 = fx->a.temp_c;
        tau[k] = ps_devices_step_actuator(&fx->a, 0.0, 0.0, 2000, 1.0);
        assert_true(fabs(tau[k] - 5.0) < 0.2);
        rise[k] = fx->a.temp_c - t0;
    }
    assert_true(rise[0] > 0.0);
    const double want = (tau[1] / 2.0) * (tau[1] / 2.0) / (tau[0] * tau[0]);
    assert_float_equal(rise[1] / rise[0], want, 1e-6);
    assert_float_equal(want, 0.25, 0.02);
}

/* ---- drive dynamics: PD rate and torque-speed limit ------------------- */

/* A drive at 1 kHz PD under a 0.5 ms physics step: the torque of one PD
 * update holds for two steps, then follows the new state. */
static void test_step_actuator_pd_rate_holds_torque_between_updates(void **state)
{
    fixture_t *fx = *state;
    fx->j.motor = (ps_act_motor_t){100.0f, 40.0f, 17.0f, 20.0f, 0.04f, 1000.0f};
    ps_devices_init_actuator(&fx->a, &fx->j, &fx->lim, &fx->sim);
    enter(fx, 0);
    const ps_mit_cmd_t c = {.p_rad = 0.5f, .kp_nm_rad = 10.0f};
    ps_can_frame_t rep;
    send_cmd(fx, &c, 0.0, 0.0, 1000, &rep);
    const int64_t t0 = 2000000;
    const double tau0 = ps_devices_step_actuator(&fx->a, 0.0, 0.0, t0, 5e-4);
    const double tau1 = ps_devices_step_actuator(&fx->a, 0.2, 0.0, t0 + 500000, 5e-4);
    const double tau2 = ps_devices_step_actuator(&fx->a, 0.2, 0.0, t0 + 1000000, 5e-4);
    assert_true(tau0 > 4.9);
    assert_true(tau1 == tau0);       /* held: the PD has not run since */
    assert_true(fabs(tau2 - (tau0 - 10.0 * 0.2)) < 0.01); /* the next PD update */
}

/* The torque-speed limit acts on the torque the drive delivers at the
 * joint's speed, after the PD, on every step. */
static void test_step_actuator_torque_speed_limit_at_speed(void **state)
{
    fixture_t *fx = *state;
    /* stall = 10 * 20 / (20 - 15) = 40 Nm; peak 12, so at 18 rad/s the line
     * gives 40 (1 - 18 / 20) = 4 Nm while motoring. */
    fx->j.motor = (ps_act_motor_t){12.0f, 10.0f, 15.0f, 20.0f, 0.01f, 1e6f};
    fx->lim.vel_max_rad_s = 20.0f;
    ps_devices_init_actuator(&fx->a, &fx->j, &fx->lim, &fx->sim);
    enter(fx, 0);
    const ps_mit_cmd_t c = {.p_rad = 1.5f, .kp_nm_rad = 200.0f};
    ps_can_frame_t rep;
    send_cmd(fx, &c, 0.0, 0.0, 1000, &rep);
    assert_true(fabs(ps_devices_step_actuator(&fx->a, 0.0, 0.0, 2000, 5e-4) - 12.0) < 1e-6);
    assert_true(fabs(ps_devices_step_actuator(&fx->a, 0.0, 18.0, 3000, 5e-4) - 4.0) < 1e-4);
    /* braking (moving the other way) the peak is available */
    assert_true(fabs(ps_devices_step_actuator(&fx->a, 0.0, -18.0, 4000, 5e-4) - 12.0) < 1e-6);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup(test_handle_frame_cmd_before_enter_ignored_but_replied, setup),
        cmocka_unit_test_setup(test_handle_frame_exit_goes_limp, setup),
        cmocka_unit_test_setup(test_step_actuator_pd_equals_quantised_command, setup),
        cmocka_unit_test_setup(test_step_actuator_large_error_saturates_at_torque_max, setup),
        cmocka_unit_test_setup(test_step_actuator_joint_above_wire_saturates_at_wire_t, setup),
        cmocka_unit_test_setup(test_handle_frame_reply_content_ids_and_latency, setup),
        cmocka_unit_test_setup(test_handle_frame_zero_offsets_position, setup),
        cmocka_unit_test_setup(test_handle_frame_drop_knob_suppresses_reply_obeys_cmd, setup),
        cmocka_unit_test_setup(test_handle_frame_other_id_enoent_not_counted, setup),
        cmocka_unit_test_setup(test_handle_frame_bad_len_or_fd_protocol_counted, setup),
        cmocka_unit_test_setup(test_step_actuator_no_cmd_100ms_limp_comms_lost, setup),
        cmocka_unit_test_setup(test_handle_frame_out_of_limit_fields_counted, setup),
        cmocka_unit_test_setup(test_step_actuator_temp_follows_first_order_model, setup),
        cmocka_unit_test_setup(test_step_actuator_above_temp_max_faults_and_refuses_enter, setup),
        cmocka_unit_test_setup(test_handle_frame_geared_reversed_joint_obeys_joint_units, setup),
        cmocka_unit_test_setup(test_handle_frame_set_zero_with_zero_offset_reads_offset, setup),
        cmocka_unit_test_setup(test_step_actuator_geared_copper_loss_quarter, setup),
        cmocka_unit_test_setup(test_step_actuator_pd_rate_holds_torque_between_updates, setup),
        cmocka_unit_test_setup(test_step_actuator_torque_speed_limit_at_speed, setup),
        cmocka_unit_test(test_tick_imu_rate_div_frames_ids_and_seq),
        cmocka_unit_test(test_tick_imu_noise_statistics_match_sigma_and_bias),
        cmocka_unit_test(test_tick_imu_same_seed_identical_other_seed_differs),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
