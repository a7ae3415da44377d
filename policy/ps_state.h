/*
 * ps_state: the measured and estimated robot state shared by the estimator,
 * the policy slot and the servo layer. Plain data, no functions.
 */
#ifndef PS_STATE_H
#define PS_STATE_H

#include <stdbool.h>
#include <stdint.h>

#include "../drivers/ps_actuator.h"
#include "../rt/ps_limits.h"
#include "../rt/ps_neighbours.h"

/* One joint as its drive last reported it: ps_act_meas_t (joint units, fault
 * bits ps_act_fault_t, t_ns the tick the reply was taken, 0: never). */

typedef struct {
    float gyro_body_rad_s[3];
    float accel_body_m_s2[3];
    int64_t t_ns; /**< 0: never */
} ps_imu_meas_t;

typedef struct {
    uint32_t n_joints;
    ps_act_meas_t joints[PS_MAX_JOINTS];
    ps_imu_meas_t imu;
    /** The neighbours' shoulders from camera perception (rt/ps_perception),
     *  taken and aged by the loop each tick: is_valid false and no shoulders
     *  when the board has no camera or the newest list is too old. */
    ps_neighbours_t neighbours;
} ps_meas_t;

/** Estimated state. Ground frame: origin on the ground under the midpoint of
 *  the feet, x forward (trunk heading), y left, z up. */
typedef struct {
    float roll_rad, pitch_rad; /**< trunk tilt (complementary filter) */
    float com_m[3];            /**< com_m[2] is the CoM height above the ground */
    float com_vel_m_s[3];
    float cop_m[2];     /**< centre of pressure (x, y) */
    float foot_m[2][3]; /**< sole centres, [0] left, [1] right */
    bool is_contact[2];
    bool is_fallen;
    /** Pelvis pose in the ground frame: origin (the IMU) and axes (columns),
     *  from the tilt and the legs; p_ground = pelvis_rot p_pelvis + pelvis_m. */
    float pelvis_m[3];
    float pelvis_rot[3][3];
} ps_estimate_t;

/** Joint targets produced by the policy slot. */
typedef struct {
    uint32_t n_joints;
    float q_rad[PS_MAX_JOINTS];
    float qd_rad_s[PS_MAX_JOINTS];
    float tau_ff_nm[PS_MAX_JOINTS];
} ps_targets_t;

#endif /* PS_STATE_H */
