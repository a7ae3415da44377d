/*
 * ps_mlp_policy: the trained MLP in the policy slot, with a fallback.
 *
 * Each step: the observation (policy/ps_obs, the contract's layout and
 * normalisation), one forward pass (policy/ps_mlp), then joint targets
 * q = stance + scale * a for the contract's action joints (the others hold
 * their stance), clamped to the joints' limits; qd = tau_ff = 0. A residual
 * policy (contract action.base "capture", policy/ps_weights.h) adds its
 * action a to the capture-point controller's of the same step (the
 * fallback's, in action units, clipped), the sum clipped to the contract's
 * clip: q = stance + scale * clip(a_capture + a); the observation's previous
 * action is that sum, as in training (tools/psenv).
 *
 * The policy misbehaves when the observation cannot be built (-ERANGE; for a
 * residual policy also when the capture controller has no targets), an
 * action is NaN or beyond the contract's clip ("out of range"), or the step
 * takes longer than late_ns on the given clock ("late"). Then the fallback
 * policy (the capture-point controller) computes this step's targets, and
 * keeps the slot for fallback_hold_s before the MLP is tried again (its
 * observation history restarts). The fallback runs every step in the
 * background while the MLP is in charge, so that it takes over with a
 * current estimate of the CoM velocity. Counters say how often and why.
 *
 * Threads: loop thread. Allocation: none (the weights are loaded at INIT).
 */
#ifndef PS_MLP_POLICY_H
#define PS_MLP_POLICY_H

#include <stdint.h>

#include "../rt/ps_clock.h"
#include "ps_obs.h"
#include "ps_policy.h"
#include "ps_servo.h"
#include "ps_weights.h"

/** Why the fallback took over (bits, also counted). */
typedef enum {
    PS_MLP_FAULT_OBS = 1u << 0,   /**< observation not finite / no support */
    PS_MLP_FAULT_NAN = 1u << 1,   /**< an action NaN or infinite */
    PS_MLP_FAULT_RANGE = 1u << 2, /**< an action beyond the contract's clip */
    PS_MLP_FAULT_LATE = 1u << 3,  /**< the step took longer than late_ns */
} ps_mlp_fault_t;

typedef struct {
    ps_weights_t *w;                    /**< loaded, checked against the robot (kept) */
    const ps_servo_joint_cfg_t *joints; /**< the robot's, by joint (kept) */
    uint32_t n_joints;
    ps_obs_t obs;
    ps_policy_t fallback;    /**< required */
    const ps_clock_t *clock; /**< NULL: never late */
    int64_t late_ns;
    float fallback_hold_s, dt_s;
    uint32_t joint_idx[PS_MAX_JOINTS]; /**< robot joint of each contract joint */
    float in[PS_OBS_MAX], act[PS_MAX_JOINTS], applied[PS_MAX_JOINTS];
    /* read-only */
    bool is_fallback;
    float fallback_left_s;
    uint32_t last_faults;
    uint64_t n_steps, n_fallback_steps, n_obs_faults, n_nan, n_range, n_late;
    /** The loop time of the first takeover (the IMU reading's t_ns then, ns;
     *  0 when no reading had come yet); -1: never. Tells whether the fallback
     *  acted before or after something else, such as a fall. */
    int64_t first_fallback_t_ns;
} ps_mlp_policy_t;

/** @pre w loaded and ps_weights_check_robot passed for this robot; the
 *  joint names are the robot's (same order as the contract); fallback set
 *  @return 0 | -EINVAL NULL, no fallback, n_joints differs from the
 *          contract's, no mass model in kin, or the observation config
 *          refused (ps_obs_init) | -ENOENT a leg joint missing  @rt INIT */
int ps_mlp_policy_init(ps_mlp_policy_t *p, ps_weights_t *w, uint32_t n_joints,
                       const char (*joint_name)[PS_NAME_LEN], const ps_servo_joint_cfg_t *joints,
                       const ps_kinematics_cfg_t *kin, float dt_s, ps_policy_t fallback,
                       const ps_clock_t *clock, int64_t late_ns);

/** @post *out is this policy in the slot (name "mlp"). Its step returns 0,
 *  or what the fallback's returns while it is in charge.  @rt INIT */
void ps_mlp_policy_as_policy(ps_mlp_policy_t *p, ps_policy_t *out);

#endif /* PS_MLP_POLICY_H */
