/*
 * Tests of the simulated crowd: the social-force terms against hand-computed
 * values and the cell grid (sim/ps_social.c), placement and the generated
 * scene (sim/ps_scene.c), and the crowd in the MuJoCo plant (sim/ps_crowd.c
 * through sim/ps_plant.c): free speed, body compression, a pushed queue,
 * densities, speed against density, stepping and falling, moving walls,
 * determinism; the AprilTag plates on the people's shoulders (ids, sides,
 * the family's limit) and that they leave the physics as it was. The robot (robots/ps1.yaml) hangs
 * limp in its harness. Run from the repo root.
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

#include <apriltag/tag36h11.h>
#include <mujoco/mujoco.h>
#include <time.h>

#include "../rt/ps_config.h"
#include "../rt/ps_err.h"
#include "../sim/ps_plant.h"
#include "../sim/ps_scene.h"
#include "../sim/ps_social.h"

#define ROBOT_PATH "robots/ps1.yaml"
#define MODEL_PATH "sim/models/ps1.xml"

static ps_robot_cfg_t robot;
static float stance[PS_MAX_JOINTS];

static int setup_robot(void **state)
{
    (void)state;
    char err[PS_ERR_MSG_LEN];
    if (ps_config_load_robot(ROBOT_PATH, &robot, err, sizeof(err)) != 0) {
        fprintf(stderr, "setup: %s\n", err);
        return -1;
    }
    for (uint32_t j = 0; j < robot.n_joints; j++)
        stance[j] = robot.servo[j].stance_rad;
    return 0;
}

static ps_plant_t *make_plant_in(const char *model, const ps_crowd_cfg_t *crowd, double rx,
                                 double ry, uint32_t seed)
{
    const ps_plant_cfg_t pc = {
        .model_path = model,
        .n_joints = robot.n_joints,
        .joint_name = robot.joint_name,
        .stance_rad = stance,
        .spawn_xy_m = {rx, ry},
        .crowd = crowd,
        .seed = seed,
    };
    ps_plant_t *p = NULL;
    char err[PS_ERR_MSG_LEN] = "";
    const int rc = ps_plant_create(&pc, &p, err, sizeof(err));
    if (rc != 0)
        fail_msg("ps_plant_create: %s (%s)", err, ps_strerror(rc));
    return p;
}

static ps_plant_t *make_plant(const ps_crowd_cfg_t *crowd, double rx, double ry, uint32_t seed)
{
    return make_plant_in(MODEL_PATH, crowd, rx, ry, seed);
}

static void run_s(ps_plant_t *p, double t_s)
{
    const int n = (int)lround(t_s / ps_plant_timestep_s(p));
    for (int i = 0; i < n; i++) {
        const int rc = ps_plant_step(p);
        if (rc != 0) {
            fail_msg("plant step: %s", ps_plant_error_reason(p));
        }
    }
}

static ps_crowd_agent_state_t agent(ps_plant_t *p, uint32_t i)
{
    ps_crowd_agent_state_t a;
    assert_int_equal(ps_crowd_get_agent(ps_plant_crowd(p), i, &a), 0);
    return a;
}

/* A crowd cfg with an open arena around the origin and one group; crowd-only
 * tests step at 1 ms (timestep_s) to stay short: the crowd model is what they
 * check, the robot hangs in its harness far away or nearby. */
static ps_crowd_cfg_t base_cfg(void)
{
    ps_crowd_cfg_t c;
    ps_crowd_default_cfg(&c);
    c.is_enabled = true;
    c.timestep_s = 0.001f;
    c.arena = (ps_crowd_rect_t){-20, -20, 20, 20};
    c.measure = c.arena;
    c.n_groups = 1;
    ps_crowd_group_cfg_t *g = &c.groups[0];
    *g = (ps_crowd_group_cfg_t){.name = "g", .height_m = 1.7f, .mass_kg = 70.0f, .radius_m = 0.17f};
    return c;
}

static void line_group(ps_crowd_cfg_t *c, uint32_t n, float spacing_m, float x0, float y0,
                       float x1, float y1)
{
    ps_crowd_group_cfg_t *g = &c->groups[0];
    g->count = n;
    g->layout = PS_CROWD_LAYOUT_LINE;
    g->spacing_m = spacing_m;
    g->region = (ps_crowd_rect_t){x0, y0, x1, y1};
}

/* ---- social-force terms against hand-computed values --------------------- */

static void test_social_drive_hand_computed(void **state)
{
    (void)state;
    const double e[2] = {1.0, 0.0}, v[2] = {0.5, 0.2};
    double f[2];
    ps_social_drive(70.0, 1.29, 0.54, e, v, f);
    /* 70 (1.29 - 0.5) / 0.54 = 102.4074, 70 (0 - 0.2) / 0.54 = -25.9259 */
    assert_true(fabs(f[0] - 102.4074) < 1e-3);
    assert_true(fabs(f[1] + 25.9259) < 1e-3);
}

static void test_social_agent_repulsion_hand_computed(void **state)
{
    (void)state;
    ps_social_params_t p;
    ps_social_default_params(&p); /* A 2000 N, B 0.08 m, lambda 0.5, range 1 m */
    const double xi[2] = {0.0, 0.0}, xj[2] = {0.5, 0.0}, none[2] = {0.0, 0.0};
    double f[2];
    /* no heading: 2000 exp((0.34 - 0.5) / 0.08) = 2000 e^-2 = 270.6706 N along -x */
    ps_social_agent_repulsion(&p, xi, 0.17, none, xj, 0.17, f);
    assert_true(fabs(f[0] + 270.6706) < 1e-3 && fabs(f[1]) < 1e-12);
    /* j straight ahead: w = 1; straight behind: w = lambda = 0.5 */
    const double ahead[2] = {1.0, 0.0}, away[2] = {-1.0, 0.0};
    ps_social_agent_repulsion(&p, xi, 0.17, ahead, xj, 0.17, f);
    assert_true(fabs(f[0] + 270.6706) < 1e-3);
    ps_social_agent_repulsion(&p, xi, 0.17, away, xj, 0.17, f);
    assert_true(fabs(f[0] + 135.3353) < 1e-3);
    /* j to the side: cos phi = 0, w = 0.5 + 0.5 * 0.5 = 0.75 */
    const double side[2] = {0.0, 1.0};
    ps_social_agent_repulsion(&p, xi, 0.17, side, xj, 0.17, f);
    assert_true(fabs(f[0] + 203.0029) < 1e-3);
    /* beyond range_m: nothing */
    const double far[2] = {1.2, 0.0};
    ps_social_agent_repulsion(&p, xi, 0.17, none, far, 0.17, f);
    assert_true(f[0] == 0.0 && f[1] == 0.0);
}

/* Both sides of a pair at once are the two one-sided terms, bit for bit,
 * in range, out of range, and with no heading. */
