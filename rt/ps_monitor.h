/*
 * ps_monitor: `pushstep monitor`, a bus decoder that knows the robot. Every
 * frame on the board's buses (live, through SocketCAN; or from a candump -L
 * log, for offline analysis) is printed as what it means for the robot file:
 * which joint's command (set-points, joint side) or mode request, which
 * joint's reply (position, velocity, torque, temperature, faults) or fault
 * report, which IMU
 * half or sample; anything else as raw bytes, marked unknown. With --rates
 * it prints, per joint, commands and replies per second instead.
 *
 * The decoding is the runtime's own (drivers/ps_actuator, ps_imu): the
 * monitor shows what the loop would understand.
 *
 * Threads: main thread. Allocation: none after start-up.
 */
#ifndef PS_MONITOR_H
#define PS_MONITOR_H

#include <stddef.h>
#include <stdint.h>

#include "../drivers/ps_can.h"
#include "../drivers/ps_imu.h"
#include "ps_config.h"

typedef enum {
    PS_MONITOR_UNKNOWN = 0,
    PS_MONITOR_COMMAND,
    PS_MONITOR_REQUEST,
    PS_MONITOR_REPLY,
    PS_MONITOR_IMU,
    PS_MONITOR_MALFORMED, /**< addressed to a joint or the IMU, but not decodable */
    PS_MONITOR_FAULT,     /**< a drive's own fault report (RobStride type 21) */
} ps_monitor_kind_t;

/** State the decoder keeps: the IMU's half samples. */
typedef struct {
    ps_imu_rx_t imu_rx;
    /** an IMU frame has started or completed a sample: before it, a frame
     *  that does not pair is the rest of a sample begun before the capture */
    bool has_imu_start;
} ps_monitor_t;

/** @rt INIT */
void ps_monitor_init(ps_monitor_t *m, const ps_robot_cfg_t *r);

/** Describe one frame of bus bus_idx in words (no time, no bus name).
 *  @post *out_joint: the joint index for commands, requests, replies and
 *        malformed joint frames, else -1
 *  @return its kind  @rt RT-SAFE (snprintf only) */
ps_monitor_kind_t ps_monitor_describe(ps_monitor_t *m, const ps_robot_cfg_t *r, uint32_t bus_idx,
                                      const ps_can_frame_t *f, int *out_joint, char *out,
                                      size_t len);

/** Parse argv (argv[0] = "monitor"), run, print.
 *  @return process exit status: 0 ok, 1 runtime failure, 2 usage/config  @rt INIT */
int ps_monitor_main(int argc, char **argv, const char *data_dir);

#endif /* PS_MONITOR_H */
