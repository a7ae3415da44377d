#include "ps_env.h"

#include <errno.h>
#include <libgen.h>
#include <limits.h>
#include <math.h>
#include <pthread.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../drivers/ps_actuator.h"
#include "../../policy/ps_capture.h"
#include "../../policy/ps_estimate.h"
#include "../../policy/ps_obs.h"
#include "../../policy/ps_servo.h"
#include "../../rt/ps_config.h"
#include "../../rt/ps_config_sim.h"
#include "../../rt/ps_err.h"
#include "../../sim/ps_devices.h"
#include "../../sim/ps_plant.h"

/* The stage-1 contract's layout (policy/train/contract.py says the same);
 * is_obs_base_action appends PS_OBS_BASE_ACTION. */
static const ps_obs_field_t FIELDS[] = {
    PS_OBS_GRAVITY_BODY, PS_OBS_GYRO_BODY, PS_OBS_JOINT_POS, PS_OBS_JOINT_VEL,
    PS_OBS_PREV_ACTION,  PS_OBS_COM_POS,   PS_OBS_COM_VEL,   PS_OBS_CAPTURE_POINT,
    PS_OBS_BOS_MARGIN,   PS_OBS_FEET,      PS_OBS_CONTACT,
};
#define N_FIELDS  (sizeof(FIELDS) / sizeof(FIELDS[0]))
#define N_ACT     12u
#define ACT_SCALE 0.25f
#define ACT_CLIP  4.0f
static const char *const LEGS[N_ACT] = {
    "l_hip_yaw", "l_hip_roll", "l_hip_pitch", "l_knee", "l_ankle_pitch", "l_ankle_roll",
    "r_hip_yaw", "r_hip_roll", "r_hip_pitch", "r_knee", "r_ankle_pitch", "r_ankle_roll"};

#define MAX_PENDING 96u
#define MAX_THREADS 8u
#define REWARD_K    10.0 /* 1/m: e^{-k d} */

typedef struct {
    ps_can_frame_t f;
    int64_t due_ns;
    int joint;
    bool is_used;
} pending_t;

typedef struct {
    double t_s, dur_s, force_n[3], dv_m_s;
} push_t;

typedef struct {
    ps_plant_t *plant;
    ps_devices_actuator_t act[PS_MAX_JOINTS];
    ps_act_limits_t lim[PS_MAX_JOINTS]; /* randomised copies */
    ps_estimator_t est;
    ps_obs_t obs;
    ps_capture_t cap;
    ps_policy_t cap_pol;
    ps_meas_t meas;
    ps_targets_t tgt;
    uint64_t rng;
    int64_t latency_ns;
    /* this episode's other draws, kept for the critic's privileged state */
    double friction_scale, strength, torso_mass_scale, pelvis_mass_scale, torso_com_off_m[3];
    double imu_noise_scale, gyro_bias[3], accel_bias[3];
    int64_t t_ns;
    uint64_t tick;
    push_t push[2];
    int n_push;
    double release_s; /* the harness lets go at this episode time; 0: free from the start */
    /* is_ramp_start: the servo layer's mode, and the ramp's start and pose */
    ps_servo_mode_kind_t servo_kind;
    int64_t ramp_t0_ns;
    float ramp_from_q[PS_MAX_JOINTS];
    bool is_held;
    push_t fixed; /* ps_env_set_push: this push every episode instead */
    bool has_fixed;
    double z_rest, yaw0, prev_com[3], prev_ankle[2][3];
    bool prev_contact[2];
    pending_t pend[MAX_PENDING];
    double last_dv, r_bal, r_q, effort;
    int n_effort;
    int torso, pelvis, feet[2];
} env1_t;

struct ps_env;

/* A worker thread's argument: its environment and slice (one per thread, in
 * the environment: a second environment in the process has its own). */
typedef struct {
    struct ps_env *e;
    uint32_t idx;
} worker_arg_t;

struct ps_env {
    ps_env_cfg_t cfg;
    ps_robot_cfg_t robot;
    ps_sim_devices_cfg_t dev;
    char model_path[PATH_MAX];
    env1_t *envs;
    uint32_t n_obs;
    int leg_idx[N_ACT];
    float stance[PS_MAX_JOINTS];
    uint32_t ticks_per_step;
    pthread_t th[MAX_THREADS];
    worker_arg_t th_arg[MAX_THREADS];
    uint32_t n_th;
    pthread_barrier_t go, done_b;
    bool is_quit, is_reset;
    int rc;
    const float *act;
    float *obs, *rew, *expert, *info;
    uint8_t *done;
};

/* ---- random numbers: splitmix64 ------------------------------------------ */

