/*
 * ps_clock: the time source of the loop, behind an ops table so that the
 * simulation (lockstep) and tests can inject their own clock.
 *
 * Times are int64_t nanoseconds of CLOCK_MONOTONIC (or simulated time that
 * starts at an arbitrary epoch). Threads: the real clock is thread-safe; an
 * injected clock says so itself. Allocation: none.
 */
#ifndef PS_CLOCK_H
#define PS_CLOCK_H

#include <stdint.h>

#define PS_NS_PER_S  1000000000LL
#define PS_NS_PER_MS 1000000LL
#define PS_NS_PER_US 1000LL

typedef struct {
    /** @return current time  @units ns  @rt RT-SAFE */
    int64_t (*now_ns)(void *ctx);
    /** Sleep until an absolute time (return at once if it has passed).
     *  @return 0 | -EINTR interrupted | -errno  @units ns  @rt RT-SAFE (blocks only by design) */
    int (*sleep_until_ns)(void *ctx, int64_t deadline_ns);
    void *ctx;
} ps_clock_t;

/** The real clock: CLOCK_MONOTONIC and clock_nanosleep(TIMER_ABSTIME).
 *  @return pointer to a static, thread-safe clock  @rt RT-SAFE */
const ps_clock_t *ps_clock_monotonic(void);

/** The calling thread's CPU time (CLOCK_THREAD_CPUTIME_ID): time the thread
 *  actually ran, which preemption does not advance. For measuring work, e.g.
 *  the policy deadline in lockstep; sleep_until_ns returns -EINVAL.
 *  @return pointer to a static clock  @rt RT-SAFE */
const ps_clock_t *ps_clock_thread_cpu(void);

/** @return clock's current time  @units ns  @rt RT-SAFE */
static inline int64_t ps_clock_now_ns(const ps_clock_t *c)
{
    return c->now_ns(c->ctx);
}

/** @return 0 | -errno  @units ns  @rt RT-SAFE */
static inline int ps_clock_sleep_until_ns(const ps_clock_t *c, int64_t deadline_ns)
{
    return c->sleep_until_ns(c->ctx, deadline_ns);
}

/** Seconds as float from ns, for logs and physics. @rt RT-SAFE */
static inline double ps_ns_to_s(int64_t t_ns)
{
    return (double)t_ns * 1e-9;
}

/** @rt RT-SAFE  @units s -> ns, rounded to nearest */
static inline int64_t ps_s_to_ns(double t_s)
{
    return (int64_t)(t_s * 1e9 + (t_s >= 0 ? 0.5 : -0.5));
}

#endif /* PS_CLOCK_H */
