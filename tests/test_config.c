/*
 * Tests for rt/ps_config (rt/ps_config_board.c, ps_config_robot.c,
 * ps_config_scenario.c, ps_config_common.c): the shipped boards and scenarios, the fixtures in
 * tests/data/config/, and rejection cases. Each rejection case copies a valid
 * fixture into a temp dir with one edit and checks the whole message; the
 * expected line number is measured in the edited text, not typed in.
 * Run from the repository root.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../rt/ps_config.h"
#include "../rt/ps_config_sim.h"
#include "../rt/ps_err.h"

#define FIXTURES    "tests/data/config/"
#define ROBOT_OK    FIXTURES "robot_ok.yaml"
#define BOARD_OK    FIXTURES "board_ok.yaml"
#define SCENARIO_OK FIXTURES "scenario_ok.yaml"
#define TEXT_MAX    16384

typedef struct {
    char dir[64];
    char path[128];      /* the edited copy */
    char text[TEXT_MAX]; /* its content */
    char err[PS_ERR_MSG_LEN];
    char want[PS_ERR_MSG_LEN];
    ps_board_cfg_t board;
    ps_robot_cfg_t robot;
    ps_sim_devices_cfg_t robot_sim;
    ps_scenario_cfg_t scenario;
} fx_t;

static int setup(void **state)
{
    fx_t *f = calloc(1, sizeof(*f));
    if (f == NULL)
        return -1;
    (void)snprintf(f->dir, sizeof(f->dir), "/tmp/ps_test_config.XXXXXX");
    if (mkdtemp(f->dir) == NULL) {
        free(f);
        return -1;
    }
    *state = f;
    return 0;
}

static int teardown(void **state)
{
    fx_t *f = *state;
    if (f->path[0] != '\0')
        (void)unlink(f->path); /* may not exist when a test failed early */
    (void)rmdir(f->dir);
    free(f);
    return 0;
}

static void read_text(const char *path, char *out, size_t out_len)
{
    FILE *fp = fopen(path, "rb");
    assert_non_null(fp);
    const size_t n = fread(out, 1, out_len - 1u, fp);
    assert_int_equal(ferror(fp), 0);
    assert_true(n < out_len - 1u);
    out[n] = '\0';
    assert_int_equal(fclose(fp), 0);
}

/* Copies src to the temp dir with the first `from` replaced by `to`. */
static const char *edit(fx_t *f, const char *src, const char *from, const char *to)
{
    char orig[TEXT_MAX];
    read_text(src, orig, sizeof(orig));
    const char *at = strstr(orig, from);
    assert_non_null(at);
    const size_t head = (size_t)(at - orig);
    const int n =
        snprintf(f->text, sizeof(f->text), "%.*s%s%s", (int)head, orig, to, at + strlen(from));
    assert_true(n > 0 && (size_t)n < sizeof(f->text));
    (void)snprintf(f->path, sizeof(f->path), "%s/edited.yaml", f->dir);
    FILE *fp = fopen(f->path, "wb");
    assert_non_null(fp);
    assert_int_equal(fwrite(f->text, 1, (size_t)n, fp), (size_t)n);
    assert_int_equal(fclose(fp), 0);
    return f->path;
}

/* A second replacement in the edited copy. */
static void edit_again(fx_t *f, const char *from, const char *to)
{
    char src[sizeof(f->path)];
    (void)snprintf(src, sizeof(src), "%s", f->path);
    (void)edit(f, src, from, to);
}

/* Text appended to the edited copy. */
static void append(fx_t *f, const char *text)
{
    const size_t n = strlen(f->text), k = strlen(text);
    assert_true(n + k < sizeof(f->text));
    memcpy(f->text + n, text, k + 1u);
    FILE *fp = fopen(f->path, "wb");
    assert_non_null(fp);
    assert_int_equal(fwrite(f->text, 1, n + k, fp), n + k);
    assert_int_equal(fclose(fp), 0);
}

/* 1-based line of the first occurrence of needle in the edited text. */
static int line_of(const fx_t *f, const char *needle)
{
    const char *at = strstr(f->text, needle);
    assert_non_null(at);
    int line = 1;
    for (const char *p = f->text; p < at; p++)
        line += *p == '\n';
    return line;
}

