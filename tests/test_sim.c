/*
 * Tests of sim/ps_sim.c end to end: the MuJoCo plant (sim/ps_plant.c), the
 * simulated buses and GPIO, and the emulated devices, driven by a tiny
 * test-local "controller" that talks to the host CAN ports exactly as the
 * loop does (ENTER, then MIT PD at the stance, replies and IMU frames in)
 * and paces itself with the sim clock's sleep_until. Run from the repo root;
 * needs boards/sim.yaml, robots/ps1.yaml and sim/models/ps1.xml.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "../drivers/ps_imu_msg.h"
#include "../drivers/ps_mit.h"
#include "../rt/ps_app.h"
#include "../rt/ps_clock.h"
#include "../rt/ps_config.h"
#include "../rt/ps_config_sim.h"
#include "../rt/ps_err.h"
#include "../rt/ps_sm.h"
#include "../sim/ps_gpio_sim.h"
#include "../sim/ps_sim.h"

#define BOARD_PATH "boards/sim.yaml"
#define ROBOT_PATH "robots/ps1.yaml"
#define PERIOD_NS  PS_NS_PER_MS
#define START_NS   (5 * PS_NS_PER_S) /* arbitrary epoch, not 0 */

typedef struct {
    ps_board_cfg_t board;
    ps_robot_cfg_t robot;
    ps_sim_board_t sim_board; /* the two as the composition root hands them to the sim */
    ps_sim_robot_t sim_robot;
    ps_sim_devices_cfg_t devices; /* the robot file's sim: section */
    ps_scenario_cfg_t sc;
    char model[2 * PS_PATH_LEN];
} fixture_t;

static int setup(void **state)
{
    static fixture_t fx;
    char err[PS_ERR_MSG_LEN];
    memset(&fx, 0, sizeof fx);
    if (ps_config_load_board(BOARD_PATH, &fx.board, err, sizeof err) != 0 ||
        ps_config_load_robot_sim(ROBOT_PATH, &fx.robot, &fx.devices, err, sizeof err) != 0) {
        fprintf(stderr, "setup: %s\n", err);
        return -1;
    }
    if (fx.robot.model[0] == '/' || access(fx.robot.model, R_OK) == 0)
        (void)snprintf(fx.model, sizeof fx.model, "%s", fx.robot.model);
    else
        (void)snprintf(fx.model, sizeof fx.model, "robots/%s", fx.robot.model);
    strcpy(fx.sc.name, "test");
    fx.sc.seed = 1;
    *state = &fx;
    return 0;
}

static void add_event(ps_scenario_cfg_t *sc, float t_s, ps_event_kind_t kind)
{
    ps_event_cfg_t *e = &sc->events[sc->n_events++];
    memset(e, 0, sizeof *e);
    e->t_s = t_s;
    e->kind = kind;
}

static ps_sim_cfg_t sim_cfg(fixture_t *fx, bool is_lockstep)
{
    ps_app_sim_board(&fx->board, &fx->sim_board);
    ps_app_sim_robot(&fx->robot, &fx->devices, &fx->sim_robot);
    return (ps_sim_cfg_t){.board = &fx->sim_board,
                          .robot = &fx->sim_robot,
                          .scenario = &fx->sc,
                          .model_path = fx->model,
                          .is_lockstep = is_lockstep,
                          .period_ns = PERIOD_NS};
}

/* ---- the test-local controller ---------------------------------------- */

#define MAX_LOG 4096

typedef struct {
    ps_sim_t *sim;
    const ps_robot_cfg_t *robot;
    const ps_clock_t *clk;
    ps_can_port_t port[PS_MAX_BUSES];
    uint32_t n_buses;
    ps_gpio_port_t gpio;
    ps_imu_msg_rx_t imu_rx;
    int64_t t_ns; /**< the current tick's start */
    uint64_t tick;
    double q_rad[PS_MAX_JOINTS];
    uint64_t n_replies[PS_MAX_JOINTS];
    uint64_t n_bad_motor_id;
    uint64_t n_unknown_frames;
    uint64_t n_imu;
    int64_t last_reply_t_ns[PS_MAX_JOINTS];
    float gyro_y_rad_s; /**< latest pitch rate, fed back at the ankles */
    uint64_t imu_hash;  /**< FNV-1a over all IMU frame bytes */
    uint32_t requests_seen;
    int64_t request_t_ns[3]; /**< first time START, STOP, RESET were taken */
    unsigned n_request_takes[3];
    bool is_heartbeat_stopped; /**< test may set: no more heartbeat writes */
    bool is_heartbeat_steady;  /**< test may set: write a steady high level */
} ctl_t;

