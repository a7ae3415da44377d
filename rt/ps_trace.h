/*
 * ps_trace: optional trace points for kernel-level analysis, written to
 * ftrace's trace_marker so they land in the same timeline as the scheduler
 * and interrupt events (trace-cmd / KernelShark; docs/latency.md).
 *
 * Off unless opened (`pushstep --trace`). Each mark is one write(2) of a short
 * line formatted by hand on the stack (no printf, no allocation); writes to
 * trace_marker go into the kernel's ring buffer and do not block. A failed
 * write is counted, never retried.
 *
 * Lines the loop writes: "pushstep: tick n=N wake_ns=W" after each wake,
 * "pushstep: end n=N work_ns=T" after each tick's write stage,
 * "pushstep: overrun n=N missed=M", "pushstep: state from=A to=B" (ps_sm_state_t).
 *
 * Threads: marks from the loop thread; open/close on the main thread.
 * Allocation: none.
 */
#ifndef PS_TRACE_H
#define PS_TRACE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

typedef struct {
    bool is_open; /**< false: marks are no-ops (a zeroed struct is closed) */
    int fd;
    uint64_t n_marks;
    uint64_t n_failed;
} ps_trace_t;

/** @post t closed (marks do nothing)  @rt INIT */
void ps_trace_init(ps_trace_t *t);

/** Open trace_marker: path, or NULL to try /sys/kernel/tracing and then
 *  /sys/kernel/debug/tracing. Closes t first if it was open.
 *  @pre t initialised (ps_trace_init) or zeroed  @post err says which paths
 *  failed and why  @return 0 | -errno  @rt INIT */
int ps_trace_open(ps_trace_t *t, const char *path, char *err, size_t err_len);

/** Write "pushstep: <what> <key1>=<v1> <key2>=<v2>\n". key2 may be NULL.
 *  @rt RT-SAFE: one non-blocking write, loop thread */
void ps_trace_mark(ps_trace_t *t, const char *what, const char *key1, int64_t v1, const char *key2,
                   int64_t v2);

/** Safe twice.  @rt INIT */
void ps_trace_close(ps_trace_t *t);

#endif /* PS_TRACE_H */
