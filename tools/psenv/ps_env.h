/*
 * ps_env: the training environment, batched, for policy/train/ (Python via
 * ctypes: build/libpsenv.so). Not part of the runtime: it lives in tools/
 * because it composes sim/ (the MuJoCo plant, the emulated drives) with
 * policy/ (estimator, observation builder, servo layer, the capture-point
 * controller as expert), which no layer of the runtime may do.
 *
 * One environment is the runtime's chain without the wire timing: every
 * servo tick (1 ms) the joints and the IMU (with noise and bias) are read
 * into a ps_meas_t, the estimator (policy/ps_estimate) updates, the servo
 * layer (policy/ps_servo, TRACK with the robot file's gains) turns the
 * policy's targets into commands for the joints due that tick (legs every
 * 2 ms: the 500 Hz leg command rate), each command is encoded in the
 * joint's protocol and decoded by its emulated drive (sim/ps_devices:
 * quantisation, the drive's PD at its rate, its torque-speed limit),
 * delayed by the episode's command latency; two physics steps per tick.
 * Every policy step (policy_hz) the observation is ps_obs_build's; the
 * layout is policy/train/contract.py's OBS_FIELDS (OBS_FIELDS_BASE with
 * is_obs_base_action).
 *
 * Episodes (episode_s): the robot starts in its stance, free; one or two
 * pushes on the torso at random times, directions, delta-v in
 * [push_dv_min, push_dv_max] m/s and durations 0.1 or 0.3 s. With
 * probability harness_p an episode starts as the runtime's do: the sim
 * harness holds the pelvis while the policy already acts, and lets go at a
 * random time in [0.2, 2] s (the runtime releases at 2 s, the policy having
 * acted from 0.2 s; a policy that drifts while held falls at release); the
 * pushes and the episode's end move on by the time held. With probability
 * focus_p a push's direction is drawn from focus_dir_rad +- 45 deg instead
 * of the whole circle (more of the pushes a policy handles worst). Domain randomisation
 * (is_dr) per episode: torso and pelvis mass x [0.9, 1.1] and the torso's
 * CoM moved up to 2 cm, friction x [0.6, 1.4], motor strength (peak and
 * torque_max) x [0.85, 1.15], command latency 0..2 ms, IMU noise x [0.5, 2]
 * and new biases. An episode ends at a fall (a robot body other than the
 * feet on the floor) or at episode_s; the environment then resets itself.
 *
 * Reward (docs/policy.md): Push-and-Step's balance term
 * 0.5 (e^{-k|CoM - CoM_target|} + e^{-k|CoP - CoP_target|}) with
 * CoM_target the centre of the base of support at the resting CoM height,
 * CoP_target the capture point clipped into the base of support (the CoP
 * that stops the CoM in the linear inverted pendulum), k = 10 /m; plus its
 * quality terms (foot sliding, heading, effort), 0.7 balance + 0.3
 * quality; a fall gives -1 and ends the episode. All from the plant's
 * ground truth.
 *
 * Threads: n_threads workers (pthreads) step disjoint slices of the
 * environments; the API is called from one thread. Allocation: at create.
 */
#ifndef PS_ENV_H
#define PS_ENV_H

#include <stddef.h>
#include <stdint.h>

typedef struct ps_env ps_env_t;

typedef struct {
    uint32_t n_envs;
    uint32_t n_threads;
    uint64_t seed;
    float episode_s;
    float push_dv_max_m_s;
    int is_dr;     /**< domain randomisation */
    int is_expert; /**< compute the capture-point controller's actions */
    /* Added for fine-tuning; zero (with push_dv_min_m_s 0.05) gives the
     * episodes of the first stage, random draws included, bit for bit. */
    double push_dv_min_m_s; /**< smallest random push delta-v (double: 0.05 as before) */
    float harness_p;        /**< probability that an episode starts harnessed */
    float focus_p;          /**< probability that a push comes from focus_dir_rad +-45 deg */
    float focus_dir_rad;    /**< world frame, direction of the force, 0 = +x */
    /* Added 2026-12-03; zero gives the runtime's capture-point controller. */
    int is_expert_slow; /**< the expert steps as the controller did until 2026-12-03: 0.3 s
                           swing, 5 cm lift, 0.1 s trigger lookahead, 0.3 s settling, the
                           swing leg solved for a level trunk (what the shipped policy
                           cloned; its clone measured better, docs/policy.md) */
    /* Added 2026-12-04; zero keeps the harnessed start above. */
    int is_ramp_start; /**< a harnessed episode starts as the runtime's trials do: the drives
                          limp in the harness for the 0.2 s settling, then the targets ramp
                          from that pose over the robot's ramp_s (the servo layer's RAMP),
                          the harness letting go ramp_s + [0.2, 1.0] s in (the runtime's
                          trials: 0.8 s) */
    /* Added 2026-12-04; zero keeps the stage-1 layout. */
    int is_obs_base_action; /**< the observation ends with base_action (policy/ps_obs.h): the
                               capture-point controller's action of this step, which the
                               expert output gives too (for a residual policy); the
                               controller then steps at ps_env_reset too (to fill the field),
                               so its later actions differ from those of an environment
                               without the flag */
} ps_env_cfg_t;

