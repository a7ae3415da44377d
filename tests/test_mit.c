/* Tests of drivers/ps_mit: MIT-mode packing against hand-computed vectors. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <string.h>

#include "../drivers/ps_mit.h"
#include "../rt/ps_err.h"
#include "fakes/ps_test_wire.h"

/* The AK-style ranges of tests/fakes/ps_test_wire.h. */
static const ps_act_range_t RANGE = PS_TEST_WIRE_AK_INIT;

static void assert_bytes(const uint8_t *got, const uint8_t *want)
{
    for (unsigned i = 0; i < PS_MIT_FRAME_LEN; i++) {
        if (got[i] != want[i])
            fail_msg("byte %u: got 0x%02X want 0x%02X", i, got[i], want[i]);
    }
}

/* ---- float <-> uint -------------------------------------------------- */

static void test_float_to_uint_zero_symmetric_rounds_half_up(void **state)
{
    (void)state;
    /* p = 0 on +-12.5, 16 bits: (0 + 12.5) * 65535 / 25 = 32767.5 exactly, a
     * half step; round half up gives 32768 = 0x8000 (truncation would give
     * 0x7FFF). Same for 12-bit v/t: 45 * 4095 / 90 = 2047.5 -> 2048 = 0x800. */
    assert_int_equal(ps_mit_float_to_uint(0.0f, -12.5f, 12.5f, 16), 0x8000);
    assert_int_equal(ps_mit_float_to_uint(0.0f, -45.0f, 45.0f, 12), 0x800);
    assert_int_equal(ps_mit_float_to_uint(0.0f, -18.0f, 18.0f, 12), 0x800);
}

static void test_float_to_uint_half_steps_round_up_not_to_even(void **state)
{
    (void)state;
    /* Range 0..4095 with 12 bits: one LSB per unit, so x maps to itself. */
    assert_int_equal(ps_mit_float_to_uint(0.49f, 0.0f, 4095.0f, 12), 0);
    assert_int_equal(ps_mit_float_to_uint(0.5f, 0.0f, 4095.0f, 12), 1);
    assert_int_equal(ps_mit_float_to_uint(1.5f, 0.0f, 4095.0f, 12), 2);
    /* Banker's rounding (rint) would give 2 here. */
    assert_int_equal(ps_mit_float_to_uint(2.5f, 0.0f, 4095.0f, 12), 3);
    assert_int_equal(ps_mit_float_to_uint(4094.5f, 0.0f, 4095.0f, 12), 4095);
}

static void test_float_to_uint_out_of_range_saturates(void **state)
{
    (void)state;
    assert_int_equal(ps_mit_float_to_uint(-12.5f, -12.5f, 12.5f, 16), 0);
    assert_int_equal(ps_mit_float_to_uint(-100.0f, -12.5f, 12.5f, 16), 0);
    assert_int_equal(ps_mit_float_to_uint(12.5f, -12.5f, 12.5f, 16), 0xFFFF);
    assert_int_equal(ps_mit_float_to_uint(1e30f, -12.5f, 12.5f, 16), 0xFFFF);
    assert_int_equal(ps_mit_float_to_uint(INFINITY, -45.0f, 45.0f, 12), 0xFFF);
    assert_int_equal(ps_mit_float_to_uint(-INFINITY, -45.0f, 45.0f, 12), 0);
    assert_int_equal(ps_mit_float_to_uint(NAN, -45.0f, 45.0f, 12), 0);
}

static void test_uint_to_float_ends_are_exact(void **state)
{
    (void)state;
    assert_true(ps_mit_uint_to_float(0, -12.5f, 12.5f, 16) == -12.5f);
    assert_true(ps_mit_uint_to_float(0xFFFF, -12.5f, 12.5f, 16) == 12.5f);
    assert_true(ps_mit_uint_to_float(0xFFF, 0.0f, 500.0f, 12) == 500.0f);
    /* Beyond the field saturates to max. */
    assert_true(ps_mit_uint_to_float(0x1FFF, 0.0f, 500.0f, 12) == 500.0f);
}

