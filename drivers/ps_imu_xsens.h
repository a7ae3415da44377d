/*
 * ps_imu_xsens: the CAN output of an Xsens MTi-600-series IMU (MTi-610/620/
 * 630/670/680; also Avior and Sirius), as the receiver in the loop and as the
 * emulated device. Layout from Xsens' "MTi 600-series MT CAN Protocol
 * Documentation" (document MT1604P, rev. A, 2019; mtidocs.movella.com/
 * canmessages): classical frames, 11-bit identifiers, big-endian fields.
 *
 *   id      message (default id)   data
 *   0x005   XCID_SampleTime        uint32, 10 kHz ticks (100 us)
 *   0x006   XCID_GroupCounter      uint16, +1 per output group (sample)
 *   0x011   XCDI_StatusWord        uint32: bit 0 self-test passed, bit 1
 *                                  filter valid, bits 8..10 accelerometer
 *                                  x/y/z clipped, bits 11..13 gyroscope
 *                                  x/y/z clipped (XDI_StatusWord's bits)
 *   0x032   XCDI_RateOfTurn        int16 x, y, z; 2^-9 rad/s per LSB (+-64 rad/s)
 *   0x034   XCDI_Acceleration      int16 x, y, z; 2^-8 m/s^2 per LSB (+-128 m/s^2)
 *
 * The device sends one output group per sample, lowest id first (that is
 * also CAN's priority order). A configured IMU may use other identifiers:
 * base_id is the SampleTime message's id and the others keep their default
 * offsets from it (0x005 gives the defaults). Sensor frame as the device's:
 * x forward, y left, z up; acceleration is specific force (+g on z, level).
 *
 * The receiver assembles a group: GroupCounter opens it; RateOfTurn and
 * Acceleration are required, SampleTime and StatusWord used when present.
 * The sample is complete at the Acceleration frame. Checks: every frame's
 * length; a group whose gyro frame is missing is dropped (counted); a counter
 * that does not advance by one is a gap (counted; the sample is still taken,
 * and the loop's repeat check sees seq = the counter's low byte); a
 * SampleTime that does not advance while the counter does is a frozen
 * sensor (the sample is refused).
 *
 * Not used: Error (0x001) and Warning (0x002) messages, orientation,
 * magnetic field, temperature.
 *
 * Threads: any (pure). Allocation: none.
 */
#ifndef PS_IMU_XSENS_H
#define PS_IMU_XSENS_H

#include <stdbool.h>
#include <stdint.h>

#include "ps_can.h"
#include "ps_imu_msg.h"

#define PS_IMU_XSENS_DEFAULT_BASE_ID 0x005u
#define PS_IMU_XSENS_N_FRAMES        5u
#define PS_IMU_XSENS_GYRO_LSB_RAD_S  (1.0f / 512.0f)
#define PS_IMU_XSENS_ACCEL_LSB_M_S2  (1.0f / 256.0f)
#define PS_IMU_XSENS_STATUS_SELFTEST 0x00000001u
#define PS_IMU_XSENS_STATUS_FILTER   0x00000002u
#define PS_IMU_XSENS_STATUS_CLIP_ACC 0x00000700u /**< bits 8..10 */
#define PS_IMU_XSENS_STATUS_CLIP_GYR 0x00003800u /**< bits 11..13 */

/** Offsets of each message's id from the SampleTime id. */
enum {
    PS_IMU_XSENS_OFS_SAMPLE_TIME = 0x000,
    PS_IMU_XSENS_OFS_COUNTER = 0x001,
    PS_IMU_XSENS_OFS_STATUS = 0x00c,
    PS_IMU_XSENS_OFS_RATE_OF_TURN = 0x02d,
    PS_IMU_XSENS_OFS_ACCELERATION = 0x02f,
};

typedef struct {
    uint32_t base_id;
    bool is_open; /* a GroupCounter frame opened the group */
    bool has_gyro, has_time, has_status;
    uint16_t counter;
    bool has_last_counter;
    uint16_t last_counter;
    uint32_t sample_time, last_sample_time;
    uint32_t pending_time; /* a SampleTime not yet claimed by a GroupCounter */
    bool has_pending_time;
    int64_t pending_t_ns;
    bool has_last_time;
    uint32_t status_word;
    float gyro_body_rad_s[3];
    int64_t t_ns;          /* the group's first frame */
    uint64_t n_gaps;       /**< counters that did not advance by one */
    uint64_t n_incomplete; /**< groups dropped for a missing frame */
    uint64_t n_frozen;     /**< samples refused: SampleTime did not advance */
} ps_imu_xsens_rx_t;

/** The five frames of one sample, in send order (SampleTime, GroupCounter,
 *  StatusWord, RateOfTurn, Acceleration). sample_time in 100 us ticks.
 *  Values round to the LSB and saturate to +-32767, setting the status
 *  word's clip bits; a NaN is sent as 0, clipped. s->status's self-test
 *  failure clears the self-test bit.  @return 5  @rt RT-SAFE */
int ps_imu_xsens_encode(uint32_t base_id, const ps_imu_sample_t *s, uint16_t counter,
                        uint32_t sample_time, ps_can_frame_t out[PS_IMU_XSENS_N_FRAMES]);

/** @rt RT-SAFE */
void ps_imu_xsens_rx_init(ps_imu_xsens_rx_t *rx, uint32_t base_id);

/** Feed one frame.  @post *out written when 1 is returned (seq: the counter's
 *  low byte; status: PS_IMU_STATUS_* from the status word; t_ns: the group's
 *  first frame; temp_c 0)
 *  @return 1 sample complete | 0 frame taken | -ENOENT not one of the IMU's
 *          | -PS_ERR_PROTOCOL wrong length, a group without its gyro frame, a
 *            frozen SampleTime  @rt RT-SAFE O(1) */
int ps_imu_xsens_rx_feed(ps_imu_xsens_rx_t *rx, const ps_can_frame_t *f, ps_imu_sample_t *out);

#endif /* PS_IMU_XSENS_H */
