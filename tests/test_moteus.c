/*
 * Tests of drivers/ps_moteus: the moteus register frames against bytes
 * computed by hand from mjbots' published layout (mjbots/moteus
 * docs/protocol/can.md: id = source << 8 | destination, bit 15 asks for a
 * reply; subframes 0x00/0x04/0x08/0x0c write int8/int16/int32/float with the
 * count in the 2 LSBs or a varuint after, varuint start register, values
 * little-endian; 0x1x read, 0x2x reply, 0x50 nop; docs/protocol/registers.md:
 * registers, modes, fault codes, integer scalings), and against the two
 * example frames that can.md itself gives.
 *
 * Floats by hand (IEEE 754 binary32, bytes least significant first):
 *   0.25 = 0x3E800000 -> 00 00 80 3E     -0.5 = 0xBF000000 -> 00 00 00 BF
 *   2.5  = 0x40200000 -> 00 00 20 40      0.2 = 0x3E4CCCCD -> CD CC 4C 3E
 *   10.0 = 0x41200000 -> 00 00 20 41     -1.5 = 0xBFC00000 -> 00 00 C0 BF
 *   1.0  = 0x3F800000 -> 00 00 80 3F     11.0 = 0x41300000 -> 00 00 30 41
 * float(pi) = 0x40490FDB and float(2 pi) = 0x40C90FDB have the same
 * significand, so pi/2 -> 0.25 rev and -pi rad/s -> -0.5 rev/s exactly.
 *
 * Drive 0x0B, host 0x05: commands go on 0x850B (source 0x80 | 0x05), replies
 * come on 0x0B05. Wire: p +-4 pi rad, v +-20 rad/s, kp 0..200 Nm/rad (the
 * drive's servo.pid_position.kp = 200 * 2 pi Nm/rev), kd 0..5, t +-30 Nm.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <string.h>

#include "../drivers/ps_actuator.h"
#include "../drivers/ps_moteus.h"
#include "../rt/ps_err.h"
#include "fakes/ps_test_wire.h"

#define PI_F     3.14159265f
#define TWO_PI_F 6.28318548f
#define CMD_ID   0x850Bu
#define REPLY_ID 0x0B05u

static ps_act_cfg_t drive(void)
{
    return ps_test_wire_moteus();
}

/* An FD frame with a 29-bit id and these bytes, the rest NOP-free zero. */
static ps_can_frame_t fd_frame(uint32_t id, const uint8_t *data, uint8_t len)
{
    ps_can_frame_t f;
    memset(&f, 0, sizeof f);
    f.id = id;
    f.is_ext = 1;
    f.is_fd = 1;
    f.is_brs = 1;
    f.len = len;
    memcpy(f.data, data, len);
    return f;
}

static void assert_host_frame_shape(const ps_can_frame_t *f)
{
    assert_int_equal(f->id, CMD_ID);
    assert_true(f->is_ext);
    assert_true(f->is_fd);
    assert_true(f->is_brs);
    assert_int_equal(f->len, 32);
}

static void test_ps_moteus_proto_table_shape(void **state)
{
    (void)state;
    const ps_act_proto_t *p = ps_act_proto_get(PS_ACT_PROTO_MOTEUS);
    assert_ptr_equal(p, &ps_moteus_proto);
    assert_int_equal(ps_act_proto_find("moteus"), PS_ACT_PROTO_MOTEUS);
    assert_int_equal(p->id_bits, 29); /* command ids are >= 0x8000 */
    assert_true(p->is_fd);
    assert_int_equal(p->cmd_len, 32);
    assert_int_equal(p->reply_len, 32);
    assert_int_equal(p->n_cmd, 1);
    assert_int_equal(p->n_reply, 1);
    assert_true(p->is_reply_id_shared);
    /* can.md's example: from source 0 with the reply bit, to drive 1 */
    assert_int_equal(ps_moteus_id(PS_MOTEUS_REPLY_FLAG | 0u, 1u), 0x8001);
    char err[128];
    ps_act_cfg_t a = drive();
    assert_int_equal(ps_act_check_cfg(&a, err, sizeof err), 0);
    a.can_id = 7; /* the firmware would answer it with an 11-bit id (0x0705) */
    assert_int_equal(ps_act_check_cfg(&a, err, sizeof err), -EINVAL);
    assert_string_equal(err, "can_id/reply_id: 0x7/0x5 outside [0x8, 0x7e] for protocol moteus");
    a.can_id = 0x7f; /* broadcast */
    assert_int_equal(ps_act_check_cfg(&a, err, sizeof err), -EINVAL);
    a.can_id = 0x08;
    a.reply_id = 0x7f;
    assert_int_equal(ps_act_check_cfg(&a, err, sizeof err), -EINVAL);
    a.reply_id = 0x00; /* the host id moteus tools use */
    assert_int_equal(ps_act_check_cfg(&a, err, sizeof err), 0);
}