static void test_social_pair_repulsion_equals_both_sides(void **state)
{
    (void)state;
    ps_social_params_t p;
    ps_social_default_params(&p);
    const double xi[2] = {0.1, -0.2}, ei[2] = {0.6, 0.8}, ej[2] = {0.0, 0.0};
    const double xjs[3][2] = {{0.5, 0.1}, {0.05, -0.6}, {2.0, 0.0}}; /* last beyond range */
    for (int k = 0; k < 3; k++) {
        double fi[2], fj[2], gi[2], gj[2];
        ps_social_pair_repulsion(&p, xi, 0.17, ei, xjs[k], 0.19, ej, fi, fj);
        ps_social_agent_repulsion(&p, xi, 0.17, ei, xjs[k], 0.19, gi);
        ps_social_agent_repulsion(&p, xjs[k], 0.19, ej, xi, 0.17, gj);
        assert_memory_equal(fi, gi, sizeof(fi));
        assert_memory_equal(fj, gj, sizeof(fj));
        assert_true(k == 2 ? fi[0] == 0.0 : fi[0] != 0.0);
    }
}

static void test_social_wall_repulsion_hand_computed(void **state)
{
    (void)state;
    ps_social_params_t p;
    ps_social_default_params(&p);
    const double a[2] = {-1.0, 0.0}, b[2] = {1.0, 0.0};
    const double x[2] = {0.3, 0.5};
    double f[2];
    /* 2000 exp((0.17 - 0.5) / 0.08) = 2000 e^-4.125 = 32.3270 N along +y */
    ps_social_wall_repulsion(&p, x, 0.17, a, b, f);
    assert_true(fabs(f[0]) < 1e-12 && fabs(f[1] - 32.3270) < 1e-3);
    /* past the segment's end: from the end point (1, 0), distance 0.5 at 45 deg */
    const double y[2] = {1.0 + 0.5 / sqrt(2.0), 0.5 / sqrt(2.0)};
    ps_social_wall_repulsion(&p, y, 0.17, a, b, f);
    assert_true(fabs(f[0] - 32.3270 / sqrt(2.0)) < 1e-3 && fabs(f[1] - 32.3270 / sqrt(2.0)) < 1e-3);
}

static void test_social_evasive_steps_aside_away_from_neighbours(void **state)
{
    (void)state;
    ps_social_params_t p;
    ps_social_default_params(&p); /* evasive 80 N */
    const double e[2] = {1.0, 0.0}, o_left[2] = {1.0, 0.3}, o_right[2] = {1.0, -0.3};
    double f[2];
    ps_social_evasive(&p, true, e, o_left, f); /* neighbours on the left: go right */
    assert_true(fabs(f[0]) < 1e-12 && fabs(f[1] + 80.0) < 1e-9);
    ps_social_evasive(&p, true, e, o_right, f);
    assert_true(fabs(f[1] - 80.0) < 1e-9);
    ps_social_evasive(&p, false, e, o_left, f); /* nothing in the way */
    assert_true(f[0] == 0.0 && f[1] == 0.0);
    const double xi[2] = {0, 0}, ahead[2] = {1.0, 0.3}, aside[2] = {1.0, 0.5};
    assert_true(ps_social_is_ahead(xi, e, ahead, 1.5)); /* 16.7 deg */
    assert_false(ps_social_is_ahead(xi, e, aside, 1.5)); /* 26.6 deg: outside the 45 deg sector */
}

static void test_social_grid_finds_every_neighbour_in_range(void **state)
{
    (void)state;
    enum { N = 300 };
    static double xy[2 * N];
    uint32_t seed = 7;
    for (int i = 0; i < 2 * N; i++) {
        seed = seed * 1664525u + 1013904223u;
        xy[i] = -5.0 + 10.0 * (double)(seed >> 8) / (double)(1u << 24);
    }
    xy[0] = 40.0; /* outside the grid: clamped into a border cell, still found */
    const uint32_t n_cells = ps_social_grid_cells(12.0, 12.0, 1.0);
    assert_int_equal(n_cells, 144);
    static uint32_t start[145], items[N], cell_of[N];
    ps_social_grid_t g;
    ps_social_grid_init(&g, -6.0, -6.0, 12.0, 12.0, 1.0, start, items, cell_of, N);
    ps_social_grid_build(&g, xy, N);
    for (int i = 1; i < N; i++) {
        int cx, cy, n_grid = 0, n_all = 0;
        ps_social_grid_cell(&g, xy + 2 * i, &cx, &cy);
        for (int gy = cy - 1; gy <= cy + 1; gy++)
            for (int gx = cx - 1; gx <= cx + 1; gx++) {
                if (gx < 0 || gy < 0 || gx >= g.nx || gy >= g.ny)
                    continue;
                const uint32_t c = (uint32_t)(gy * g.nx + gx);
                for (uint32_t k = start[c]; k < start[c + 1]; k++) {
                    const uint32_t j = items[k];
                    const double d = hypot(xy[2 * i] - xy[2 * j], xy[2 * i + 1] - xy[2 * j + 1]);
                    n_grid += (j != (uint32_t)i && d <= 1.0) ? 1 : 0;
                }
            }
        for (int j = 0; j < N; j++)
            n_all += (j != i && hypot(xy[2 * i] - xy[2 * j], xy[2 * i + 1] - xy[2 * j + 1]) <= 1.0);
        assert_int_equal(n_grid, n_all);
    }
}

/* ---- placement and scene --------------------------------------------------- */

static void test_scene_place_seeded_lattice_density_and_clearance(void **state)
{
    (void)state;
    ps_crowd_cfg_t c = base_cfg();
    ps_crowd_group_cfg_t *g = &c.groups[0];
    g->density_m2 = 4.0f;
    g->region = (ps_crowd_rect_t){-3, -3, 3, 3};
    g->clear_m = 0.5f;
    g->height_sd_m = 0.07f;
    static ps_crowd_agent_spec_t a[PS_CROWD_MAX_AGENTS], b[PS_CROWD_MAX_AGENTS];
    uint32_t na = 0, nb = 0;
    char err[PS_ERR_MSG_LEN];
    const double robot_xy[2] = {0.0, 0.0};
    assert_int_equal(ps_scene_place(&c, 9, robot_xy, a, PS_CROWD_MAX_AGENTS, &na, err, sizeof(err)), 0);
    assert_int_equal(ps_scene_place(&c, 9, robot_xy, b, PS_CROWD_MAX_AGENTS, &nb, err, sizeof(err)), 0);
    assert_int_equal(na, nb);
    assert_memory_equal(a, b, na * sizeof(a[0])); /* same seed, same crowd */
    /* 36 m^2 at 4 / m^2, less the clearance disc around the robot */
    assert_true(na >= 130 && na <= 150);
    for (uint32_t i = 0; i < na; i++) {
        assert_true(hypot(a[i].x_m, a[i].y_m) >= 0.5);
        assert_true(a[i].height_m >= 1.7f - 2.5 * 0.07f - 1e-6 &&
                    a[i].height_m <= 1.7f + 2.5 * 0.07f + 1e-6);
    }
    assert_int_equal(ps_scene_place(&c, 10, robot_xy, b, PS_CROWD_MAX_AGENTS, &nb, err, sizeof(err)), 0);
    assert_true(memcmp(a, b, na * sizeof(a[0])) != 0); /* another seed, another crowd */
    /* a region that cannot hold its count */
    g->density_m2 = 0.0f;
    g->count = 10;
    g->layout = PS_CROWD_LAYOUT_RANDOM;
    g->region = (ps_crowd_rect_t){-0.5f, -0.5f, 0.5f, 0.5f};
    g->clear_m = 0.0f;
    assert_int_equal(ps_scene_place(&c, 9, robot_xy, a, PS_CROWD_MAX_AGENTS, &na, err, sizeof(err)),
                     -PS_ERR_CONFIG);
    assert_non_null(strstr(err, "crowd.groups[0] (g): its region holds only"));
}

