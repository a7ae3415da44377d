/*
 * ps_clock: the real clock, CLOCK_MONOTONIC with absolute-deadline sleeps.
 */
#include "ps_clock.h"

#include <errno.h>
#include <time.h>

static int64_t mono_now_ns(void *ctx)
{
    (void)ctx;
    struct timespec ts;
    /* CLOCK_MONOTONIC cannot fail with a valid pointer; the vDSO answers it
     * without a syscall. */
    (void)clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * PS_NS_PER_S + (int64_t)ts.tv_nsec;
}

static int mono_sleep_until_ns(void *ctx, int64_t deadline_ns)
{
    (void)ctx;
    if (deadline_ns < 0)
        deadline_ns = 0; /* the past: return at once, like any passed deadline */
    struct timespec ts = {
        .tv_sec = (time_t)(deadline_ns / PS_NS_PER_S),
        .tv_nsec = (long)(deadline_ns % PS_NS_PER_S),
    };
    /* clock_nanosleep returns the error number itself and does not set errno.
     * EINTR is handed back, not retried: the caller decides (the pacer
     * retries, a shutdown path may not want to). */
    const int rc = clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL);
    return -rc;
}

static const ps_clock_t MONOTONIC = {
    .now_ns = mono_now_ns,
    .sleep_until_ns = mono_sleep_until_ns,
    .ctx = NULL,
};

const ps_clock_t *ps_clock_monotonic(void)
{
    return &MONOTONIC;
}

static int64_t thread_cpu_now_ns(void *ctx)
{
    (void)ctx;
    struct timespec ts;
    (void)clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts); /* valid pointer: cannot fail */
    return (int64_t)ts.tv_sec * PS_NS_PER_S + (int64_t)ts.tv_nsec;
}

static int thread_cpu_sleep_until_ns(void *ctx, int64_t deadline_ns)
{
    (void)ctx;
    (void)deadline_ns;
    return -EINVAL; /* CPU time cannot be slept on: a measuring clock only */
}

static const ps_clock_t THREAD_CPU = {
    .now_ns = thread_cpu_now_ns,
    .sleep_until_ns = thread_cpu_sleep_until_ns,
    .ctx = NULL,
};

const ps_clock_t *ps_clock_thread_cpu(void)
{
    return &THREAD_CPU;
}