/* q = pi/2 rad = 0.25 rev, qd = -pi rad/s = -0.5 rev/s, tau 2.5 Nm,
 * kp 50 of 200 = scale 0.25, kd 1 of 5 = scale 0.2:
 *   01 00 0A          write int8 x1 at 0x000: mode 10
 *   0C 05 20          write float, count 5 (varuint), at 0x020
 *   00 00 80 3E  00 00 00 BF  00 00 20 40  00 00 80 3E  CD CC 4C 3E
 *   1C 04 00          read float x4 at 0x000
 *   10 06 0A          read int8 x6 at 0x00a
 * 3 + 3 + 20 + 3 + 3 = 32 bytes, an FD length: no padding. */
static void test_ps_act_encode_command_moteus_hand_vector(void **state)
{
    (void)state;
    const ps_act_cfg_t a = drive();
    const ps_act_cmd_t cmd = {.q_rad = PI_F / 2.0f,
                              .qd_rad_s = -PI_F,
                              .kp_nm_rad = 50.0f,
                              .kd_nm_s_rad = 1.0f,
                              .tau_ff_nm = 2.5f};
    ps_can_frame_t f[PS_ACT_MAX_FRAMES];
    assert_int_equal(ps_act_encode_command(&a, &cmd, f, PS_ACT_MAX_FRAMES), 1);
    assert_host_frame_shape(&f[0]);
    static const uint8_t WANT[32] = {
        0x01, 0x00, 0x0A, 0x0C, 0x05, 0x20, 0x00, 0x00, 0x80, 0x3E, 0x00,
        0x00, 0x00, 0xBF, 0x00, 0x00, 0x20, 0x40, 0x00, 0x00, 0x80, 0x3E,
        0xCD, 0xCC, 0x4C, 0x3E, 0x1C, 0x04, 0x00, 0x10, 0x06, 0x0A,
    };
    assert_memory_equal(f[0].data, WANT, 32);
    /* the drive side reads it back; it is a command, not a request */
    assert_true(ps_moteus_proto.is_for_drive(&a, &f[0]));
    assert_int_equal(ps_moteus_proto.classify_request(&a, &f[0]), -ENOENT);
    ps_act_cmd_t back;
    assert_int_equal(ps_moteus_proto.decode_cmd(&a, &f[0], &back), 0);
    assert_float_equal(back.q_rad, PI_F / 2.0f, 0.0f);
    assert_float_equal(back.qd_rad_s, -PI_F, 0.0f);
    assert_float_equal(back.kp_nm_rad, 50.0f, 0.0f);
    assert_float_equal(back.kd_nm_s_rad, 1.0f, 1e-6f);
    assert_float_equal(back.tau_ff_nm, 2.5f, 0.0f);
}

/* All zero: the same frame with twenty zero bytes for the five floats. */
static void test_ps_act_encode_command_moteus_zero_hand_vector(void **state)
{
    (void)state;
    const ps_act_cfg_t a = drive();
    const ps_act_cmd_t cmd = {0};
    ps_can_frame_t f[1];
    assert_int_equal(ps_act_encode_command(&a, &cmd, f, 1), 1);
    uint8_t want[32] = {0x01, 0x00, 0x0A, 0x0C, 0x05, 0x20};
    memcpy(&want[26], (const uint8_t[]){0x1C, 0x04, 0x00, 0x10, 0x06, 0x0A}, 6);
    assert_memory_equal(f[0].data, want, 32);
}

/* Out of the wire range, NaN or infinite: refused, never clamped, and the
 * output untouched; no room: -ENOSPC. */
static void test_ps_moteus_encode_cmd_refuses_out_of_range(void **state)
{
    (void)state;
    const ps_act_cfg_t a = drive();
    const ps_act_cmd_t ok = {.q_rad = 1.0f, .kp_nm_rad = 200.0f, .kd_nm_s_rad = 5.0f};
    ps_act_cmd_t bad[] = {ok, ok, ok, ok, ok, ok, ok, ok, ok};
    bad[0].q_rad = 4.0f * PI_F + 0.01f;
    bad[1].qd_rad_s = -20.5f;
    bad[2].kp_nm_rad = 200.5f;
    bad[3].kd_nm_s_rad = -0.1f;
    bad[4].tau_ff_nm = 30.5f;
    bad[5].q_rad = NAN;
    bad[6].qd_rad_s = INFINITY;
    bad[7].kd_nm_s_rad = NAN;
    bad[8].tau_ff_nm = -INFINITY;
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        ps_can_frame_t f[1];
        memset(f, 0xa5, sizeof f);
        assert_int_equal(ps_moteus_proto.encode_cmd(&a, &bad[i], f, 1), -PS_ERR_LIMIT);
        assert_int_equal(f[0].data[0], 0xa5);
        assert_int_equal(f[0].id, 0xa5a5a5a5u);
    }
    ps_can_frame_t f[1];
    assert_int_equal(ps_moteus_proto.encode_cmd(&a, &ok, f, 0), -ENOSPC);
    assert_int_equal(ps_moteus_proto.encode_request(&a, PS_ACT_REQ_ENABLE, f, 0), -ENOSPC);
    assert_int_equal(ps_moteus_proto.encode_cmd(&a, &ok, f, 1), 1); /* the edges are in */
}

