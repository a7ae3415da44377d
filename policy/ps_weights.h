/*
 * ps_weights: a policy file, the trained MLP and its contract, in
 * safetensors (policy/ps_safetensors.h).
 *
 * Tensors (F32, PyTorch's [out][in] layout):
 *   base.K.weight, base.K.bias       base layer K = 0, 1, ... (bias optional)
 *   adapt.K.weight, adapt.K.bias     internal adapter in parallel with base K
 *   embed.J.weight, embed.J.bias     latent-injection embedding layer J
 * Anything else is refused. Metadata key "pushstep.contract" holds the
 * contract as JSON (docs/policy.md has an example):
 *   version            1
 *   robot              name it was trained for (informative)
 *   policy_hz          rate it was trained at (must equal the robot file's)
 *   joints             joint names in order: the order of joint_pos and
 *                      joint_vel and the indices of the actions
 *   kp, kd             per joint, the gains it was trained with
 *   stance             per joint, the offset of joint_pos and of the actions
 *   observation        {"fields": [names, ps_obs.h], "mean": [...], "std":
 *                      [...], "clip": c}
 *   action             {"joints": [names], "scale": [...], "clip": c, "base": b}:
 *                      target q = stance + scale * (base_a + a), |a| <= clip,
 *                      the sum clipped to clip too; base "stance" (the
 *                      default, base_a = 0) or "capture" (a residual policy:
 *                      base_a is the capture-point controller's action,
 *                      (q_capture - stance) / scale clipped to clip, computed
 *                      in the same step: policy/ps_mlp_policy.h)
 *   activations        one per base layer ("elu", "relu", ... ps_mlp.h)
 *   groups             optional, one per base layer: 1 dense, G > 1 a grouped
 *                      layer whose base.K.weight is [out, in / G] (ps_mlp.h)
 *   embed_activations  one per embedding layer; inject_layer; extra_size
 *   trained_by         the command and seed that made it (informative)
 * Loading checks the file (ps_safetensors), every value of every tensor
 * finite, the layers chained, the observation size equal to the first
 * layer's input and the action count to the last layer's output, every
 * field known; ps_weights_check_robot checks it against a robot and names
 * what differs.
 *
 * Threads: INIT only. Allocation: load allocates the engine's arena (one
 * malloc, freed by ps_weights_free).
 */
#ifndef PS_WEIGHTS_H
#define PS_WEIGHTS_H

#include <stdint.h>

#include "../rt/ps_limits.h"
#include "ps_mlp.h"
#include "ps_obs.h"
#include "ps_servo.h"

#define PS_WEIGHTS_VERSION      1u
#define PS_WEIGHTS_CONTRACT_KEY "pushstep.contract"

/** What the actions are added to (contract action.base). */
typedef enum {
    PS_WEIGHTS_BASE_STANCE = 0, /**< "stance": the actions alone */
    PS_WEIGHTS_BASE_CAPTURE,    /**< "capture": a residual on the capture-point controller */
} ps_weights_base_t;

typedef struct {
    uint32_t version;
    char robot[PS_NAME_LEN];
    uint32_t policy_hz;
    uint32_t n_joints;
    char joint_name[PS_MAX_JOINTS][PS_NAME_LEN];
    float kp_nm_rad[PS_MAX_JOINTS], kd_nm_s_rad[PS_MAX_JOINTS], stance_rad[PS_MAX_JOINTS];
    uint32_t n_fields;
    ps_obs_field_t fields[PS_OBS_MAX_FIELDS];
    uint32_t n_obs;
    float obs_mean[PS_OBS_MAX], obs_std[PS_OBS_MAX], obs_clip;
    uint32_t n_act;
    uint32_t act_joint[PS_MAX_JOINTS]; /**< index into joint_name */
    float act_scale[PS_MAX_JOINTS], act_clip;
    ps_weights_base_t act_base;
    uint32_t n_extra;
    char trained_by[1024]; /**< how the file was made; longer text is cut */
} ps_weights_contract_t;

typedef struct {
    ps_weights_contract_t contract; /**< read-only */
    ps_mlp_t mlp;                   /**< ready to run (read-only) */
    float *arena;                   /**< owned */
    size_t n_arena;
} ps_weights_t;

/** Load a policy file. @post *w ready on success (ps_weights_free releases
 *  it); err holds "PATH: problem" on failure and w holds nothing
 *  @return 0 | -ENOENT | -EIO | -EINVAL (err says what) | -ENOTSUP (a dtype)
 *          | -ERANGE (a NaN/Inf value) | -ENOMEM  @rt INIT */
int ps_weights_load(ps_weights_t *w, const char *path, char *err, size_t err_len);

/** The contract against a robot: the same joints in the same order, the
 *  same kp, kd (relative 1e-3) and stance (1e-4 rad) per joint, the same
 *  policy rate. A mismatch is refused with a message naming the first
 *  difference, e.g. "joints[3]: policy has l_knee, robot file has
 *  l_hip_pitch (trained for another joint order)".
 *  @return 0 | -PS_ERR_CONFIG | -EINVAL NULL  @rt INIT */
int ps_weights_check_robot(const ps_weights_contract_t *c, uint32_t n_joints,
                           const char (*joint_name)[PS_NAME_LEN], const ps_servo_joint_cfg_t *servo,
                           uint32_t policy_hz, char *err, size_t err_len);

/** Safe on a zeroed struct and twice. */
void ps_weights_free(ps_weights_t *w);

#endif /* PS_WEIGHTS_H */
