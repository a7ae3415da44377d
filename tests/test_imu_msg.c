/* Tests of drivers/ps_imu_msg: IMU-over-CAN encode and rx pairing. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <string.h>

#include "../drivers/ps_imu_msg.h"
#include "../rt/ps_err.h"

#define BASE 0x100u

static void assert_data(const ps_can_frame_t *f, const uint8_t *want)
{
    for (unsigned i = 0; i < 8; i++) {
        if (f->data[i] != want[i])
            fail_msg("id 0x%x byte %u: got 0x%02X want 0x%02X", (unsigned)f->id, i, f->data[i],
                     want[i]);
    }
}

static void test_encode_typical_sample_exact_bytes(void **state)
{
    (void)state;
    /* gyro 1.0, -0.5, 0.001 rad/s -> 1000 = 0x03E8, -500 = 0xFE0C, 1 (LE);
     * accel 0, 0, 9.81 m/s^2 -> 0, 0, 4905 = 0x1329; temp -10 = 0xF6; seq 42. */
    const ps_imu_sample_t s = {.gyro_body_rad_s = {1.0f, -0.5f, 0.001f},
                               .accel_body_m_s2 = {0.0f, 0.0f, 9.81f},
                               .temp_c = -10,
                               .seq = 42};
    ps_can_frame_t f[2];
    ps_imu_msg_encode(BASE, &s, f);
    const uint8_t gyro[8] = {0xE8, 0x03, 0x0C, 0xFE, 0x01, 0x00, 42, 0x00};
    const uint8_t accel[8] = {0x00, 0x00, 0x00, 0x00, 0x29, 0x13, 0xF6, 42};
    assert_int_equal(f[0].id, BASE);
    assert_int_equal(f[1].id, BASE + 1);
    assert_int_equal(f[0].len, 8);
    assert_int_equal(f[1].len, 8);
    assert_int_equal(f[0].is_ext, 0);
    assert_data(&f[0], gyro);
    assert_data(&f[1], accel);
}

static void test_encode_out_of_range_saturates_and_sets_status(void **state)
{
    (void)state;
    ps_imu_sample_t s = {.gyro_body_rad_s = {40.0f, 0.0f, 0.0f},
                         .accel_body_m_s2 = {0.0f, 0.0f, -100.0f},
                         .status = PS_IMU_STATUS_SELFTEST_FAIL};
    ps_can_frame_t f[2];
    ps_imu_msg_encode(BASE, &s, f);
    assert_int_equal(f[0].data[0], 0xFF); /* +32767 = 0x7FFF */
    assert_int_equal(f[0].data[1], 0x7F);
    assert_int_equal(f[1].data[4], 0x01); /* -32767 = 0x8001 */
    assert_int_equal(f[1].data[5], 0x80);
    assert_int_equal(f[0].data[7], PS_IMU_STATUS_SELFTEST_FAIL | PS_IMU_STATUS_GYRO_SAT |
                                       PS_IMU_STATUS_ACCEL_SAT);

    /* Exactly full scale is representable and not saturated. */
    memset(&s, 0, sizeof s);
    s.gyro_body_rad_s[1] = -32.767f;
    s.accel_body_m_s2[2] = 65.534f;
    ps_imu_msg_encode(BASE, &s, f);
    assert_int_equal(f[0].data[2], 0x01);
    assert_int_equal(f[0].data[3], 0x80);
    assert_int_equal(f[1].data[4], 0xFF);
    assert_int_equal(f[1].data[5], 0x7F);
    assert_int_equal(f[0].data[7], 0);
}

static void test_encode_nan_zero_with_status(void **state)
{
    (void)state;
    ps_imu_sample_t s = {.gyro_body_rad_s = {0.0f, NAN, 0.0f}};
    ps_can_frame_t f[2];
    ps_imu_msg_encode(BASE, &s, f);
    assert_int_equal(f[0].data[2], 0);
    assert_int_equal(f[0].data[3], 0);
    assert_int_equal(f[0].data[7], PS_IMU_STATUS_GYRO_SAT);
    s.gyro_body_rad_s[1] = 0.0f;
    s.accel_body_m_s2[0] = NAN;
    ps_imu_msg_encode(BASE, &s, f);
    assert_int_equal(f[0].data[7], PS_IMU_STATUS_ACCEL_SAT);
}

