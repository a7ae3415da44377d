/*
 * ps_servo: the PD servo layer. Turns joint targets into MIT-mode commands
 * for the on-driver PD (p, v, kp, kd, tau_ff), according to the safety state:
 *   STANDBY, ESTOP: kp = kd = tau = 0 (limp; the command still polls a reply)
 *   RAMP:    target blended from the pose measured at ramp entry, gains
 *            blended from 0, by alpha in [0, 1]
 *   ACTIVE:  targets and configured gains
 *   DAMPING: kp = 0, kd = damping_kd, tau = 0
 * Every command is clamped into the joint's configured limits (position,
 * velocity, kp_max, kd_max, torque_max) before it leaves; a NaN or
 * out-of-range *target* is reported so the state machine can react, and the
 * command falls back to damping for that joint.
 *
 * Threads: loop thread (pure). Allocation: none.
 */
#ifndef PS_SERVO_H
#define PS_SERVO_H

#include <stdbool.h>

#include "../drivers/ps_mit.h"
#include "../rt/ps_sm.h"
#include "ps_state.h"

typedef struct {
    ps_sm_state_t state;
    float ramp_alpha;                 /**< 0..1, RAMP only */
    const float *ramp_from_q_rad;     /**< pose at ramp entry, RAMP only */
} ps_servo_mode_t;

/** Compute one joint's command. @post *out within the joint's limits
 *  @return 0 | -PS_ERR_LIMIT target NaN or outside pos limits (out = damping)
 *  @rt RT-SAFE O(1) */
int ps_servo_command(const ps_joint_cfg_t *j, const ps_control_cfg_t *c,
                     const ps_servo_mode_t *mode, unsigned joint_idx, const ps_targets_t *t,
                     ps_mit_cmd_t *out);

/** @return true if cmd is inside the joint's configured limits  @rt RT-SAFE */
bool ps_servo_is_within_limits(const ps_joint_cfg_t *j, const ps_mit_cmd_t *cmd);

#endif /* PS_SERVO_H */