static void ctl_init(ctl_t *c, ps_sim_t *sim, const ps_robot_cfg_t *robot, uint32_t n_buses)
{
    memset(c, 0, sizeof *c);
    c->sim = sim;
    c->robot = robot;
    c->clk = ps_sim_clock(sim);
    c->n_buses = n_buses;
    for (uint32_t b = 0; b < n_buses; b++)
        c->port[b] = ps_sim_can_port(sim, b);
    c->gpio = ps_sim_gpio_port(sim);
    ps_imu_msg_rx_init(&c->imu_rx, robot->imu.base_id);
    for (unsigned i = 0; i < 3; i++)
        c->request_t_ns[i] = -1;
}

static void ctl_read(ctl_t *c)
{
    for (uint32_t b = 0; b < c->n_buses; b++) {
        ps_can_frame_t f[64];
        int n;
        while ((n = ps_can_recv_batch(&c->port[b], f, 64)) > 0) {
            for (int i = 0; i < n; i++) {
                ps_imu_sample_t s;
                const int r = ps_imu_msg_rx_feed(&c->imu_rx, &f[i], &s);
                if (r != -ENOENT) {
                    for (unsigned k = 0; k < 8; k++)
                        c->imu_hash = (c->imu_hash ^ f[i].data[k]) * 1099511628211ull;
                    if (r == 1) {
                        c->n_imu++;
                        c->gyro_y_rad_s = s.gyro_body_rad_s[1];
                    }
                    continue;
                }
                bool is_known = false;
                for (uint32_t j = 0; j < c->robot->n_joints; j++) {
                    const ps_act_cfg_t *jc = &c->robot->act[j];
                    if (jc->bus_idx != b || jc->reply_id != f[i].id)
                        continue;
                    ps_mit_reply_t rep;
                    assert_int_equal(ps_mit_decode_reply(&jc->wire, f[i].data, f[i].len, &rep), 0);
                    if (rep.motor_id != (jc->can_id & 0xFu))
                        c->n_bad_motor_id++;
                    c->q_rad[j] = rep.p_rad;
                    c->n_replies[j]++;
                    c->last_reply_t_ns[j] = f[i].t_ns;
                    is_known = true;
                    break;
                }
                if (!is_known)
                    c->n_unknown_frames++;
            }
            if (n < 64)
                break;
        }
    }
}

static float clampf(float x, float lo, float hi)
{
    return x < lo ? lo : (x > hi ? hi : x);
}

/* ENTER on tick 0, then PD at the stance every rate_div ticks; the ankle
 * pitch joints add a small damping term on the measured pitch rate, so the
 * IMU (and its seeded noise) feeds back into the motion. */
static void ctl_write(ctl_t *c)
{
    ps_can_frame_t out[PS_MAX_BUSES][PS_MAX_JOINTS];
    size_t n_out[PS_MAX_BUSES] = {0};
    for (uint32_t j = 0; j < c->robot->n_joints; j++) {
        const ps_act_cfg_t *jc = &c->robot->act[j];
        const ps_servo_joint_cfg_t *jc_s = &c->robot->servo[j];
        if (c->tick != 0 && c->tick % jc->rate_div != 0)
            continue;
        ps_can_frame_t *f = &out[jc->bus_idx][n_out[jc->bus_idx]++];
        memset(f, 0, sizeof *f);
        f->id = jc->can_id;
        f->len = PS_MIT_FRAME_LEN;
        if (c->tick == 0) {
            ps_mit_encode_special(PS_MIT_SPECIAL_ENTER, f->data);
            continue;
        }
        float t_ff = 0.0f;
        if (strstr(c->robot->joint_name[j], "ankle_pitch") != NULL)
            t_ff =
                clampf(-2.0f * c->gyro_y_rad_s, -jc_s->lim.torque_max_nm, jc_s->lim.torque_max_nm);
        const ps_mit_cmd_t cmd = {
            .p_rad = clampf(jc_s->stance_rad, jc_s->lim.pos_min_rad, jc_s->lim.pos_max_rad),
            .v_rad_s = 0.0f,
            .kp_nm_rad = fminf(jc_s->kp_nm_rad, jc_s->lim.kp_max_nm_rad),
            .kd_nm_s_rad = fminf(jc_s->kd_nm_s_rad, jc_s->lim.kd_max_nm_s_rad),
            .t_ff_nm = t_ff,
        };
        assert_int_equal(ps_mit_encode_cmd(&jc->wire, &cmd, f->data), 0);
    }
    for (uint32_t b = 0; b < c->n_buses; b++) {
        if (n_out[b] > 0)
            assert_int_equal(ps_can_send_batch(&c->port[b], out[b], n_out[b]), (int)n_out[b]);
    }
    /* the power relay's heartbeat, as the loop beats it (or a stuck level) */
    if (!c->is_heartbeat_stopped)
        assert_int_equal(ps_gpio_set_heartbeat(&c->gpio, c->is_heartbeat_steady || (c->tick & 1u)),
                         0);
}

