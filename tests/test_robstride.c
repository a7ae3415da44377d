/*
 * Tests of drivers/ps_robstride: the RobStride / CyberGear frames against
 * bytes computed by hand from the vendor's layout (the CyberGear instruction
 * manual, section 4.1: 29-bit identifier = type | data area 2 | target, 16-bit
 * big-endian fields mapped over their ranges), with the CyberGear ranges:
 * angle +-4 pi rad, velocity +-30 rad/s, kp 0..500, kd 0..5, torque +-12 Nm.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <math.h>
#include <string.h>

#include "../drivers/ps_actuator.h"
#include "../drivers/ps_robstride.h"
#include "../rt/ps_err.h"
#include "fakes/ps_test_wire.h"
#include "../sim/ps_devices.h"

#define PI_F 3.14159265f

/* Drive 0x01 of host 0xFD. */
static ps_act_cfg_t cybergear(void)
{
    return ps_test_wire_cybergear();
}

static void test_ps_robstride_proto_table_shape(void **state)
{
    (void)state;
    const ps_act_proto_t *p = ps_act_proto_get(PS_ACT_PROTO_ROBSTRIDE);
    assert_ptr_equal(p, &ps_robstride_proto);
    assert_int_equal(ps_act_proto_find("robstride"), PS_ACT_PROTO_ROBSTRIDE);
    assert_int_equal(p->id_bits, 29);
    assert_false(p->is_fd);
    assert_int_equal(p->cmd_len, 8);
    assert_int_equal(p->id_max, 0xff);
    assert_true(p->is_reply_id_shared);
    char err[128];
    ps_act_cfg_t a = cybergear();
    assert_int_equal(ps_act_check_cfg(&a, err, sizeof err), 0);
    a.can_id = 0x100; /* drive ids are 8 bits */
    assert_int_equal(ps_act_check_cfg(&a, err, sizeof err), -EINVAL);
}

/* All zero: angle, velocity and torque on symmetric ranges land on the half
 * step 32767.5, rounded up to 0x8000; kp = kd = 0. Identifier: type 1,
 * torque 0x8000 in bits 23..8, drive 0x01: 0x01800001. */
static void test_ps_act_encode_command_robstride_zero_hand_vector(void **state)
{
    (void)state;
    const ps_act_cfg_t a = cybergear();
    const ps_act_cmd_t cmd = {0};
    ps_can_frame_t f[PS_ACT_MAX_FRAMES];
    assert_int_equal(ps_act_encode_command(&a, &cmd, f, PS_ACT_MAX_FRAMES), 1);
    assert_true(f[0].is_ext);
    assert_false(f[0].is_fd);
    assert_int_equal(f[0].id, 0x01800001);
    assert_int_equal(f[0].len, 8);
    static const uint8_t WANT[8] = {0x80, 0x00, 0x80, 0x00, 0x00, 0x00, 0x00, 0x00};
    assert_memory_equal(f[0].data, WANT, 8);
}

/* q = pi: (pi + 4 pi) / 8 pi = 0.625 of 65535 = 40959.375 -> 0x9FFF;
 * qd = -15: 15/60 of 65535 = 16383.75 -> 0x4000; kp 100 and kd 1: 1/5 of
 * 65535 = 13107 = 0x3333; tau 6: 18/24 of 65535 = 49151.25 -> 0xBFFF in
 * the identifier: 0x01BFFF01. */
static void test_ps_act_encode_command_robstride_hand_vector(void **state)
{
    (void)state;
    const ps_act_cfg_t a = cybergear();
    const ps_act_cmd_t cmd = {.q_rad = PI_F,
                              .qd_rad_s = -15.0f,
                              .kp_nm_rad = 100.0f,
                              .kd_nm_s_rad = 1.0f,
                              .tau_ff_nm = 6.0f};
    ps_can_frame_t f[PS_ACT_MAX_FRAMES];
    assert_int_equal(ps_act_encode_command(&a, &cmd, f, PS_ACT_MAX_FRAMES), 1);
    assert_int_equal(f[0].id, 0x01BFFF01);
    static const uint8_t WANT[8] = {0x9F, 0xFF, 0x40, 0x00, 0x33, 0x33, 0x33, 0x33};
    assert_memory_equal(f[0].data, WANT, 8);
    /* the drive side reads it back within one step of each field */
    ps_act_cmd_t back;
    assert_int_equal(ps_robstride_proto.decode_cmd(&a, &f[0], &back), 0);
    assert_float_equal(back.q_rad, PI_F, 8.0f * PI_F / 65535.0f);
    assert_float_equal(back.qd_rad_s, -15.0f, 60.0f / 65535.0f);
    assert_float_equal(back.kp_nm_rad, 100.0f, 500.0f / 65535.0f);
    assert_float_equal(back.kd_nm_s_rad, 1.0f, 5.0f / 65535.0f);
    assert_float_equal(back.tau_ff_nm, 6.0f, 24.0f / 65535.0f);
    assert_int_equal(ps_robstride_proto.classify_request(&a, &f[0]), -ENOENT); /* a command */
    /* out of the wire range: refused, never clamped */
    const ps_act_cmd_t fast = {.qd_rad_s = 31.0f};
    assert_int_equal(ps_act_encode_command(&a, &fast, f, PS_ACT_MAX_FRAMES), -PS_ERR_LIMIT);
}

