/*
 * The fault-injection matrix (issue 14, docs/safety.md "Fault matrix"): the
 * whole system as `pushstep --lockstep` wires it (ps_app: configs, bus plan,
 * MuJoCo plant, emulated drives, IMU and GPIO, loop, standing controller,
 * flight recorder), one row per fault. Each row starts from ACTIVE (the robot
 * still in the harness, so that a state reaction is not confused with a
 * fall), injects one fault at INJECT_S and checks its stated outcome:
 *
 *  - the state reached within `within_ticks` ticks of the injection (or, for
 *    faults the runtime must ride through, that the state never changes);
 *  - every frame the loop put on any bus, at every tick, decoded by the
 *    drive's own protocol (device side) is a mode request or a command
 *    inside the joint's configured limits (one wire LSB of slack);
 *  - the flight recorder's ring holds the evidence: the transition into the
 *    expected state with the fault's condition bit, or the row's own
 *    recorded field (bus mode, frame counts, temperatures, ...).
 *
 * Injection sits in test fakes around the simulated ports (a CAN port
 * wrapper per bus, a GPIO wrapper, a policy wrapper), in the scenario
 * (drive faults) and in one sim knob (a drive's winding temperature): never
 * in the loop or the real drivers.
 *
 * At the end the group prints the figures (rows run, faults injected, share
 * that ended in the expected state) and, with PUSHSTEP_FAULTS_JSON set,
 * writes them there as JSON (bench/faults.sh).
 *
 * Built plain and with ASan and UBSan (build/tests/san/, whose config
 * reload row runs the sanitized runtime); both interpose clock_gettime.
 */
#include <dlfcn.h>
#include <errno.h>
#include <math.h>
#include <poll.h>
#include <setjmp.h>
#include <signal.h>
#include <spawn.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <cmocka.h>

#include "../drivers/ps_imu_msg.h"
#include "../rt/ps_app.h"
#include "../rt/ps_err.h"
#include "../rt/ps_perception.h"
#include "../rt/ps_recorder.h"
#include "fakes/ps_cli.h"
#include "fakes/ps_clock_fake.h"
#include "fakes/ps_san.h"

#define START_NS PS_NS_PER_S
#define INJECT_S 1.5 /* ACTIVE since 1.2 s (start 0.2 s, ramp 1 s), harness on until 2 s */
#define MAX_ROWS 64u
#define PENDING  512u /* frames a delaying port holds */
#define SERVO_NS PS_NS_PER_MS

/* ---- CLOCK_REALTIME, interposed ----------------------------------------- */

static int64_t realtime_offset_ns; /* added to CLOCK_REALTIME readings */
static uint64_t n_realtime_reads;  /* CLOCK_REALTIME readings while offset != 0 */

int clock_gettime(clockid_t id, struct timespec *ts)
{
    static int (*real)(clockid_t, struct timespec *);
    if (real == NULL)
        real = (int (*)(clockid_t, struct timespec *))dlsym(RTLD_NEXT, "clock_gettime");
    const int rc = real(id, ts);
    if (rc == 0 && id == CLOCK_REALTIME && realtime_offset_ns != 0) {
        n_realtime_reads++;
        int64_t t = (int64_t)ts->tv_sec * PS_NS_PER_S + ts->tv_nsec + realtime_offset_ns;
        ts->tv_sec = (time_t)(t / PS_NS_PER_S);
        ts->tv_nsec = (long)(t % PS_NS_PER_S);
    }
    return rc;
}

/* ---- the knobs the fakes read -------------------------------------------- */

typedef enum {
    IMU_PASS = 0,
    IMU_DROP,          /* no IMU frames: silence */
    IMU_FROZEN,        /* the same two frames (same seq) again and again */
    IMU_NAN,           /* the sensor's gyro reads NaN (its encoder flags it) */
    IMU_SATURATED,     /* gyro beyond its range */
    IMU_FROZEN_VALUES, /* the same six values, the seq advancing */
} imu_fault_t;

typedef struct {
    bool drop_rx_all[PS_MAX_BUSES];
    int64_t delay_rx_ns; /* every bus */
    bool duplicate_rx;   /* every bus */
    bool reverse_rx;     /* every bus: each batch in reverse order */
    int silent_joint;    /* -1: none; its commands and replies vanish */
    int drop_reply_joint;
    int truncate_reply_joint; /* replies cut to 3 bytes (a corrupt DLC) */
    int flip_reply_joint;     /* replies with their position's top bit flipped, length kept */
    int bus_mode_bus;         /* -1: none */
    ps_can_bus_mode_t bus_mode;
    int64_t burn_recv_ns; /* CPU burnt in bus 0's recv while burn_ticks_left > 0 */
    unsigned burn_ticks_left;
    imu_fault_t imu;
    /* GPIO */
    bool estop_held;
    unsigned estop_pattern_left; /* reads left in a press pattern */
    uint32_t estop_pattern;      /* bit k: read k pressed (LSB first) */
    bool heartbeat_fails;
    /* policy */
    int policy_fault; /* 0 none, 1 NaN, 2 +inf, 3 out of range, 4 feed-forward policy_tau_ff_nm */
    float policy_tau_ff_nm;
    int64_t policy_burn_ns;
    unsigned policy_burn_runs_left;
} knobs_t;

static knobs_t k;

static void reset_knobs(void)
{
    memset(&k, 0, sizeof(k));
    k.silent_joint = k.drop_reply_joint = k.truncate_reply_joint = k.flip_reply_joint =
        k.bus_mode_bus = -1;
}

/* ---- the system ---------------------------------------------------------- */

static ps_app_t app; /* large: static, like main's */
static ps_recorder_t rec;
static char rec_dir[] = "/tmp/ps_faults_XXXXXX";
static bool has_rec_dir;
static char scen_path[64];

static int64_t now_ns(void)
{
    return ps_clock_now_ns(app.loop.cfg.clock);
}

/* The loop's deadline clock here (rt/ps_loop.h deadline_clock; in lockstep
 * the thread's CPU time, which judges a late policy step and an overrunning
 * tick): the CPU time the fakes declare they burnt, nothing else. On a
 * virtual machine without steal accounting the host's time away from the
 * vCPU counts as the thread's, so a loaded CI host once made a step "late"
 * while the robot ramped up and it went DAMPING before any fault was
 * injected. The rows test the runtime's reaction to lateness, not the host;
 * the real CPU-time clock runs end to end in tests/test_e2e_cli.c. */
static ps_clock_fake_t declared_cpu;

static void declare_cpu_burnt(int64_t ns)
{
    ps_clock_fake_advance(&declared_cpu, ns);
}

/* ---- a CAN port wrapper: injection and an independent command check ------ */

typedef struct {
    ps_can_port_t inner;
    uint32_t bus_idx;
    ps_can_frame_t pending[PENDING]; /* delay: frames taken from the wire, not yet given */
    uint32_t n_pending;
    ps_can_frame_t imu_frozen[2];
    bool has_imu_frozen;
    uint64_t n_commands, n_requests, n_violations, n_unknown;
    char first_violation[200];
} fault_port_t;

static fault_port_t ports[PS_MAX_BUSES];

static bool is_within(float v, float lo, float hi, float lsb)
{
    return isfinite(v) && v >= lo - lsb && v <= hi + lsb;
}

/* The drive's view: its protocol's device-side decoder, then the joint side. */
static void check_tx(fault_port_t *p, const ps_can_frame_t *f)
{
    const ps_robot_cfg_t *r = &app.robot;
    for (uint32_t j = 0; j < r->n_joints; j++) {
        const ps_act_cfg_t *a = &r->act[j];
        const ps_act_proto_t *pr = ps_act_proto_get(a->protocol);
        if (a->bus_idx != p->bus_idx || !pr->is_for_drive(a, f))
            continue;
        if (pr->classify_request(a, f) >= 0) {
            p->n_requests++;
            return;
        }
        ps_act_cmd_t motor, c;
        const bool is_decoded = pr->decode_cmd(a, f, &motor) == 0;
        if (is_decoded)
            ps_act_cmd_from_motor(a, &motor, &c);
        float lsb[5];
        ps_act_joint_lsb(a, lsb);
        const ps_act_limits_t *l = &r->servo[j].lim;
        const bool is_ok = is_decoded &&
                           is_within(c.q_rad, l->pos_min_rad, l->pos_max_rad, lsb[0]) &&
                           is_within(c.qd_rad_s, -l->vel_max_rad_s, l->vel_max_rad_s, lsb[1]) &&
                           is_within(c.kp_nm_rad, 0.0f, l->kp_max_nm_rad, lsb[2]) &&
                           is_within(c.kd_nm_s_rad, 0.0f, l->kd_max_nm_s_rad, lsb[3]) &&
                           is_within(c.tau_ff_nm, -l->torque_max_nm, l->torque_max_nm, lsb[4]);
        p->n_commands++;
        if (!is_ok && p->n_violations++ == 0)
            snprintf(p->first_violation, sizeof(p->first_violation),
                     "%s at %.4f s: p %.3f v %.3f kp %.2f kd %.3f t %.3f%s", r->joint_name[j],
                     ps_ns_to_s(now_ns() - START_NS), (double)c.q_rad, (double)c.qd_rad_s,
                     (double)c.kp_nm_rad, (double)c.kd_nm_s_rad, (double)c.tau_ff_nm,
                     is_decoded ? "" : " (undecodable)");
        return;
    }
    p->n_unknown++;
}

