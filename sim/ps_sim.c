#include "ps_sim.h"

#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <mujoco/mujoco.h>

#include "../rt/ps_err.h"
#include "../rt/ps_mailbox.h"
#include "ps_can_sim.h"
#include "ps_gpio_sim.h"
#include "ps_plant.h"

/* Frames per bus queue direction: a 12-joint robot puts ~26 frames on a bus
 * per period; 256 leaves room for a loop that falls several periods behind. */
#define BUS_QUEUE_LEN 256u
/* Frames taken from a device end per recv_batch call. */
#define RX_BATCH 32u

struct ps_sim {
    ps_sim_board_t board;
    ps_sim_robot_t robot;
    ps_scenario_cfg_t scenario;
    ps_sim_hooks_t hooks;
    int64_t frame_ns; /* pictures: ps_sim_set_frame_hook */
    void (*frame_fn)(void *ctx, const struct ps_plant *p);
    void *frame_ctx;
    bool is_lockstep;
    int64_t period_ns;
    int64_t dt_ns; /**< physics timestep */
    double dt_s;

    ps_plant_t *plant;
    ps_can_sim_bus_t *bus[PS_MAX_BUSES];
    ps_can_port_t dev_port[PS_MAX_BUSES];
    ps_gpio_sim_t gpio;
    ps_clock_t clock;       /**< lockstep clock; unused in real time */
    _Atomic int64_t now_ns; /**< lockstep simulated time */

    ps_devices_actuator_t act[PS_MAX_JOINTS];
    ps_devices_imu_t imu;
    double q_rad[PS_MAX_JOINTS];
    double qd_rad_s[PS_MAX_JOINTS];
    double tau_nm[PS_MAX_JOINTS];

    /* scenario, precomputed at create */
    int push_slot[PS_MAX_PUSHES];      /**< index into push_body_idx */
    int64_t push_t0_ns[PS_MAX_PUSHES]; /**< relative to start */
    int64_t push_t1_ns[PS_MAX_PUSHES];
    int n_push_bodies;
    int push_body_idx[PS_MAX_PUSHES]; /**< plant body index per slot */
    double push_applied_n[PS_MAX_PUSHES][3];
    int64_t event_t_ns[PS_MAX_EVENTS];
    int event_joint_idx[PS_MAX_EVENTS]; /**< DROP_REPLIES target */
    bool is_event_done[PS_MAX_EVENTS];
    atomic_uint requests;

    /* stepping state: lockstep on the loop thread, real time on the plant thread */
    bool is_started;
    int64_t start_ns;
    int64_t plant_rel_ns; /**< physics time since start */
    uint64_t n_steps;
    uint64_t n_unrouted;
    uint64_t n_dev_tx_dropped;
    uint64_t n_overruns;
    int64_t max_lag_ns; /**< real time: most simulated time lagged the wall clock */
    int64_t slow_ns;    /**< test knob PUSHSTEP_SIM_SLOW_NS: extra sleep per period */
    int plant_err;
    const char *plant_err_reason;
    double plant_err_t_s;
    double min_com_active_m; /**< INFINITY until the controller is active */
    double tau_abs_sum_nm;   /**< sum of |torque| applied at the last physics step */

    /* real-time plant thread */
    pthread_t thread;
    bool has_thread;
    atomic_bool is_running;

    ps_ring_t crowd_ring;
    ps_sim_crowd_sample_t crowd_storage[PS_SIM_CROWD_RING_SLOTS];
    double crowd_density_max;

    pthread_mutex_t truth_mu;
    double first_fall_t_s; /**< plant time of the first fall, -1: none yet */
    double heading_dev_max_rad, foot_slide_m, kinetic_max_j; /**< motion metrics */
    double foot_prev_m[2][3];
    bool foot_prev_loaded[2];
    int foot_body[2];
    bool has_mutex;
    ps_sim_truth_t truth;

    /* the scene for a rendering camera (ps_sim_read_scene) */
    ps_mailbox_t scene_mb;
    uint8_t *scene_slots; /**< PS_MAILBOX_SLOTS x (scene_hdr_t + nq doubles) */
    uint32_t scene_nq;
    uint64_t scene_seq;
    atomic_uint truth_seq;   /**< odd while truth_rt is being written */
    ps_sim_truth_t truth_rt; /**< lock-free copy for ps_sim_read_truth_rt */
};

/* A scene slot: this header, then nq doubles of qpos. */
typedef struct {
    int64_t t_ns;
    uint64_t seq;
} scene_hdr_t;

static int init_scene(ps_sim_t *s, char *err, size_t err_len);

