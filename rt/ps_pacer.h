/*
 * ps_pacer: fixed-period scheduling on absolute deadlines.
 *
 * Deadlines are start + k * period, never "now + period", so the schedule
 * does not drift. If a tick ends after the next deadline (an overrun), the
 * missed deadlines are counted and the pacer skips to the first deadline
 * still in the future, keeping the grid.
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
    int64_t start_ns;     /**< deadline of tick 0 */
    int64_t next_ns;      /**< deadline the next wait sleeps until */
    uint64_t tick;        /**< index of the tick about to run (grid index) */
    uint64_t n_overruns;  /**< ticks that ended after the next deadline */
    uint64_t n_missed;    /**< deadlines skipped because of overruns */
    int64_t last_wake_latency_ns; /**< wake time minus deadline of the last wait */
} ps_pacer_t;

/** @pre period_ns > 0  @post first deadline = start_ns  @return 0 | -EINVAL  @rt INIT */
int ps_pacer_init(ps_pacer_t *p, const ps_clock_t *clock, int64_t period_ns, int64_t start_ns);

/** Sleep until the next deadline. @post p->tick = grid index of this tick,
 *  p->last_wake_latency_ns set  @return wake latency >= 0 | -errno from the clock
 *  @units ns  @rt RT-SAFE, loop thread */
int64_t ps_pacer_wait(ps_pacer_t *p);

/** Call at the end of a tick: checks the tick finished before the next
 *  deadline, else counts an overrun and the deadlines it missed and moves
 *  next_ns to the first grid deadline after now.
 *  @return number of deadlines missed (0 = on time)  @rt RT-SAFE */
uint64_t ps_pacer_end_tick(ps_pacer_t *p);

#endif /* PS_PACER_H */