/* Ids repeat across buses (l_knee's reply id is r_knee's on bus 1): the
 * frame must be on the joint's bus too. */
static bool is_for_joint(const fault_port_t *p, const ps_can_frame_t *f, int j, bool is_reply)
{
    if (j < 0 || app.robot.act[j].bus_idx != p->bus_idx)
        return false;
    const ps_act_cfg_t *a = &app.robot.act[j];
    const ps_act_proto_t *pr = ps_act_proto_get(a->protocol);
    return is_reply ? pr->match_reply(a, f) : pr->is_for_drive(a, f);
}

static int port_send(void *ctx, const ps_can_frame_t *frames, size_t n)
{
    fault_port_t *p = ctx;
    for (size_t i = 0; i < n; i++)
        check_tx(p, &frames[i]);
    if (k.silent_joint < 0 || app.robot.act[k.silent_joint].bus_idx != p->bus_idx)
        return ps_can_send_batch(&p->inner, frames, n);
    /* The silent drive hears nothing: its frames leave the loop and vanish. */
    ps_can_frame_t keep[PS_LOOP_MAX_TX];
    size_t n_keep = 0;
    for (size_t i = 0; i < n && n_keep < PS_LOOP_MAX_TX; i++)
        if (!is_for_joint(p, &frames[i], k.silent_joint, false))
            keep[n_keep++] = frames[i];
    const int rc = ps_can_send_batch(&p->inner, keep, n_keep);
    return rc < 0 ? rc : (int)n; /* the controller took them all */
}

static bool is_imu_frame(const fault_port_t *p, const ps_can_frame_t *f, bool *out_is_gyro)
{
    const ps_imu_cfg_t *imu = &app.robot.imu;
    if (p->bus_idx != imu->bus_idx || f->is_ext || imu->protocol != PS_IMU_PROTO_PUSHSTEP)
        return false;
    *out_is_gyro = f->id == imu->base_id;
    return f->id == imu->base_id || f->id == imu->base_id + 1u;
}

/* @return false when the frame is to vanish */
static bool alter_rx(fault_port_t *p, ps_can_frame_t *f)
{
    if (k.drop_rx_all[p->bus_idx] || is_for_joint(p, f, k.silent_joint, true) ||
        is_for_joint(p, f, k.drop_reply_joint, true))
        return false;
    if (is_for_joint(p, f, k.truncate_reply_joint, true))
        f->len = 3;
    if (is_for_joint(p, f, k.flip_reply_joint, true))
        f->data[1] ^= 0x80u; /* MIT reply: p16's top bit (half the wire range) */
    bool is_gyro = false;
    if (k.imu == IMU_PASS || !is_imu_frame(p, f, &is_gyro))
        return true;
    switch (k.imu) {
    case IMU_DROP:
        return false;
    case IMU_FROZEN:
        if (!p->has_imu_frozen) {
            if (is_gyro)
                p->imu_frozen[0] = *f;
            else {
                p->imu_frozen[1] = *f;
                p->has_imu_frozen = true;
            }
            return true;
        }
        memcpy(f->data, p->imu_frozen[is_gyro ? 0 : 1].data, sizeof(f->data));
        return true;
    case IMU_FROZEN_VALUES: {
        /* The sensor stopped; its interface goes on: the first sample's
         * values under each new seq (gyro frame byte 6, accel frame byte 7). */
        const unsigned seq_at = is_gyro ? 6u : 7u;
        if (!p->has_imu_frozen) {
            p->imu_frozen[is_gyro ? 0 : 1] = *f;
            p->has_imu_frozen = !is_gyro;
            return true;
        }
        const uint8_t seq = f->data[seq_at];
        memcpy(f->data, p->imu_frozen[is_gyro ? 0 : 1].data, sizeof(f->data));
        f->data[seq_at] = seq;
        return true;
    }
    case IMU_NAN:
    case IMU_SATURATED:
        if (is_gyro) {
            /* What the IMU's own encoder sends for such a reading. */
            const float g = k.imu == IMU_NAN ? NAN : 40.0f;
            ps_imu_sample_t s = {.gyro_body_rad_s = {g, 0.0f, 0.0f}, .seq = f->data[6]};
            ps_can_frame_t out[2];
            ps_imu_msg_encode(app.robot.imu.base_id, &s, out);
            memcpy(f->data, out[0].data, 8);
        }
        return true;
    case IMU_PASS:
    default:
        return true;
    }
}

static int port_recv(void *ctx, ps_can_frame_t *out, size_t max)
{
    fault_port_t *p = ctx;
    if (p->bus_idx == 0 && k.burn_ticks_left > 0) {
        k.burn_ticks_left--;
        declare_cpu_burnt(k.burn_recv_ns);
    }
    if (k.delay_rx_ns > 0 || p->n_pending > 0) {
        /* Everything due on the wire goes into the wrapper's queue; it comes
         * out delay_rx_ns after it was complete. */
        int n;
        while (p->n_pending < PENDING &&
               (n = ps_can_recv_batch(&p->inner, &p->pending[p->n_pending],
                                      PENDING - p->n_pending)) > 0)
            p->n_pending += (uint32_t)n;
        const int64_t now = now_ns();
        size_t n_out = 0, n_keep = 0;
        for (uint32_t i = 0; i < p->n_pending; i++) {
            if (n_out < max && p->pending[i].t_ns + k.delay_rx_ns <= now && n_keep == 0)
                out[n_out++] = p->pending[i];
            else
                p->pending[n_keep++] = p->pending[i];
        }
        p->n_pending = (uint32_t)n_keep;
        max = n_out; /* then altered like any other batch */
        size_t n_alt = 0;
        for (size_t i = 0; i < max; i++)
            if (alter_rx(p, &out[i]))
                out[n_alt++] = out[i];
        return (int)n_alt;
    }
    const size_t want = k.duplicate_rx ? max / 2 : max;
    int n = ps_can_recv_batch(&p->inner, out, want);
    if (n <= 0)
        return n;
    size_t n_alt = 0;
    for (int i = 0; i < n; i++)
        if (alter_rx(p, &out[i]))
            out[n_alt++] = out[i];
    if (k.reverse_rx)
        for (size_t i = 0; i < n_alt / 2; i++) {
            const ps_can_frame_t t = out[i];
            out[i] = out[n_alt - 1 - i];
            out[n_alt - 1 - i] = t;
        }
    if (k.duplicate_rx) {
        for (size_t i = n_alt; i-- > 0;) {
            out[2 * i] = out[i];
            out[2 * i + 1] = out[i];
        }
        n_alt *= 2;
    }
    return (int)n_alt;
}

static int port_state(void *ctx, ps_can_state_t *out)
{
    fault_port_t *p = ctx;
    const int rc = ps_can_get_state(&p->inner, out);
    if (rc == 0 && k.bus_mode_bus == (int)p->bus_idx) {
        out->mode = k.bus_mode;
        out->tx_error_count = k.bus_mode == PS_CAN_BUS_OFF ? 256 : 136;
    }
    return rc;
}

static const ps_can_ops_t PORT_OPS = {
    .send_batch = port_send, .recv_batch = port_recv, .get_state = port_state};

/* ---- a GPIO wrapper -------------------------------------------------------- */

static ps_gpio_port_t gpio_inner;
static uint64_t n_heartbeat_refused;

static int gpio_read_estop(void *ctx, bool *out)
{
    (void)ctx;
    const int rc = ps_gpio_read_estop(&gpio_inner, out);
    if (rc < 0)
        return rc;
    if (k.estop_pattern_left > 0) {
        *out |= (k.estop_pattern & 1u) != 0;
        k.estop_pattern >>= 1;
        k.estop_pattern_left--;
    }
    *out |= k.estop_held;
    return 0;
}

static int gpio_set_heartbeat(void *ctx, bool level)
{
    (void)ctx;
    if (k.heartbeat_fails) {
        n_heartbeat_refused++;
        return -EIO; /* the line cannot be driven: the relay sees no beat */
    }
    return gpio_inner.ops->set_heartbeat(gpio_inner.ctx, level);
}

static int gpio_set_led(void *ctx, ps_gpio_led_t led)
{
    (void)ctx;
    return gpio_inner.ops->set_led(gpio_inner.ctx, led);
}

static int gpio_read_button(void *ctx, bool *out)
{
    (void)ctx;
    return ps_gpio_read_button(&gpio_inner, out);
}