/** Floats of info per environment and step: */
#define PS_ENV_INFO (PS_ENV_INFO_PRIV + PS_ENV_PRIV)
/* [0] fell this step, [1] episode ended, [2] episode time s, [3] last push
 * delta-v m/s, [4] r_balance, [5] r_quality, [6] CoM height m, [7] pushes so far,
 * [8] 1 when the expert's action for the new observation's state is part of a
 * step (the capture-point controller is in its swing), 0 otherwise and when no
 * expert output is asked for (added 2026-12-04: a cost on a residual while the
 * controller steps, train.py --swing-cost) */
#define PS_ENV_INFO_EXPERT_SWING 8 /**< the index of that flag */
/* [9] seconds since the robot was last disturbed, for the new observation's
 * state: since the harness let go or a push ended, whichever came last; -1
 * while held or pushed (added 2026-12-05: a cost on a residual while the
 * robot stands undisturbed, train.py --quiet-cost) */
#define PS_ENV_INFO_QUIET_S 9
/* [10] horizontal distance between the feet bodies (m), for the new
 * observation's state (added 2026-12-05: a cost on a stance wider than a
 * target, train.py --width-cost) */
#define PS_ENV_INFO_FEET_APART_M 10
/* [11] the left foot body's offset from the right one's along the floating
 * base's heading (m, > 0: left ahead) and [12] across it (m, > 0: left on
 * the left), for the new observation's state (added 2026-12-07: a cost on
 * a staggered stance, train.py --stagger-cost) */
#define PS_ENV_INFO_FEET_STAGGER_M 11
#define PS_ENV_INFO_FEET_LATERAL_M 12
/* [13 ..] the critic's privileged state (added 2026-12-07: train.py
 * --priv-critic), for the new observation's state, from the plant's truth
 * and the episode's draws, which the policy does not observe; horizontal
 * vectors in the frame of the floating base's heading: CoM relative to the
 * feet's midpoint (x, y; z above the resting height) m; the floating base's
 * linear velocity m/s (x, y, z); the left and the right foot's normal force
 * / weight; the push acting now / weight (x, y); seconds left of that push
 * (0: none); seconds until the next push starts (at most 1; 1: none to
 * come); 1 while the harness holds; friction scale; motor strength scale;
 * command latency ms; torso and pelvis mass scales; the torso's CoM offset m
 * (x, y, z) */
#define PS_ENV_INFO_PRIV 13
#define PS_ENV_PRIV      21

/** @return 0 | -errno; err holds the reason  @rt INIT */
int ps_env_create(const char *robot_path, const ps_env_cfg_t *cfg, ps_env_t **out, char *err,
                  size_t err_len);
uint32_t ps_env_obs_size(const ps_env_t *e);
uint32_t ps_env_act_size(const ps_env_t *e);
/** PS_ENV_INFO, for a caller that sizes the info buffer itself (Python checks it). */
uint32_t ps_env_info_size(void);

/** Reset every environment. @post obs: n_envs x obs_size  @return 0 | -errno */
int ps_env_reset(ps_env_t *e, float *obs);

/** One policy step of every environment with actions act (n_envs x
 *  act_size, the contract's scale applies: target = stance + scale a).
 *  @post obs (the next observation, after an automatic reset where an
 *  episode ended), rew, done (1: the episode ended with this step), expert
 *  (n_envs x act_size, the capture-point controller's actions for the new
 *  observation's state; may be NULL), info (n_envs x PS_ENV_INFO; may be
 *  NULL)  @return 0 | -errno */
int ps_env_step(ps_env_t *e, const float *act, float *obs, float *rew, uint8_t *done, float *expert,
                float *info);

/** Evaluation: environment env's episodes from its next reset on get one
 *  torso push of delta-v dv_m_s (m/s; force dv m / dur_s) over dur_s seconds
 *  at t_s, in direction dir_rad (world frame, 0 = +x), instead of random
 *  pushes; dur_s <= 0 goes back to random pushes.  @return 0 | -EINVAL */
int ps_env_set_push(ps_env_t *e, uint32_t env, float t_s, float dur_s, float dv_m_s, float dir_rad);

/** Curriculum: the largest push delta-v from the next episodes on. */
void ps_env_set_push_dv_max(ps_env_t *e, float dv_max_m_s);

void ps_env_destroy(ps_env_t *e);

#endif /* PS_ENV_H */