static void test_uint_to_float_round_trip_within_half_lsb(void **state)
{
    (void)state;
    const double lsb16 = 25.0 / 65535.0;
    const double lsb12 = 90.0 / 4095.0;
    double worst16 = 0.0, worst12 = 0.0;
    for (int k = 0; k <= 100000; k++) {
        const float x16 = -12.5f + 25.0f * (float)k / 100000.0f;
        const float y16 =
            ps_mit_uint_to_float(ps_mit_float_to_uint(x16, -12.5f, 12.5f, 16), -12.5f, 12.5f, 16);
        worst16 = fmax(worst16, fabs((double)y16 - (double)x16));
        const float x12 = -45.0f + 90.0f * (float)k / 100000.0f;
        const float y12 =
            ps_mit_uint_to_float(ps_mit_float_to_uint(x12, -45.0f, 45.0f, 12), -45.0f, 45.0f, 12);
        worst12 = fmax(worst12, fabs((double)y12 - (double)x12));
    }
    /* Half an LSB plus float representation error of values near 12.5/45. */
    assert_true(worst16 <= 0.5 * lsb16 + 2e-6);
    assert_true(worst12 <= 0.5 * lsb12 + 8e-6);
    /* And the bound is not vacuous: some inputs land well away from a code. */
    assert_true(worst16 > 0.4 * lsb16);
    assert_true(worst12 > 0.4 * lsb12);
}

/* ---- command --------------------------------------------------------- */

static void test_encode_cmd_zero_command_exact_bytes(void **state)
{
    (void)state;
    /* p 0x8000, v 0x800, kp 0, kd 0, t 0x800 (see the half-step test):
     * b0 p>>8 = 80, b1 p&ff = 00, b2 v>>4 = 80, b3 (v&f)<<4 | kp>>8 = 00,
     * b4 kp&ff = 00, b5 kd>>4 = 00, b6 (kd&f)<<4 | t>>8 = 08, b7 t&ff = 00. */
    const ps_mit_cmd_t cmd = {0};
    const uint8_t want[8] = {0x80, 0x00, 0x80, 0x00, 0x00, 0x00, 0x08, 0x00};
    uint8_t out[8];
    assert_int_equal(ps_mit_encode_cmd(&RANGE, &cmd, out), 0);
    assert_bytes(out, want);
}

static void test_encode_cmd_typical_command_exact_bytes(void **state)
{
    (void)state;
    /* p  =  1.0: (13.5) * 65535 / 25 = 35388.9   -> 35389 = 0x8A3D
     * v  = -2.0: (43)   * 4095 / 90  = 1956.5    -> 1957  = 0x7A5 (half up)
     * kp = 50  :  50    * 4095 / 500 = 409.5     -> 410   = 0x19A (half up)
     * kd = 1.0 :  1     * 4095 / 5   = 819       -> 819   = 0x333
     * t  = 3.0 : (21)   * 4095 / 36  = 2388.75   -> 2389  = 0x955
     * bytes: 8A 3D | 7A | 5<<4|1 = 51 | 9A | 33 | 3<<4|9 = 39 | 55 */
    const ps_mit_cmd_t cmd = {
        .p_rad = 1.0f, .v_rad_s = -2.0f, .kp_nm_rad = 50.0f, .kd_nm_s_rad = 1.0f, .t_ff_nm = 3.0f};
    const uint8_t want[8] = {0x8A, 0x3D, 0x7A, 0x51, 0x9A, 0x33, 0x39, 0x55};
    uint8_t out[8];
    assert_int_equal(ps_mit_encode_cmd(&RANGE, &cmd, out), 0);
    assert_bytes(out, want);
}

