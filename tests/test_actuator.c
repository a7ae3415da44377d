/*
 * Tests of drivers/ps_actuator: the protocol registry, the one place where
 * gear ratio, direction and zero offset are applied, and MIT mode as the
 * first protocol behind the neutral port. Frame bytes are computed by hand
 * from the MIT layout in docs/can-protocols.md.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <string.h>

#include "../drivers/ps_actuator.h"
#include "../drivers/ps_mit.h"
#include "../rt/ps_err.h"
#include "fakes/ps_test_wire.h"

/* AK-style wire: p +-12.5 rad, v +-45 rad/s, kp 0..500, kd 0..5, t +-18 Nm. */
static ps_act_cfg_t mit_cfg(void)
{
    ps_act_cfg_t a;
    memset(&a, 0, sizeof a);
    a.protocol = PS_ACT_PROTO_MIT;
    a.can_id = 0x13;
    a.reply_id = 0x113;
    a.wire = ps_test_wire_ak();
    a.gear_ratio = 1.0f;
    a.direction = 1.0f;
    a.kt_nm_a = 0.5f;
    a.temp_max_c = 80.0f;
    a.rate_div = 1;
    return a;
}

static void test_ps_act_proto_find_known_and_unknown(void **state)
{
    (void)state;
    assert_int_equal(ps_act_proto_find("mit"), PS_ACT_PROTO_MIT);
    assert_int_equal(ps_act_proto_find("no-such-protocol"), -ENOENT);
    assert_int_equal(ps_act_proto_find(NULL), -ENOENT);
    assert_ptr_equal(ps_act_proto_get(PS_ACT_PROTO_MIT), &ps_mit_proto);
    assert_null(ps_act_proto_get(PS_ACT_PROTO_COUNT));
    const ps_act_proto_t *p = &ps_mit_proto;
    assert_int_equal(p->id_bits, 11);
    assert_false(p->is_fd);
    assert_int_equal(p->cmd_len, 8);
    assert_int_equal(p->n_cmd, 1);
    assert_int_equal(p->id_max, 0x7ff);
}

/* All-zero command: p = round(12.5 * 65535 / 25) = 32768 (half up), v and t
 * at mid-code 2048, kp = kd = 0: 80 00 80 00 00 00 08 00. */
static void test_ps_act_encode_command_mit_zero_hand_vector(void **state)
{
    (void)state;
    const ps_act_cfg_t a = mit_cfg();
    const ps_act_cmd_t cmd = {0};
    ps_can_frame_t f[PS_ACT_MAX_FRAMES];
    assert_int_equal(ps_act_encode_command(&a, &cmd, f, PS_ACT_MAX_FRAMES), 1);
    static const uint8_t WANT[8] = {0x80, 0x00, 0x80, 0x00, 0x00, 0x00, 0x08, 0x00};
    assert_int_equal(f[0].id, 0x13);
    assert_int_equal(f[0].len, 8);
    assert_false(f[0].is_ext);
    assert_false(f[0].is_fd);
    assert_memory_equal(f[0].data, WANT, 8);
}

static void test_ps_act_encode_command_out_of_wire_limit_refused(void **state)
{
    (void)state;
    const ps_act_cfg_t a = mit_cfg();
    ps_can_frame_t f[PS_ACT_MAX_FRAMES];
    const ps_act_cmd_t too_far = {.q_rad = 13.0f};
    assert_int_equal(ps_act_encode_command(&a, &too_far, f, PS_ACT_MAX_FRAMES), -PS_ERR_LIMIT);
    const ps_act_cmd_t nan_tau = {.tau_ff_nm = NAN};
    assert_int_equal(ps_act_encode_command(&a, &nan_tau, f, PS_ACT_MAX_FRAMES), -PS_ERR_LIMIT);
    assert_int_equal(ps_act_encode_command(&a, &nan_tau, f, 0), -ENOSPC); /* room first */
    const ps_act_cmd_t ok = {0};
    assert_int_equal(ps_act_encode_command(&a, &ok, f, 0), -ENOSPC);
    assert_int_equal(ps_act_encode_command(NULL, &ok, f, 1), -EINVAL);
}

/* p, v, kp, kd all at their maxima and t near its maximum packs into the
 * special frames FF..FC/FD/FE: the MIT encoder steps kd down two LSB
 * (4095 -> 4093) and sends a set-point, never a mode change. */