static void test_scene_loads_around_unchanged_robot_with_sizes(void **state)
{
    (void)state;
    ps_crowd_cfg_t c = base_cfg();
    c.timestep_s = 0.0f; /* the robot model's own */
    line_group(&c, 7, 0.5f, 2, 2, 5, 2);
    c.has_arena_walls = true;
    c.arena = (ps_crowd_rect_t){-6, -6, 6, 6};
    ps_plant_t *p = make_plant(&c, 0, 0, 1);
    const mjModel *m = ps_plant_model(p);
    assert_int_equal(mj_name2id(m, mjOBJ_BODY, "pelvis"), ps_plant_root_body(p));
    assert_true(mj_name2id(m, mjOBJ_BODY, "agent6_ring") > 0);
    assert_true(mj_name2id(m, mjOBJ_BODY, "agent7") < 0);
    assert_true(mj_name2id(m, mjOBJ_GEOM, "arena_wall3") >= 0);
    assert_true(m->opt.timestep == 0.0005); /* ps1.xml's */
    /* the scene's solver settings (sim/ps_scene.c), the model's integrator */
    assert_int_equal(m->opt.solver, mjSOL_NEWTON);
    assert_int_equal(m->opt.cone, mjCONE_PYRAMIDAL);
    assert_int_equal(m->opt.jacobian, mjJAC_SPARSE);
    assert_int_equal(m->opt.integrator, mjINT_EULER);
    int nconmax, njmax;
    ps_scene_sizes(7, 150, 600, &nconmax, &njmax);
    assert_int_equal(m->nconmax, nconmax);
    assert_int_equal(m->njmax, njmax);
    assert_int_equal(ps_crowd_agent_count(ps_plant_crowd(p)), 7);
    ps_plant_destroy(p);
}

/* ---- the crowd in the plant ---------------------------------------------- */

/* An unobstructed agent reaches its configured free speed within 10 %. */
static void test_crowd_free_speed_within_10_percent(void **state)
{
    (void)state;
    const float speeds[] = {1.29f, 0.8f};
    for (int k = 0; k < 2; k++) {
        ps_crowd_cfg_t c = base_cfg();
        line_group(&c, 1, 1.0f, -8, 8, -7, 8);
        c.groups[0].goal = PS_CROWD_GOAL_DIRECTION;
        c.groups[0].goal_xy[0] = 1.0f;
        c.groups[0].speed_m_s = speeds[k];
        ps_plant_t *p = make_plant(&c, 0, 0, 1);
        run_s(p, 3.0);
        const ps_crowd_agent_state_t a = agent(p, 0);
        printf("free speed: configured %.2f m/s, measured %.3f m/s\n", (double)speeds[k],
               hypot(a.vel_m_s[0], a.vel_m_s[1]));
        assert_true(fabs(hypot(a.vel_m_s[0], a.vel_m_s[1]) - speeds[k]) <= 0.1 * speeds[k]);
        assert_false(a.is_fallen);
        ps_plant_destroy(p);
    }
}

/* Whether someone ahead blocks an agent (RESCUE's evasive term) may not
 * depend on where the neighbour grid's cells happen to fall: a person
 * walking at a standing one 1.3 m ahead (inside evasive_range_m, 1.5 m,
 * beyond the 1 m repulsion range) with a walker at their side steps aside
 * the same wherever the scene stands. Before the grid's cells covered the
 * evasion's reach, the pair was missed when they fell two cells apart. */
static void test_crowd_blocking_ahead_independent_of_grid(void **state)
{
    (void)state;
    double lateral0 = 0.0;
    const double offsets_m[] = {0.0, 0.3, 0.6, 0.9};
    for (int k = 0; k < 4; k++) {
        const float x0 = (float)(-5.0 + offsets_m[k]);
        ps_crowd_cfg_t c = base_cfg();
        c.n_groups = 2;
        line_group(&c, 2, 0.6f, x0, 0.0f, x0, 1.0f); /* A at (x0, 0), its neighbour 0.6 m left */
        c.groups[0].goal = PS_CROWD_GOAL_DIRECTION;
        c.groups[0].goal_xy[0] = 1.0f;
        c.groups[0].speed_m_s = 1.29f;
        c.groups[1] = c.groups[0];
        (void)snprintf(c.groups[1].name, sizeof(c.groups[1].name), "ahead");
        c.groups[1].count = 1;
        c.groups[1].goal = PS_CROWD_GOAL_HOLD;
        c.groups[1].region = (ps_crowd_rect_t){x0 + 1.3f, 0.0f, x0 + 2.3f, 0.0f};
        ps_plant_t *p = make_plant(&c, 0, -10, 1);
        run_s(p, 0.2);
        const double lateral = agent(p, 0).com_m[1];
        printf("blocked walker at x0 %+.2f m: lateral %.6f m after 0.2 s\n", (double)x0, lateral);
        if (k == 0)
            lateral0 = lateral;
        else
            assert_true(fabs(lateral - lateral0) < 1e-6);
        ps_plant_destroy(p);
    }
}

/* Depth and normal force of the contact between two geoms (0 if none). */
static double pair_depth(ps_plant_t *p, int geom_a, int geom_b, double *out_force_n)
{
    const mjModel *m = ps_plant_model(p);
    const mjData *d = ps_plant_data(p);
    double depth = 0.0;
    *out_force_n = 0.0;
    for (int k = 0; k < d->ncon; k++) {
        const mjContact *con = &d->contact[k];
        if ((con->geom1 == geom_a && con->geom2 == geom_b) ||
            (con->geom1 == geom_b && con->geom2 == geom_a)) {
            mjtNum f[6];
            mj_contactForce(m, d, k, f);
            depth = -con->dist;
            *out_force_n = f[0];
        }
    }
    return depth;
}

/* Two agents pressed together by a steady push (the pushed one's feet take
 * part of it) compress by the force between them over K, the configured
 * body stiffness (Helbing 2000's k), at two stiffnesses. */
