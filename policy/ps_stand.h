/*
 * ps_stand: the standing controller in the policy slot. Holds the robot's
 * configured stance and adds an ankle strategy: ankle pitch/roll targets lean
 * against the trunk tilt and the CoM offset from the support centre, so small
 * disturbances are absorbed without stepping.
 *
 * Threads: loop thread. Allocation: none.
 */
#ifndef PS_STAND_H
#define PS_STAND_H

#include "ps_policy.h"
#include "ps_servo.h"

#define PS_STAND_K_TILT_DEFAULT 0.5f  /**< rad of ankle per rad of trunk tilt */
#define PS_STAND_K_COM_DEFAULT  0.0f  /**< rad of ankle per m of CoM offset (see ps_stand.c) */
#define PS_STAND_K_VEL_DEFAULT  0.25f /**< rad of ankle per m/s of CoM velocity */
#define PS_STAND_CORR_MAX_RAD   0.15f /**< |ankle correction| limit */

typedef struct {
    uint32_t n_joints;
    const ps_servo_joint_cfg_t *joints;        /**< stance and limits, by joint (kept) */
    int idx_ankle_pitch[2], idx_ankle_roll[2]; /**< [0] left, [1] right, -1 if absent */
    float k_tilt;                              /**< ankle angle per rad of trunk tilt */
    float k_com;                               /**< ankle angle per m of CoM offset */
    float k_vel;                               /**< ankle angle per m/s of CoM velocity */
} ps_stand_t;

/** Finds l/r_ankle_pitch and l/r_ankle_roll by name among joint_name (-1 if
 *  absent: that joint gets no correction), sets the default gains (user may
 *  modify).
 *  @pre joints (n_joints entries) outlives st; joint_name is not kept
 *  @post st ready
 *  @return 0 | -EINVAL an argument NULL, n_joints 0 or > PS_MAX_JOINTS  @rt INIT */
int ps_stand_init(ps_stand_t *st, uint32_t n_joints, const char (*joint_name)[PS_NAME_LEN],
                  const ps_servo_joint_cfg_t *joints);

/** @post *out is this controller in the policy slot (name "stand"). Its step
 *  writes stance_rad for every joint, qd = tau_ff = 0, plus the ankle
 *  correction (sign derivation in ps_stand.c), clamped to
 *  +-PS_STAND_CORR_MAX_RAD and to the joint limits. No correction when est is
 *  NULL, non-finite or fallen. step returns 0 | -EINVAL ctx/out NULL or bad
 *  joint count | -PS_ERR_LIMIT a target is not finite (out untouched).
 *  @pre st initialised, both non-NULL  @rt INIT */
void ps_stand_as_policy(ps_stand_t *st, ps_policy_t *out);

#endif /* PS_STAND_H */