static void test_encode_cmd_minimum_all_zero_maximum_all_ones(void **state)
{
    (void)state;
    const ps_mit_cmd_t lo = {.p_rad = -12.5f, .v_rad_s = -45.0f, .t_ff_nm = -18.0f};
    const ps_mit_cmd_t hi = {.p_rad = 12.5f,
                             .v_rad_s = 45.0f,
                             .kp_nm_rad = 500.0f,
                             .kd_nm_s_rad = 5.0f,
                             .t_ff_nm = 18.0f};
    const uint8_t zeros[8] = {0};
    const uint8_t ones[8] = {0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF};
    uint8_t out[8];
    assert_int_equal(ps_mit_encode_cmd(&RANGE, &lo, out), 0);
    assert_bytes(out, zeros);
    assert_int_equal(ps_mit_encode_cmd(&RANGE, &hi, out), 0);
    assert_bytes(out, ones);
}

static void check_refused(ps_mit_cmd_t cmd)
{
    uint8_t out[8];
    memset(out, 0xA5, sizeof out);
    assert_int_equal(ps_mit_encode_cmd(&RANGE, &cmd, out), -PS_ERR_LIMIT);
    for (unsigned i = 0; i < 8; i++)
        assert_int_equal(out[i], 0xA5); /* untouched on failure */
}

static void test_encode_cmd_out_of_range_refused(void **state)
{
    (void)state;
    const ps_mit_cmd_t ok = {
        .p_rad = 0.5f, .v_rad_s = 1.0f, .kp_nm_rad = 20.0f, .kd_nm_s_rad = 0.5f, .t_ff_nm = 1.0f};
    ps_mit_cmd_t c;
    c = ok, c.p_rad = 12.51f, check_refused(c);
    c = ok, c.p_rad = -12.51f, check_refused(c);
    c = ok, c.v_rad_s = 45.01f, check_refused(c);
    c = ok, c.v_rad_s = -45.01f, check_refused(c);
    c = ok, c.kp_nm_rad = -0.001f, check_refused(c);
    c = ok, c.kp_nm_rad = 500.1f, check_refused(c);
    c = ok, c.kd_nm_s_rad = -0.001f, check_refused(c);
    c = ok, c.kd_nm_s_rad = 5.01f, check_refused(c);
    c = ok, c.t_ff_nm = 18.01f, check_refused(c);
    c = ok, c.t_ff_nm = -18.01f, check_refused(c);
    /* The unmodified command is accepted, so the refusals above are real. */
    uint8_t out[8];
    assert_int_equal(ps_mit_encode_cmd(&RANGE, &ok, out), 0);
}

static void test_encode_cmd_nan_or_inf_refused(void **state)
{
    (void)state;
    const ps_mit_cmd_t ok = {0};
    const float bad[] = {NAN, INFINITY, -INFINITY};
    for (unsigned k = 0; k < 3; k++) {
        ps_mit_cmd_t c;
        c = ok, c.p_rad = bad[k], check_refused(c);
        c = ok, c.v_rad_s = bad[k], check_refused(c);
        c = ok, c.kp_nm_rad = bad[k], check_refused(c);
        c = ok, c.kd_nm_s_rad = bad[k], check_refused(c);
        c = ok, c.t_ff_nm = bad[k], check_refused(c);
    }
}

static void test_encode_cmd_packs_to_special_refused(void **state)
{
    (void)state;
    /* t code 0xFFC with everything else at max packs to FF FF FF FF FF FF FF FC. */
    ps_mit_cmd_t c = {.p_rad = 12.5f, .v_rad_s = 45.0f, .kp_nm_rad = 500.0f, .kd_nm_s_rad = 5.0f};
    for (uint32_t code = 0xFFC; code <= 0xFFE; code++) {
        c.t_ff_nm = ps_mit_uint_to_float(code, -18.0f, 18.0f, 12);
        assert_int_equal(ps_mit_float_to_uint(c.t_ff_nm, -18.0f, 18.0f, 12), code);
        check_refused(c);
    }
    /* One code below is an ordinary command. */
    c.t_ff_nm = ps_mit_uint_to_float(0xFFB, -18.0f, 18.0f, 12);
    uint8_t out[8];
    assert_int_equal(ps_mit_encode_cmd(&RANGE, &c, out), 0);
    assert_int_equal(out[7], 0xFB);
}

