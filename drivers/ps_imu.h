/*
 * ps_imu: the IMU port, protocol-neutral, as the loop, the planner, the
 * SocketCAN filters, the monitor and the emulated IMU see it. The robot
 * file's `imu.protocol` picks the message: `pushstep` (our own two-frame
 * message, drivers/ps_imu_msg.h) or `xsens` (an Xsens MTi-600's CAN output,
 * drivers/ps_imu_xsens.h). Every protocol gives the same ps_imu_sample_t.
 *
 * Frozen values: a MEMS IMU's raw gyro and accelerometer readings always
 * carry noise of a few LSB, so consecutive samples bit-identical on all six
 * axes mean a sensor that stopped measuring while its interface (sequence
 * number, counter) goes on. ps_imu_rx_feed checks this for every protocol:
 * from the cfg.frozen_samples-th identical sample in a row on, each such
 * sample is refused (-PS_ERR_STALE) until the values change. The robot
 * file's default (ps_imu_frozen_default) is PS_IMU_FROZEN_DEFAULT_S worth
 * of samples.
 *
 * Threads: any (pure). Allocation: none.
 */
#ifndef PS_IMU_H
#define PS_IMU_H

#include <stdint.h>

#include "ps_can.h"
#include "ps_imu_msg.h"
#include "ps_imu_xsens.h"

/** Frames one sample takes at most, over every protocol. */
#define PS_IMU_MAX_FRAMES 5u

/** Default of imu.frozen_samples: the samples of this long (50 ms). */
#define PS_IMU_FROZEN_DEFAULT_S 0.05
/** Largest imu.frozen_samples. */
#define PS_IMU_FROZEN_SAMPLES_MAX 10000u

typedef struct {
    ps_imu_proto_id_t protocol;
    union {
        ps_imu_msg_rx_t msg;
        ps_imu_xsens_rx_t xsens;
    } u;
    uint32_t frozen_samples;   /**< cfg.frozen_samples; 0: no check */
    float last_values[6];      /**< the last sample's gyro, then accel */
    uint32_t n_same;           /**< samples in a row with exactly last_values */
    uint64_t n_frozen_values;  /**< samples refused as frozen (read-only) */
} ps_imu_rx_t;

/** @return the protocol's name as written in robot files ("pushstep", "xsens"),
 *  "?" outside the enum  @rt RT-SAFE */
const char *ps_imu_proto_name(ps_imu_proto_id_t id);

/** @return protocol id for its name, -ENOENT unknown  @rt INIT */
int ps_imu_proto_find(const char *name);

/** @pre cfg->protocol valid  @rt RT-SAFE */
void ps_imu_rx_init(ps_imu_rx_t *rx, const ps_imu_cfg_t *cfg);

/** @return imu.frozen_samples' default for an IMU sampled at imu_hz: the
 *  samples of PS_IMU_FROZEN_DEFAULT_S, rounded up, at least 2  @rt INIT */
uint32_t ps_imu_frozen_default(uint32_t imu_hz);

/** Feed one frame of the IMU's bus: as ps_imu_msg_rx_feed (1 sample, 0 taken,
 *  -ENOENT not the IMU's, -PS_ERR_PROTOCOL refused), and -PS_ERR_STALE: a
 *  complete sample refused as frozen (its six values identical to those of
 *  the frozen_samples - 1 samples before it; *out written all the same).
 *  @rt RT-SAFE O(1) */
int ps_imu_rx_feed(ps_imu_rx_t *rx, const ps_can_frame_t *f, ps_imu_sample_t *out);

/** Device side: the frames of sample number n (its seq or counter), taken at
 *  t_ns (the Xsens SampleTime counts 100 us ticks of it).
 *  @return frames written (2 or 5)  @rt RT-SAFE */
int ps_imu_encode(const ps_imu_cfg_t *cfg, const ps_imu_sample_t *s, uint32_t n, int64_t t_ns,
                  ps_can_frame_t out[PS_IMU_MAX_FRAMES]);

/** The identifiers (11-bit) and payload lengths of one sample's frames, for
 *  receive filters and the bus planner.  @return how many  @rt RT-SAFE */
unsigned ps_imu_frames(const ps_imu_cfg_t *cfg, uint32_t ids[PS_IMU_MAX_FRAMES],
                       uint8_t lens[PS_IMU_MAX_FRAMES]);

#endif /* PS_IMU_H */