static void test_ps_act_encode_command_mit_special_corner_kd_stepped_down(void **state)
{
    (void)state;
    const ps_act_cfg_t a = mit_cfg();
    const float taus[] = {17.99f, 17.98f, 17.974f}; /* t codes 0xFFE, 0xFFD, 0xFFC */
    for (size_t i = 0; i < 3; i++) {
        const ps_act_cmd_t corner = {.q_rad = 12.5f,
                                     .qd_rad_s = 45.0f,
                                     .kp_nm_rad = 500.0f,
                                     .kd_nm_s_rad = 5.0f,
                                     .tau_ff_nm = taus[i]};
        ps_can_frame_t f[PS_ACT_MAX_FRAMES];
        assert_int_equal(ps_act_encode_command(&a, &corner, f, PS_ACT_MAX_FRAMES), 1);
        assert_int_equal(ps_mit_classify_special(f[0].data, f[0].len), 0);
        const uint32_t kd = ((uint32_t)f[0].data[5] << 4) | (f[0].data[6] >> 4);
        assert_int_equal(kd, 0xFFD);
    }
}

static void test_ps_act_encode_request_mit_special_frames(void **state)
{
    (void)state;
    const ps_act_cfg_t a = mit_cfg();
    const struct {
        ps_act_request_t req;
        uint8_t last;
    } CASES[] = {
        {PS_ACT_REQ_ENABLE, 0xFC},
        {PS_ACT_REQ_DISABLE, 0xFD},
        {PS_ACT_REQ_SET_ZERO, 0xFE},
        {PS_ACT_REQ_CLEAR_FAULT, 0xFC}, /* MIT drives clear a fault when entered again */
    };
    for (size_t i = 0; i < sizeof CASES / sizeof CASES[0]; i++) {
        ps_can_frame_t f[PS_ACT_MAX_FRAMES];
        assert_int_equal(ps_act_encode_request(&a, CASES[i].req, f, PS_ACT_MAX_FRAMES), 1);
        assert_int_equal(f[0].id, 0x13);
        for (unsigned k = 0; k < 7; k++)
            assert_int_equal(f[0].data[k], 0xFF);
        assert_int_equal(f[0].data[7], CASES[i].last);
        /* and the drive side reads it back as the same request (clear = enable) */
        const int back = ps_mit_proto.classify_request(&a, &f[0]);
        assert_int_equal(back, CASES[i].req == PS_ACT_REQ_CLEAR_FAULT ? PS_ACT_REQ_ENABLE
                                                                      : (int)CASES[i].req);
    }
    ps_can_frame_t f[1];
    assert_int_equal(ps_act_encode_request(&a, PS_ACT_REQ_COUNT, f, 1), -EINVAL);
    assert_int_equal(ps_act_encode_request(&a, PS_ACT_REQ_ENABLE, f, 0), -ENOSPC);
}

/* Reply: byte 0 = id nibble 3 | fault 0xC << 4, p code 0x8000 (0.0002 rad),
 * v 0x800, i 0x800 (0.0098 A), temperatures 40 and 55 degC. */
static ps_can_frame_t mit_reply(uint32_t id, uint8_t byte0)
{
    ps_can_frame_t f;
    memset(&f, 0, sizeof f);
    f.id = id;
    f.len = 8;
    const uint8_t data[8] = {byte0, 0x80, 0x00, 0x80, 0x08, 0x00, 40, 55};
    memcpy(f.data, data, 8);
    return f;
}