/* Enable type 3, stop type 4 (data[0] = 1: and clear faults), zero type 6
 * with data[0] = 1; host 0xFD in bits 15..8, drive 0x01. */
static void test_ps_act_encode_request_robstride_frames(void **state)
{
    (void)state;
    const ps_act_cfg_t a = cybergear();
    const struct {
        ps_act_request_t req;
        uint32_t id;
        uint8_t byte0;
    } CASES[] = {
        {PS_ACT_REQ_ENABLE, 0x0300FD01, 0},
        {PS_ACT_REQ_DISABLE, 0x0400FD01, 0},
        {PS_ACT_REQ_CLEAR_FAULT, 0x0400FD01, 1},
        {PS_ACT_REQ_SET_ZERO, 0x0600FD01, 1},
    };
    for (size_t i = 0; i < sizeof CASES / sizeof CASES[0]; i++) {
        ps_can_frame_t f[PS_ACT_MAX_FRAMES];
        assert_int_equal(ps_act_encode_request(&a, CASES[i].req, f, PS_ACT_MAX_FRAMES), 1);
        assert_int_equal(f[0].id, CASES[i].id);
        assert_true(f[0].is_ext);
        assert_int_equal(f[0].len, 8);
        assert_int_equal(f[0].data[0], CASES[i].byte0);
        for (unsigned k = 1; k < 8; k++)
            assert_int_equal(f[0].data[k], 0);
        assert_true(ps_robstride_proto.is_for_drive(&a, &f[0]));
        assert_int_equal(ps_robstride_proto.classify_request(&a, &f[0]), (int)CASES[i].req);
    }
    /* another drive's frames are not this one's */
    ps_act_cfg_t other = a;
    other.can_id = 0x02;
    ps_can_frame_t f[1];
    assert_int_equal(ps_act_encode_request(&other, PS_ACT_REQ_ENABLE, f, 1), 1);
    assert_false(ps_robstride_proto.is_for_drive(&a, &f[0]));
}

/* Feedback: type 2, mode 2 (run) in bits 23..22, over-temperature in bit 18,
 * drive 0x01 in bits 15..8, host 0xFD: 0x028401FD. Data: angle 0x9FFF,
 * velocity 0x8000, torque 0xBFFF, temperature 0x01F4 = 500 -> 50.0 degC. */
