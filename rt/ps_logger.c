#include "ps_logger.h"

#include <string.h>
#include <time.h>

#include "../drivers/ps_candump.h"
#include "ps_err.h"
#include "ps_rtsetup.h"

#define STATUS_INTERVAL_NS PS_NS_PER_S
#define IDLE_SLEEP_NS      (5 * PS_NS_PER_MS)

void ps_logger_format_cond(uint32_t cond, char *buf, size_t len)
{
    size_t used = 0;
    buf[0] = '\0';
    for (uint32_t bit = 1; bit != 0; bit <<= 1) {
        if ((cond & bit) == 0 || used + 1 >= len)
            continue;
        int n = snprintf(buf + used, len - used, "%s%s", used ? "|" : "", ps_sm_cond_name(bit));
        if (n < 0)
            return;
        used += (size_t)n < len - used ? (size_t)n : len - used - 1;
    }
}

static int64_t wall_now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * PS_NS_PER_S + ts.tv_nsec;
}

/* Histogram of the samples recorded since prev (bucket-wise difference). The
 * exact min/max of the interval are unknown: bucket edges stand in, the max
 * clamped to the run's exact max. */
static void hist_delta(const ps_perf_hist_t *now, const ps_perf_hist_t *prev, ps_perf_hist_t *out)
{
    ps_perf_reset(out);
    bool has_min = false;
    for (unsigned i = 0; i < PS_PERF_N_BUCKETS; i++) {
        uint32_t d = now->buckets[i] - prev->buckets[i];
        if (d == 0)
            continue;
        out->buckets[i] = d;
        out->n += d;
        if (!has_min)
            out->min_ns = ps_perf_bucket_lo_ns(i);
        has_min = true;
        out->max_ns = ps_perf_bucket_hi_ns(i) - 1;
    }
    if (out->max_ns > now->max_ns)
        out->max_ns = now->max_ns;
}

static void print_status(ps_logger_t *lg, const ps_loop_rec_t *rec)
{
    const ps_loop_t *loop = lg->loop;
    ps_perf_hist_t snap = loop->perf[PS_STAGE_TICK]; /* torn read accepted */
    hist_delta(&snap, &lg->prev_tick, &lg->delta);
    lg->prev_tick = snap;
    int64_t wall = wall_now_ns();
    double dt_s = ps_ns_to_s(rec->t_ns - lg->last_status_ns);
    double speed = (double)(rec->t_ns - lg->last_status_ns) / (double)(wall - lg->last_wall_ns);
    double policy_hz = dt_s > 0 ? (double)(rec->n_policy_runs - lg->last_policy_runs) / dt_s : 0;
    char extra[160] = "";
    if (lg->status_extra != NULL)
        lg->status_extra(lg->status_extra_ctx, extra, sizeof(extra));
    fprintf(lg->out,
            "t=%6.1fs %-7s ticks=%-8llu overruns=%-4llu tick p50/p99/max=%5.1f/%5.1f/%5.1fus "
            "com_z=%.3fm tilt=%4.1fdeg policy=%4.1fHz speed=%.1fx%s%s\n",
            ps_ns_to_s(rec->t_ns - lg->start_ns), ps_sm_state_name((ps_sm_state_t)rec->state),
            (unsigned long long)rec->tick, (unsigned long long)rec->n_overruns,
            (double)ps_perf_quantile_ns(&lg->delta, 0.5) * 1e-3,
            (double)ps_perf_quantile_ns(&lg->delta, 0.99) * 1e-3,
            (double)ps_perf_quantile_ns(&lg->delta, 1.0) * 1e-3, (double)rec->com_height_m,
            (double)rec->tilt_rad * 57.29578, policy_hz, speed, extra[0] ? " " : "", extra);
    fflush(lg->out);
    lg->last_status_ns = rec->t_ns;
    lg->last_wall_ns = wall;
    lg->last_policy_runs = rec->n_policy_runs;
}

