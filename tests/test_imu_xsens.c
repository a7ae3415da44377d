/*
 * Tests of drivers/ps_imu_xsens (and its place behind drivers/ps_imu): the
 * Xsens MTi-600 CAN output against bytes worked out by hand from the MT CAN
 * protocol documentation (MT1604P: big-endian fields; XCDI_RateOfTurn 0x032,
 * int16 x/y/z at 2^-9 rad/s; XCDI_Acceleration 0x034, int16 at 2^-8 m/s^2;
 * XCID_SampleTime 0x005, uint32 in 100 us ticks; XCID_GroupCounter 0x006,
 * uint16; XCDI_StatusWord 0x011, uint32), and the receiver's checks: group
 * assembly, counter gaps, a frozen sample time, missing and malformed frames.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <math.h>
#include <string.h>

#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

#include "../drivers/ps_imu.h"
#include "../rt/ps_config.h"
#include "../drivers/ps_imu_xsens.h"
#include "../rt/ps_err.h"

#define BASE PS_IMU_XSENS_DEFAULT_BASE_ID

static void assert_frame(const ps_can_frame_t *f, uint32_t id, const uint8_t *bytes, uint8_t len)
{
    assert_int_equal(f->id, id);
    assert_false(f->is_ext);
    assert_false(f->is_fd);
    assert_int_equal(f->len, len);
    assert_memory_equal(f->data, bytes, len);
}

/* gyro (0.5, -1, 2) rad/s = (256, -512, 1024) LSB; accel (0, 0.1, 9.81) m/s^2 =
 * (0, 25.6 -> 26, 2511.36 -> 2511) LSB; counter 0x1234; 12.3456 s = 123456
 * ticks = 0x0001E240; status: self-test passed (bit 0), filter valid (bit 1). */
static void test_encode_matches_the_hand_worked_frames(void **state)
{
    (void)state;
    const ps_imu_sample_t s = {.gyro_body_rad_s = {0.5f, -1.0f, 2.0f},
                               .accel_body_m_s2 = {0.0f, 0.1f, 9.81f}};
    ps_can_frame_t f[PS_IMU_XSENS_N_FRAMES];
    assert_int_equal(ps_imu_xsens_encode(BASE, &s, 0x1234, 123456u, f), 5);
    assert_frame(&f[0], 0x005, (const uint8_t[]){0x00, 0x01, 0xE2, 0x40}, 4);
    assert_frame(&f[1], 0x006, (const uint8_t[]){0x12, 0x34}, 2);
    assert_frame(&f[2], 0x011, (const uint8_t[]){0x00, 0x00, 0x00, 0x03}, 4);
    assert_frame(&f[3], 0x032, (const uint8_t[]){0x01, 0x00, 0xFE, 0x00, 0x04, 0x00}, 6);
    assert_frame(&f[4], 0x034, (const uint8_t[]){0x00, 0x00, 0x00, 0x1A, 0x09, 0xCF}, 6);
}

/* 70 rad/s is 35840 LSB: clipped to 0x7FFF with the gyro-x clip bit (11);
 * -200 m/s^2 on z clips to -32767 = 0x8001 with accel-z's (bit 10); a NaN is
 * sent as 0, clipped; a failed self-test clears bit 0. */
static void test_encode_clips_and_flags(void **state)
{
    (void)state;
    const ps_imu_sample_t s = {.gyro_body_rad_s = {70.0f, 0.0f, NAN},
                               .accel_body_m_s2 = {0.0f, 0.0f, -200.0f},
                               .status = PS_IMU_STATUS_SELFTEST_FAIL};
    ps_can_frame_t f[PS_IMU_XSENS_N_FRAMES];
    ps_imu_xsens_encode(BASE, &s, 1, 0, f);
    assert_frame(&f[3], 0x032, (const uint8_t[]){0x7F, 0xFF, 0x00, 0x00, 0x00, 0x00}, 6);
    assert_frame(&f[4], 0x034, (const uint8_t[]){0x00, 0x00, 0x00, 0x00, 0x80, 0x01}, 6);
    /* bits 1 (filter), 10 (acc z), 11 (gyr x), 13 (gyr z): 0x2C02 */
    assert_frame(&f[2], 0x011, (const uint8_t[]){0x00, 0x00, 0x2C, 0x02}, 4);
}