static void test_ps_act_decode_reply_robstride_hand_vector(void **state)
{
    (void)state;
    const ps_act_cfg_t a = cybergear();
    ps_can_frame_t f;
    memset(&f, 0, sizeof f);
    f.id = 0x028401FD;
    f.is_ext = 1;
    f.len = 8;
    const uint8_t data[8] = {0x9F, 0xFF, 0x80, 0x00, 0xBF, 0xFF, 0x01, 0xF4};
    memcpy(f.data, data, 8);
    ps_act_meas_t m = {0};
    assert_int_equal(ps_act_decode_reply(&a, &f, &m), 0);
    assert_float_equal(m.q_rad, 40959.0f * 8.0f * PI_F / 65535.0f - 4.0f * PI_F, 1e-5f);
    assert_float_equal(m.qd_rad_s, 32768.0f * 60.0f / 65535.0f - 30.0f, 1e-5f);
    assert_float_equal(m.tau_nm, 49151.0f * 24.0f / 65535.0f - 12.0f, 1e-5f);
    assert_float_equal(m.temp_c, 50.0f, 1e-6f);
    assert_int_equal(m.fault_bits, PS_ACT_FAULT_MOTOR_OVERTEMP);
    /* every fault bit of the field */
    assert_int_equal(ps_robstride_fault_bits(1u << 16), PS_ACT_FAULT_UNDERVOLTAGE);
    assert_int_equal(ps_robstride_fault_bits(1u << 17), PS_ACT_FAULT_OVERCURRENT);
    assert_int_equal(ps_robstride_fault_bits(1u << 19), PS_ACT_FAULT_ENCODER);
    assert_int_equal(ps_robstride_fault_bits(1u << 20), PS_ACT_FAULT_ENCODER);
    assert_int_equal(ps_robstride_fault_bits(1u << 21), PS_ACT_FAULT_OTHER);
    assert_int_equal(ps_robstride_fault_bits(0x020001FD), 0);
    /* not this drive's: another drive, another host, an 11-bit frame, a command */
    f.id = 0x028402FD;
    assert_int_equal(ps_act_decode_reply(&a, &f, &m), -ENOENT);
    f.id = 0x028401FE;
    assert_int_equal(ps_act_decode_reply(&a, &f, &m), -ENOENT);
    f.id = 0x028401FD;
    f.is_ext = 0;
    assert_int_equal(ps_act_decode_reply(&a, &f, &m), -ENOENT);
    f.is_ext = 1;
    f.id = 0x01BFFF01;
    assert_int_equal(ps_act_decode_reply(&a, &f, &m), -ENOENT);
    /* its frame but short: malformed */
    f.id = 0x028401FD;
    f.len = 6;
    assert_int_equal(ps_act_decode_reply(&a, &f, &m), -PS_ERR_PROTOCOL);
}

/* The drive side's reply reads back through the host side, faults included. */
static void test_ps_robstride_encode_reply_round_trip(void **state)
{
    (void)state;
    const ps_act_cfg_t a = cybergear();
    const ps_act_meas_t sent = {.q_rad = -1.25f,
                                .qd_rad_s = 3.0f,
                                .tau_nm = -4.5f,
                                .temp_c = 41.3f,
                                .fault_bits = PS_ACT_FAULT_OVERCURRENT};
    ps_can_frame_t f[1];
    assert_int_equal(ps_robstride_proto.encode_reply(&a, &sent, f, 1), 1);
    assert_int_equal(f[0].id >> 24, 2);
    assert_int_equal((f[0].id >> 22) & 3u, 0); /* faulted: not in run mode */
    ps_act_meas_t got = {0};
    assert_int_equal(ps_act_decode_reply(&a, &f[0], &got), 0);
    assert_float_equal(got.q_rad, sent.q_rad, 8.0f * PI_F / 65535.0f);
    assert_float_equal(got.qd_rad_s, sent.qd_rad_s, 60.0f / 65535.0f);
    assert_float_equal(got.tau_nm, sent.tau_nm, 24.0f / 65535.0f);
    assert_float_equal(got.temp_c, 41.3f, 0.051f);
    assert_int_equal(got.fault_bits, PS_ACT_FAULT_OVERCURRENT);
    const ps_act_meas_t healthy = {.temp_c = 30.0f};
    assert_int_equal(ps_robstride_proto.encode_reply(&a, &healthy, f, 1), 1);
    assert_int_equal((f[0].id >> 22) & 3u, 2); /* run mode */
}

/* ---- fault report (type 21), CyberGear manual 4.1.10 -------------------- */

/* Drive 0x01, host 0xFD: id = 21 << 24 | 0xFD << 8 | 0x01 = 0x1500FD01;
 * fault value 0x00000005 (bit 0 motor over-temperature, bit 2 under-voltage)
 * little-endian in bytes 0..3; warning 0x00000001 in 4..7. */