/* Requests, each with the same query so the drive answers with a full reply,
 * padded with NOP (0x50) to 32 bytes:
 *   disable, clear fault  01 00 00 (mode 0: stopped, clears faults) + query
 *   enable   01 00 0A, 0C 05 20, 00 00 C0 7F (NaN: hold the present position),
 *            four zero floats (velocity, torque, kp and kd scale) + query
 *   set zero 0D B1 02 00 00 00 00: write float x1 at 0x131 (varuint of
 *            0x131 = 305: 0x31 | 0x80, then 305 >> 7 = 0x02), value 0.0 */
static void test_ps_act_encode_request_moteus_frames(void **state)
{
    (void)state;
    const ps_act_cfg_t a = drive();
    static const uint8_t QUERY[6] = {0x1C, 0x04, 0x00, 0x10, 0x06, 0x0A};
    uint8_t stop[32], enable[32], zero[32];
    memset(stop, 0x50, 32);
    memcpy(stop, (const uint8_t[]){0x01, 0x00, 0x00}, 3);
    memcpy(&stop[3], QUERY, 6);
    memset(enable, 0x00, 32);
    memcpy(enable, (const uint8_t[]){0x01, 0x00, 0x0A, 0x0C, 0x05, 0x20, 0x00, 0x00, 0xC0, 0x7F},
           10);
    memcpy(&enable[26], QUERY, 6);
    memset(zero, 0x50, 32);
    memcpy(zero, (const uint8_t[]){0x0D, 0xB1, 0x02, 0x00, 0x00, 0x00, 0x00}, 7);
    memcpy(&zero[7], QUERY, 6);
    const struct {
        ps_act_request_t req;
        const uint8_t *want;
        int classified;
    } CASES[] = {
        {PS_ACT_REQ_ENABLE, enable, PS_ACT_REQ_ENABLE},
        {PS_ACT_REQ_DISABLE, stop, PS_ACT_REQ_DISABLE},
        {PS_ACT_REQ_SET_ZERO, zero, PS_ACT_REQ_SET_ZERO},
        /* the drive stops when it clears a fault: one frame for both */
        {PS_ACT_REQ_CLEAR_FAULT, stop, PS_ACT_REQ_DISABLE},
    };
    for (size_t i = 0; i < sizeof CASES / sizeof CASES[0]; i++) {
        ps_can_frame_t f[PS_ACT_MAX_FRAMES];
        assert_int_equal(ps_act_encode_request(&a, CASES[i].req, f, PS_ACT_MAX_FRAMES), 1);
        assert_host_frame_shape(&f[0]);
        assert_memory_equal(f[0].data, CASES[i].want, 32);
        assert_true(ps_moteus_proto.is_for_drive(&a, &f[0]));
        assert_int_equal(ps_moteus_proto.classify_request(&a, &f[0]), CASES[i].classified);
    }
    /* another drive's frames are not this one's */
    ps_act_cfg_t other = a;
    other.can_id = 0x0C;
    ps_can_frame_t f[1];
    assert_int_equal(ps_act_encode_request(&other, PS_ACT_REQ_ENABLE, f, 1), 1);
    assert_int_equal(f[0].id, 0x850C);
    assert_false(ps_moteus_proto.is_for_drive(&a, &f[0]));
    /* an output position other than 0 is no request of ours: 0.5 rev */
    memcpy(zero, (const uint8_t[]){0x0D, 0xB1, 0x02, 0x00, 0x00, 0x00, 0x3F}, 7);
    const ps_can_frame_t half = fd_frame(CMD_ID, zero, 32);
    assert_int_equal(ps_moteus_proto.classify_request(&a, &half), -ENOENT);
    ps_act_cmd_t c;
    assert_int_equal(ps_moteus_proto.decode_cmd(&a, &half, &c), -PS_ERR_PROTOCOL);
}

/* Reply from drive 0x0B to host 0x05 (id 0x0B05):
 *   2C 04 00      reply float x4 at 0x000
 *   00 00 20 41   mode 10 (position)
 *   00 00 80 3E   position 0.25 rev = pi/2 rad
 *   00 00 00 BF   velocity -0.5 rev/s = -pi rad/s
 *   00 00 C0 BF   torque -1.5 Nm
 *   20 06 0A      reply int8 x6 at 0x00a
 *   2D 00 00 30 28 00   motor 45 degC, trajectory 0, home 0, 24 V
 *                       (48 x 0.5), board 40 degC, fault 0
 *   50 50 50 50   NOP padding to 32
 * Temperature: the hotter of motor and board, 45 degC. */
static const uint8_t REPLY[32] = {
    0x2C, 0x04, 0x00, 0x00, 0x00, 0x20, 0x41, 0x00, 0x00, 0x80, 0x3E, 0x00, 0x00, 0x00, 0xBF, 0x00,
    0x00, 0xC0, 0xBF, 0x20, 0x06, 0x0A, 0x2D, 0x00, 0x00, 0x30, 0x28, 0x00, 0x50, 0x50, 0x50, 0x50,
};