static void publish_scene(ps_sim_t *s)
{
    if (s->scene_slots == NULL)
        return;
    uint8_t *slot = ps_mailbox_write_slot(&s->scene_mb);
    const scene_hdr_t h = {.t_ns = s->start_ns + s->plant_rel_ns, .seq = s->scene_seq++};
    memcpy(slot, &h, sizeof(h));
    ps_plant_get_qpos(s->plant, (double *)(void *)(slot + sizeof(h)));
    ps_mailbox_publish(&s->scene_mb);
}

/* ---- one physics step ------------------------------------------------ */

static void send_dev(ps_sim_t *s, unsigned bus_idx, const ps_can_frame_t *f, size_t n)
{
    if (n == 0)
        return;
    const int rc = ps_can_send_batch(&s->dev_port[bus_idx], f, n);
    const size_t sent = rc > 0 ? (size_t)rc : 0u;
    s->n_dev_tx_dropped += n - sent;
}

static void run_scenario(ps_sim_t *s, int64_t rel_ns)
{
    const ps_scenario_cfg_t *sc = &s->scenario;
    for (uint32_t e = 0; e < sc->n_events; e++) {
        if (s->is_event_done[e] || rel_ns < s->event_t_ns[e])
            continue;
        s->is_event_done[e] = true;
        const ps_event_cfg_t *ev = &sc->events[e];
        switch (ev->kind) {
        case PS_EVENT_START:
            atomic_fetch_or(&s->requests, (unsigned)PS_SIM_REQ_START);
            break;
        case PS_EVENT_STOP:
            atomic_fetch_or(&s->requests, (unsigned)PS_SIM_REQ_STOP);
            break;
        case PS_EVENT_RESET:
            atomic_fetch_or(&s->requests, (unsigned)PS_SIM_REQ_RESET);
            break;
        case PS_EVENT_ESTOP_PRESS:
            ps_gpio_sim_set_estop(&s->gpio, true);
            break;
        case PS_EVENT_ESTOP_RELEASE:
            ps_gpio_sim_set_estop(&s->gpio, false);
            break;
        case PS_EVENT_HARNESS_RELEASE:
            ps_plant_set_harness(s->plant, false);
            break;
        case PS_EVENT_DROP_REPLIES:
            /* Device time is start-based in both modes (simulated or monotonic). */
            s->act[s->event_joint_idx[e]].drop_replies_until_ns =
                s->start_ns + s->event_t_ns[e] + ps_s_to_ns((double)ev->duration_s);
            break;
        case PS_EVENT_DRIVE_FAULT: {
            ps_devices_actuator_t *a = &s->act[s->event_joint_idx[e]];
            a->fault_bits |= PS_ACT_FAULT_OVERVOLTAGE;
            a->is_motor_mode = false; /* a faulted drive gives no torque */
            break;
        }
        case PS_EVENT_RECORD_BUTTON: /* a press shorter than a tick: latched until read */
            ps_gpio_sim_set_button(&s->gpio, true);
            ps_gpio_sim_set_button(&s->gpio, false);
            break;
        case PS_EVENT_COUNT:
        default:
            break;
        }
    }

    /* Pushes: the sum of the active pushes per body, applied on change only. */
    double f[PS_MAX_PUSHES][3];
    memset(f, 0, sizeof f);
    for (uint32_t p = 0; p < sc->n_pushes; p++) {
        if (rel_ns >= s->push_t0_ns[p] && rel_ns < s->push_t1_ns[p]) {
            double k = 1.0;
            if (sc->pushes[p].profile == PS_CROWD_PROFILE_HALF_SINE)
                k = sin(M_PI * (double)(rel_ns - s->push_t0_ns[p]) /
                        (double)(s->push_t1_ns[p] - s->push_t0_ns[p]));
            for (unsigned a = 0; a < 3; a++)
                f[s->push_slot[p]][a] += k * (double)sc->pushes[p].force_n[a];
        }
    }
    for (int b = 0; b < s->n_push_bodies; b++) {
        if (memcmp(f[b], s->push_applied_n[b], sizeof f[b]) != 0) {
            ps_plant_set_external_force(s->plant, s->push_body_idx[b], f[b]);
            memcpy(s->push_applied_n[b], f[b], sizeof f[b]);
        }
    }
}

static void route_frames(ps_sim_t *s)
{
    for (uint32_t b = 0; b < s->board.n_buses; b++) {
        ps_can_frame_t rx[RX_BATCH];
        int n;
        while ((n = ps_can_recv_batch(&s->dev_port[b], rx, RX_BATCH)) > 0) {
            ps_can_frame_t tx[RX_BATCH];
            size_t n_tx = 0;
            for (int i = 0; i < n; i++) {
                const int rc = ps_devices_route_frame(s->act, s->robot.n_joints, b, &rx[i],
                                                      s->q_rad, s->qd_rad_s, &tx[n_tx], NULL);
                if (rc == -ENOENT)
                    s->n_unrouted++;
                else if (rc == 1)
                    n_tx++;
            }
            send_dev(s, b, tx, n_tx);
            if ((unsigned)n < RX_BATCH)
                break;
        }
    }
}