static int feed_all(ps_imu_xsens_rx_t *rx, const ps_can_frame_t *f, unsigned n,
                    ps_imu_sample_t *out)
{
    int rc = 0;
    for (unsigned i = 0; i < n; i++)
        rc = ps_imu_xsens_rx_feed(rx, &f[i], out);
    return rc;
}

static void test_a_group_decodes_back_within_one_lsb(void **state)
{
    (void)state;
    const ps_imu_sample_t s = {.gyro_body_rad_s = {0.5f, -1.0f, 2.0f},
                               .accel_body_m_s2 = {0.0f, 0.1f, 9.81f}};
    ps_can_frame_t f[5];
    ps_imu_xsens_encode(0x205, &s, 0x1234, 77, f);
    for (int i = 0; i < 5; i++)
        f[i].t_ns = 1000 + i;
    ps_imu_xsens_rx_t rx;
    ps_imu_xsens_rx_init(&rx, 0x205);
    ps_imu_sample_t out;
    for (int i = 0; i < 4; i++)
        assert_int_equal(ps_imu_xsens_rx_feed(&rx, &f[i], &out), 0);
    assert_int_equal(ps_imu_xsens_rx_feed(&rx, &f[4], &out), 1);
    assert_float_equal(out.gyro_body_rad_s[0], 0.5f, 1e-6f);
    assert_float_equal(out.gyro_body_rad_s[1], -1.0f, 1e-6f);
    assert_float_equal(out.accel_body_m_s2[1], 26.0f / 256.0f, 1e-6f);
    assert_float_equal(out.accel_body_m_s2[2], 2511.0f / 256.0f, 1e-6f);
    assert_int_equal(out.seq, 0x34);
    assert_int_equal(out.status, 0);
    assert_int_equal(out.t_ns, 1000); /* the SampleTime frame: the group's first */
    /* The default ids are not this IMU's. */
    ps_can_frame_t other = f[3];
    other.id = 0x032;
    assert_int_equal(ps_imu_xsens_rx_feed(&rx, &other, &out), -ENOENT);
    other.id = 0x205 + 0x10; /* inside the range, no message there */
    assert_int_equal(ps_imu_xsens_rx_feed(&rx, &other, &out), -ENOENT);
}

static void test_status_word_maps_to_the_sample_status(void **state)
{
    (void)state;
    const ps_imu_sample_t s = {.gyro_body_rad_s = {70.0f, 0, 0},
                               .accel_body_m_s2 = {0, 0, 500.0f},
                               .status = PS_IMU_STATUS_SELFTEST_FAIL};
    ps_can_frame_t f[5];
    ps_imu_xsens_encode(BASE, &s, 9, 5, f);
    ps_imu_xsens_rx_t rx;
    ps_imu_xsens_rx_init(&rx, BASE);
    ps_imu_sample_t out;
    assert_int_equal(feed_all(&rx, f, 5, &out), 1);
    assert_int_equal(out.status, PS_IMU_STATUS_GYRO_SAT | PS_IMU_STATUS_ACCEL_SAT |
                                     PS_IMU_STATUS_SELFTEST_FAIL);
}

/* An IMU configured to send only the counter and the inertial data. */
static void test_sample_time_and_status_are_optional(void **state)
{
    (void)state;
    const ps_imu_sample_t s = {.accel_body_m_s2 = {0, 0, 9.81f}};
    ps_can_frame_t f[5];
    ps_imu_xsens_encode(BASE, &s, 3, 5, f);
    ps_imu_xsens_rx_t rx;
    ps_imu_xsens_rx_init(&rx, BASE);
    ps_imu_sample_t out;
    const ps_can_frame_t only[3] = {f[1], f[3], f[4]};
    assert_int_equal(feed_all(&rx, only, 3, &out), 1);
    assert_int_equal(out.seq, 3);
}