static void want(fx_t *f, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void want(fx_t *f, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    (void)vsnprintf(f->want, sizeof(f->want), fmt, ap);
    va_end(ap);
}

static void expect_board_error(fx_t *f)
{
    assert_int_equal(ps_config_load_board(f->path, &f->board, f->err, sizeof(f->err)),
                     -PS_ERR_CONFIG);
    assert_string_equal(f->err, f->want);
}

static void expect_robot_error(fx_t *f)
{
    assert_int_equal(ps_config_load_robot(f->path, &f->robot, f->err, sizeof(f->err)),
                     -PS_ERR_CONFIG);
    assert_string_equal(f->err, f->want);
}

static void expect_scenario_error_any(fx_t *f)
{
    assert_int_equal(ps_config_load_scenario(f->path, &f->scenario, f->err, sizeof(f->err)),
                     -PS_ERR_CONFIG);
    assert_non_null(strstr(f->err, f->path));
}

static void expect_scenario_error(fx_t *f)
{
    assert_int_equal(ps_config_load_scenario(f->path, &f->scenario, f->err, sizeof(f->err)),
                     -PS_ERR_CONFIG);
    assert_string_equal(f->err, f->want);
}

/* ---- shipped files ---------------------------------------------------- */

static void test_load_board_shipped_boards_ok(void **state)
{
    fx_t *f = *state;
    static const char *const LINUX_BOARDS[] = {"boards/rpi4.yaml", "boards/rpi5.yaml",
                                               "boards/jetson-orin.yaml", "boards/bbai64.yaml"};
    for (size_t i = 0; i < sizeof(LINUX_BOARDS) / sizeof(LINUX_BOARDS[0]); i++) {
        memset(&f->board, 0, sizeof(f->board));
        const int rc = ps_config_load_board(LINUX_BOARDS[i], &f->board, f->err, sizeof(f->err));
        if (rc != 0)
            print_error("%s\n", f->err);
        assert_int_equal(rc, 0);
        assert_int_equal(f->board.kind, PS_BOARD_LINUX);
        assert_int_equal(f->board.n_buses, 4);
        for (uint32_t b = 0; b < f->board.n_buses; b++)
            assert_int_equal(f->board.buses[b].bitrate, 1000000);
        assert_true(f->board.rt.loop_cpu > 0);
        /* real e-stop contacts bounce: every real board debounces them */
        assert_int_equal(f->board.gpio.estop_debounce_us, 2000);
    }
}

static void test_load_board_sim_exact_values(void **state)
{
    fx_t *f = *state;
    assert_int_equal(ps_config_load_board("boards/sim.yaml", &f->board, f->err, sizeof(f->err)), 0);
    const ps_board_cfg_t *b = &f->board;
    assert_string_equal(b->name, "sim");
    assert_int_equal(b->kind, PS_BOARD_SIM);
    assert_int_equal(b->n_buses, 4);
    static const char *const IFNAMES[] = {"can0", "can1", "can2", "can3"};
    for (uint32_t i = 0; i < 4; i++) {
        assert_string_equal(b->buses[i].ifname, IFNAMES[i]);
        assert_int_equal(b->buses[i].bitrate, 1000000);
    }
    assert_true(b->bus_budget == 0.8f);
    assert_string_equal(b->gpio.chip, "sim");
    assert_true(b->gpio.is_estop_active_low);
    assert_int_equal(b->rt.priority, 80);
    assert_int_equal(b->rt.loop_cpu, 1);
    assert_int_equal(b->rt.plant_cpu, 0);
    assert_int_equal(b->rt.worker_cpu, 0);
}

static void test_load_board_optional_absent_default_applied(void **state)
{
    fx_t *f = *state;
    assert_int_equal(ps_config_load_board(BOARD_OK, &f->board, f->err, sizeof(f->err)), 0);
    const ps_board_cfg_t *b = &f->board;
    assert_string_equal(b->name, "bench");
    assert_int_equal(b->kind, PS_BOARD_LINUX);
    assert_true(b->bus_budget == 0.8f);
    assert_int_equal(b->n_buses, 2);
    assert_string_equal(b->buses[1].ifname, "vcan1");
    assert_int_equal(b->buses[0].bitrate, 500000);
    assert_string_equal(b->gpio.chip, "gpiochip0");
    assert_false(b->gpio.is_estop_active_low);
    assert_int_equal(b->gpio.estop_line, 4);
    assert_int_equal(b->gpio.enable_line, 5);
    assert_int_equal(b->gpio.led_line, 6);
    assert_int_equal(b->rt.priority, 0);
    assert_int_equal(b->rt.loop_cpu, -1);
    assert_int_equal(b->rt.plant_cpu, -1);
    assert_int_equal(b->rt.worker_cpu, -1);
}

static void test_load_scenario_shipped_scenarios_ok(void **state)
{
    fx_t *f = *state;
    ps_scenario_cfg_t *s = &f->scenario;

    assert_int_equal(ps_config_load_scenario("scenarios/stand.yaml", s, f->err, sizeof(f->err)), 0);
    assert_string_equal(s->name, "stand");
    assert_true(s->duration_s == 20.0f);
    assert_int_equal(s->n_pushes, 0);
    assert_int_equal(s->n_events, 2);
    assert_int_equal(s->events[0].kind, PS_EVENT_START);
    assert_true(s->events[0].t_s == 0.2f);
    assert_int_equal(s->events[1].kind, PS_EVENT_HARNESS_RELEASE);
    assert_true(s->events[1].t_s == 2.0f);

    assert_int_equal(ps_config_load_scenario("scenarios/push.yaml", s, f->err, sizeof(f->err)), 0);
    assert_true(s->n_pushes >= 2);
    for (uint32_t i = 0; i < s->n_pushes; i++) {
        assert_string_equal(s->pushes[i].body, "torso");
        assert_true(s->pushes[i].t_s > 4.0f);
        assert_true(s->pushes[i].duration_s > 0.0f);
    }

    assert_int_equal(ps_config_load_scenario("scenarios/estop.yaml", s, f->err, sizeof(f->err)), 0);
    static const ps_event_kind_t ESTOP_KINDS[] = {PS_EVENT_START,       PS_EVENT_HARNESS_RELEASE,
                                                  PS_EVENT_ESTOP_PRESS, PS_EVENT_ESTOP_RELEASE,
                                                  PS_EVENT_RESET,       PS_EVENT_START};
    static const float ESTOP_T_S[] = {0.2f, 2.0f, 4.0f, 5.0f, 6.0f, 6.5f};
    assert_int_equal(s->n_events, 6);
    for (uint32_t i = 0; i < 6; i++) {
        assert_int_equal(s->events[i].kind, ESTOP_KINDS[i]);
        assert_true(s->events[i].t_s == ESTOP_T_S[i]);
    }

    assert_int_equal(
        ps_config_load_scenario("scenarios/fault-drop.yaml", s, f->err, sizeof(f->err)), 0);
    const ps_event_cfg_t *drop = &s->events[s->n_events - 1u];
    assert_int_equal(drop->kind, PS_EVENT_DROP_REPLIES);
    assert_string_equal(drop->joint, "l_knee");
    assert_true(drop->t_s == 4.0f);
    assert_true(drop->duration_s == 0.05f);
}

static void test_load_scenario_fixture_defaults_applied(void **state)
{
    fx_t *f = *state;
    ps_scenario_cfg_t *s = &f->scenario;
    assert_int_equal(ps_config_load_scenario(SCENARIO_OK, s, f->err, sizeof(f->err)), 0);
    assert_string_equal(s->name, "mixed");
    assert_true(s->duration_s == 0.0f);
    assert_int_equal(s->seed, 42);
    assert_int_equal(s->n_events, 3);
    assert_string_equal(s->events[0].joint, "");  /* optional, absent */
    assert_true(s->events[1].duration_s == 0.0f); /* optional, absent: rest of the run */
    assert_string_equal(s->events[2].joint, "r_knee");
    assert_true(s->events[2].duration_s == 0.25f);
    assert_int_equal(s->n_pushes, 1);
    assert_true(s->pushes[0].force_n[0] == 10.0f);
    assert_true(s->pushes[0].force_n[1] == -20.5f);
    assert_true(s->pushes[0].force_n[2] == 0.0f);
}

#define CROWD_OK "tests/data/config/crowd_ok.yaml"

static void test_load_scenario_crowd_fixture_values_and_defaults(void **state)
{
    fx_t *f = *state;
    ps_scenario_cfg_t *s = &f->scenario;
    assert_int_equal(ps_config_load_scenario(CROWD_OK, s, f->err, sizeof(f->err)), 0);
    const ps_crowd_cfg_t *c = &s->crowd;
    assert_true(c->is_enabled);
    assert_true(s->robot_xy_m[0] == 0.5f && s->robot_xy_m[1] == -0.25f);
    assert_true(s->robot_yaw_rad == 0.3f);
    assert_true(c->has_arena_walls);
    assert_true(c->robot_a_n == 0.0f);   /* given as 0: kept, not defaulted */
    assert_true(c->social.v0_m_s == 1.1f);
    assert_true(c->social.a_n == 500.0f);
    assert_true(c->social.tau_s == 0.54f); /* default: thesis 004, Table 6.1 */
    assert_true(c->social.b_m == 0.08f);   /* default: Helbing 2000 */
    assert_true(c->body.body_k_n_m == 60000.0f);
    assert_true(c->body.step_max_m == 0.73f);
    assert_true(c->measure.x_min_m == -4.0f && c->measure.y_max_m == 3.0f); /* = arena */
    assert_int_equal(c->n_groups, 2);
    assert_int_equal(c->groups[0].layout, PS_CROWD_LAYOUT_LATTICE);
    assert_int_equal(c->groups[0].goal, PS_CROWD_GOAL_HOLD);
    assert_true(c->groups[0].height_m == 1.70f && c->groups[0].radius_m == 0.17f);
    assert_true(c->groups[1].height_m == 1.8f);
    assert_int_equal(c->groups[1].layout, PS_CROWD_LAYOUT_LINE);
    assert_int_equal(c->n_walls, 1);
    assert_int_equal(c->n_obstacles, 1);
    assert_int_equal(c->n_events, 3);
    assert_int_equal(c->events[0].agent, 3);
    assert_int_equal(c->events[0].profile, PS_CROWD_PROFILE_HALF_SINE);
    assert_int_equal(c->events[1].agent, -1); /* absent: the whole group */
    assert_true(c->events[1].direction[0] == 0.0f && c->events[1].direction[1] == 1.0f);
    assert_int_equal(c->events[2].kind, PS_CROWD_EVENT_WALL);
    assert_int_equal(c->tags, PS_CROWD_TAGS_AUTO); /* absent: as the camera decides */
    assert_true(c->tag_size_m == 0.12f);
    edit(f, CROWD_OK, "arena_walls: true", "arena_walls: true\n  tags: false");
    assert_int_equal(ps_config_load_scenario(f->path, s, f->err, sizeof(f->err)), 0);
    assert_int_equal(s->crowd.tags, PS_CROWD_TAGS_OFF);
    edit(f, CROWD_OK, "arena_walls: true", "arena_walls: true\n  tags: true");
    assert_int_equal(ps_config_load_scenario(f->path, s, f->err, sizeof(f->err)), 0);
    assert_int_equal(s->crowd.tags, PS_CROWD_TAGS_ON);

    /* a scenario without a crowd section has none */
    assert_int_equal(ps_config_load_scenario("scenarios/stand.yaml", s, f->err, sizeof(f->err)),
                     0);
    assert_false(s->crowd.is_enabled);
}

static void test_load_scenario_crowd_rejections(void **state)
{
    fx_t *f = *state;
    edit(f, CROWD_OK, "density_m2: 3", "density_m2: 9");
    want(f, "%s:%d: crowd.groups[0].density_m2: value 9 outside [0, 8]", f->path,
         line_of(f, "density_m2: 9"));
    expect_scenario_error(f);

    edit(f, CROWD_OK, "goal: hold", "goal: stage");
    want(f,
         "%s:%d: crowd.groups[0].goal: unknown value \"stage\" (allowed: hold, direction, point, "
         "robot)",
         f->path, line_of(f, "stage"));
    expect_scenario_error(f);

    edit(f, CROWD_OK, "density_m2: 3, ", "");
    want(f, "%s:%d: crowd.groups[0]: needs a count or a density_m2", f->path,
         line_of(f, "{name: fans"));
    expect_scenario_error(f);

    edit(f, CROWD_OK, "group: line,", "group: lane,");
    want(f, "%s:%d: crowd.events[0].group: \"lane\" is not a group of the crowd", f->path,
         line_of(f, "lane"));
    expect_scenario_error(f);

    edit(f, CROWD_OK, "agent: 3,", "agent: 4,");
    want(f, "%s:%d: crowd.events[0].agent: value 4, group line has 4 agents", f->path,
         line_of(f, "agent: 4"));
    expect_scenario_error(f);

    edit(f, CROWD_OK, "rows: 2, ", "");
    want(f, "%s:%d: crowd.events[1]: a surge needs rows, speed_m_s and a direction", f->path,
         line_of(f, "kind: surge") );
    expect_scenario_error(f);

    edit(f, CROWD_OK, "wall: [-3.9, -3, -3.9, 0], ", "");
    want(f,
         "%s:%d: crowd.events[2]: a wall needs a wall [x0, y0, x1, y1], speed_m_s and a "
         "direction",
         f->path, line_of(f, "kind: wall"));
    expect_scenario_error(f);

    edit(f, CROWD_OK, "x_max_m: 4, y_max_m: 3}\n  arena_walls", "x_max_m: -4, y_max_m: 3}\n  arena_walls");
    want(f, "%s:%d: crowd.arena: empty rectangle: x -4..-4, y -3..3", f->path,
         line_of(f, "arena: {"));
    expect_scenario_error(f);

    edit(f, CROWD_OK, "body: {body_k_n_m: 60000}", "body: {step_time_s: 0.3}");
    want(f, "%s:%d: crowd.body.step_time_s: value 0.3 outside [0.5, 1]", f->path,
         line_of(f, "step_time_s"));
    expect_scenario_error(f);

    edit(f, CROWD_OK, "name: line,", "name: fans,");
    want(f, "%s:%d: crowd.groups[1].name: \"fans\" names an earlier group too", f->path,
         line_of(f, "name: fans, count"));
    expect_scenario_error(f);

    edit(f, CROWD_OK, "arena_walls: true", "arena_walls: yes");
    expect_scenario_error_any(f);

    edit(f, CROWD_OK, "arena_walls: true", "arena_walls: true\n  tags: maybe");
    want(f, "%s:%d: crowd.tags: unknown value \"maybe\" (allowed: auto, true, false)", f->path,
         line_of(f, "tags: maybe"));
    expect_scenario_error(f);
}

/* ---- robot fixture ---------------------------------------------------- */

static void test_load_robot_fixture_exact_values(void **state)
{
    fx_t *f = *state;
    ps_robot_cfg_t *r = &f->robot;
    assert_int_equal(ps_config_load_robot(ROBOT_OK, r, f->err, sizeof(f->err)), 0);
    assert_string_equal(r->name, "tiny");
    assert_string_equal(r->model, "../models/tiny.xml"); /* stored as given */
    assert_int_equal(r->control.servo_hz, 1000);
    assert_int_equal(r->control.policy_hz, 50);
    assert_true(r->control.policy_deadline_s == 0.0004f);
    assert_int_equal(r->control.overrun_limit, 5);
    assert_true(r->control.overrun_window_s == 1.0f);
    assert_true(r->control.hold_s == 10.0f);
    /* thermal settings and the frozen-IMU run not written: the defaults */
    assert_true(r->control.derate_band_c == 15.0f);
    assert_true(r->control.hot_margin_c == 5.0f);
    assert_true(r->control.derate_min == 0.5f);
    assert_int_equal(r->imu.bus_idx, 1);
    assert_int_equal(r->imu.base_id, 0x80); /* hex in the file */
    assert_int_equal(r->imu.rate_div, 1);
    assert_int_equal(r->imu.frozen_samples, 50); /* 50 ms at 1000 Hz */
    assert_true(r->kin.mass_kg == 32.0f);
    assert_true(r->kin.fall_com_height_m == 0.4f);

    assert_int_equal(r->n_joints, 3);
    const ps_act_cfg_t *a0 = &r->act[0];
    const ps_servo_joint_cfg_t *s0 = &r->servo[0];
    assert_string_equal(r->joint_name[0], "l_hip_yaw");
    assert_int_equal(a0->bus_idx, 0);
    assert_int_equal(a0->can_id, 0x01);
    assert_int_equal(a0->reply_id, 0x101);
    assert_int_equal(a0->protocol, PS_ACT_PROTO_MIT);
    assert_true(s0->lim.pos_min_rad == -0.6f);
    assert_true(s0->kd_nm_s_rad == 1.5f);
    assert_true(a0->kt_nm_a == 0.6f);
    assert_int_equal(a0->rate_div, 2);
    /* no gear, direction or zero offset written: identity */
    assert_true(a0->gear_ratio == 1.0f);
    assert_true(a0->direction == 1.0f);
    assert_true(a0->zero_offset_rad == 0.0f);
    /* ak80-9 ranges copied into the actuator, and seen unchanged by the servo */
    assert_true(a0->wire.p_min_rad == -12.5f);
    assert_true(a0->wire.v_max_rad_s == 50.0f);
    assert_true(a0->wire.kd_max_nm_s_rad == 5.0f);
    assert_true(a0->wire.t_max_nm == 18.0f);
    assert_true(a0->wire.i_min_a == -30.0f);
    assert_true(s0->wire.p_min_rad == -12.5f);
    assert_true(s0->wire.t_max_nm == 18.0f);
    /* ak70-10 ranges for the knees */
    for (uint32_t i = 1; i < 3; i++) {
        assert_true(r->act[i].wire.v_min_rad_s == -30.0f);
        assert_true(r->act[i].wire.t_min_nm == -25.0f);
        assert_true(r->act[i].wire.i_max_a == 40.0f);
    }
    assert_int_equal(r->act[2].bus_idx, 1);
    /* where the fields other files refer to are */
    assert_string_equal(r->src.path, ROBOT_OK);
    assert_int_equal(r->src.imu_bus_line, 7);
    assert_int_equal(r->src.joint_bus_line[0], 19);
    assert_int_equal(r->src.joint_bus_line[2], 25);
}

static void test_load_robot_sim_fixture_same_robot_and_section(void **state)
{
    fx_t *f = *state;
    ps_robot_cfg_t plain;
    assert_int_equal(ps_config_load_robot(ROBOT_OK, &plain, f->err, sizeof(f->err)), 0);
    assert_int_equal(
        ps_config_load_robot_sim(ROBOT_OK, &f->robot, &f->robot_sim, f->err, sizeof(f->err)), 0);
    assert_memory_equal(&plain, &f->robot, sizeof(plain));
    assert_true(f->robot_sim.gyro_noise_rad_s == 0.002f);
    assert_true(f->robot_sim.reply_latency_s == 0.00005f);
    assert_true(f->robot_sim.thermal_tau_s == 60.0f);
    assert_true(f->robot_sim.ambient_c == 25.0f);
    assert_int_equal(ps_config_load_robot_sim(ROBOT_OK, &f->robot, NULL, f->err, sizeof(f->err)),
                     -EINVAL);
}

static void test_load_robot_ps1_when_present_ok(void **state)
{
    fx_t *f = *state;
    if (access("robots/ps1.yaml", R_OK) != 0)
        skip(); /* written with the MuJoCo model by another change */
    int rc = ps_config_load_robot("robots/ps1.yaml", &f->robot, f->err, sizeof(f->err));
    if (rc != 0)
        print_error("%s\n", f->err);
    assert_int_equal(rc, 0);
    assert_true(f->robot.n_joints >= 1);
    /* the shipped sim board and scenarios fit it */
    assert_int_equal(ps_config_load_board("boards/sim.yaml", &f->board, f->err, sizeof(f->err)), 0);
    static const char *const SCENARIOS[] = {"scenarios/stand.yaml", "scenarios/push.yaml",
                                            "scenarios/estop.yaml", "scenarios/fault-drop.yaml"};
    for (size_t i = 0; i < sizeof(SCENARIOS) / sizeof(SCENARIOS[0]); i++) {
        assert_int_equal(
            ps_config_load_scenario(SCENARIOS[i], &f->scenario, f->err, sizeof(f->err)), 0);
        rc = ps_config_check_pair(&f->board, &f->robot, f->err, sizeof(f->err));
        if (rc == 0)
            rc = ps_config_check_scenario(&f->robot, &f->scenario, f->err, sizeof(f->err));
        if (rc != 0)
            print_error("%s\n", f->err);
        assert_int_equal(rc, 0);
    }
}

/* ---- errors common to all loaders -------------------------------------- */

static void test_load_missing_file_enoent(void **state)
{
    fx_t *f = *state;
    const char *path = FIXTURES "no_such_file.yaml";
    assert_int_equal(ps_config_load_board(path, &f->board, f->err, sizeof(f->err)), -ENOENT);
    want(f, "%s: cannot open: %s", path, strerror(ENOENT));
    assert_string_equal(f->err, f->want);
    assert_int_equal(ps_config_load_robot(path, &f->robot, f->err, sizeof(f->err)), -ENOENT);
    assert_int_equal(ps_config_load_scenario(path, &f->scenario, f->err, sizeof(f->err)), -ENOENT);
}

static void test_load_null_args_einval(void **state)
{
    fx_t *f = *state;
    assert_int_equal(ps_config_load_board(NULL, &f->board, f->err, sizeof(f->err)), -EINVAL);
    assert_int_equal(ps_config_load_board(BOARD_OK, NULL, f->err, sizeof(f->err)), -EINVAL);
    assert_int_equal(ps_config_load_robot(NULL, &f->robot, f->err, sizeof(f->err)), -EINVAL);
    assert_int_equal(ps_config_load_scenario(SCENARIO_OK, NULL, f->err, sizeof(f->err)), -EINVAL);
    assert_int_equal(ps_config_check_pair(NULL, &f->robot, f->err, sizeof(f->err)), -EINVAL);
    assert_int_equal(ps_config_check_scenario(&f->robot, NULL, f->err, sizeof(f->err)), -EINVAL);
}

static void test_load_board_failure_out_untouched(void **state)
{
    fx_t *f = *state;
    edit(f, "boards/sim.yaml", "bitrate: 1000000", "bitrate: 5");
    memset(&f->board, 0xa5, sizeof(f->board));
    ps_board_cfg_t before;
    memcpy(&before, &f->board, sizeof(before));
    assert_int_equal(ps_config_load_board(f->path, &f->board, f->err, sizeof(f->err)),
                     -PS_ERR_CONFIG);
    assert_memory_equal(&f->board, &before, sizeof(before));
}

static void test_load_board_small_or_null_err_truncated(void **state)
{
    fx_t *f = *state;
    edit(f, "boards/sim.yaml", "bitrate: 1000000", "bitrate: 5");
    assert_int_equal(ps_config_load_board(f->path, &f->board, NULL, 0), -PS_ERR_CONFIG);
    char small[8];
    memset(small, 'x', sizeof(small));
    assert_int_equal(ps_config_load_board(f->path, &f->board, small, sizeof(small)),
                     -PS_ERR_CONFIG);
    assert_int_equal(strlen(small), sizeof(small) - 1u);
    assert_memory_equal(small, f->path, sizeof(small) - 1u);
}

/* ---- board rejections --------------------------------------------------- */

static void test_load_board_top_field_missing_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, "boards/sim.yaml", "\nbuses:\n", "\nbusses:\n");
    want(f, "%s:%d: unknown key \"busses\"", f->path, line_of(f, "busses:"));
    expect_board_error(f);

    /* Without the misspelt key the field is plainly missing: no line for the root. */
    edit(f, "boards/sim.yaml", "name: sim\n", "");
    want(f, "%s: missing field \"name\"", f->path);
    expect_board_error(f);
}

