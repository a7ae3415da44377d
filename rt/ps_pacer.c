/*
 * ps_pacer: absolute-deadline pacing with overrun accounting.
 */
#include "ps_pacer.h"

#include <errno.h>
#include <stddef.h>

int ps_pacer_init(ps_pacer_t *p, const ps_clock_t *clock, int64_t period_ns, int64_t start_ns)
{
    if (p == NULL || clock == NULL || period_ns <= 0)
        return -EINVAL;
    *p = (ps_pacer_t){
        .clock = clock,
        .period_ns = period_ns,
        .start_ns = start_ns,
        .next_ns = start_ns,
    };
    return 0;
}

int64_t ps_pacer_deadline_ns(const ps_pacer_t *p, uint64_t idx)
{
    return p->start_ns + (int64_t)idx * p->period_ns;
}

int64_t ps_pacer_wait(ps_pacer_t *p)
{
    const int64_t deadline_ns = p->next_ns;
    int rc;
    do {
        rc = ps_clock_sleep_until_ns(p->clock, deadline_ns);
    } while (rc == -EINTR);
    if (rc < 0)
        return rc;

    const int64_t now_ns = ps_clock_now_ns(p->clock);
    /* A clock may wake a hair early (or a fake may say so): report 0, never a
     * negative latency that would read as an error code. */
    const int64_t latency_ns = now_ns > deadline_ns ? now_ns - deadline_ns : 0;
    /* next_ns stays on the grid: index from the deadline, not from now. */
    p->tick = (uint64_t)((deadline_ns - p->start_ns) / p->period_ns);
    p->next_ns = deadline_ns + p->period_ns;
    p->last_wake_latency_ns = latency_ns;
    return latency_ns;
}

uint64_t ps_pacer_end_tick(ps_pacer_t *p)
{
    const int64_t now_ns = ps_clock_now_ns(p->clock);
    if (now_ns < p->next_ns)
        return 0;
    /* Deadlines next_ns, next_ns + P, ... <= now are gone; the first one
     * strictly after now is next_ns + missed * P. */
    const uint64_t missed = (uint64_t)((now_ns - p->next_ns) / p->period_ns) + 1u;
    p->next_ns += (int64_t)missed * p->period_ns;
    p->n_overruns++;
    p->n_missed += missed;
    return missed;
}
