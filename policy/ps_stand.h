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

typedef struct {
    const ps_robot_cfg_t *robot;
    int idx_ankle_pitch[2], idx_ankle_roll[2]; /**< [0] left, [1] right, -1 if absent */
    float k_tilt;     /**< ankle angle per rad of trunk tilt */
    float k_com;      /**< ankle angle per m of CoM offset */
} ps_stand_t;

/** @pre robot outlives st  @return 0 | -EINVAL  @rt INIT */
int ps_stand_init(ps_stand_t *st, const ps_robot_cfg_t *robot);

/** @post *out is this controller in the policy slot  @rt INIT */
void ps_stand_as_policy(ps_stand_t *st, ps_policy_t *out);

#endif /* PS_STAND_H */
