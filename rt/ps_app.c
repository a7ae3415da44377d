#include "ps_app.h"

#include <libgen.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../sim/ps_plant.h"
#include "ps_err.h"
#include "ps_guard.h"
#include "ps_rtsetup.h"

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
    ps_config_resolve(dd, o->board ? o->board : "sim", "boards", "sim", app->board_path,
                      sizeof(app->board_path));
    ps_config_resolve(dd, o->robot, "robots", "ps1", app->robot_path, sizeof(app->robot_path));
    int rc = ps_config_load_board(app->board_path, &app->board, err, len);
    if (rc == 0)
        rc = ps_config_load_robot_sim(app->robot_path, &app->robot, &app->robot_sim, err, len);
    /* a replay has no plant for the default scenario to drive */
    const bool is_sim_run = app->board.kind == PS_BOARD_SIM && o->replay_path == NULL;
    if (rc == 0 && (o->scenario != NULL || is_sim_run)) {
        ps_config_resolve(dd, o->scenario, "scenarios", "crowd", app->scenario_path,
                          sizeof(app->scenario_path));
        rc = ps_config_load_scenario(app->scenario_path, &app->scenario, err, len);
    }
    if (rc == 0)
        rc = ps_config_check_pair(&app->board, &app->robot, err, len);
    if (rc == 0)
        rc = ps_config_check_scenario(&app->robot, &app->scenario, err, len);
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
    uint32_t bits = 0;
    const uint32_t sim_bits = app->op.sim ? ps_sim_take_requests(app->op.sim) : 0u;
    if (sim_bits & PS_SIM_REQ_START)
        bits |= PS_SM_C_REQ_START;
    if (sim_bits & PS_SIM_REQ_STOP)
        bits |= PS_SM_C_REQ_STOP;
    if (sim_bits & PS_SIM_REQ_RESET)
        bits |= PS_SM_C_REQ_RESET;
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

int ps_app_plan_buses(const ps_board_cfg_t *b, const ps_robot_cfg_t *r, ps_canbus_plan_t *out,
                      char *err, size_t err_len)
{
    if (b == NULL || r == NULL || r->n_joints > PS_MAX_JOINTS) {
        ps_err_format(err, err_len, "bus plan: no board or robot, or too many joints");
        return -PS_ERR_CONFIG;
    }
    char names[PS_CANBUS_MAX_SOURCES][PS_NAME_LEN + 8]; /* for the planner's messages */
    ps_canbus_source_t src[PS_CANBUS_MAX_SOURCES];
    memset(src, 0, sizeof(src));
    for (uint32_t j = 0; j < r->n_joints; j++) {
        const ps_act_proto_t *p = ps_act_proto_get(r->act[j].protocol);
        snprintf(names[j], sizeof(names[j]), "joint %s", r->joint_name[j]);
        src[j].name = names[j];
        src[j].bus_idx = r->act[j].bus_idx;
        src[j].rate_div = r->act[j].rate_div;
        if (p == NULL || p->n_cmd + p->n_reply > PS_CANBUS_MAX_SOURCE_FRAMES)
            continue; /* n_frames 0: the planner names the joint */
        const bool is_ext = p->id_bits > 11u;
        for (uint32_t k = 0; k < p->n_cmd + p->n_reply; k++)
            src[j].frames[k] = (ps_canbus_frame_shape_t){
                .len = k < p->n_cmd ? p->cmd_len : p->reply_len,
                .is_ext = is_ext,
                .is_fd = p->is_fd,
                .is_brs = p->is_fd,
                .is_rx = k >= p->n_cmd, /* the drive's replies */
            };
        src[j].n_frames = p->n_cmd + p->n_reply;
    }
    ps_canbus_source_t *imu = &src[r->n_joints];
    imu->name = "imu";
    imu->bus_idx = r->imu.bus_idx;
    imu->rate_div = r->imu.rate_div;
    uint32_t imu_ids[PS_IMU_MAX_FRAMES];
    uint8_t imu_lens[PS_IMU_MAX_FRAMES];
    imu->n_frames = ps_imu_frames(&r->imu, imu_ids, imu_lens); /* one sample's frames */
    for (uint32_t k = 0; k < imu->n_frames; k++)
        imu->frames[k] = (ps_canbus_frame_shape_t){.len = imu_lens[k], .is_rx = true};
    const ps_canbus_cfg_t cfg = {
        .n_buses = b->n_buses,
        .buses = b->buses,
        .bus_budget = b->bus_budget,
        .servo_hz = r->control.servo_hz,
    };
    return ps_canbus_plan(&cfg, src, r->n_joints + 1u, out, err, err_len);
}