static void test_crowd_two_body_compression_as_configured(void **state)
{
    (void)state;
    const double ks[] = {1.2e5, 3e4};
    const double f_n = 200.0;
    for (int k = 0; k < 2; k++) {
        ps_crowd_cfg_t c = base_cfg();
        c.social.a_n = 0.0f; /* contact only */
        c.social.wall_a_n = 0.0f;
        c.social.v0_m_s = 0.0f;
        c.robot_a_n = 0.0f;
        c.body.body_k_n_m = (float)ks[k];
        c.n_walls = 1;
        c.walls[0] = (ps_crowd_wall_cfg_t){1.0f, -1.0f, 1.0f, 1.0f};
        line_group(&c, 2, 0.36f, 0.35f, 0, 1, 0);
        c.groups[0].goal = PS_CROWD_GOAL_DIRECTION;
        c.groups[0].goal_xy[0] = 1.0f;
        c.n_events = 1;
        c.events[0] = (ps_crowd_event_cfg_t){.t_s = 0, .duration_s = 100,
                                             .kind = PS_CROWD_EVENT_PUSH, .group = "g",
                                             .agent = 0, .force_n = {(float)f_n, 0, 0}};
        ps_plant_t *p = make_plant(&c, -5, -5, 1);
        const mjModel *m = ps_plant_model(p);
        run_s(p, 3.0);
        double f_contact = 0.0;
        const double depth = pair_depth(p, mj_name2id(m, mjOBJ_GEOM, "agent0_ring"),
                                        mj_name2id(m, mjOBJ_GEOM, "agent1_ring"), &f_contact);
        printf("compression: K %.0f N/m, push %.0f N, contact force %.1f N: depth %.3f mm, "
               "F/K %.3f mm\n",
               ks[k], f_n, f_contact, depth * 1e3, f_contact / ks[k] * 1e3);
        assert_true(f_contact > 0.5 * f_n);
        assert_true(fabs(depth - f_contact / ks[k]) <= 0.05 * f_contact / ks[k]);
        ps_plant_destroy(p);
    }
}

/* Push-and-Step's 5-person queue: a shove on the rear person reaches the
 * front person later and measurably; arrival grows along the queue. */
static void test_crowd_queue_push_arrives_in_order(void **state)
{
    (void)state;
    ps_crowd_cfg_t c = base_cfg();
    c.social.a_n = 200.0f;
    line_group(&c, 5, 0.38f, 2.0f, 3.0f, 0.0f, 3.0f); /* agent 0 at the front (x 2), 4 at the rear */
    c.groups[0].goal = PS_CROWD_GOAL_HOLD;
    c.n_events = 1;
    c.events[0] = (ps_crowd_event_cfg_t){.t_s = 3.0f, .duration_s = 0.3f,
                                         .kind = PS_CROWD_EVENT_PUSH, .group = "g", .agent = 4,
                                         .force_n = {400, 0, 0},
                                         .profile = PS_CROWD_PROFILE_HALF_SINE};
    ps_plant_t *p = make_plant(&c, -5, -5, 1);
    run_s(p, 2.999); /* settled: the queue stands still */
    double x0[5], arrival[5], moved[5];
    for (uint32_t i = 0; i < 5; i++) {
        x0[i] = agent(p, i).com_m[0];
        arrival[i] = -1.0;
        moved[i] = 0.0;
    }
    for (int k = 0; k < 2500; k++) { /* 2.5 s in 1 ms steps */
        assert_int_equal(ps_plant_step(p), 0);
        for (uint32_t i = 0; i < 5; i++) {
            const double dx = agent(p, i).com_m[0] - x0[i]; /* the push is along +x */
            moved[i] = dx > moved[i] ? dx : moved[i];
            if (arrival[i] < 0 && dx > 0.01)
                arrival[i] = k * 1e-3;
        }
    }
    for (uint32_t i = 0; i < 5; i++)
        printf("queue: agent %u (%u from the rear) moved %.3f m, 1 cm reached %.3f s after the push\n",
               i, 4 - i, moved[i], arrival[i]);
    for (uint32_t i = 0; i < 5; i++)
        assert_true(arrival[i] >= 0.0); /* all of them, the front one included, moved 1 cm */
    for (uint32_t i = 0; i < 4; i++)
        assert_true(arrival[i] > arrival[i + 1]); /* farther from the rear: later */
    ps_plant_destroy(p);
}

/* A walled pen held at a preset density keeps it in the measuring area. */
static void test_crowd_density_presets_within_10_percent(void **state)
{
    (void)state;
    const float presets[] = {4.0f, 6.0f};
    for (int k = 0; k < 2; k++) {
        ps_crowd_cfg_t c = base_cfg();
        c.arena = (ps_crowd_rect_t){-2, -2, 2, 2};
        c.has_arena_walls = true;
        c.measure = (ps_crowd_rect_t){-1.5f, -1.5f, 1.5f, 1.5f};
        ps_crowd_group_cfg_t *g = &c.groups[0];
        g->density_m2 = presets[k];
        g->region = c.arena;
        g->goal = PS_CROWD_GOAL_HOLD;
        ps_plant_t *p = make_plant(&c, 30, 30, 2); /* robot out of the pen */
        run_s(p, 1.5);
        ps_crowd_stats_t st;
        ps_crowd_get_stats(ps_plant_crowd(p), &st);
        printf("density preset %.1f / m^2: %u agents, measured %.2f / m^2 in the central 9 m^2\n",
               (double)presets[k], st.n_agents, st.measure_density_m2);
        assert_true(fabs(st.measure_density_m2 - presets[k]) <= 0.1 * presets[k]);
        ps_plant_destroy(p);
    }
}

/* Walking down a wide wrapping corridor (10 m x 3 m, periodic in x) at
 * several densities, everyone wanting the same 1.29 m/s (so density is all
 * that changes): the mean speed in the corridor falls as density grows (the
 * fundamental diagram), and the walkers stay on their feet. */
static void test_crowd_speed_falls_with_density(void **state)
{
    (void)state;
    const float densities[] = {0.5f, 1.5f, 2.5f, 3.5f};
    double speed[4];
    for (int k = 0; k < 4; k++) {
        ps_crowd_cfg_t c = base_cfg();
        c.arena = (ps_crowd_rect_t){-5, -1.5f, 5, 1.5f};
        c.has_arena_walls = true;
        c.is_periodic_x = true;
        c.measure = c.arena;
        ps_crowd_group_cfg_t *g = &c.groups[0];
        g->density_m2 = densities[k];
        g->region = c.arena;
        g->goal = PS_CROWD_GOAL_DIRECTION;
        g->goal_xy[0] = 1.0f;
        ps_plant_t *p = make_plant(&c, 30, 30, 11);
        run_s(p, 2.5); /* from rest into the flow */
        double sum = 0.0;
        const int n_samples = 15;
        for (int q = 0; q < n_samples; q++) {
            run_s(p, 0.1);
            ps_crowd_stats_t st;
            ps_crowd_get_stats(ps_plant_crowd(p), &st);
            sum += st.measure_speed_m_s;
        }
        ps_crowd_stats_t st;
        ps_crowd_get_stats(ps_plant_crowd(p), &st);
        speed[k] = sum / n_samples;
        printf("corridor at %.1f / m^2 (%u agents): mean speed %.3f m/s over 1.5 s, %u fallen, "
               "%llu reflex steps\n",
               (double)densities[k], st.n_agents, speed[k], st.n_fallen,
               (unsigned long long)st.n_steps_taken);
        assert_int_equal(st.n_fallen, 0);
        ps_plant_destroy(p);
    }
    assert_true(fabs(speed[0] - 1.29) < 0.1 * 1.29); /* nearly free at 0.5 / m^2 */
    for (int k = 0; k < 3; k++)
        assert_true(speed[k + 1] < speed[k] - 0.02);
}

