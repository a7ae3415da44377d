/*
 * ps_servo: the PD servo layer. Turns joint targets into MIT-mode commands
 * for the on-driver PD (p, v, kp, kd, tau_ff), according to the safety state:
 *   STANDBY, ESTOP: kp = kd = tau = 0 (limp; the command still polls a reply)
 *   RAMP:    target blended from the pose measured at ramp entry, gains
 *            blended from 0, by alpha in [0, 1]
 *   ACTIVE:  targets and configured gains
 *   DAMPING: kp = 0, kd = damping_kd, tau = 0
 * Every command is clamped into the joint's configured limits (position,
 * velocity, kp_max, kd_max, torque_max) and into the driver's wire range
 * (j->wire), so ps_mit_encode_cmd() never refuses it; a NaN or out-of-range
 * *target* is reported so the state machine can react, and the command falls
 * back to damping for that joint. A command in the corner that would pack
 * into an MIT special frame (p, v, kp, kd all at their wire maxima) gets kd
 * lowered by two LSB, so it always encodes as a set-point.
 *
 * Torque-limited set-point (RAMP, ACTIVE): the driver computes
 *   tau = kp * (p - q) + kd * (v - qd) + tau_ff,
 * so p is also clamped into q_meas +/- (torque_max - |tau_ff|) / kp: the
 * spring term alone never asks for more than the torque left after the
 * feed-forward. If the measured q lies outside the position limits (the
 * window and the limits do not overlap), kp is lowered instead so that
 * kp * |p - q| still fits. The damping term is not bounded here (it needs
 * qd); kd_max and vel_max bound it.
 *
 * RAMP keeps kd at the ACTIVE value from alpha = 0: a limp joint being pulled
 * towards a new set-point by a growing spring is safest fully damped.
 * v and tau_ff are blended by alpha like p and kp.
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
    float ramp_alpha;             /**< 0..1, RAMP only; clamped, NaN counts as 0 */
    const float *ramp_from_q_rad; /**< pose at ramp entry, RAMP only, by joint;
                                       NULL or a non-finite entry: meas_q_rad used */
    const float *meas_q_rad;      /**< measured position, by joint (every state):
                                       set-point of the limp/damping command and
                                       centre of the torque-limited window */
} ps_servo_mode_t;

/** Compute one joint's command.
 *  STANDBY/ESTOP: p = measured q clamped into limits, v = kp = kd = tau = 0.
 *  DAMPING: same p, kd = c->damping_kd_nm_s_rad clamped to kd_max.
 *  ACTIVE: targets and j's gains, clamped, torque-limited set-point.
 *  RAMP: p = from + alpha * (target - from), kp, v, tau_ff scaled by alpha,
 *        kd full; clamped and torque-limited like ACTIVE.
 *  Where the measured q is not finite, the limp/damping set-point is the
 *  stance clamped into limits (irrelevant to the drive since kp = 0).
 *  Targets (t) are read only in RAMP/ACTIVE; t may be NULL in other states.
 *  qd/tau_ff targets outside their limits are clamped silently (only a
 *  position target is range-checked).
 *  @pre j checked by ps_config (pos limits inside the wire range, 0 inside
 *       the wire's v and t ranges), mode->meas_q_rad has joint_idx + 1 entries
 *  @post *out within the joint's limits and wire range whenever j and out are
 *        non-NULL, also on error: on -PS_ERR_LIMIT (and -EINVAL for t NULL)
 *        the damping command; on the other -EINVAL cases the limp command
 *  @return 0 | -PS_ERR_LIMIT target NaN/inf (q, qd or tau_ff), q outside pos
 *          limits, joint_idx >= t->n_joints, or measured q not finite in
 *          RAMP/ACTIVE (out = damping)
 *          | -EINVAL j/c/mode/out/meas_q_rad NULL, t NULL in RAMP/ACTIVE,
 *          joint_idx >= PS_MAX_JOINTS, state not a ps_sm_state_t
 *  @units rad, rad/s, Nm/rad, Nm s/rad, Nm
 *  @rt RT-SAFE O(1), pure, loop thread */
int ps_servo_command(const ps_joint_cfg_t *j, const ps_control_cfg_t *c,
                     const ps_servo_mode_t *mode, unsigned joint_idx, const ps_targets_t *t,
                     ps_mit_cmd_t *out);

/** Every field finite; p in [pos_min, pos_max]; |v| <= vel_max;
 *  0 <= kp <= kp_max; 0 <= kd <= kd_max; |tau_ff| <= torque_max; and every
 *  field inside j->wire (so the frame encodes).
 *  @return true if cmd is inside the joint's configured limits; false also
 *          for NULL arguments  @rt RT-SAFE O(1), pure */
bool ps_servo_is_within_limits(const ps_joint_cfg_t *j, const ps_mit_cmd_t *cmd);

#endif /* PS_SERVO_H */