static void test_load_board_nested_field_missing_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, "boards/sim.yaml", "chip: sim, ", "");
    want(f, "%s:%d: gpio: missing field \"chip\"", f->path, line_of(f, "gpio:"));
    expect_board_error(f);
}

static void test_load_board_string_for_number_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, "boards/sim.yaml", "{ifname: can1, bitrate: 1000000}", "{ifname: can1, bitrate: fast}");
    /* an integer field: the loader's own words, with the field's range */
    want(f, "%s:%d: buses[1].bitrate: value \"fast\" is not an integer in [10000, 1000000]",
         f->path, line_of(f, "bitrate: fast"));
    expect_board_error(f);
}

static void test_load_board_bitrate_high_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, "boards/sim.yaml", "{ifname: can1, bitrate: 1000000}",
         "{ifname: can1, bitrate: 2000000}");
    want(f, "%s:%d: buses[1].bitrate: value 2000000 outside [10000, 1000000]", f->path,
         line_of(f, "2000000"));
    expect_board_error(f);
}

static void test_load_board_bitrate_low_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, "boards/sim.yaml", "{ifname: can3, bitrate: 1000000}", "{ifname: can3, bitrate: 9999}");
    want(f, "%s:%d: buses[3].bitrate: value 9999 outside [10000, 1000000]", f->path,
         line_of(f, "9999"));
    expect_board_error(f);
}

static void test_load_board_budget_zero_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, "boards/sim.yaml", "bus_budget: 0.8", "bus_budget: 0");
    want(f, "%s:%d: bus_budget: value 0 outside (0, 1]", f->path, line_of(f, "bus_budget"));
    expect_board_error(f);
}

static void test_load_board_cpu_below_minus_one_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, "boards/sim.yaml", "loop_cpu: 1", "loop_cpu: -2");
    want(f, "%s:%d: rt.loop_cpu: value -2 outside [-1, 1023]", f->path, line_of(f, "loop_cpu"));
    expect_board_error(f);
}

static void test_load_board_unknown_nested_key_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, "boards/sim.yaml", "priority: 80,", "priority: 80, prio: 3,");
    want(f, "%s:%d: rt: unknown key \"prio\"", f->path, line_of(f, "prio:"));
    expect_board_error(f);
}

static void test_load_board_unknown_kind_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, "boards/sim.yaml", "kind: sim", "kind: simulator");
    want(f, "%s:%d: kind: unknown value \"simulator\" (allowed: sim, linux)", f->path,
         line_of(f, "kind:"));
    expect_board_error(f);

    /* A number is not an enum value either (libcyaml would take 1 as linux). */
    edit(f, "boards/sim.yaml", "kind: sim", "kind: 1");
    want(f, "%s:%d: kind: unknown value \"1\" (allowed: sim, linux)", f->path, line_of(f, "kind:"));
    expect_board_error(f);
}

static void test_load_board_bool_typo_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, "boards/sim.yaml", "estop_active_low: true", "estop_active_low: off");
    want(f, "%s:%d: gpio.estop_active_low: unknown value \"off\" (allowed: true, false)", f->path,
         line_of(f, "estop_active_low"));
    expect_board_error(f);
}

static void test_load_board_too_many_buses_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, "boards/sim.yaml", "  - {ifname: can3, bitrate: 1000000}\n",
         "  - {ifname: can3, bitrate: 1000000}\n  - {ifname: can4, bitrate: 1000000}\n"
         "  - {ifname: can5, bitrate: 1000000}\n  - {ifname: can6, bitrate: 1000000}\n"
         "  - {ifname: can7, bitrate: 1000000}\n  - {ifname: can8, bitrate: 1000000}\n");
    want(f, "%s:%d: buses: 9 entries outside [1, 8]", f->path, line_of(f, "  - {ifname: can0"));
    expect_board_error(f);
}

static void test_load_board_long_ifname_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, "boards/sim.yaml", "ifname: can2", "ifname: can_interface_with_a_very_long_name");
    want(f,
         "%s:%d: buses[2].ifname: string \"can_interface_with_a_very_long_name\" length 35 "
         "outside [1, 31]",
         f->path, line_of(f, "very_long"));
    expect_board_error(f);
}

static void test_load_board_duplicate_ifname_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, "boards/sim.yaml", "ifname: can3", "ifname: \"can0\"");
    want(f, "%s:%d: buses[3].ifname: duplicate interface \"can0\" (also buses[0])", f->path,
         line_of(f, "\"can0\""));
    expect_board_error(f);
}

static void test_load_board_duplicate_key_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, "boards/sim.yaml", "bus_budget: 0.8\n", "bus_budget: 0.8\nbus_budget: 0.5\n");
    want(f, "%s:%d: duplicate key \"bus_budget\"", f->path, line_of(f, "bus_budget: 0.5"));
    expect_board_error(f);
}

static void test_load_board_syntax_error_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, "boards/sim.yaml", "{ifname: can1, bitrate: 1000000}", "{ifname: can1, bitrate: 1");
    const int open_line = line_of(f, "{ifname: can1");
    assert_int_equal(ps_config_load_board(f->path, &f->board, f->err, sizeof(f->err)),
                     -PS_ERR_CONFIG);
    /* libyaml notices the missing '}' on the next line and names the opener */
    want(f, "%s:%d: YAML syntax error: ", f->path, open_line + 1);
    assert_memory_equal(f->err, f->want, strlen(f->want));
    want(f, "(while parsing a flow mapping at line %d)", open_line);
    assert_non_null(strstr(f->err, f->want));
}

static void test_load_board_gpio_line_reused_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, "boards/sim.yaml", "led_line: 2", "led_line: 0");
    want(f, "%s:%d: gpio.led_line: line 0 already used by gpio.estop_line", f->path,
         line_of(f, "led_line"));
    expect_board_error(f);
}

/* Lines by name instead of offset, with the optional bias and debounce. */
static void test_load_board_gpio_names_loaded(void **state)
{
    fx_t *f = *state;
    edit(f, BOARD_OK, "estop_line: 4, estop_active_low: false, enable_line: 5, led_line: 6",
         "estop_name: GPIO17, estop_active_low: false, enable_name: \"GPIO27\", led_line: 6,\n"
         "       estop_bias: pull-up, estop_debounce_us: 2000");
    assert_int_equal(ps_config_load_board(f->path, &f->board, f->err, sizeof(f->err)), 0);
    const ps_gpio_cfg_t *g = &f->board.gpio;
    assert_string_equal(g->estop_name, "GPIO17");
    assert_string_equal(g->enable_name, "GPIO27");
    assert_string_equal(g->led_name, "");
    assert_int_equal(g->estop_line, 0);
    assert_int_equal(g->enable_line, 0);
    assert_int_equal(g->led_line, 6);
    assert_int_equal(g->estop_bias, PS_GPIO_BIAS_PULL_UP);
    assert_int_equal(g->estop_debounce_us, 2000);

    /* absent: no name, bias as-is, no debounce */
    assert_int_equal(ps_config_load_board(BOARD_OK, &f->board, f->err, sizeof(f->err)), 0);
    assert_string_equal(f->board.gpio.estop_name, "");
    assert_int_equal(f->board.gpio.estop_bias, PS_GPIO_BIAS_AS_IS);
    assert_int_equal(f->board.gpio.estop_debounce_us, 0);
}