/* A light push makes an agent step and recover; a hard one fells it, and it
 * then lies on the floor. The light push's recovery takes three steps, the
 * last about 2 s after the push (measured: tilt 0.177 rad at 2.5 s, 0.064 at
 * 3.0 s, 0.009 at 4.0 s, below 0.005 from 4.5 s), so the run lasts 5 s. */
static void test_crowd_push_steps_or_fells(void **state)
{
    (void)state;
    const float forces[] = {250.0f, 1200.0f};
    for (int k = 0; k < 2; k++) {
        ps_crowd_cfg_t c = base_cfg();
        line_group(&c, 1, 1.0f, 0, 5, 1, 5);
        c.groups[0].goal = PS_CROWD_GOAL_HOLD;
        c.n_events = 1;
        c.events[0] = (ps_crowd_event_cfg_t){.t_s = 0.5f, .duration_s = 0.2f,
                                             .kind = PS_CROWD_EVENT_PUSH, .group = "g",
                                             .agent = -1, .force_n = {forces[k], 0, 0}};
        ps_plant_t *p = make_plant(&c, 30, 30, 4);
        double max_tilt = 0.0;
        for (int q = 0; q < 50; q++) {
            run_s(p, 0.1);
            const double tilt = agent(p, 0).tilt_rad;
            max_tilt = tilt > max_tilt ? tilt : max_tilt;
        }
        ps_crowd_stats_t st;
        ps_crowd_get_stats(ps_plant_crowd(p), &st);
        const ps_crowd_agent_state_t a = agent(p, 0);
        printf("push %.0f N for 0.2 s: %llu steps, max tilt %.3f rad, fallen %d, tilt now %.3f\n",
               (double)forces[k], (unsigned long long)st.n_steps_taken, max_tilt, a.is_fallen,
               a.tilt_rad);
        assert_true(st.n_steps_taken >= 1);
        if (k == 0) {
            assert_false(a.is_fallen);
            assert_true(a.tilt_rad < 0.05);
        } else {
            assert_true(a.is_fallen);
            assert_int_equal(st.n_fallen, 1);
            assert_true(a.tilt_rad > 1.4); /* lying on the floor */
            assert_true(a.com_m[2] < 0.35);
        }
        ps_plant_destroy(p);
    }
}

/* A moving wall pushes the people in front of it. */
static void test_crowd_moving_wall_pushes_agents(void **state)
{
    (void)state;
    ps_crowd_cfg_t c = base_cfg();
    line_group(&c, 4, 0.6f, 0.5f, -0.9f, 0.5f, 1.0f);
    c.groups[0].goal = PS_CROWD_GOAL_HOLD;
    c.n_events = 1;
    c.events[0] = (ps_crowd_event_cfg_t){.t_s = 0.2f, .duration_s = 2.0f,
                                         .kind = PS_CROWD_EVENT_WALL, .speed_m_s = 0.5f,
                                         .direction = {1, 0}, .wall = {0.0f, -1.5f, 0.0f, 1.5f}};
    ps_plant_t *p = make_plant(&c, 30, 30, 5);
    run_s(p, 2.5);
    for (uint32_t i = 0; i < 4; i++) {
        const ps_crowd_agent_state_t a = agent(p, i);
        assert_true(a.base_m[0] > 0.5 + 0.5); /* the wall went 1 m; they were 0.5 m ahead */
    }
    ps_plant_destroy(p);
}

/* The crowd turns a force on a torso into generalised forces on the agent's
 * joints itself (J^T f, O(1) per agent): for a tilted agent they equal what
 * MuJoCo's mj_applyFT makes of the same force at the same point. The push
 * is isolated as the difference of two calls between crowd updates, one
 * inside the push and one after it. */
static void test_crowd_torso_force_equals_mj_applyft(void **state)
{
    (void)state;
    ps_crowd_cfg_t c = base_cfg();
    line_group(&c, 1, 1.0f, 0, 5, 1, 5);
    c.groups[0].goal = PS_CROWD_GOAL_HOLD;
    c.n_events = 1;
    c.events[0] = (ps_crowd_event_cfg_t){.t_s = 0.0f, .duration_s = 0.01f,
                                         .kind = PS_CROWD_EVENT_PUSH, .group = "g",
                                         .agent = -1, .force_n = {300, -200, 50}};
    ps_plant_t *p = make_plant(&c, 30, 30, 4);
    const mjModel *m = ps_plant_model(p);
    mjData *d = (mjData *)ps_plant_data(p);
    d->qpos[m->jnt_qposadr[mj_name2id(m, mjOBJ_JOINT, "agent0_tx")]] = 0.3;
    d->qpos[m->jnt_qposadr[mj_name2id(m, mjOBJ_JOINT, "agent0_ty")]] = -0.2;
    d->qpos[m->jnt_qposadr[mj_name2id(m, mjOBJ_JOINT, "agent0_x")]] = 0.4;
    mj_forward(m, d);
    ps_crowd_t *cr = ps_plant_crowd(p);
    ps_crowd_before_step(cr, m, d, 0.005); /* updates, then pushes */
    double *with = calloc((size_t)m->nv, sizeof(double));
    double *want = calloc((size_t)m->nv, sizeof(double));
    assert_non_null(with);
    assert_non_null(want);
    memcpy(with, d->qfrc_applied, (size_t)m->nv * sizeof(double));
    ps_crowd_before_step(cr, m, d, 0.02); /* no update (every 2 steps), no push */
    const int ring = mj_name2id(m, mjOBJ_BODY, "agent0_ring");
    mjtNum f[3] = {300, -200, 50}, zero[3] = {0, 0, 0};
    mj_applyFT(m, d, f, zero, d->xpos + 3 * ring, ring, want);
    double worst = 0.0, largest = 0.0;
    for (int i = 0; i < m->nv; i++) {
        const double e = fabs((with[i] - d->qfrc_applied[i]) - want[i]);
        worst = e > worst ? e : worst;
        largest = fabs(want[i]) > largest ? fabs(want[i]) : largest;
    }
    printf("torso force: largest generalised force %.3f, worst difference to mj_applyFT %.3g\n",
           largest, worst);
    assert_true(largest > 100.0);
    assert_true(worst < 1e-9 * largest);
    free(with);
    free(want);
    ps_plant_destroy(p);
}

/* The arena's sides hold people in through Helbing's wall contact (no MuJoCo
 * geoms): an agent driven into a side without the social wall term stops
 * at it, compressed by about its drive over the body stiffness. */