static void test_counter_gaps_are_counted_and_a_frozen_clock_refused(void **state)
{
    (void)state;
    const ps_imu_sample_t s = {.accel_body_m_s2 = {0, 0, 9.81f}};
    ps_can_frame_t f[5];
    ps_imu_xsens_rx_t rx;
    ps_imu_xsens_rx_init(&rx, BASE);
    ps_imu_sample_t out;
    const uint16_t counters[] = {0xFFFE, 0xFFFF, 0x0000, 0x0002}; /* wraps, then skips 1 */
    for (unsigned k = 0; k < 4; k++) {
        ps_imu_xsens_encode(BASE, &s, counters[k], 10u * k, f);
        assert_int_equal(feed_all(&rx, f, 5, &out), 1);
    }
    assert_int_equal(rx.n_gaps, 1);
    /* the counter moves, the sample time does not: a stuck sensor */
    ps_imu_xsens_encode(BASE, &s, 3, 30u, f);
    assert_int_equal(feed_all(&rx, f, 5, &out), -PS_ERR_PROTOCOL);
    assert_int_equal(rx.n_frozen, 1);
    ps_imu_xsens_encode(BASE, &s, 4, 40u, f);
    assert_int_equal(feed_all(&rx, f, 5, &out), 1);
}

static void test_missing_and_malformed_frames_drop_the_group(void **state)
{
    (void)state;
    const ps_imu_sample_t s = {.accel_body_m_s2 = {0, 0, 9.81f}};
    ps_can_frame_t f[5];
    ps_imu_xsens_encode(BASE, &s, 1, 1, f);
    ps_imu_xsens_rx_t rx;
    ps_imu_xsens_rx_init(&rx, BASE);
    ps_imu_sample_t out;
    /* no RateOfTurn: acceleration alone is not a sample */
    const ps_can_frame_t no_gyro[4] = {f[0], f[1], f[2], f[4]};
    assert_int_equal(feed_all(&rx, no_gyro, 4, &out), -PS_ERR_PROTOCOL);
    assert_int_equal(rx.n_incomplete, 1);
    /* a gyro frame from before the counter does not count for this group */
    ps_imu_xsens_encode(BASE, &s, 2, 2, f);
    const ps_can_frame_t late_counter[3] = {f[3], f[1], f[4]};
    assert_int_equal(feed_all(&rx, late_counter, 3, &out), -PS_ERR_PROTOCOL);
    /* a short RateOfTurn breaks the group */
    ps_imu_xsens_encode(BASE, &s, 3, 3, f);
    f[3].len = 5;
    assert_int_equal(ps_imu_xsens_rx_feed(&rx, &f[1], &out), 0);
    assert_int_equal(ps_imu_xsens_rx_feed(&rx, &f[3], &out), -PS_ERR_PROTOCOL);
    assert_int_equal(ps_imu_xsens_rx_feed(&rx, &f[4], &out), -PS_ERR_PROTOCOL);
    /* a new group opened before the last closed: the old one is dropped */
    ps_imu_xsens_encode(BASE, &s, 4, 4, f);
    assert_int_equal(ps_imu_xsens_rx_feed(&rx, &f[1], &out), 0);
    const uint64_t before = rx.n_incomplete;
    assert_int_equal(feed_all(&rx, f, 5, &out), 1);
    assert_int_equal(rx.n_incomplete, before + 1);
    /* A group that lost its acceleration lends its time and status to no
     * later group: here the next one has neither, and a failed self-test in
     * the lost group must not show. */
    const ps_imu_sample_t bad = {.status = PS_IMU_STATUS_SELFTEST_FAIL};
    ps_can_frame_t g[5];
    ps_imu_xsens_encode(BASE, &bad, 5, 99, g);
    for (int i = 0; i < 4; i++) /* SampleTime .. RateOfTurn, no Acceleration */
        (void)ps_imu_xsens_rx_feed(&rx, &g[i], &out);
    ps_imu_xsens_encode(BASE, &s, 6, 99, f);
    const ps_can_frame_t bare[3] = {f[1], f[3], f[4]};
    assert_int_equal(feed_all(&rx, bare, 3, &out), 1); /* not refused as frozen at 99 */
    assert_int_equal(out.status, 0);
    ps_can_frame_t ext = f[4];
    ext.is_ext = 1;
    assert_int_equal(ps_imu_xsens_rx_feed(&rx, &ext, &out), -ENOENT);
}

/* Through the neutral port: the protocol picks the message; ids and lengths
 * for the filters and the planner. */
