#include "ps_summary.h"

#include <cjson/cJSON.h>
#include <errno.h>
#include <string.h>

#include "ps_config.h"
#include "ps_err.h"
#include "ps_rtsetup.h"

static const double QUANTILES[] = {0.5, 0.9, 0.99, 0.999};
static const char *const QUANTILE_KEYS[] = {"p50_us", "p90_us", "p99_us", "p999_us"};

static cJSON *stage_json(const ps_perf_hist_t *h)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "n", (double)h->n);
    cJSON_AddNumberToObject(o, "min_us", h->n ? (double)h->min_ns * 1e-3 : 0.0);
    cJSON_AddNumberToObject(o, "avg_us", ps_perf_mean_ns(h) * 1e-3);
    for (size_t i = 0; i < sizeof(QUANTILES) / sizeof(QUANTILES[0]); i++)
        cJSON_AddNumberToObject(o, QUANTILE_KEYS[i],
                                (double)ps_perf_quantile_ns(h, QUANTILES[i]) * 1e-3);
    cJSON_AddNumberToObject(o, "max_us", (double)h->max_ns * 1e-3);
    return o;
}

static cJSON *transitions_json(const ps_logger_t *lg)
{
    cJSON *a = cJSON_CreateArray();
    uint32_t n = lg->n_transitions < PS_LOGGER_MAX_TRANSITIONS ? lg->n_transitions
                                                               : PS_LOGGER_MAX_TRANSITIONS;
    for (uint32_t i = 0; i < n; i++) {
        const ps_logger_transition_t *t = &lg->transitions[i];
        char cond[160];
        ps_logger_format_cond(t->cond, cond, sizeof(cond));
        cJSON *o = cJSON_CreateObject();
        cJSON_AddNumberToObject(o, "t_s", t->t_s);
        cJSON_AddStringToObject(o, "from", ps_sm_state_name((ps_sm_state_t)t->from));
        cJSON_AddStringToObject(o, "to", ps_sm_state_name((ps_sm_state_t)t->to));
        cJSON_AddStringToObject(o, "conditions", cond);
        cJSON_AddItemToArray(a, o);
    }
    return a;
}

static const char *bus_mode_name(ps_can_bus_mode_t m)
{
    static const char *const NAMES[] = {"error-active", "error-warning", "error-passive",
                                        "bus-off"};
    return (unsigned)m < sizeof(NAMES) / sizeof(NAMES[0]) ? NAMES[m] : "?";
}

static cJSON *buses_json(const ps_summary_t *s)
{
    cJSON *a = cJSON_CreateArray();
    for (uint32_t b = 0; b < s->board->n_buses; b++) {
        cJSON *o = cJSON_CreateObject();
        cJSON_AddStringToObject(o, "name", s->board->buses[b].ifname);
        cJSON_AddNumberToObject(o, "bitrate", s->board->buses[b].bitrate);
        cJSON_AddNumberToObject(o, "planned_peak_tick_load", s->plan->load_peak[b]);
        cJSON_AddNumberToObject(o, "planned_avg_load", s->plan->load_avg[b]);
        cJSON_AddNumberToObject(o, "observed_load", s->bus_states[b].load);
        cJSON_AddNumberToObject(o, "tx_frames", (double)s->bus_states[b].n_tx_frames);
        cJSON_AddNumberToObject(o, "rx_frames", (double)s->bus_states[b].n_rx_frames);
        cJSON_AddNumberToObject(o, "late_frames", (double)s->bus_states[b].n_late);
        cJSON_AddNumberToObject(
            o, "dropped_frames",
            (double)(s->bus_states[b].n_tx_dropped + s->bus_states[b].n_rx_dropped));
        /* the controller's own reports (SocketCAN error frames; 0 on the sim) */
        const ps_can_state_t *st = &s->bus_states[b];
        cJSON_AddStringToObject(o, "mode", bus_mode_name(st->mode));
        cJSON_AddNumberToObject(o, "tx_error_count", st->tx_error_count);
        cJSON_AddNumberToObject(o, "rx_error_count", st->rx_error_count);
        cJSON_AddNumberToObject(o, "error_frames", (double)st->n_err_frames);
        cJSON_AddNumberToObject(o, "bus_off", (double)st->n_bus_off);
        cJSON_AddNumberToObject(o, "restarts", (double)st->n_restarts);
        cJSON_AddNumberToObject(o, "protocol_errors", (double)st->n_prot_errors);
        cJSON_AddNumberToObject(o, "no_ack", (double)st->n_no_ack);
        cJSON_AddNumberToObject(o, "tx_saturated", (double)st->n_tx_saturated);
        cJSON_AddItemToArray(a, o);
    }
    return a;
}