static void test_crowd_arena_side_stops_agent(void **state)
{
    (void)state;
    ps_crowd_cfg_t c = base_cfg();
    c.arena = (ps_crowd_rect_t){-2, -2, 2, 2};
    c.has_arena_walls = true;
    c.social.wall_a_n = 0.0f; /* contact alone */
    line_group(&c, 1, 1.0f, 1.0f, 0, 1.5f, 0);
    c.groups[0].goal = PS_CROWD_GOAL_DIRECTION;
    c.groups[0].goal_xy[0] = 1.0f;
    c.groups[0].speed_m_s = 1.0f;
    ps_plant_t *p = make_plant(&c, 30, 30, 4);
    run_s(p, 3.0);
    const ps_crowd_agent_state_t a = agent(p, 0);
    ps_crowd_stats_t st;
    ps_crowd_get_stats(ps_plant_crowd(p), &st);
    /* at rest the drive m v0 / tau presses it on; depth F / K */
    const double drive_n = 70.0 * 1.0 / (double)c.social.tau_s;
    printf("arena side: base x %.4f m, CoM x %.4f m, overlap %.2f mm (drive / K %.2f mm), "
           "max %.2f mm, speed %.3f m/s\n",
           a.base_m[0], a.com_m[0], st.penetration_m * 1e3, drive_n / 1.2e5 * 1e3,
           st.penetration_max_m * 1e3, hypot(a.vel_m_s[0], a.vel_m_s[1]));
    assert_false(a.is_fallen);
    assert_true(a.com_m[0] < 2.0 - 0.17 + 0.01);
    assert_true(hypot(a.vel_m_s[0], a.vel_m_s[1]) < 0.02);
    assert_true(st.penetration_m > 0.2 * drive_n / 1.2e5);
    assert_true(st.penetration_max_m < 0.02);
    ps_plant_destroy(p);
}

/* A walled square arena of half side half_m filled at density_m2 with
 * people walking at the robot (at the origin), clear_m around it. */
static ps_crowd_cfg_t press_cfg(float half_m, float density_m2, float clear_m)
{
    ps_crowd_cfg_t c = base_cfg();
    c.arena = (ps_crowd_rect_t){-half_m, -half_m, half_m, half_m};
    c.has_arena_walls = true;
    c.groups[0].density_m2 = density_m2;
    c.groups[0].region = c.arena;
    c.groups[0].goal = PS_CROWD_GOAL_ROBOT;
    c.groups[0].clear_m = clear_m;
    c.robot_a_n = 0.0f;
    return c;
}

/* A 4 m x 4 m pen at 3 / m^2, everyone walking at the robot in its middle. */
static ps_crowd_cfg_t pen_cfg(void)
{
    ps_crowd_cfg_t c = press_cfg(2.0f, 3.0f, 0.5f);
    c.groups[0].speed_sd_m_s = 0.1f;
    return c;
}

/* Two plants: the same state, bit for bit. */
static void assert_same_state(ps_plant_t *a, ps_plant_t *b)
{
    const mjModel *m = ps_plant_model(a);
    assert_int_equal(m->nq, ps_plant_model(b)->nq);
    assert_memory_equal(ps_plant_data(a)->qpos, ps_plant_data(b)->qpos,
                        (size_t)m->nq * sizeof(mjtNum));
    assert_memory_equal(ps_plant_data(a)->qvel, ps_plant_data(b)->qvel,
                        (size_t)m->nv * sizeof(mjtNum));
}

/* The same, then both destroyed. */
static void assert_same_state_and_destroy(ps_plant_t *p[2])
{
    assert_same_state(p[0], p[1]);
    ps_plant_destroy(p[0]);
    ps_plant_destroy(p[1]);
}

/* ---- tags on the shoulders ------------------------------------------------- */

/* The name of site s's material, or "". */
static const char *site_material(const mjModel *m, int s)
{
    const int mat = m->site_matid[s];
    return mat >= 0 ? m->names + m->name_matadr[mat] : "";
}

/* Agent k wears tag36h11 2k (left) and 2k + 1 (right) on plates on the
 * front of its shoulders, facing the robot it walks to: the left plate on
 * its left, at 0.80 of its height, 0.11 of it off the axis, 5 mm in front
 * of its torso; a texture and a material per tag. A robot model with tags
 * of its own pushes the crowd's numbering past them. Off: no plates. */
static void test_scene_tags_on_shoulders_ids_and_sides(void **state)
{
    (void)state;
    ps_crowd_cfg_t c = base_cfg();
    c.groups[0].count = 6;
    c.groups[0].region = (ps_crowd_rect_t){1, -1.5f, 3, 1.5f};
    c.groups[0].goal = PS_CROWD_GOAL_ROBOT;
    c.groups[0].height_sd_m = 0.07f;
    c.tags = PS_CROWD_TAGS_ON;
    ps_plant_t *p = make_plant(&c, 0, 0, 2);
    const mjModel *m = ps_plant_model(p);
    const mjData *d = ps_plant_data(p);
    for (uint32_t k = 0; k < 6; k++) {
        char name[48];
        snprintf(name, sizeof(name), "agent%u", k);
        const int b = mj_name2id(m, mjOBJ_BODY, name);
        snprintf(name, sizeof(name), "agent%u_body", k);
        const int g = mj_name2id(m, mjOBJ_GEOM, name);
        assert_true(b > 0 && g >= 0);
        const double r = m->geom_size[3 * g], h = 2.0 * (m->geom_size[3 * g + 1] + r);
        const double *axis = d->xpos + 3 * b;
        double f[2] = {-axis[0], -axis[1]}; /* toward the robot at the origin */
        const double fn = hypot(f[0], f[1]);
        f[0] /= fn;
        f[1] /= fn;
        for (uint32_t side = 0; side < 2; side++) {
            snprintf(name, sizeof(name), "agent%u_tag_%s", k, side == 0 ? "left" : "right");
            const int si = mj_name2id(m, mjOBJ_SITE, name);
            assert_true(si >= 0);
            assert_int_equal(m->site_bodyid[si], b);
            char tag[32];
            snprintf(tag, sizeof(tag), "tag36h11_%u", 2 * k + side);
            assert_string_equal(site_material(m, si), tag);
            const int mat = m->site_matid[si];
            assert_string_equal(m->names + m->name_texadr[m->mat_texid[mat]], tag);
            const double *sp = d->site_xpos + 3 * si, *sr = d->site_xmat + 9 * si;
            const double dx = sp[0] - axis[0], dy = sp[1] - axis[1];
            const double ahead = dx * f[0] + dy * f[1], leftward = -dx * f[1] + dy * f[0];
            assert_true(fabs(ahead - (r + 0.005)) < 1e-4);
            assert_true(fabs(leftward - (side == 0 ? 0.11 : -0.11) * h) < 1e-4);
            assert_true(fabs(sp[2] - 0.80 * h) < 1e-4);
            assert_true(sr[2] * f[0] + sr[5] * f[1] > 0.9999);      /* the face looks ahead */
            assert_true(fabs(m->site_size[3 * si] - 0.075) < 1e-6); /* 0.12 m black square */
        }
    }
    ps_plant_destroy(p);
    /* a model that wears tags 0-5 itself: the crowd's start at 6 */
    p = make_plant_in("tests/data/models/ps1-tags.xml", &c, 0, 0, 2);
    m = ps_plant_model(p);
    assert_string_equal(site_material(m, mj_name2id(m, mjOBJ_SITE, "agent0_tag_left")),
                        "tag36h11_6");
    assert_string_equal(site_material(m, mj_name2id(m, mjOBJ_SITE, "agent5_tag_right")),
                        "tag36h11_17");
    ps_plant_destroy(p);
    c.tags = PS_CROWD_TAGS_OFF;
    p = make_plant(&c, 0, 0, 2);
    m = ps_plant_model(p);
    assert_true(mj_name2id(m, mjOBJ_SITE, "agent0_tag_left") < 0);
    assert_true(mj_name2id(m, mjOBJ_TEXTURE, "tag36h11_0") < 0);
    ps_plant_destroy(p);
    c.tags = PS_CROWD_TAGS_AUTO; /* the plant's own default: none */
    p = make_plant(&c, 0, 0, 2);
    assert_true(mj_name2id(ps_plant_model(p), mjOBJ_SITE, "agent0_tag_left") < 0);
    ps_plant_destroy(p);
}