static void ctl_take_requests(ctl_t *c)
{
    const uint32_t r = ps_sim_take_requests(c->sim);
    const uint32_t bits[3] = {PS_SM_C_REQ_START, PS_SM_C_REQ_STOP, PS_SM_C_REQ_RESET};
    for (unsigned i = 0; i < 3; i++) {
        if (r & bits[i]) {
            c->n_request_takes[i]++;
            if (c->request_t_ns[i] < 0)
                c->request_t_ns[i] = c->t_ns;
        }
    }
    c->requests_seen |= r;
}

/* One loop tick at c->t_ns, then sleep to the next. */
static void ctl_tick(ctl_t *c)
{
    ctl_read(c);
    ctl_take_requests(c);
    ctl_write(c);
    c->tick++;
    c->t_ns += PERIOD_NS;
    const int rc = ps_clock_sleep_until_ns(c->clk, c->t_ns);
    assert_true(rc == 0 || rc == -EINTR);
}

static void ctl_run_until(ctl_t *c, int64_t rel_ns)
{
    while (c->t_ns < START_NS + rel_ns)
        ctl_tick(c);
}

static ps_sim_t *make_lockstep(fixture_t *fx, ctl_t *c)
{
    const ps_sim_cfg_t cfg = sim_cfg(fx, true);
    ps_sim_t *sim = NULL;
    char err[PS_ERR_MSG_LEN] = "";
    const int rc = ps_sim_create(&cfg, &sim, err, sizeof err);
    if (rc != 0)
        fail_msg("ps_sim_create: %d %s", rc, err);
    assert_int_equal(ps_sim_start(sim, START_NS), 0);
    ctl_init(c, sim, &fx->robot, fx->board.n_buses);
    c->t_ns = START_NS;
    assert_int_equal(ps_clock_now_ns(c->clk), START_NS);
    return sim;
}

/* ---- create errors ------------------------------------------------------ */

static void test_create_unknown_push_body_config_error_names_it(void **state)
{
    fixture_t *fx = *state;
    fx->sc.n_pushes = 1;
    fx->sc.pushes[0] = (ps_push_cfg_t){.t_s = 1.0f, .duration_s = 0.1f, .body = "no_such_body"};
    const ps_sim_cfg_t cfg = sim_cfg(fx, true);
    ps_sim_t *sim = NULL;
    char err[PS_ERR_MSG_LEN] = "";
    assert_int_equal(ps_sim_create(&cfg, &sim, err, sizeof err), -PS_ERR_CONFIG);
    assert_null(sim);
    assert_non_null(strstr(err, "no_such_body"));
}

/* A push body the model lacks, loaded from a file: the message names the
 * scenario file and the line of pushes[1].body, like every config error. */