/* One physics step starting at device time t_dev_ns, physics time rel_ns after
 * start: scenario, frames in and out, IMU on the period grid, torques, step. */
static void substep(ps_sim_t *s, int64_t t_dev_ns, int64_t rel_ns)
{
    run_scenario(s, rel_ns);
    ps_plant_get_joints(s->plant, s->q_rad, s->qd_rad_s);
    route_frames(s);

    if (rel_ns % s->period_ns == 0) {
        double gyro[3], accel[3];
        ps_plant_get_imu(s->plant, gyro, accel);
        ps_can_frame_t f[PS_IMU_MAX_FRAMES];
        const uint64_t tick = (uint64_t)(rel_ns / s->period_ns);
        const int n = ps_devices_tick_imu(&s->imu, tick, gyro, accel, t_dev_ns, f);
        if (n > 0)
            send_dev(s, s->robot.imu.bus_idx, f, (size_t)n);
    }

    /* The drives' power stage is fed through the watchdog relay: without the
     * loop's heartbeat it gives no torque (the drives' logic keeps running). */
    const bool is_power_on = ps_gpio_sim_update_relay(&s->gpio, t_dev_ns);
    s->tau_abs_sum_nm = 0.0;
    for (uint32_t j = 0; j < s->robot.n_joints; j++) {
        const double tau =
            ps_devices_step_actuator(&s->act[j], s->q_rad[j], s->qd_rad_s[j], t_dev_ns, s->dt_s);
        ps_can_frame_t report;
        if (ps_devices_take_fault_report(&s->act[j], t_dev_ns, &report) == 1)
            send_dev(s, s->robot.act[j].bus_idx, &report, 1);
        s->tau_nm[j] = is_power_on ? tau : 0.0;
        s->tau_abs_sum_nm += fabs(s->tau_nm[j]);
    }
    if (s->plant_err == 0) {
        ps_plant_set_torques(s->plant, s->tau_nm);
        const int rc = ps_plant_step(s->plant);
        if (rc < 0) {
            /* NaN, instability, dropped contacts: freeze physics, keep the devices */
            s->plant_err = rc;
            s->plant_err_reason = ps_plant_error_reason(s->plant);
            s->plant_err_t_s = ps_ns_to_s(rel_ns);
        } else
            s->n_steps++;
    }
    s->plant_rel_ns += s->dt_ns;
    if (s->frame_fn != NULL && s->plant_rel_ns % s->frame_ns == 0)
        s->frame_fn(s->frame_ctx, s->plant);
}

int ps_sim_set_frame_hook(ps_sim_t *s, int64_t frame_ns,
                          void (*fn)(void *ctx, const struct ps_plant *p), void *ctx)
{
    if (fn != NULL && (frame_ns <= 0 || frame_ns % s->dt_ns != 0))
        return -EINVAL;
    s->frame_ns = frame_ns;
    s->frame_fn = fn;
    s->frame_ctx = ctx;
    return 0;
}

/* Heading, foot sliding and kinetic energy over the run (the push-recovery
 * benchmark's quality figures). */
static void update_motion(ps_sim_t *s)
{
    /* while the controller is in charge (as the lowest CoM): a robot
     * damped to the floor after the run does not count */
    if (!s->is_started || s->hooks.is_controller_active == NULL ||
        !s->hooks.is_controller_active(s->hooks.ctx) || s->first_fall_t_s >= 0) {
        s->foot_prev_loaded[0] = s->foot_prev_loaded[1] = false;
        return;
    }
    double pos[3], quat[4], vel[3], force[2], cop[2][3];
    ps_plant_get_root(s->plant, pos, quat, vel);
    const double yaw = atan2(2.0 * (quat[0] * quat[3] + quat[1] * quat[2]),
                             1.0 - 2.0 * (quat[2] * quat[2] + quat[3] * quat[3]));
    s->heading_dev_max_rad = fmax(s->heading_dev_max_rad, fabs(yaw));
    s->kinetic_max_j = fmax(s->kinetic_max_j, ps_plant_kinetic_energy_j(s->plant));
    if (s->foot_body[0] < 0 || ps_plant_get_feet_contact(s->plant, force, cop) != 0)
        return;
    for (int f = 0; f < 2; f++) {
        double p[3];
        ps_plant_get_body_pos(s->plant, s->foot_body[f], p);
        const bool is_loaded = force[f] > 20.0;
        if (is_loaded && s->foot_prev_loaded[f])
            s->foot_slide_m += hypot(p[0] - s->foot_prev_m[f][0], p[1] - s->foot_prev_m[f][1]);
        s->foot_prev_loaded[f] = is_loaded;
        memcpy(s->foot_prev_m[f], p, sizeof(p));
    }
}

