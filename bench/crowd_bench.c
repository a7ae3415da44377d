/*
 * crowd_bench: the simulated crowd's cost (make bench, bench/crowd.sh).
 * For N agents pressed around the robot (they walk toward it in a walled
 * pen, 4 persons/m^2), after 1 s of settling it runs S simulated seconds of
 * the plant (robot limp on its harness, crowd forces, decisions and
 * measurements), and before each plant step the bare mj_step of the same
 * generated model from a copy of the same state (the crowd's last forces
 * held): the two interleaved, so both see the same load. Times in wall and
 * in thread CPU time (what one core spends). MuJoCo's stage timers come from
 * a separate pass of bare steps afterwards: they read the thread CPU clock,
 * a system call, about twenty times a step, which would slow the timed steps.
 * Prints one JSON object per N. Run from the repository root.
 * Env: CROWD_BENCH_DT (physics step; 0: the robot model's own).
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

/* thread CPU time: what one core spends, whatever else the machine runs */
static double cpu_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static mjtNum timer_us(void)
{
    return 1e6 * cpu_s();
}

#define STAGE_STEPS 500 /* bare steps timed stage by stage */

int main(int argc, char **argv)
{
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
    /* Interleaved, step by step: the bare mj_step from a copy of the
     * plant's state (the forces it applied last step held), then the
     * plant's own step from that same state; both under the same load. */
    mjData *bare = mj_makeData(m);
    if (bare == NULL) {
        fprintf(stderr, "crowd_bench: out of memory\n");
        return 1;
    }
    double wall_plant = 0.0, wall_bare = 0.0, cpu_plant = 0.0, cpu_bare = 0.0;
    for (long i = 0; i < steps; i++) {
        bare->time = d->time;
        mju_copy(bare->qpos, d->qpos, m->nq);
        mju_copy(bare->qvel, d->qvel, m->nv);
        mju_copy(bare->act, d->act, m->na);
        mju_copy(bare->ctrl, d->ctrl, m->nu);
        mju_copy(bare->qacc_warmstart, d->qacc_warmstart, m->nv);
        mju_copy(bare->qfrc_applied, d->qfrc_applied, m->nv);
        mju_copy(bare->xfrc_applied, d->xfrc_applied, 6 * m->nbody);
        mju_copy(bare->mocap_pos, d->mocap_pos, 3 * m->nmocap);
        mju_copy(bare->mocap_quat, d->mocap_quat, 4 * m->nmocap);
        double w0 = now_s(), k0 = cpu_s();
        mj_step(m, bare);
        double w1 = now_s(), k1 = cpu_s();
        wall_bare += w1 - w0;
        cpu_bare += k1 - k0;
        if (ps_plant_step(p) != 0) {
            fprintf(stderr, "crowd_bench: %s\n", ps_plant_error_reason(p));
            return 1;
        }
        wall_plant += now_s() - w1;
        cpu_plant += cpu_s() - k1;
        ncon += d->ncon;
        nefc += d->nefc;
    }
    ps_plant_get_timing(p, &c1, &m1);
    /* the stage timers: bare steps on from the plant's last state */
    mjcb_time = timer_us;
    for (int k = 0; k < mjNTIMER; k++)
        bare->timer[k].duration = bare->timer[k].number = 0;
    for (int i = 0; i < STAGE_STEPS; i++)
        mj_step(m, bare);
    mjcb_time = NULL;
    ps_crowd_stats_t st;
    memset(&st, 0, sizeof(st));
    if (ps_plant_crowd(p) != NULL)
        ps_crowd_get_stats(ps_plant_crowd(p), &st);
    /* MuJoCo's own stage timers (thread CPU time) of the bare steps */
    static const int STAGES[] = {mjTIMER_POS_KINEMATICS, mjTIMER_POS_INERTIA,
                                 mjTIMER_POS_COLLISION,  mjTIMER_POS_MAKE,
                                 mjTIMER_POS_PROJECT,    mjTIMER_VELOCITY,
                                 mjTIMER_ACTUATION,      mjTIMER_ACCELERATION,
                                 mjTIMER_CONSTRAINT};
    static const char *const STAGE_NAMES[] = {"kinematics", "inertia",  "collision",
                                              "make_constraint", "project", "velocity",
                                              "actuation",  "acceleration", "solver"};
    char stages[512] = "";
    size_t used = 0;
    for (size_t k = 0; k < sizeof(STAGES) / sizeof(STAGES[0]); k++) {
        const mjTimerStat *ts = &bare->timer[STAGES[k]];
        const int w = snprintf(stages + used, sizeof(stages) - used, "%s\"%s\": %.1f",
                               k > 0 ? ", " : "", STAGE_NAMES[k],
                               ts->number > 0 ? ts->duration / ts->number : 0.0);
        used += w > 0 ? (size_t)w : 0u;
    }
    printf("{\"agents\": %u, \"timestep_s\": %g, \"sim_s\": %g, \"nv\": %d, \"nbody\": %d, "
           "\"ncon_mean\": %.1f, \"nefc_mean\": %.1f, "
           "\"plant_rtf_wall\": %.3f, \"bare_rtf_wall\": %.3f, "
           "\"plant_rtf_cpu\": %.3f, \"bare_rtf_cpu\": %.3f, "
           "\"plant_us_per_step_cpu\": %.1f, \"bare_us_per_step_cpu\": %.1f, "
           "\"crowd_us_per_step\": %.2f, \"mj_step_us_per_step\": %.1f, "
           "\"crowd_share_of_mj_step\": %.4f, \"plant_over_bare_cpu\": %.4f, "
           "\"robot_force_n\": %.1f, "
           "\"local_density_m2\": %.2f, \"mujoco_stage_us_cpu\": {%s}}\n",
           n, dt, sim_s, m->nv, m->nbody, (double)ncon / steps, (double)nefc / steps,
           sim_s / wall_plant, sim_s / wall_bare, sim_s / cpu_plant, sim_s / cpu_bare,
           1e6 * cpu_plant / steps, 1e6 * cpu_bare / steps, 1e-3 * (double)(c1 - c0) / steps,
           1e-3 * (double)(m1 - m0) / steps, (double)(c1 - c0) / (double)(m1 - m0),
           cpu_plant / cpu_bare, st.robot_force_n, st.local_density_m2, stages);
    mj_deleteData(bare);
    ps_plant_destroy(p);
    return 0;
}