static void test_create_unknown_push_body_from_file_names_file_and_line(void **state)
{
    fixture_t *fx = *state;
    char path[] = "/tmp/ps_test_sim_scenario.XXXXXX";
    const int fd = mkstemp(path);
    assert_true(fd >= 0);
    static const char TEXT[] = "name: bad_body\n"
                               "duration_s: 2\n"
                               "seed: 1\n"
                               "pushes:\n"
                               "  - {t_s: 0.5, duration_s: 0.1, body: pelvis, force_n: [1, 0, 0]}\n"
                               "  - t_s: 1.0\n"
                               "    duration_s: 0.1\n"
                               "    body: no_such_body\n"
                               "    force_n: [0, 1, 0]\n";
    assert_int_equal(write(fd, TEXT, sizeof TEXT - 1u), (ssize_t)(sizeof TEXT - 1u));
    assert_int_equal(close(fd), 0);
    char err[PS_ERR_MSG_LEN] = "";
    const int rc = ps_config_load_scenario(path, &fx->sc, err, sizeof err);
    (void)unlink(path);
    assert_int_equal(rc, 0);
    const ps_sim_cfg_t cfg = sim_cfg(fx, true);
    ps_sim_t *sim = NULL;
    assert_int_equal(ps_sim_create(&cfg, &sim, err, sizeof err), -PS_ERR_CONFIG);
    assert_null(sim);
    char want[PS_ERR_MSG_LEN];
    (void)snprintf(want, sizeof want,
                   "%s:8: pushes[1].body: 'no_such_body' is not a body of the model", path);
    assert_string_equal(err, want);
}

static void test_create_unknown_drop_joint_config_error_names_it(void **state)
{
    fixture_t *fx = *state;
    add_event(&fx->sc, 0.1f, PS_EVENT_DROP_REPLIES);
    strcpy(fx->sc.events[0].joint, "no_such_joint");
    const ps_sim_cfg_t cfg = sim_cfg(fx, true);
    ps_sim_t *sim = NULL;
    char err[PS_ERR_MSG_LEN] = "";
    assert_int_equal(ps_sim_create(&cfg, &sim, err, sizeof err), -PS_ERR_CONFIG);
    assert_non_null(strstr(err, "no_such_joint"));
}

static void test_create_bad_model_path_plant_error(void **state)
{
    fixture_t *fx = *state;
    strcpy(fx->model, "sim/models/does_not_exist.xml");
    const ps_sim_cfg_t cfg = sim_cfg(fx, true);
    ps_sim_t *sim = NULL;
    char err[PS_ERR_MSG_LEN] = "";
    assert_int_equal(ps_sim_create(&cfg, &sim, err, sizeof err), -PS_ERR_PLANT);
    assert_true(strlen(err) > 0);
}

static void test_create_joint_bus_missing_config_error(void **state)
{
    fixture_t *fx = *state;
    fx->robot.act[0].bus_idx = fx->board.n_buses;
    const ps_sim_cfg_t cfg = sim_cfg(fx, true);
    ps_sim_t *sim = NULL;
    char err[PS_ERR_MSG_LEN] = "";
    assert_int_equal(ps_sim_create(&cfg, &sim, err, sizeof err), -PS_ERR_CONFIG);
    assert_non_null(strstr(err, fx->robot.joint_name[0]));
}

static void test_create_null_cfg_einval(void **state)
{
    (void)state;
    ps_sim_t *sim = NULL;
    assert_int_equal(ps_sim_create(NULL, &sim, NULL, 0), -EINVAL);
}

static void test_get_actuator_bad_index_einval(void **state)
{
    fixture_t *fx = *state;
    ctl_t c;
    ps_sim_t *sim = make_lockstep(fx, &c);
    ps_devices_actuator_t a;
    assert_int_equal(ps_sim_get_actuator(sim, fx->robot.n_joints, &a), -EINVAL);
    assert_int_equal(ps_sim_get_actuator(sim, 0, &a), 0);
    assert_false(a.is_motor_mode);
    assert_int_equal(ps_sim_start(sim, START_NS), -EBUSY);
    ps_sim_destroy(sim);
}

/* ---- lockstep ----------------------------------------------------------- */