static void test_ps_act_decode_reply_moteus_hand_vector(void **state)
{
    (void)state;
    const ps_act_cfg_t a = drive();
    ps_can_frame_t f = fd_frame(REPLY_ID, REPLY, 32);
    ps_act_meas_t m = {.t_ns = 7};
    assert_int_equal(ps_act_decode_reply(&a, &f, &m), 0);
    assert_float_equal(m.q_rad, PI_F / 2.0f, 0.0f);
    assert_float_equal(m.qd_rad_s, -PI_F, 0.0f);
    assert_float_equal(m.tau_nm, -1.5f, 0.0f);
    assert_float_equal(m.temp_c, 45.0f, 0.0f);
    assert_int_equal(m.fault_bits, 0);
    assert_int_equal(m.t_ns, 7); /* untouched */
    /* no thermistor: the motor temperature reads -128 (not available) */
    f.data[22] = 0x80;
    assert_int_equal(ps_act_decode_reply(&a, &f, &m), 0);
    assert_float_equal(m.temp_c, 40.0f, 0.0f);
    /* fault: mode 1.0, code 38 (0x26, over-temperature) */
    memcpy(&f.data[3], (const uint8_t[]){0x00, 0x00, 0x80, 0x3F}, 4);
    f.data[27] = 0x26;
    assert_int_equal(ps_act_decode_reply(&a, &f, &m), 0);
    assert_int_equal(m.fault_bits, PS_ACT_FAULT_MOTOR_OVERTEMP);
    /* the drive's command timeout: mode 11.0, code 0 */
    memcpy(&f.data[3], (const uint8_t[]){0x00, 0x00, 0x30, 0x41}, 4);
    f.data[27] = 0x00;
    assert_int_equal(ps_act_decode_reply(&a, &f, &m), 0);
    assert_int_equal(m.fault_bits, PS_ACT_FAULT_COMMS_LOST);
    /* position mode, code 99 (0x63): the current limit at work, no fault */
    memcpy(&f.data[3], (const uint8_t[]){0x00, 0x00, 0x20, 0x41}, 4);
    f.data[27] = 0x63;
    assert_int_equal(ps_act_decode_reply(&a, &f, &m), 0);
    assert_int_equal(m.fault_bits, 0);
}

/* Found by tests/fuzz/fuzz_moteus: moteus sends floats, so a reply can hold
 * a torque that is finite on the motor side (1e38 Nm) and inf on a joint
 * geared 9:1; ps_act_decode_reply gave the loop that inf. Refused now, the
 * measurement untouched; the same reply on a direct drive still decodes. */
static void test_ps_act_decode_reply_moteus_not_finite_geared_refused(void **state)
{
    (void)state;
    ps_act_cfg_t a = drive();
    ps_can_frame_t f = fd_frame(REPLY_ID, REPLY, 32);
    memcpy(&f.data[15], (const uint8_t[]){0x99, 0x76, 0x96, 0x7e}, 4); /* 1e38 Nm */
    ps_act_meas_t m = {.q_rad = 3.0f, .t_ns = 7};
    assert_int_equal(ps_act_decode_reply(&a, &f, &m), 0);
    assert_float_equal(m.tau_nm, 1e38f, 1e31f);
    a.gear_ratio = 9.0f;
    m = (ps_act_meas_t){.q_rad = 3.0f, .t_ns = 7};
    assert_int_equal(ps_act_decode_reply(&a, &f, &m), -PS_ERR_PROTOCOL);
    assert_float_equal(m.q_rad, 3.0f, 0.0f);
    assert_int_equal(m.t_ns, 7);
}

/* can.md's own example reply, int16 values, 16 bytes:
 *   24 04 00  reply int16 x4 (varuint count) at 0x000
 *   0A 00     mode 10
 *   50 00     position 80 x 0.0001 rev = 0.008 rev (2.88 deg) = 0.0502655 rad
 *   00 01     velocity 256 x 0.00025 rev/s = 0.064 rev/s = 0.4021239 rad/s
 *   70 FF     torque -144 x 0.01 Nm = -1.44 Nm
 *   23 0D     reply int8 x3 at 0x00d
 *   18 14 00  voltage 24 x 0.5 = 12 V, temperature 20 degC, fault 0
 * (The example's id 0x100 is drive 1 to host 0; it decodes, but an id below
 * 0x800 is no reply this table's drives send.) */
static void test_ps_moteus_decode_reply_vendor_example(void **state)
{
    (void)state;
    const ps_act_cfg_t a = drive();
    static const uint8_t EX[16] = {0x24, 0x04, 0x00, 0x0a, 0x00, 0x50, 0x00, 0x00,
                                   0x01, 0x70, 0xff, 0x23, 0x0d, 0x18, 0x14, 0x00};
    ps_can_frame_t f = fd_frame(0x100, EX, 16);
    f.is_ext = 0;
    ps_act_meas_t m;
    assert_int_equal(ps_moteus_proto.decode_reply(&a, &f, &m), 0);
    assert_float_equal(m.q_rad, 0.008f * TWO_PI_F, 1e-6f);
    assert_float_equal(m.qd_rad_s, 0.064f * TWO_PI_F, 1e-6f);
    assert_float_equal(m.tau_nm, -1.44f, 1e-6f);
    assert_float_equal(m.temp_c, 20.0f, 0.0f);
    assert_int_equal(m.fault_bits, 0);
    assert_false(ps_moteus_proto.match_reply(&a, &f));
}

