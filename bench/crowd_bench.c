/*
 * crowd_bench: the simulated crowd's cost (make bench, bench/crowd.sh).
 * For N agents pressed around the robot (they walk toward it in a walled
 * pen, 4 persons/m^2), after 1 s of settling it runs S simulated seconds of
 * the plant (robot limp on its harness, crowd forces, decisions and
 * measurements) and then, from the same pressed state, the bare mj_step of
 * the same generated model for the same steps (no crowd work: the agents
 * coast). Prints one JSON object per N. Run from the repository root.
 *
 * usage: crowd_bench N [S]
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <mujoco/mujoco.h>

#include "../rt/ps_config.h"
#include "../rt/ps_err.h"
#include "../sim/ps_plant.h"

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static mjtNum timer_us(void)
{
    return 1e6 * now_s();
}

int main(int argc, char **argv)
{
    if (getenv("CROWD_BENCH_TIMERS") != NULL)
        mjcb_time = timer_us;
    if (argc < 2) {
        fprintf(stderr, "usage: crowd_bench N [S]\n");
        return 2;
    }
    const unsigned n = (unsigned)atoi(argv[1]);
    const double sim_s = argc > 2 ? atof(argv[2]) : 2.0;
    static ps_robot_cfg_t robot;
    char err[PS_ERR_MSG_LEN];
    if (ps_config_load_robot("robots/ps1.yaml", &robot, err, sizeof(err)) != 0) {
        fprintf(stderr, "crowd_bench: %s\n", err);
        return 1;
    }
    float stance[PS_MAX_JOINTS];
    for (uint32_t j = 0; j < robot.n_joints; j++)
        stance[j] = robot.servo[j].stance_rad;
    ps_crowd_cfg_t c;
    ps_crowd_default_cfg(&c);
    c.is_enabled = n > 0;
    c.timestep_s = getenv("CROWD_BENCH_DT") != NULL ? (float)atof(getenv("CROWD_BENCH_DT")) : 0.0f;
    c.is_enabled = c.is_enabled || c.timestep_s > 0.0f;
    /* a square pen holding n agents at 4 / m^2 around the robot's clearance */
    const double side = sqrt((n + 2.0) / 4.0) + 0.2;
    c.arena = (ps_crowd_rect_t){(float)(-side / 2), (float)(-side / 2), (float)(side / 2),
                                (float)(side / 2)};
    c.has_arena_walls = true;
    c.measure = c.arena;
    c.robot_a_n = 0.0f;
    c.social.a_n = 100.0f; /* a crush: people press into each other and the robot */
    c.n_groups = n > 0 ? 1u : 0u;
    c.groups[0] = (ps_crowd_group_cfg_t){.name = "press",
                                         .count = n,
                                         .density_m2 = 4.0f,
                                         .region = c.arena,
                                         .goal = PS_CROWD_GOAL_ROBOT,
                                         .speed_m_s = 1.0f,
                                         .height_m = 1.7f,
                                         .height_sd_m = 0.07f,
                                         .mass_kg = 70.0f,
                                         .mass_sd_kg = 10.0f,
                                         .radius_m = 0.17f,
                                         .radius_sd_m = 0.01f,
                                         .clear_m = 0.4f};
    const ps_plant_cfg_t pc = {.model_path = "sim/models/ps1.xml",
                               .n_joints = robot.n_joints,
                               .joint_name = robot.joint_name,
                               .stance_rad = stance,
                               .crowd = &c,
                               .seed = 1};
    ps_plant_t *p = NULL;
    int rc = ps_plant_create(&pc, &p, err, sizeof(err));
    if (rc != 0) {
        fprintf(stderr, "crowd_bench: %s\n", err);
        return 1;
    }
    const double dt = ps_plant_timestep_s(p);
    const long settle = lround(1.0 / dt), steps = lround(sim_s / dt);
    for (long i = 0; i < settle; i++)
        if (ps_plant_step(p) != 0) {
            fprintf(stderr, "crowd_bench: settling: %s\n", ps_plant_error_reason(p));
            return 1;
        }
    int64_t c0, m0, c1, m1;
    ps_plant_get_timing(p, &c0, &m0);
    long ncon = 0, nefc = 0;
    const mjModel *m = ps_plant_model(p);
    const mjData *d = ps_plant_data(p);
    double t0 = now_s();
    for (long i = 0; i < steps; i++) {
        if (ps_plant_step(p) != 0) {
            fprintf(stderr, "crowd_bench: %s\n", ps_plant_error_reason(p));
            return 1;
        }
        ncon += d->ncon;
        nefc += d->nefc;
    }
    const double wall_plant = now_s() - t0;
    ps_plant_get_timing(p, &c1, &m1);
    /* the bare step on the same model from a copy of the pressed state */
    mjData *bare = mj_copyData(NULL, m, d);
    mju_zero(bare->xfrc_applied, 6 * m->nbody);
    mju_zero(bare->qfrc_applied, m->nv);
    t0 = now_s();
    for (long i = 0; i < steps; i++)
        mj_step(m, bare);
    const double wall_bare = now_s() - t0;
    mj_deleteData(bare);
    ps_crowd_stats_t st;
    memset(&st, 0, sizeof(st));
    if (ps_plant_crowd(p) != NULL)
        ps_crowd_get_stats(ps_plant_crowd(p), &st);
    printf("{\"agents\": %u, \"timestep_s\": %g, \"sim_s\": %g, \"nv\": %d, \"ncon_mean\": %.1f, "
           "\"nefc_mean\": %.1f, \"plant_rtf\": %.3f, \"bare_mujoco_rtf\": %.3f, "
           "\"plant_us_per_step\": %.1f, \"bare_us_per_step\": %.1f, \"crowd_us_per_step\": %.2f, "
           "\"mj_step_us_per_step\": %.1f, \"crowd_share_of_mj_step\": %.4f, "
           "\"robot_force_n\": %.1f, \"local_density_m2\": %.2f}\n",
           n, dt, sim_s, m->nv, (double)ncon / steps, (double)nefc / steps, sim_s / wall_plant,
           sim_s / wall_bare, 1e6 * wall_plant / steps, 1e6 * wall_bare / steps,
           1e-3 * (double)(c1 - c0) / steps, 1e-3 * (double)(m1 - m0) / steps,
           (double)(c1 - c0) / (double)(m1 - m0), st.robot_force_n, st.local_density_m2);
    if (mjcb_time != NULL) {
        static const char *const NAMES[] = {"step",     "forward", "inverse",   "position",
                                            "velocity", "actuation", "acceleration", "constraint",
                                            "kinematics", "inertia", "collision", "make",
                                            "project"};
        for (int i = 0; i < 13; i++)
            fprintf(stderr, "%s %.1f us  ", NAMES[i],
                    d->timer[i].number > 0 ? d->timer[i].duration / d->timer[i].number : 0.0);
        fprintf(stderr, "\n");
    }
    ps_plant_destroy(p);
    return 0;
}