static unsigned count_of(const char *text, const char *what)
{
    unsigned n = 0;
    for (const char *q = strstr(text, what); q != NULL; q = strstr(q + 1, what))
        n++;
    return n;
}

/* Who wears tags: the people nearest the robot, as many as MuJoCo 2.2.2's
 * renderer has texture slots for (100: 50 people on a model without
 * textures of its own), and only those whose pair fits tag36h11's 587 ids;
 * the scene writes their plates and textures and refuses ids that are no
 * pair's first. */
static void test_scene_tags_on_the_nearest_within_limits(void **state)
{
    (void)state;
    apriltag_family_t *fam = tag36h11_create();
    assert_int_equal(fam->ncodes, PS_SCENE_TAG_IDS);
    tag36h11_destroy(fam);
    static ps_crowd_agent_spec_t a[PS_CROWD_MAX_AGENTS];
    static int32_t id[PS_CROWD_MAX_AGENTS];
    for (uint32_t i = 0; i < PS_CROWD_MAX_AGENTS; i++) /* a 20 x 15 grid, 0.5 m apart */
        a[i] = (ps_crowd_agent_spec_t){.x_m = 0.5 * (i % 20) - 4.75,
                                       .y_m = 0.5 * (i / 20) - 3.5,
                                       .height_m = 1.7,
                                       .mass_kg = 70,
                                       .radius_m = 0.17};
    const double robot_xy[2] = {0.3, 0.1};
    assert_int_equal(ps_scene_choose_tagged(a, PS_CROWD_MAX_AGENTS, robot_xy, 0, 50, id), 50);
    double far_in = 0.0, near_out = 1e9;
    for (uint32_t k = 0; k < PS_CROWD_MAX_AGENTS; k++) {
        const double d = hypot(a[k].x_m - robot_xy[0], a[k].y_m - robot_xy[1]);
        if (id[k] >= 0) {
            assert_int_equal(id[k], 2 * (int)k);
            far_in = d > far_in ? d : far_in;
        } else {
            near_out = d < near_out ? d : near_out;
        }
    }
    assert_true(far_in <= near_out); /* the 50 nearest */
    /* ids past tag36h11: agents from 293 on (and 290 on from id 6) wear none */
    assert_int_equal(ps_scene_choose_tagged(a, PS_CROWD_MAX_AGENTS, robot_xy, 0, 300, id), 293);
    assert_int_equal(id[292], 584);
    assert_int_equal(id[293], -1);
    assert_int_equal(ps_scene_choose_tagged(a, PS_CROWD_MAX_AGENTS, robot_xy, 6, 300, id), 290);
    assert_int_equal(ps_scene_choose_tagged(a, 24, robot_xy, 0, 0, id), 0);
    /* the scene: plates and textures for the 50 */
    ps_crowd_cfg_t c = base_cfg();
    (void)ps_scene_choose_tagged(a, PS_CROWD_MAX_AGENTS, robot_xy, 0, 50, id);
    char *xml = NULL;
    char err[PS_ERR_MSG_LEN];
    assert_int_equal(ps_scene_write_mjcf(&c, a, PS_CROWD_MAX_AGENTS, "ps1.xml", 150, 600, id, &xml,
                                         err, sizeof(err)),
                     0);
    assert_int_equal(count_of(xml, "_tag_left\""), 50);
    assert_int_equal(count_of(xml, "_tag_right\""), 50);
    assert_int_equal(count_of(xml, "<texture name=\"tag36h11_"), 100);
    free(xml);
    id[3] = 7;
    assert_int_equal(ps_scene_write_mjcf(&c, a, 4, "ps1.xml", 150, 600, id, &xml, err, sizeof(err)),
                     -EINVAL); /* a pair starts even */
    assert_non_null(strstr(err, "agent 3: tag 7"));
}

/* A crowd bigger than the renderer's texture slots: tags on the 50 people
 * nearest the robot; the camera can draw the scene. */
static void test_crowd_large_crowd_tagged_nearest_fifty(void **state)
{
    (void)state;
    ps_crowd_cfg_t c = pen_cfg();
    c.arena = (ps_crowd_rect_t){-3, -3, 3, 3};
    c.groups[0].region = c.arena;
    c.tags = PS_CROWD_TAGS_ON;
    ps_plant_t *p = make_plant(&c, 0, 0, 6);
    const mjModel *m = ps_plant_model(p);
    const uint32_t n = ps_crowd_agent_count(ps_plant_crowd(p));
    assert_true(n > 50);
    assert_int_equal(m->ntex, 100);
    assert_int_equal(m->nsite, 1 + 100); /* the robot's IMU site and the plates */
    ps_plant_destroy(p);
}

/* The plates are sites: they draw, never collide. Same scene, tags on and
 * off: the same trajectories, bit for bit; the time of each run printed. */
static void test_crowd_tags_leave_physics_unchanged(void **state)
{
    (void)state;
    ps_crowd_cfg_t c = pen_cfg();
    ps_plant_t *p[2];
    double wall_s[2];
    for (int k = 0; k < 2; k++) {
        c.tags = k == 0 ? PS_CROWD_TAGS_OFF : PS_CROWD_TAGS_ON;
        p[k] = make_plant(&c, 0, 0, 6);
        struct timespec t0, t1;
        clock_gettime(CLOCK_MONOTONIC, &t0);
        run_s(p[k], 1.0);
        clock_gettime(CLOCK_MONOTONIC, &t1);
        wall_s[k] = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
    }
    const mjModel *m0 = ps_plant_model(p[0]), *m1 = ps_plant_model(p[1]);
    printf("tags off: %d sites, 1 s in %.3f s; on: %d sites, %d textures, 1 s in %.3f s "
           "(%u agents)\n",
           m0->nsite, wall_s[0], m1->nsite, m1->ntex, wall_s[1],
           ps_crowd_agent_count(ps_plant_crowd(p[0])));
    assert_int_equal(m1->nsite - m0->nsite, 2 * (int)ps_crowd_agent_count(ps_plant_crowd(p[0])));
    assert_int_equal(m0->ngeom, m1->ngeom);
    assert_same_state(p[0], p[1]);
    assert_true(ps_plant_data(p[1])->ncon > 0); /* they do press */
    assert_int_equal(ps_plant_data(p[0])->ncon, ps_plant_data(p[1])->ncon);
    ps_plant_destroy(p[0]);
    ps_plant_destroy(p[1]);
}