static const ps_gpio_ops_t GPIO_OPS = {.read_estop = gpio_read_estop,
                                       .set_heartbeat = gpio_set_heartbeat,
                                       .set_led = gpio_set_led,
                                       .read_button = gpio_read_button};

/* ---- a policy wrapper ------------------------------------------------------ */

static ps_policy_t policy_inner;

static int policy_step(void *ctx, const ps_meas_t *m, const ps_estimate_t *e, ps_targets_t *out)
{
    (void)ctx;
    if (k.policy_burn_runs_left > 0) {
        k.policy_burn_runs_left--;
        declare_cpu_burnt(k.policy_burn_ns);
    }
    const int rc = policy_inner.ops->step(policy_inner.ctx, m, e, out);
    const int j = 3; /* l_knee */
    if (k.policy_fault == 1)
        out->q_rad[j] = NAN;
    else if (k.policy_fault == 2)
        out->q_rad[j] = INFINITY;
    else if (k.policy_fault == 3)
        out->q_rad[j] = app.robot.servo[j].lim.pos_max_rad + 0.5f;
    else if (k.policy_fault == 4)
        out->tau_ff_nm[j] = k.policy_tau_ff_nm;
    return rc;
}

static void policy_reset(void *ctx)
{
    (void)ctx;
    policy_inner.ops->reset(policy_inner.ctx);
}

static const ps_policy_ops_t POLICY_OPS = {
    .name = "faulty", .step = policy_step, .reset = policy_reset};

/* ---- fixture --------------------------------------------------------------- */

/* The scenario: stand in the harness, started at 0.2 s, plus the row's events. */
static void write_scenario(const char *extra_events)
{
    snprintf(scen_path, sizeof(scen_path), "/tmp/ps_faults_XXXXXX.yaml");
    const int fd = mkstemps(scen_path, 5);
    assert_true(fd >= 0);
    char yaml[1024];
    snprintf(yaml, sizeof(yaml),
             "name: faults\nduration_s: 10\nseed: 5\nevents:\n"
             "  - {t_s: 0.2, kind: start}\n%s",
             extra_events != NULL ? extra_events : "");
    assert_int_equal(write(fd, yaml, strlen(yaml)), (ssize_t)strlen(yaml));
    assert_int_equal(close(fd), 0);
}

/* ps1 with other drive temperature thresholds (control.derate_band_c,
 * hot_margin_c, derate_min): written once, removed at the end. The robot
 * file's relative paths (model, policy weights: ": ../") are made absolute,
 * since the copy lives in /tmp. */
#define THERMAL_BAND_C   30.0f
#define THERMAL_MARGIN_C 10.0f
#define THERMAL_MIN      0.3f
static char thermal_robot[64];

/* text[from, to) with every ": ../" as ": ROOT/". */
static void write_rooted(FILE *out, const char *from, const char *to, const char *root)
{
    const char *rel = ": ../";
    for (const char *p = from; p < to;) {
        const char *hit = strstr(p, rel);
        if (hit == NULL || hit >= to) {
            fprintf(out, "%.*s", (int)(to - p), p);
            return;
        }
        fprintf(out, "%.*s: %s/", (int)(hit - p), p, root);
        p = hit + strlen(rel);
    }
}

static const char *thermal_robot_path(void)
{
    if (thermal_robot[0] != '\0')
        return thermal_robot;
    FILE *in = fopen("robots/ps1.yaml", "r");
    assert_non_null(in);
    static char text[1 << 16];
    const size_t n = fread(text, 1, sizeof(text) - 1, in);
    fclose(in);
    text[n] = '\0';
    const char *thermal = "derate_band_c: 15, hot_margin_c: 5, derate_min: 0.5}";
    const char *hold = strstr(text, thermal);
    assert_non_null(hold);
    char cwd[512];
    assert_non_null(getcwd(cwd, sizeof(cwd)));
    snprintf(thermal_robot, sizeof(thermal_robot), "/tmp/ps_faults_robot_XXXXXX.yaml");
    const int fd = mkstemps(thermal_robot, 5);
    assert_true(fd >= 0);
    FILE *out = fdopen(fd, "w");
    assert_non_null(out);
    write_rooted(out, text, hold, cwd);
    fprintf(out, "derate_band_c: %g, hot_margin_c: %g, derate_min: %g}", (double)THERMAL_BAND_C,
            (double)THERMAL_MARGIN_C, (double)THERMAL_MIN);
    const char *rest = hold + strlen(thermal);
    write_rooted(out, rest, rest + strlen(rest), cwd);
    assert_int_equal(fclose(out), 0);
    return thermal_robot;
}

static void start_system_robot(const char *robot, const char *extra_events, double ring_s)
{
    reset_knobs();
    write_scenario(extra_events);
    char err[PS_ERR_MSG_LEN] = "";
    ps_app_opts_t o = {.data_dir = ".",
                       .board = "sim",
                       .robot = robot,
                       .scenario = scen_path,
                       .is_lockstep = true};
    const int rc = ps_app_init(&app, &o, err, sizeof(err));
    (void)unlink(scen_path);
    if (rc != 0)
        fail_msg("ps_app_init: %s (%s)", err, ps_strerror(rc));
    for (uint32_t b = 0; b < app.board.n_buses; b++) {
        memset(&ports[b], 0, sizeof(ports[b]));
        ports[b].inner = app.loop.cfg.buses[b];
        ports[b].bus_idx = b;
        app.loop.cfg.buses[b] = (ps_can_port_t){.ops = &PORT_OPS, .ctx = &ports[b], .name = "f"};
    }
    gpio_inner = app.loop.cfg.gpio;
    app.loop.cfg.gpio = (ps_gpio_port_t){.ops = &GPIO_OPS, .ctx = NULL};
    n_heartbeat_refused = 0;
    policy_inner = app.loop.cfg.policy;
    app.loop.cfg.policy = (ps_policy_t){.ops = &POLICY_OPS, .ctx = NULL};
    ps_clock_fake_init(&declared_cpu, 0);
    app.loop.cfg.deadline_clock = &declared_cpu.clock;
    if (app.mlp.clock != NULL)
        app.mlp.clock = &declared_cpu.clock; /* its own late check: the same clock */

    if (!has_rec_dir)
        has_rec_dir = mkdtemp(rec_dir) != NULL;
    assert_true(has_rec_dir);
    ps_recorder_cfg_t rc_cfg = {.dir = rec_dir, .pre_s = 1, .post_s = 1, .ring_s = ring_s};
    ps_app_recorder_cfg(&app, &rc_cfg);
    if (ps_recorder_init(&rec, &rc_cfg, err, sizeof(err)) != 0)
        fail_msg("ps_recorder_init: %s", err);
    ps_app_attach_recorder(&app, &rec); /* the ring only: no writer thread */
    assert_int_equal(ps_sim_start(app.sim, START_NS), 0);
    assert_int_equal(ps_loop_start(&app.loop, START_NS), 0);
}

static void start_system(const char *extra_events, double ring_s)
{
    start_system_robot(NULL, extra_events, ring_s);
}

static int teardown(void **state)
{
    (void)state;
    realtime_offset_ns = 0;
    reset_knobs();
    ps_app_deinit(&app);
    ps_recorder_deinit(&rec);
    return 0;
}

static double loop_time_s(void)
{
    return ps_ns_to_s(app.loop.t_deadline_ns - START_NS);
}

static void step(void)
{
    assert_int_equal(ps_loop_step(&app.loop), 0);
}

static void step_until(double t_s)
{
    while (loop_time_s() < t_s)
        step();
}

/* ---- the recorder's evidence ----------------------------------------------- */

static ps_rec_tick_t rtick; /* large: one at a time */

/* Records from tick `from` on (the recorder has one per tick from tick 0). */
typedef bool (*rec_pred_t)(const ps_rec_tick_t *r, const void *arg);

static bool recorder_has(uint64_t from, rec_pred_t pred, const void *arg, uint64_t *out_tick)
{
    const uint64_t head = atomic_load(&rec.head);
    for (uint64_t i = from; i < head; i++) {
        if (ps_recorder_read(&rec, i, &rtick) != 0)
            continue;
        if (pred(&rtick, arg)) {
            if (out_tick != NULL)
                *out_tick = rtick.tick;
            return true;
        }
    }
    return false;
}

typedef struct {
    ps_sm_state_t to;
    uint32_t cond;
} transition_t;

static bool is_transition(const ps_rec_tick_t *r, const void *arg)
{
    const transition_t *t = arg;
    return r->state == t->to && r->state_before != t->to && (r->cond & t->cond) != 0u;
}

/* ---- the figures -------------------------------------------------------------- */

typedef struct {
    const char *name;
    const char *expected;
    bool is_as_expected;
    int64_t ticks_to_state; /* -1: no state change expected */
} outcome_t;

static outcome_t outcomes[MAX_ROWS];
static unsigned n_outcomes;

/* The row under way: registered as it starts, as expected only once every
 * check of it passed (a failed row stays false in the figures). */