static void test_rx_feed_pair_round_trip_within_half_lsb(void **state)
{
    (void)state;
    const ps_imu_sample_t s = {.gyro_body_rad_s = {0.1234f, -2.5f, 30.0f},
                               .accel_body_m_s2 = {-0.0031f, 1.5f, 9.81f},
                               .temp_c = -40,
                               .seq = 255,
                               .status = PS_IMU_STATUS_SELFTEST_FAIL};
    ps_can_frame_t f[2];
    ps_imu_msg_encode(BASE, &s, f);
    f[0].t_ns = 1000;
    f[1].t_ns = 2000;
    ps_imu_msg_rx_t rx;
    ps_imu_msg_rx_init(&rx, BASE);
    ps_imu_sample_t out;
    memset(&out, 0, sizeof out);
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &f[0], &out), 0);
    assert_int_equal(out.seq, 0); /* not written yet */
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &f[1], &out), 1);
    for (unsigned a = 0; a < 3; a++) {
        assert_float_equal(out.gyro_body_rad_s[a], s.gyro_body_rad_s[a], 0.0005f + 1e-6f);
        assert_float_equal(out.accel_body_m_s2[a], s.accel_body_m_s2[a], 0.001f + 1e-6f);
    }
    assert_int_equal(out.temp_c, -40);
    assert_int_equal(out.seq, 255);
    assert_int_equal(out.status, PS_IMU_STATUS_SELFTEST_FAIL);
    assert_int_equal(out.t_ns, 1000);
    /* The pair is consumed: the same accel again has no gyro. */
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &f[1], &out), -PS_ERR_PROTOCOL);
}

static void test_rx_feed_accel_without_gyro_protocol_error(void **state)
{
    (void)state;
    const ps_imu_sample_t s = {.seq = 7};
    ps_can_frame_t f[2];
    ps_imu_msg_encode(BASE, &s, f);
    ps_imu_msg_rx_t rx;
    ps_imu_msg_rx_init(&rx, BASE);
    ps_imu_sample_t out;
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &f[1], &out), -PS_ERR_PROTOCOL);
}

static void test_rx_feed_seq_mismatch_protocol_error_drops_gyro(void **state)
{
    (void)state;
    ps_imu_sample_t s = {.seq = 7};
    ps_can_frame_t a[2], b[2];
    ps_imu_msg_encode(BASE, &s, a);
    s.seq = 8;
    ps_imu_msg_encode(BASE, &s, b);
    ps_imu_msg_rx_t rx;
    ps_imu_msg_rx_init(&rx, BASE);
    ps_imu_sample_t out;
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &a[0], &out), 0);
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &b[1], &out), -PS_ERR_PROTOCOL);
    /* The gyro half of seq 7 was discarded with the mismatch. */
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &a[1], &out), -PS_ERR_PROTOCOL);
    /* A fresh pair still works. */
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &b[0], &out), 0);
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &b[1], &out), 1);
    assert_int_equal(out.seq, 8);
}

static void test_rx_feed_newer_gyro_replaces_unpaired(void **state)
{
    (void)state;
    ps_imu_sample_t s = {.gyro_body_rad_s = {1.0f, 0.0f, 0.0f}, .seq = 1};
    ps_can_frame_t a[2], b[2];
    ps_imu_msg_encode(BASE, &s, a);
    s.gyro_body_rad_s[0] = 2.0f;
    s.seq = 2;
    ps_imu_msg_encode(BASE, &s, b);
    ps_imu_msg_rx_t rx;
    ps_imu_msg_rx_init(&rx, BASE);
    ps_imu_sample_t out;
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &a[0], &out), 0);
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &b[0], &out), 0);
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &b[1], &out), 1);
    assert_float_equal(out.gyro_body_rad_s[0], 2.0f, 1e-6f);
}

