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

static cJSON *crowd_json(const ps_summary_crowd_t *c)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "agents", c->n_agents);
    cJSON_AddNumberToObject(o, "agents_fallen", c->n_fallen);
    cJSON_AddNumberToObject(o, "reflex_steps", (double)c->n_steps_taken);
    cJSON_AddNumberToObject(o, "local_density_m2", c->local_density_m2);
    cJSON_AddNumberToObject(o, "local_density_max_m2", c->local_density_max_m2);
    cJSON_AddNumberToObject(o, "robot_force_max_n", c->robot_force_max_n);
    cJSON_AddNumberToObject(o, "transmitted_impulse_ns", c->transmitted_impulse_ns);
    cJSON_AddNumberToObject(o, "penetration_max_m", c->penetration_max_m);
    cJSON *parts = cJSON_AddArrayToObject(o, "robot_parts");
    for (unsigned i = 0; i < c->n_parts && i < PS_SUMMARY_MAX_PARTS; i++) {
        cJSON *p = cJSON_CreateObject();
        cJSON_AddStringToObject(p, "body", c->part_name[i]);
        cJSON_AddNumberToObject(p, "force_max_n", c->part_force_max_n[i]);
        cJSON_AddNumberToObject(p, "impulse_ns", c->part_impulse_ns[i]);
        cJSON_AddItemToArray(parts, p);
    }
    return o;
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

/* Run time of the fallback's first takeover; one before the first IMU reading
 * (time 0) counts as the run's start. @pre it took over */
static double first_takeover_s(const ps_summary_policy_t *p)
{
    const int64_t t_ns = p->mlp->first_fallback_t_ns;
    return t_ns > p->start_ns ? ps_ns_to_s(t_ns - p->start_ns) : 0.0;
}

/* What the MLP's actions are added to: its contract's action.base. */
static const char *action_base_name(const ps_mlp_policy_t *m)
{
    return m->w->contract.act_base == PS_WEIGHTS_BASE_CAPTURE ? "capture" : "stance";
}

static cJSON *policy_json(const ps_summary_policy_t *p)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "controller", p->name);
    const ps_mlp_policy_t *m = p->mlp;
    if (m == NULL)
        return o;
    cJSON_AddStringToObject(o, "weights", p->weights_path ? p->weights_path : "");
    cJSON_AddStringToObject(o, "action_base", action_base_name(m));
    cJSON_AddNumberToObject(o, "steps", (double)m->n_steps);
    cJSON_AddNumberToObject(o, "fallback_steps", (double)m->n_fallback_steps);
    cJSON *t = cJSON_AddObjectToObject(o, "fallback_takeovers");
    cJSON_AddNumberToObject(t, "observation", (double)m->n_obs_faults);
    cJSON_AddNumberToObject(t, "nan", (double)m->n_nan);
    cJSON_AddNumberToObject(t, "out_of_range", (double)m->n_range);
    cJSON_AddNumberToObject(t, "late", (double)m->n_late);
    if (m->first_fallback_t_ns >= 0)
        cJSON_AddNumberToObject(o, "first_takeover_t_s", first_takeover_s(p));
    else
        cJSON_AddNullToObject(o, "first_takeover_t_s");
    return o;
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
    cJSON_AddNumberToObject(o, "imu_frozen", (double)c->n_imu_frozen);
    cJSON_AddNumberToObject(o, "replies_implausible", (double)c->n_reply_implausible);
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

static cJSON *rec_file_json(const ps_recorder_stats_t *r, const ps_rec_file_stats_t *f)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "path", f->path);
    cJSON_AddNumberToObject(o, "records", (double)f->n_records);
    cJSON_AddNumberToObject(o, "messages", (double)f->n_messages);
    cJSON_AddNumberToObject(o, "bytes", (double)f->n_bytes);
    cJSON_AddNumberToObject(o, "records_lost_ring", (double)f->n_lost_ring);
    cJSON_AddNumberToObject(o, "records_lost_io", (double)f->n_lost_io);
    cJSON_AddNumberToObject(o, "index_bytes", (double)f->n_index_bytes);
    if (f->err != 0)
        cJSON_AddStringToObject(o, "error", strerror(-f->err));
    else
        cJSON_AddNullToObject(o, "error");
    cJSON *ch = cJSON_AddObjectToObject(o, "channel_messages");
    for (uint32_t c = 0; c < r->n_channels; c++)
        if (f->channel_n_messages[c] > 0)
            cJSON_AddNumberToObject(ch, r->channel_topic[c], (double)f->channel_n_messages[c]);
    return o;
}

static void trigger_names(uint32_t bits, char *buf, size_t len)
{
    size_t used = 0;
    buf[0] = '\0';
    for (unsigned i = 0; i < PS_REC_TRIG_COUNT && used + 1 < len; i++)
        if (bits & (1u << i)) {
            int n = snprintf(buf + used, len - used, "%s%s", used ? "|" : "",
                             ps_recorder_trigger_name((ps_rec_trigger_t)(1u << i)));
            used += n > 0 && (size_t)n < len - used ? (size_t)n : 0u;
        }
}