static void test_lockstep_replies_and_imu_arrive_with_right_ids(void **state)
{
    fixture_t *fx = *state;
    ctl_t c;
    ps_sim_t *sim = make_lockstep(fx, &c);
    ctl_run_until(&c, 200 * PS_NS_PER_MS);
    assert_int_equal(ps_clock_now_ns(c.clk), START_NS + 200 * PS_NS_PER_MS);
    for (uint32_t j = 0; j < fx->robot.n_joints; j++) {
        /* ENTER + one command every rate_div ticks, each answered. */
        const uint64_t want = 1 + (200 - 1) / fx->robot.act[j].rate_div;
        if (c.n_replies[j] + 2 < want || c.n_replies[j] > want)
            fail_msg("joint %s: %llu replies, want ~%llu", fx->robot.joint_name[j],
                     (unsigned long long)c.n_replies[j], (unsigned long long)want);
        /* A reply arrives after its command: within the tick it was sent in. */
        assert_true(c.last_reply_t_ns[j] > START_NS);
        ps_devices_actuator_t a;
        assert_int_equal(ps_sim_get_actuator(sim, j, &a), 0);
        assert_true(a.is_motor_mode);
        /* The reply carries the joint angle: near the stance. */
        assert_true(fabs(c.q_rad[j] - fx->robot.servo[j].stance_rad) < 0.1);
    }
    assert_int_equal(c.n_bad_motor_id, 0);
    assert_int_equal(c.n_unknown_frames, 0);
    const uint64_t want_imu = 200 / fx->robot.imu.rate_div;
    assert_true(c.n_imu + 1 >= want_imu && c.n_imu <= want_imu);

    ps_sim_truth_t t;
    ps_sim_get_truth(sim, &t);
    assert_true(fabs(t.t_s - 0.2) < 1e-9);
    /* Whole periods of physics, at least one step each. */
    assert_true(t.n_steps >= 200 && t.n_steps % 200 == 0);
    assert_true(t.n_cmd_frames > 0);
    assert_int_equal(t.n_cmd_out_of_limits, 0);
    assert_int_equal(t.n_bad_frames, 0);
    assert_int_equal(t.n_cmd_ignored, 0);
    assert_int_equal(t.n_dev_tx_dropped, 0);
    assert_int_equal(t.n_imu_samples, want_imu); /* the last may still be on the wire */
    assert_int_equal(t.plant_err, 0);
    ps_sim_destroy(sim);
}

/* A model too small for the robot's contacts: the plant's error and its
 * reason reach the truth, and physics stops there. */
static void test_lockstep_contacts_beyond_nconmax_plant_err_in_truth(void **state)
{
    fixture_t *fx = *state;
    FILE *in = fopen(fx->model, "r");
    assert_non_null(in);
    static char text[128 * 1024];
    const size_t n = fread(text, 1, sizeof text - 1, in);
    text[n] = '\0';
    (void)fclose(in);
    char *sz = strstr(text, "nconmax=\"150\"");
    assert_non_null(sz);
    memcpy(sz, "nconmax=\"2\"  ", strlen("nconmax=\"150\"")); /* same length */
    char path[] = "/tmp/test_sim_nconmax_XXXXXX.xml";
    const int fd = mkstemps(path, 4);
    assert_true(fd >= 0);
    assert_int_equal(write(fd, text, n), (ssize_t)n);
    assert_int_equal(close(fd), 0);
    (void)snprintf(fx->model, sizeof fx->model, "%s", path);
    ctl_t c;
    ps_sim_t *sim = make_lockstep(fx, &c);
    ctl_run_until(&c, 50 * PS_NS_PER_MS);
    (void)unlink(path);
    ps_sim_truth_t t;
    ps_sim_get_truth(sim, &t);
    assert_int_equal(t.plant_err, -PS_ERR_PLANT);
    assert_non_null(t.plant_err_reason);
    assert_non_null(strstr(t.plant_err_reason, "nconmax"));
    assert_true(t.plant_err_t_s >= 0.0 && t.plant_err_t_s < 0.05);
    assert_true(t.n_steps < 100); /* physics stopped at the error */
    ps_sim_destroy(sim);
}

/* A loop that stops ticking stops the heartbeat: the watchdog relay cuts
 * the drives' power within its timeout and they give no torque, though
 * commands still arrive. */
static void test_lockstep_heartbeat_stops_drives_limp_within_relay_timeout(void **state)
{
    fixture_t *fx = *state;
    ctl_t c;
    ps_sim_t *sim = make_lockstep(fx, &c);
    ctl_run_until(&c, 200 * PS_NS_PER_MS);
    ps_sim_truth_t t;
    ps_sim_get_truth(sim, &t);
    assert_true(t.is_drive_power_on);
    assert_true(t.tau_abs_sum_nm > 1.0); /* the PD holds the stance in the harness */
    c.is_heartbeat_stopped = true;
    const int64_t t_stop = c.t_ns;
    int64_t t_off = -1;
    while (c.t_ns < t_stop + 3 * PS_GPIO_SIM_RELAY_TIMEOUT_NS) {
        ctl_tick(&c);
        ps_sim_get_truth(sim, &t);
        if (!t.is_drive_power_on && t_off < 0) {
            t_off = c.t_ns;
            assert_true(t.tau_abs_sum_nm == 0.0);
        }
    }
    assert_true(t_off > t_stop);
    assert_true(t_off <= t_stop + PS_GPIO_SIM_RELAY_TIMEOUT_NS + PERIOD_NS);
    assert_int_equal(t.n_power_cuts, 1);
    assert_true(t.tau_abs_sum_nm == 0.0);
    ps_devices_actuator_t a;
    assert_int_equal(ps_sim_get_actuator(sim, 0, &a), 0);
    assert_true(a.is_motor_mode); /* the drive's logic still runs and obeys */
    ps_sim_destroy(sim);
}