static void begin_row(const char *name, const char *expected)
{
    assert_true(n_outcomes < MAX_ROWS);
    outcomes[n_outcomes++] = (outcome_t){.name = name, .expected = expected, .ticks_to_state = -1};
}

static void row_done(void)
{
    outcomes[n_outcomes - 1].is_as_expected = true;
}

static void assert_commands_clean(void)
{
    uint64_t n_cmd = 0;
    for (uint32_t b = 0; b < app.board.n_buses; b++) {
        if (ports[b].n_violations != 0)
            fail_msg("bus %u: %llu command(s) outside limits, first: %s", b,
                     (unsigned long long)ports[b].n_violations, ports[b].first_violation);
        assert_int_equal(ports[b].n_unknown, 0);
        n_cmd += ports[b].n_commands;
    }
    assert_true(n_cmd > 1000u); /* the check saw the run */
    assert_int_equal(app.loop.counters.n_cmd_replaced, 0);
    ps_sim_truth_t t;
    ps_sim_get_truth(app.sim, &t);
    assert_int_equal(t.n_cmd_out_of_limits, 0); /* and the drives agree */
}

/* A row whose fault must move the state machine: `to` reached within
 * `within` ticks of the injection (the tick that first ran with the fault),
 * and the recorder holds that transition with the fault's condition bit;
 * the ticks it took go into the row's figures. */
static void expect_state(uint64_t inj_tick, ps_sm_state_t to, uint32_t cond, unsigned within)
{
    while (app.loop.state != to && app.loop.counters.n_ticks - inj_tick < within + 1u)
        step();
    if (app.loop.state != to)
        fail_msg("still %s %u ticks after the injection, want %s", ps_sm_state_name(app.loop.state),
                 within, ps_sm_state_name(to));
    const transition_t t = {.to = to, .cond = cond};
    uint64_t at = 0;
    if (!recorder_has(inj_tick, is_transition, &t, &at))
        fail_msg("the recorder has no transition to %s with %s", ps_sm_state_name(to),
                 ps_sm_cond_name(cond));
    const int64_t ticks = (int64_t)(at - inj_tick) + 1;
    print_message("      -> %s by %s after %lld tick(s) (limit %u)\n", ps_sm_state_name(to),
                  ps_sm_cond_name(cond), (long long)ticks, within);
    assert_true(ticks <= (int64_t)within);
    outcomes[n_outcomes - 1].ticks_to_state = ticks;
}

/* The state stays `s` on every tick until t_s. */
static void expect_stays(ps_sm_state_t s, double t_s)
{
    while (loop_time_s() < t_s) {
        step();
        if (app.loop.state != s)
            fail_msg("left %s for %s at %.4f s (cond 0x%x)", ps_sm_state_name(s),
                     ps_sm_state_name(app.loop.state), loop_time_s(), app.loop.last.cond);
    }
}

/* ---- the rows ------------------------------------------------------------------ */

/* Reply timeout 10 ms + rate_div 2 ticks: stale after 12 ms without a reply;
 * the IMU after 10 ms + 1 tick. */
#define REPLY_STALE_TICKS 16u
#define IMU_STALE_TICKS   14u
/* Frozen values: refused from the 50th sample in a row (ps1's
 * imu.frozen_samples default, 50 ms at 1 kHz), then stale as above. */
#define IMU_FROZEN_TICKS (50u + IMU_STALE_TICKS)
/* The policy runs every 20 ticks; the state machine sees its result next tick. */
#define POLICY_TICKS 22u
#define L_KNEE       3 /* ps1's joint 3 */

typedef struct {
    const char *name;         /* in the figures */
    const char *events;       /* scenario events beside the start (NULL: none) */
    double ring_s;            /* recorder ring (0: 4 s, the whole run) */
    void (*arm)(void);        /* injects the fault once ACTIVE, at INJECT_S */
    double fault_s;           /* 0: the fault stays; else every knob cleared after this long */
    ps_sm_state_t to;         /* the state the fault must lead to (ACTIVE: ride through) */
    uint32_t cond;            /* the condition on the transition into `to` (0: none) */
    unsigned within;          /* ticks from the injection to `to` */
    double watch_s;           /* `to` held on every tick until INJECT_S + watch_s */
    rec_pred_t evidence;      /* a recorded tick that shows the fault (NULL: the transition) */
    const void *evidence_arg; /* for evidence */
    void (*check)(void);      /* further checks after the run (NULL: none) */
    bool is_thermal_robot;    /* ps1 with other temperature thresholds (thermal_robot_path) */
} row_t;

static void run_row(void **state)
{
    const row_t *r = *state;
    begin_row(r->name, ps_sm_state_name(r->to));
    start_system_robot(r->is_thermal_robot ? thermal_robot_path() : NULL, r->events,
                       r->ring_s > 0 ? r->ring_s : 4.0);
    step_until(INJECT_S);
    if (app.loop.state != PS_SM_ACTIVE)
        fail_msg("%s before the injection at %.2f s (conditions now 0x%x; %llu late policy "
                 "steps, %llu overruns)",
                 ps_sm_state_name(app.loop.state), INJECT_S, app.loop.last.cond,
                 (unsigned long long)app.loop.counters.n_policy_late,
                 (unsigned long long)app.loop.pacer.n_overruns);
    const uint64_t inj = app.loop.counters.n_ticks;
    if (r->arm != NULL)
        r->arm();
    if (r->cond != 0u)
        expect_state(inj, r->to, r->cond, r->within);
    if (r->fault_s > 0) {
        expect_stays(r->to, INJECT_S + r->fault_s);
        reset_knobs();
    }
    expect_stays(r->to, INJECT_S + r->watch_s);
    if (r->evidence != NULL && !recorder_has(inj, r->evidence, r->evidence_arg, NULL))
        fail_msg("no recorded tick since the injection shows the fault");
    if (r->check != NULL)
        r->check();
    assert_commands_clean();
    row_done();
}

/* -- CAN -- */

static bool no_rx_on_any_bus(const ps_rec_tick_t *r, const void *arg)
{
    (void)arg;
    for (uint32_t b = 0; b < r->n_buses; b++)
        if (r->bus_n_rx[b] != 0)
            return false;
    return true;
}

/* Not one tick while ACTIVE went by without a frame: such a tick after the
 * injection is the fault's. */
static void assert_rx_every_tick_before(void)
{
    assert_false(recorder_has(atomic_load(&rec.head) - 200, no_rx_on_any_bus, NULL, NULL));
}

static void arm_drop_all_buses(void)
{
    assert_rx_every_tick_before();
    for (uint32_t b = 0; b < PS_MAX_BUSES; b++)
        k.drop_rx_all[b] = true;
}

static void arm_drop_l_knee_replies(void)
{
    k.drop_reply_joint = L_KNEE;
}

static void arm_delay_5ms(void)
{
    assert_rx_every_tick_before();
    k.delay_rx_ns = 5 * PS_NS_PER_MS;
}

static void arm_delay_20ms(void)
{
    k.delay_rx_ns = 20 * PS_NS_PER_MS;
}

static uint64_t n_rx_bad_at_arm;
static uint64_t head_at_arm_flip;

static bool has_rx_bad(const ps_rec_tick_t *r, const void *arg)
{
    (void)arg;
    return r->n_rx_bad > n_rx_bad_at_arm;
}

static void arm_truncate_l_knee_replies(void)
{
    n_rx_bad_at_arm = app.loop.counters.n_rx_bad;
    k.truncate_reply_joint = L_KNEE;
}

static uint16_t imu_bus_rx_max; /* the most frames the IMU's bus gave a tick before */

static bool has_more_imu_bus_rx(const ps_rec_tick_t *r, const void *arg)
{
    (void)arg;
    return r->bus_n_rx[app.robot.imu.bus_idx] > imu_bus_rx_max;
}

static void arm_duplicate(void)
{
    imu_bus_rx_max = 0;
    const uint64_t head = atomic_load(&rec.head);
    for (uint64_t i = head - 200; i < head; i++)
        if (ps_recorder_read(&rec, i, &rtick) == 0 &&
            rtick.bus_n_rx[app.robot.imu.bus_idx] > imu_bus_rx_max)
            imu_bus_rx_max = rtick.bus_n_rx[app.robot.imu.bus_idx];
    n_rx_bad_at_arm = app.loop.counters.n_rx_bad;
    k.duplicate_rx = true;
}

/* A reply twice is the same measurement twice; the IMU's second accel half
 * finds no gyro half to pair with and is refused (counted), the first pair
 * already made the sample. */
static void check_duplicate(void)
{
    print_message("      %llu IMU halves refused\n",
                  (unsigned long long)(app.loop.counters.n_rx_bad - n_rx_bad_at_arm));
    assert_true(app.loop.counters.n_rx_bad > n_rx_bad_at_arm);
    assert_int_equal(app.loop.counters.n_imu_repeated, 0);
}