static cJSON *recorder_json(const ps_recorder_stats_t *r, bool has_cont)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "ring_slots", r->n_slots);
    cJSON_AddNumberToObject(o, "records_pushed", (double)r->n_pushed);
    cJSON_AddNumberToObject(o, "bytes_written", (double)r->bytes_total);
    uint64_t lost = r->cont.n_lost_ring + r->cont.n_lost_io;
    for (uint32_t i = 0; i < r->n_dumps && i < PS_REC_MAX_DUMP_STATS; i++)
        lost += r->dump[i].n_lost_ring + r->dump[i].n_lost_io;
    cJSON_AddNumberToObject(o, "records_lost", (double)lost);
    cJSON *topics = cJSON_AddArrayToObject(o, "channels");
    for (uint32_t c = 0; c < r->n_channels; c++)
        cJSON_AddItemToArray(topics, cJSON_CreateString(r->channel_topic[c]));
    cJSON_AddNumberToObject(o, "triggers", r->n_triggers);
    cJSON *by = cJSON_AddObjectToObject(o, "triggers_by");
    for (unsigned i = 0; i < PS_REC_TRIG_COUNT; i++)
        cJSON_AddNumberToObject(by, ps_recorder_trigger_name((ps_rec_trigger_t)(1u << i)),
                                r->n_triggers_by[i]);
    if (has_cont)
        cJSON_AddItemToObject(o, "continuous", rec_file_json(r, &r->cont));
    else
        cJSON_AddNullToObject(o, "continuous");
    cJSON *fl = cJSON_AddObjectToObject(o, "flight");
    cJSON_AddNumberToObject(fl, "dumps", r->n_dumps);
    cJSON_AddNumberToObject(fl, "dumps_failed", r->n_dumps_failed);
    cJSON *files = cJSON_AddArrayToObject(fl, "files");
    for (uint32_t i = 0; i < r->n_dumps && i < PS_REC_MAX_DUMP_STATS; i++) {
        cJSON *f = rec_file_json(r, &r->dump[i]);
        char causes[80];
        trigger_names(r->dump[i].triggers, causes, sizeof(causes));
        cJSON_AddStringToObject(f, "trigger", causes);
        cJSON_AddNumberToObject(f, "trigger_record", (double)r->dump[i].trigger_tick);
        cJSON_AddItemToArray(files, f);
    }
    return o;
}

/* Lockstep runs on simulated time, but judges an overrunning tick and a late
 * policy step on the loop thread's CPU time (rt/ps_loop.h): either changes what
 * the robot does (a hold, the fallback taking over), and on a loaded machine (a
 * VM without steal accounting) time taken from the thread counts as its own.
 * A lockstep run with neither is a function of its inputs alone. */
static bool is_deterministic(const ps_summary_t *s)
{
    return s->is_lockstep && s->loop->pacer.n_overruns == 0 && s->loop->counters.n_policy_late == 0;
}

