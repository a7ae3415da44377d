/*
 * Tests of the simulated crowd: the social-force terms against hand-computed
 * values and the cell grid (sim/ps_social.c), placement and the generated
 * scene (sim/ps_scene.c), and the crowd in the MuJoCo plant (sim/ps_crowd.c
 * through sim/ps_plant.c): free speed, body compression, a pushed queue,
 * densities, speed against density, stepping and falling, moving walls,
 * determinism. The robot (robots/ps1.yaml) hangs limp in its harness.
 * Run from the repo root.
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

#include <mujoco/mujoco.h>

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

static ps_plant_t *make_plant(const ps_crowd_cfg_t *crowd, double rx, double ry, uint32_t seed)
{
    const ps_plant_cfg_t pc = {
        .model_path = MODEL_PATH,
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

static void run_s(ps_plant_t *p, double t_s)
{
    const int n = (int)lround(t_s / ps_plant_timestep_s(p));
    for (int i = 0; i < n; i++)
        assert_int_equal(ps_plant_step(p), 0);
}

static ps_crowd_agent_state_t agent(ps_plant_t *p, uint32_t i)
{
    ps_crowd_agent_state_t a;
    assert_int_equal(ps_crowd_get_agent(ps_plant_crowd(p), i, &a), 0);
    return a;
}

/* A crowd cfg with an open arena around the origin and one group. */
static ps_crowd_cfg_t base_cfg(void)
{
    ps_crowd_cfg_t c;
    ps_crowd_default_cfg(&c);
    c.is_enabled = true;
    c.arena = (ps_crowd_rect_t){-20, -20, 20, 20};
    c.measure = c.arena;
    c.n_groups = 1;
    ps_crowd_group_cfg_t *g = &c.groups[0];
    *g = (ps_crowd_group_cfg_t){.name = "g", .height_m = 1.7f, .mass_kg = 70.0f, .radius_m = 0.17f};
    return c;
}

/* ---- exploratory: one free walker ----------------------------------------- */

static void test_crowd_free_walker_reaches_free_speed(void **state)
{
    (void)state;
    ps_crowd_cfg_t c = base_cfg();
    ps_crowd_group_cfg_t *g = &c.groups[0];
    g->count = 1;
    g->layout = PS_CROWD_LAYOUT_LINE;
    g->region = (ps_crowd_rect_t){-5, 5, -4, 5};
    g->goal = PS_CROWD_GOAL_DIRECTION;
    g->goal_xy[0] = 1.0f;
    ps_plant_t *p = make_plant(&c, 0, 0, 1);
    for (int k = 0; k < 10; k++) {
        run_s(p, 0.5);
        const ps_crowd_agent_state_t a = agent(p, 0);
        printf("t=%.1f x=%.2f y=%.2f v=%.2f tilt=%.3f step=%d fall=%d\n", 0.5 * (k + 1), a.com_m[0],
               a.com_m[1], a.vel_m_s[0], a.tilt_rad, a.is_stepping, a.is_fallen);
    }
    ps_plant_destroy(p);
}

static double pair_depth(ps_plant_t *p, int body_a, int body_b)
{
    const mjModel *m = ps_plant_model(p);
    const mjData *d = ps_plant_data(p);
    double depth = 0.0;
    for (int k = 0; k < d->ncon; k++) {
        const int b1 = m->geom_bodyid[d->contact[k].geom1], b2 = m->geom_bodyid[d->contact[k].geom2];
        if ((b1 == body_a && b2 == body_b) || (b1 == body_b && b2 == body_a))
            depth = -d->contact[k].dist > depth ? -d->contact[k].dist : depth;
    }
    return depth;
}

static void explore_compression(double k, double f)
{
    ps_crowd_cfg_t c = base_cfg();
    c.social.a_n = 0.0f;
    c.social.wall_a_n = 0.0f;
    c.robot_a_n = 0.0f;
    c.body.body_k_n_m = (float)k;
    c.social.v0_m_s = 0.0f;
    c.n_walls = 1;
    c.walls[0] = (ps_crowd_wall_cfg_t){1.0f, -1.0f, 1.0f, 1.0f};
    ps_crowd_group_cfg_t *g = &c.groups[0];
    g->count = 2;
    g->layout = PS_CROWD_LAYOUT_LINE;
    g->spacing_m = 0.36f;
    g->region = (ps_crowd_rect_t){0.35f, 0, 1, 0};
    g->goal = PS_CROWD_GOAL_DIRECTION;
    g->speed_m_s = 0.0f;
    g->goal_xy[0] = 1.0f;
    c.n_events = 1;
    c.events[0] = (ps_crowd_event_cfg_t){.t_s = 0, .duration_s = 100, .kind = PS_CROWD_EVENT_PUSH, .group = "g", .agent = 0, .force_n = {(float)f, 0, 0}};
    ps_plant_t *p = make_plant(&c, -5, -5, 1);
    const mjModel *m = ps_plant_model(p);
    const int ta = mj_name2id(m, mjOBJ_BODY, "agent0_torso"), tb = mj_name2id(m, mjOBJ_BODY, "agent1_torso");
    for (int i = 0; i < 6; i++) {
        run_s(p, 0.5);
        {
            const mjData *d = ps_plant_data(p);
            for (int q = 0; q < d->ncon; q++) {
                const mjContact *cc = &d->contact[q];
                mjtNum f6[6];
                mj_contactForce(m, d, q, f6);
                printf("  con %s-%s dist %.5f fn %.1f pos %.3f %.3f %.3f n %.2f %.2f %.2f\n", mj_id2name(m, mjOBJ_GEOM, cc->geom1), mj_id2name(m, mjOBJ_GEOM, cc->geom2), cc->dist, f6[0], cc->pos[0], cc->pos[1], cc->pos[2], cc->frame[0], cc->frame[1], cc->frame[2]);
            }
        }
        printf("K=%g F=%g t=%.1f depth=%.5f expect %.5f tilt %.3f %.3f\n", k, f, 0.5*(i+1), pair_depth(p, ta, tb), f / k, agent(p,0).tilt_rad, agent(p,1).tilt_rad);
    }
    ps_plant_destroy(p);
}

static void test_explore(void **state)
{
    (void)state;
    explore_compression(1.2e5, 200);
    explore_compression(3e4, 200);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_crowd_free_walker_reaches_free_speed),
        cmocka_unit_test(test_explore),
    };
    return cmocka_run_group_tests(tests, setup_robot, NULL);
}