static void arm_reverse(void)
{
    n_rx_bad_at_arm = app.loop.counters.n_rx_bad;
    k.reverse_rx = true; /* each batch reversed: the IMU's accel half before its gyro half */
}

typedef struct {
    uint32_t bus_idx;
    ps_can_bus_mode_t mode;
} bus_mode_t;

static bool has_bus_mode(const ps_rec_tick_t *r, const void *arg)
{
    const bus_mode_t *m = arg;
    return r->bus_mode[m->bus_idx] == (uint8_t)m->mode;
}

static const bus_mode_t BUS0_PASSIVE = {0, PS_CAN_BUS_ERROR_PASSIVE};
static const bus_mode_t BUS0_OFF = {0, PS_CAN_BUS_OFF};

static void arm_error_passive(void)
{
    k.bus_mode_bus = 0;
    k.bus_mode = PS_CAN_BUS_ERROR_PASSIVE; /* frames still flow */
}

static void arm_bus_off(void)
{
    k.bus_mode_bus = 0;
    k.bus_mode = PS_CAN_BUS_OFF;
}

/* -- actuators -- */

static void arm_silent_l_knee(void)
{
    k.silent_joint = L_KNEE; /* neither hears nor answers */
}

static bool has_l_knee_fault_bits(const ps_rec_tick_t *r, const void *arg)
{
    (void)arg;
    return r->fault_bits[L_KNEE] != 0u;
}

static void arm_overheat_l_knee(void)
{
    const double t = (double)app.robot.act[L_KNEE].temp_max_c + 2.0;
    assert_int_equal(ps_sim_set_actuator_temp(app.sim, L_KNEE, t), 0);
}

static bool has_l_knee_over_temp(const ps_rec_tick_t *r, const void *arg)
{
    (void)arg;
    return r->temp_c[L_KNEE] > app.robot.act[L_KNEE].temp_max_c;
}

/* The temperature thresholds the row's robot file gives: the defaults, or
 * those written into thermal_robot_path's file (not read back from the
 * loaded config, so that a loader that dropped them fails the row). */
typedef struct {
    float band_c, margin_c, min_share;
} thresholds_t;

static thresholds_t thr;

static void expect_thresholds(bool is_thermal_robot)
{
    thr = is_thermal_robot ? (thresholds_t){THERMAL_BAND_C, THERMAL_MARGIN_C, THERMAL_MIN}
                           : (thresholds_t){15.0f, 5.0f, 0.5f};
}

static bool has_l_knee_over_temp_band(const ps_rec_tick_t *r, const void *arg)
{
    (void)arg;
    return r->temp_c[L_KNEE] > app.robot.act[L_KNEE].temp_max_c - thr.band_c;
}

/* The torque budget a drive at temp_c may be commanded, written from the
 * spec (docs/safety.md "Hot drives"), not from the loop's function. */
static float budget_nm(float temp_c, float temp_max_c, float torque_max_nm)
{
    /* 0 at the band's start, 1 at the hot margin */
    const float x = (temp_c - (temp_max_c - thr.band_c)) / (thr.band_c - thr.margin_c);
    const float share = x <= 0.0f   ? 1.0f
                        : x >= 1.0f ? thr.min_share
                                    : 1.0f - (1.0f - thr.min_share) * x;
    return share * torque_max_nm;
}

static void warm_l_knee_full_feed_forward(double under_c)
{
    const double t = (double)app.robot.act[L_KNEE].temp_max_c - under_c; /* in the band */
    assert_int_equal(ps_sim_set_actuator_temp(app.sim, L_KNEE, t), 0);
    k.policy_fault = 4; /* the policy asks for the whole torque_max as feed-forward */
    k.policy_tau_ff_nm = app.robot.servo[L_KNEE].lim.torque_max_nm;
    n_rx_bad_at_arm = atomic_load(&rec.head); /* the first record of the row */
}

static void arm_warm_l_knee_full_feed_forward(void)
{
    expect_thresholds(false);
    warm_l_knee_full_feed_forward(6.0);
}

/* 20 degC under temp_max_c: no derating with the defaults (15 degC band),
 * 0.65 of the torque with the robot file's 30 degC band down to 0.3 at 10. */
static void arm_warm_l_knee_robot_file_thresholds(void)
{
    expect_thresholds(true);
    assert_true(app.robot.control.derate_band_c == THERMAL_BAND_C); /* the file was read */
    warm_l_knee_full_feed_forward(20.0);
}

/* Every command l_knee got from the injection on stays inside the budget
 * of the temperature the loop had measured: the feed-forward and the
 * spring's reach (|kp (p - q)| + |tau_ff|); and the budget is what bounded
 * it (the feed-forward sits at the derated cap, well under torque_max). */
static void check_derated(void)
{
    const float tmax_c = app.robot.act[L_KNEE].temp_max_c;
    const float tq_max = app.robot.servo[L_KNEE].lim.torque_max_nm;
    const uint64_t head = atomic_load(&rec.head);
    unsigned n_at_cap = 0, n_sent = 0;
    float least_budget = tq_max;
    for (uint64_t i = n_rx_bad_at_arm; i < head; i++) {
        assert_int_equal(ps_recorder_read(&rec, i, &rtick), 0);
        if (!rtick.is_cmd_sent[L_KNEE])
            continue;
        n_sent++;
        const float budget = budget_nm(rtick.temp_c[L_KNEE], tmax_c, tq_max);
        least_budget = fminf(least_budget, budget);
        const float ff = fabsf(rtick.cmd_tau_ff_nm[L_KNEE]);
        const float spring =
            rtick.cmd_kp_nm_rad[L_KNEE] * fabsf(rtick.cmd_q_rad[L_KNEE] - rtick.q_rad[L_KNEE]);
        if (ff > budget + 1e-3f || spring + ff > budget + 1e-2f)
            fail_msg("tick %llu: %.1f degC, budget %.2f Nm: tau_ff %.2f, spring %.2f",
                     (unsigned long long)rtick.tick, (double)rtick.temp_c[L_KNEE], (double)budget,
                     (double)ff, (double)spring);
        n_at_cap += ff > budget - 0.5f;
    }
    print_message(
        "      l_knee: %u commands, %u at the derated cap; least budget %.1f of %.0f Nm\n", n_sent,
        n_at_cap, (double)least_budget, (double)tq_max);
    assert_true(n_sent > 100);
    assert_true(n_at_cap > 100);
    assert_true(least_budget < 0.7f * tq_max);
}

/* 8 degC under temp_max_c: only derating with the defaults (hot from 5 degC
 * under), DRIVE_HOT with the robot file's 10 degC margin. */
static void arm_hot_l_knee_robot_file_thresholds(void)
{
    assert_true(app.robot.control.hot_margin_c == THERMAL_MARGIN_C);
    const double t = (double)app.robot.act[L_KNEE].temp_max_c - 8.0;
    assert_int_equal(ps_sim_set_actuator_temp(app.sim, L_KNEE, t), 0);
}

static void arm_hot_l_knee(void)
{
    const double t = (double)app.robot.act[L_KNEE].temp_max_c - 3.0; /* under its own trip */
    assert_int_equal(ps_sim_set_actuator_temp(app.sim, L_KNEE, t), 0);
}

/* Damped down to STANDBY, and no START while the drive is that hot. */
static void check_hot_no_start(void)
{
    while (app.loop.state != PS_SM_STANDBY && loop_time_s() < INJECT_S + 3.0)
        step();
    assert_int_equal(app.loop.state, PS_SM_STANDBY);
    ps_loop_rec_t r;
    while (ps_ring_pop(&app.ring, &r) == 0) {
    }
    ps_loop_request(&app.loop, PS_SM_C_REQ_START);
    step();
    assert_int_equal(app.loop.state, PS_SM_STANDBY);
    bool is_refused = false;
    while (ps_ring_pop(&app.ring, &r) == 0)
        is_refused |= r.kind == PS_REC_REFUSED && r.reason != NULL &&
                      strcmp(r.reason, "start refused: drive too hot") == 0;
    assert_true(is_refused);
}

/* -- IMU -- */

static void arm_imu_drop(void)
{
    k.imu = IMU_DROP;
}

static void arm_imu_frozen(void)
{
    k.imu = IMU_FROZEN;
}

static void arm_imu_nan(void)
{
    k.imu = IMU_NAN;
}

static void arm_imu_saturated(void)
{
    k.imu = IMU_SATURATED;
}

static void check_imu_repeated(void)
{
    assert_true(app.loop.counters.n_imu_repeated > 0);
}

static void check_imu_rejected(void)
{
    assert_true(app.loop.counters.n_imu_rejected > 0);
}

static void arm_imu_frozen_values(void)
{
    k.imu = IMU_FROZEN_VALUES;
}

