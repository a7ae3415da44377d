/*
 * ps_logger: the non-real-time side of the loop's records.
 *
 * A worker thread drains the loop's SPSC ring: it prints state transitions
 * and refused requests as they come, a status line about once per second of
 * loop time (state, ticks, overruns, tick latency p50/p99/max over the last
 * interval, CoM height, policy rate), and keeps the transitions for the end
 * summary. It reads the loop's histograms and counters directly; a torn read
 * of a counter that is being written only skews one status line.
 *
 * Threads: start/stop on the main thread; the worker is internal.
 * Allocation: none after start (the struct holds everything).
 */
#ifndef PS_LOGGER_H
#define PS_LOGGER_H

#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdio.h>

#include "ps_loop.h"

#define PS_LOGGER_MAX_TRANSITIONS 256u

typedef struct {
    double t_s; /**< loop time since start */
    uint8_t from, to;
    uint32_t cond;
} ps_logger_transition_t;

/** The candump log of the loop's frames (`--candump FILE`): the worker drains
 *  the loop's frame ring into out as drivers/ps_candump lines. */
typedef struct {
    ps_ring_t *ring; /**< ps_loop_frame_rec_t records */
    FILE *out;
    const char *ifname[PS_MAX_BUSES]; /**< by bus index */
    uint32_t n_buses;
    uint64_t n_lines;   /**< written */
    uint64_t n_refused; /**< records ps_candump_format refused (a bad bus index) */
} ps_logger_frames_t;

typedef struct {
    const ps_loop_t *loop;
    ps_ring_t *ring;
    FILE *out;
    int64_t start_ns;           /**< loop time origin */
    bool is_quiet;              /**< no status lines (transitions still printed) */
    ps_logger_frames_t *frames; /**< NULL: no candump log */
    int cpu;
    pthread_t thread;
    bool has_thread;
    atomic_bool should_stop;
    int64_t last_status_ns;
    int64_t last_wall_ns;
    uint64_t last_policy_runs;
    ps_perf_hist_t prev_tick;
    ps_perf_hist_t delta;
    /** Appended to each status line when set (user may set before
     *  ps_logger_start, which keeps it): writes a few words into buf, e.g.
     *  the simulated crowd's state. Called on the worker thread. */
    void (*status_extra)(void *ctx, char *buf, size_t len);
    void *status_extra_ctx;
    uint32_t n_transitions; /**< may exceed the array; extra ones are counted only */
    ps_logger_transition_t transitions[PS_LOGGER_MAX_TRANSITIONS];
} ps_logger_t;

/** @pre loop, ring and frames (NULL: no candump log) outlive the logger; the
 *  worker owns frames' counters until ps_logger_stop  @post worker running
 *  @return 0 | -errno (thread creation)  @rt INIT, main thread */
int ps_logger_start(ps_logger_t *lg, const ps_loop_t *loop, ps_ring_t *ring, FILE *out,
                    int64_t start_ns, bool is_quiet, int cpu, ps_logger_frames_t *frames);

/** Drain what is left and join the worker. Safe to call twice. @rt INIT */
void ps_logger_stop(ps_logger_t *lg);

/** Format a condition bitmask as "REPLY_STALE|FALL". @post buf NUL-terminated @rt NON-RT */
void ps_logger_format_cond(uint32_t cond, char *buf, size_t len);

#endif /* PS_LOGGER_H */