/* A steady enable-style level written every tick keeps no power on. */
static void test_lockstep_steady_heartbeat_level_no_drive_power(void **state)
{
    fixture_t *fx = *state;
    ctl_t c;
    ps_sim_t *sim = make_lockstep(fx, &c);
    c.is_heartbeat_steady = true;
    ctl_run_until(&c, 100 * PS_NS_PER_MS);
    ps_sim_truth_t t;
    ps_sim_get_truth(sim, &t);
    assert_false(t.is_drive_power_on);
    assert_true(t.tau_abs_sum_nm == 0.0);
    ps_sim_destroy(sim);
}

static void test_lockstep_stands_5s_after_harness_release(void **state)
{
    fixture_t *fx = *state;
    add_event(&fx->sc, 0.5f, PS_EVENT_HARNESS_RELEASE);
    ctl_t c;
    ps_sim_t *sim = make_lockstep(fx, &c);
    ps_sim_truth_t t0, t;
    ctl_run_until(&c, 500 * PS_NS_PER_MS);
    ps_sim_get_truth(sim, &t0);
    struct timespec w0, w1;
    clock_gettime(CLOCK_MONOTONIC, &w0);
    ctl_run_until(&c, 5500 * PS_NS_PER_MS);
    clock_gettime(CLOCK_MONOTONIC, &w1);
    ps_sim_get_truth(sim, &t);
    const double wall_s =
        (double)(w1.tv_sec - w0.tv_sec) + 1e-9 * (double)(w1.tv_nsec - w0.tv_nsec);
    printf("lockstep with controller: %.1f simulated s per wall s\n", 5.0 / wall_s);
    assert_false(t.is_fallen);
    assert_int_equal(t.plant_err, 0);
    assert_true(t.head_height_m > 0.9 * t0.head_height_m);
    assert_true(t.com_m[2] > 0.9 * t0.com_m[2]);
    assert_int_equal(t.n_cmd_out_of_limits, 0);
    assert_int_equal(t.n_bad_frames, 0);
    ps_sim_destroy(sim);
}

static void test_lockstep_estop_events_toggle_gpio(void **state)
{
    fixture_t *fx = *state;
    add_event(&fx->sc, 0.1f, PS_EVENT_ESTOP_PRESS);
    add_event(&fx->sc, 0.2f, PS_EVENT_ESTOP_RELEASE);
    ctl_t c;
    ps_sim_t *sim = make_lockstep(fx, &c);
    int64_t first_pressed = -1, first_released = -1;
    while (c.t_ns < START_NS + 300 * PS_NS_PER_MS) {
        bool is_pressed = true;
        assert_int_equal(ps_gpio_read_estop(&c.gpio, &is_pressed), 0);
        const int64_t rel = c.t_ns - START_NS;
        if (is_pressed && first_pressed < 0)
            first_pressed = rel;
        if (!is_pressed && first_pressed >= 0 && first_released < 0)
            first_released = rel;
        ctl_tick(&c);
    }
    /* Seen by the first tick after the event time (events act at physics steps). */
    assert_true(first_pressed >= 100 * PS_NS_PER_MS && first_pressed <= 101 * PS_NS_PER_MS);
    assert_true(first_released >= 200 * PS_NS_PER_MS && first_released <= 201 * PS_NS_PER_MS);
    ps_sim_destroy(sim);
}