static void test_robstride_fault_report_hand_vector(void **state)
{
    (void)state;
    const ps_act_cfg_t a = cybergear();
    ps_can_frame_t f = {.id = 0x1500FD01u,
                        .is_ext = 1,
                        .len = 8,
                        .data = {0x05, 0x00, 0x00, 0x00, 0x01, 0x00, 0x00, 0x00}};
    uint32_t bits = 0;
    assert_int_equal(ps_act_decode_fault(&a, &f, &bits), 0);
    assert_int_equal(bits, PS_ACT_FAULT_MOTOR_OVERTEMP | PS_ACT_FAULT_UNDERVOLTAGE);
    /* overload (bits 8..15), phase A over-current (bit 16), a bit the manual
     * does not name (6): OVERLOAD, OVERCURRENT, OTHER */
    f.data[0] = 0x40;
    f.data[1] = 0x03;
    f.data[2] = 0x01;
    assert_int_equal(ps_act_decode_fault(&a, &f, &bits), 0);
    assert_int_equal(bits, PS_ACT_FAULT_OVERLOAD | PS_ACT_FAULT_OVERCURRENT | PS_ACT_FAULT_OTHER);
    /* the warning alone is no fault */
    memset(f.data, 0, 8);
    f.data[4] = 0x01;
    assert_int_equal(ps_act_decode_fault(&a, &f, &bits), 0);
    assert_int_equal(bits, 0u);
    /* another host, another drive, a feedback frame, a short frame */
    ps_can_frame_t g = f;
    g.id = 0x1500FE01u;
    assert_int_equal(ps_act_decode_fault(&a, &g, &bits), -ENOENT);
    g.id = 0x1500FD02u;
    assert_int_equal(ps_act_decode_fault(&a, &g, &bits), -ENOENT);
    g.id = 0x020001FDu;
    assert_int_equal(ps_act_decode_fault(&a, &g, &bits), -ENOENT);
    g = f;
    g.len = 4;
    assert_int_equal(ps_act_decode_fault(&a, &g, &bits), -PS_ERR_PROTOCOL);
    /* the receive filter passes the report, not a neighbour's */
    uint32_t id, mask;
    ps_robstride_proto.fault_filter(&a, &id, &mask);
    assert_int_equal(f.id & mask, id & mask);
    assert_int_not_equal(0x1500FD02u & mask, id & mask);
}

/* The emulated drive: MOTOR_OVERTEMP | OVERVOLTAGE -> bits 0 and 3 = 0x09;
 * reported once per newly latched fault, again after a clear. */
static void test_robstride_emulated_drive_reports_each_new_fault_once(void **state)
{
    (void)state;
    const ps_act_cfg_t a = cybergear();
    const ps_act_limits_t lim = {.pos_min_rad = -1, .pos_max_rad = 1};
    const ps_sim_devices_cfg_t sim = {.ambient_c = 25};
    ps_devices_actuator_t d;
    ps_devices_init_actuator(&d, &a, &lim, &sim);
    ps_can_frame_t f;
    assert_int_equal(ps_devices_take_fault_report(&d, 100, &f), 0);
    d.fault_bits = PS_ACT_FAULT_MOTOR_OVERTEMP | PS_ACT_FAULT_OVERVOLTAGE;
    assert_int_equal(ps_devices_take_fault_report(&d, 100, &f), 1);
    assert_int_equal(f.id, 0x1500FD01u);
    assert_true(f.is_ext && f.len == 8 && f.t_ns == 100);
    static const uint8_t want[8] = {0x09, 0, 0, 0, 0, 0, 0, 0};
    assert_memory_equal(f.data, want, 8);
    uint32_t bits = 0;
    assert_int_equal(ps_act_decode_fault(&a, &f, &bits), 0);
    assert_int_equal(bits, PS_ACT_FAULT_MOTOR_OVERTEMP | PS_ACT_FAULT_OVERVOLTAGE);
    assert_int_equal(ps_devices_take_fault_report(&d, 200, &f), 0); /* nothing new */
    d.fault_bits = 0;                                               /* an enable cleared it */
    assert_int_equal(ps_devices_take_fault_report(&d, 300, &f), 0);
    d.fault_bits = PS_ACT_FAULT_MOTOR_OVERTEMP;
    assert_int_equal(ps_devices_take_fault_report(&d, 400, &f), 1);
    assert_int_equal(d.n_fault_reports, 2);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ps_robstride_proto_table_shape),
        cmocka_unit_test(test_ps_act_encode_command_robstride_zero_hand_vector),
        cmocka_unit_test(test_ps_act_encode_command_robstride_hand_vector),
        cmocka_unit_test(test_ps_act_encode_request_robstride_frames),
        cmocka_unit_test(test_ps_act_decode_reply_robstride_hand_vector),
        cmocka_unit_test(test_ps_robstride_encode_reply_round_trip),
        cmocka_unit_test(test_robstride_fault_report_hand_vector),
        cmocka_unit_test(test_robstride_emulated_drive_reports_each_new_fault_once),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