static void test_ps_act_decode_reply_mit_hand_vector_fault_bits(void **state)
{
    (void)state;
    const ps_act_cfg_t a = mit_cfg();
    ps_can_frame_t f = mit_reply(0x113, 0xC3);
    ps_act_meas_t m = {.t_ns = 77};
    assert_int_equal(ps_act_decode_reply(&a, &f, &m), 0);
    assert_float_equal(m.q_rad, 32768.0f * 25.0f / 65535.0f - 12.5f, 1e-6f);
    assert_float_equal(m.qd_rad_s, 2048.0f * 90.0f / 4095.0f - 45.0f, 1e-5f);
    assert_float_equal(m.tau_nm, (2048.0f * 80.0f / 4095.0f - 40.0f) * 0.5f, 1e-5f);
    assert_float_equal(m.temp_c, 55.0f, 0.0f);
    assert_int_equal(m.fault_bits, PS_ACT_FAULT_MOTOR_OVERTEMP);
    assert_int_equal(m.t_ns, 77); /* the caller stamps the time */
    /* not this drive's: another id, a 29-bit or an FD frame with that id */
    f.id = 0x114;
    assert_int_equal(ps_act_decode_reply(&a, &f, &m), -ENOENT);
    f.id = 0x113;
    f.is_ext = 1;
    assert_int_equal(ps_act_decode_reply(&a, &f, &m), -ENOENT);
    f.is_ext = 0;
    f.is_fd = 1;
    assert_int_equal(ps_act_decode_reply(&a, &f, &m), -ENOENT);
    /* its id but another motor's nibble, or short: malformed */
    f = mit_reply(0x113, 0x04);
    assert_int_equal(ps_act_decode_reply(&a, &f, &m), -PS_ERR_PROTOCOL);
    f = mit_reply(0x113, 0x03);
    f.len = 6;
    assert_int_equal(ps_act_decode_reply(&a, &f, &m), -PS_ERR_PROTOCOL);
}

static void test_ps_mit_fault_bits_every_code(void **state)
{
    (void)state;
    assert_int_equal(ps_mit_fault_bits(PS_MIT_FAULT_NONE), 0);
    assert_int_equal(ps_mit_fault_bits(PS_MIT_FAULT_OVERVOLTAGE), PS_ACT_FAULT_OVERVOLTAGE);
    assert_int_equal(ps_mit_fault_bits(PS_MIT_FAULT_UNDERVOLTAGE), PS_ACT_FAULT_UNDERVOLTAGE);
    assert_int_equal(ps_mit_fault_bits(PS_MIT_FAULT_OVERCURRENT), PS_ACT_FAULT_OVERCURRENT);
    assert_int_equal(ps_mit_fault_bits(PS_MIT_FAULT_MOS_OVERTEMP), PS_ACT_FAULT_DRIVER_OVERTEMP);
    assert_int_equal(ps_mit_fault_bits(PS_MIT_FAULT_ROTOR_OVERTEMP), PS_ACT_FAULT_MOTOR_OVERTEMP);
    assert_int_equal(ps_mit_fault_bits(PS_MIT_FAULT_COMMS_LOST), PS_ACT_FAULT_COMMS_LOST);
    assert_int_equal(ps_mit_fault_bits(PS_MIT_FAULT_OVERLOAD), PS_ACT_FAULT_OVERLOAD);
    assert_int_equal(ps_mit_fault_bits(0x3), PS_ACT_FAULT_OTHER); /* no such code */
    for (uint8_t c = 0x8; c <= 0xE; c++)
        assert_int_equal(ps_mit_fault_code(ps_mit_fault_bits(c)), c);
    assert_string_equal(ps_act_fault_name(0), "none");
    assert_string_equal(ps_act_fault_name(PS_ACT_FAULT_COMMS_LOST), "COMMS_LOST");
}

/* Gear 2, direction -1, zero 0.25 rad: q_m = -2 (q_j - 0.25), kp_m = kp_j / 4,
 * tau_m = -tau_j / 2; and back. */