/* can.md's own example command, 16 bytes:
 *   01 00 0A  mode 10;  07 20: write int16 x3 at 0x020
 *   60 00     position 96 x 0.0001 = 0.0096 rev
 *   20 01     velocity 288 x 0.00025 = 0.072 rev/s
 *   50 FF     feed-forward torque -176 x 0.01 = -1.76 Nm
 *   14 04 00  read int16 x4 at 0x000;  13 0D: read int8 x3 at 0x00d
 * kp and kd scale are left out: the documented default 1.0, i.e. the
 * drive's configured gains (kp_max, kd_max of the wire). */
static void test_ps_moteus_decode_cmd_vendor_example(void **state)
{
    (void)state;
    const ps_act_cfg_t a = drive();
    static const uint8_t EX[16] = {0x01, 0x00, 0x0a, 0x07, 0x20, 0x60, 0x00, 0x20,
                                   0x01, 0x50, 0xff, 0x14, 0x04, 0x00, 0x13, 0x0d};
    const ps_can_frame_t f = fd_frame(0x8001, EX, 16);
    assert_int_equal(ps_moteus_proto.classify_request(&a, &f), -ENOENT);
    ps_act_cmd_t c;
    assert_int_equal(ps_moteus_proto.decode_cmd(&a, &f, &c), 0);
    assert_float_equal(c.q_rad, 0.0096f * TWO_PI_F, 1e-6f);
    assert_float_equal(c.qd_rad_s, 0.072f * TWO_PI_F, 1e-6f);
    assert_float_equal(c.tau_ff_nm, -1.76f, 1e-6f);
    assert_float_equal(c.kp_nm_rad, 200.0f, 0.0f);
    assert_float_equal(c.kd_nm_s_rad, 5.0f, 0.0f);
}

/* Found by tests/fuzz/fuzz_moteus: a position set-point of 1.27e38 rev is
 * finite but inf in rad; the decoded command was inf. Refused now, output
 * untouched; a large finite one still decodes. */
static void test_ps_moteus_decode_cmd_overflowing_scale_refused(void **state)
{
    (void)state;
    const ps_act_cfg_t a = drive();
    /* mode 10; write 5 floats at 0x020: position 0x7ec00000, velocity and
     * torque 0, kp and kd scale 1; NOP padding */
    static const uint8_t CRASH[32] = {0x01, 0x00, 0x0a, 0x0c, 0x05, 0x20, 0x00, 0x00,
                                      0xc0, 0x7e, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
                                      0x00, 0x00, 0x00, 0x00, 0x80, 0x3f, 0x00, 0x00,
                                      0x80, 0x3f, 0x50, 0x50, 0x50, 0x50, 0x50, 0x50};
    ps_can_frame_t f = fd_frame(0x810b, CRASH, 32);
    ps_act_cmd_t c = {.q_rad = 7.0f};
    assert_int_equal(ps_moteus_proto.decode_cmd(&a, &f, &c), -PS_ERR_PROTOCOL);
    assert_float_equal(c.q_rad, 7.0f, 0.0f);
    f.data[9] = 0x4e;  /* 1.6e9 rev: finite in rad */
    f.data[21] = 0x7f; /* and a kp scale of 3e38 is inf in Nm/rad */
    f.data[20] = 0x70;
    assert_int_equal(ps_moteus_proto.decode_cmd(&a, &f, &c), -PS_ERR_PROTOCOL);
    f.data[21] = 0x3f;
    f.data[20] = 0x80;
    assert_int_equal(ps_moteus_proto.decode_cmd(&a, &f, &c), 0);
    assert_true(isfinite(c.q_rad) && isfinite(c.qd_rad_s));
}

