/*
 * ps_hoist: the robot hanging on a hoist, as its drives and IMU present it on
 * the CAN buses. It is what a bring-up engineer first powers on, and what
 * `pushstep emulate` puts at the far end of real CAN interfaces (a vxcan
 * pair in the test VM), so the real SocketCAN and libgpiod drivers can run
 * the whole loop with no robot.
 *
 * Each joint is a free rotor, joint side: J qdd = tau - b qd, no gravity, no
 * contact (the feet hang), integrated semi-implicitly. Each drive is the
 * emulated drive of sim/ps_devices (its protocol, its PD, its faults, motor
 * mode off at power-up, comms-loss timeout), so every protocol the plant
 * emulates works here. The IMU reports the trunk upright and still: gyro 0,
 * accel +g on z, with the robot file's noise and bias (ps_devices_tick_imu).
 *
 * Power: is_powered (one for every drive) stands for the watchdog relay; the
 * caller drops it when the loop's heartbeat stops.
 *
 * Threads: one. Allocation: none (caller owns the struct).
 */
#ifndef PS_HOIST_H
#define PS_HOIST_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "../rt/ps_limits.h"
#include "ps_devices.h"
#include "ps_sim.h"

#define PS_HOIST_INERTIA_KG_M2    0.05 /**< a leg link and rotor, seen from the joint */
#define PS_HOIST_DAMPING_NM_S_RAD 0.5

typedef struct {
    uint32_t n_joints;
    ps_devices_actuator_t act[PS_MAX_JOINTS];
    double q_rad[PS_MAX_JOINTS];
    double qd_rad_s[PS_MAX_JOINTS];
    ps_devices_imu_t imu;
    uint32_t imu_bus_idx;
    uint64_t tick;
    uint64_t n_frames;     /**< frames taken */
    uint64_t n_unclaimed;  /**< frames no drive on that bus took */
    uint64_t n_bad_frames; /**< frames a drive rejected as malformed */
    uint64_t n_replies;
} ps_hoist_t;

/** @pre robot checked by the config loader  @post joints at their stance
 *  angles, at rest; drives powered, motor mode off  @rt INIT */
void ps_hoist_init(ps_hoist_t *h, const ps_sim_robot_t *robot, uint64_t seed);

/** One frame that arrived on bus bus_idx at f->t_ns.
 *  @post *out_reply written when 1 is returned; *out_joint the joint whose
 *        drive took it, -1 when none
 *  @return 1 a drive answered | 0 taken, no answer | -ENOENT no drive on
 *          that bus is addressed | -PS_ERR_PROTOCOL malformed for the drive
 *  @rt RT-SAFE O(joints) */
int ps_hoist_take_frame(ps_hoist_t *h, uint32_t bus_idx, const ps_can_frame_t *f,
                        ps_can_frame_t *out_reply, int *out_joint);

/** Advance every joint by dt_s ending at now_ns; on IMU ticks write its
 *  frames (bus: h->imu_bus_idx).  @return IMU frames written | 0
 *  @units s, ns  @rt RT-SAFE O(joints) */
int ps_hoist_step(ps_hoist_t *h, int64_t now_ns, double dt_s,
                  ps_can_frame_t out_imu[PS_IMU_MAX_FRAMES]);

/** Power of every drive (the relay).  @rt RT-SAFE */
void ps_hoist_set_power(ps_hoist_t *h, bool is_powered);

#endif /* PS_HOIST_H */
