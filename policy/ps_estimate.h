/*
 * ps_estimate: state estimation from joint replies and the IMU.
 *
 * Trunk roll/pitch: complementary filter of gyro integration and the
 * accelerometer's gravity direction. Feet: forward kinematics of each 6-DoF
 * leg (hip yaw, roll, pitch, knee, ankle pitch, roll; lengths from the robot
 * file) rotated by the trunk tilt. Contact: a foot is in contact when its sole
 * is within a threshold of the lowest sole. CoM: lumped trunk model, the
 * pelvis plus com_offset_z_m along the trunk axis, placed above the contact
 * feet. CoP: from the ankle torques of the feet in contact (x = -tau_pitch /
 * F_z, y = tau_roll / F_z per foot, weight shared by contact), clamped to the
 * support polygon. Fallen: tilt beyond fall_tilt_rad or CoM below
 * fall_com_height_m.
 *
 * Threads: loop thread. Allocation: none.
 */
#ifndef PS_ESTIMATE_H
#define PS_ESTIMATE_H

#include "ps_state.h"

/** Leg joints in chain order, hip yaw to ankle roll. */
enum { PS_LEG_HIP_YAW, PS_LEG_HIP_ROLL, PS_LEG_HIP_PITCH, PS_LEG_KNEE, PS_LEG_ANKLE_PITCH,
       PS_LEG_ANKLE_ROLL, PS_LEG_N_JOINTS };

typedef struct {
    const ps_robot_cfg_t *robot;
    int leg_idx[2][PS_LEG_N_JOINTS]; /**< joint index of each leg joint, [0] left */
    float dt_s;
    float filter_tau_s;  /**< complementary filter time constant */
    bool has_tilt;
    ps_estimate_t est;
    float prev_com_m[3];
} ps_estimator_t;

/** Finds the leg joints by name ("l_hip_yaw" ... "r_ankle_roll").
 *  @pre robot outlives e  @return 0 | -ENOENT a leg joint is missing  @rt INIT */
int ps_estimate_init(ps_estimator_t *e, const ps_robot_cfg_t *robot, float dt_s);

/** @post e->est updated from m  @rt RT-SAFE O(joints) */
void ps_estimate_update(ps_estimator_t *e, const ps_meas_t *m);

/** Forward kinematics of one leg, exposed for tests: sole centre in the pelvis
 *  frame. @pre side 0 left, 1 right  @units rad in, m out  @rt RT-SAFE */
void ps_estimate_leg_fk(const ps_kinematics_cfg_t *k, int side, const float q_rad[PS_LEG_N_JOINTS],
                        float out_sole_m[3]);

#endif /* PS_ESTIMATE_H */