/* Malformed replies and commands: -PS_ERR_PROTOCOL, output untouched. */
static void test_ps_moteus_malformed_frames_refused(void **state)
{
    (void)state;
    const ps_act_cfg_t a = drive();
    struct {
        const char *what;
        size_t at;
        uint8_t bytes[4];
        size_t n;
        uint8_t len;
    } CASES[] = {
        {"read error subframe", 28, {0x31, 0x0f, 0x01}, 3, 32},
        {"write error subframe", 28, {0x30, 0x20, 0x02}, 3, 32},
        {"unknown subframe type", 28, {0x40}, 1, 32},
        {"a read inside a reply", 28, {0x11, 0x00}, 2, 32},
        {"a write inside a reply", 28, {0x01, 0x00, 0x0a}, 3, 32},
        {"floats cut short", 0, {0x2C, 0x09, 0x00}, 3, 32},
        {"varuint runs off the frame", 28, {0x2C, 0xff, 0xff, 0xff}, 4, 32},
        {"truncated by the length", 0, {0x2C}, 1, 12},
        {"not an FD length", 0, {0x2C}, 1, 13},
        {"mode 10.5", 3, {0x00, 0x00, 0x28, 0x41}, 4, 32},
        {"position NaN", 7, {0x00, 0x00, 0xC0, 0x7F}, 4, 32},
        {"board temperature not available", 26, {0x80}, 1, 32},
    };
    for (size_t i = 0; i < sizeof CASES / sizeof CASES[0]; i++) {
        ps_can_frame_t f = fd_frame(REPLY_ID, REPLY, 32);
        memcpy(&f.data[CASES[i].at], CASES[i].bytes, CASES[i].n);
        f.len = CASES[i].len;
        ps_act_meas_t m = {.q_rad = 123.0f};
        const int rc = ps_act_decode_reply(&a, &f, &m);
        if (rc != -PS_ERR_PROTOCOL)
            fail_msg("%s: rc %d", CASES[i].what, rc);
        assert_float_equal(m.q_rad, 123.0f, 0.0f);
    }
    /* well formed but without the torque: 2F 00 = reply float x3 at 0x000 */
    uint8_t short_reply[32];
    memset(short_reply, 0x50, 32);
    memcpy(short_reply, (const uint8_t[]){0x2F, 0x00}, 2);
    memcpy(&short_reply[2], &REPLY[3], 12);  /* mode, position, velocity */
    memcpy(&short_reply[14], &REPLY[19], 9); /* 20 06 0A + six int8 */
    ps_can_frame_t s = fd_frame(REPLY_ID, short_reply, 32);
    ps_act_meas_t m = {.q_rad = 123.0f};
    assert_int_equal(ps_act_decode_reply(&a, &s, &m), -PS_ERR_PROTOCOL);
    memcpy(short_reply, (const uint8_t[]){0x2C, 0x04, 0x00}, 3); /* with it: fine */
    memcpy(&short_reply[3], &REPLY[3], 16);
    memcpy(&short_reply[19], &REPLY[19], 9);
    s = fd_frame(REPLY_ID, short_reply, 32);
    assert_int_equal(ps_act_decode_reply(&a, &s, &m), 0);
    /* commands: no mode write, another mode, values before the mode write
     * (the firmware resets them), a classical frame */
    ps_can_frame_t f[1];
    const ps_act_cmd_t ok = {.q_rad = 1.0f};
    assert_int_equal(ps_act_encode_command(&a, &ok, f, 1), 1);
    ps_act_cmd_t c = {.q_rad = 99.0f};
    ps_can_frame_t g = f[0];
    g.data[0] = 0x50; /* the mode write becomes NOP, 00 0A a... */
    g.data[1] = 0x50;
    g.data[2] = 0x50;
    assert_int_equal(ps_moteus_proto.decode_cmd(&a, &g, &c), -PS_ERR_PROTOCOL);
    g = f[0];
    g.data[2] = 9; /* current mode */
    assert_int_equal(ps_moteus_proto.decode_cmd(&a, &g, &c), -PS_ERR_PROTOCOL);
    assert_int_equal(ps_moteus_proto.classify_request(&a, &g), -ENOENT);
    g = f[0];
    g.is_fd = 0;
    g.len = 8;
    assert_int_equal(ps_moteus_proto.decode_cmd(&a, &g, &c), -PS_ERR_PROTOCOL);
    assert_float_equal(c.q_rad, 99.0f, 0.0f);
    /* the set-points first, the mode after: the set-points are dropped and
     * the documented defaults apply (position 0, scales 1) */
    uint8_t late[32];
    memset(late, 0x50, 32);
    memcpy(late, &f[0].data[3], 23); /* 0C 05 20 + five floats */
    memcpy(&late[23], (const uint8_t[]){0x01, 0x00, 0x0A}, 3);
    const ps_can_frame_t h = fd_frame(CMD_ID, late, 32);
    assert_int_equal(ps_moteus_proto.decode_cmd(&a, &h, &c), 0);
    assert_float_equal(c.q_rad, 0.0f, 0.0f);
    assert_float_equal(c.kp_nm_rad, 200.0f, 0.0f);
}

/* Matching: only this drive's FD replies to this host with a 29-bit id and
 * no can prefix; every reply passes the drive's own filter, a neighbour's
 * does not. */
static void test_ps_moteus_match_reply_and_filter(void **state)
{
    (void)state;
    const ps_act_cfg_t a = drive();
    ps_act_cfg_t b = a;
    b.can_id = 0x0C;
    uint32_t id, mask;
    ps_moteus_proto.reply_filter(&a, &id, &mask);
    assert_int_equal(id, REPLY_ID);
    assert_int_equal(mask, 0x1fffffff);
    const ps_can_frame_t f = fd_frame(REPLY_ID, REPLY, 32);
    assert_true(ps_moteus_proto.match_reply(&a, &f));
    assert_false(ps_moteus_proto.match_reply(&b, &f));
    const uint32_t others[] = {0x0C05, 0x0B06, 0x10B05, CMD_ID};
    for (size_t i = 0; i < sizeof others / sizeof others[0]; i++) {
        ps_can_frame_t g = f;
        g.id = others[i];
        assert_false(ps_moteus_proto.match_reply(&a, &g));
        assert_false((g.id & mask) == (id & mask));
    }
    ps_can_frame_t g = f;
    g.is_ext = 0; /* the same number as an 11-bit id */
    assert_false(ps_moteus_proto.match_reply(&a, &g));
    g = f;
    g.is_fd = 0;
    g.len = 8;
    assert_false(ps_moteus_proto.match_reply(&a, &g));
    ps_act_meas_t m;
    assert_int_equal(ps_act_decode_reply(&a, &g, &m), -ENOENT);
    /* the drive side: addressed by the low byte, 29-bit, no prefix */
    ps_can_frame_t c = f;
    c.id = CMD_ID;
    assert_true(ps_moteus_proto.is_for_drive(&a, &c));
    assert_false(ps_moteus_proto.is_for_drive(&b, &c));
    c.id = 0x1850B;
    assert_false(ps_moteus_proto.is_for_drive(&a, &c));
    c.id = 0x050B; /* no reply asked: still addressed to it */
    assert_true(ps_moteus_proto.is_for_drive(&a, &c));
    c.is_ext = 0;
    assert_false(ps_moteus_proto.is_for_drive(&a, &c));
}

