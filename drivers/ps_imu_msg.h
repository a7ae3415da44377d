/*
 * ps_imu_msg: the IMU-over-CAN message (our design; docs/can-protocols.md).
 *
 * Two classical frames per sample, both 8 bytes, little-endian:
 *   base_id + 0, gyro:  int16 x, y, z in 1 mrad/s (+-32.767 rad/s), u8 seq, u8 status
 *   base_id + 1, accel: int16 x, y, z in 2 mm/s^2 (+-65.534 m/s^2), int8 temp degC, u8 seq
 * Body frame: x forward, y left, z up. The two frames of one sample carry the
 * same seq; a receiver pairs them and rejects a sample whose halves differ.
 * status bits: 0 gyro saturated, 1 accel saturated, 7 self-test failed.
 *
 * Threads: any (pure). Allocation: none.
 */
#ifndef PS_IMU_MSG_H
#define PS_IMU_MSG_H

#include <stdint.h>

#include "ps_can.h"

#define PS_IMU_GYRO_LSB_RAD_S  0.001f
#define PS_IMU_ACCEL_LSB_M_S2  0.002f
#define PS_IMU_STATUS_GYRO_SAT  0x01u
#define PS_IMU_STATUS_ACCEL_SAT 0x02u
#define PS_IMU_STATUS_SELFTEST_FAIL 0x80u

typedef struct {
    float gyro_body_rad_s[3];
    float accel_body_m_s2[3]; /**< specific force: +9.81 on z when level and still */
    int8_t temp_c;
    uint8_t seq;
    uint8_t status;
} ps_imu_sample_t;

/** Encode a sample into its two frames (values saturate to the int16 range
 *  and set the saturation status bits). @post out[0] gyro, out[1] accel  @rt RT-SAFE */
void ps_imu_msg_encode(uint32_t base_id, const ps_imu_sample_t *s, ps_can_frame_t out[2]);

/** Pairs frames into samples. Feed every frame from the IMU's bus. */
typedef struct {
    uint32_t base_id;
    uint8_t has_gyro;
    uint8_t gyro_seq;
    uint8_t gyro_status;
    int64_t gyro_t_ns;
    float gyro_body_rad_s[3];
} ps_imu_msg_rx_t;

/** @post rx reset for base_id  @rt RT-SAFE */
void ps_imu_msg_rx_init(ps_imu_msg_rx_t *rx, uint32_t base_id);

/** Feed one frame. @post *out written when a complete sample is formed
 *  @return 1 sample complete | 0 frame consumed, no sample yet | -ENOENT not an IMU frame
 *          | -PS_ERR_PROTOCOL wrong length or seq mismatch  @rt RT-SAFE O(1) */
int ps_imu_msg_rx_feed(ps_imu_msg_rx_t *rx, const ps_can_frame_t *f, ps_imu_sample_t *out);

#endif /* PS_IMU_MSG_H */