static cJSON *summary_json(const ps_summary_t *s)
{
    const ps_loop_t *loop = s->loop;
    cJSON *root = cJSON_CreateObject();
    cJSON_AddStringToObject(root, "board", s->board_path);
    cJSON_AddStringToObject(root, "robot", s->robot_path);
    cJSON_AddStringToObject(root, "scenario", s->scenario_path ? s->scenario_path : "");
    cJSON_AddStringToObject(root, "mode", s->is_lockstep ? "lockstep" : "realtime");
    cJSON_AddBoolToObject(root, "deterministic", is_deterministic(s));
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
    if (s->policy.name != NULL)
        cJSON_AddItemToObject(root, "policy", policy_json(&s->policy));
    cJSON_AddBoolToObject(root, "fall_detected", loop->counters.has_fallen);
    if (s->recorder != NULL)
        cJSON_AddItemToObject(root, "recorder",
                              recorder_json(s->recorder, s->recorder->cont.path[0] != '\0'));
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
    if (s->has_crowd)
        cJSON_AddItemToObject(root, "crowd", crowd_json(&s->crowd));
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

static void print_rec_file(const char *what, const ps_rec_file_stats_t *f, FILE *out)
{
    fprintf(out, "  %s %s: %llu records, %llu messages, %.1f kB", what, f->path,
            (unsigned long long)f->n_records, (unsigned long long)f->n_messages,
            (double)f->n_bytes / 1000.0);
    if (f->n_lost_ring > 0 || f->n_lost_io > 0 || f->err != 0)
        fprintf(out,
                "; LOST %llu records (%llu overwritten before the writer read them, %llu "
                "not written%s%s)",
                (unsigned long long)(f->n_lost_ring + f->n_lost_io),
                (unsigned long long)f->n_lost_ring, (unsigned long long)f->n_lost_io,
                f->err ? ": " : "", f->err ? strerror(-f->err) : "");
    fprintf(out, "\n");
}

static void print_recorder(const ps_recorder_stats_t *r, FILE *out)
{
    fprintf(out, " recorder: %llu records into a ring of %u, %u triggers",
            (unsigned long long)r->n_pushed, r->n_slots, r->n_triggers);
    for (unsigned i = 0; i < PS_REC_TRIG_COUNT; i++)
        if (r->n_triggers_by[i] > 0)
            fprintf(out, " %s=%u", ps_recorder_trigger_name((ps_rec_trigger_t)(1u << i)),
                    r->n_triggers_by[i]);
    fprintf(out, ", %u flight dumps (%u failed)\n", r->n_dumps, r->n_dumps_failed);
    if (r->cont.path[0] != '\0')
        print_rec_file("continuous", &r->cont, out);
    for (uint32_t i = 0; i < r->n_dumps && i < PS_REC_MAX_DUMP_STATS; i++) {
        char what[96], causes[80];
        trigger_names(r->dump[i].triggers, causes, sizeof(causes));
        snprintf(what, sizeof(what), "flight (%s)", causes);
        print_rec_file(what, &r->dump[i], out);
    }
}

/* " controller mlp (FILE[, a residual on capture]): fallback in charge N of M
 * steps; it took over after N bad observations, ..., N late steps[, first at
 * T s]" */
static void print_policy(const ps_summary_policy_t *p, FILE *out)
{
    if (p->name == NULL)
        return;
    const ps_mlp_policy_t *m = p->mlp;
    if (m == NULL) {
        fprintf(out, " controller %s\n", p->name);
        return;
    }
    fprintf(out,
            " controller %s (%s%s): fallback in charge %llu of %llu steps; it took over after "
            "%llu bad observations, %llu NaN actions, %llu actions out of range, %llu late "
            "steps",
            p->name, p->weights_path ? p->weights_path : "?",
            m->w->contract.act_base == PS_WEIGHTS_BASE_CAPTURE ? ", a residual on capture" : "",
            (unsigned long long)m->n_fallback_steps, (unsigned long long)m->n_steps,
            (unsigned long long)m->n_obs_faults, (unsigned long long)m->n_nan,
            (unsigned long long)m->n_range, (unsigned long long)m->n_late);
    if (m->first_fallback_t_ns >= 0)
        fprintf(out, ", first at %.3f s", first_takeover_s(p));
    fprintf(out, "\n");
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
    if (s->is_lockstep && !is_deterministic(s))
        fprintf(out,
                "  not deterministic: %llu overruns and %llu late policy steps on this "
                "machine's CPU time (a loaded host?); a rerun may differ\n",
                (unsigned long long)loop->pacer.n_overruns,
                (unsigned long long)loop->counters.n_policy_late);
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
            "rejected %llu, repeated %llu, frozen %llu; replies implausible %llu\n",
            (unsigned long long)c->n_policy_runs, (unsigned long long)c->n_policy_late,
            (unsigned long long)c->n_transitions, (unsigned long long)c->n_refused,
            (unsigned long long)c->n_cmd_replaced, (unsigned long long)c->n_rx_bad,
            (unsigned long long)c->n_rx_unknown, (unsigned long long)c->n_rx_capped,
            (unsigned long long)c->n_imu_rejected, (unsigned long long)c->n_imu_repeated,
            (unsigned long long)c->n_imu_frozen, (unsigned long long)c->n_reply_implausible);
    print_policy(&s->policy, out);
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
    if (s->has_crowd) {
        const ps_summary_crowd_t *cr = &s->crowd;
        unsigned top = 0;
        for (unsigned i = 1; i < cr->n_parts; i++)
            top = cr->part_force_max_n[i] > cr->part_force_max_n[top] ? i : top;
        fprintf(out,
                " crowd: %u agents, %u fell, %llu reflex steps; around the robot %.2f / m^2 "
                "(max %.2f); crowd force on the robot up to %.0f N (most on %s: %.0f N), "
                "transmitted impulse %.1f N s, deepest penetration %.1f mm\n",
                cr->n_agents, cr->n_fallen, cr->n_steps_taken, cr->local_density_m2,
                cr->local_density_max_m2, cr->robot_force_max_n,
                cr->n_parts > 0 ? cr->part_name[top] : "-",
                cr->n_parts > 0 ? cr->part_force_max_n[top] : 0.0, cr->transmitted_impulse_ns,
                cr->penetration_max_m * 1e3);
    }
    if (s->recorder != NULL)
        print_recorder(s->recorder, out);
    if (s->has_truth && s->truth_plant_err != 0)
        fprintf(out, " sim truth: PLANT ERROR at t=%.4f s, physics stopped: %s\n",
                s->truth_plant_err_t_s,
                s->truth_plant_err_reason ? s->truth_plant_err_reason
                                          : ps_strerror(s->truth_plant_err));
}
