/*
 * fuzz_imu: the IMU messages' receivers under one harness (included by
 * fuzz_imu_msg.c and fuzz_imu_xsens.c with their protocol).
 *
 * Input: frame records (tests/fuzz/fuzz.h), fed in order with times 1 ms
 * apart to two receivers: one sees the bytes past each frame's length as
 * 0xA5, the other as 0x5A; both must agree on every result (nothing past len
 * is read). Contract: ps_imu_rx_feed returns 1, 0, -ENOENT or
 * -PS_ERR_PROTOCOL; *out is written only with 1; a sample is finite, each
 * gyro and accel component within the message's scale (32767 LSB), the
 * status only PS_IMU_STATUS_* bits where the protocol maps them, t_ns the
 * time of a frame already fed and not in the future.
 */
#ifndef PS_FUZZ_IMU_H
#define PS_FUZZ_IMU_H

#include <errno.h>

#include "../../drivers/ps_imu.h"
#include "../../rt/ps_err.h"
#include "fuzz.h"

static void fuzz_imu_run(const ps_imu_cfg_t *cfg, float gyro_max, float accel_max,
                         bool is_status_mapped, const uint8_t *data, size_t size)
{
    ps_imu_rx_t rx1, rx2;
    ps_imu_rx_init(&rx1, cfg);
    ps_imu_rx_init(&rx2, cfg);
    fuzz_in_t in = {data, size};
    ps_can_frame_t f;
    int64_t t_ns = 1000000;
    const ps_imu_sample_t sentinel = {{-1, -2, -3}, {-4, -5, -6}, 7, 8, 9, 10};
    while (fuzz_next_frame(&in, &f, t_ns)) {
        ps_imu_sample_t s1 = sentinel, s2 = sentinel;
        fuzz_frame_poison(&f, 0xa5u);
        const int rc1 = ps_imu_rx_feed(&rx1, &f, &s1);
        fuzz_frame_poison(&f, 0x5au);
        const int rc2 = ps_imu_rx_feed(&rx2, &f, &s2);
        FUZZ_CHECK(rc1 == 1 || rc1 == 0 || rc1 == -ENOENT || rc1 == -PS_ERR_PROTOCOL,
                   "ps_imu_rx_feed returned %d", rc1);
        FUZZ_CHECK(rc1 == rc2 && !memcmp(&s1, &s2, sizeof s1) && !memcmp(&rx1, &rx2, sizeof rx1),
                   "the result depends on bytes past the frame's length %u", f.len);
        if (rc1 != 1) {
            FUZZ_CHECK(!memcmp(&s1, &sentinel, sizeof s1), "sample written with %d", rc1);
        } else {
            for (int k = 0; k < 3; k++) {
                FUZZ_CHECK(fuzz_in_range(s1.gyro_body_rad_s[k], -gyro_max, gyro_max),
                           "gyro[%d] %.9g beyond %g", k, s1.gyro_body_rad_s[k], gyro_max);
                FUZZ_CHECK(fuzz_in_range(s1.accel_body_m_s2[k], -accel_max, accel_max),
                           "accel[%d] %.9g beyond %g", k, s1.accel_body_m_s2[k], accel_max);
            }
            const uint8_t known =
                PS_IMU_STATUS_GYRO_SAT | PS_IMU_STATUS_ACCEL_SAT | PS_IMU_STATUS_SELFTEST_FAIL;
            FUZZ_CHECK(!is_status_mapped || (s1.status & ~known) == 0, "status 0x%02x", s1.status);
            FUZZ_CHECK(s1.t_ns >= 1000000 && s1.t_ns <= t_ns && s1.t_ns % 1000000 == 0,
                       "sample time %lld, frame time %lld", (long long)s1.t_ns, (long long)t_ns);
        }
        t_ns += 1000000;
    }
}

#endif /* PS_FUZZ_IMU_H */
