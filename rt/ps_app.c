#include "ps_app.h"

#include <libgen.h>
#include <stdio.h>
#include <string.h>

#include "ps_err.h"

static bool is_file_arg(const char *arg)
{
    size_t n = strlen(arg);
    return strchr(arg, '/') != NULL || (n > 5 && strcmp(arg + n - 5, ".yaml") == 0);
}

static void resolve(const char *data_dir, const char *arg, const char *dir, const char *fallback,
                    char *out, size_t len)
{
    if (arg != NULL && is_file_arg(arg))
        snprintf(out, len, "%s", arg);
    else
        snprintf(out, len, "%s/%s/%s.yaml", data_dir, dir, arg ? arg : fallback);
}

/* The model path in a robot file is relative to the robot file. */
static void resolve_model_path(ps_app_t *app)
{
    char robot_dir[PATH_MAX];
    snprintf(robot_dir, sizeof(robot_dir), "%s", app->robot_path);
    if (app->robot.model[0] == '/')
        snprintf(app->model_path, sizeof(app->model_path), "%s", app->robot.model);
    else
        snprintf(app->model_path, sizeof(app->model_path), "%s/%s", dirname(robot_dir),
                 app->robot.model);
}

static int load_configs(ps_app_t *app, const ps_app_opts_t *o, char *err, size_t len)
{
    const char *dd = o->data_dir ? o->data_dir : ".";
    resolve(dd, o->board ? o->board : "sim", "boards", "sim", app->board_path,
            sizeof(app->board_path));
    resolve(dd, o->robot, "robots", "ps1", app->robot_path, sizeof(app->robot_path));
    int rc = ps_config_load_board(app->board_path, &app->board, err, len);
    if (rc == 0)
        rc = ps_config_load_robot(app->robot_path, &app->robot, err, len);
    if (rc == 0 && (o->scenario != NULL || app->board.kind == PS_BOARD_SIM)) {
        resolve(dd, o->scenario, "scenarios", "stand", app->scenario_path,
                sizeof(app->scenario_path));
        rc = ps_config_load_scenario(app->scenario_path, &app->scenario, err, len);
    }
    if (rc == 0)
        rc = ps_config_check_pair(&app->board, &app->robot, &app->scenario, err, len);
    if (rc < 0)
        return rc;
    if (o->is_lockstep && app->board.kind != PS_BOARD_SIM) {
        snprintf(err, len, "--lockstep needs a simulated board; %s is kind linux", app->board_path);
        return -PS_ERR_CONFIG;
    }
    resolve_model_path(app);
    return 0;
}

static uint32_t take_operator_requests(void *ctx)
{
    ps_app_t *app = ctx;
    uint32_t bits = app->op.sim ? ps_sim_take_requests(app->op.sim) : 0;
    int64_t at = atomic_load(&app->op.start_request_ns);
    if (at > 0 && ps_clock_now_ns(app->op.clock) >= at) {
        bits |= PS_SM_C_REQ_START;
        atomic_store(&app->op.start_request_ns, 0);
    }
    return bits;
}

void ps_app_request_start_at(ps_app_t *app, int64_t t_ns)
{
    atomic_store(&app->op.start_request_ns, t_ns);
}

/* For the plant's truth: the controller is in charge in RAMP and ACTIVE. */
static bool is_loop_in_charge(void *ctx)
{
    const ps_sm_state_t st = ps_loop_get_state(ctx);
    return st == PS_SM_RAMP || st == PS_SM_ACTIVE;
}

static int wire_sim(ps_app_t *app, ps_loop_cfg_t *lc, char *err, size_t len)
{
    ps_sim_cfg_t sc = {
        .board = &app->board,
        .robot = &app->robot,
        .scenario = &app->scenario,
        .model_path = app->model_path,
        .is_lockstep = app->is_lockstep,
        .period_ns = PS_NS_PER_S / app->robot.control.servo_hz,
        .joint_phase = app->plan.joint_phase,
        .is_controller_active = is_loop_in_charge,
        .is_controller_active_ctx = &app->loop,
    };
    int rc = ps_sim_create(&sc, &app->sim, err, len);
    if (rc < 0)
        return rc;
    for (uint32_t b = 0; b < app->board.n_buses; b++)
        lc->buses[b] = ps_sim_can_port(app->sim, b);
    lc->gpio = ps_sim_gpio_port(app->sim);
    lc->clock = ps_sim_clock(app->sim);
    lc->perf_clock = ps_clock_monotonic();
    if (app->is_lockstep)
        lc->deadline_clock = ps_clock_thread_cpu();
    return 0;
}

static int wire(ps_app_t *app, const ps_app_opts_t *opts, char *err, size_t len)
{
    ps_loop_cfg_t lc = {
        .board = &app->board,
        .robot = &app->robot,
        .plan = &app->plan,
        .ring = &app->ring,
        .status_every = PS_APP_STATUS_EVERY,
        .wake_hist_us = opts->wake_hist_us,
        .trace = opts->trace,
    };
    if (app->board.kind != PS_BOARD_SIM) {
        snprintf(err, len,
                 "board %s (%s) is kind linux: the SocketCAN and libgpiod drivers are not "
                 "part of this build yet; use --board sim",
                 app->board.name, app->board_path);
        return -ENOTSUP;
    }
    int rc = wire_sim(app, &lc, err, len);
    if (rc < 0)
        return rc;
    rc = ps_stand_init(&app->stand, &app->robot);
    if (rc < 0) {
        snprintf(err, len, "standing controller: %s", ps_strerror(rc));
        return rc;
    }
    ps_stand_as_policy(&app->stand, &lc.policy);
    app->op.sim = app->sim;
    app->op.clock = lc.clock;
    atomic_init(&app->op.start_request_ns, 0);
    lc.op = (ps_operator_t){.take = take_operator_requests, .ctx = app};
    rc = ps_ring_init(&app->ring, app->ring_storage, PS_APP_RING_SLOTS,
                      sizeof(app->ring_storage[0]));
    if (rc == 0)
        rc = ps_loop_init(&app->loop, &lc);
    if (rc < 0)
        snprintf(err, len, "loop init: %s", ps_strerror(rc));
    return rc;
}

int ps_app_init(ps_app_t *app, const ps_app_opts_t *opts, char *err, size_t err_len)
{
    memset(app, 0, sizeof(*app));
    app->is_lockstep = opts->is_lockstep;
    int rc = load_configs(app, opts, err, err_len);
    if (rc == 0)
        rc = ps_canbus_plan(&app->board, &app->robot, &app->plan, err, err_len);
    if (rc == 0)
        rc = wire(app, opts, err, err_len);
    if (rc < 0 && rc != -PS_ERR_BUS_BUDGET)
        ps_app_deinit(app);
    return rc;
}

void ps_app_deinit(ps_app_t *app)
{
    ps_sim_destroy(app->sim);
    app->sim = NULL;
    ps_loop_deinit(&app->loop);
}
