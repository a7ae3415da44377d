/*
 * ps_servo: the PD servo layer. Turns joint targets into neutral joint
 * commands for the drive's own PD (q, qd, kp, kd, tau_ff, ps_act_cmd_t), in
 * the servo mode the loop asks for:
 *   LIMP:  kp = kd = tau = 0 (the command still polls a reply)
 *   DAMP:  kp = 0, kd = damping_kd, tau = 0
 *   RAMP:  target blended from the pose measured at ramp entry, gains
 *          blended from 0, by alpha in [0, 1]
 *   TRACK: targets and configured gains
 *   HOLD:  the hold pose (mode->hold_q_rad) with the configured gains,
 *          qd = tau_ff = 0: stiff, for faults where the drives still answer
 * The loop maps its safety state to a mode; this module knows no state
 * machine and no protocol.
 *
 * Every command is clamped into the joint's configured limits (position,
 * velocity, kp_max, kd_max, torque_max) and into the drive's wire range seen
 * from the joint (j->wire, from ps_act_joint_range), so the protocol's
 * encoder never refuses it; a NaN or out-of-range *target* is reported so the
 * state machine can react, and the command falls back to damping for that
 * joint.
 *
 * Torque-limited set-point (RAMP, TRACK, HOLD): the drive computes
 *   tau = kp * (p - q) + kd * (v - qd) + tau_ff,
 * so p is also clamped into q_meas +/- (torque_max - |tau_ff|) / kp: the
 * spring term alone never asks for more than the torque left after the
 * feed-forward. If the measured q lies outside the position limits (the
 * window and the limits do not overlap), kp is lowered instead so that
 * kp * |p - q| still fits. The damping term is not bounded here (it needs
 * qd); kd_max and vel_max bound it.
 *
 * RAMP keeps kd at the TRACK value from alpha = 0: a limp joint being pulled
 * towards a new set-point by a growing spring is safest fully damped.
 * v and tau_ff are blended by alpha like p and kp.
 *
 * Threads: loop thread (pure). Allocation: none.
 */
#ifndef PS_SERVO_H
#define PS_SERVO_H

#include <stdbool.h>

#include "../drivers/ps_actuator.h"
#include "ps_state.h"

/** One joint as the servo layer sees it (robot file, per joint). */
typedef struct {
    ps_act_limits_t lim; /**< configured limits; no command leaves them */
    float kp_nm_rad;     /**< stiffness in TRACK and HOLD */
    float kd_nm_s_rad;   /**< damping in TRACK, RAMP and HOLD */
    float stance_rad;    /**< nominal standing pose */
    ps_act_range_t wire; /**< the drive's wire ranges seen from the joint */
} ps_servo_joint_cfg_t;

/** Settings shared by every joint. */
typedef struct {
    float damping_kd_nm_s_rad; /**< kd of every joint in DAMP (clamped to kd_max) */
} ps_servo_cfg_t;

typedef enum {
    PS_SERVO_LIMP = 0,
    PS_SERVO_DAMP,
    PS_SERVO_RAMP,
    PS_SERVO_TRACK,
    PS_SERVO_HOLD,
    PS_SERVO_MODE_COUNT
} ps_servo_mode_kind_t;

typedef struct {
    ps_servo_mode_kind_t kind;
    float ramp_alpha;             /**< 0..1, RAMP only; clamped, NaN counts as 0 */
    const float *ramp_from_q_rad; /**< pose at ramp entry, RAMP only, by joint;
                                       NULL or a non-finite entry: meas_q_rad used */
    const float *meas_q_rad;      /**< measured position, by joint (every state):
                                       set-point of the limp/damping command and
                                       centre of the torque-limited window */
    const float *hold_q_rad;      /**< HOLD: pose to hold, by joint; NULL or a
                                       non-finite entry: the stance */
} ps_servo_mode_t;

/** Compute one joint's command.
 *  LIMP: p = measured q clamped into limits, v = kp = kd = tau = 0.
 *  DAMP: same p, kd = c->damping_kd_nm_s_rad clamped to kd_max.
 *  TRACK: targets and j's gains, clamped, torque-limited set-point.
 *  RAMP: p = from + alpha * (target - from), kp, v, tau_ff scaled by alpha,
 *        kd full; clamped and torque-limited like TRACK.
 *  HOLD: p = hold pose, j's gains, v = tau = 0, torque-limited like TRACK;
 *        targets are not read.
 *  Where the measured q is not finite, the limp/damping set-point is the
 *  stance clamped into limits (irrelevant to the drive since kp = 0).
 *  Targets (t) are read only in RAMP/TRACK; t may be NULL in other modes.
 *  qd/tau_ff targets outside their limits are clamped silently (only a
 *  position target is range-checked).
 *  @pre j checked by the config loader (limits inside j->wire, 0 inside the
 *       wire's v and t ranges), mode->meas_q_rad has joint_idx + 1 entries
 *  @post *out within the joint's limits and wire range whenever j and out are
 *        non-NULL, also on error: on -PS_ERR_LIMIT (and -EINVAL for t NULL)
 *        the damping command; on the other -EINVAL cases the limp command
 *  @return 0 | -PS_ERR_LIMIT target NaN/inf (q, qd or tau_ff), q outside pos
 *          limits, joint_idx >= t->n_joints, or measured q not finite in
 *          RAMP/TRACK/HOLD (out = damping)
 *          | -EINVAL j/c/mode/out/meas_q_rad NULL, t NULL in RAMP/TRACK,
 *          joint_idx >= PS_MAX_JOINTS, kind not a ps_servo_mode_kind_t
 *  @units rad, rad/s, Nm/rad, Nm s/rad, Nm
 *  @rt RT-SAFE O(1), pure, loop thread */
int ps_servo_command(const ps_servo_joint_cfg_t *j, const ps_servo_cfg_t *c,
                     const ps_servo_mode_t *mode, unsigned joint_idx, const ps_targets_t *t,
                     ps_act_cmd_t *out);

/** Every field finite; q in [pos_min, pos_max]; |qd| <= vel_max;
 *  0 <= kp <= kp_max; 0 <= kd <= kd_max; |tau_ff| <= torque_max; and every
 *  field inside j->wire (so the frame encodes).
 *  @return true if cmd is inside the joint's configured limits; false also
 *          for NULL arguments  @rt RT-SAFE O(1), pure */
bool ps_servo_is_within_limits(const ps_servo_joint_cfg_t *j, const ps_act_cmd_t *cmd);

/** @return "limp", "damp", "ramp", "track", "hold" or "?"  @rt RT-SAFE */
const char *ps_servo_mode_name(ps_servo_mode_kind_t kind);

#endif /* PS_SERVO_H */