static void update_truth(ps_sim_t *s)
{
    update_motion(s);
    ps_plant_truth_t pt;
    ps_plant_get_truth(s->plant, &pt);
    ps_sim_truth_t t;
    memset(&t, 0, sizeof t);
    t.t_s = pt.t_s;
    memcpy(t.com_m, pt.com_m, sizeof t.com_m);
    memcpy(t.pelvis_m, pt.pelvis_m, sizeof t.pelvis_m);
    t.head_height_m = pt.head_height_m;
    t.is_fallen = pt.is_fallen;
    t.n_steps = s->n_steps;
    t.max_temp_c = s->robot.devices.ambient_c;
    for (uint32_t j = 0; j < s->robot.n_joints; j++) {
        const ps_devices_actuator_t *a = &s->act[j];
        t.n_cmd_frames += a->n_cmd_frames;
        t.n_cmd_out_of_limits += a->n_cmd_out_of_limits;
        t.n_bad_frames += a->n_bad_frames;
        t.n_cmd_ignored += a->n_cmd_ignored;
        t.n_reply_frames += a->n_replies;
        if (a->temp_c > t.max_temp_c)
            t.max_temp_c = a->temp_c;
    }
    t.n_bad_frames += s->n_unrouted;
    t.n_unrouted_frames = s->n_unrouted;
    t.n_imu_samples = s->imu.n_samples;
    t.n_dev_tx_dropped = s->n_dev_tx_dropped;
    t.n_plant_overruns = s->n_overruns;
    t.max_plant_lag_ns = s->max_lag_ns;
    if (s->is_started && s->hooks.is_controller_active != NULL &&
        s->hooks.is_controller_active(s->hooks.ctx) && pt.com_m[2] < s->min_com_active_m)
        s->min_com_active_m = pt.com_m[2];
    t.min_com_height_active_m = isfinite(s->min_com_active_m) ? s->min_com_active_m : -1.0;
    if (pt.is_fallen && s->first_fall_t_s < 0)
        s->first_fall_t_s = pt.t_s;
    t.first_fall_t_s = s->first_fall_t_s;
    t.heading_dev_max_rad = s->heading_dev_max_rad;
    t.foot_slide_m = s->foot_slide_m;
    t.kinetic_energy_max_j = s->kinetic_max_j;
    t.plant_err = s->plant_err;
    t.is_drive_power_on = ps_gpio_sim_is_power_on(&s->gpio);
    t.n_power_cuts = s->gpio.n_power_cuts;
    t.tau_abs_sum_nm = s->tau_abs_sum_nm;
    t.plant_err_reason = s->plant_err_reason;
    t.plant_err_t_s = s->plant_err_t_s;
    const ps_crowd_t *crowd = ps_plant_crowd(s->plant);
    if (crowd != NULL) {
        t.has_crowd = true;
        ps_crowd_get_stats(crowd, &t.crowd);
        if (t.crowd.local_density_m2 > s->crowd_density_max)
            s->crowd_density_max = t.crowd.local_density_m2;
        t.crowd_local_density_max_m2 = s->crowd_density_max;
        if (s->is_started) {
            ps_sim_crowd_sample_t cs = {
                .t_s = pt.t_s,
                .n_fallen = t.crowd.n_fallen,
                .n_stepping = t.crowd.n_stepping,
                .local_density_m2 = (float)t.crowd.local_density_m2,
                .robot_force_n = (float)t.crowd.robot_force_n,
                .transmitted_impulse_ns = (float)t.crowd.transmitted_impulse_ns,
                .penetration_m = (float)t.crowd.penetration_m,
                .n_parts = t.crowd.n_parts,
            };
            for (uint32_t k = 0; k < t.crowd.n_parts && k < PS_CROWD_MAX_PARTS; k++)
                cs.part_force_n[k] = (float)t.crowd.part_force_n[k];
            (void)ps_ring_push(&s->crowd_ring, &cs); /* full: dropped and counted */
        }
    }
    for (int b = 0; b < s->n_push_bodies; b++)
        for (int k = 0; k < 3; k++)
            t.push_force_n[k] += s->push_applied_n[b][k];
    /* Sequence-counted copy for readers that may not lock (one writer). */
    const unsigned seq = atomic_load_explicit(&s->truth_seq, memory_order_relaxed);
    atomic_store_explicit(&s->truth_seq, seq + 1u, memory_order_relaxed);
    atomic_thread_fence(memory_order_release);
    s->truth_rt = t;
    atomic_store_explicit(&s->truth_seq, seq + 2u, memory_order_release);
    /* Held only for the copy, so the plant thread is never delayed for long. */
    pthread_mutex_lock(&s->truth_mu);
    s->truth = t;
    pthread_mutex_unlock(&s->truth_mu);
    publish_scene(s);
}

