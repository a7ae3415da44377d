/*
 * ps_capture: the capture-point stepping controller, in the policy slot.
 * The benchmark's analytic baseline and the fallback of the trained policy.
 *
 * Every policy tick it computes the whole-body CoM (ps_balance's mass
 * model, in the estimator's ground frame), its velocity over the ground and
 * the LIPM capture point xi = c + v / omega0 (Pratt et al. 2006). Then:
 *
 *   STAND  both feet down. The pelvis is held level, crouched so that no leg
 *          is longer than reach_frac of its length (measured: the bent knees
 *          take pushes better than the stance's), with the CoM over the
 *          centre of the base of support (leg IK), plus
 *          the standing controller's ankle strategy (trunk tilt and CoM
 *          velocity, policy/ps_stand.c). When xi leaves the base of support
 *          shrunk by trigger_margin_m, a step starts.
 *   SWING  one foot swings to the step target: the capture point predicted
 *          at touch-down, xi(T) = p + (xi - p) e^{omega0 T} with p the stance
 *          foot's centre, plus step_offset_m beyond it; clamped to the leg's
 *          reach and never across the stance foot. The swing foot follows a
 *          minimum-jerk path in x and y and a sine arch of lift_m in z over
 *          swing_s; the target is re-planned while the first half of the
 *          swing lasts. The stance leg holds the pelvis level at the
 *          standing height; the swing leg is solved from the trunk's
 *          estimated pose, so the sole keeps to its path over the ground
 *          while the trunk leans.
 *   SETTLE both feet down again for settle_s (no new step), then STAND
 *          around the new base of support.
 *
 * The swing foot is the one on the side the capture point moved to
 * (lateral), else the less loaded one (the farther from the capture point).
 * Targets are joint positions from the analytic leg IK (ps_legik), feet
 * flat and heading-aligned; the other joints hold their stance. Everything
 * is clamped to the joints' limits.
 *
 * Threads: loop thread. Allocation: none.
 */
#ifndef PS_CAPTURE_H
#define PS_CAPTURE_H

#include <stdbool.h>
#include <stdint.h>

#include "ps_balance.h"
#include "ps_policy.h"
#include "ps_servo.h"

typedef enum { PS_CAPTURE_STAND = 0, PS_CAPTURE_SWING, PS_CAPTURE_SETTLE } ps_capture_phase_t;

/** Tunables (defaults from ps_capture_init; user may modify). */
typedef struct {
    float swing_s;          /**< swing duration */
    float settle_s;         /**< double support after a step before the next */
    float lift_m;           /**< swing foot apex */
    float trigger_margin_m; /**< step when xi is closer than this to the BoS edge (or out) */
    float step_offset_m;    /**< place the foot this far beyond the predicted xi */
    float max_step_m;       /**< longest step from the stance foot, horizontal */
    float min_width_m;      /**< the swing foot stays this far to its side of the stance foot */
    float k_tilt, k_vel;    /**< ankle strategy while standing (ps_stand's meaning) */
    float k_com;            /**< pelvis shift per m of CoM offset from the BoS centre */
    float lookahead_s;      /**< trigger on xi predicted this far ahead (LIPM about the CoP) */
    float max_load_frac;    /**< no sideways step with a foot the CoM is this far across to */
    float reach_frac;       /**< hip-ankle distance at most this share of thigh + shank */
    /** true: the swing leg is solved from the trunk's estimated pose; false: for a
     *  level trunk (the controller until 2026-12-03, kept for the training's expert) */
    bool swing_follows_trunk;
} ps_capture_params_t;

typedef struct {
    uint32_t n_joints;
    const ps_servo_joint_cfg_t *joints; /**< stance and limits, by joint (kept) */
    ps_kinematics_cfg_t kin;            /**< with a mass model */
    int leg_idx[2][PS_LEG_N_JOINTS];    /**< joint index of each leg joint */
    float dt_s;                         /**< policy period */
    float height_m;                     /**< pelvis above the soles at the stance */
    float stance_sole_m[2][3];          /**< soles in the pelvis frame at the stance */
    ps_capture_params_t p;              /**< user may modify */
    /* state (read-only) */
    ps_capture_phase_t phase;
    int swing_side;          /**< 0 left, 1 right; valid in SWING */
    float t_phase_s;         /**< time in the phase */
    float swing_from_m[3];   /**< swing sole at lift-off, from the stance sole, in its frame */
    float swing_to_m[3];     /**< its target, from the stance sole, in its frame */
    float foot_yaw[2];       /**< each sole's heading in the ground frame */
    float com_m[3], com_vel_m_s[3], xi_m[2]; /**< last computed (ground frame) */
    float bos_margin_m;      /**< xi's signed distance to the BoS (> 0 inside) */
    float prev_com_m[3], prev_feet_m[2][3]; /**< trunk frame, for the odometry */
    bool prev_contact[2], has_prev;
    bool was_out;       /**< xi was outside the shrunk BoS at the last tick */
    float height_cmd_m; /**< pelvis height target, rate-limited; 0: take the measured */
    uint32_t n_steps; /**< steps started since init */
} ps_capture_t;

/** Finds the leg joints by name (l_hip_yaw ... r_ankle_roll), computes the
 *  standing height and soles from the stance by forward kinematics, sets the
 *  default parameters.
 *  @pre joints outlives c; kin has a mass model
 *  @return 0 | -EINVAL NULL, n_joints 0 or > PS_MAX_JOINTS, dt <= 0, no mass
 *          model | -ENOENT a leg joint missing  @rt INIT */
int ps_capture_init(ps_capture_t *c, uint32_t n_joints, const char (*joint_name)[PS_NAME_LEN],
                    const ps_servo_joint_cfg_t *joints, const ps_kinematics_cfg_t *kin,
                    float dt_s);

/** @post *out is this controller in the policy slot (name "capture"). Its step
 *  returns 0 | -EINVAL | -PS_ERR_LIMIT (a target not finite: out untouched).
 *  With no estimate, a fallen one, or no foot in contact it holds the stance.
 *  @rt INIT */
void ps_capture_as_policy(ps_capture_t *c, ps_policy_t *out);

/** @return "stand", "swing", "settle" */
const char *ps_capture_phase_name(ps_capture_phase_t p);

#endif /* PS_CAPTURE_H */