static void test_ps_act_cmd_to_motor_gear_direction_zero(void **state)
{
    (void)state;
    ps_act_cfg_t a = mit_cfg();
    a.gear_ratio = 2.0f;
    a.direction = -1.0f;
    a.zero_offset_rad = 0.25f;
    const ps_act_cmd_t j = {.q_rad = 1.25f,
                            .qd_rad_s = 3.0f,
                            .kp_nm_rad = 40.0f,
                            .kd_nm_s_rad = 2.0f,
                            .tau_ff_nm = 3.0f};
    ps_act_cmd_t m, back;
    ps_act_cmd_to_motor(&a, &j, &m);
    assert_float_equal(m.q_rad, -2.0f, 1e-6f);
    assert_float_equal(m.qd_rad_s, -6.0f, 1e-6f);
    assert_float_equal(m.kp_nm_rad, 10.0f, 1e-6f);
    assert_float_equal(m.kd_nm_s_rad, 0.5f, 1e-6f);
    assert_float_equal(m.tau_ff_nm, -1.5f, 1e-6f);
    ps_act_cmd_from_motor(&a, &m, &back);
    assert_float_equal(back.q_rad, j.q_rad, 1e-6f);
    assert_float_equal(back.qd_rad_s, j.qd_rad_s, 1e-6f);
    assert_float_equal(back.kp_nm_rad, j.kp_nm_rad, 1e-5f);
    assert_float_equal(back.kd_nm_s_rad, j.kd_nm_s_rad, 1e-6f);
    assert_float_equal(back.tau_ff_nm, j.tau_ff_nm, 1e-6f);
    /* the PD the drive runs on the motor side is the joint's: at q_j = 1.0,
     * tau_j = 40 (1.25 - 1.0) = 10 Nm; motor: 10 (-2 - (-1.5)) = -5 = -10 / 2 */
    const float q_m = -2.0f * (1.0f - 0.25f);
    assert_float_equal(m.kp_nm_rad * (m.q_rad - q_m), -10.0f / 2.0f, 1e-5f);

    const ps_act_meas_t mm = {.q_rad = -2.0f, .qd_rad_s = -6.0f, .tau_nm = 1.5f, .temp_c = 40.0f};
    ps_act_meas_t jm;
    ps_act_meas_from_motor(&a, &mm, &jm);
    assert_float_equal(jm.q_rad, 1.25f, 1e-6f);
    assert_float_equal(jm.qd_rad_s, 3.0f, 1e-6f);
    assert_float_equal(jm.tau_nm, -3.0f, 1e-6f);
    assert_float_equal(jm.temp_c, 40.0f, 0.0f);
    ps_act_meas_t mm2;
    ps_act_meas_to_motor(&a, &jm, &mm2);
    assert_float_equal(mm2.q_rad, mm.q_rad, 1e-6f);
    assert_float_equal(mm2.tau_nm, mm.tau_nm, 1e-6f);
}

static void test_ps_act_joint_range_gear_direction_zero(void **state)
{
    (void)state;
    ps_act_cfg_t a = mit_cfg();
    ps_act_range_t j;
    ps_act_joint_range(&a, &j); /* identity */
    assert_memory_equal(&j, &a.wire, sizeof j);
    a.gear_ratio = 2.0f;
    a.direction = -1.0f;
    a.zero_offset_rad = 0.25f;
    ps_act_joint_range(&a, &j);
    assert_float_equal(j.p_min_rad, 0.25f - 6.25f, 1e-6f);
    assert_float_equal(j.p_max_rad, 0.25f + 6.25f, 1e-6f);
    assert_float_equal(j.v_min_rad_s, -22.5f, 1e-6f);
    assert_float_equal(j.v_max_rad_s, 22.5f, 1e-6f);
    assert_float_equal(j.kp_max_nm_rad, 2000.0f, 1e-3f);
    assert_float_equal(j.kd_max_nm_s_rad, 20.0f, 1e-6f);
    assert_float_equal(j.t_min_nm, -36.0f, 1e-6f);
    assert_float_equal(j.t_max_nm, 36.0f, 1e-6f);
    /* an asymmetric wire range flips with the direction */
    a.wire.t_min_nm = -10.0f;
    ps_act_joint_range(&a, &j);
    assert_float_equal(j.t_min_nm, -36.0f, 1e-6f);
    assert_float_equal(j.t_max_nm, 20.0f, 1e-6f);
}

/* Every corner of the joint-side wire range encodes, whatever the gear
 * ratio, direction and zero offset (the conversion's float rounding used to
 * push some 1 ulp outside the motor-side range); just outside is refused. */