/* The flight recorder's button: optional, by line or name, a line of its own. */
static void test_load_board_gpio_record_button(void **state)
{
    fx_t *f = *state;
    assert_int_equal(ps_config_load_board(BOARD_OK, &f->board, f->err, sizeof(f->err)), 0);
    assert_false(f->board.gpio.has_button); /* absent: none */
    edit(f, BOARD_OK, "led_line: 6}", "led_line: 6, record_button_line: 7}");
    assert_int_equal(ps_config_load_board(f->path, &f->board, f->err, sizeof(f->err)), 0);
    assert_true(f->board.gpio.has_button);
    assert_int_equal(f->board.gpio.button_line, 7);
    assert_false(f->board.gpio.is_button_active_low);
    edit(f, BOARD_OK, "led_line: 6}",
         "led_line: 6, record_button_name: GPIO22, record_button_active_low: true}");
    assert_int_equal(ps_config_load_board(f->path, &f->board, f->err, sizeof(f->err)), 0);
    assert_true(f->board.gpio.has_button);
    assert_string_equal(f->board.gpio.button_name, "GPIO22");
    assert_true(f->board.gpio.is_button_active_low);
    edit(f, BOARD_OK, "led_line: 6}", "led_line: 6, record_button_line: 6}");
    want(f, "%s:%d: gpio.record_button_line: line 6 already used by gpio.led_line", f->path,
         line_of(f, "record_button_line"));
    expect_board_error(f);
    edit(f, BOARD_OK, "led_line: 6}",
         "led_line: 6, record_button_line: 7, record_button_name: GPIO22}");
    want(f, "%s:%d: gpio.record_button_name: give gpio.record_button_line or "
            "gpio.record_button_name, not both",
         f->path, line_of(f, "record_button_name"));
    expect_board_error(f);
}

static void test_load_board_gpio_debounce_out_of_range_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, BOARD_OK, "led_line: 6}", "led_line: 6, estop_debounce_us: 20001}");
    want(f, "%s:%d: gpio.estop_debounce_us: value 20001 outside [0, 20000]", f->path,
         line_of(f, "estop_debounce_us"));
    expect_board_error(f);
    edit(f, BOARD_OK, "led_line: 6}", "led_line: 6, estop_debounce_us: -1}");
    want(f, "%s:%d: gpio.estop_debounce_us: value -1 outside [0, 20000]", f->path,
         line_of(f, "estop_debounce_us"));
    expect_board_error(f);
    edit(f, BOARD_OK, "led_line: 6}", "led_line: 6, estop_debounce_us: 2.5}");
    want(f, "%s:%d: gpio.estop_debounce_us: value \"2.5\" is not an integer in [0, 20000]", f->path,
         line_of(f, "estop_debounce_us"));
    expect_board_error(f);
    edit(f, BOARD_OK, "led_line: 6}", "led_line: 6, estop_debounce_us: 20000}"); /* the bound */
    assert_int_equal(ps_config_load_board(f->path, &f->board, f->err, sizeof(f->err)), 0);
    assert_int_equal(f->board.gpio.estop_debounce_us, 20000);
}

static void test_load_board_gpio_name_too_long_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, BOARD_OK, "led_line: 6", "led_name: abcdefghijklmnopqrstuvwxyz012345");
    want(f,
         "%s:%d: gpio.led_name: string \"abcdefghijklmnopqrstuvwxyz012345\" length 32 "
         "outside [1, 31]",
         f->path, line_of(f, "led_name"));
    expect_board_error(f);
    edit(f, BOARD_OK, "led_line: 6", "led_name: \"\""); /* written, so not empty */
    want(f, "%s:%d: gpio.led_name: string \"\" length 0 outside [1, 31]", f->path,
         line_of(f, "led_name"));
    expect_board_error(f);
}

/* Each line by offset or by name: exactly one of the two. */
static void test_load_board_gpio_line_and_name_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, BOARD_OK, "enable_line: 5", "enable_line: 5, enable_name: GPIO27");
    want(f, "%s:%d: gpio.enable_name: give gpio.enable_line or gpio.enable_name, not both", f->path,
         line_of(f, "enable_name"));
    expect_board_error(f);
    edit(f, BOARD_OK, "enable_line: 5, ", "");
    want(f, "%s:%d: gpio: missing field \"enable_line\" (or \"enable_name\")", f->path,
         line_of(f, "gpio:"));
    expect_board_error(f);
}

static void test_load_board_gpio_name_reused_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, BOARD_OK, "estop_line: 4", "estop_name: GPIO17");
    edit_again(f, "led_line: 6", "led_name: GPIO17");
    want(f, "%s:%d: gpio.led_name: line \"GPIO17\" already used by gpio.estop_name", f->path,
         line_of(f, "led_name"));
    expect_board_error(f);
    /* a name and an offset are not compared: the port checks them on the chip */
    edit(f, BOARD_OK, "estop_line: 4", "estop_name: GPIO5");
    assert_int_equal(ps_config_load_board(f->path, &f->board, f->err, sizeof(f->err)), 0);
}

/* buses[i].controller: loaded, checked against fd, unknown names refused;
 * camera: optional. */
static void test_load_board_controller_and_camera_loaded(void **state)
{
    fx_t *f = *state;
    edit(f, BOARD_OK, "{ifname: can0, bitrate: 500000}",
         "{ifname: can0, bitrate: 500000, controller: mcp2515}");
    append(f, "camera: {sensor: imx708}\n");
    assert_int_equal(ps_config_load_board(f->path, &f->board, f->err, sizeof(f->err)), 0);
    assert_int_equal(f->board.buses[0].controller, PS_CANBUS_CTRL_MCP2515);
    assert_int_equal(f->board.buses[1].controller, PS_CANBUS_CTRL_ANY); /* absent */
    assert_true(f->board.has_camera);
    assert_string_equal(f->board.camera.sensor, "imx708");
    assert_int_equal(ps_config_load_board(BOARD_OK, &f->board, f->err, sizeof(f->err)), 0);
    assert_false(f->board.has_camera);
}

static void test_load_board_fd_on_classical_controller_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, BOARD_OK, "{ifname: can0, bitrate: 500000}",
         "{ifname: can0, bitrate: 500000, fd: true, controller: mcp2515}");
    want(f, "%s:%d: buses[0].fd: controller mcp2515 is classical CAN only", f->path,
         line_of(f, "fd: true"));
    expect_board_error(f);
    edit(f, BOARD_OK, "{ifname: can0, bitrate: 500000}",
         "{ifname: can0, bitrate: 500000, fd: true, controller: mcp251xfd}");
    assert_int_equal(ps_config_load_board(f->path, &f->board, f->err, sizeof(f->err)), 0);
    assert_int_equal(f->board.buses[0].controller, PS_CANBUS_CTRL_MCP251XFD);
}

static void test_load_board_unknown_controller_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, BOARD_OK, "{ifname: can0, bitrate: 500000}",
         "{ifname: can0, bitrate: 500000, controller: sja1000}");
    want(f,
         "%s:%d: buses[0].controller: unknown value \"sja1000\" (allowed: mcp2515, mcp251xfd, "
         "mttcan, m_can, gs_usb, virtual)",
         f->path, line_of(f, "controller"));
    expect_board_error(f);
    edit(f, BOARD_OK, "rt:", "camera: {}\nrt:");
    want(f, "%s:%d: camera: missing field \"sensor\"", f->path, line_of(f, "camera"));
    expect_board_error(f);
}

static void test_load_board_gpio_bias_unknown_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, BOARD_OK, "led_line: 6}", "led_line: 6, estop_bias: up}");
    want(f,
         "%s:%d: gpio.estop_bias: unknown value \"up\" (allowed: as-is, pull-up, pull-down, "
         "disabled)",
         f->path, line_of(f, "estop_bias"));
    expect_board_error(f);
}

/* ---- robot rejections --------------------------------------------------- */

static void test_load_robot_string_for_number_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "ramp_s: 1.0", "ramp_s: fast");
    want(f, "%s:%d: control.ramp_s: value \"fast\" is not a number in [0.1, 10]", f->path,
         line_of(f, "ramp_s"));
    expect_robot_error(f);
    /* a mapping where a number belongs keeps libcyaml's text */
    edit(f, ROBOT_OK, "ramp_s: 1.0", "ramp_s: {a: 1}");
    char prefix[256];
    (void)snprintf(prefix, sizeof(prefix), "%s:%d: control.ramp_s: ", f->path,
                   line_of(f, "ramp_s"));
    assert_int_equal(ps_config_load_robot(f->path, &f->robot, f->err, sizeof(f->err)),
                     -PS_ERR_CONFIG);
    assert_memory_equal(f->err, prefix, strlen(prefix));
}

static void test_load_robot_missing_field_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "kt_nm_a: 0.6, ", "");
    want(f, "%s:%d: joints[0]: missing field \"kt_nm_a\"", f->path, line_of(f, "l_hip_yaw"));
    expect_robot_error(f);
}

static void test_load_robot_duplicate_can_id_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "{name: r_knee, bus: 1,", "{name: r_knee, bus: 0,");
    want(f, "%s:%d: joints[2].can_id: id 0x002 on bus 0 already used by joints[1].can_id", f->path,
         line_of(f, "r_knee"));
    expect_robot_error(f);
}

static void test_load_robot_reply_id_on_imu_rejected(void **state)
{
    fx_t *f = *state;
    /* the IMU listens on 0x080 and 0x081 of bus 1, where r_knee sits */
    edit(f, ROBOT_OK, "{name: r_knee, bus: 1, can_id: 0x02, reply_id: 0x102",
         "{name: r_knee, bus: 1, can_id: 0x02, reply_id: 0x081");
    want(f, "%s:%d: joints[2].reply_id: id 0x081 on bus 1 already used by imu.base_id+1", f->path,
         line_of(f, "r_knee"));
    expect_robot_error(f);
}

/* The policy runs inside one servo tick: a deadline beyond half the period
 * (the 1.5 ms policy that overran every tick passed a 2 ms deadline) is
 * refused, and so are stale-data timeouts of more than a few periods. */
static void test_load_robot_policy_deadline_beyond_half_period_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "policy_deadline_s: 0.0004", "policy_deadline_s: 0.002");
    want(f,
         "%s:%d: control.policy_deadline_s: value 0.002 does not fit in the servo period: at most "
         "half of 1/servo_hz = 0.0005 s",
         f->path, line_of(f, "policy_deadline_s: 0.002"));
    expect_robot_error(f);
}

static void test_load_robot_reply_timeout_beyond_periods_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "reply_timeout_s: 0.005", "reply_timeout_s: 0.5");
    want(f,
         "%s:%d: control.reply_timeout_s: value 0.5 is more than 10 command periods of the fastest "
         "joint (rate_div 1 at 1000 Hz): at most 0.01 s",
         f->path, line_of(f, "reply_timeout_s: 0.5"));
    expect_robot_error(f);
}