/* Refused as frozen, not as repeated (the seq advanced) nor as a bad reading. */
static void check_imu_frozen_values(void)
{
    print_message("      %llu samples refused as frozen (imu.frozen_samples %u)\n",
                  (unsigned long long)app.loop.counters.n_imu_frozen, app.robot.imu.frozen_samples);
    assert_true(app.loop.counters.n_imu_frozen > 0);
    assert_int_equal(app.loop.counters.n_imu_repeated, 0);
    assert_int_equal(app.loop.counters.n_imu_rejected, 0);
}

static void arm_flip_l_knee_replies(void)
{
    n_rx_bad_at_arm = app.loop.counters.n_rx_bad;
    head_at_arm_flip = atomic_load(&rec.head);
    k.flip_reply_joint = L_KNEE;
}

/* Each flipped reply refused as implausible; none of them reached the
 * estimator: l_knee's recorded position stays where the knee is. */
static void check_flipped_replies_unused(void)
{
    print_message("      %llu replies refused as implausible (%llu ticks, rx_bad +%llu)\n",
                  (unsigned long long)app.loop.counters.n_reply_implausible,
                  (unsigned long long)(atomic_load(&rec.head) - head_at_arm_flip),
                  (unsigned long long)(app.loop.counters.n_rx_bad - n_rx_bad_at_arm));
    assert_true(app.loop.counters.n_reply_implausible >= 20);
    const ps_act_limits_t *l = &app.robot.servo[L_KNEE].lim;
    const uint64_t head = atomic_load(&rec.head);
    for (uint64_t i = head_at_arm_flip; i < head; i++) {
        assert_int_equal(ps_recorder_read(&rec, i, &rtick), 0);
        if (rtick.q_rad[L_KNEE] < l->pos_min_rad || rtick.q_rad[L_KNEE] > l->pos_max_rad)
            fail_msg("tick %llu: l_knee measured at %.3f rad", (unsigned long long)rtick.tick,
                     (double)rtick.q_rad[L_KNEE]);
    }
}

/* -- e-stop, heartbeat -- */

static bool is_estop_read(const ps_rec_tick_t *r, const void *arg)
{
    (void)arg;
    return r->is_estop_input != 0;
}

static void check_power_cut(void)
{
    ps_sim_truth_t t;
    ps_sim_get_truth(app.sim, &t);
    assert_false(t.is_drive_power_on); /* heartbeat still: the relay cut the drives */
}

static void arm_estop_held(void)
{
    k.estop_held = true;
}

static void arm_estop_glitch(void)
{
    k.estop_pattern = 1u; /* pressed on one read only */
    k.estop_pattern_left = 1;
}

static uint64_t n_transitions_at_arm;

static void arm_estop_bounce(void)
{
    n_transitions_at_arm = app.loop.counters.n_transitions;
    k.estop_pattern = 0x5555u; /* pressed, released, ... over 16 reads */
    k.estop_pattern_left = 16;
}

static void check_bounce_then_reset(void)
{
    check_power_cut();
    assert_int_equal(app.loop.counters.n_transitions, n_transitions_at_arm + 1); /* into ESTOP */
    ps_loop_request(&app.loop, PS_SM_C_REQ_RESET);
    step();
    assert_int_equal(app.loop.state, PS_SM_STANDBY);
}

static bool has_gpio_error_not_pressed(const ps_rec_tick_t *r, const void *arg)
{
    (void)arg;
    return r->n_gpio_errors > 0 && r->is_estop_input == 0 && r->state == PS_SM_ESTOP;
}

static void arm_heartbeat_fails(void)
{
    n_heartbeat_refused = 0;
    k.heartbeat_fails = true;
}

static void check_heartbeat(void)
{
    assert_true(n_heartbeat_refused >= 1);
    check_power_cut();
}

/* -- policy, overruns -- */

static void arm_policy_nan(void)
{
    k.policy_fault = 1;
}

static void arm_policy_inf(void)
{
    k.policy_fault = 2;
}

static void arm_policy_out_of_range(void)
{
    k.policy_fault = 3;
}

static bool is_target_invalid_rec(const ps_rec_tick_t *r, const void *arg)
{
    (void)arg;
    return r->is_target_invalid != 0;
}

static void arm_policy_late(void)
{
    k.policy_burn_ns = 3 * PS_NS_PER_MS / 2; /* 1.5 ms of CPU: deadline 0.5 ms */
    k.policy_burn_runs_left = 1;
}

static void arm_policy_stalled(void)
{
    k.policy_burn_ns = 30 * PS_NS_PER_MS;
    k.policy_burn_runs_left = 1;
}

static bool is_policy_late_rec(const ps_rec_tick_t *r, const void *arg)
{
    (void)arg;
    return r->is_policy_late != 0;
}

static void arm_overrun_burst(void)
{
    k.burn_recv_ns = 12 * PS_NS_PER_MS / 10; /* 1.2 ms of CPU in a 1 ms tick */
    k.burn_ticks_left = 8;
}

static bool has_five_overruns(const ps_rec_tick_t *r, const void *arg)
{
    (void)arg;
    return r->n_overruns >= 5;
}

/* -- perception -- */

static ps_mailbox_t mailbox;
static ps_neighbours_t mailbox_storage[PS_MAILBOX_SLOTS];
static uint64_t n_stale_at_arm;

/* The loop's camera mailbox, wired as ps_app does for a board with a camera;
 * the test is the perception thread. */
static void wire_mailbox(void)
{
    assert_int_equal(ps_mailbox_init(&mailbox, mailbox_storage, sizeof(ps_neighbours_t)), 0);
    app.loop.cfg.neighbours = &mailbox;
    app.loop.neighbours_max_age_ns = 200 * PS_NS_PER_MS;
    n_stale_at_arm = app.loop.counters.n_neighbour_stale;
}

static void arm_perception_stale(void)
{
    wire_mailbox();
    ps_neighbours_t n = {.n_shoulders = 1, .t_exposure_ns = now_ns() - PS_NS_PER_S};
    n.shoulders[0] = (ps_shoulder_t){.pos_robot_m = {0.4f, 0.2f, 1.3f}, .confidence = 0.9f};
    ps_mailbox_put(&mailbox, &n);
}

static void check_perception_stale(void)
{
    assert_int_equal(app.loop.counters.n_neighbour_lists, 1);
    assert_true(app.loop.counters.n_neighbour_stale >= n_stale_at_arm + 199);
    assert_false(app.loop.meas.neighbours.is_valid);
    assert_int_equal(app.loop.meas.neighbours.n_shoulders, 0); /* no information, not old */
}

static void arm_perception_absurd(void)
{
    wire_mailbox();
    const int64_t t0 = now_ns();
    /* More shoulders than a list holds; one from far in the future (it would
     * never age); a NaN position; a confidence outside 0..1: one a tick. */
    ps_neighbours_t bad[4] = {
        {.n_shoulders = 1000, .t_exposure_ns = t0},
        {.n_shoulders = 1, .t_exposure_ns = t0 + 3600 * PS_NS_PER_S},
        {.n_shoulders = 1, .t_exposure_ns = t0},
        {.n_shoulders = 1, .t_exposure_ns = t0},
    };
    bad[2].shoulders[0].pos_robot_m[0] = NAN;
    bad[3].shoulders[0].confidence = 7.0f;
    for (unsigned i = 0; i < 4; i++) {
        ps_mailbox_put(&mailbox, &bad[i]);
        step();
        assert_int_equal(app.loop.counters.n_neighbour_lists, i + 1);
        assert_false(app.loop.meas.neighbours.is_valid);
        assert_int_equal(app.loop.meas.neighbours.n_shoulders, 0);
    }
}

static void check_perception_absurd(void)
{
    assert_false(app.loop.meas.neighbours.is_valid);
    assert_true(app.loop.counters.n_neighbour_stale >= n_stale_at_arm + 199);
}

/* -- threads around the loop -- */

static uint64_t n_ring_dropped_at_arm;

static void arm_logger_stalled(void)
{
    /* The logger thread stopped draining: the record ring is full. */
    ps_loop_rec_t junk = {.kind = PS_REC_STATUS};
    while (ps_ring_push(&app.ring, &junk) == 0) {
    }
    n_ring_dropped_at_arm = app.loop.counters.n_ring_dropped;
    k.estop_held = true;
}

static void check_logger_stalled(void)
{
    assert_true(app.loop.counters.n_ring_dropped > n_ring_dropped_at_arm); /* counted, no wait */
}

static uint64_t head_at_arm;

static void arm_recorder_stalled_estop(void)
{
    head_at_arm = atomic_load(&rec.head);
    k.estop_held = true;
}

static void check_recorder_stalled(void)
{
    /* The writer never ran: the ring (128 records) went round; the
     * injection's record is lost, and known to be lost. */
    assert_int_equal(ps_recorder_read(&rec, head_at_arm, &rtick), -ESTALE);
    const uint64_t head = atomic_load(&rec.head);
    assert_int_equal(ps_recorder_read(&rec, head - 1, &rtick), 0); /* the newest kept */
    assert_int_equal(rtick.state, PS_SM_ESTOP);
    assert_true(rtick.is_estop_input != 0);
}