static cJSON *counters_json(const ps_loop_counters_t *c)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "policy_runs", (double)c->n_policy_runs);
    cJSON_AddNumberToObject(o, "policy_late", (double)c->n_policy_late);
    cJSON_AddNumberToObject(o, "rx_frames", (double)c->n_rx_frames);
    cJSON_AddNumberToObject(o, "rx_unknown", (double)c->n_rx_unknown);
    cJSON_AddNumberToObject(o, "rx_bad", (double)c->n_rx_bad);
    cJSON_AddNumberToObject(o, "rx_capped_ticks", (double)c->n_rx_capped);
    cJSON_AddNumberToObject(o, "imu_rejected", (double)c->n_imu_rejected);
    cJSON_AddNumberToObject(o, "imu_repeated", (double)c->n_imu_repeated);
    cJSON_AddNumberToObject(o, "tx_frames", (double)c->n_tx_frames);
    cJSON_AddNumberToObject(o, "tx_refused", (double)c->n_tx_refused);
    cJSON_AddNumberToObject(o, "bus_errors", (double)c->n_bus_errors);
    cJSON_AddNumberToObject(o, "gpio_errors", (double)c->n_gpio_errors);
    cJSON_AddNumberToObject(o, "target_invalid", (double)c->n_target_invalid);
    cJSON_AddNumberToObject(o, "commands_replaced", (double)c->n_cmd_replaced);
    cJSON_AddNumberToObject(o, "requests_refused", (double)c->n_refused);
    cJSON_AddNumberToObject(o, "records_dropped", (double)c->n_ring_dropped);
    return o;
}

/* The conditions the figures were taken under: what was asked and what the
 * system granted. */
static cJSON *rt_json(const ps_summary_t *s)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "period_us", (double)s->period_ns * 1e-3);
    cJSON_AddNumberToObject(o, "priority", s->priority);
    cJSON_AddNumberToObject(o, "loop_cpu", s->loop_cpu);
    cJSON_AddBoolToObject(
        o, "is_fifo", !s->is_lockstep && s->priority > 0 && !(s->rt_missing & PS_RT_MISSING_FIFO));
    cJSON_AddBoolToObject(o, "is_mlocked", !(s->rt_missing & PS_RT_MISSING_MLOCK));
    cJSON_AddBoolToObject(o, "is_cpu_latency_held",
                          !s->is_lockstep && !(s->rt_missing & PS_RT_MISSING_CPU_LATENCY));
    cJSON_AddBoolToObject(o, "is_pinned",
                          !s->is_lockstep && s->loop_cpu >= 0 &&
                              !(s->rt_missing & PS_RT_MISSING_AFFINITY));
    return o;
}