/* ---- lockstep clock ---------------------------------------------------- */

static int64_t sim_now_ns(void *ctx)
{
    ps_sim_t *s = ctx;
    return atomic_load_explicit(&s->now_ns, memory_order_relaxed);
}

static int sim_sleep_until_ns(void *ctx, int64_t deadline_ns)
{
    ps_sim_t *s = ctx;
    if (s->is_started) {
        /* The plant's work runs on the loop thread here but is not the loop's:
         * keep it out of the allocation and page-fault counts. */
        if (s->hooks.pause_guard != NULL)
            s->hooks.pause_guard(s->hooks.ctx);
        bool has_stepped = false;
        while (s->start_ns + s->plant_rel_ns < deadline_ns) {
            const int64_t t = s->start_ns + s->plant_rel_ns;
            atomic_store_explicit(&s->now_ns, t, memory_order_relaxed);
            substep(s, t, s->plant_rel_ns);
            has_stepped = true;
        }
        if (has_stepped)
            update_truth(s);
        if (s->hooks.resume_guard != NULL)
            s->hooks.resume_guard(s->hooks.ctx);
    }
    if (deadline_ns > atomic_load_explicit(&s->now_ns, memory_order_relaxed))
        atomic_store_explicit(&s->now_ns, deadline_ns, memory_order_relaxed);
    return 0;
}

/* ---- real-time plant thread ------------------------------------------ */

static void sleep_abs(int64_t t_ns)
{
    const struct timespec ts = {.tv_sec = (time_t)(t_ns / PS_NS_PER_S),
                                .tv_nsec = (long)(t_ns % PS_NS_PER_S)};
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR) {
    }
}

static void *plant_thread(void *arg)
{
    ps_sim_t *s = arg;
    if (s->hooks.setup_thread != NULL) /* best effort, like the sim itself */
        s->hooks.setup_thread(s->hooks.ctx, s->board.plant_priority, s->board.plant_cpu);
    const ps_clock_t *mono = ps_clock_monotonic();
    const int64_t n_sub = s->period_ns / s->dt_ns;
    int64_t next_ns = s->start_ns + s->period_ns / 2;
    while (atomic_load(&s->is_running)) {
        sleep_abs(next_ns);
        if (!atomic_load(&s->is_running))
            break;
        for (int64_t i = 0; i < n_sub; i++)
            substep(s, next_ns + i * s->dt_ns, s->plant_rel_ns);
        if (s->slow_ns > 0)
            sleep_abs(ps_clock_now_ns(mono) + s->slow_ns); /* test knob: a slow plant */
        next_ns += s->period_ns;
        const int64_t now = ps_clock_now_ns(mono);
        /* Simulated time should reach start + plant_rel_ns by the next slot;
         * skipped periods leave it behind the wall clock for good. */
        const int64_t lag = now - (s->start_ns + s->period_ns / 2 + s->plant_rel_ns);
        if (lag > s->max_lag_ns)
            s->max_lag_ns = lag;
        update_truth(s);
        if (now > next_ns) {
            /* Physics slower than real time: skip to the next future slot of
             * the grid, like hardware that misses its tick, and count it. */
            const int64_t missed = (now - next_ns) / s->period_ns + 1;
            next_ns += missed * s->period_ns;
            s->n_overruns += (uint64_t)missed;
        }
    }
    return NULL;
}

/* ---- lifecycle --------------------------------------------------------- */

static int find_joint(const ps_sim_robot_t *r, const char *name)
{
    for (uint32_t j = 0; j < r->n_joints; j++) {
        if (strncmp(r->joint_name[j], name, PS_NAME_LEN) == 0)
            return (int)j;
    }
    return -ENOENT;
}