static void test_load_robot_imu_timeout_beyond_periods_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "imu_timeout_s: 0.005", "imu_timeout_s: 0.0101");
    want(f,
         "%s:%d: control.imu_timeout_s: value 0.0101 is more than 10 IMU sample periods (rate_div "
         "1 at 1000 Hz): at most 0.01 s",
         f->path, line_of(f, "imu_timeout_s: 0.0101"));
    expect_robot_error(f);
}

static void test_load_robot_overrun_limit_zero_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "overrun_limit: 5", "overrun_limit: 0");
    want(f, "%s:%d: control.overrun_limit: value 0 outside [1, 64]", f->path,
         line_of(f, "overrun_limit: 0"));
    expect_robot_error(f);
}

/* Drive temperature thresholds (docs/safety.md "Hot drives"), optional in
 * `control:`: taken as written; refused outside their ranges, and when the
 * derating band has no width (the message names a field the file has). */
static void test_load_robot_thermal_settings_taken(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "hold_s: 10.0", "hold_s: 10.0, derate_band_c: 30, hot_margin_c: 0, derate_min: 1");
    assert_int_equal(ps_config_load_robot(f->path, &f->robot, f->err, sizeof(f->err)), 0);
    assert_true(f->robot.control.derate_band_c == 30.0f);
    assert_true(f->robot.control.hot_margin_c == 0.0f);
    assert_true(f->robot.control.derate_min == 1.0f);
}

static void test_load_robot_thermal_settings_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "hold_s: 10.0", "hold_s: 10.0, derate_band_c: 5, hot_margin_c: 5");
    want(f,
         "%s:%d: control.derate_band_c: value 5 not above hot_margin_c 5: derating must start "
         "before the drive is hot",
         f->path, line_of(f, "derate_band_c: 5"));
    expect_robot_error(f);
    edit(f, ROBOT_OK, "hold_s: 10.0", "hold_s: 10.0, hot_margin_c: 20");
    want(f,
         "%s:%d: control.hot_margin_c: value 20 not below derate_band_c 15 (its default): "
         "derating must start before the drive is hot",
         f->path, line_of(f, "hot_margin_c: 20"));
    expect_robot_error(f);
    edit(f, ROBOT_OK, "hold_s: 10.0", "hold_s: 10.0, hot_margin_c: -1");
    want(f, "%s:%d: control.hot_margin_c: value -1 outside [0, 100]", f->path,
         line_of(f, "hot_margin_c: -1"));
    expect_robot_error(f);
    edit(f, ROBOT_OK, "hold_s: 10.0", "hold_s: 10.0, derate_band_c: 0");
    want(f, "%s:%d: control.derate_band_c: value 0 outside (0, 100]", f->path,
         line_of(f, "derate_band_c: 0"));
    expect_robot_error(f);
    edit(f, ROBOT_OK, "hold_s: 10.0", "hold_s: 10.0, derate_min: 0");
    want(f, "%s:%d: control.derate_min: value 0 outside (0, 1]", f->path,
         line_of(f, "derate_min: 0"));
    expect_robot_error(f);
    edit(f, ROBOT_OK, "hold_s: 10.0", "hold_s: 10.0, derate_min: 1.5");
    want(f, "%s:%d: control.derate_min: value 1.5 outside (0, 1]", f->path,
         line_of(f, "derate_min: 1.5"));
    expect_robot_error(f);
    edit(f, ROBOT_OK, "hold_s: 10.0", "hold_s: 10.0, derate_min: half");
    want(f, "%s:%d: control.derate_min: value \"half\" is not a number in (0, 1]", f->path,
         line_of(f, "derate_min: half"));
    expect_robot_error(f);
}

/* imu.frozen_samples: 0 (off) or a run of 2..10000; its default follows the
 * IMU's rate (50 ms of samples). */
static void test_load_robot_imu_frozen_samples_checked(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "rate_div: 1}", "rate_div: 1, frozen_samples: 0}");
    assert_int_equal(ps_config_load_robot(f->path, &f->robot, f->err, sizeof(f->err)), 0);
    assert_int_equal(f->robot.imu.frozen_samples, 0);
    edit(f, ROBOT_OK, "rate_div: 1}", "rate_div: 1, frozen_samples: 1}");
    want(f, "%s:%d: imu.frozen_samples: value 1 is neither 0 (off) nor a run of at least 2 samples",
         f->path, line_of(f, "frozen_samples: 1"));
    expect_robot_error(f);
    edit(f, ROBOT_OK, "rate_div: 1}", "rate_div: 1, frozen_samples: 10001}");
    want(f, "%s:%d: imu.frozen_samples: value 10001 outside [0, 10000]", f->path,
         line_of(f, "frozen_samples: 10001"));
    expect_robot_error(f);
    edit(f, ROBOT_OK, "rate_div: 1}", "rate_div: 5}"); /* 200 Hz: 10 samples */
    assert_int_equal(ps_config_load_robot(f->path, &f->robot, f->err, sizeof(f->err)), 0);
    assert_int_equal(f->robot.imu.frozen_samples, 10);
}

/* The file takes 29-bit identifiers; an 11-bit protocol refuses one above 0x7ff. */
static void test_load_robot_can_id_high_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "can_id: 0x01", "can_id: 0x800");
    want(f, "%s:%d: joints[0].can_id: value 0x800 above protocol mit's largest id 0x7ff", f->path,
         line_of(f, "0x800"));
    expect_robot_error(f);
}

/* RobStride drive ids are 8 bits; the host id (reply_id) is shared by every
 * drive of a bus, the drive ids (can_id) must differ. */
static void test_load_robot_robstride_ids_checked(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "can_id: 0x01, reply_id: 0x101, protocol: mit",
         "can_id: 0x100, reply_id: 0xFD, protocol: robstride");
    want(f, "%s:%d: joints[0].can_id: value 0x100 above protocol robstride's largest id 0xff",
         f->path, line_of(f, "0x100"));
    expect_robot_error(f);
}

static void test_load_robot_robstride_shared_host_id_ok(void **state)
{
    fx_t *f = *state;
    (void)f;
    ps_robot_cfg_t r;
    char err[PS_ERR_MSG_LEN] = "";
    const int rc = ps_config_load_robot("tests/data/robots/ps1-mixed.yaml", &r, err, sizeof err);
    if (rc != 0)
        fail_msg("%s", err);
    unsigned n_on_bus0 = 0;
    for (uint32_t j = 0; j < r.n_joints; j++)
        if (r.act[j].protocol == PS_ACT_PROTO_ROBSTRIDE && r.act[j].bus_idx == 0) {
            assert_int_equal(r.act[j].reply_id, 0xFD); /* one host id for all */
            n_on_bus0++;
        }
    assert_int_equal(n_on_bus0, 4);
}

/* moteus drive ids start at 8: below, the firmware replies with 11-bit ids
 * (drivers/ps_moteus.h). */
static void test_load_robot_moteus_low_id_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "can_id: 0x01, reply_id: 0x101, protocol: mit",
         "can_id: 0x07, reply_id: 0x01, protocol: moteus");
    want(f, "%s:%d: joints[0].can_id: value 0x7 below protocol moteus's smallest drive id 0x8",
         f->path, line_of(f, "0x07"));
    expect_robot_error(f);
}

/* A moteus joint loads; it needs an FD bus, and the pair check names the
 * robot file's protocol line when the board's bus is classical. */
static void test_check_pair_moteus_needs_fd_bus(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "can_id: 0x01, reply_id: 0x101, protocol: mit",
         "can_id: 0x08, reply_id: 0x01, protocol: moteus");
    assert_int_equal(ps_config_load_robot(f->path, &f->robot, f->err, sizeof(f->err)), 0);
    assert_int_equal(f->robot.act[0].protocol, PS_ACT_PROTO_MOTEUS);
    assert_int_equal(ps_config_load_board(BOARD_OK, &f->board, f->err, sizeof(f->err)), 0);
    assert_int_equal(ps_config_check_pair(&f->board, &f->robot, f->err, sizeof(f->err)),
                     -PS_ERR_CONFIG);
    want(f,
         "%s:%d: joints[0].protocol: moteus needs CAN FD but bus 0 (can0) of board bench is "
         "classical",
         f->path, line_of(f, "protocol: moteus"));
    assert_string_equal(f->err, f->want);
    edit(f, BOARD_OK, "{ifname: can0, bitrate: 500000}",
         "{ifname: can0, bitrate: 500000, fd: true, data_bitrate: 2000000}");
    assert_int_equal(ps_config_load_board(f->path, &f->board, f->err, sizeof(f->err)), 0);
    assert_int_equal(ps_config_check_pair(&f->board, &f->robot, f->err, sizeof(f->err)), 0);
}

static void test_load_robot_can_id_beyond_29_bits_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "can_id: 0x01", "can_id: 0x20000000");
    want(f, "%s:%d: joints[0].can_id: value 0x20000000 outside [0x1, 0x1fffffff]", f->path,
         line_of(f, "0x20000000"));
    expect_robot_error(f);
}

static void test_load_robot_gear_direction_zero_applied(void **state)
{
    fx_t *f = *state;
    /* joint 0 of the test robot: ak80-9 wire p +-12.5 rad, t +-18 Nm */
    edit(f, ROBOT_OK, "can_id: 0x01",
         "can_id: 0x01, gear_ratio: 2.0, direction: -1, zero_offset_rad: 0.25");
    assert_int_equal(ps_config_load_robot(f->path, &f->robot, f->err, sizeof(f->err)), 0);
    const ps_act_cfg_t *a = &f->robot.act[0];
    assert_true(a->gear_ratio == 2.0f && a->direction == -1.0f && a->zero_offset_rad == 0.25f);
    /* the servo sees the wire from the joint: p = 0.25 -+ 12.5 / 2, t = +-36 Nm */
    const ps_act_range_t *w = &f->robot.servo[0].wire;
    assert_float_equal(w->p_min_rad, 0.25f - 6.25f, 1e-6f);
    assert_float_equal(w->p_max_rad, 0.25f + 6.25f, 1e-6f);
    assert_float_equal(w->t_min_nm, -36.0f, 1e-6f);
    assert_float_equal(w->t_max_nm, 36.0f, 1e-6f);
}

static void test_load_robot_direction_not_unit_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "can_id: 0x01", "can_id: 0x01, direction: 0.5");
    want(f, "%s:%d: joints[0].direction: value 0.5 is not 1 or -1", f->path,
         line_of(f, "direction: 0.5"));
    expect_robot_error(f);
}

static void test_load_robot_gear_ratio_zero_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "can_id: 0x01", "can_id: 0x01, gear_ratio: 0");
    want(f, "%s:%d: joints[0].gear_ratio: value 0 outside (0, 1000]", f->path,
         line_of(f, "gear_ratio: 0"));
    expect_robot_error(f);
}

static void test_load_robot_unknown_driver_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "driver: ak70-10,", "driver: ak10,");
    want(f, "%s:%d: joints[1].driver: unknown driver \"ak10\" (known: ak80-9, ak70-10)", f->path,
         line_of(f, "driver: ak10"));
    expect_robot_error(f);
}

/* A zero ramp would step to full stiffness; no braking time would drop the
 * robot on Ctrl-C: both are refused. */
static void test_load_robot_zero_ramp_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "ramp_s: 1.0", "ramp_s: 0");
    want(f, "%s:%d: control.ramp_s: value 0 outside [0.1, 10]", f->path, line_of(f, "ramp_s"));
    expect_robot_error(f);
}

static void test_load_robot_servo_not_multiple_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "policy_hz: 50", "policy_hz: 30");
    want(f, "%s:%d: control.policy_hz: servo_hz 1000 is not a multiple of policy_hz 30", f->path,
         line_of(f, "policy_hz"));
    expect_robot_error(f);
}