static void test_ps_act_encode_command_joint_range_corners_encode(void **state)
{
    (void)state;
    const float ratios[] = {1.0f, 3.3f, 6.0f, 7.3f, 9.0f, 10.0f, 13.7f, 36.0f};
    const float zeros[] = {0.0f, 0.1f, -0.37f, 1.234f};
    unsigned n_checked = 0;
    for (size_t r = 0; r < sizeof ratios / sizeof ratios[0]; r++)
        for (int d = -1; d <= 1; d += 2)
            for (size_t z = 0; z < sizeof zeros / sizeof zeros[0]; z++) {
                ps_act_cfg_t a = mit_cfg();
                a.gear_ratio = ratios[r];
                a.direction = (float)d;
                a.zero_offset_rad = zeros[z];
                ps_act_range_t j;
                ps_act_joint_range(&a, &j);
                for (unsigned c = 0; c < 32; c++) {
                    const ps_act_cmd_t cmd = {
                        .q_rad = (c & 1) ? j.p_max_rad : j.p_min_rad,
                        .qd_rad_s = (c & 2) ? j.v_max_rad_s : j.v_min_rad_s,
                        .kp_nm_rad = (c & 4) ? j.kp_max_nm_rad : 0.0f,
                        .kd_nm_s_rad = (c & 8) ? j.kd_max_nm_s_rad : 0.0f,
                        .tau_ff_nm = (c & 16) ? j.t_max_nm : j.t_min_nm,
                    };
                    ps_can_frame_t f[PS_ACT_MAX_FRAMES];
                    if (ps_act_encode_command(&a, &cmd, f, PS_ACT_MAX_FRAMES) != 1)
                        fail_msg("N %g d %d z %g corner %u refused", (double)ratios[r], d,
                                 (double)zeros[z], c);
                    n_checked++;
                }
                ps_act_cmd_t beyond = {.kp_nm_rad = j.kp_max_nm_rad * 1.001f};
                ps_can_frame_t f[PS_ACT_MAX_FRAMES];
                assert_int_equal(ps_act_encode_command(&a, &beyond, f, PS_ACT_MAX_FRAMES),
                                 -PS_ERR_LIMIT);
            }
    assert_int_equal(n_checked, 8u * 2u * 4u * 32u);
}

static void test_ps_act_check_cfg_rejects_each_bad_field(void **state)
{
    (void)state;
    char err[128];
    ps_act_cfg_t a = mit_cfg();
    assert_int_equal(ps_act_check_cfg(&a, err, sizeof err), 0);
    a.gear_ratio = 0.0f;
    assert_int_equal(ps_act_check_cfg(&a, err, sizeof err), -EINVAL);
    assert_non_null(strstr(err, "gear_ratio"));
    a = mit_cfg();
    a.direction = 0.5f;
    assert_int_equal(ps_act_check_cfg(&a, err, sizeof err), -EINVAL);
    assert_non_null(strstr(err, "direction"));
    a = mit_cfg();
    a.zero_offset_rad = INFINITY;
    assert_int_equal(ps_act_check_cfg(&a, err, sizeof err), -EINVAL);
    a = mit_cfg();
    a.can_id = 0x800; /* MIT ids are 11-bit */
    assert_int_equal(ps_act_check_cfg(&a, err, sizeof err), -EINVAL);
    assert_non_null(strstr(err, "0x7ff"));
    a = mit_cfg();
    a.wire.t_max_nm = a.wire.t_min_nm;
    assert_int_equal(ps_act_check_cfg(&a, err, sizeof err), -EINVAL);
    a = mit_cfg();
    a.protocol = PS_ACT_PROTO_COUNT;
    assert_int_equal(ps_act_check_cfg(&a, err, sizeof err), -EINVAL);
    assert_int_equal(ps_act_check_cfg(NULL, NULL, 0), -EINVAL);
}

/* ---- drive dynamics: the torque-speed limit --------------------------- */

/* RobStride 04's datasheet points (robots/ps1.yaml): 120 Nm peak, 40 Nm at
 * 167 rpm, 200 rpm no-load: stall torque 40 * 20.944 / (20.944 - 17.488)
 * = 242.41 Nm on the line. */
static const ps_act_motor_t RS04_MOTOR = {120.0f, 40.0f, 17.488f, 20.944f, 0.04f, 10000.0f};

