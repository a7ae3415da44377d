/*
 * ps_obs: the observation builder, one source of truth for the runtime (the
 * MLP policy in the loop) and training (the C environment in sim/ calls the
 * same function on the emulated robot's measurements and estimate).
 *
 * An observation is a list of named fields in the order a policy's contract
 * gives (policy/ps_weights.h); each field's raw value is normalised as
 * (raw - mean) / std and clipped to +-clip. Fields (frames: the estimator's
 * ground frame, heading-aligned, origin on the ground between the soles; "BoS
 * centre": the centre of the support polygon of the feet in contact):
 *
 *   gravity_body  3  unit gravity direction in the trunk frame (from the tilt)
 *   gyro_body     3  trunk angular velocity, IMU frame (rad/s)
 *   joint_pos     N  q - offset of the contract's joints (rad; offset = stance)
 *   joint_vel     N  qd of the contract's joints (rad/s)
 *   prev_action   A  the previous action the policy applied
 *   com_pos       3  whole-body CoM (mass model) from the BoS centre; z = height
 *   com_vel       3  its velocity over the ground (finite difference over the
 *                    build period, relative to the soles in contact at both
 *                    builds: the ground frame's origin moves with a swing foot)
 *   cop           2  centre of pressure from the BoS centre
 *   capture_point 2  LIPM capture point from the BoS centre
 *   bos_margin    1  signed distance of the capture point to the BoS (> 0 inside)
 *   feet          6  sole centres (left xyz, right xyz) from the CoM's ground point
 *   contact       2  1 when the foot is in contact, else 0
 *   momentum      6  linear momentum / mass (m/s), angular momentum about the
 *                    CoM / mass (m^2/s), point-mass model
 *   base_action   A  a residual policy's base this step: the capture-point
 *                    controller's targets in action units, clipped, as the
 *                    action is added to them (set with ps_obs_set_base_action
 *                    before the build; the contract allows it only with
 *                    action.base "capture"). prev_action holds the total
 *                    applied, so without this field the policy cannot tell
 *                    its own part from the controller's step of this instant
 *
 * Threads: loop thread (or one training worker per instance). Allocation:
 * none.
 */
#ifndef PS_OBS_H
#define PS_OBS_H

#include <stdbool.h>
#include <stdint.h>

#include "../rt/ps_limits.h"
#include "ps_balance.h"
#include "ps_state.h"

#define PS_OBS_MAX        256u /**< floats in one observation */
#define PS_OBS_MAX_FIELDS 24u

typedef enum {
    PS_OBS_GRAVITY_BODY = 0,
    PS_OBS_GYRO_BODY,
    PS_OBS_JOINT_POS,
    PS_OBS_JOINT_VEL,
    PS_OBS_PREV_ACTION,
    PS_OBS_COM_POS,
    PS_OBS_COM_VEL,
    PS_OBS_COP,
    PS_OBS_CAPTURE_POINT,
    PS_OBS_BOS_MARGIN,
    PS_OBS_FEET,
    PS_OBS_CONTACT,
    PS_OBS_MOMENTUM,
    PS_OBS_BASE_ACTION,
    PS_OBS_FIELD_COUNT
} ps_obs_field_t;

typedef struct {
    uint32_t n_fields;
    ps_obs_field_t fields[PS_OBS_MAX_FIELDS];
    uint32_t n_joints;                       /**< N: joints of joint_pos / joint_vel */
    uint32_t joint_idx[PS_MAX_JOINTS];       /**< measurement index of each */
    float joint_offset_rad[PS_MAX_JOINTS];   /**< subtracted from q (the stance) */
    uint32_t n_act;                          /**< A: size of prev_action, base_action */
    float mean[PS_OBS_MAX], std[PS_OBS_MAX]; /**< per observation float; std > 0 */
    float clip;                              /**< |normalised| <= clip; > 0 */
    ps_kinematics_cfg_t kin;                 /**< with a mass model */
    int leg_idx[2][PS_LEG_N_JOINTS];         /**< measurement index of the leg joints */
    float dt_s;                              /**< time between builds (the policy period) */
} ps_obs_cfg_t;

typedef struct {
    ps_obs_cfg_t cfg; /**< copy (read-only) */
    uint32_t n_obs;   /**< read-only */
    ps_balance_point_t prev_pts[PS_BALANCE_N_POINTS];
    float prev_com_m[3];
    float prev_feet_m[2][3];
    bool prev_contact[2];
    bool has_prev;
    float prev_action[PS_MAX_JOINTS];
    float base_action[PS_MAX_JOINTS];
} ps_obs_t;

/** @return the field's name ("gravity_body", ...), NULL out of range */
const char *ps_obs_field_name(ps_obs_field_t f);
/** @return the field of that name | -ENOENT  @rt INIT */
int ps_obs_field_find(const char *name);
/** @return floats of the field for N joints and A actions; 0 out of range */
uint32_t ps_obs_field_size(ps_obs_field_t f, uint32_t n_joints, uint32_t n_act);

/** @return floats of the whole observation cfg describes; 0 if invalid */
uint32_t ps_obs_size(const ps_obs_cfg_t *cfg);

/** Check and copy cfg.
 *  @return 0 | -EINVAL NULL, no fields or an unknown one, n_joints or n_act
 *          above PS_MAX_JOINTS, joint or leg index beyond PS_MAX_JOINTS, size
 *          above PS_OBS_MAX, a std <= 0 or non-finite, clip <= 0, dt <= 0, no
 *          mass model  @rt INIT */
int ps_obs_init(ps_obs_t *o, const ps_obs_cfg_t *cfg);

/** Forget the previous build, action and base (velocities 0 on the next build). */
void ps_obs_reset(ps_obs_t *o);

/** Record the action the policy applied (prev_action of the next build).
 *  @pre a has cfg.n_act floats  @rt RT-SAFE */
void ps_obs_set_action(ps_obs_t *o, const float *a);

/** Record the residual's base of this step (base_action of the next build).
 *  @pre a has cfg.n_act floats  @rt RT-SAFE */
void ps_obs_set_base_action(ps_obs_t *o, const float *a);

/** Build one observation from the latest measurement and estimate.
 *  @post out_norm (n_obs floats) normalised and clipped; out_raw (may be
 *        NULL) before normalisation; velocities use the previous build
 *  @return n_obs | -EINVAL NULL argument | -ERANGE a raw value not finite or
 *          no foot in contact (out written anyway; the caller must not use it)
 *  @rt RT-SAFE O(n_obs) */
int ps_obs_build(ps_obs_t *o, const ps_meas_t *m, const ps_estimate_t *est, float *out_norm,
                 float *out_raw);

#endif /* PS_OBS_H */