static void test_decode_cmd_hand_vector_within_half_lsb(void **state)
{
    (void)state;
    const uint8_t in[8] = {0x8A, 0x3D, 0x7A, 0x51, 0x9A, 0x33, 0x39, 0x55};
    ps_mit_cmd_t c;
    assert_int_equal(ps_mit_decode_cmd(&RANGE, in, 8, &c), 0);
    assert_float_equal(c.p_rad, 1.0f, 0.5f * 25.0f / 65535.0f);
    assert_float_equal(c.v_rad_s, -2.0f, 0.5f * 90.0f / 4095.0f + 1e-6f);
    assert_float_equal(c.kp_nm_rad, 50.0f, 0.5f * 500.0f / 4095.0f + 1e-5f);
    assert_float_equal(c.kd_nm_s_rad, 1.0f, 1e-6f);
    assert_float_equal(c.t_ff_nm, 3.0f, 0.5f * 36.0f / 4095.0f);
}

static void test_decode_cmd_wrong_len_or_special_protocol_error(void **state)
{
    (void)state;
    uint8_t in[8] = {0x80, 0x00, 0x80, 0x00, 0x00, 0x00, 0x08, 0x00};
    ps_mit_cmd_t c;
    assert_int_equal(ps_mit_decode_cmd(&RANGE, in, 7, &c), -PS_ERR_PROTOCOL);
    assert_int_equal(ps_mit_decode_cmd(&RANGE, in, 0, &c), -PS_ERR_PROTOCOL);
    assert_int_equal(ps_mit_decode_cmd(&RANGE, in, 9, &c), -PS_ERR_PROTOCOL);
    assert_int_equal(ps_mit_decode_cmd(&RANGE, in, 8, &c), 0);
    const ps_mit_special_t sp[] = {PS_MIT_SPECIAL_ENTER, PS_MIT_SPECIAL_EXIT, PS_MIT_SPECIAL_ZERO};
    for (unsigned k = 0; k < 3; k++) {
        ps_mit_encode_special(sp[k], in);
        assert_int_equal(ps_mit_decode_cmd(&RANGE, in, 8, &c), -PS_ERR_PROTOCOL);
    }
}

/* ---- special frames --------------------------------------------------- */

static void test_encode_special_each_code_exact_bytes(void **state)
{
    (void)state;
    uint8_t out[8];
    const uint8_t enter[8] = {0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFC};
    ps_mit_encode_special(PS_MIT_SPECIAL_ENTER, out);
    assert_bytes(out, enter);
    ps_mit_encode_special(PS_MIT_SPECIAL_EXIT, out);
    assert_int_equal(out[7], 0xFD);
    assert_int_equal(out[0], 0xFF);
    ps_mit_encode_special(PS_MIT_SPECIAL_ZERO, out);
    assert_int_equal(out[7], 0xFE);
    assert_int_equal(out[6], 0xFF);
}

static void test_classify_special_only_exact_patterns(void **state)
{
    (void)state;
    uint8_t f[8];
    ps_mit_encode_special(PS_MIT_SPECIAL_ENTER, f);
    assert_int_equal(ps_mit_classify_special(f, 8), 0xFC);
    assert_int_equal(ps_mit_classify_special(f, 7), 0);
    ps_mit_encode_special(PS_MIT_SPECIAL_EXIT, f);
    assert_int_equal(ps_mit_classify_special(f, 8), 0xFD);
    ps_mit_encode_special(PS_MIT_SPECIAL_ZERO, f);
    assert_int_equal(ps_mit_classify_special(f, 8), 0xFE);
    f[7] = 0xFB;
    assert_int_equal(ps_mit_classify_special(f, 8), 0);
    f[7] = 0xFF;
    assert_int_equal(ps_mit_classify_special(f, 8), 0);
    ps_mit_encode_special(PS_MIT_SPECIAL_ENTER, f);
    f[3] = 0xFE;
    assert_int_equal(ps_mit_classify_special(f, 8), 0);
}

/* ---- reply ------------------------------------------------------------ */