static void test_ps_act_motor_limit_torque_rs04_by_hand(void **state)
{
    (void)state;
    const ps_act_motor_t *m = &RS04_MOTOR;
    const float stall = 40.0f * 20.944f / (20.944f - 17.488f);
    assert_float_equal(stall, 242.41f, 0.01f);
    /* at rest: the peak, either sign */
    assert_float_equal(ps_act_motor_limit_torque(m, 500.0f, 0.0f), 120.0f, 1e-4);
    assert_float_equal(ps_act_motor_limit_torque(m, -500.0f, 0.0f), -120.0f, 1e-4);
    assert_float_equal(ps_act_motor_limit_torque(m, 50.0f, 0.0f), 50.0f, 1e-6);
    /* the rated point lies on the line */
    assert_float_equal(ps_act_motor_limit_torque(m, 500.0f, 17.488f), 40.0f, 1e-3);
    /* motoring at 15 rad/s: 242.41 (1 - 15 / 20.944) = 68.80 Nm */
    assert_float_equal(ps_act_motor_limit_torque(m, 500.0f, 15.0f), 68.80f, 0.01f);
    assert_float_equal(ps_act_motor_limit_torque(m, -500.0f, -15.0f), -68.80f, 0.01f);
    /* braking at 15 rad/s: the peak */
    assert_float_equal(ps_act_motor_limit_torque(m, -500.0f, 15.0f), -120.0f, 1e-4);
    /* the line reaches the peak at 20.944 (1 - 120 / 242.41) = 10.577 rad/s */
    assert_float_equal(ps_act_motor_limit_torque(m, 500.0f, 10.0f), 120.0f, 1e-4);
    assert_true(ps_act_motor_limit_torque(m, 500.0f, 11.0f) < 120.0f);
    /* above no-load speed only braking is left */
    assert_true(ps_act_motor_limit_torque(m, 10.0f, 25.0f) < 0.0f);
    assert_true(isnan(ps_act_motor_limit_torque(m, NAN, 0.0f)));
    assert_true(isnan(ps_act_motor_limit_torque(m, 1.0f, NAN)));
    /* not modelled: unchanged */
    const ps_act_motor_t none = {0};
    assert_float_equal(ps_act_motor_limit_torque(&none, 500.0f, 15.0f), 500.0f, 0.0);
    assert_false(ps_act_motor_is_modelled(&none));
    assert_true(ps_act_motor_is_modelled(m));
}

static void test_ps_act_check_motor_rejects_each_bad_field(void **state)
{
    (void)state;
    char err[128];
    const ps_act_motor_t none = {0};
    assert_int_equal(ps_act_check_motor(&none, err, sizeof(err)), 0);
    assert_int_equal(ps_act_check_motor(&RS04_MOTOR, err, sizeof(err)), 0);
    static const struct {
        size_t off;
        float value;
        const char *key;
    } BAD[] = {
        {offsetof(ps_act_motor_t, peak_torque_nm), 0.0f, "peak_torque_nm:"},
        {offsetof(ps_act_motor_t, rated_torque_nm), 130.0f, "rated_torque_nm:"},
        {offsetof(ps_act_motor_t, rated_speed_rad_s), 21.0f, "rated_speed_rad_s:"},
        {offsetof(ps_act_motor_t, no_load_speed_rad_s), NAN, "rated_speed_rad_s:"},
        {offsetof(ps_act_motor_t, armature_kg_m2), -0.1f, "armature_kg_m2:"},
        {offsetof(ps_act_motor_t, pd_hz), 0.0f, "pd_hz:"},
    };
    for (size_t i = 0; i < sizeof(BAD) / sizeof(BAD[0]); i++) {
        ps_act_motor_t m = RS04_MOTOR;
        memcpy((char *)&m + BAD[i].off, &BAD[i].value, sizeof(float));
        assert_int_equal(ps_act_check_motor(&m, err, sizeof(err)), -EINVAL);
        assert_ptr_equal(strstr(err, BAD[i].key), err);
    }
    assert_int_equal(ps_act_check_motor(NULL, err, sizeof(err)), -EINVAL);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ps_act_proto_find_known_and_unknown),
        cmocka_unit_test(test_ps_act_encode_command_mit_zero_hand_vector),
        cmocka_unit_test(test_ps_act_encode_command_out_of_wire_limit_refused),
        cmocka_unit_test(test_ps_act_encode_command_mit_special_corner_kd_stepped_down),
        cmocka_unit_test(test_ps_act_encode_request_mit_special_frames),
        cmocka_unit_test(test_ps_act_decode_reply_mit_hand_vector_fault_bits),
        cmocka_unit_test(test_ps_mit_fault_bits_every_code),
        cmocka_unit_test(test_ps_act_cmd_to_motor_gear_direction_zero),
        cmocka_unit_test(test_ps_act_joint_range_gear_direction_zero),
        cmocka_unit_test(test_ps_act_encode_command_joint_range_corners_encode),
        cmocka_unit_test(test_ps_act_check_cfg_rejects_each_bad_field),
        cmocka_unit_test(test_ps_act_motor_limit_torque_rs04_by_hand),
        cmocka_unit_test(test_ps_act_check_motor_rejects_each_bad_field),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
