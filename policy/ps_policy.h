/*
 * ps_policy: the policy slot. The loop runs one policy every
 * servo_hz / policy_hz ticks through this ops table. Now: the standing
 * controller (policy/ps_stand.c); later the trained MLP through the same slot.
 *
 * Threads: loop thread. Allocation: implementations allocate in their own
 * INIT function only.
 */
#ifndef PS_POLICY_H
#define PS_POLICY_H

#include "ps_state.h"

typedef struct {
    const char *name;
    /** Compute targets from the latest measurement and estimate.
     *  @post out fully written on success  @return 0 | -errno | -PS_ERR_*
     *  @rt RT-SAFE */
    int (*step)(void *ctx, const ps_meas_t *meas, const ps_estimate_t *est, ps_targets_t *out);
    /** Forget internal state (entering RAMP).  @rt RT-SAFE */
    void (*reset)(void *ctx);
} ps_policy_ops_t;

typedef struct {
    const ps_policy_ops_t *ops;
    void *ctx;
} ps_policy_t;

#endif /* PS_POLICY_H */