static void handle_record(ps_logger_t *lg, const ps_loop_rec_t *rec)
{
    double t_s = ps_ns_to_s(rec->t_ns - lg->start_ns);
    char conds[160];
    switch (rec->kind) {
    case PS_REC_STATUS:
        if (!lg->is_quiet && rec->t_ns - lg->last_status_ns >= STATUS_INTERVAL_NS)
            print_status(lg, rec);
        break;
    case PS_REC_TRANSITION:
        ps_logger_format_cond(rec->cond, conds, sizeof(conds));
        fprintf(lg->out, "t=%6.3fs state %s -> %s (%s)\n", t_s,
                ps_sm_state_name((ps_sm_state_t)rec->from_state),
                ps_sm_state_name((ps_sm_state_t)rec->state), conds[0] ? conds : "-");
        if (lg->n_transitions < PS_LOGGER_MAX_TRANSITIONS)
            lg->transitions[lg->n_transitions] = (ps_logger_transition_t){
                .t_s = t_s, .from = rec->from_state, .to = rec->state, .cond = rec->cond};
        lg->n_transitions++;
        break;
    case PS_REC_REFUSED:
        fprintf(lg->out, "t=%6.3fs request %s refused: %s\n", t_s, ps_sm_cond_name(rec->cond),
                rec->reason ? rec->reason : "?");
        break;
    default:
        fprintf(lg->out, "logger: unknown record kind %u\n", rec->kind);
    }
}

/* At most this many frames between two looks at the record ring, so that a
 * loop that sends faster than the file takes them cannot starve the
 * transitions. */
#define FRAMES_PER_DRAIN 4096u

/* @return true if frames are left for the next pass */
static bool drain_frames(ps_logger_frames_t *fr)
{
    ps_loop_frame_rec_t rec;
    char line[PS_CANDUMP_LINE_MAX];
    for (uint32_t k = 0; k < FRAMES_PER_DRAIN; k++) {
        if (ps_ring_pop(fr->ring, &rec) != 0)
            return false;
        const int n =
            rec.bus_idx < fr->n_buses
                ? ps_candump_format(&rec.frame, fr->ifname[rec.bus_idx], line, sizeof(line))
                : -EINVAL;
        if (n < 0) {
            fr->n_refused++;
            continue;
        }
        (void)fwrite(line, 1, (size_t)n, fr->out);
        fr->n_lines++;
    }
    return true;
}

/* @return true if frames are left (records are always drained) */
static bool drain(ps_logger_t *lg)
{
    ps_loop_rec_t rec;
    while (ps_ring_pop(lg->ring, &rec) == 0)
        handle_record(lg, &rec);
    return lg->frames != NULL && drain_frames(lg->frames);
}

static void *worker_main(void *arg)
{
    ps_logger_t *lg = arg;
    if (lg->cpu >= 0)
        (void)ps_rtsetup_thread_best_effort(0, lg->cpu); /* best effort: the worker is not RT */
    const struct timespec idle = {0, IDLE_SLEEP_NS};
    while (!atomic_load(&lg->should_stop)) {
        if (!drain(lg))
            nanosleep(&idle, NULL);
    }
    while (drain(lg)) {
    }
    return NULL;
}

int ps_logger_start(ps_logger_t *lg, const ps_loop_t *loop, ps_ring_t *ring, FILE *out,
                    int64_t start_ns, bool is_quiet, int cpu, ps_logger_frames_t *frames)
{
    void (*extra)(void *, char *, size_t) = lg->status_extra;
    void *extra_ctx = lg->status_extra_ctx;
    memset(lg, 0, sizeof(*lg));
    lg->status_extra = extra;
    lg->status_extra_ctx = extra_ctx;
    lg->loop = loop;
    lg->ring = ring;
    lg->out = out;
    lg->start_ns = start_ns;
    lg->last_status_ns = start_ns;
    lg->last_wall_ns = wall_now_ns();
    lg->is_quiet = is_quiet;
    lg->frames = frames;
    lg->cpu = cpu;
    ps_perf_reset(&lg->prev_tick);
    atomic_init(&lg->should_stop, false);
    int rc = pthread_create(&lg->thread, NULL, worker_main, lg);
    if (rc != 0)
        return -rc;
    lg->has_thread = true;
    return 0;
}

void ps_logger_stop(ps_logger_t *lg)
{
    if (!lg->has_thread)
        return;
    atomic_store(&lg->should_stop, true);
    (void)pthread_join(lg->thread, NULL); /* the worker cannot fail */
    lg->has_thread = false;
}