/* clang-format off */
static const row_t ROWS[] = {
    {.name = "can_loss_5ms_all_buses", .arm = arm_drop_all_buses, .fault_s = 0.005,
     .to = PS_SM_ACTIVE, .watch_s = 0.3, .evidence = no_rx_on_any_bus},
    {.name = "can_loss_one_joint_50ms", .arm = arm_drop_l_knee_replies, .fault_s = 0.05,
     .to = PS_SM_HOLD, .cond = PS_SM_C_REPLY_STALE, .within = REPLY_STALE_TICKS, .watch_s = 0.4},
    {.name = "plant_stalled_30ms", .arm = arm_drop_all_buses, .fault_s = 0.03,
     .to = PS_SM_HOLD, .cond = PS_SM_C_REPLY_STALE | PS_SM_C_IMU_STALE,
     .within = REPLY_STALE_TICKS, .watch_s = 0.4},
    {.name = "can_delay_5ms", .arm = arm_delay_5ms, .to = PS_SM_ACTIVE, .watch_s = 0.3,
     .evidence = no_rx_on_any_bus},
    {.name = "can_delay_20ms", .arm = arm_delay_20ms, .to = PS_SM_HOLD,
     .cond = PS_SM_C_REPLY_STALE, .within = REPLY_STALE_TICKS, .watch_s = 0.3},
    {.name = "can_corrupt_replies_one_joint", .arm = arm_truncate_l_knee_replies,
     .to = PS_SM_HOLD, .cond = PS_SM_C_REPLY_STALE, .within = REPLY_STALE_TICKS,
     .watch_s = 0.2, .evidence = has_rx_bad},
    {.name = "can_corrupt_payload", .arm = arm_flip_l_knee_replies, .to = PS_SM_HOLD,
     .cond = PS_SM_C_REPLY_STALE, .within = REPLY_STALE_TICKS, .watch_s = 0.2,
     .evidence = has_rx_bad, .check = check_flipped_replies_unused},
    {.name = "can_duplicate_frames", .arm = arm_duplicate, .to = PS_SM_ACTIVE, .watch_s = 0.3,
     .evidence = has_more_imu_bus_rx, .check = check_duplicate},
    {.name = "can_out_of_order_frames", .arm = arm_reverse, .to = PS_SM_HOLD,
     .cond = PS_SM_C_IMU_STALE, .within = IMU_STALE_TICKS, .watch_s = 0.2,
     .evidence = has_rx_bad},
    {.name = "can_error_passive", .arm = arm_error_passive, .to = PS_SM_ACTIVE, .watch_s = 0.3,
     .evidence = has_bus_mode, .evidence_arg = &BUS0_PASSIVE},
    {.name = "can_bus_off", .arm = arm_bus_off, .to = PS_SM_ESTOP, .cond = PS_SM_C_BUS_OFF,
     .within = 1, .watch_s = 0.2, .evidence = has_bus_mode, .evidence_arg = &BUS0_OFF,
     .check = check_power_cut},
    {.name = "actuator_silent", .arm = arm_silent_l_knee, .to = PS_SM_HOLD,
     .cond = PS_SM_C_REPLY_STALE, .within = REPLY_STALE_TICKS, .watch_s = 0.3},
    {.name = "actuator_fault_bits",
     .events = "  - {t_s: 1.5005, kind: drive_fault, joint: l_knee}\n",
     .to = PS_SM_ESTOP, .cond = PS_SM_C_DRIVE_FAULT, .within = 6, .watch_s = 0.2,
     .evidence = has_l_knee_fault_bits, .check = check_power_cut},
    {.name = "actuator_warm_derated", .arm = arm_warm_l_knee_full_feed_forward,
     .to = PS_SM_ACTIVE, .watch_s = 0.3, .evidence = has_l_knee_over_temp_band,
     .check = check_derated},
    {.name = "actuator_hot_damps", .arm = arm_hot_l_knee, .to = PS_SM_DAMPING,
     .cond = PS_SM_C_DRIVE_HOT, .within = 6, .watch_s = 0.15, .check = check_hot_no_start},
    {.name = "actuator_over_temperature", .arm = arm_overheat_l_knee, .to = PS_SM_ESTOP,
     .cond = PS_SM_C_DRIVE_FAULT, .within = 6, .watch_s = 0.2,
     .evidence = has_l_knee_over_temp, .check = check_power_cut},
    {.name = "actuator_warm_derated_robot_file", .is_thermal_robot = true,
     .arm = arm_warm_l_knee_robot_file_thresholds, .to = PS_SM_ACTIVE, .watch_s = 0.3,
     .evidence = has_l_knee_over_temp_band, .check = check_derated},
    {.name = "actuator_hot_damps_robot_file", .is_thermal_robot = true,
     .arm = arm_hot_l_knee_robot_file_thresholds, .to = PS_SM_DAMPING,
     .cond = PS_SM_C_DRIVE_HOT, .within = 6, .watch_s = 0.15, .check = check_hot_no_start},
    {.name = "imu_stale", .arm = arm_imu_drop, .to = PS_SM_HOLD, .cond = PS_SM_C_IMU_STALE,
     .within = IMU_STALE_TICKS, .watch_s = 0.2},
    {.name = "imu_frozen", .arm = arm_imu_frozen, .to = PS_SM_HOLD, .cond = PS_SM_C_IMU_STALE,
     .within = IMU_STALE_TICKS, .watch_s = 0.2, .check = check_imu_repeated},
    {.name = "imu_frozen_values", .arm = arm_imu_frozen_values, .to = PS_SM_HOLD,
     .cond = PS_SM_C_IMU_STALE, .within = IMU_FROZEN_TICKS, .watch_s = 0.2,
     .check = check_imu_frozen_values},
    {.name = "imu_nan", .arm = arm_imu_nan, .to = PS_SM_HOLD, .cond = PS_SM_C_IMU_STALE,
     .within = IMU_STALE_TICKS, .watch_s = 0.2, .check = check_imu_rejected},
    {.name = "imu_saturated", .arm = arm_imu_saturated, .to = PS_SM_HOLD,
     .cond = PS_SM_C_IMU_STALE, .within = IMU_STALE_TICKS, .watch_s = 0.2,
     .check = check_imu_rejected},
    {.name = "estop_press", .arm = arm_estop_held, .to = PS_SM_ESTOP,
     .cond = PS_SM_C_ESTOP_INPUT, .within = 1, .watch_s = 0.1, .evidence = is_estop_read,
     .check = check_power_cut},
    {.name = "estop_glitch", .arm = arm_estop_glitch, .to = PS_SM_ESTOP,
     .cond = PS_SM_C_ESTOP_INPUT, .within = 1, .watch_s = 0.1, .evidence = is_estop_read,
     .check = check_power_cut},
    {.name = "estop_bounce", .arm = arm_estop_bounce, .to = PS_SM_ESTOP,
     .cond = PS_SM_C_ESTOP_INPUT, .within = 1, .watch_s = 0.1, .evidence = is_estop_read,
     .check = check_bounce_then_reset},
    {.name = "heartbeat_write_fails", .arm = arm_heartbeat_fails, .to = PS_SM_ESTOP,
     .cond = PS_SM_C_ESTOP_INPUT, .within = 2, .watch_s = 0.1,
     .evidence = has_gpio_error_not_pressed, .check = check_heartbeat},
    {.name = "policy_nan", .arm = arm_policy_nan, .to = PS_SM_HOLD,
     .cond = PS_SM_C_TARGET_INVALID, .within = POLICY_TICKS, .watch_s = 0.2,
     .evidence = is_target_invalid_rec},
    {.name = "policy_inf", .arm = arm_policy_inf, .to = PS_SM_HOLD,
     .cond = PS_SM_C_TARGET_INVALID, .within = POLICY_TICKS, .watch_s = 0.2,
     .evidence = is_target_invalid_rec},
    {.name = "policy_out_of_range", .arm = arm_policy_out_of_range, .to = PS_SM_HOLD,
     .cond = PS_SM_C_TARGET_INVALID, .within = POLICY_TICKS, .watch_s = 0.2,
     .evidence = is_target_invalid_rec},
    {.name = "policy_late", .arm = arm_policy_late, .to = PS_SM_HOLD,
     .cond = PS_SM_C_POLICY_LATE, .within = POLICY_TICKS, .watch_s = 0.2,
     .evidence = is_policy_late_rec},
    {.name = "policy_stalled_30ms", .arm = arm_policy_stalled, .to = PS_SM_HOLD,
     .cond = PS_SM_C_POLICY_LATE, .within = POLICY_TICKS, .watch_s = 0.2,
     .evidence = is_policy_late_rec},
    /* overrun_limit 5 within 1 s: the sixth tick sees OVERRUN */
    {.name = "overrun_burst", .arm = arm_overrun_burst, .to = PS_SM_HOLD,
     .cond = PS_SM_C_OVERRUN, .within = 7, .watch_s = 0.2, .evidence = has_five_overruns},
    {.name = "perception_stale", .arm = arm_perception_stale, .to = PS_SM_ACTIVE,
     .watch_s = 0.2, .check = check_perception_stale},
    {.name = "perception_absurd", .arm = arm_perception_absurd, .to = PS_SM_ACTIVE,
     .watch_s = 0.2, .check = check_perception_absurd},
    {.name = "logger_stalled", .arm = arm_logger_stalled, .to = PS_SM_ESTOP,
     .cond = PS_SM_C_ESTOP_INPUT, .within = 1, .watch_s = 0.1, .evidence = is_estop_read,
     .check = check_logger_stalled},
    {.name = "recorder_writer_stalled", .ring_s = 0.1, .arm = arm_recorder_stalled_estop,
     .to = PS_SM_ESTOP, .cond = PS_SM_C_ESTOP_INPUT, .within = 1, .watch_s = 0.5,
     .check = check_recorder_stalled},
};
/* clang-format on */