static void test_load_robot_pos_outside_wire_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "pos_max_rad: 0.6", "pos_max_rad: 13");
    want(f,
         "%s:%d: joints[0].pos_max_rad: value 13 outside driver \"ak80-9\" wire range "
         "[-12.5, 12.5]",
         f->path, line_of(f, "pos_max_rad: 13"));
    expect_robot_error(f);
}

static void test_load_robot_pos_min_not_below_max_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "pos_min_rad: -0.6", "pos_min_rad: 0.6");
    want(f, "%s:%d: joints[0].pos_max_rad: value 0.6 not above pos_min_rad 0.6", f->path,
         line_of(f, "pos_max_rad"));
    expect_robot_error(f);
}

static void test_load_robot_kp_above_max_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "kp_nm_rad: 60", "kp_nm_rad: 250");
    want(f, "%s:%d: joints[0].kp_nm_rad: value 250 above kp_max_nm_rad 200", f->path,
         line_of(f, "kp_nm_rad: 250"));
    expect_robot_error(f);

    edit(f, ROBOT_OK, "kd_max_nm_s_rad: 4,", "kd_max_nm_s_rad: 6,");
    want(f, "%s:%d: joints[0].kd_max_nm_s_rad: value 6 above driver \"ak80-9\" kd_max_nm_s_rad 5",
         f->path, line_of(f, "kd_max_nm_s_rad: 6"));
    expect_robot_error(f);
}

static void test_load_robot_torque_outside_driver_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "torque_max_nm: 15", "torque_max_nm: 19");
    want(f, "%s:%d: joints[0].torque_max_nm: +/-19 outside driver \"ak80-9\" wire range [-18, 18]",
         f->path, line_of(f, "torque_max_nm: 19"));
    expect_robot_error(f);
}

static void test_load_robot_duplicate_names_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "name: r_knee", "name: l_knee");
    want(f, "%s:%d: joints[2].name: duplicate joint name \"l_knee\" (also joints[1])", f->path,
         line_of(f, "bus: 1, can_id"));
    expect_robot_error(f);

    edit(f, ROBOT_OK, "{name: ak70-10,", "{name: \"ak80-9\",");
    want(f, "%s:%d: drivers[1].name: duplicate driver name \"ak80-9\" (also drivers[0])", f->path,
         line_of(f, "\"ak80-9\""));
    expect_robot_error(f);
}

/* The optional drive dynamics: all six or none, consistent, and no joint's
 * torque_max above its drive's peak. */
static void test_load_robot_driver_dynamics_checked(void **state)
{
    fx_t *f = *state;
    const char *dyn = "i_min_a: -30, i_max_a: 30, peak_torque_nm: 18, rated_torque_nm: 6, "
                      "rated_speed_rad_s: 30, no_load_speed_rad_s: 40, armature_kg_m2: 0.02, "
                      "pd_hz: 10000}";
    edit(f, ROBOT_OK, "i_min_a: -30, i_max_a: 30}", dyn);
    assert_int_equal(ps_config_load_robot(f->path, &f->robot, f->err, sizeof(f->err)), 0);
    assert_true(f->robot.act[0].motor.peak_torque_nm == 18.0f);
    assert_true(f->robot.act[0].motor.pd_hz == 10000.0f);

    edit(f, ROBOT_OK, "i_min_a: -30, i_max_a: 30}",
         "i_min_a: -30, i_max_a: 30, peak_torque_nm: 18, rated_torque_nm: 20, "
         "rated_speed_rad_s: 30, no_load_speed_rad_s: 40, armature_kg_m2: 0.02, pd_hz: 10000}");
    want(f,
         "%s:%d: drivers[0].rated_torque_nm: 20 is not in (0, peak_torque_nm 18] (give all six "
         "of peak_torque_nm, rated_torque_nm, rated_speed_rad_s, no_load_speed_rad_s, "
         "armature_kg_m2, pd_hz, or none)",
         f->path, line_of(f, "rated_torque_nm: 20"));
    expect_robot_error(f);

    edit(f, ROBOT_OK, "i_min_a: -30, i_max_a: 30}",
         "i_min_a: -30, i_max_a: 30, peak_torque_nm: 18}");
    want(f,
         "%s:%d: drivers[0].rated_torque_nm: 0 is not in (0, peak_torque_nm 18] (give all six "
         "of peak_torque_nm, rated_torque_nm, rated_speed_rad_s, no_load_speed_rad_s, "
         "armature_kg_m2, pd_hz, or none)",
         f->path, line_of(f, "{name: ak80-9"));
    expect_robot_error(f);

    /* a joint on ak80-9 asking for more than a 12 Nm peak */
    edit(f, ROBOT_OK, "i_min_a: -30, i_max_a: 30}",
         "i_min_a: -30, i_max_a: 30, peak_torque_nm: 12, rated_torque_nm: 6, "
         "rated_speed_rad_s: 30, no_load_speed_rad_s: 40, armature_kg_m2: 0.02, pd_hz: 10000}");
    assert_int_equal(ps_config_load_robot(f->path, &f->robot, f->err, sizeof(f->err)),
                     -PS_ERR_CONFIG);
    assert_non_null(strstr(f->err, ".torque_max_nm: value "));
    assert_non_null(strstr(f->err, "above driver \"ak80-9\" peak torque 12 at the joint"));
}

static void test_load_robot_driver_min_not_below_max_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "t_max_nm: 18", "t_max_nm: -19");
    want(f, "%s:%d: drivers[0].t_max_nm: value -19 not above t_min_nm -18", f->path,
         line_of(f, "t_max_nm: -19"));
    expect_robot_error(f);
}

static void test_load_robot_rate_div_not_dividing_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "rate_div: 2}", "rate_div: 3}");
    want(f, "%s:%d: joints[0].rate_div: value 3 does not divide servo_hz/policy_hz = 20", f->path,
         line_of(f, "rate_div: 3"));
    expect_robot_error(f);

    edit(f, ROBOT_OK, "rate_div: 2}", "rate_div: 0}");
    want(f, "%s:%d: joints[0].rate_div: value 0 outside [1, 64]", f->path,
         line_of(f, "rate_div: 0"));
    expect_robot_error(f);
}

static void test_load_robot_unknown_protocol_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "protocol: mit, driver: ak80-9", "protocol: canopen, driver: ak80-9");
    want(f,
         "%s:%d: joints[0].protocol: unknown value \"canopen\" (allowed: mit, robstride, moteus)",
         f->path, line_of(f, "canopen"));
    expect_robot_error(f);
}

static void test_load_robot_mass_zero_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, ROBOT_OK, "mass_kg: 32", "mass_kg: 0");
    want(f, "%s:%d: kinematics.mass_kg: value 0 outside (0, 500]", f->path, line_of(f, "mass_kg"));
    expect_robot_error(f);
}

/* ---- scenario rejections ------------------------------------------------ */

static void test_load_scenario_unknown_key_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, SCENARIO_OK, "duration_s: 0\n", "durration: 0\n");
    want(f, "%s:%d: unknown key \"durration\"", f->path, line_of(f, "durration"));
    expect_scenario_error(f);
}

static void test_load_scenario_unknown_event_kind_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, SCENARIO_OK, "kind: start}", "kind: begin}");
    want(f,
         "%s:%d: events[0].kind: unknown value \"begin\" (allowed: start, stop, estop_press, "
         "estop_release, reset, harness_release, drop_replies, drive_fault, record_button)",
         f->path, line_of(f, "begin"));
    expect_scenario_error(f);
}

static void test_load_scenario_force_not_three_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, SCENARIO_OK, "force_n: [10, -20.5, 0]", "force_n: [10, -20.5]");
    want(f, "%s:%d: pushes[0].force_n: 2 entries, need exactly 3", f->path, line_of(f, "force_n"));
    expect_scenario_error(f);
}

static void test_load_scenario_force_too_large_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, SCENARIO_OK, "force_n: [10, -20.5, 0]", "force_n: [10, -2500, 0]");
    want(f, "%s:%d: pushes[0].force_n[1]: value -2500 outside [-2000, 2000]", f->path,
         line_of(f, "force_n"));
    expect_scenario_error(f);

    /* each component in range, the magnitude not */
    edit(f, SCENARIO_OK, "force_n: [10, -20.5, 0]", "force_n: [1500, -1500, 0]");
    want(f, "%s:%d: pushes[0].force_n: magnitude 2121.32 N outside [0, 2000]", f->path,
         line_of(f, "force_n"));
    expect_scenario_error(f);
}

static void test_load_scenario_drop_without_joint_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, SCENARIO_OK, ", joint: l_knee}", "}");
    want(f, "%s:%d: events[1]: drop_replies needs a \"joint\"", f->path,
         line_of(f, "kind: drop_replies}"));
    expect_scenario_error(f);

    edit(f, SCENARIO_OK, "kind: start}", "kind: start, duration_s: 1}");
    want(f, "%s:%d: events[0].duration_s: only drop_replies takes a duration, not start", f->path,
         line_of(f, "kind: start"));
    expect_scenario_error(f);
    edit(f, SCENARIO_OK, "kind: drop_replies, joint: l_knee", "kind: drive_fault");
    want(f, "%s:%d: events[1]: drive_fault needs a \"joint\"", f->path,
         line_of(f, "kind: drive_fault"));
    expect_scenario_error(f);

    edit(f, SCENARIO_OK, "kind: start}", "kind: start, joint: l_knee}");
    want(f, "%s:%d: events[0].joint: only drop_replies and drive_fault take a joint, not start",
         f->path, line_of(f, "kind: start"));
    expect_scenario_error(f);
}

static void test_load_scenario_duration_high_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, SCENARIO_OK, "duration_s: 0\n", "duration_s: 86401\n");
    want(f, "%s:%d: duration_s: value 86401 outside [0, 86400]", f->path,
         line_of(f, "duration_s: 86401"));
    expect_scenario_error(f);

    edit(f, SCENARIO_OK, "duration_s: 0\n", "duration_s: 2\n");
    want(f, "%s:%d: events[2].t_s: value 3 after the end of the run (duration_s 2)", f->path,
         line_of(f, "t_s: 3"));
    expect_scenario_error(f);
}

/* ---- strict scalars: what libcyaml 1.3.1 alone would accept ------------- */

/* Integers: libcyaml reads "2.5" as 2 and "1e30" or "0x1.8p1" as 1. */
static void test_load_robot_integer_not_integer_rejected(void **state)
{
    fx_t *f = *state;
    static const char *const BAD[] = {"2.5", "1e30", "0x1.8p1", "true", "010", "2x", "0x"};
    for (size_t i = 0; i < sizeof(BAD) / sizeof(BAD[0]); i++) {
        char to[64];
        (void)snprintf(to, sizeof(to), "rate_div: %s}", BAD[i]);
        edit(f, ROBOT_OK, "rate_div: 2}", to);
        want(f, "%s:%d: joints[0].rate_div: value \"%s\" is not an integer in [1, 64]", f->path,
             line_of(f, to), BAD[i]);
        expect_robot_error(f);
    }
    /* hex and signs as documented still load */
    edit(f, ROBOT_OK, "rate_div: 2}", "rate_div: +0x2}");
    assert_int_equal(ps_config_load_robot(f->path, &f->robot, f->err, sizeof(f->err)), 0);
    assert_int_equal(f->robot.act[0].rate_div, 2);
}

