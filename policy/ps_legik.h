/*
 * ps_legik: analytic inverse kinematics of one 6-DoF leg (hip yaw, roll,
 * pitch, knee, ankle pitch, roll; docs/robot.md's convention, the same
 * geometry as ps_estimate_leg_fk_pose, which it inverts).
 *
 * Method: the closed form for a leg whose three hip axes intersect and whose
 * ankle axes intersect (Kajita et al., "Introduction to Humanoid Robotics",
 * section 2.5): the hip-to-ankle distance gives the knee, the hip centre seen
 * from the foot gives the ankle pitch and roll, and what is left of the foot
 * rotation, Rz(yaw) Rx(roll) Ry(pitch), gives the hip angles.
 *
 * Threads: any (pure). Allocation: none.
 */
#ifndef PS_LEGIK_H
#define PS_LEGIK_H

#include "ps_estimate.h"

/** Joint angles that put the sole centre of leg `side` at sole_m with the
 *  foot's axes foot_rot (columns in the pelvis frame), both in the pelvis
 *  frame (origin at the IMU). A target beyond the leg's reach (hip to ankle
 *  farther than thigh + shank, or nearer than |thigh - shank|) gets the
 *  straightest (or most bent) leg pointing at it.
 *  @pre side 0 left, 1 right; foot_rot a rotation matrix
 *  @post out_q_rad written whenever the return is >= 0 (joint limits are not
 *        applied: the caller clamps)
 *  @return 0 | 1 target out of reach (best effort written) | -EINVAL NULL
 *          argument, side not 0/1, non-finite input or zero leg lengths
 *  @units m, rad  @rt RT-SAFE O(1) */
int ps_legik_solve(const ps_kinematics_cfg_t *k, int side, const float sole_m[3],
                   const float foot_rot[3][3], float out_q_rad[PS_LEG_N_JOINTS]);

/** The rotation R = Rz(yaw) Ry(pitch) Rx(roll) as a row-major matrix (the
 *  estimator's trunk convention with a heading).  @rt RT-SAFE, pure */
void ps_legik_rot_rpy(float roll_rad, float pitch_rad, float yaw_rad, float out_rot[3][3]);

#endif /* PS_LEGIK_H */