static int setup_scenario(ps_sim_t *s, char *err, size_t err_len)
{
    const ps_scenario_cfg_t *sc = &s->scenario;
    if (sc->n_pushes > PS_MAX_PUSHES || sc->n_events > PS_MAX_EVENTS) {
        ps_err_format(err, err_len, "scenario %s: too many pushes or events", sc->name);
        return -PS_ERR_CONFIG;
    }
    for (uint32_t p = 0; p < sc->n_pushes; p++) {
        const ps_push_cfg_t *pc = &sc->pushes[p];
        const int body = ps_plant_find_body(s->plant, pc->body);
        if (body < 0) {
            /* The file and line where the loader recorded them, as for every
             * other configuration error; else the scenario's name. */
            if (sc->path[0] != '\0' && pc->body_line > 0)
                ps_err_format(
                    err, err_len, "%.*s:%u: pushes[%u].body: '%.*s' is not a body of the model",
                    (int)sizeof(sc->path), sc->path, pc->body_line, p, (int)PS_NAME_LEN, pc->body);
            else
                ps_err_format(err, err_len,
                              "scenario %s: pushes[%u].body: '%.*s' is not a body of the model",
                              sc->name, p, (int)PS_NAME_LEN, pc->body);
            return -PS_ERR_CONFIG;
        }
        int slot = -1;
        for (int b = 0; b < s->n_push_bodies; b++) {
            if (s->push_body_idx[b] == body)
                slot = b;
        }
        if (slot < 0) {
            slot = s->n_push_bodies++;
            s->push_body_idx[slot] = body;
        }
        s->push_slot[p] = slot;
        s->push_t0_ns[p] = ps_s_to_ns((double)pc->t_s);
        s->push_t1_ns[p] = ps_s_to_ns((double)pc->t_s + (double)pc->duration_s);
    }
    for (uint32_t e = 0; e < sc->n_events; e++) {
        const ps_event_cfg_t *ev = &sc->events[e];
        s->event_t_ns[e] = ps_s_to_ns((double)ev->t_s);
        s->event_joint_idx[e] = -1;
        if (ev->kind == PS_EVENT_DROP_REPLIES || ev->kind == PS_EVENT_DRIVE_FAULT) {
            const int j = find_joint(&s->robot, ev->joint);
            if (j < 0 && sc->path[0] != '\0' && ev->joint_line > 0) {
                ps_err_format(err, err_len,
                              "%.*s:%u: events[%u].joint: '%.*s' is not a joint of %s",
                              (int)sizeof(sc->path), sc->path, ev->joint_line, e, (int)PS_NAME_LEN,
                              ev->joint, s->robot.name);
                return -PS_ERR_CONFIG;
            }
            if (j < 0) {
                ps_err_format(err, err_len,
                              "scenario %s: events[%u].joint: '%.*s' is not a joint of %s",
                              sc->name, e, (int)PS_NAME_LEN, ev->joint, s->robot.name);
                return -PS_ERR_CONFIG;
            }
            s->event_joint_idx[e] = j;
        }
    }
    return 0;
}