static void test_encode_reply_fault_and_negative_temp_exact_bytes(void **state)
{
    (void)state;
    /* id 3, fault 0xA -> byte0 0xA3. p 1.0 -> 0x8A3D, v -2.0 -> 0x7A5,
     * i 0 on +-40: 40 * 4095 / 80 = 2047.5 -> 0x800. b4 = 5<<4 | 8 = 0x58,
     * b5 = 0x00. temp mos -5 -> 0xFB (two's complement), rotor 85 -> 0x55. */
    const ps_mit_reply_t rep = {.motor_id = 3,
                                .fault = PS_MIT_FAULT_OVERCURRENT,
                                .p_rad = 1.0f,
                                .v_rad_s = -2.0f,
                                .i_a = 0.0f,
                                .temp_mos_c = -5,
                                .temp_rotor_c = 85};
    const uint8_t want[8] = {0xA3, 0x8A, 0x3D, 0x7A, 0x58, 0x00, 0xFB, 0x55};
    uint8_t out[8];
    ps_mit_encode_reply(&RANGE, &rep, out);
    assert_bytes(out, want);
}

static void test_encode_reply_out_of_range_saturates(void **state)
{
    (void)state;
    const ps_mit_reply_t rep = {.motor_id = 0x13, /* only the low nibble goes out */
                                .p_rad = 100.0f,
                                .v_rad_s = -100.0f,
                                .i_a = 1e9f,
                                .temp_mos_c = -128,
                                .temp_rotor_c = 127};
    const uint8_t want[8] = {0x03, 0xFF, 0xFF, 0x00, 0x0F, 0xFF, 0x80, 0x7F};
    uint8_t out[8];
    ps_mit_encode_reply(&RANGE, &rep, out);
    assert_bytes(out, want);
}

static void test_decode_reply_hand_vector_fields(void **state)
{
    (void)state;
    const uint8_t in[8] = {0xD7, 0x8A, 0x3D, 0x7A, 0x58, 0x00, 0xFB, 0x9C};
    ps_mit_reply_t r;
    assert_int_equal(ps_mit_decode_reply(&RANGE, in, 8, &r), 0);
    assert_int_equal(r.motor_id, 7);
    assert_int_equal(r.fault, PS_MIT_FAULT_COMMS_LOST);
    assert_float_equal(r.p_rad, 1.0f, 0.5f * 25.0f / 65535.0f);
    assert_float_equal(r.v_rad_s, -2.0f, 0.5f * 90.0f / 4095.0f + 1e-6f);
    /* 0x800 = 2048 -> 2048 * 80 / 4095 - 40 = +0.00977 A (half an LSB above 0) */
    assert_float_equal(r.i_a, 2048.0f * 80.0f / 4095.0f - 40.0f, 1e-5f);
    assert_int_equal(r.temp_mos_c, -5);
    assert_int_equal(r.temp_rotor_c, -100); /* 0x9C */
}

static void test_decode_reply_wrong_len_protocol_error(void **state)
{
    (void)state;
    const uint8_t in[9] = {0};
    ps_mit_reply_t r;
    assert_int_equal(ps_mit_decode_reply(&RANGE, in, 7, &r), -PS_ERR_PROTOCOL);
    assert_int_equal(ps_mit_decode_reply(&RANGE, in, 9, &r), -PS_ERR_PROTOCOL);
    assert_int_equal(ps_mit_decode_reply(&RANGE, in, 0, &r), -PS_ERR_PROTOCOL);
    assert_int_equal(ps_mit_decode_reply(&RANGE, in, 8, &r), 0);
}