static void test_lockstep_requests_taken_once_at_their_times(void **state)
{
    fixture_t *fx = *state;
    add_event(&fx->sc, 0.05f, PS_EVENT_START);
    add_event(&fx->sc, 0.10f, PS_EVENT_STOP);
    add_event(&fx->sc, 0.15f, PS_EVENT_RESET);
    ctl_t c;
    ps_sim_t *sim = make_lockstep(fx, &c);
    ctl_run_until(&c, 200 * PS_NS_PER_MS);
    const int64_t want[3] = {50, 100, 150};
    for (unsigned i = 0; i < 3; i++) {
        assert_int_equal(c.n_request_takes[i], 1);
        const int64_t rel = c.request_t_ns[i] - START_NS;
        if (rel < want[i] * PS_NS_PER_MS || rel > (want[i] + 1) * PS_NS_PER_MS)
            fail_msg("request %u taken at %lld ns", i, (long long)rel);
    }
    assert_int_equal(ps_sim_take_requests(sim), 0);
    ps_sim_destroy(sim);
}

static void run_push(fixture_t *fx, bool has_push, ps_sim_truth_t *out)
{
    fx->sc.n_events = 0;
    add_event(&fx->sc, 0.2f, PS_EVENT_HARNESS_RELEASE);
    fx->sc.n_pushes = has_push ? 1u : 0u;
    fx->sc.pushes[0] = (ps_push_cfg_t){
        .t_s = 0.5f, .duration_s = 0.1f, .body = "pelvis", .force_n = {80.0f, 0.0f, 0.0f}};
    ctl_t c;
    ps_sim_t *sim = make_lockstep(fx, &c);
    ctl_run_until(&c, 700 * PS_NS_PER_MS);
    ps_sim_get_truth(sim, out);
    ps_sim_destroy(sim);
}

static void test_lockstep_push_moves_com_forward(void **state)
{
    fixture_t *fx = *state;
    ps_sim_truth_t quiet, pushed;
    run_push(fx, false, &quiet);
    run_push(fx, true, &pushed);
    /* 80 N x 0.1 s on ~38 kg: ~0.2 m/s of CoM velocity, ~1 cm in 0.1 s after. */
    assert_true(pushed.com_m[0] - quiet.com_m[0] > 0.005);
    assert_true(fabs(pushed.com_m[1] - quiet.com_m[1]) < pushed.com_m[0] - quiet.com_m[0]);
}

static void test_lockstep_drop_replies_event_silences_one_joint(void **state)
{
    fixture_t *fx = *state;
    add_event(&fx->sc, 0.1f, PS_EVENT_DROP_REPLIES);
    strcpy(fx->sc.events[0].joint, fx->robot.joint_name[0]);
    fx->sc.events[0].duration_s = 0.1f;
    ctl_t c;
    ps_sim_t *sim = make_lockstep(fx, &c);
    ctl_run_until(&c, 110 * PS_NS_PER_MS);
    const uint64_t n0 = c.n_replies[0], n1 = c.n_replies[1];
    ctl_run_until(&c, 190 * PS_NS_PER_MS);
    assert_int_equal(c.n_replies[0], n0);  /* silent */
    assert_true(c.n_replies[1] > n1 + 20); /* the others go on */
    ctl_run_until(&c, 250 * PS_NS_PER_MS);
    assert_true(c.n_replies[0] > n0 + 10); /* and it comes back */
    ps_devices_actuator_t a;
    assert_int_equal(ps_sim_get_actuator(sim, 0, &a), 0);
    assert_true(a.n_replies_dropped > 30);
    assert_true(a.is_motor_mode); /* commands were still obeyed */
    ps_sim_destroy(sim);
}

typedef struct {
    ps_sim_truth_t truth;
    uint64_t imu_hash;
} run_result_t;

static void run_seeded(fixture_t *fx, uint32_t seed, run_result_t *out)
{
    fx->sc.seed = seed;
    fx->sc.n_events = 0;
    add_event(&fx->sc, 0.1f, PS_EVENT_HARNESS_RELEASE);
    ctl_t c;
    ps_sim_t *sim = make_lockstep(fx, &c);
    ctl_run_until(&c, 1000 * PS_NS_PER_MS);
    ps_sim_get_truth(sim, &out->truth);
    out->imu_hash = c.imu_hash;
    ps_sim_destroy(sim);
}

static bool truth_equal(const ps_sim_truth_t *a, const ps_sim_truth_t *b)
{
    return memcmp(&a->t_s, &b->t_s, sizeof a->t_s) == 0 &&
           memcmp(a->com_m, b->com_m, sizeof a->com_m) == 0 &&
           memcmp(a->pelvis_m, b->pelvis_m, sizeof a->pelvis_m) == 0 &&
           memcmp(&a->head_height_m, &b->head_height_m, sizeof a->head_height_m) == 0 &&
           memcmp(&a->max_temp_c, &b->max_temp_c, sizeof a->max_temp_c) == 0 &&
           a->n_steps == b->n_steps && a->n_cmd_frames == b->n_cmd_frames;
}