int ps_sim_create(const ps_sim_cfg_t *cfg, ps_sim_t **out_sim, char *err, size_t err_len)
{
    if (cfg == NULL || out_sim == NULL || cfg->board == NULL || cfg->robot == NULL ||
        cfg->model_path == NULL || cfg->period_ns <= 0) {
        ps_err_format(err, err_len, "sim: missing board, robot, model path or period");
        return -EINVAL;
    }
    ps_sim_t *s = calloc(1, sizeof *s);
    if (s == NULL) {
        ps_err_format(err, err_len, "sim: out of memory");
        return -ENOMEM;
    }
    int rc;
    s->board = *cfg->board;
    s->robot = *cfg->robot;
    s->hooks = cfg->hooks;
    if (cfg->scenario != NULL)
        s->scenario = *cfg->scenario;
    s->is_lockstep = cfg->is_lockstep;
    s->period_ns = cfg->period_ns;
    atomic_init(&s->now_ns, 0);
    s->first_fall_t_s = -1.0;
    s->plant_err_t_s = -1.0;
    const char *slow = getenv("PUSHSTEP_SIM_SLOW_NS");
    s->slow_ns = slow != NULL ? strtoll(slow, NULL, 10) : 0;
    if (s->slow_ns < 0 || s->slow_ns > PS_NS_PER_S)
        s->slow_ns = 0;
    s->min_com_active_m = INFINITY;
    atomic_init(&s->requests, 0u);
    atomic_init(&s->truth_seq, 0u);
    atomic_init(&s->is_running, false);
    s->clock = (ps_clock_t){.now_ns = sim_now_ns, .sleep_until_ns = sim_sleep_until_ns, .ctx = s};
    (void)ps_ring_init(&s->crowd_ring, s->crowd_storage, PS_SIM_CROWD_RING_SLOTS,
                       sizeof(s->crowd_storage[0])); /* constant, valid sizes */

    /* Priority inheritance: the SCHED_FIFO plant thread and the SCHED_OTHER
     * main thread share this mutex. */
    pthread_mutexattr_t attr;
    bool is_attr_ok = pthread_mutexattr_init(&attr) == 0;
    if (is_attr_ok && pthread_mutexattr_setprotocol(&attr, PTHREAD_PRIO_INHERIT) != 0) {
        (void)pthread_mutexattr_destroy(&attr); /* fall back to a plain mutex */
        is_attr_ok = false;
    }
    int mutex_rc = pthread_mutex_init(&s->truth_mu, is_attr_ok ? &attr : NULL);
    if (is_attr_ok)
        (void)pthread_mutexattr_destroy(&attr); /* the mutex keeps its own copy */
    if (mutex_rc != 0) {
        ps_err_format(err, err_len, "sim: mutex init failed");
        free(s);
        return -ENOMEM;
    }
    s->has_mutex = true;

    if (s->robot.n_joints > PS_MAX_JOINTS || s->board.n_buses > PS_MAX_BUSES) {
        ps_err_format(err, err_len, "sim: too many joints or buses");
        rc = -PS_ERR_CONFIG;
        goto fail;
    }
    for (uint32_t j = 0; j < s->robot.n_joints; j++) {
        if (s->robot.act[j].bus_idx >= s->board.n_buses) {
            ps_err_format(err, err_len, "sim: joint %s: bus %u not on board %s",
                          s->robot.joint_name[j], s->robot.act[j].bus_idx, s->board.name);
            rc = -PS_ERR_CONFIG;
            goto fail;
        }
    }
    if (s->robot.imu.bus_idx >= s->board.n_buses) {
        ps_err_format(err, err_len, "sim: imu bus %u not on board %s", s->robot.imu.bus_idx,
                      s->board.name);
        rc = -PS_ERR_CONFIG;
        goto fail;
    }

    const ps_plant_cfg_t plant_cfg = {
        .model_path = cfg->model_path,
        .n_joints = s->robot.n_joints,
        .joint_name = s->robot.joint_name,
        .stance_rad = s->robot.stance_rad,
        .src_path = s->robot.src_path,
        .joint_name_line = s->robot.joint_name_line,
        .model_line = s->robot.model_line,
        .spawn_xy_m = {s->scenario.robot_xy_m[0], s->scenario.robot_xy_m[1]},
        .spawn_yaw_rad = s->scenario.robot_yaw_rad,
        .crowd = &s->scenario.crowd,
        .seed = s->scenario.seed,
    };
    rc = ps_plant_create(&plant_cfg, &s->plant, err, err_len);
    if (rc < 0)
        goto fail;
    s->dt_s = ps_plant_timestep_s(s->plant);
    s->dt_ns = ps_s_to_ns(s->dt_s);
    s->foot_body[0] = ps_plant_find_body(s->plant, "l_foot"); /* motion metrics */
    s->foot_body[1] = ps_plant_find_body(s->plant, "r_foot");
    if (s->foot_body[1] < 0)
        s->foot_body[0] = -1;
    if (s->dt_ns <= 0 || s->period_ns % s->dt_ns != 0) {
        ps_err_format(err, err_len,
                      "sim: model timestep %g s does not divide the servo period %lld ns", s->dt_s,
                      (long long)s->period_ns);
        rc = -PS_ERR_CONFIG;
        goto fail;
    }
    rc = setup_scenario(s, err, err_len);
    if (rc < 0)
        goto fail;

    const ps_clock_t *bus_clock = s->is_lockstep ? &s->clock : ps_clock_monotonic();
    for (uint32_t b = 0; b < s->board.n_buses; b++) {
        rc = ps_can_sim_create(&s->bus[b], s->board.buses[b].ifname, s->board.buses[b].bitrate,
                               bus_clock, s->period_ns, BUS_QUEUE_LEN);
        if (rc < 0) {
            ps_err_format(err, err_len, "sim: bus %s: %s", s->board.buses[b].ifname,
                          ps_strerror(rc));
            goto fail;
        }
        if (s->board.buses[b].is_fd)
            ps_can_sim_set_fd(s->bus[b], s->board.buses[b].data_bitrate);
        s->dev_port[b] = ps_can_sim_device_port(s->bus[b]);
    }
    ps_gpio_sim_init(&s->gpio);
    for (uint32_t j = 0; j < s->robot.n_joints; j++)
        ps_devices_init_actuator(&s->act[j], &s->robot.act[j], &s->robot.lim[j], &s->robot.devices);
    ps_devices_init_imu(&s->imu, &s->robot.imu, &s->robot.devices, (uint64_t)s->scenario.seed);
    rc = init_scene(s, err, err_len);
    if (rc < 0)
        goto fail;
    update_truth(s);
    *out_sim = s;
    return 0;

fail:
    ps_sim_destroy(s);
    return rc;
}

ps_can_port_t ps_sim_can_port(ps_sim_t *s, unsigned bus_idx)
{
    if (bus_idx >= s->board.n_buses || s->bus[bus_idx] == NULL) {
        const ps_can_port_t none = {0};
        return none;
    }
    return ps_can_sim_host_port(s->bus[bus_idx]);
}

ps_gpio_port_t ps_sim_gpio_port(ps_sim_t *s)
{
    return ps_gpio_sim_port(&s->gpio);
}

const ps_clock_t *ps_sim_clock(ps_sim_t *s)
{
    return s->is_lockstep ? &s->clock : ps_clock_monotonic();
}