static void test_decode_reply_round_trip_encode(void **state)
{
    (void)state;
    const ps_mit_reply_t rep = {.motor_id = 0xF,
                                .fault = PS_MIT_FAULT_ROTOR_OVERTEMP,
                                .p_rad = -3.3f,
                                .v_rad_s = 12.0f,
                                .i_a = -7.25f,
                                .temp_mos_c = 60,
                                .temp_rotor_c = -40};
    uint8_t buf[8];
    ps_mit_reply_t back;
    ps_mit_encode_reply(&RANGE, &rep, buf);
    assert_int_equal(ps_mit_decode_reply(&RANGE, buf, 8, &back), 0);
    assert_int_equal(back.motor_id, 0xF);
    assert_int_equal(back.fault, PS_MIT_FAULT_ROTOR_OVERTEMP);
    assert_float_equal(back.p_rad, -3.3f, 0.5f * 25.0f / 65535.0f + 1e-6f);
    assert_float_equal(back.v_rad_s, 12.0f, 0.5f * 90.0f / 4095.0f + 1e-5f);
    assert_float_equal(back.i_a, -7.25f, 0.5f * 80.0f / 4095.0f + 1e-5f);
    assert_int_equal(back.temp_mos_c, 60);
    assert_int_equal(back.temp_rotor_c, -40);
}

/* ---- range check ------------------------------------------------------ */

static void test_check_range_valid_ok(void **state)
{
    (void)state;
    assert_int_equal(ps_mit_check_range(&RANGE), 0);
}

static void test_check_range_bad_tables_einval(void **state)
{
    (void)state;
    ps_act_range_t r;
    assert_int_equal(ps_mit_check_range(NULL), -EINVAL);
    r = RANGE, r.p_min_rad = 12.5f, assert_int_equal(ps_mit_check_range(&r), -EINVAL);
    r = RANGE, r.p_max_rad = -13.0f, assert_int_equal(ps_mit_check_range(&r), -EINVAL);
    r = RANGE, r.v_max_rad_s = NAN, assert_int_equal(ps_mit_check_range(&r), -EINVAL);
    r = RANGE, r.v_min_rad_s = -INFINITY, assert_int_equal(ps_mit_check_range(&r), -EINVAL);
    r = RANGE, r.kp_max_nm_rad = 0.0f, assert_int_equal(ps_mit_check_range(&r), -EINVAL);
    r = RANGE, r.kd_max_nm_s_rad = -1.0f, assert_int_equal(ps_mit_check_range(&r), -EINVAL);
    r = RANGE, r.kd_max_nm_s_rad = INFINITY, assert_int_equal(ps_mit_check_range(&r), -EINVAL);
    r = RANGE, r.t_min_nm = 18.0f, assert_int_equal(ps_mit_check_range(&r), -EINVAL);
    r = RANGE, r.i_max_a = -41.0f, assert_int_equal(ps_mit_check_range(&r), -EINVAL);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_float_to_uint_zero_symmetric_rounds_half_up),
        cmocka_unit_test(test_float_to_uint_half_steps_round_up_not_to_even),
        cmocka_unit_test(test_float_to_uint_out_of_range_saturates),
        cmocka_unit_test(test_uint_to_float_ends_are_exact),
        cmocka_unit_test(test_uint_to_float_round_trip_within_half_lsb),
        cmocka_unit_test(test_encode_cmd_zero_command_exact_bytes),
        cmocka_unit_test(test_encode_cmd_typical_command_exact_bytes),
        cmocka_unit_test(test_encode_cmd_minimum_all_zero_maximum_all_ones),
        cmocka_unit_test(test_encode_cmd_out_of_range_refused),
        cmocka_unit_test(test_encode_cmd_nan_or_inf_refused),
        cmocka_unit_test(test_encode_cmd_packs_to_special_refused),
        cmocka_unit_test(test_decode_cmd_hand_vector_within_half_lsb),
        cmocka_unit_test(test_decode_cmd_wrong_len_or_special_protocol_error),
        cmocka_unit_test(test_encode_special_each_code_exact_bytes),
        cmocka_unit_test(test_classify_special_only_exact_patterns),
        cmocka_unit_test(test_encode_reply_fault_and_negative_temp_exact_bytes),
        cmocka_unit_test(test_encode_reply_out_of_range_saturates),
        cmocka_unit_test(test_decode_reply_hand_vector_fields),
        cmocka_unit_test(test_decode_reply_wrong_len_protocol_error),
        cmocka_unit_test(test_decode_reply_round_trip_encode),
        cmocka_unit_test(test_check_range_valid_ok),
        cmocka_unit_test(test_check_range_bad_tables_einval),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