/* Same scene, seed and events: the same trajectories, bit for bit. */
static void test_crowd_same_seed_identical_trajectories(void **state)
{
    (void)state;
    ps_crowd_cfg_t c = press_cfg(2.0f, 3.0f, 0.5f);
    c.groups[0].speed_sd_m_s = 0.1f;
    ps_plant_t *p[2];
    for (int k = 0; k < 2; k++) {
        p[k] = make_plant(&c, 0, 0, 6);
        run_s(p[k], 1.0);
    }
    assert_same_state_and_destroy(p);
}

/* Capsule gating (crowd.gate_capsules): agents far from the robot and the
 * walls have their capsules switched out of collision, and the run is
 * bitwise the one without gating (the capsules it switches off would have
 * touched nothing). */
static void test_crowd_capsule_gating_keeps_contacts(void **state)
{
    (void)state;
    ps_crowd_cfg_t c = press_cfg(3.0f, 2.5f, 0.45f);
    c.n_walls = 1; /* a wall segment the agents by it touch */
    c.walls[0] = (ps_crowd_wall_cfg_t){-2.5f, 2.3f, 2.5f, 2.3f};
    ps_plant_t *p[2];
    uint32_t n_off = 0, n_agents = 0;
    for (int k = 0; k < 2; k++) {
        c.gate_capsules = k == 0;
        p[k] = make_plant(&c, 0, 0, 9);
        run_s(p[k], 1.0);
        const mjModel *m = ps_plant_model(p[k]);
        n_agents = ps_crowd_agent_count(ps_plant_crowd(p[k]));
        for (uint32_t i = 0; i < n_agents && k == 0; i++) {
            char name[32];
            (void)snprintf(name, sizeof(name), "agent%u_body", i);
            n_off += m->geom_contype[mj_name2id(m, mjOBJ_GEOM, name)] == 0 ? 1u : 0u;
        }
    }
    ps_crowd_stats_t st;
    ps_crowd_get_stats(ps_plant_crowd(p[0]), &st);
    printf("gating: %u of %u capsules out of collision after 1 s; crowd force on the robot up "
           "to %.0f N\n",
           n_off, n_agents, st.robot_force_max_n);
    assert_true(n_off > n_agents / 2 && n_off < n_agents); /* it gates, not all */
    assert_true(st.robot_force_max_n > 50.0);              /* and the press is on */
    assert_same_state_and_destroy(p);
}

/* People pressing on the robot: force per robot part, transmitted impulse,
 * local density, penetration. */
static void test_crowd_measures_the_press_on_the_robot(void **state)
{
    (void)state;
    ps_crowd_cfg_t c = base_cfg();
    c.timestep_s = 0.0f; /* the robot's own step: it is measured here */
    c.arena = (ps_crowd_rect_t){-1.5f, -1.5f, 1.5f, 1.5f};
    c.has_arena_walls = true;
    c.groups[0].density_m2 = 3.0f;
    c.groups[0].region = c.arena;
    c.groups[0].goal = PS_CROWD_GOAL_ROBOT;
    c.groups[0].speed_m_s = 0.6f;
    c.groups[0].clear_m = 0.45f;
    c.robot_a_n = 0.0f;
    ps_plant_t *p = make_plant(&c, 0, 0, 7);
    run_s(p, 1.5);
    ps_crowd_stats_t st;
    ps_crowd_get_stats(ps_plant_crowd(p), &st);
    double part_max = 0.0;
    const char *part = "";
    for (uint32_t i = 0; i < st.n_parts; i++)
        if (st.part_force_max_n[i] > part_max) {
            part_max = st.part_force_max_n[i];
            part = st.part_name[i];
        }
    printf("press: %u agents, force on the robot %.1f N (max %.1f), most on %s (%.1f N), impulse "
           "%.2f N s, local density %.2f / m^2, penetration max %.2f mm\n",
           st.n_agents, st.robot_force_n, st.robot_force_max_n, part, part_max,
           st.transmitted_impulse_ns, st.local_density_m2, st.penetration_max_m * 1e3);
    assert_true(st.n_parts >= 10);
    assert_true(st.robot_force_max_n > 50.0);
    assert_true(part_max > 10.0);
    assert_true(st.transmitted_impulse_ns > 1.0);
    assert_true(st.local_density_m2 > 1.0);
    assert_true(st.penetration_max_m > 0.0 && st.penetration_max_m < 0.05);
    ps_plant_destroy(p);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_social_drive_hand_computed),
        cmocka_unit_test(test_social_agent_repulsion_hand_computed),
        cmocka_unit_test(test_social_pair_repulsion_equals_both_sides),
        cmocka_unit_test(test_social_wall_repulsion_hand_computed),
        cmocka_unit_test(test_social_evasive_steps_aside_away_from_neighbours),
        cmocka_unit_test(test_crowd_blocking_ahead_independent_of_grid),
        cmocka_unit_test(test_social_grid_finds_every_neighbour_in_range),
        cmocka_unit_test(test_scene_place_seeded_lattice_density_and_clearance),
        cmocka_unit_test(test_scene_loads_around_unchanged_robot_with_sizes),
        cmocka_unit_test(test_scene_tags_on_shoulders_ids_and_sides),
        cmocka_unit_test(test_scene_tags_on_the_nearest_within_limits),
        cmocka_unit_test(test_crowd_large_crowd_tagged_nearest_fifty),
        cmocka_unit_test(test_crowd_tags_leave_physics_unchanged),
        cmocka_unit_test(test_crowd_free_speed_within_10_percent),
        cmocka_unit_test(test_crowd_two_body_compression_as_configured),
        cmocka_unit_test(test_crowd_queue_push_arrives_in_order),
        cmocka_unit_test(test_crowd_density_presets_within_10_percent),
        cmocka_unit_test(test_crowd_speed_falls_with_density),
        cmocka_unit_test(test_crowd_push_steps_or_fells),
        cmocka_unit_test(test_crowd_moving_wall_pushes_agents),
        cmocka_unit_test(test_crowd_torso_force_equals_mj_applyft),
        cmocka_unit_test(test_crowd_arena_side_stops_agent),
        cmocka_unit_test(test_crowd_same_seed_identical_trajectories),
        cmocka_unit_test(test_crowd_capsule_gating_keeps_contacts),
        cmocka_unit_test(test_crowd_measures_the_press_on_the_robot),
    };
    return cmocka_run_group_tests(tests, setup_robot, NULL);
}