static void test_the_imu_port_dispatches_by_protocol(void **state)
{
    (void)state;
    assert_int_equal(ps_imu_proto_find("xsens"), PS_IMU_PROTO_XSENS);
    assert_int_equal(ps_imu_proto_find("pushstep"), PS_IMU_PROTO_PUSHSTEP);
    assert_int_equal(ps_imu_proto_find("bosch"), -ENOENT);
    const ps_imu_cfg_t x = {
        .bus_idx = 3, .base_id = 0x205, .rate_div = 2, .protocol = PS_IMU_PROTO_XSENS};
    uint32_t ids[PS_IMU_MAX_FRAMES];
    uint8_t lens[PS_IMU_MAX_FRAMES];
    assert_int_equal(ps_imu_frames(&x, ids, lens), 5);
    const uint32_t want_ids[] = {0x205, 0x206, 0x211, 0x232, 0x234};
    const uint8_t want_lens[] = {4, 2, 4, 6, 6};
    assert_memory_equal(ids, want_ids, sizeof want_ids);
    assert_memory_equal(lens, want_lens, sizeof want_lens);
    ps_imu_sample_t s = {.accel_body_m_s2 = {0, 0, 9.81f}};
    ps_can_frame_t f[PS_IMU_MAX_FRAMES];
    /* 1.23456 s is 12345 ticks of 100 us */
    assert_int_equal(ps_imu_encode(&x, &s, 7, 1234560000LL, f), 5);
    assert_frame(&f[0], 0x205, (const uint8_t[]){0x00, 0x00, 0x30, 0x39}, 4);
    ps_imu_rx_t rx;
    ps_imu_rx_init(&rx, &x);
    ps_imu_sample_t out;
    int rc = 0;
    for (int i = 0; i < 5; i++)
        rc = ps_imu_rx_feed(&rx, &f[i], &out);
    assert_int_equal(rc, 1);
    assert_int_equal(out.seq, 7);
    const ps_imu_cfg_t p = {.bus_idx = 3, .base_id = 0x80, .rate_div = 1};
    assert_int_equal(ps_imu_frames(&p, ids, lens), 2);
    assert_int_equal(ids[1], 0x81);
    assert_int_equal(ps_imu_encode(&p, &s, 7, 0, f), 2);
}

/* Frozen values, the same check for every protocol behind the port: the
 * frozen_samples-th sample in a row with the same six values (while the seq
 * or counter and the Xsens SampleTime advance) is refused with
 * -PS_ERR_STALE, and so is each after it, until a value changes; one LSB on
 * one axis is a change. 0 turns the check off. */
static void feed_sample(ps_imu_rx_t *rx, const ps_imu_cfg_t *c, float gyro_x, uint32_t n,
                        int want_rc)
{
    const ps_imu_sample_t s = {.gyro_body_rad_s = {gyro_x, 0.01f, -0.02f},
                               .accel_body_m_s2 = {0.1f, 0.2f, 9.81f},
                               .seq = (uint8_t)n};
    ps_can_frame_t f[PS_IMU_MAX_FRAMES];
    const int n_frames = ps_imu_encode(c, &s, n, (int64_t)n * 2000000, f);
    ps_imu_sample_t out;
    int rc = 0;
    for (int i = 0; i < n_frames; i++)
        rc = ps_imu_rx_feed(rx, &f[i], &out);
    assert_int_equal(rc, want_rc);
}

