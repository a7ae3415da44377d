/*
 * ps_clock_fake: an injectable clock for tests.
 *
 * Time only moves when told to: ps_clock_fake_set/advance, or a sleep, which
 * jumps to max(now, deadline) plus a wake latency (a constant, or per sleep
 * call from a script). Each now() call can also add scripted extra time, to
 * stand for work between two readings. Sleeps can be made to fail (-EINTR,
 * -EINVAL, ...) from a script, in which case time does not move. Every
 * sleep's deadline is recorded.
 *
 * Threads: not thread-safe (one test thread). Allocation: none.
 */
#ifndef PS_CLOCK_FAKE_H
#define PS_CLOCK_FAKE_H

#include <stddef.h>
#include <stdint.h>

#include "../../rt/ps_clock.h"

#define PS_CLOCK_FAKE_MAX_CALLS 4096u

typedef struct {
    ps_clock_t clock;                 /**< pass &fake->clock to the code under test */
    int64_t now_ns;                   /**< current fake time; tests may write it */
    int64_t wake_latency_ns;          /**< added to every sleep wake (after the script runs out) */
    const int64_t *latency_script_ns; /**< per sleep call i: latency (overrides constant) */
    size_t n_latency_script;
    const int *rc_script; /**< per sleep call i: return code; < 0 fails without moving time */
    size_t n_rc_script;
    const int64_t *now_extra_script_ns; /**< per now() call i: time added after the reading */
    size_t n_now_extra_script;
    size_t n_now_calls;
    size_t n_sleep_calls;                                /**< every call, failed ones included */
    int64_t sleep_deadlines_ns[PS_CLOCK_FAKE_MAX_CALLS]; /**< deadline of sleep call i */
} ps_clock_fake_t;

/** @pre f != NULL  @post f zeroed, now = start_ns, clock ops bound to f  @rt tests */
void ps_clock_fake_init(ps_clock_fake_t *f, int64_t start_ns);

/** @post now = t_ns  @units ns */
void ps_clock_fake_set(ps_clock_fake_t *f, int64_t t_ns);

/** @post now += dt_ns  @units ns */
void ps_clock_fake_advance(ps_clock_fake_t *f, int64_t dt_ns);

#endif /* PS_CLOCK_FAKE_H */