int ps_sim_start(ps_sim_t *s, int64_t start_ns)
{
    if (s->is_started)
        return -EBUSY;
    s->start_ns = start_ns;
    s->plant_rel_ns = 0;
    for (uint32_t b = 0; b < s->board.n_buses; b++)
        ps_can_sim_set_epoch(s->bus[b], start_ns);
    if (s->is_lockstep) {
        atomic_store(&s->now_ns, start_ns);
        s->is_started = true;
        return 0;
    }
    /* set before the thread starts: it reads is_started (ThreadSanitizer
     * found it written after pthread_create) */
    s->is_started = true;
    atomic_store(&s->is_running, true);
    const int rc = pthread_create(&s->thread, NULL, plant_thread, s);
    if (rc != 0) {
        atomic_store(&s->is_running, false);
        s->is_started = false;
        return -rc;
    }
    s->has_thread = true;
    return 0;
}

void ps_sim_stop(ps_sim_t *s)
{
    if (s == NULL || !s->has_thread)
        return;
    atomic_store(&s->is_running, false);
    (void)pthread_join(s->thread, NULL); /* cannot fail for a joinable thread we own */
    s->has_thread = false;
}

bool ps_sim_read_truth_rt(ps_sim_t *s, ps_sim_truth_t *out)
{
    for (int attempt = 0; attempt < 4; attempt++) {
        const unsigned s1 = atomic_load_explicit(&s->truth_seq, memory_order_acquire);
        if (s1 & 1u)
            continue;
        memcpy(out, &s->truth_rt, sizeof(*out)); /* seqlock read: validated below */
        atomic_thread_fence(memory_order_acquire);
        if (atomic_load_explicit(&s->truth_seq, memory_order_relaxed) == s1)
            return true;
    }
    return false;
}

void ps_sim_get_truth(ps_sim_t *s, ps_sim_truth_t *out)
{
    pthread_mutex_lock(&s->truth_mu);
    *out = s->truth;
    pthread_mutex_unlock(&s->truth_mu);
}

uint32_t ps_sim_take_requests(ps_sim_t *s)
{
    return atomic_exchange(&s->requests, 0u);
}

int ps_sim_get_actuator(ps_sim_t *s, unsigned joint_idx, ps_devices_actuator_t *out)
{
    if (joint_idx >= s->robot.n_joints)
        return -EINVAL;
    *out = s->act[joint_idx];
    return 0;
}

int ps_sim_take_crowd_sample(ps_sim_t *s, ps_sim_crowd_sample_t *out)
{
    if (ps_plant_crowd(s->plant) == NULL)
        return -ENOENT;
    return ps_ring_pop(&s->crowd_ring, out);
}

uint64_t ps_sim_crowd_samples_dropped(ps_sim_t *s)
{
    return ps_ring_dropped(&s->crowd_ring);
}

const struct ps_plant *ps_sim_plant(const ps_sim_t *s)
{
    return s->plant;
}

void ps_sim_destroy(ps_sim_t *s)
{
    if (s == NULL)
        return;
    ps_sim_stop(s);
    for (uint32_t b = 0; b < PS_MAX_BUSES; b++) {
        ps_can_sim_destroy(s->bus[b]);
        s->bus[b] = NULL;
    }
    ps_plant_destroy(s->plant);
    if (s->has_mutex)
        pthread_mutex_destroy(&s->truth_mu);
    free(s->scene_slots);
    free(s);
}

/* ---- the scene -------------------------------------------------------- */

static int init_scene(ps_sim_t *s, char *err, size_t err_len)
{
    s->scene_nq = (uint32_t)ps_plant_model(s->plant)->nq;
    const size_t slot = sizeof(scene_hdr_t) + sizeof(double) * s->scene_nq;
    s->scene_slots = malloc(PS_MAILBOX_SLOTS * slot);
    if (s->scene_slots == NULL) {
        ps_err_format(err, err_len, "sim: no memory for the scene");
        return -ENOMEM;
    }
    return ps_mailbox_init(&s->scene_mb, s->scene_slots, slot);
}

struct mjModel_ *ps_sim_copy_model(ps_sim_t *s)
{
    return mj_copyModel(NULL, ps_plant_model(s->plant));
}

uint32_t ps_sim_scene_nq(const ps_sim_t *s)
{
    return s->scene_nq;
}

int ps_sim_read_scene(ps_sim_t *s, double *out_qpos, uint32_t nq, int64_t *out_t_ns,
                      uint64_t *out_seq)
{
    if (s == NULL || out_qpos == NULL || nq != s->scene_nq || s->scene_slots == NULL)
        return -EINVAL;
    const uint8_t *slot = ps_mailbox_read(&s->scene_mb, NULL);
    scene_hdr_t h;
    memcpy(&h, slot, sizeof(h));
    memcpy(out_qpos, slot + sizeof(h), sizeof(double) * nq);
    if (out_t_ns != NULL)
        *out_t_ns = h.t_ns;
    if (out_seq != NULL)
        *out_seq = h.seq;
    return 0;
}