static cJSON *summary_json(const ps_summary_t *s)
{
    const ps_loop_t *loop = s->loop;
    cJSON *root = cJSON_CreateObject();
    cJSON_AddStringToObject(root, "board", s->board_path);
    cJSON_AddStringToObject(root, "robot", s->robot_path);
    cJSON_AddStringToObject(root, "scenario", s->scenario_path ? s->scenario_path : "");
    cJSON_AddStringToObject(root, "mode", s->is_lockstep ? "lockstep" : "realtime");
    cJSON_AddNumberToObject(root, "loop_s", s->loop_s);
    cJSON_AddNumberToObject(root, "wall_s", s->wall_s);
    cJSON_AddNumberToObject(root, "ticks", (double)loop->counters.n_ticks);
    cJSON_AddNumberToObject(root, "overruns", (double)loop->pacer.n_overruns);
    cJSON_AddNumberToObject(root, "missed_deadlines", (double)loop->pacer.n_missed);
    cJSON_AddStringToObject(root, "final_state", ps_sm_state_name(loop->state));
    cJSON *stages = cJSON_AddObjectToObject(root, "latency");
    for (int st = 0; st < PS_STAGE_COUNT; st++)
        cJSON_AddItemToObject(stages, ps_loop_stage_name((ps_stage_t)st),
                              stage_json(&loop->perf[st]));
    cJSON_AddItemToObject(root, "transitions", transitions_json(s->logger));
    cJSON *after = cJSON_AddObjectToObject(root, "after_init");
    cJSON_AddNumberToObject(after, "mallocs", (double)s->guard.n_allocs);
    cJSON_AddNumberToObject(after, "frees", (double)s->guard.n_frees);
    cJSON_AddNumberToObject(after, "page_faults", (double)s->guard.n_faults);
    cJSON_AddNumberToObject(after, "locks", (double)s->guard.n_locks);
    cJSON_AddBoolToObject(after, "allocations_counted", s->is_guard_exact);
    char rt[200];
    ps_rtsetup_describe(s->rt_missing, rt, sizeof(rt));
    cJSON_AddStringToObject(root, "rt_missing", rt);
    cJSON_AddItemToObject(root, "rt", rt_json(s));
    if (s->is_profile) {
        cJSON *p = rt_json(s);
        if (s->stress != NULL)
            cJSON_AddStringToObject(p, "stress", s->stress);
        else
            cJSON_AddNullToObject(p, "stress");
        cJSON_AddNumberToObject(p, "hist_us", s->hist_us);
        cJSON_AddItemToObject(root, "profile", p);
    }
    cJSON_AddItemToObject(root, "buses", buses_json(s));
    cJSON_AddItemToObject(root, "counters", counters_json(&loop->counters));
    cJSON_AddBoolToObject(root, "fall_detected", loop->counters.has_fallen);
    if (s->has_truth) {
        cJSON *sim = cJSON_AddObjectToObject(root, "sim_truth");
        cJSON_AddBoolToObject(sim, "fell_while_active", s->truth_fell_while_active);
        cJSON_AddNumberToObject(sim, "first_fall_t_s", s->truth_first_fall_t_s);
        cJSON_AddNumberToObject(sim, "min_com_height_active_m", s->truth_min_com_height_active_m);
        cJSON_AddNumberToObject(sim, "commands_out_of_limits", (double)s->truth_cmd_out_of_limits);
        cJSON_AddNumberToObject(sim, "plant_overruns", (double)s->truth_plant_overruns);
        cJSON_AddNumberToObject(sim, "plant_max_lag_ms", s->truth_plant_max_lag_ms);
        cJSON_AddNumberToObject(sim, "heading_dev_deg", s->truth_heading_dev_deg);
        cJSON_AddNumberToObject(sim, "foot_slide_m", s->truth_foot_slide_m);
        cJSON_AddNumberToObject(sim, "kinetic_energy_j", s->truth_kinetic_max_j);
        cJSON_AddBoolToObject(sim, "fell_behind_real_time",
                              s->truth_plant_overruns > 0 || s->truth_plant_max_lag_ms > 0);
        if (s->truth_plant_err != 0) {
            cJSON_AddStringToObject(sim, "plant_error",
                                    s->truth_plant_err_reason ? s->truth_plant_err_reason
                                                              : ps_strerror(s->truth_plant_err));
            cJSON_AddNumberToObject(sim, "plant_error_t_s", s->truth_plant_err_t_s);
        } else {
            cJSON_AddNullToObject(sim, "plant_error");
        }
    }
    return root;
}

int ps_summary_write_json(const ps_summary_t *s, const char *path, char *err, size_t err_len)
{
    cJSON *root = summary_json(s);
    char *text = root ? cJSON_Print(root) : NULL;
    cJSON_Delete(root);
    if (text == NULL) {
        snprintf(err, err_len, "summary: out of memory building JSON");
        return -ENOMEM;
    }
    FILE *f = fopen(path, "w");
    int rc = 0;
    if (f == NULL || fputs(text, f) < 0 || fputc('\n', f) < 0) {
        rc = -errno;
        snprintf(err, err_len, "summary: cannot write %s: %s", path, strerror(errno));
    }
    if (f != NULL && fclose(f) != 0 && rc == 0) {
        rc = -errno;
        snprintf(err, err_len, "summary: cannot write %s: %s", path, strerror(errno));
    }
    cJSON_free(text);
    return rc;
}

static void print_stage(FILE *out, const char *name, const ps_perf_hist_t *h)
{
    fprintf(out,
            "  %-9s n=%-8llu min=%7.1f avg=%7.1f p50=%7.1f p99=%7.1f p99.9=%7.1f max=%7.1f us\n",
            name, (unsigned long long)h->n, h->n ? (double)h->min_ns * 1e-3 : 0.0,
            ps_perf_mean_ns(h) * 1e-3, (double)ps_perf_quantile_ns(h, 0.5) * 1e-3,
            (double)ps_perf_quantile_ns(h, 0.99) * 1e-3,
            (double)ps_perf_quantile_ns(h, 0.999) * 1e-3, (double)h->max_ns * 1e-3);
}

