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

/** Which IMU message an IMU sends (robot file, `imu.protocol`). */
typedef enum {
    PS_IMU_PROTO_PUSHSTEP = 0, /**< this file's two-frame message */
    PS_IMU_PROTO_XSENS,        /**< Xsens MTi-600 CAN output: drivers/ps_imu_xsens.h */
    PS_IMU_PROTO_COUNT
} ps_imu_proto_id_t;

/** Where the IMU sits on the wire (robot file, `imu:`). */
typedef struct {
    uint32_t bus_idx;
    uint32_t base_id;  /**< pushstep: gyro frame on base_id, accel frame on base_id + 1;
                            xsens: the SampleTime message's id (default 0x005), the
                            others at their default offsets from it (11-bit) */
    uint32_t rate_div; /**< one sample every rate_div servo ticks */
    ps_imu_proto_id_t protocol;
    uint32_t frozen_samples; /**< this many consecutive samples bit-identical on all six
                                  axes: a frozen sensor, refused (drivers/ps_imu.h); 0: off */
} ps_imu_cfg_t;

#define PS_IMU_GYRO_LSB_RAD_S       0.001f
#define PS_IMU_ACCEL_LSB_M_S2       0.002f
#define PS_IMU_STATUS_GYRO_SAT      0x01u
#define PS_IMU_STATUS_ACCEL_SAT     0x02u
#define PS_IMU_STATUS_SELFTEST_FAIL 0x80u

typedef struct {
    float gyro_body_rad_s[3];
    float accel_body_m_s2[3]; /**< specific force: +9.81 on z when level and still */
    int8_t temp_c;
    uint8_t seq;
    uint8_t status;
    int64_t t_ns; /**< rx: end-of-frame time of the gyro frame (the earlier
                       half, closest to the measurement); encode ignores it */
} ps_imu_sample_t;

/** Encode a sample into its two frames. Values are rounded to the nearest
 *  LSB and saturate to +-32767 LSB, setting the matching saturation bit in the
 *  status byte (s->status is kept and OR-ed with those bits); a NaN component
 *  is sent as 0 with its saturation bit set, so the receiver sees it flagged.
 *  Frames are 11-bit ids, len 8, t_ns 0.
 *  @post out[0] gyro (id base_id), out[1] accel (id base_id + 1)  @rt RT-SAFE O(1) */
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

/** Feed one frame. A gyro frame is held until the accel frame with the same
 *  seq arrives (a newer gyro frame replaces an unpaired one). An accel frame
 *  with no held gyro frame, or with a different seq, is refused and the held
 *  gyro frame discarded; so is any IMU frame of the wrong length.
 *  Extended-id (29-bit) frames are never IMU frames.
 *  @post *out written only when a complete sample is formed (status from the
 *        gyro frame, t_ns of the gyro frame)
 *  @return 1 sample complete | 0 frame consumed, no sample yet | -ENOENT not an IMU frame
 *          | -PS_ERR_PROTOCOL wrong length, seq mismatch, or a component of
 *          -32768 LSB (outside +-32767: no sender writes it)  @rt RT-SAFE O(1) */
int ps_imu_msg_rx_feed(ps_imu_msg_rx_t *rx, const ps_can_frame_t *f, ps_imu_sample_t *out);

#endif /* PS_IMU_MSG_H */