static void test_lockstep_same_seed_bit_identical_other_seed_differs(void **state)
{
    fixture_t *fx = *state;
    static run_result_t r1, r2, r3;
    run_seeded(fx, 7, &r1);
    run_seeded(fx, 7, &r2);
    run_seeded(fx, 8, &r3);
    assert_true(truth_equal(&r1.truth, &r2.truth));
    assert_true(r1.imu_hash == r2.imu_hash);
    assert_false(truth_equal(&r1.truth, &r3.truth));
    assert_true(r1.imu_hash != r3.imu_hash);
}

/* ---- real time ---------------------------------------------------------- */

static void test_realtime_smoke_sees_replies(void **state)
{
    fixture_t *fx = *state;
    if (getenv("PS_QEMU_USER") != NULL)
        skip(); /* real time: the plant under qemu-user runs ~150x slower than the host */
    const ps_sim_cfg_t cfg = sim_cfg(fx, false);
    ps_sim_t *sim = NULL;
    char err[PS_ERR_MSG_LEN] = "";
    assert_int_equal(ps_sim_create(&cfg, &sim, err, sizeof err), 0);
    ctl_t c;
    ctl_init(&c, sim, &fx->robot, fx->board.n_buses);
    assert_ptr_equal(c.clk, ps_clock_monotonic());
    const int64_t start = ps_clock_now_ns(c.clk) + 5 * PS_NS_PER_MS;
    assert_int_equal(ps_sim_start(sim, start), 0);
    c.t_ns = start;
    assert_int_equal(ps_clock_sleep_until_ns(c.clk, start), 0);
    while (c.t_ns < start + 300 * PS_NS_PER_MS)
        ctl_tick(&c);
    ps_sim_stop(sim);
    ps_sim_stop(sim); /* twice is fine */
    ps_sim_truth_t t;
    ps_sim_get_truth(sim, &t);
    printf("real time 0.3 s: %llu physics steps, %llu plant overruns\n",
           (unsigned long long)t.n_steps, (unsigned long long)t.n_plant_overruns);
    for (uint32_t j = 0; j < fx->robot.n_joints; j++)
        assert_true(c.n_replies[j] > 10);
    assert_true(c.n_imu > 10);
    assert_true(t.n_steps > 100);
    assert_int_equal(t.n_bad_frames, 0);
    assert_int_equal(t.n_cmd_out_of_limits, 0);
    ps_sim_destroy(sim);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup(test_create_unknown_push_body_config_error_names_it, setup),
        cmocka_unit_test_setup(test_create_unknown_push_body_from_file_names_file_and_line, setup),
        cmocka_unit_test_setup(test_create_unknown_drop_joint_config_error_names_it, setup),
        cmocka_unit_test_setup(test_create_bad_model_path_plant_error, setup),
        cmocka_unit_test_setup(test_create_joint_bus_missing_config_error, setup),
        cmocka_unit_test(test_create_null_cfg_einval),
        cmocka_unit_test_setup(test_get_actuator_bad_index_einval, setup),
        cmocka_unit_test_setup(test_lockstep_replies_and_imu_arrive_with_right_ids, setup),
        cmocka_unit_test_setup(test_lockstep_contacts_beyond_nconmax_plant_err_in_truth, setup),
        cmocka_unit_test_setup(test_lockstep_heartbeat_stops_drives_limp_within_relay_timeout,
                               setup),
        cmocka_unit_test_setup(test_lockstep_steady_heartbeat_level_no_drive_power, setup),
        cmocka_unit_test_setup(test_lockstep_stands_5s_after_harness_release, setup),
        cmocka_unit_test_setup(test_lockstep_estop_events_toggle_gpio, setup),
        cmocka_unit_test_setup(test_lockstep_requests_taken_once_at_their_times, setup),
        cmocka_unit_test_setup(test_lockstep_push_moves_com_forward, setup),
        cmocka_unit_test_setup(test_lockstep_drop_replies_event_silences_one_joint, setup),
        cmocka_unit_test_setup(test_lockstep_same_seed_bit_identical_other_seed_differs, setup),
        cmocka_unit_test_setup(test_realtime_smoke_sees_replies, setup),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