void ps_summary_print(const ps_summary_t *s, FILE *out)
{
    const ps_loop_t *loop = s->loop;
    fprintf(out, "\n== summary (%s) ==\n", s->is_lockstep ? "lockstep" : "real time");
    fprintf(out,
            "  loop time %.2f s in %.2f s wall (%.1fx), %llu ticks, %llu overruns "
            "(%llu deadlines missed), final state %s\n",
            s->loop_s, s->wall_s, s->wall_s > 0 ? s->loop_s / s->wall_s : 0.0,
            (unsigned long long)loop->counters.n_ticks, (unsigned long long)loop->pacer.n_overruns,
            (unsigned long long)loop->pacer.n_missed, ps_sm_state_name(loop->state));
    fprintf(out, " latency per stage:\n");
    for (int st = 0; st < PS_STAGE_COUNT; st++)
        print_stage(out, ps_loop_stage_name((ps_stage_t)st), &loop->perf[st]);
    fprintf(out, " buses:\n");
    for (uint32_t b = 0; b < s->board->n_buses; b++) {
        const ps_can_state_t *st = &s->bus_states[b];
        fprintf(out, "  %-6s planned peak %5.1f%% avg %5.1f%%, observed %5.1f%%, late %llu\n",
                s->board->buses[b].ifname, s->plan->load_peak[b] * 100, s->plan->load_avg[b] * 100,
                st->load * 100, (unsigned long long)st->n_late);
        if (st->n_err_frames || st->n_tx_saturated || st->n_tx_dropped || st->n_rx_dropped ||
            st->mode != PS_CAN_BUS_ERROR_ACTIVE)
            fprintf(out,
                    "         %s, TEC %u REC %u, %llu error reports (%llu bus-off, %llu "
                    "restarts, %llu protocol, %llu no ACK), queue full %llu times (%llu frames "
                    "dropped), %llu received frames lost\n",
                    bus_mode_name(st->mode), st->tx_error_count, st->rx_error_count,
                    (unsigned long long)st->n_err_frames, (unsigned long long)st->n_bus_off,
                    (unsigned long long)st->n_restarts, (unsigned long long)st->n_prot_errors,
                    (unsigned long long)st->n_no_ack, (unsigned long long)st->n_tx_saturated,
                    (unsigned long long)st->n_tx_dropped, (unsigned long long)st->n_rx_dropped);
    }
    fprintf(out,
            " after init on the loop thread: %llu mallocs%s, %llu frees, %llu page faults, "
            "%llu locks%s\n",
            (unsigned long long)s->guard.n_allocs, s->is_guard_exact ? "" : " (not counted)",
            (unsigned long long)s->guard.n_frees, (unsigned long long)s->guard.n_faults,
            (unsigned long long)s->guard.n_locks, s->is_guard_exact ? "" : " (not counted)");
    const ps_loop_counters_t *c = &loop->counters;
    fprintf(out,
            " policy runs %llu (late %llu), transitions %llu, requests refused %llu, "
            "commands replaced %llu\n rx bad %llu, unknown %llu, capped ticks %llu; IMU samples "
            "rejected %llu, repeated %llu\n",
            (unsigned long long)c->n_policy_runs, (unsigned long long)c->n_policy_late,
            (unsigned long long)c->n_transitions, (unsigned long long)c->n_refused,
            (unsigned long long)c->n_cmd_replaced, (unsigned long long)c->n_rx_bad,
            (unsigned long long)c->n_rx_unknown, (unsigned long long)c->n_rx_capped,
            (unsigned long long)c->n_imu_rejected, (unsigned long long)c->n_imu_repeated);
    fprintf(out, " fall detected: %s\n", loop->counters.has_fallen ? "yes" : "no");
    if (s->has_truth)
        fprintf(out,
                " sim truth: fell while active %s, min CoM height while active %.3f m, "
                "commands out of limits %llu, plant overruns %llu\n",
                s->truth_fell_while_active ? "yes" : "no", s->truth_min_com_height_active_m,
                (unsigned long long)s->truth_cmd_out_of_limits,
                (unsigned long long)s->truth_plant_overruns);
    if (s->has_truth && (s->truth_plant_overruns > 0 || s->truth_plant_max_lag_ms > 0))
        fprintf(out,
                " WARNING: the simulation fell behind real time: %llu plant periods skipped, "
                "simulated time up to %.1f ms behind the wall clock (device timestamps follow "
                "the wall clock; the run is not faithful)\n",
                (unsigned long long)s->truth_plant_overruns, s->truth_plant_max_lag_ms);
    if (s->has_truth && s->truth_plant_err != 0)
        fprintf(out, " sim truth: PLANT ERROR at t=%.4f s, physics stopped: %s\n",
                s->truth_plant_err_t_s,
                s->truth_plant_err_reason ? s->truth_plant_err_reason
                                          : ps_strerror(s->truth_plant_err));
}