static void test_load_scenario_seed_beyond_uint32_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, SCENARIO_OK, "seed: 42", "seed: 1e30");
    want(f, "%s:%d: seed: value \"1e30\" is not an integer in [0, 4294967295]", f->path,
         line_of(f, "seed:"));
    expect_scenario_error(f);
    edit(f, SCENARIO_OK, "seed: 42", "seed: 4294967296");
    want(f, "%s:%d: seed: value 4294967296 outside [0, 4294967295]", f->path, line_of(f, "seed:"));
    expect_scenario_error(f);
    edit(f, SCENARIO_OK, "seed: 42", "seed: -1");
    want(f, "%s:%d: seed: value -1 outside [0, 4294967295]", f->path, line_of(f, "seed:"));
    expect_scenario_error(f);
    edit(f, SCENARIO_OK, "seed: 42", "seed: 4294967295");
    assert_int_equal(ps_config_load_scenario(f->path, &f->scenario, f->err, sizeof(f->err)), 0);
    assert_int_equal(f->scenario.seed, 4294967295u);
}

static void test_load_board_signed_integer_beyond_int32_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, BOARD_OK, "loop_cpu: -1", "loop_cpu: -2147483649");
    want(f, "%s:%d: rt.loop_cpu: value -2147483649 outside [-1, 1023]", f->path,
         line_of(f, "loop_cpu"));
    expect_board_error(f);
    edit(f, BOARD_OK, "loop_cpu: -1", "loop_cpu: -1.5");
    want(f, "%s:%d: rt.loop_cpu: value \"-1.5\" is not an integer in [-1, 1023]", f->path,
         line_of(f, "loop_cpu"));
    expect_board_error(f);
}

/* A field without a range rule gets its type's range. */
static void test_load_board_optional_integer_not_integer_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, BOARD_OK, "{ifname: can0, bitrate: 500000}",
         "{ifname: can0, bitrate: 500000, fd: true, data_bitrate: 2e6}");
    want(f, "%s:%d: buses[0].data_bitrate: value \"2e6\" is not an integer in [10000, 8000000]",
         f->path, line_of(f, "data_bitrate"));
    expect_board_error(f);
}

/* Floats: libcyaml reads "1.0abc" and "1_0" as 1; NaN and inf fail every range. */
static void test_load_robot_float_not_number_rejected(void **state)
{
    fx_t *f = *state;
    static const char *const BAD[] = {"1.0abc", "1_0", ".inf", "0x1p-1"};
    static const char *const SHOWN[] = {"1.0abc", "1_0", ".inf", "0x1p-1"};
    for (size_t i = 0; i < sizeof(BAD) / sizeof(BAD[0]); i++) {
        char to[64];
        (void)snprintf(to, sizeof(to), "ramp_s: %s", BAD[i]);
        edit(f, ROBOT_OK, "ramp_s: 1.0", to);
        want(f, "%s:%d: control.ramp_s: value \"%s\" is not a number in [0.1, 10]", f->path,
             line_of(f, to), SHOWN[i]);
        expect_robot_error(f);
    }
    /* quoted or tagged: a string, not a number */
    static const char *const QUOTED[] = {"' 1.0'", "\"1.0\"", "!!str 1.0"};
    static const char *const QSHOWN[] = {" 1.0", "1.0", "1.0"};
    for (size_t i = 0; i < sizeof(QUOTED) / sizeof(QUOTED[0]); i++) {
        char to[64];
        (void)snprintf(to, sizeof(to), "ramp_s: %s", QUOTED[i]);
        edit(f, ROBOT_OK, "ramp_s: 1.0", to);
        want(f,
             "%s:%d: control.ramp_s: value \"%s\" is quoted or tagged, not a number in [0.1, 10]",
             f->path, line_of(f, to), QSHOWN[i]);
        expect_robot_error(f);
    }
    /* a number a float cannot hold, or would round to zero */
    edit(f, ROBOT_OK, "ramp_s: 1.0", "ramp_s: 1e39");
    want(f, "%s:%d: control.ramp_s: value 1e39 is outside the float range in [0.1, 10]", f->path,
         line_of(f, "ramp_s"));
    expect_robot_error(f);
    edit(f, ROBOT_OK, "hold_s: 10.0", "hold_s: 1e-50");
    want(f, "%s:%d: control.hold_s: value 1e-50 is outside the float range in [0, 60]", f->path,
         line_of(f, "hold_s"));
    expect_robot_error(f);
    edit(f, ROBOT_OK, "ramp_s: 1.0", "ramp_s: nan");
    want(f, "%s:%d: control.ramp_s: value nan outside [0.1, 10]", f->path, line_of(f, "ramp_s"));
    expect_robot_error(f);
    edit(f, SCENARIO_OK, "force_n: [10, -20.5, 0]", "force_n: [10, -20.5, 0x]");
    want(f, "%s:%d: pushes[0].force_n[2]: value \"0x\" is not a number in [-2000, 2000]", f->path,
         line_of(f, "force_n"));
    expect_scenario_error(f);
}

/* Integers: a quoted or tagged number is a string (YAML's rule), refused. */
static void test_load_board_quoted_integer_rejected(void **state)
{
    fx_t *f = *state;
    static const char *const QUOTED[] = {"\"80\"", "'80'", "!!str 80", "!!float 80"};
    for (size_t i = 0; i < sizeof(QUOTED) / sizeof(QUOTED[0]); i++) {
        char to[64];
        (void)snprintf(to, sizeof(to), "priority: %s", QUOTED[i]);
        edit(f, BOARD_OK, "priority: 0", to);
        want(f, "%s:%d: rt.priority: value \"80\" is quoted or tagged, not an integer in [0, 98]",
             f->path, line_of(f, "priority"));
        expect_board_error(f);
    }
}

/* YAML aliases would carry a value past these checks (a word for a
 * boolean, a fraction for an integer): refused where they are written. */
static void test_load_board_alias_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, BOARD_OK, "name: bench", "name: &k bench");
    edit_again(f, "loop_cpu: -1", "loop_cpu: *k");
    want(f, "%s:%d: YAML syntax error: YAML aliases (*name) are not supported; write the value",
         f->path, line_of(f, "*k"));
    expect_board_error(f);
}

/* One document per file: a second one is refused, not ignored. */
static void test_load_board_second_document_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, BOARD_OK, "name: bench", "name: bench");
    append(f, "---\ngarbage: [unclosed\n");
    want(f, "%s:%d: YAML syntax error: one YAML document per file (a second one starts here)",
         f->path, line_of(f, "---"));
    expect_board_error(f);
}

/* A FIFO (or any file that is not a regular one) is refused at once, never
 * waited on; /dev/null likewise. */
static void test_load_board_not_regular_file_rejected(void **state)
{
    fx_t *f = *state;
    char fifo[PS_PATH_LEN];
    (void)snprintf(fifo, sizeof(fifo), "%s/fifo.yaml", f->dir);
    assert_int_equal(mkfifo(fifo, 0600), 0);
    alarm(5); /* a blocking open would end the test binary, a failure */
    assert_int_equal(ps_config_load_board(fifo, &f->board, f->err, sizeof(f->err)), -PS_ERR_CONFIG);
    alarm(0);
    char want_msg[PS_ERR_MSG_LEN];
    (void)snprintf(want_msg, sizeof(want_msg), "%s: not a regular file", fifo);
    assert_string_equal(f->err, want_msg);
    (void)unlink(fifo);
    assert_int_equal(ps_config_load_board("/dev/null", &f->board, f->err, sizeof(f->err)),
                     -PS_ERR_CONFIG);
    assert_string_equal(f->err, "/dev/null: not a regular file");
}

/* Booleans: only plain true/false; a quoted "true" is a string. */
static void test_load_board_bool_quoted_or_word_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, BOARD_OK, "estop_active_low: false", "estop_active_low: \"false\"");
    want(f,
         "%s:%d: gpio.estop_active_low: value \"false\" is quoted or tagged (allowed: true, "
         "false)",
         f->path, line_of(f, "estop_active_low"));
    expect_board_error(f);
    edit(f, BOARD_OK, "estop_active_low: false", "estop_active_low: 0");
    want(f, "%s:%d: gpio.estop_active_low: unknown value \"0\" (allowed: true, false)", f->path,
         line_of(f, "estop_active_low"));
    expect_board_error(f);
}

/* Enums: only their words, case-sensitive; no numbers. */
static void test_load_board_enum_number_or_case_rejected(void **state)
{
    fx_t *f = *state;
    static const char *const BAD[] = {"1", "Linux", "linux2"};
    for (size_t i = 0; i < sizeof(BAD) / sizeof(BAD[0]); i++) {
        char to[64];
        (void)snprintf(to, sizeof(to), "kind: %s", BAD[i]);
        edit(f, BOARD_OK, "kind: linux", to);
        want(f, "%s:%d: kind: unknown value \"%s\" (allowed: sim, linux)", f->path, line_of(f, to),
             BAD[i]);
        expect_board_error(f);
    }
}

/* Strings: a YAML null is not a name; lengths are checked. */
static void test_load_board_string_null_or_long_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, BOARD_OK, "name: bench", "name: ~");
    want(f, "%s:%d: name: value ~ is null, not a string", f->path, line_of(f, "name: ~"));
    expect_board_error(f);
    edit(f, BOARD_OK, "name: bench", "name: null");
    want(f, "%s:%d: name: value null is null, not a string", f->path, line_of(f, "name: null"));
    expect_board_error(f);
    edit(f, BOARD_OK, "name: bench", "name: \"null\""); /* quoted: a string */
    assert_int_equal(ps_config_load_board(f->path, &f->board, f->err, sizeof(f->err)), 0);
    assert_string_equal(f->board.name, "null");
    edit(f, BOARD_OK, "name: bench", "name: abcdefghijklmnopqrstuvwxyz012345");
    want(f, "%s:%d: name: string \"abcdefghijklmnopqrstuvwxyz012345\" length 32 outside [1, 31]",
         f->path, line_of(f, "name:"));
    expect_board_error(f);
}

/* Lists: entry counts are checked, fixed-length lists exactly. */
static void test_load_scenario_list_length_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, SCENARIO_OK, "force_n: [10, -20.5, 0]", "force_n: [10, -20.5, 0, 1]");
    want(f, "%s:%d: pushes[0].force_n: 4 entries, need exactly 3", f->path, line_of(f, "force_n"));
    expect_scenario_error(f);
    edit(f, BOARD_OK, "buses:\n", "buses: []\nx_buses:\n");
    want(f, "%s:%d: buses: 0 entries outside [1, 8]", f->path, line_of(f, "buses: []"));
    expect_board_error(f);
}

/* ---- a directory where a file belongs ------------------------------------ */

static void test_load_directory_says_so(void **state)
{
    fx_t *f = *state;
    assert_int_equal(ps_config_load_board("boards/", &f->board, f->err, sizeof(f->err)),
                     -PS_ERR_CONFIG);
    assert_string_equal(f->err, "boards/: is a directory");
    assert_int_equal(ps_config_load_robot("robots", &f->robot, f->err, sizeof(f->err)),
                     -PS_ERR_CONFIG);
    assert_string_equal(f->err, "robots: is a directory");
    assert_int_equal(
        ps_config_load_robot_sim("robots/", &f->robot, &f->robot_sim, f->err, sizeof(f->err)),
        -PS_ERR_CONFIG);
    assert_string_equal(f->err, "robots/: is a directory");
    assert_int_equal(ps_config_load_scenario(f->dir, &f->scenario, f->err, sizeof(f->err)),
                     -PS_ERR_CONFIG);
    want(f, "%s: is a directory", f->dir);
    assert_string_equal(f->err, f->want);
}

/* ---- cross-file checks and look-ups ------------------------------------ */