static uint64_t next_u64(uint64_t *s)
{
    uint64_t z = (*s += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

static double uni(uint64_t *s, double lo, double hi)
{
    return lo + (hi - lo) * ((double)(next_u64(s) >> 11) * 0x1.0p-53);
}

static double gauss(uint64_t *s)
{
    const double u1 = uni(s, 1e-12, 1.0), u2 = uni(s, 0.0, 1.0);
    return sqrt(-2.0 * log(u1)) * cos(6.283185307179586 * u2);
}

/* ---- one environment --------------------------------------------------------- */

static int send_frame(env1_t *v, int j, const ps_can_frame_t *f, double q, double qd)
{
    ps_can_frame_t reply;
    const int rc = ps_devices_handle_frame(&v->act[j], f, q, qd, &reply);
    return rc < 0 && rc != -ENOENT ? rc : 0;
}

static void randomise(const ps_env_t *e, env1_t *v)
{
    const ps_robot_cfg_t *r = &e->robot;
    const bool dr = e->cfg.is_dr != 0;
    const double strength = dr ? uni(&v->rng, 0.85, 1.15) : 1.0;
    v->strength = strength;
    for (uint32_t j = 0; j < r->n_joints; j++) {
        ps_act_cfg_t a = r->act[j];
        v->lim[j] = r->servo[j].lim;
        v->lim[j].torque_max_nm = (float)(v->lim[j].torque_max_nm * strength);
        a.motor.peak_torque_nm = (float)(a.motor.peak_torque_nm * strength);
        a.motor.rated_torque_nm = (float)(a.motor.rated_torque_nm * strength);
        ps_devices_init_actuator(&v->act[j], &a, &v->lim[j], &e->dev);
    }
    const double off[3] = {dr ? uni(&v->rng, -0.02, 0.02) : 0.0,
                           dr ? uni(&v->rng, -0.02, 0.02) : 0.0,
                           dr ? uni(&v->rng, -0.02, 0.02) : 0.0};
    memcpy(v->torso_com_off_m, off, sizeof(off));
    /* one draw a statement, in this order: the random stream of every run */
    v->torso_mass_scale = dr ? uni(&v->rng, 0.9, 1.1) : 1.0;
    ps_plant_scale_body_mass(v->plant, v->torso, v->torso_mass_scale, off);
    v->pelvis_mass_scale = dr ? uni(&v->rng, 0.9, 1.1) : 1.0;
    ps_plant_scale_body_mass(v->plant, v->pelvis, v->pelvis_mass_scale, NULL);
    v->friction_scale = dr ? uni(&v->rng, 0.6, 1.4) : 1.0;
    ps_plant_scale_friction(v->plant, v->friction_scale);
    v->latency_ns = dr ? (int64_t)uni(&v->rng, 0.0, 2e6) : 0;
    v->imu_noise_scale = dr ? uni(&v->rng, 0.5, 2.0) : 1.0;
    for (int k = 0; k < 3; k++) {
        v->gyro_bias[k] = uni(&v->rng, -1.0, 1.0) * e->dev.gyro_bias_rad_s;
        v->accel_bias[k] = uni(&v->rng, -1.0, 1.0) * e->dev.accel_bias_m_s2;
    }
}

static void plan_pushes(const ps_env_t *e, env1_t *v)
{
    const double mass = e->robot.kin.mass_kg;
    if (v->has_fixed) {
        v->n_push = 1;
        v->push[0] = v->fixed;
        v->push[0].t_s += v->release_s;
        return;
    }
    v->n_push = uni(&v->rng, 0.0, 1.0) < 0.5 ? 2 : 1;
    for (int i = 0; i < v->n_push; i++) {
        push_t *p = &v->push[i];
        p->t_s = v->release_s + (i == 0 ? uni(&v->rng, 0.8, 2.0) : uni(&v->rng, 3.2, 4.2));
        p->dur_s = uni(&v->rng, 0.0, 1.0) < 0.5 ? 0.1 : 0.3;
        p->dv_m_s = uni(&v->rng, e->cfg.push_dv_min_m_s, e->cfg.push_dv_max_m_s);
        double dir = uni(&v->rng, 0.0, 6.283185307179586);
        /* a draw only when asked for, so that focus_p 0 keeps the stream */
        if (e->cfg.focus_p > 0.0f && uni(&v->rng, 0.0, 1.0) < e->cfg.focus_p)
            dir = e->cfg.focus_dir_rad + (dir - 3.141592653589793) * 0.25;
        const double f = p->dv_m_s * mass / p->dur_s;
        p->force_n[0] = f * cos(dir);
        p->force_n[1] = f * sin(dir);
        p->force_n[2] = 0.0;
    }
}

static void read_meas(const ps_env_t *e, env1_t *v)
{
    const ps_robot_cfg_t *r = &e->robot;
    double q[PS_MAX_JOINTS], qd[PS_MAX_JOINTS], gyro[3], accel[3];
    ps_plant_get_joints(v->plant, q, qd);
    ps_plant_get_imu(v->plant, gyro, accel);
    v->meas.n_joints = r->n_joints;
    for (uint32_t j = 0; j < r->n_joints; j++) {
        ps_act_meas_t *m = &v->meas.joints[j];
        m->q_rad = (float)q[j];
        m->qd_rad_s = (float)qd[j];
        m->tau_nm = (float)v->act[j].tau_nm;
        m->t_ns = v->t_ns;
    }
    const double s = v->imu_noise_scale;
    for (int k = 0; k < 3; k++) {
        v->meas.imu.gyro_body_rad_s[k] =
            (float)(gyro[k] + v->gyro_bias[k] + s * e->dev.gyro_noise_rad_s * gauss(&v->rng));
        v->meas.imu.accel_body_m_s2[k] =
            (float)(accel[k] + v->accel_bias[k] + s * e->dev.accel_noise_m_s2 * gauss(&v->rng));
    }
    v->meas.imu.t_ns = v->t_ns;
}

/* Commands of the joints due this tick, queued for delivery after the
 * episode's latency. */
static void servo_tick(const ps_env_t *e, env1_t *v)
{
    const ps_robot_cfg_t *r = &e->robot;
    float meas_q[PS_MAX_JOINTS];
    for (uint32_t j = 0; j < r->n_joints; j++)
        meas_q[j] = v->meas.joints[j].q_rad;
    ps_servo_mode_t mode = {.kind = v->servo_kind, .meas_q_rad = meas_q};
    if (v->servo_kind == PS_SERVO_RAMP) {
        const double alpha =
            (double)(v->t_ns - v->ramp_t0_ns) / ((double)r->control.ramp_s * (double)PS_NS_PER_S);
        mode.ramp_alpha = (float)fmin(fmax(alpha, 0.0), 1.0);
        mode.ramp_from_q_rad = v->ramp_from_q;
        if (alpha >= 1.0)
            v->servo_kind = PS_SERVO_TRACK;
    }
    for (uint32_t j = 0; j < r->n_joints; j++) {
        if (v->tick % r->act[j].rate_div != 0)
            continue;
        ps_act_cmd_t cmd;
        (void)ps_servo_command(&r->servo[j], &r->servo_common, &mode, j, &v->tgt, &cmd);
        ps_can_frame_t f[PS_ACT_MAX_FRAMES];
        const int n = ps_act_encode_command(&r->act[j], &cmd, f, PS_ACT_MAX_FRAMES);
        for (int k = 0; k < n; k++) {
            for (uint32_t p = 0; p < MAX_PENDING; p++) {
                if (!v->pend[p].is_used) {
                    v->pend[p] = (pending_t){f[k], v->t_ns + v->latency_ns, (int)j, true};
                    break;
                }
            }
        }
    }
}

static int physics_step(const ps_env_t *e, env1_t *v, int64_t now_ns, double dt)
{
    const ps_robot_cfg_t *r = &e->robot;
    double q[PS_MAX_JOINTS], qd[PS_MAX_JOINTS], tau[PS_MAX_JOINTS];
    ps_plant_get_joints(v->plant, q, qd);
    for (uint32_t p = 0; p < MAX_PENDING; p++) {
        pending_t *pd = &v->pend[p];
        if (pd->is_used && pd->due_ns <= now_ns) {
            pd->f.t_ns = now_ns;
            (void)send_frame(v, pd->joint, &pd->f, q[pd->joint], qd[pd->joint]);
            pd->is_used = false;
        }
    }
    double effort = 0.0;
    for (uint32_t j = 0; j < r->n_joints; j++) {
        tau[j] = ps_devices_step_actuator(&v->act[j], q[j], qd[j], now_ns, dt);
        const double t = tau[j] / v->lim[j].torque_max_nm;
        effort += t * t;
    }
    v->effort += effort / r->n_joints;
    v->n_effort++;
    ps_plant_set_torques(v->plant, tau);
    const double t_s = (double)now_ns * 1e-9;
    if (v->is_held && t_s >= v->release_s) {
        ps_plant_set_harness(v->plant, false);
        v->is_held = false;
    }
    double f[3] = {0, 0, 0};
    for (int i = 0; i < v->n_push; i++) {
        const push_t *p = &v->push[i];
        if (t_s >= p->t_s && t_s < p->t_s + p->dur_s) {
            memcpy(f, p->force_n, sizeof(f));
            v->last_dv = p->dv_m_s;
        }
    }
    ps_plant_set_external_force(v->plant, v->torso, f);
    return ps_plant_step(v->plant);
}

static double yaw_of(const double qt[4])
{
    return atan2(2.0 * (qt[0] * qt[3] + qt[1] * qt[2]),
                 1.0 - 2.0 * (qt[2] * qt[2] + qt[3] * qt[3]));
}

static double wrap(double a)
{
    return remainder(a, 6.283185307179586);
}

/* Reward of the last policy step from the plant's truth; *fell on a fall. */
static double reward(const ps_env_t *e, env1_t *v, bool *fell)
{
    ps_plant_truth_t tr;
    ps_plant_get_truth(v->plant, &tr);
    *fell = tr.is_fallen;
    const double dt = 1.0 / e->robot.control.policy_hz;
    double force[2], cop_foot[2][3], ankle[2][3], pos[3], quat[4], vel[3];
    (void)ps_plant_get_feet_contact(v->plant, force, cop_foot);
    ps_plant_get_root(v->plant, pos, quat, vel);
    const double yaw = yaw_of(quat);
    bool contact[2];
    double lo[2] = {1e9, 1e9}, hi[2] = {-1e9, -1e9}, centre[2] = {0, 0}, cop[2] = {0, 0}, fz = 0;
    int n_c = 0;
    for (int s = 0; s < 2; s++) {
        ps_plant_get_body_pos(v->plant, v->feet[s], ankle[s]);
        contact[s] = force[s] > 20.0;
        if (!contact[s])
            continue;
        const double sx = ankle[s][0] + e->robot.kin.foot_offset_x_m * cos(yaw);
        const double sy = ankle[s][1] + e->robot.kin.foot_offset_x_m * sin(yaw);
        const double hl = 0.5 * e->robot.kin.foot_length_m, hw = 0.5 * e->robot.kin.foot_width_m;
        lo[0] = fmin(lo[0], sx - hl), hi[0] = fmax(hi[0], sx + hl);
        lo[1] = fmin(lo[1], sy - hw), hi[1] = fmax(hi[1], sy + hw);
        centre[0] += sx, centre[1] += sy;
        cop[0] += force[s] * cop_foot[s][0], cop[1] += force[s] * cop_foot[s][1];
        fz += force[s];
        n_c++;
    }
    double com_vel[3];
    for (int k = 0; k < 3; k++)
        com_vel[k] = (tr.com_m[k] - v->prev_com[k]) / dt;
    double r_bal = 0.0;
    if (n_c > 0) {
        centre[0] /= n_c, centre[1] /= n_c;
        cop[0] /= fz, cop[1] /= fz;
        const double d_com =
            sqrt(pow(tr.com_m[0] - centre[0], 2) + pow(tr.com_m[1] - centre[1], 2) +
                 pow(tr.com_m[2] - v->z_rest, 2));
        const double w0 = sqrt(9.81 / fmax(tr.com_m[2], 0.2));
        double cp_t[2];
        for (int k = 0; k < 2; k++)
            cp_t[k] = fmin(fmax(tr.com_m[k] + com_vel[k] / w0, lo[k]), hi[k]);
        const double d_cop = hypot(cop[0] - cp_t[0], cop[1] - cp_t[1]);
        r_bal = 0.5 * (exp(-REWARD_K * d_com) + exp(-REWARD_K * d_cop));
    }
    double slide = 0.0;
    int n_s = 0;
    for (int s = 0; s < 2; s++) {
        if (contact[s] && v->prev_contact[s]) {
            slide +=
                hypot(ankle[s][0] - v->prev_ankle[s][0], ankle[s][1] - v->prev_ankle[s][1]) / dt;
            n_s++;
        }
        v->prev_contact[s] = contact[s];
        memcpy(v->prev_ankle[s], ankle[s], sizeof(ankle[s]));
    }
    const double r_foot = exp(-(n_s > 0 ? slide / n_s : 0.0) / 0.1);
    const double r_head = exp(-fabs(wrap(yaw - v->yaw0)) / 0.5);
    const double r_eff = exp(-(v->n_effort > 0 ? v->effort / v->n_effort : 0.0) / 0.1);
    v->effort = 0.0;
    v->n_effort = 0;
    memcpy(v->prev_com, tr.com_m, sizeof(v->prev_com));
    v->r_bal = r_bal;
    v->r_q = (r_foot + r_head + r_eff) / 3.0;
    return *fell ? -1.0 : 0.7 * r_bal + 0.3 * v->r_q;
}

static void targets_from_action(const ps_env_t *e, env1_t *v, const float *a, float *applied)
{
    const ps_robot_cfg_t *r = &e->robot;
    memset(&v->tgt, 0, sizeof(v->tgt));
    v->tgt.n_joints = r->n_joints;
    for (uint32_t j = 0; j < r->n_joints; j++)
        v->tgt.q_rad[j] = e->stance[j];
    for (uint32_t k = 0; k < N_ACT; k++) {
        float x = isfinite(a[k]) ? a[k] : 0.0f;
        x = x > ACT_CLIP ? ACT_CLIP : (x < -ACT_CLIP ? -ACT_CLIP : x);
        applied[k] = x;
        const int j = e->leg_idx[k];
        const ps_act_limits_t *l = &r->servo[j].lim;
        float q = e->stance[j] + ACT_SCALE * x;
        v->tgt.q_rad[j] =
            q < l->pos_min_rad ? l->pos_min_rad : (q > l->pos_max_rad ? l->pos_max_rad : q);
    }
}

static void expert_action(const ps_env_t *e, env1_t *v, float *out)
{
    ps_targets_t t;
    if (v->cap_pol.ops->step(v->cap_pol.ctx, &v->meas, &v->est.est, &t) != 0) {
        memset(out, 0, N_ACT * sizeof(float));
        return;
    }
    for (uint32_t k = 0; k < N_ACT; k++) {
        const int j = e->leg_idx[k];
        float a = (t.q_rad[j] - e->stance[j]) / ACT_SCALE;
        out[k] = a > ACT_CLIP ? ACT_CLIP : (a < -ACT_CLIP ? -ACT_CLIP : a);
    }
}

/* Observation of the current state (after the ticks). */
static void observe(const ps_env_t *e, env1_t *v, float *obs)
{
    float raw[PS_OBS_MAX];
    if (ps_obs_build(&v->obs, &v->meas, &v->est.est, obs, raw) < 0)
        memset(obs, 0, e->n_obs * sizeof(float)); /* no support: the episode is ending */
    for (uint32_t i = 0; i < e->n_obs; i++)
        if (!isfinite(obs[i]))
            obs[i] = 0.0f;
}

/* The observation and, when asked for, the expert's action. The expert runs
 * first when the observation holds its action (base_action), as in the
 * runtime, where the fallback steps before the MLP's build; it is stepped
 * only when needed, since it keeps state from step to step. */
static void observe_with_expert(const ps_env_t *e, env1_t *v, float *obs, float *expert)
{
    float base[N_ACT];
    const bool is_base = e->cfg.is_obs_base_action != 0;
    if (is_base || expert != NULL)
        expert_action(e, v, base);
    if (is_base)
        ps_obs_set_base_action(&v->obs, base);
    observe(e, v, obs);
    if (expert != NULL)
        memcpy(expert, base, sizeof(base));
}

/* Run servo ticks until the next policy step. */
static int run_ticks(const ps_env_t *e, env1_t *v)
{
    const double dt = ps_plant_timestep_s(v->plant);
    const int64_t tick_ns = PS_NS_PER_S / e->robot.control.servo_hz;
    const int n_sub = (int)lround((double)tick_ns * 1e-9 / dt);
    for (uint32_t k = 0; k < e->ticks_per_step; k++) {
        read_meas(e, v);
        ps_estimate_update(&v->est, &v->meas);
        servo_tick(e, v);
        for (int s = 0; s < n_sub; s++) {
            const int rc = physics_step(e, v, v->t_ns + (int64_t)(s * dt * 1e9), dt);
            if (rc != 0)
                return rc;
        }
        v->t_ns += tick_ns;
        v->tick++;
    }
    read_meas(e, v);
    ps_estimate_update(&v->est, &v->meas);
    return 0;
}

static int reset1(const ps_env_t *e, env1_t *v, float *obs, float *expert)
{
    const ps_robot_cfg_t *r = &e->robot;
    randomise(e, v); /* first: mj_setConst (mass changes) moves the model to qpos0 */
    v->release_s = 0.0;
    if (e->cfg.harness_p > 0.0f && uni(&v->rng, 0.0, 1.0) < e->cfg.harness_p)
        v->release_s = uni(&v->rng, 0.2, 2.0);
    v->is_held = v->release_s > 0.0;
    const bool is_ramped = v->is_held && e->cfg.is_ramp_start;
    if (is_ramped)
        v->release_s = (double)r->control.ramp_s + uni(&v->rng, 0.2, 1.0);
    v->servo_kind = is_ramped ? PS_SERVO_LIMP : PS_SERVO_TRACK;
    ps_plant_reset(v->plant, e->stance, v->is_held);
    plan_pushes(e, v);
    memset(v->pend, 0, sizeof(v->pend));
    v->t_ns = 0;
    v->tick = 0;
    v->last_dv = 0.0;
    v->effort = 0.0;
    v->n_effort = 0;
    for (uint32_t j = 0; j < r->n_joints; j++) {
        ps_can_frame_t f[PS_ACT_MAX_FRAMES];
        const int n = ps_act_encode_request(&r->act[j], PS_ACT_REQ_ENABLE, f, PS_ACT_MAX_FRAMES);
        for (int k = 0; k < n; k++)
            (void)send_frame(v, (int)j, &f[k], r->servo[j].stance_rad, 0.0);
    }
    int rc = ps_estimate_init(&v->est, &r->kin, r->joint_name, r->n_joints,
                              1.0f / (float)r->control.servo_hz);
    if (rc != 0)
        return rc;
    float zero[N_ACT] = {0};
    float applied[N_ACT];
    targets_from_action(e, v, zero, applied);
    /* Settle 0.2 s at the stance with a fast tilt filter (the runtime's robot
     * settles in its harness for seconds; the placement's contact impulse
     * would otherwise stay in the tilt estimate), then the usual filter. */
    v->est.filter_tau_s = 0.02f;
    for (int k = 0; k < 10 && rc == 0; k++)
        rc = run_ticks(e, v);
    v->est.filter_tau_s = PS_ESTIMATE_FILTER_TAU_S;
    if (is_ramped) { /* the runtime's RAMP: from the pose the limp drives let it sag to */
        for (uint32_t j = 0; j < r->n_joints; j++)
            v->ramp_from_q[j] = v->meas.joints[j].q_rad;
        v->ramp_t0_ns = v->t_ns;
        v->servo_kind = PS_SERVO_RAMP;
    }
    ps_obs_reset(&v->obs);
    ps_obs_set_action(&v->obs, applied);
    v->cap_pol.ops->reset(v->cap_pol.ctx);
    if (rc == 0)
        rc = run_ticks(e, v);
    ps_plant_truth_t tr;
    ps_plant_get_truth(v->plant, &tr);
    v->z_rest = tr.com_m[2];
    memcpy(v->prev_com, tr.com_m, sizeof(v->prev_com));
    double pos[3], quat[4], vel[3], force[2], cop[2][3];
    ps_plant_get_root(v->plant, pos, quat, vel);
    v->yaw0 = yaw_of(quat);
    (void)ps_plant_get_feet_contact(v->plant, force, cop);
    for (int s = 0; s < 2; s++) {
        ps_plant_get_body_pos(v->plant, v->feet[s], v->prev_ankle[s]);
        v->prev_contact[s] = force[s] > 20.0;
    }
    observe_with_expert(e, v, obs, expert);
    return rc;
}

/* Seconds since the harness let go or the last push ended, whichever came
 * last; -1 while held or pushed. */
static float quiet_s(const env1_t *v)
{
    const double t_s = (double)v->t_ns * 1e-9;
    if (v->is_held)
        return -1.0f;
    double since = v->release_s;
    for (int i = 0; i < v->n_push; i++) {
        const push_t *p = &v->push[i];
        if (t_s < p->t_s)
            continue;
        if (t_s < p->t_s + p->dur_s)
            return -1.0f;
        since = fmax(since, p->t_s + p->dur_s);
    }
    return (float)(t_s - since);
}

/* A world vector's horizontal part in the frame of heading yaw. */
static void to_heading(double yaw, double x, double y, float out[2])
{
    out[0] = (float)(cos(yaw) * x + sin(yaw) * y);
    out[1] = (float)(-sin(yaw) * x + cos(yaw) * y);
}

/* The stance, from the feet bodies read once: their horizontal distance
 * (width and stagger in one number) and the left one's place relative to
 * the right one's in the frame of the floating base's heading, along it
 * (the stagger, > 0 with the left foot ahead) and across it (the width,
 * > 0 with the left foot on the left), into info's three stance fields. */
_Static_assert(PS_ENV_INFO_FEET_STAGGER_M == PS_ENV_INFO_FEET_APART_M + 1 &&
                   PS_ENV_INFO_FEET_LATERAL_M == PS_ENV_INFO_FEET_APART_M + 2,
               "stance fills the three in one go");
static void stance(const env1_t *v, float out[3])
{
    double p[2][3], pos[3], quat[4], vel[3];
    for (int s = 0; s < 2; s++)
        ps_plant_get_body_pos(v->plant, v->feet[s], p[s]);
    ps_plant_get_root(v->plant, pos, quat, vel);
    const double dx = p[0][0] - p[1][0], dy = p[0][1] - p[1][1];
    out[0] = (float)hypot(dx, dy);
    to_heading(yaw_of(quat), dx, dy, out + 1);
}

/* The critic's privileged state (PS_ENV_INFO_PRIV, ps_env.h, in its order),
 * for the state of the observation just made. */
static void privileged(const ps_env_t *e, const env1_t *v, float out[PS_ENV_PRIV])
{
    ps_plant_truth_t tr;
    double feet[2][3], force[2], cop[2][3], pos[3], quat[4], vel[3];
    ps_plant_get_truth(v->plant, &tr);
    ps_plant_get_root(v->plant, pos, quat, vel);
    (void)ps_plant_get_feet_contact(v->plant, force, cop);
    for (int s = 0; s < 2; s++)
        ps_plant_get_body_pos(v->plant, v->feet[s], feet[s]);
    const double yaw = yaw_of(quat), weight_n = e->robot.kin.mass_kg * 9.81;
    const double t_s = (double)v->t_ns * 1e-9;
    double push_n[2] = {0, 0}, left_s = 0.0, next_s = 1.0;
    for (int i = 0; i < v->n_push; i++) {
        const push_t *p = &v->push[i];
        if (t_s >= p->t_s && t_s < p->t_s + p->dur_s) {
            push_n[0] = p->force_n[0] / weight_n, push_n[1] = p->force_n[1] / weight_n;
            left_s = p->t_s + p->dur_s - t_s;
        } else if (t_s < p->t_s) {
            next_s = fmin(next_s, p->t_s - t_s);
        }
    }
    to_heading(yaw, tr.com_m[0] - 0.5 * (feet[0][0] + feet[1][0]),
               tr.com_m[1] - 0.5 * (feet[0][1] + feet[1][1]), out);
    out[2] = (float)(tr.com_m[2] - v->z_rest);
    to_heading(yaw, vel[0], vel[1], out + 3);
    out[5] = (float)vel[2];
    out[6] = (float)(force[0] / weight_n);
    out[7] = (float)(force[1] / weight_n);
    to_heading(yaw, push_n[0], push_n[1], out + 8);
    out[10] = (float)left_s;
    out[11] = (float)next_s;
    out[12] = v->is_held ? 1.0f : 0.0f;
    out[13] = (float)v->friction_scale;
    out[14] = (float)v->strength;
    out[15] = (float)((double)v->latency_ns * 1e-6);
    out[16] = (float)v->torso_mass_scale;
    out[17] = (float)v->pelvis_mass_scale;
    for (int k = 0; k < 3; k++)
        out[18 + k] = (float)v->torso_com_off_m[k];
}

static int step1(const ps_env_t *e, env1_t *v, const float *a, float *obs, float *rew,
                 uint8_t *done, float *expert, float *info)
{
    float applied[N_ACT];
    targets_from_action(e, v, a, applied);
    ps_obs_set_action(&v->obs, applied);
    const int rc = run_ticks(e, v);
    bool fell = false;
    double r = reward(e, v, &fell);
    if (rc != 0) { /* the physics broke (a huge push): count it as a fall */
        fell = true;
        r = -1.0;
    }
    const double t_s = (double)v->t_ns * 1e-9;
    const bool is_end = fell || t_s >= e->cfg.episode_s + v->release_s;
    *rew = (float)r;
    *done = is_end ? 1u : 0u;
    if (info != NULL) {
        ps_plant_truth_t tr;
        ps_plant_get_truth(v->plant, &tr);
        int n_done = 0;
        for (int i = 0; i < v->n_push; i++)
            n_done += t_s >= v->push[i].t_s;
        const float vals[PS_ENV_INFO] = {fell ? 1.0f : 0.0f, is_end ? 1.0f : 0.0f, (float)t_s,
                                         (float)v->last_dv,  (float)v->r_bal,      (float)v->r_q,
                                         (float)tr.com_m[2], (float)n_done};
        memcpy(info, vals, sizeof(vals));
    }
    int rc_next = 0;
    if (is_end)
        rc_next = reset1(e, v, obs, expert);
    else
        observe_with_expert(e, v, obs, expert);
    if (info != NULL) {
        info[PS_ENV_INFO_EXPERT_SWING] =
            expert != NULL && v->cap.phase == PS_CAPTURE_SWING ? 1.0f : 0.0f;
        info[PS_ENV_INFO_QUIET_S] = quiet_s(v);
        stance(v, info + PS_ENV_INFO_FEET_APART_M);
        privileged(e, v, info + PS_ENV_INFO_PRIV);
    }
    return rc_next;
}

/* ---- threads ------------------------------------------------------------------- */

static void run_slice(ps_env_t *e, uint32_t w)
{
    const uint32_t n = e->cfg.n_envs, nt = e->n_th;
    const uint32_t lo = n * w / nt, hi = n * (w + 1) / nt;
    const uint32_t no = e->n_obs;
    for (uint32_t i = lo; i < hi; i++) {
        int rc;
        float *ex = e->expert != NULL ? e->expert + (size_t)i * N_ACT : NULL;
        if (e->is_reset)
            rc = reset1(e, &e->envs[i], e->obs + (size_t)i * no, ex);
        else
            rc = step1(e, &e->envs[i], e->act + (size_t)i * N_ACT, e->obs + (size_t)i * no,
                       e->rew + i, e->done + i, ex,
                       e->info != NULL ? e->info + (size_t)i * PS_ENV_INFO : NULL);
        if (rc != 0)
            e->rc = rc; /* benign race: any error wins */
    }
}

static void *worker(void *p)
{
    worker_arg_t *a = p;
    for (;;) {
        pthread_barrier_wait(&a->e->go);
        if (a->e->is_quit)
            break;
        run_slice(a->e, a->idx);
        pthread_barrier_wait(&a->e->done_b);
    }
    return NULL;
}

static int run_all(ps_env_t *e)
{
    e->rc = 0;
    pthread_barrier_wait(&e->go);
    run_slice(e, 0); /* the calling thread takes slice 0 */
    pthread_barrier_wait(&e->done_b);
    return e->rc;
}

/* ---- API ------------------------------------------------------------------------ */

uint32_t ps_env_obs_size(const ps_env_t *e)
{
    return e->n_obs;
}

uint32_t ps_env_act_size(const ps_env_t *e)
{
    (void)e;
    return N_ACT;
}

uint32_t ps_env_info_size(void)
{
    return PS_ENV_INFO;
}

int ps_env_reset(ps_env_t *e, float *obs)
{
    e->is_reset = true;
    e->obs = obs;
    e->expert = NULL;
    return run_all(e);
}

int ps_env_step(ps_env_t *e, const float *act, float *obs, float *rew, uint8_t *done, float *expert,
                float *info)
{
    e->is_reset = false;
    e->act = act;
    e->obs = obs;
    e->rew = rew;
    e->done = done;
    e->expert = expert;
    e->info = info;
    return run_all(e);
}

/* The capture-point controller's tunables before its 2026-12-03 change. */
static void slow_expert(ps_capture_params_t *p)
{
    p->swing_s = 0.3f;
    p->settle_s = 0.3f;
    p->lift_m = 0.05f;
    p->lookahead_s = 0.1f;
    p->swing_follows_trunk = false;
}

static int init1(ps_env_t *e, env1_t *v, uint32_t i, char *err, size_t len)
{
    const ps_robot_cfg_t *r = &e->robot;
    v->rng = e->cfg.seed * 0x9E3779B97F4A7C15ull + i + 1u;
    const ps_plant_cfg_t pc = {.model_path = e->model_path,
                               .n_joints = r->n_joints,
                               .joint_name = r->joint_name,
                               .stance_rad = e->stance};
    int rc = ps_plant_create(&pc, &v->plant, err, len);
    if (rc != 0)
        return rc;
    v->torso = ps_plant_find_body(v->plant, "torso");
    v->pelvis = ps_plant_find_body(v->plant, "pelvis");
    v->feet[0] = ps_plant_find_body(v->plant, "l_foot");
    v->feet[1] = ps_plant_find_body(v->plant, "r_foot");
    if (v->torso < 0 || v->pelvis < 0 || v->feet[0] < 0 || v->feet[1] < 0) {
        snprintf(err, len, "%s: needs bodies torso, pelvis, l_foot, r_foot", e->model_path);
        return -PS_ERR_CONFIG;
    }
    ps_obs_cfg_t oc;
    memset(&oc, 0, sizeof(oc));
    oc.n_fields = N_FIELDS;
    memcpy(oc.fields, FIELDS, sizeof(FIELDS));
    if (e->cfg.is_obs_base_action)
        oc.fields[oc.n_fields++] = PS_OBS_BASE_ACTION;
    oc.n_joints = r->n_joints;
    oc.n_act = N_ACT;
    for (uint32_t j = 0; j < r->n_joints; j++) {
        oc.joint_idx[j] = j;
        oc.joint_offset_rad[j] = e->stance[j];
    }
    for (uint32_t k = 0; k < PS_OBS_MAX; k++)
        oc.std[k] = 1.0f;
    oc.clip = 1e9f;
    oc.kin = r->kin;
    for (int s = 0; s < 2; s++)
        for (int j = 0; j < PS_LEG_N_JOINTS; j++)
            oc.leg_idx[s][j] = e->leg_idx[6 * s + j];
    oc.dt_s = 1.0f / (float)r->control.policy_hz;
    rc = ps_obs_init(&v->obs, &oc);
    if (rc == 0)
        rc = ps_capture_init(&v->cap, r->n_joints, r->joint_name, r->servo, &r->kin, oc.dt_s);
    if (rc != 0) {
        snprintf(err, len, "observation or capture controller: %s", ps_strerror(rc));
        return rc;
    }
    if (e->cfg.is_expert_slow)
        slow_expert(&v->cap.p);
    ps_capture_as_policy(&v->cap, &v->cap_pol);
    e->n_obs = v->obs.n_obs;
    return 0;
}

int ps_env_create(const char *robot_path, const ps_env_cfg_t *cfg, ps_env_t **out, char *err,
                  size_t err_len)
{
    if (robot_path == NULL || cfg == NULL || out == NULL || cfg->n_envs == 0 ||
        cfg->n_threads == 0 || cfg->n_threads > MAX_THREADS || !(cfg->push_dv_min_m_s >= 0.0) ||
        !(cfg->push_dv_min_m_s <= cfg->push_dv_max_m_s) || !(cfg->harness_p >= 0.0f) ||
        !(cfg->harness_p <= 1.0f) || !(cfg->focus_p >= 0.0f) || !(cfg->focus_p <= 1.0f) ||
        !isfinite(cfg->focus_dir_rad))
        return -EINVAL;
    ps_env_t *e = calloc(1, sizeof(*e));
    if (e == NULL)
        return -ENOMEM;
    e->cfg = *cfg;
    int rc = ps_config_load_robot_sim(robot_path, &e->robot, &e->dev, err, err_len);
    if (rc == 0) {
        char dir[PATH_MAX];
        snprintf(dir, sizeof(dir), "%s", robot_path);
        snprintf(e->model_path, sizeof(e->model_path), "%s/%s", dirname(dir), e->robot.model);
        for (uint32_t j = 0; j < e->robot.n_joints; j++)
            e->stance[j] = e->robot.servo[j].stance_rad;
        for (uint32_t k = 0; k < N_ACT && rc == 0; k++) {
            e->leg_idx[k] = ps_config_find_joint(&e->robot, LEGS[k]);
            if (e->leg_idx[k] < 0) {
                snprintf(err, err_len, "%s: no joint %s", robot_path, LEGS[k]);
                rc = -PS_ERR_CONFIG;
            }
        }
        e->ticks_per_step = e->robot.control.servo_hz / e->robot.control.policy_hz;
    }
    if (rc == 0) {
        e->envs = calloc(cfg->n_envs, sizeof(env1_t));
        rc = e->envs == NULL ? -ENOMEM : 0;
    }
    for (uint32_t i = 0; rc == 0 && i < cfg->n_envs; i++)
        rc = init1(e, &e->envs[i], i, err, err_len);
    if (rc == 0) {
        e->n_th = cfg->n_threads < cfg->n_envs ? cfg->n_threads : cfg->n_envs;
        pthread_barrier_init(&e->go, NULL, e->n_th);
        pthread_barrier_init(&e->done_b, NULL, e->n_th);
        for (uint32_t w = 1; w < e->n_th; w++) {
            e->th_arg[w] = (worker_arg_t){e, w};
            pthread_create(&e->th[w], NULL, worker, &e->th_arg[w]);
        }
        *out = e;
        return 0;
    }
    if (e->envs != NULL)
        for (uint32_t i = 0; i < cfg->n_envs; i++)
            ps_plant_destroy(e->envs[i].plant);
    free(e->envs);
    free(e);
    return rc;
}

int ps_env_set_push(ps_env_t *e, uint32_t env, float t_s, float dur_s, float dv_m_s, float dir_rad)
{
    if (e == NULL || env >= e->cfg.n_envs || !isfinite(t_s) || !isfinite(dur_s) ||
        !isfinite(dv_m_s) || !isfinite(dir_rad))
        return -EINVAL;
    env1_t *v = &e->envs[env];
    if (dur_s <= 0.0f) {
        v->has_fixed = false;
        return 0;
    }
    const double f = dv_m_s * e->robot.kin.mass_kg / dur_s;
    v->fixed = (push_t){.t_s = t_s,
                        .dur_s = dur_s,
                        .dv_m_s = dv_m_s,
                        .force_n = {f * cos(dir_rad), f * sin(dir_rad), 0.0}};
    v->has_fixed = true;
    return 0;
}

void ps_env_set_push_dv_max(ps_env_t *e, float dv_max_m_s)
{
    if (e != NULL && dv_max_m_s > 0.05f)
        e->cfg.push_dv_max_m_s = dv_max_m_s;
}

void ps_env_destroy(ps_env_t *e)
{
    if (e == NULL)
        return;
    e->is_quit = true;
    pthread_barrier_wait(&e->go);
    for (uint32_t w = 1; w < e->n_th; w++)
        pthread_join(e->th[w], NULL);
    pthread_barrier_destroy(&e->go);
    pthread_barrier_destroy(&e->done_b);
    for (uint32_t i = 0; i < e->cfg.n_envs; i++)
        ps_plant_destroy(e->envs[i].plant);
    free(e->envs);
    free(e);
}