/* The emulated drive's reply reads back through the host side; values
 * beyond the wire range saturate; one fault code per reply. */
static void test_ps_moteus_encode_reply_round_trip(void **state)
{
    (void)state;
    ps_act_cfg_t a = drive();
    a.gear_ratio = 6.0f;
    a.direction = -1.0f;
    a.zero_offset_rad = 0.3f;
    const ps_act_meas_t joint = {
        .q_rad = -0.75f, .qd_rad_s = 1.5f, .tau_nm = 24.0f, .temp_c = 41.4f};
    ps_act_meas_t motor;
    ps_act_meas_to_motor(&a, &joint, &motor);
    ps_can_frame_t f[1];
    assert_int_equal(ps_moteus_proto.encode_reply(&a, &motor, f, 1), 1);
    assert_int_equal(f[0].id, REPLY_ID);
    assert_true(f[0].is_ext && f[0].is_fd && f[0].len == 32);
    assert_memory_equal(&f[0].data[28], ((const uint8_t[]){0x50, 0x50, 0x50, 0x50}), 4);
    ps_act_meas_t got = {0};
    assert_int_equal(ps_act_decode_reply(&a, &f[0], &got), 0);
    assert_float_equal(got.q_rad, joint.q_rad, 1e-5f);
    assert_float_equal(got.qd_rad_s, joint.qd_rad_s, 1e-5f);
    assert_float_equal(got.tau_nm, joint.tau_nm, 1e-4f);
    assert_float_equal(got.temp_c, 41.0f, 0.0f); /* 1 degC per LSB */
    assert_int_equal(got.fault_bits, 0);
    /* beyond the wire range: on its edge */
    const ps_act_meas_t far = {
        .q_rad = 100.0f, .qd_rad_s = -100.0f, .tau_nm = 99.0f, .temp_c = 300.0f};
    a = drive();
    assert_int_equal(ps_moteus_proto.encode_reply(&a, &far, f, 1), 1);
    assert_int_equal(ps_act_decode_reply(&a, &f[0], &got), 0);
    assert_float_equal(got.q_rad, 4.0f * PI_F, 1e-5f);
    assert_float_equal(got.qd_rad_s, -20.0f, 1e-5f);
    assert_float_equal(got.tau_nm, 30.0f, 0.0f);
    assert_float_equal(got.temp_c, 127.0f, 0.0f);
    /* faults: each neutral bit the layout names reads back as itself */
    const struct {
        uint32_t sent, read;
    } FAULTS[] = {
        {PS_ACT_FAULT_MOTOR_OVERTEMP, PS_ACT_FAULT_MOTOR_OVERTEMP},
        {PS_ACT_FAULT_DRIVER_OVERTEMP, PS_ACT_FAULT_MOTOR_OVERTEMP}, /* one code for both */
        {PS_ACT_FAULT_OVERVOLTAGE, PS_ACT_FAULT_OVERVOLTAGE},
        {PS_ACT_FAULT_UNDERVOLTAGE, PS_ACT_FAULT_UNDERVOLTAGE},
        {PS_ACT_FAULT_ENCODER, PS_ACT_FAULT_ENCODER},
        {PS_ACT_FAULT_COMMS_LOST, PS_ACT_FAULT_COMMS_LOST}, /* the timeout mode */
        {PS_ACT_FAULT_OVERCURRENT, PS_ACT_FAULT_OTHER},     /* no code of its own */
        {PS_ACT_FAULT_OTHER, PS_ACT_FAULT_OTHER},
    };
    for (size_t i = 0; i < sizeof FAULTS / sizeof FAULTS[0]; i++) {
        const ps_act_meas_t m = {.temp_c = 30.0f, .fault_bits = FAULTS[i].sent};
        assert_int_equal(ps_moteus_proto.encode_reply(&a, &m, f, 1), 1);
        assert_int_equal(ps_act_decode_reply(&a, &f[0], &got), 0);
        assert_int_equal(got.fault_bits, FAULTS[i].read);
    }
    assert_int_equal(ps_moteus_proto.encode_reply(&a, &far, f, 0), -ENOSPC);
}