static void load_pair(fx_t *f)
{
    assert_int_equal(ps_config_load_board(BOARD_OK, &f->board, f->err, sizeof(f->err)), 0);
    assert_int_equal(ps_config_load_robot(ROBOT_OK, &f->robot, f->err, sizeof(f->err)), 0);
    assert_int_equal(ps_config_load_scenario(SCENARIO_OK, &f->scenario, f->err, sizeof(f->err)), 0);
}

static void test_check_pair_consistent_ok(void **state)
{
    fx_t *f = *state;
    load_pair(f);
    assert_int_equal(ps_config_check_pair(&f->board, &f->robot, f->err, sizeof(f->err)), 0);
    assert_int_equal(ps_config_check_scenario(&f->robot, &f->scenario, f->err, sizeof(f->err)), 0);
}

/* Two files: the message names the robot file and the line of joints[2].bus. */
static void test_check_pair_joint_bus_missing_rejected(void **state)
{
    fx_t *f = *state;
    /* the bus on a line of its own: the message points at it, not at the entry */
    edit(f, ROBOT_OK, "{name: r_knee, bus: 1,", "{name: r_knee,\n     bus: 2,");
    assert_int_equal(ps_config_load_board(BOARD_OK, &f->board, f->err, sizeof(f->err)), 0);
    assert_int_equal(ps_config_load_robot(f->path, &f->robot, f->err, sizeof(f->err)), 0);
    assert_int_equal(ps_config_check_pair(&f->board, &f->robot, f->err, sizeof(f->err)),
                     -PS_ERR_CONFIG);
    want(f, "%s:%d: joints[2].bus: bus 2 not on board bench (buses 0..1)", f->path,
         line_of(f, "bus: 2"));
    assert_string_equal(f->err, f->want);
}

static void test_check_pair_imu_bus_missing_rejected(void **state)
{
    fx_t *f = *state;
    assert_int_equal(ps_config_load_board(BOARD_OK, &f->board, f->err, sizeof(f->err)), 0);
    assert_int_equal(ps_config_load_robot(ROBOT_OK, &f->robot, f->err, sizeof(f->err)), 0);
    f->board.n_buses = 1;
    f->robot.act[2].bus_idx = 0;
    assert_int_equal(ps_config_check_pair(&f->board, &f->robot, f->err, sizeof(f->err)),
                     -PS_ERR_CONFIG);
    want(f, "%s:7: imu.bus: bus 1 not on board bench (buses 0..0)", ROBOT_OK);
    assert_string_equal(f->err, f->want);
}

/* A robot built in code has no file: the robot's name stands in. */
static void test_check_pair_no_source_names_robot(void **state)
{
    fx_t *f = *state;
    load_pair(f);
    memset(&f->robot.src, 0, sizeof(f->robot.src));
    f->robot.act[2].bus_idx = 2;
    assert_int_equal(ps_config_check_pair(&f->board, &f->robot, f->err, sizeof(f->err)),
                     -PS_ERR_CONFIG);
    assert_string_equal(f->err, "robot tiny: joints[2].bus: bus 2 not on board bench (buses 0..1)");
}

/* Two files: the message names the scenario file and the line of events[2].joint. */
static void test_check_scenario_drop_joint_unknown_rejected(void **state)
{
    fx_t *f = *state;
    edit(f, SCENARIO_OK, "joint: r_knee", "joint: r_ankle");
    assert_int_equal(ps_config_load_robot(ROBOT_OK, &f->robot, f->err, sizeof(f->err)), 0);
    assert_int_equal(ps_config_load_scenario(f->path, &f->scenario, f->err, sizeof(f->err)), 0);
    assert_int_equal(ps_config_check_scenario(&f->robot, &f->scenario, f->err, sizeof(f->err)),
                     -PS_ERR_CONFIG);
    want(f, "%s:%d: events[2].joint: no joint \"r_ankle\" in robot tiny", f->path,
         line_of(f, "joint: r_ankle"));
    assert_string_equal(f->err, f->want);

    f->scenario.path[0] = '\0'; /* built in code: the scenario's name stands in */
    assert_int_equal(ps_config_check_scenario(&f->robot, &f->scenario, f->err, sizeof(f->err)),
                     -PS_ERR_CONFIG);
    assert_string_equal(f->err,
                        "scenario mixed: events[2].joint: no joint \"r_ankle\" in robot tiny");
}

static void test_load_scenario_fixture_lines_recorded(void **state)
{
    fx_t *f = *state;
    ps_scenario_cfg_t *s = &f->scenario;
    assert_int_equal(ps_config_load_scenario(SCENARIO_OK, s, f->err, sizeof(f->err)), 0);
    assert_string_equal(s->path, SCENARIO_OK);
    assert_int_equal(s->events[0].joint_line, 0); /* start: no joint */
    assert_int_equal(s->events[1].joint_line, 7);
    assert_int_equal(s->events[2].joint_line, 8);
    assert_int_equal(s->pushes[0].body_line, 10);
}

static void test_find_joint_name_index_or_enoent(void **state)
{
    fx_t *f = *state;
    assert_int_equal(ps_config_load_robot(ROBOT_OK, &f->robot, f->err, sizeof(f->err)), 0);
    assert_int_equal(ps_config_find_joint(&f->robot, "l_hip_yaw"), 0);
    assert_int_equal(ps_config_find_joint(&f->robot, "r_knee"), 2);
    assert_int_equal(ps_config_find_joint(&f->robot, "r_kne"), -ENOENT);
    assert_int_equal(ps_config_find_joint(&f->robot, NULL), -ENOENT);
}

static void test_event_name_every_kind_named(void **state)
{
    (void)state;
    static const char *const NAMES[PS_EVENT_COUNT] = {
        "start",           "stop",         "estop_press", "estop_release", "reset",
        "harness_release", "drop_replies", "drive_fault", "record_button"};
    for (int k = 0; k < (int)PS_EVENT_COUNT; k++)
        assert_string_equal(ps_config_event_name((ps_event_kind_t)k), NAMES[k]);
    assert_string_equal(ps_config_event_name(PS_EVENT_COUNT), "unknown");
}

#define T(fn) cmocka_unit_test_setup_teardown(fn, setup, teardown)

int main(void)
{
    const struct CMUnitTest tests[] = {
        T(test_load_board_shipped_boards_ok),
        T(test_load_board_sim_exact_values),
        T(test_load_board_optional_absent_default_applied),
        T(test_load_scenario_shipped_scenarios_ok),
        T(test_load_scenario_fixture_defaults_applied),
        T(test_load_robot_fixture_exact_values),
        T(test_load_robot_ps1_when_present_ok),
        T(test_load_missing_file_enoent),
        T(test_load_null_args_einval),
        T(test_load_board_failure_out_untouched),
        T(test_load_board_small_or_null_err_truncated),
        T(test_load_board_top_field_missing_rejected),
        T(test_load_board_nested_field_missing_rejected),
        T(test_load_board_string_for_number_rejected),
        T(test_load_board_bitrate_high_rejected),
        T(test_load_board_bitrate_low_rejected),
        T(test_load_board_budget_zero_rejected),
        T(test_load_board_cpu_below_minus_one_rejected),
        T(test_load_board_unknown_nested_key_rejected),
        T(test_load_board_unknown_kind_rejected),
        T(test_load_board_bool_typo_rejected),
        T(test_load_board_too_many_buses_rejected),
        T(test_load_board_long_ifname_rejected),
        T(test_load_board_duplicate_ifname_rejected),
        T(test_load_board_duplicate_key_rejected),
        T(test_load_board_syntax_error_rejected),
        T(test_load_board_gpio_line_reused_rejected),
        T(test_load_board_gpio_names_loaded),
        T(test_load_board_gpio_debounce_out_of_range_rejected),
        T(test_load_board_gpio_record_button),
        T(test_load_board_gpio_name_too_long_rejected),
        T(test_load_board_gpio_line_and_name_rejected),
        T(test_load_board_gpio_name_reused_rejected),
        T(test_load_board_gpio_bias_unknown_rejected),
        T(test_load_board_controller_and_camera_loaded),
        T(test_load_board_fd_on_classical_controller_rejected),
        T(test_load_board_unknown_controller_rejected),
        T(test_load_robot_string_for_number_rejected),
        T(test_load_robot_missing_field_rejected),
        T(test_load_robot_duplicate_can_id_rejected),
        T(test_load_robot_reply_id_on_imu_rejected),
        T(test_load_robot_thermal_settings_taken),
        T(test_load_robot_thermal_settings_rejected),
        T(test_load_robot_imu_frozen_samples_checked),
        T(test_load_robot_can_id_high_rejected),
        T(test_load_robot_robstride_ids_checked),
        T(test_load_robot_robstride_shared_host_id_ok),
        T(test_load_robot_moteus_low_id_rejected),
        T(test_check_pair_moteus_needs_fd_bus),
        T(test_load_robot_policy_deadline_beyond_half_period_rejected),
        T(test_load_robot_reply_timeout_beyond_periods_rejected),
        T(test_load_robot_imu_timeout_beyond_periods_rejected),
        T(test_load_robot_overrun_limit_zero_rejected),
        T(test_load_robot_can_id_beyond_29_bits_rejected),
        T(test_load_robot_gear_direction_zero_applied),
        T(test_load_robot_direction_not_unit_rejected),
        T(test_load_robot_gear_ratio_zero_rejected),
        T(test_load_robot_unknown_driver_rejected),
        T(test_load_robot_zero_ramp_rejected),
        T(test_load_robot_servo_not_multiple_rejected),
        T(test_load_robot_pos_outside_wire_rejected),
        T(test_load_robot_pos_min_not_below_max_rejected),
        T(test_load_robot_kp_above_max_rejected),
        T(test_load_robot_torque_outside_driver_rejected),
        T(test_load_robot_duplicate_names_rejected),
        T(test_load_robot_driver_min_not_below_max_rejected),
        T(test_load_robot_driver_dynamics_checked),
        T(test_load_robot_rate_div_not_dividing_rejected),
        T(test_load_robot_unknown_protocol_rejected),
        T(test_load_robot_mass_zero_rejected),
        T(test_load_scenario_crowd_fixture_values_and_defaults),
        T(test_load_scenario_crowd_rejections),
        T(test_load_scenario_unknown_key_rejected),
        T(test_load_scenario_unknown_event_kind_rejected),
        T(test_load_scenario_force_not_three_rejected),
        T(test_load_scenario_force_too_large_rejected),
        T(test_load_scenario_drop_without_joint_rejected),
        T(test_load_scenario_duration_high_rejected),
        T(test_load_robot_integer_not_integer_rejected),
        T(test_load_scenario_seed_beyond_uint32_rejected),
        T(test_load_board_signed_integer_beyond_int32_rejected),
        T(test_load_board_optional_integer_not_integer_rejected),
        T(test_load_robot_float_not_number_rejected),
        T(test_load_board_bool_quoted_or_word_rejected),
        T(test_load_board_quoted_integer_rejected),
        T(test_load_board_alias_rejected),
        T(test_load_board_second_document_rejected),
        T(test_load_board_not_regular_file_rejected),
        T(test_load_board_enum_number_or_case_rejected),
        T(test_load_board_string_null_or_long_rejected),
        T(test_load_scenario_list_length_rejected),
        T(test_load_directory_says_so),
        T(test_check_pair_consistent_ok),
        T(test_check_pair_joint_bus_missing_rejected),
        T(test_check_pair_imu_bus_missing_rejected),
        T(test_check_pair_no_source_names_robot),
        T(test_check_scenario_drop_joint_unknown_rejected),
        T(test_load_scenario_fixture_lines_recorded),
        T(test_load_robot_sim_fixture_same_robot_and_section),
        T(test_find_joint_name_index_or_enoent),
        T(test_event_name_every_kind_named),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