void ps_app_sim_board(const ps_board_cfg_t *b, ps_sim_board_t *out)
{
    memset(out, 0, sizeof(*out));
    memcpy(out->name, b->name, sizeof(out->name));
    out->n_buses = b->n_buses;
    memcpy(out->buses, b->buses, sizeof(out->buses));
    out->plant_priority = b->rt.priority > 1u ? b->rt.priority - 1u : 0u;
    out->plant_cpu = b->rt.plant_cpu;
}

void ps_app_sim_robot(const ps_robot_cfg_t *r, const ps_sim_devices_cfg_t *devices,
                      ps_sim_robot_t *out)
{
    memset(out, 0, sizeof(*out));
    memcpy(out->name, r->name, sizeof(out->name));
    out->n_joints = r->n_joints;
    memcpy(out->joint_name, r->joint_name, sizeof(out->joint_name));
    memcpy(out->act, r->act, sizeof(out->act));
    for (uint32_t j = 0; j < r->n_joints && j < PS_MAX_JOINTS; j++) {
        out->lim[j] = r->servo[j].lim;
        out->stance_rad[j] = r->servo[j].stance_rad;
    }
    out->imu = r->imu;
    out->devices = *devices;
    memcpy(out->src_path, r->src.path, sizeof(out->src_path));
    memcpy(out->joint_name_line, r->src.joint_name_line, sizeof(out->joint_name_line));
    out->model_line = r->src.model_line;
}

static void hook_setup_thread(void *ctx, unsigned priority, int cpu)
{
    (void)ctx;
    (void)ps_rtsetup_thread_best_effort(priority, cpu); /* the sim runs as it can */
}

static void hook_pause_guard(void *ctx)
{
    (void)ctx;
    ps_guard_pause();
}

static void hook_resume_guard(void *ctx)
{
    (void)ctx;
    ps_guard_resume();
}

/* For the plant's truth: the controller is in charge in RAMP, ACTIVE and HOLD. */
static bool is_loop_in_charge(void *ctx)
{
    const ps_sm_state_t st = ps_loop_get_state(ctx);
    return st == PS_SM_RAMP || st == PS_SM_ACTIVE || st == PS_SM_HOLD;
}

ps_sim_hooks_t ps_app_sim_hooks(ps_loop_t *loop)
{
    const ps_sim_hooks_t h = {
        .ctx = loop,
        .setup_thread = hook_setup_thread,
        .pause_guard = hook_pause_guard,
        .resume_guard = hook_resume_guard,
        .is_controller_active = loop != NULL ? is_loop_in_charge : NULL,
    };
    return h;
}

/* The crowd wears tags when the scenario says so, or (auto) when the board's
 * camera is the simulated one: that camera looks at the scene and finds
 * people by the tags on their shoulders. Their size is the camera's. */
static void resolve_crowd_tags(ps_app_t *app)
{
    ps_crowd_cfg_t *crowd = &app->scenario.crowd;
    const bool has_sim_camera =
        app->board.has_perception && app->board.perception.camera.source == PS_CAMERA_SRC_SIM;
    if (crowd->tags == PS_CROWD_TAGS_AUTO)
        crowd->tags = has_sim_camera ? PS_CROWD_TAGS_ON : PS_CROWD_TAGS_OFF;
    if (app->board.has_perception)
        crowd->tag_size_m = app->board.perception.tags.tag_size_m;
}