static void test_rx_feed_other_id_enoent(void **state)
{
    (void)state;
    const ps_imu_sample_t s = {.seq = 3};
    ps_can_frame_t f[2];
    ps_imu_msg_encode(BASE, &s, f);
    ps_imu_msg_rx_t rx;
    ps_imu_msg_rx_init(&rx, BASE);
    ps_imu_sample_t out;
    ps_can_frame_t g = f[0];
    g.id = BASE - 1;
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &g, &out), -ENOENT);
    g.id = BASE + 2;
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &g, &out), -ENOENT);
    g = f[0];
    g.is_ext = 1; /* same number, but a 29-bit identifier: a different frame */
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &g, &out), -ENOENT);
    /* Foreign frames leave a held gyro alone. */
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &f[0], &out), 0);
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &g, &out), -ENOENT);
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &f[1], &out), 1);
}

static void test_rx_feed_wrong_len_protocol_error(void **state)
{
    (void)state;
    const ps_imu_sample_t s = {.seq = 3};
    ps_can_frame_t f[2];
    ps_imu_msg_encode(BASE, &s, f);
    ps_imu_msg_rx_t rx;
    ps_imu_msg_rx_init(&rx, BASE);
    ps_imu_sample_t out;
    ps_can_frame_t g = f[0];
    g.len = 7;
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &g, &out), -PS_ERR_PROTOCOL);
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &f[0], &out), 0);
    g = f[1];
    g.len = 6;
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &g, &out), -PS_ERR_PROTOCOL);
    /* The short accel broke the pair. */
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &f[1], &out), -PS_ERR_PROTOCOL);
}

/* Found by tests/fuzz/fuzz_imu_msg: an accel y of 0x8000 (-32768 LSB) decoded
 * to -65.536 m/s^2, outside the message's +-65.534 (no encoder sends it).
 * Such a frame is refused, gyro and accel alike, and breaks the pair. */
static void test_rx_feed_minus_32768_lsb_protocol_error(void **state)
{
    (void)state;
    const ps_imu_sample_t s = {.seq = 1};
    ps_can_frame_t f[2];
    ps_imu_msg_encode(BASE, &s, f);
    ps_imu_msg_rx_t rx;
    ps_imu_msg_rx_init(&rx, BASE);
    ps_imu_sample_t out = {.seq = 99};
    ps_can_frame_t g = f[1];
    g.data[2] = 0x00;
    g.data[3] = 0x80;
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &f[0], &out), 0);
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &g, &out), -PS_ERR_PROTOCOL);
    assert_int_equal(out.seq, 99); /* not written */
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &f[1], &out), -PS_ERR_PROTOCOL);
    g = f[0];
    g.data[4] = 0x00;
    g.data[5] = 0x80;
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &g, &out), -PS_ERR_PROTOCOL);
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &f[1], &out), -PS_ERR_PROTOCOL);
    /* -32767 is the edge of the scale and decodes */
    g = f[1];
    g.data[2] = 0x01;
    g.data[3] = 0x80;
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &f[0], &out), 0);
    assert_int_equal(ps_imu_msg_rx_feed(&rx, &g, &out), 1);
    assert_float_equal(out.accel_body_m_s2[1], -65.534f, 1e-4f);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_encode_typical_sample_exact_bytes),
        cmocka_unit_test(test_encode_out_of_range_saturates_and_sets_status),
        cmocka_unit_test(test_encode_nan_zero_with_status),
        cmocka_unit_test(test_rx_feed_pair_round_trip_within_half_lsb),
        cmocka_unit_test(test_rx_feed_accel_without_gyro_protocol_error),
        cmocka_unit_test(test_rx_feed_seq_mismatch_protocol_error_drops_gyro),
        cmocka_unit_test(test_rx_feed_newer_gyro_replaces_unpaired),
        cmocka_unit_test(test_rx_feed_other_id_enoent),
        cmocka_unit_test(test_rx_feed_wrong_len_protocol_error),
        cmocka_unit_test(test_rx_feed_minus_32768_lsb_protocol_error),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
