/*
 * ps_pacer: fixed-period scheduling on absolute deadlines.
 *
 * Deadlines are start + k * period, never "now + period", so the schedule
 * does not drift. If a tick ends after the next deadline (an overrun), the
 * missed deadlines are counted and the pacer skips to the first deadline
 * still in the future, keeping the grid.
 *
 * Cycle: ps_pacer_wait() sleeps until deadline k (next_ns), sets tick = k and
 * advances next_ns to deadline k+1; the tick runs; ps_pacer_end_tick() checks
 * the time against deadline k+1. Ending exactly on a deadline counts as late
 * (now >= deadline). Example, period P, tick k woken at D_k = start + k*P:
 *   ends at D_k + 0.5P: on time, returns 0, next wait sleeps until D_{k+1};
 *   ends at D_k + 1.5P: overrun, missed 1 (D_{k+1}), next_ns = D_{k+2};
 *   ends at D_k + 2P:   overrun, missed 2 (D_{k+1}, D_{k+2}), next_ns = D_{k+3};
 *   ends at D_k + 4.5P: overrun, missed 4, next_ns = D_{k+5}.
 * so a tick that ends x periods after its own deadline (x >= 1) misses
 * floor(x) deadlines, and the skipped indices never run (tick jumps).
 * If end_tick is not called, the next wait sleeps until D_{k+1} even if it
 * has passed (returns at once, with that lateness as wake latency): the
 * catch-up behaviour is the caller's choice.
 *
 * Threads: one (the loop). Allocation: none.
 */
#ifndef PS_PACER_H
#define PS_PACER_H

#include <stdint.h>

#include "ps_clock.h"

typedef struct {
    const ps_clock_t *clock;
    int64_t period_ns;
    int64_t start_ns;             /**< deadline of tick 0 */
    int64_t next_ns;              /**< deadline the next wait sleeps until (always on the grid) */
    uint64_t tick;                /**< grid index of the tick running (set by wait); 0 before */
    uint64_t n_overruns;          /**< ticks that ended at or after the next deadline */
    uint64_t n_missed;            /**< deadlines skipped because of overruns */
    int64_t last_wake_latency_ns; /**< wake time minus deadline of the last wait, >= 0 */
} ps_pacer_t;

/** @pre p != NULL, clock != NULL  @post first deadline = start_ns, counters 0
 *  @return 0 | -EINVAL period_ns <= 0 or a NULL pointer  @units ns  @rt INIT */
int ps_pacer_init(ps_pacer_t *p, const ps_clock_t *clock, int64_t period_ns, int64_t start_ns);

/** Sleep until the next deadline (returns at once if it has passed). -EINTR
 *  from the clock is retried (signals must not break pacing; Ctrl-C is seen
 *  through a flag the loop checks after each tick).
 *  @post on success: p->tick = grid index of this tick, next_ns = following
 *  deadline, p->last_wake_latency_ns = max(0, now - deadline); on error p is
 *  unchanged (the same deadline is retried by the next call)
 *  @return wake latency >= 0 | -errno from the clock other than -EINTR
 *  @units ns  @rt RT-SAFE, loop thread */
int64_t ps_pacer_wait(ps_pacer_t *p);

/** Call at the end of a tick: checks the tick finished before the next
 *  deadline, else counts an overrun and the deadlines it missed and moves
 *  next_ns to the first grid deadline strictly after now.
 *  @post n_overruns += (missed > 0), n_missed += missed
 *  @return number of deadlines missed (0 = on time)  @rt RT-SAFE, loop thread */
uint64_t ps_pacer_end_tick(ps_pacer_t *p);

/** @return the grid deadline of tick index idx: start + idx * period
 *  @units ns  @rt RT-SAFE */
int64_t ps_pacer_deadline_ns(const ps_pacer_t *p, uint64_t idx);

#endif /* PS_PACER_H */