static int wire_sim(ps_app_t *app, ps_loop_cfg_t *lc, char *err, size_t len)
{
    resolve_crowd_tags(app);
    ps_app_sim_board(&app->board, &app->sim_board);
    ps_app_sim_robot(&app->robot, &app->robot_sim, &app->sim_robot);
    ps_sim_cfg_t sc = {
        .board = &app->sim_board,
        .robot = &app->sim_robot,
        .scenario = &app->scenario,
        .model_path = app->model_path,
        .is_lockstep = app->is_lockstep,
        .period_ns = PS_NS_PER_S / app->robot.control.servo_hz,
        .hooks = ps_app_sim_hooks(&app->loop),
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

void ps_app_bus_filters(const ps_robot_cfg_t *r, uint32_t bus_idx, ps_can_socket_cfg_t *out)
{
    out->n_filters = 0;
    for (uint32_t j = 0; j < r->n_joints && out->n_filters < PS_CAN_SOCKET_MAX_FILTERS; j++) {
        const ps_act_proto_t *p = ps_act_proto_get(r->act[j].protocol);
        if (r->act[j].bus_idx != bus_idx || p == NULL)
            continue;
        ps_can_socket_filter_t *f = &out->filters[out->n_filters++];
        p->reply_filter(&r->act[j], &f->id, &f->mask);
        f->is_ext = p->id_bits > 11u;
        if (p->fault_filter != NULL && out->n_filters < PS_CAN_SOCKET_MAX_FILTERS) {
            ps_can_socket_filter_t *g = &out->filters[out->n_filters++];
            p->fault_filter(&r->act[j], &g->id, &g->mask);
            g->is_ext = f->is_ext;
        }
    }
    uint32_t ids[PS_IMU_MAX_FRAMES];
    uint8_t lens[PS_IMU_MAX_FRAMES];
    const unsigned n_imu = r->imu.bus_idx == bus_idx ? ps_imu_frames(&r->imu, ids, lens) : 0u;
    for (unsigned k = 0; k < n_imu && out->n_filters < PS_CAN_SOCKET_MAX_FILTERS; k++)
        out->filters[out->n_filters++] = (ps_can_socket_filter_t){ids[k], 0x7ffu, false};
}

uint32_t ps_app_min_txqueuelen(const ps_robot_cfg_t *r, uint32_t bus_idx)
{
    uint32_t frames = 0;
    for (uint32_t j = 0; j < r->n_joints; j++) {
        const ps_act_proto_t *p = ps_act_proto_get(r->act[j].protocol);
        if (r->act[j].bus_idx == bus_idx && p != NULL)
            frames += p->n_cmd + 1u;
    }
    return 2u * frames > 16u ? 2u * frames : 16u;
}

static void add_note(ps_app_t *app, const char *note)
{
    const size_t used = strlen(app->notes);
    if (note[0] != '\0' && used + 1 < sizeof(app->notes))
        snprintf(app->notes + used, sizeof(app->notes) - used, "%s%s", used ? "; " : "", note);
}

static int open_bus(ps_app_t *app, uint32_t b, char *err, size_t len)
{
    const ps_canbus_bus_cfg_t *bus = &app->board.buses[b];
    ps_can_socket_iface_t info;
    char why[768], note[160];
    int rc = ps_can_socket_query(bus->ifname, &info, why, sizeof(why));
    if (rc == 0)
        rc = ps_can_socket_check_iface(bus, &info, ps_app_min_txqueuelen(&app->robot, b), why,
                                       sizeof(why), note, sizeof(note));
    if (rc < 0) {
        snprintf(err, len, "board %s: bus %u: %s", app->board_path, b, why);
        return rc;
    }
    add_note(app, note);
    ps_can_socket_cfg_t sc = {.is_fd = bus->is_fd, .bitrate = bus->bitrate};
    memcpy(sc.ifname, bus->ifname, sizeof(sc.ifname));
    ps_app_bus_filters(&app->robot, b, &sc);
    rc = ps_can_socket_open(&app->sockets[b], &sc, why, sizeof(why));
    if (rc < 0)
        snprintf(err, len, "board %s: %s", app->board_path, why);
    else
        app->n_sockets_open = b + 1u;
    return rc;
}

/* One send call takes a bus's whole tick: the loop's batch fits the
 * socket's (a longer one would be cut and counted as a full queue). */
_Static_assert(PS_LOOP_MAX_TX <= PS_CAN_SOCKET_BATCH, "a tick's frames fit one sendmmsg");

static int wire_linux(ps_app_t *app, ps_loop_cfg_t *lc, char *err, size_t len)
{
    for (uint32_t b = 0; b < app->board.n_buses; b++) {
        int rc = open_bus(app, b, err, len);
        if (rc < 0)
            return rc;
        lc->buses[b] = ps_can_socket_port(&app->sockets[b]);
    }
    char why[384];
    int rc = ps_gpio_gpiod_open(&app->gpiod, &app->board.gpio, why, sizeof(why));
    if (rc < 0) {
        snprintf(err, len, "board %s: %s", app->board_path, why);
        return rc;
    }
    app->is_gpiod_open = true;
    lc->gpio = ps_gpio_gpiod_port(&app->gpiod);
    lc->clock = ps_clock_monotonic();
    lc->perf_clock = lc->clock;
    return 0;
}

/* --replay: the buses fed from a candump log, time from the replay clock,
 * no GPIO lines. The log's storage is allocated here, at start-up, sized by
 * reading the log once; the replay ports themselves never allocate. */
static int wire_replay(ps_app_t *app, const char *path, ps_loop_cfg_t *lc, char *err, size_t len)
{
    ps_can_replay_cfg_t rc_cfg = {
        .path = path,
        .n_buses = app->board.n_buses,
        .act = app->robot.act,
        .n_joints = app->robot.n_joints,
        .imu_bus_idx = app->robot.imu.bus_idx,
        .period_ns = PS_NS_PER_S / app->robot.control.servo_hz,
    };
    for (uint32_t b = 0; b < app->board.n_buses && b < PS_MAX_BUSES; b++)
        rc_cfg.ifname[b] = app->board.buses[b].ifname;
    uint32_t imu_ids[PS_IMU_MAX_FRAMES];
    uint8_t imu_lens[PS_IMU_MAX_FRAMES];
    const unsigned n_imu = ps_imu_frames(&app->robot.imu, imu_ids, imu_lens);
    for (unsigned k = 0; k < n_imu && k < PS_CAN_REPLAY_MAX_IMU_IDS; k++)
        rc_cfg.imu_ids[rc_cfg.n_imu_ids++] = imu_ids[k];
    ps_can_replay_size_t size;
    int rc = ps_can_replay_measure(&rc_cfg, &size, err, len);
    if (rc < 0)
        return rc;
    app->replay_entries =
        calloc(size.n_entries > 0 ? size.n_entries : 1u, sizeof(*app->replay_entries));
    app->replay_data = malloc(size.n_data > 0 ? size.n_data : 1u);
    if (app->replay_entries == NULL || app->replay_data == NULL) {
        snprintf(err, len, "%s: no memory for its %zu frames", path, size.n_entries);
        return -ENOMEM;
    }
    rc = ps_can_replay_init(&app->replay, &rc_cfg, app->replay_entries, size.n_entries,
                            app->replay_data, size.n_data, err, len);
    if (rc < 0)
        return rc;
    app->is_replay = true;
    for (uint32_t b = 0; b < app->board.n_buses; b++)
        lc->buses[b] = ps_can_replay_port(&app->replay, b);
    lc->gpio = ps_can_replay_gpio_port();
    lc->clock = ps_can_replay_clock(&app->replay);
    lc->perf_clock = ps_clock_monotonic();
    lc->deadline_clock = ps_clock_thread_cpu(); /* as in lockstep: the policy's own time */
    return 0;
}

/* The board's camera: its source's port, the perception over it, started on
 * the worker CPU. clock stamps the image folder's frames (the loop's). */
static int open_camera(ps_app_t *app, const ps_clock_t *clock, bool keep_snapshot, char *err,
                       size_t len)
{
    const ps_perception_cfg_t *pc = &app->board.perception;
    ps_camera_port_t port = {0};
    int rc = 0;
    switch (pc->camera.source) {
    case PS_CAMERA_SRC_FILES: {
        /* camera.dir is relative to the board file, like a robot's model */
        char board_dir[PATH_MAX];
        snprintf(board_dir, sizeof(board_dir), "%s", app->board_path);
        if (pc->camera.dir[0] == '/')
            snprintf(app->camera_dir, sizeof(app->camera_dir), "%s", pc->camera.dir);
        else
            snprintf(app->camera_dir, sizeof(app->camera_dir), "%s/%s", dirname(board_dir),
                     pc->camera.dir);
        ps_camera_cfg_t cc = pc->camera;
        if (strlen(app->camera_dir) >= sizeof(cc.dir)) {
            snprintf(err, len, "%s: camera.dir: the folder's path is longer than %zu bytes",
                     app->board_path, sizeof(cc.dir) - 1u);
            return -PS_ERR_CONFIG;
        }
        memcpy(cc.dir, app->camera_dir, strlen(app->camera_dir) + 1u);
        ps_camera_files_init(&app->camera_files, &cc, clock, true);
        port = ps_camera_files_port(&app->camera_files);
        break;
    }
    case PS_CAMERA_SRC_LIBCAMERA:
        if (app->is_lockstep) {
            snprintf(err, len,
                     "%s:%u: camera: a libcamera camera runs in real time; --lockstep needs "
                     "source sim or files",
                     app->board_path, app->board.camera_line);
            return -PS_ERR_CONFIG;
        }
        rc = ps_camera_libcamera_create(&pc->camera, &app->camera_libcamera, err, len);
        if (rc < 0)
            return rc;
        port = ps_camera_libcamera_port(app->camera_libcamera);
        break;
    case PS_CAMERA_SRC_SIM: {
        if (app->sim == NULL) {
            snprintf(err, len, "%s:%u: camera: source sim needs the simulated plant",
                     app->board_path, app->board.camera_line);
            return -PS_ERR_CONFIG;
        }
        const ps_camera_sim_cfg_t sc = {
            .sim = app->sim,
            .camera = pc->camera,
            .k = pc->tags.k,
            .cam_pos_m = {pc->tags.cam_pos_m[0], pc->tags.cam_pos_m[1], pc->tags.cam_pos_m[2]},
            .cam_rpy_rad = {pc->tags.cam_rpy_rad[0], pc->tags.cam_rpy_rad[1],
                            pc->tags.cam_rpy_rad[2]},
            .root_body = PS_PLANT_ROOT_BODY_NAME,
        };
        rc = ps_camera_sim_create(&sc, &app->camera_sim, err, len);
        if (rc < 0)
            return rc;
        port = ps_camera_sim_port(app->camera_sim);
        break;
    }
    case PS_CAMERA_SRC_COUNT:
        return -EINVAL;
    }
    rc = ps_perception_init(&app->perception, pc, port, keep_snapshot, err, len);
    if (rc < 0)
        return rc;
    app->has_perception = true;
    return ps_perception_start(&app->perception, app->board.rt.worker_cpu, err, len);
}

/* A path in the robot file is relative to the robot file. */
static void robot_relative(const ps_app_t *app, const char *path, char *out, size_t len)
{
    char dir[PATH_MAX];
    snprintf(dir, sizeof(dir), "%s", app->robot_path);
    if (path[0] == '/')
        snprintf(out, len, "%s", path);
    else
        snprintf(out, len, "%s/%s", dirname(dir), path);
}

/* The controller in the policy slot: the command line's, else the robot
 * file's, else the standing controller. The capture-point controller is
 * built for every choice but "stand": it is the MLP's fallback. */
static int wire_policy(ps_app_t *app, const ps_app_opts_t *opts, ps_loop_cfg_t *lc, char *err,
                       size_t len)
{
    const ps_robot_cfg_t *r = &app->robot;
    const char *name = opts->policy != NULL ? opts->policy : (r->policy[0] ? r->policy : "stand");
    const int kind = ps_config_policy_find(name);
    if (kind < 0) {
        snprintf(err, len, "%s: \"%s\" is not one of %s",
                 opts->policy != NULL ? "--policy" : "robot file policy.controller", name,
                 PS_CONFIG_POLICY_NAMES);
        return -PS_ERR_CONFIG;
    }
    snprintf(app->policy_name, sizeof(app->policy_name), "%s", name);
    int rc = ps_stand_init(&app->stand, r->n_joints, r->joint_name, r->servo);
    if (rc < 0) {
        snprintf(err, len, "standing controller: %s", ps_strerror(rc));
        return rc;
    }
    if (kind == 0) {
        ps_stand_as_policy(&app->stand, &lc->policy);
        return 0;
    }
    const float dt_s = 1.0f / (float)r->control.policy_hz;
    rc = ps_capture_init(&app->capture, r->n_joints, r->joint_name, r->servo, &r->kin, dt_s);
    if (rc < 0) {
        snprintf(err, len, "capture-point controller: %s (needs the leg joints and the "
                           "kinematics' mass model, docs/policy.md)",
                 ps_strerror(rc));
        return -PS_ERR_CONFIG;
    }
    ps_policy_t capture;
    ps_capture_as_policy(&app->capture, &capture);
    if (kind == 1) {
        lc->policy = capture;
        return 0;
    }
    if (opts->weights != NULL)
        snprintf(app->weights_path, sizeof(app->weights_path), "%s", opts->weights);
    else if (r->policy_weights[0] != '\0')
        robot_relative(app, r->policy_weights, app->weights_path, sizeof(app->weights_path));
    else {
        snprintf(err, len, "--policy mlp needs a policy file: --weights FILE or the robot file's "
                           "policy.weights");
        return -PS_ERR_CONFIG;
    }
    char canon[PATH_MAX]; /* messages and the summary name the file plainly */
    if (realpath(app->weights_path, canon) != NULL)
        snprintf(app->weights_path, sizeof(app->weights_path), "%s", canon);
    rc = ps_weights_load(&app->weights, app->weights_path, err, len);
    if (rc < 0)
        return rc == -ENOMEM ? rc : -PS_ERR_CONFIG;
    char why[PS_ERR_MSG_LEN];
    rc = ps_weights_check_robot(&app->weights.contract, r->n_joints, r->joint_name, r->servo,
                                r->control.policy_hz, why, sizeof(why));
    if (rc < 0) {
        snprintf(err, len, "%s: does not fit robot %s (%s): %s", app->weights_path, r->name,
                 app->robot_path, why);
        return -PS_ERR_CONFIG;
    }
    const ps_clock_t *late_clock = lc->deadline_clock != NULL ? lc->deadline_clock : lc->clock;
    rc = ps_mlp_policy_init(&app->mlp, &app->weights, r->n_joints, r->joint_name, r->servo,
                            &r->kin, dt_s, capture, late_clock,
                            ps_s_to_ns(r->control.policy_deadline_s));
    if (rc < 0) {
        snprintf(err, len, "%s: the policy's observation cannot be built for robot %s: %s",
                 app->weights_path, r->name, ps_strerror(rc));
        return -PS_ERR_CONFIG;
    }
    ps_mlp_policy_as_policy(&app->mlp, &lc->policy);
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
        .frame_ring = opts->frame_ring,
    };
    int rc = opts->replay_path != NULL         ? wire_replay(app, opts->replay_path, &lc, err, len)
             : app->board.kind == PS_BOARD_SIM ? wire_sim(app, &lc, err, len)
                                               : wire_linux(app, &lc, err, len);
    if (rc < 0)
        return rc;
    rc = wire_policy(app, opts, &lc, err, len);
    if (rc < 0)
        return rc;
    app->op.sim = app->sim;
    app->op.clock = lc.clock;
    atomic_init(&app->op.start_request_ns, 0);
    lc.op = (ps_operator_t){.take = take_operator_requests, .ctx = app};
    /* Camera perception beside the loop (not with --replay: a log has no
     * pictures). */
    if (app->board.has_perception && opts->replay_path == NULL) {
        rc = open_camera(app, lc.clock, false, err, len);
        if (rc < 0)
            return rc;
        lc.neighbours = ps_perception_mailbox(&app->perception);
    }
    rc = ps_ring_init(&app->ring, app->ring_storage, PS_APP_RING_SLOTS,
                      sizeof(app->ring_storage[0]));
    if (rc == 0)
        rc = ps_loop_init(&app->loop, &lc);
    if (rc < 0)
        snprintf(err, len, "loop init: %s", ps_strerror(rc));
    return rc;
}

/* `pushstep camera`: the files, a plant at rest on board sim, the camera. */
static int init_camera_only(ps_app_t *app, const ps_app_opts_t *opts, char *err, size_t len)
{
    /* A real board's camera needs nothing of the robot; board sim's scene is
     * the robot's model (and its plant), so there everything is loaded. */
    ps_config_resolve(opts->data_dir ? opts->data_dir : ".", opts->board ? opts->board : "sim",
                      "boards", "sim", app->board_path, sizeof(app->board_path));
    int rc = ps_config_load_board(app->board_path, &app->board, err, len);
    if (rc == 0 && app->board.kind == PS_BOARD_SIM)
        rc = load_configs(app, opts, err, len);
    if (rc == 0 && !app->board.has_perception) {
        snprintf(err, len,
                 "%s: the board has no camera perception (camera.source; docs/config.md)",
                 app->board_path);
        rc = -PS_ERR_CONFIG;
    }
    ps_loop_cfg_t unused = {0};
    if (rc == 0 && app->board.kind == PS_BOARD_SIM) {
        app->is_lockstep = true; /* a plant that only holds the scene: no thread */
        rc = wire_sim(app, &unused, err, len);
    }
    if (rc == 0)
        rc = open_camera(app, app->sim != NULL ? ps_sim_clock(app->sim) : ps_clock_monotonic(),
                         true, err, len);
    if (rc < 0)
        ps_app_deinit(app);
    return rc;
}

int ps_app_init(ps_app_t *app, const ps_app_opts_t *opts, char *err, size_t err_len)
{
    memset(app, 0, sizeof(*app));
    app->is_lockstep = opts->is_lockstep;
    if (opts->is_camera_only)
        return init_camera_only(app, opts, err, err_len);
    int rc = load_configs(app, opts, err, err_len);
    for (uint32_t b = 0; rc == 0 && b < app->board.n_buses; b++)
        memcpy(app->bus_names[b], app->board.buses[b].ifname, PS_NAME_LEN);
    if (rc == 0)
        rc = ps_app_plan_buses(&app->board, &app->robot, &app->plan, err, err_len);
    if (rc == 0)
        rc = wire(app, opts, err, err_len);
    if (rc < 0 && rc != -PS_ERR_BUS_BUDGET)
        ps_app_deinit(app);
    return rc;
}

void ps_app_recorder_cfg(const ps_app_t *app, ps_recorder_cfg_t *out)
{
    out->servo_hz = app->robot.control.servo_hz;
    out->board_name = app->board.name;
    out->robot_name = app->robot.name;
    out->scenario_path = app->scenario_path[0] ? app->scenario_path : NULL;
    out->joint_name = (const char(*)[PS_NAME_LEN])app->robot.joint_name;
    out->n_joints = app->robot.n_joints;
    out->bus_name = (const char(*)[PS_NAME_LEN])app->bus_names;
    out->n_buses = app->board.n_buses;
    out->foot_length_m = app->robot.kin.foot_length_m;
    out->foot_width_m = app->robot.kin.foot_width_m;
    out->clock_name = app->is_lockstep || app->is_replay ? "simulated (lockstep or replay), ns"
                                                         : "CLOCK_MONOTONIC, ns";
}

/* The plant's truth for the recorder, on the loop thread: no lock. */
/* The crowd's contacts on the robot into the record (walls and obstacles
 * as agent UINT16_MAX). */
static void copy_crowd_contacts(const ps_crowd_stats_t *st, ps_rec_truth_t *out)
{
    uint32_t n = st->n_robot_contacts;
    n = n < PS_REC_MAX_CONTACTS ? n : PS_REC_MAX_CONTACTS;
    for (uint32_t i = 0; i < n; i++) {
        const ps_crowd_robot_contact_t *c = &st->robot_contact[i];
        out->contact_agent[i] = c->agent >= 0 ? (uint16_t)c->agent : UINT16_MAX;
        out->contact_fx_n[i] = (float)c->force_n[0];
        out->contact_fy_n[i] = (float)c->force_n[1];
        out->contact_fz_n[i] = (float)c->force_n[2];
        out->contact_x_m[i] = (float)c->pos_m[0];
        out->contact_y_m[i] = (float)c->pos_m[1];
        out->contact_z_m[i] = (float)c->pos_m[2];
    }
    out->n_contacts = (uint16_t)n;
}

static bool read_sim_truth(void *ctx, ps_rec_truth_t *out)
{
    ps_app_t *app = ctx;
    ps_sim_truth_t t;
    if (app->sim == NULL || !ps_sim_read_truth_rt(app->sim, &t))
        return false;
    memset(out, 0, sizeof(*out));
    out->t_s = (float)t.t_s;
    for (int k = 0; k < 3; k++) {
        out->com_m[k] = (float)t.com_m[k];
        out->pelvis_m[k] = (float)t.pelvis_m[k];
        out->push_force_n[k] = (float)t.push_force_n[k];
    }
    out->head_height_m = (float)t.head_height_m;
    out->tau_abs_sum_nm = (float)t.tau_abs_sum_nm;
    out->is_fallen = t.is_fallen;
    out->is_drive_power_on = t.is_drive_power_on;
    if (t.has_crowd)
        copy_crowd_contacts(&t.crowd, out);
    return true;
}

void ps_app_attach_recorder(ps_app_t *app, ps_recorder_t *rec)
{
    app->loop.cfg.tap = (ps_loop_tap_t){.on_tick = ps_recorder_on_tick, .ctx = rec};
    if (app->sim != NULL)
        ps_recorder_set_truth(rec, (ps_rec_truth_src_t){.read = read_sim_truth, .ctx = app});
}

void ps_app_deinit(ps_app_t *app)
{
    /* perception first: the simulated camera reads the sim */
    if (app->has_perception)
        ps_perception_deinit(&app->perception);
    app->has_perception = false;
    ps_camera_sim_destroy(app->camera_sim);
    app->camera_sim = NULL;
    ps_camera_libcamera_destroy(app->camera_libcamera);
    app->camera_libcamera = NULL;
    ps_sim_destroy(app->sim);
    app->sim = NULL;
    for (uint32_t b = 0; b < app->n_sockets_open; b++)
        ps_can_socket_close(&app->sockets[b]);
    app->n_sockets_open = 0;
    if (app->is_gpiod_open)
        ps_gpio_gpiod_close(&app->gpiod);
    app->is_gpiod_open = false;
    ps_loop_deinit(&app->loop);
    ps_weights_free(&app->weights);
    ps_can_replay_deinit(&app->replay); /* after the loop: its ports read the storage */
    free(app->replay_entries);
    free(app->replay_data);
    app->replay_entries = NULL;
    app->replay_data = NULL;
    app->is_replay = false;
}