/* The fault register by hand (registers.md, 0x00f). */
static void test_ps_moteus_fault_bits_codes(void **state)
{
    (void)state;
    assert_int_equal(ps_moteus_fault_bits(PS_MOTEUS_MODE_POSITION, 0), 0);
    assert_int_equal(ps_moteus_fault_bits(PS_MOTEUS_MODE_STOPPED, 0), 0);
    assert_int_equal(ps_moteus_fault_bits(PS_MOTEUS_MODE_FAULT, 34), PS_ACT_FAULT_OVERVOLTAGE);
    assert_int_equal(ps_moteus_fault_bits(PS_MOTEUS_MODE_FAULT, 40), PS_ACT_FAULT_UNDERVOLTAGE);
    assert_int_equal(ps_moteus_fault_bits(PS_MOTEUS_MODE_FAULT, 38), PS_ACT_FAULT_MOTOR_OVERTEMP);
    assert_int_equal(ps_moteus_fault_bits(PS_MOTEUS_MODE_FAULT, 32), PS_ACT_FAULT_ENCODER);
    assert_int_equal(ps_moteus_fault_bits(PS_MOTEUS_MODE_FAULT, 35), PS_ACT_FAULT_ENCODER);
    assert_int_equal(ps_moteus_fault_bits(PS_MOTEUS_MODE_FAULT, 42), PS_ACT_FAULT_ENCODER);
    assert_int_equal(ps_moteus_fault_bits(PS_MOTEUS_MODE_FAULT, 43), PS_ACT_FAULT_ENCODER);
    assert_int_equal(ps_moteus_fault_bits(PS_MOTEUS_MODE_FAULT, 33), PS_ACT_FAULT_OTHER);
    assert_int_equal(ps_moteus_fault_bits(PS_MOTEUS_MODE_FAULT, 36), PS_ACT_FAULT_OTHER);
    assert_int_equal(ps_moteus_fault_bits(PS_MOTEUS_MODE_FAULT, 0), PS_ACT_FAULT_OTHER);
    assert_int_equal(ps_moteus_fault_bits(PS_MOTEUS_MODE_TIMEOUT, 0), PS_ACT_FAULT_COMMS_LOST);
    for (uint32_t code = 96; code <= 105; code++) /* limits, not faults */
        assert_int_equal(ps_moteus_fault_bits(PS_MOTEUS_MODE_POSITION, code), 0);
}

/* A geared, reversed joint: the whole path joint -> wire -> drive -> joint. */
static void test_ps_moteus_command_round_trip_through_gearing(void **state)
{
    (void)state;
    ps_act_cfg_t a = drive();
    a.gear_ratio = 6.0f;
    a.direction = -1.0f;
    a.zero_offset_rad = 0.3f;
    const ps_act_cmd_t joint = {.q_rad = 1.1f,
                                .qd_rad_s = -0.4f,
                                .kp_nm_rad = 2000.0f,
                                .kd_nm_s_rad = 30.0f,
                                .tau_ff_nm = -12.0f};
    ps_can_frame_t f[1];
    assert_int_equal(ps_act_encode_command(&a, &joint, f, 1), 1);
    ps_act_cmd_t motor, back;
    assert_int_equal(ps_moteus_proto.decode_cmd(&a, &f[0], &motor), 0);
    ps_act_cmd_from_motor(&a, &motor, &back);
    float lsb[5];
    ps_act_joint_lsb(&a, lsb);
    assert_float_equal(back.q_rad, joint.q_rad, lsb[0]);
    assert_float_equal(back.qd_rad_s, joint.qd_rad_s, lsb[1]);
    assert_float_equal(back.kp_nm_rad, joint.kp_nm_rad, lsb[2]);
    assert_float_equal(back.kd_nm_s_rad, joint.kd_nm_s_rad, lsb[3]);
    assert_float_equal(back.tau_ff_nm, joint.tau_ff_nm, lsb[4]);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ps_moteus_proto_table_shape),
        cmocka_unit_test(test_ps_act_encode_command_moteus_hand_vector),
        cmocka_unit_test(test_ps_act_encode_command_moteus_zero_hand_vector),
        cmocka_unit_test(test_ps_moteus_encode_cmd_refuses_out_of_range),
        cmocka_unit_test(test_ps_act_encode_request_moteus_frames),
        cmocka_unit_test(test_ps_act_decode_reply_moteus_hand_vector),
        cmocka_unit_test(test_ps_act_decode_reply_moteus_not_finite_geared_refused),
        cmocka_unit_test(test_ps_moteus_decode_reply_vendor_example),
        cmocka_unit_test(test_ps_moteus_decode_cmd_vendor_example),
        cmocka_unit_test(test_ps_moteus_decode_cmd_overflowing_scale_refused),
        cmocka_unit_test(test_ps_moteus_malformed_frames_refused),
        cmocka_unit_test(test_ps_moteus_match_reply_and_filter),
        cmocka_unit_test(test_ps_moteus_encode_reply_round_trip),
        cmocka_unit_test(test_ps_moteus_fault_bits_codes),
        cmocka_unit_test(test_ps_moteus_command_round_trip_through_gearing),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