static void test_the_imu_port_refuses_frozen_values_every_protocol(void **state)
{
    (void)state;
    for (int proto = 0; proto < PS_IMU_PROTO_COUNT; proto++) {
        const ps_imu_cfg_t c = {.bus_idx = 3,
                                .base_id = 0x205,
                                .rate_div = 2,
                                .protocol = (ps_imu_proto_id_t)proto,
                                .frozen_samples = 4};
        ps_imu_rx_t rx;
        ps_imu_rx_init(&rx, &c);
        uint32_t n = 1;
        feed_sample(&rx, &c, 0.5f, n++, 1);
        for (int i = 0; i < 2; i++) /* 3 in a row: still taken */
            feed_sample(&rx, &c, 0.5f, n++, 1);
        feed_sample(&rx, &c, 0.5f, n++, -PS_ERR_STALE); /* the 4th */
        feed_sample(&rx, &c, 0.5f, n++, -PS_ERR_STALE);
        assert_int_equal(rx.n_frozen_values, 2);
        feed_sample(&rx, &c, 0.5f + 0.004f, n++, 1); /* a value moved */
        for (int i = 0; i < 3; i++)
            feed_sample(&rx, &c, 0.5f + 0.004f, n++, i < 2 ? 1 : -PS_ERR_STALE);
        ps_imu_cfg_t off = c;
        off.frozen_samples = 0;
        ps_imu_rx_init(&rx, &off);
        for (int i = 0; i < 100; i++)
            feed_sample(&rx, &off, 0.5f, n++, 1);
        assert_int_equal(rx.n_frozen_values, 0);
    }
    assert_int_equal(ps_imu_frozen_default(1000), 50); /* 50 ms */
    assert_int_equal(ps_imu_frozen_default(500), 25);
    assert_int_equal(ps_imu_frozen_default(30), 2); /* 1.5, rounded up */
    assert_int_equal(ps_imu_frozen_default(10), 2); /* a run is at least 2 */
}

/* ---- the robot file's imu.protocol ------------------------------------- */

static int load_variant(const char *from, const char *to, char *err, size_t len)
{
    FILE *in = fopen("tests/data/robots/ps1-xsens.yaml", "r");
    assert_non_null(in);
    static char text[1 << 16];
    const size_t n = fread(text, 1, sizeof text - 1, in);
    fclose(in);
    text[n] = '\0';
    char *at = strstr(text, from);
    assert_non_null(at);
    char path[] = "/tmp/ps_xsens_XXXXXX";
    const int fd = mkstemp(path);
    assert_true(fd >= 0);
    FILE *out = fdopen(fd, "w");
    fprintf(out, "%.*s%s%s", (int)(at - text), text, to, at + strlen(from));
    fclose(out);
    static ps_robot_cfg_t r;
    const int rc = ps_config_load_robot(path, &r, err, len);
    unlink(path);
    return rc;
}

static void test_robot_file_selects_the_xsens_message_and_checks_its_ids(void **state)
{
    (void)state;
    static ps_robot_cfg_t r;
    char err[512];
    assert_int_equal(ps_config_load_robot("tests/data/robots/ps1-xsens.yaml", &r, err, sizeof err),
                     0);
    assert_int_equal(r.imu.protocol, PS_IMU_PROTO_XSENS);
    assert_int_equal(r.imu.base_id, 0x205);
    /* The device's default ids collide with bus 3's MIT command ids 0x005/0x006. */
    assert_int_equal(load_variant("base_id: 0x205", "base_id: 0x005", err, sizeof err),
                     -PS_ERR_CONFIG);
    assert_non_null(strstr(err, "imu.base_id"));
    assert_non_null(strstr(err, "already used"));
    /* 0x7e0 + 0x2f is beyond 11 bits */
    assert_int_equal(load_variant("base_id: 0x205", "base_id: 0x7e0", err, sizeof err),
                     -PS_ERR_CONFIG);
    assert_non_null(strstr(err, "beyond 11 bits"));
    assert_int_equal(load_variant("protocol: xsens", "protocol: bosch", err, sizeof err),
                     -PS_ERR_CONFIG);
    assert_non_null(strstr(err, "protocol"));
    assert_non_null(strstr(err, "bosch"));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_encode_matches_the_hand_worked_frames),
        cmocka_unit_test(test_encode_clips_and_flags),
        cmocka_unit_test(test_the_imu_port_refuses_frozen_values_every_protocol),
        cmocka_unit_test(test_a_group_decodes_back_within_one_lsb),
        cmocka_unit_test(test_status_word_maps_to_the_sample_status),
        cmocka_unit_test(test_sample_time_and_status_are_optional),
        cmocka_unit_test(test_counter_gaps_are_counted_and_a_frozen_clock_refused),
        cmocka_unit_test(test_missing_and_malformed_frames_drop_the_group),
        cmocka_unit_test(test_the_imu_port_dispatches_by_protocol),
        cmocka_unit_test(test_robot_file_selects_the_xsens_message_and_checks_its_ids),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
