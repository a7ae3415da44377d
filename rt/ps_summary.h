/*
 * ps_summary: the end-of-run summary, printed for people and written as JSON
 * (cJSON) for tools: ticks, overruns, latency percentiles per stage, state
 * transitions, allocations and page faults after init, bus loads planned and
 * observed, fall detected, and the simulation's ground truth when there is one.
 *
 * Threads: main thread, after the loop has stopped. Allocation: yes (NON-RT).
 */
#ifndef PS_SUMMARY_H
#define PS_SUMMARY_H

#include <stdbool.h>
#include <stdio.h>

#include "../policy/ps_mlp_policy.h"
#include "ps_guard.h"
#include "ps_logger.h"
#include "ps_loop.h"
#include "ps_recorder.h"

#define PS_SUMMARY_MAX_PARTS 32u

/** What the simulated crowd did (board sim with a crowd scenario). */
typedef struct {
    unsigned n_agents, n_fallen;
    unsigned long long n_steps_taken; /**< agents' reflex steps */
    double local_density_m2;          /**< around the robot at the end */
    double local_density_max_m2;
    double robot_force_max_n; /**< largest total crowd force on the robot */
    double transmitted_impulse_ns;
    double penetration_max_m;
    unsigned n_parts;
    const char (*part_name)[32];
    const double *part_force_max_n;
    const double *part_impulse_ns;
} ps_summary_crowd_t;

/** The controller in the policy slot; for the trained policy, its counters:
 *  how often its fallback (the capture-point controller) took over and why. */
typedef struct {
    const char *name;           /**< "stand", "capture", "mlp"; NULL: not reported */
    const char *weights_path;   /**< "mlp": its policy file; NULL otherwise */
    const ps_mlp_policy_t *mlp; /**< "mlp": the policy (its counters); NULL otherwise */
    int64_t start_ns;           /**< the run's start on the loop clock (takeover times) */
} ps_summary_policy_t;

typedef struct {
    const char *board_path, *robot_path, *scenario_path;
    bool is_lockstep;
    double loop_s; /**< loop time covered */
    double wall_s; /**< wall time the loop ran */
    const ps_loop_t *loop;
    ps_summary_policy_t policy;
    const ps_logger_t *logger;
    ps_guard_counts_t guard; /**< counted on the loop thread after init */
    bool is_guard_exact;     /**< false under TSan (allocations and locks not counted) */
    unsigned rt_missing;     /**< ps_rt_missing_t bits */
    const ps_canbus_plan_t *plan;
    const ps_board_cfg_t *board;
    ps_can_state_t bus_states[PS_MAX_BUSES];
    unsigned priority; /**< SCHED_FIFO priority asked for (0: none) */
    int loop_cpu;      /**< CPU asked for (-1: none) */
    int64_t period_ns;
    bool is_profile;    /**< add the "profile" object (pushstep profile) */
    const char *stress; /**< profile: stress-ng load kind, NULL: none */
    unsigned hist_us;   /**< profile: wake-up histogram buckets */
    bool has_truth;     /**< simulation ground truth below is valid */
    bool truth_fell_while_active;
    double truth_first_fall_t_s; /**< plant's first fall since start, -1: none */
    double truth_min_com_height_active_m;
    uint64_t truth_cmd_out_of_limits;
    uint64_t truth_plant_overruns;
    double truth_plant_max_lag_ms;      /**< real time: simulated time behind the wall clock */
    int truth_plant_err;                /**< 0, or the plant's first step error */
    const char *truth_plant_err_reason; /**< why, NULL: none */
    double truth_plant_err_t_s;         /**< simulated time of it since start */
    bool has_crowd;                     /**< crowd below is valid */
    ps_summary_crowd_t crowd;
    const ps_recorder_stats_t *recorder; /**< flight recorder's account; NULL: not recording */
    double truth_heading_dev_deg;        /**< largest heading change of the base */
    double truth_foot_slide_m;           /**< feet's travel while carrying weight */
    double truth_kinetic_max_j;          /**< largest kinetic energy */
} ps_summary_t;

/** @return 0 | -EIO (err says why)  @rt NON-RT */
int ps_summary_write_json(const ps_summary_t *s, const char *path, char *err, size_t err_len);

/** Human-readable summary.  @rt NON-RT */
void ps_summary_print(const ps_summary_t *s, FILE *out);

#endif /* PS_SUMMARY_H */
