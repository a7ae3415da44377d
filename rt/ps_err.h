/*
 * ps_err: project error codes.
 *
 * Every fallible function returns 0 (or a non-negative count) on success and a
 * negative code on failure: either a negated errno (-EINVAL, -EIO, ...) or one
 * of the project codes below, which start at 4096 so they never collide with
 * errno values. Threads: any. Allocation: none.
 */
#ifndef PS_ERR_H
#define PS_ERR_H

#include <errno.h>
#include <stddef.h>

enum {
    PS_ERR_BASE = 4096,
    PS_ERR_CONFIG = 4096,  /**< a configuration value is missing, malformed or out of range */
    PS_ERR_BUS_BUDGET,     /**< a CAN schedule exceeds the configured bus-load budget */
    PS_ERR_PROTOCOL,       /**< a frame from a device is malformed or from the wrong sender */
    PS_ERR_STALE,          /**< a device reply or sensor sample is older than allowed */
    PS_ERR_LIMIT,          /**< a command or target is NaN or outside its configured limits */
    PS_ERR_ILLEGAL_STATE,  /**< a state-machine request is not allowed from the current state */
    PS_ERR_DEADLINE,       /**< a real-time deadline was missed */
    PS_ERR_RT_UNAVAILABLE, /**< real-time setup (mlockall, SCHED_FIFO, affinity) not permitted */
    PS_ERR_PLANT,          /**< the simulated plant failed (model load, instability) */
    PS_ERR_END
};

/** @pre none  @post none  @return static string naming code (positive or negative)
 *  @rt RT-SAFE O(1), any thread */
const char *ps_strerror(int code);

/** Write a one-line error message into a caller's buffer (truncated to
 *  fit); does nothing when err is NULL or err_len is 0.
 *  @rt INIT / NON-RT (vsnprintf), any thread */
void ps_err_format(char *err, size_t err_len, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));

#endif /* PS_ERR_H */