/* ---- row: CLOCK_REALTIME jumps --------------------------------------------------- */

/* Every frame the loop sent and every state, hashed tick by tick (FNV-1a). */
static uint64_t run_hash(bool is_jumping)
{
    start_system(NULL, 4.0);
    uint64_t h = 1469598103934665603ull;
    while (loop_time_s() < 2.5) {
        if (is_jumping && fabs(loop_time_s() - 1.5) < 1e-9)
            realtime_offset_ns = 86400 * PS_NS_PER_S; /* a day ahead */
        if (is_jumping && fabs(loop_time_s() - 2.0) < 1e-9)
            realtime_offset_ns = -86400 * PS_NS_PER_S; /* a day behind */
        step();
        const uint8_t st = (uint8_t)app.loop.state;
        h = (h ^ st) * 1099511628211ull;
        for (uint32_t b = 0; b < app.board.n_buses; b++)
            for (uint32_t i = 0; i < app.loop.last.n_tx[b]; i++) {
                const ps_can_frame_t *f = &app.loop.tx_buf[b][i];
                for (uint32_t x = 0; x < f->len; x++)
                    h = (h ^ f->data[x]) * 1099511628211ull;
                h = (h ^ f->id) * 1099511628211ull;
            }
    }
    assert_int_equal(app.loop.state, PS_SM_ACTIVE);
    assert_int_equal(app.loop.counters.n_transitions, 2); /* RAMP, ACTIVE: nothing else */
    assert_commands_clean();
    realtime_offset_ns = 0;
    teardown(NULL);
    return h;
}

static void test_fault_clock_realtime_jump_changes_nothing(void **state)
{
    (void)state;
    begin_row("clock_realtime_jump", "ACTIVE");
    const uint64_t h0 = run_hash(false);
    n_realtime_reads = 0;
    const uint64_t h1 = run_hash(true);
    print_message("      frames and states identical: %s (CLOCK_REALTIME read %llu times)\n",
                  h0 == h1 ? "yes" : "no", (unsigned long long)n_realtime_reads);
    assert_true(h0 == h1);
    row_done();
}

/* ---- row: a configuration reload asked for while ACTIVE ------------------------ */

extern char **environ;

static double mono_s(void)
{
    struct timespec ts;
    (void)clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* pushstep itself (lockstep, 8 s standing): SIGHUP twice once the logger
 * printed RAMP -> ACTIVE. Both are refused and said so, naming the state;
 * the run goes on to its end exactly as without them (the same transitions
 * at the same times), exit status 0. Before, SIGHUP's default action ended
 * the process unbraked. */
static void test_fault_config_reload_refused_while_active(void **state)
{
    (void)state;
    begin_row("config_reload_while_active", "ACTIVE");
    char sum[64];
    ps_cli_temp_file(sum, sizeof(sum));
    char *argv[] = {(char *)ps_cli_bin(),   "--lockstep", "--duration", "8", "--scenario",
                    "scenarios/stand.yaml", "--summary",  sum,          NULL};
    pid_t pid;
    const int rd = ps_cli_spawn_piped(argv, &pid);
    static char out[64 * 1024];
    size_t n = 0;
    int n_sent = 0;
    const double t0 = mono_s();
    for (bool is_eof = false; !is_eof && mono_s() - t0 < 60;) {
        if (n_sent < 2 && strstr(out, "RAMP -> ACTIVE") != NULL) {
            assert_int_equal(kill(pid, SIGHUP), 0);
            n_sent++;
        }
        struct pollfd pfd = {.fd = rd, .events = POLLIN};
        if (poll(&pfd, 1, 20) > 0) {
            const ssize_t got = read(rd, out + n, sizeof(out) - 1 - n);
            is_eof = got <= 0;
            n += got > 0 ? (size_t)got : 0;
            out[n] = '\0';
        }
    }
    close(rd);
    int status = 0;
    assert_int_equal(waitpid(pid, &status, 0), pid);
    ps_san_assert_no_report(out);
    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
        fail_msg("pushstep did not exit 0 (status 0x%x):\n%s", status, out);
    assert_int_equal(n_sent, 2);
    const char *said = "config reload refused (SIGHUP) in ACTIVE";
    const char *p = strstr(out, said);
    if (p == NULL)
        fail_msg("no \"%s\" in:\n%s", said, out);
    cJSON *j = ps_cli_read_json(sum);
    (void)unlink(sum);
    assert_true(ps_cli_num(j, "loop_s") >= 8.0);
    const cJSON *tr = ps_cli_obj(j, "transitions");
    assert_int_equal(cJSON_GetArraySize(tr), 4); /* RAMP, ACTIVE, DAMPING at 8 s, STANDBY */
    const cJSON *stop = cJSON_GetArrayItem(tr, 2);
    assert_string_equal(cJSON_GetStringValue(ps_cli_obj(stop, "to")), "DAMPING");
    assert_string_equal(cJSON_GetStringValue(ps_cli_obj(stop, "conditions")), "REQ_STOP");
    assert_true(ps_cli_num(stop, "t_s") >= 8.0); /* the end of the run, not the signal */
    cJSON_Delete(j);
    row_done();
}

/* ---- the figures ------------------------------------------------------------------- */

static int print_figures(void **state)
{
    (void)state;
    unsigned n_ok = 0;
    for (unsigned i = 0; i < n_outcomes; i++)
        n_ok += outcomes[i].is_as_expected;
    print_message("fault matrix: %u faults injected, %u ended in the expected state (%.0f %%)\n",
                  n_outcomes, n_ok, n_outcomes ? 100.0 * n_ok / n_outcomes : 0.0);
    if (thermal_robot[0] != '\0')
        (void)unlink(thermal_robot);
    const char *path = getenv("PUSHSTEP_FAULTS_JSON");
    if (path == NULL || path[0] == '\0')
        return 0;
    FILE *f = fopen(path, "w");
    if (f == NULL) {
        print_error("cannot write %s: %s\n", path, strerror(errno));
        return -1;
    }
    fprintf(f, "{\n  \"faults_injected\": %u,\n  \"ended_as_expected\": %u,\n", n_outcomes, n_ok);
    fprintf(f, "  \"share_as_expected\": %.4f,\n  \"rows\": [\n",
            n_outcomes ? (double)n_ok / n_outcomes : 0.0);
    for (unsigned i = 0; i < n_outcomes; i++)
        fprintf(f,
                "    {\"fault\": \"%s\", \"expected\": \"%s\", \"as_expected\": %s, "
                "\"ticks_to_state\": %lld}%s\n",
                outcomes[i].name, outcomes[i].expected,
                outcomes[i].is_as_expected ? "true" : "false",
                (long long)outcomes[i].ticks_to_state, i + 1 < n_outcomes ? "," : "");
    fprintf(f, "  ]\n}\n");
    return fclose(f) == 0 ? 0 : -1;
}

#define N_ROWS (sizeof(ROWS) / sizeof(ROWS[0]))

/* Test names: test_fault_<row> (cmocka keeps the pointer). */
static char test_names[N_ROWS][64];

int main(void)
{
    struct CMUnitTest tests[N_ROWS + 2];
    for (size_t i = 0; i < N_ROWS; i++) {
        snprintf(test_names[i], sizeof(test_names[i]), "test_fault_%s", ROWS[i].name);
        tests[i] = (struct CMUnitTest){.name = test_names[i],
                                       .test_func = run_row,
                                       .teardown_func = teardown,
                                       .initial_state = (void *)&ROWS[i]};
    }
    tests[N_ROWS] = (struct CMUnitTest)cmocka_unit_test_teardown(
        test_fault_clock_realtime_jump_changes_nothing, teardown);
    tests[N_ROWS + 1] =
        (struct CMUnitTest)cmocka_unit_test(test_fault_config_reload_refused_while_active);
    return _cmocka_run_group_tests("e2e_faults", tests, N_ROWS + 2, NULL, print_figures);
}
