/*
 * ps_sm: the safety state machine as a const edge table (Crazyflie supervisor
 * style). See ps_sm.h for the rules and docs/safety.md for the rationale.
 */
#include "ps_sm.h"

#include <assert.h>
#include <stddef.h>

#include "ps_err.h"

#define HARD PS_SM_C_HARD_FAULTS
#define SOFT PS_SM_C_SOFT_FAULTS

/*
 * Per state, the hard-fault edge comes first so that ESTOP wins over every
 * other trigger present in the same tick; then soft faults (DAMPING) before
 * the operator's STOP (same target, but the matched edge names the cause);
 * then the normal progress edge, which also lists every fault as a blocker so
 * each edge reads correctly on its own, not only through the ordering.
 */
static const ps_sm_edge_t EDGES[] = {
    /* STANDBY: drives limp. Soft faults keep it here: nothing to damp. */
    {PS_SM_STANDBY, HARD, 0u, PS_SM_ESTOP},
    {PS_SM_STANDBY, PS_SM_C_REQ_START, PS_SM_C_START_BLOCKERS, PS_SM_RAMP},

    /* RAMP: any fault or a stop aborts the blend. */
    {PS_SM_RAMP, HARD, 0u, PS_SM_ESTOP},
    {PS_SM_RAMP, SOFT, 0u, PS_SM_DAMPING},
    {PS_SM_RAMP, PS_SM_C_REQ_STOP, 0u, PS_SM_DAMPING},
    {PS_SM_RAMP, PS_SM_C_RAMP_DONE, HARD | SOFT | PS_SM_C_REQ_STOP, PS_SM_ACTIVE},

    /* ACTIVE: controller in charge. A fall or a drive about to overheat
     * damps; the other soft faults hold the last safe pose while the drives
     * still take commands. */
    {PS_SM_ACTIVE, HARD, 0u, PS_SM_ESTOP},
    {PS_SM_ACTIVE, PS_SM_C_FALL | PS_SM_C_DRIVE_HOT, 0u, PS_SM_DAMPING},
    {PS_SM_ACTIVE, PS_SM_C_HOLD_FAULTS, 0u, PS_SM_HOLD},
    {PS_SM_ACTIVE, PS_SM_C_REQ_STOP, 0u, PS_SM_DAMPING},

    /* HOLD: stiff at the last safe pose. The fault that led here may persist
     * (it does not re-trigger anything); a fall, a hot drive, the
     * operator's stop or the end of hold_s damps; a start with every fault
     * gone resumes. */
    {PS_SM_HOLD, HARD, 0u, PS_SM_ESTOP},
    {PS_SM_HOLD, PS_SM_C_FALL | PS_SM_C_HOLD_DONE | PS_SM_C_DRIVE_HOT, 0u, PS_SM_DAMPING},
    {PS_SM_HOLD, PS_SM_C_REQ_STOP, 0u, PS_SM_DAMPING},
    {PS_SM_HOLD, PS_SM_C_REQ_START, PS_SM_C_RESUME_BLOCKERS, PS_SM_RAMP},

    /* DAMPING: brake until time is up or the robot is still. Soft faults
     * change nothing (already damping); STANDBY tolerates them too. */
    {PS_SM_DAMPING, HARD, 0u, PS_SM_ESTOP},
    {PS_SM_DAMPING, PS_SM_C_DAMP_DONE, HARD, PS_SM_STANDBY},

    /* ESTOP: latched. The self-edge makes the latch explicit (and gives the
     * loop a matched edge to log); only a reset with none of the reset
     * blockers left leaves. */
    {PS_SM_ESTOP, PS_SM_C_RESET_BLOCKERS, 0u, PS_SM_ESTOP},
    {PS_SM_ESTOP, PS_SM_C_REQ_RESET, PS_SM_C_RESET_BLOCKERS, PS_SM_STANDBY},
};

#define N_EDGES (sizeof EDGES / sizeof EDGES[0])

static const char *const STATE_NAMES[] = {
    [PS_SM_STANDBY] = "STANDBY", [PS_SM_RAMP] = "RAMP",   [PS_SM_ACTIVE] = "ACTIVE",
    [PS_SM_DAMPING] = "DAMPING", [PS_SM_ESTOP] = "ESTOP", [PS_SM_HOLD] = "HOLD",
};
static_assert(sizeof STATE_NAMES / sizeof STATE_NAMES[0] == PS_SM_STATE_COUNT,
              "one name per state");

static const char *const COND_NAMES[] = {
    "REQ_START",   "REQ_STOP",    "REQ_RESET", "REQ_ESTOP",   "ESTOP_INPUT",    "RAMP_DONE",
    "DAMP_DONE",   "REPLY_STALE", "IMU_STALE", "POLICY_LATE", "TARGET_INVALID", "FALL",
    "DRIVE_FAULT", "BUS_OFF",     "OVERRUN",   "TX_REFUSED",  "HOLD_DONE",      "DRIVE_HOT",
};
static_assert(sizeof COND_NAMES / sizeof COND_NAMES[0] == PS_SM_COND_COUNT,
              "one name per condition bit");
static_assert(PS_SM_C_DRIVE_HOT == 1u << (PS_SM_COND_COUNT - 1u), "DRIVE_HOT is the last bit");

/* Refusal sentences for a blocked START or RESET, checked in this order (the
 * most actionable reason first). Every blocker bit has one; the tests check
 * that each bit of the blocker masks maps to its own sentence. */
typedef struct {
    uint32_t bit;
    const char *reason;
} blocker_reason_t;

static const blocker_reason_t START_REASONS[] = {
    {PS_SM_C_ESTOP_INPUT, "start refused: e-stop input pressed"},
    {PS_SM_C_REQ_ESTOP, "start refused: e-stop requested"},
    {PS_SM_C_BUS_OFF, "start refused: CAN bus off"},
    {PS_SM_C_DRIVE_FAULT, "start refused: drive fault"},
    {PS_SM_C_REPLY_STALE, "start refused: actuator replies stale"},
    {PS_SM_C_IMU_STALE, "start refused: IMU data stale"},
    {PS_SM_C_DRIVE_HOT, "start refused: drive too hot"},
    /* only block a resume from HOLD (PS_SM_C_RESUME_BLOCKERS) */
    {PS_SM_C_FALL, "start refused: robot fallen"},
    {PS_SM_C_POLICY_LATE, "start refused: policy still late"},
    {PS_SM_C_TARGET_INVALID, "start refused: targets still invalid"},
    {PS_SM_C_OVERRUN, "start refused: loop still overrunning"},
    {PS_SM_C_TX_REFUSED, "start refused: bus still refusing frames"},
    {PS_SM_C_HOLD_DONE, "start refused: hold time over, damping"},
};
static const blocker_reason_t RESET_REASONS[] = {
    {PS_SM_C_ESTOP_INPUT, "reset refused: e-stop input still pressed"},
    {PS_SM_C_REQ_ESTOP, "reset refused: e-stop requested"},
    {PS_SM_C_BUS_OFF, "reset refused: CAN bus still off"},
};

static int is_valid_state(ps_sm_state_t s)
{
    return (unsigned)s < (unsigned)PS_SM_STATE_COUNT;
}

int ps_sm_find_edge(ps_sm_state_t state, uint32_t cond)
{
    if (!is_valid_state(state))
        return -1;
    for (unsigned i = 0; i < N_EDGES; i++) {
        const ps_sm_edge_t *e = &EDGES[i];
        if (e->from == state && (cond & e->trigger) != 0u && (cond & e->blocker) == 0u)
            return (int)i;
    }
    return -1;
}

ps_sm_state_t ps_sm_next(ps_sm_state_t state, uint32_t cond)
{
    if (!is_valid_state(state))
        return PS_SM_ESTOP; /* corrupted state: fail safe */
    const int idx = ps_sm_find_edge(state, cond);
    return idx < 0 ? state : EDGES[idx].to;
}

static int refuse(const char **out_reason, const char *reason)
{
    if (out_reason != NULL)
        *out_reason = reason;
    return -PS_ERR_ILLEGAL_STATE;
}

/* First reason whose bit is in cond, or NULL when nothing blocks. */
static const char *blocked_by(const blocker_reason_t *r, size_t n, uint32_t cond)
{
    for (size_t i = 0; i < n; i++)
        if ((cond & r[i].bit) != 0u)
            return r[i].reason;
    return NULL;
}

int ps_sm_check_request(ps_sm_state_t state, uint32_t request, uint32_t cond,
                        const char **out_reason)
{
    /* Exactly one bit, and a request bit. */
    if (request == 0u || (request & (request - 1u)) != 0u || (request & PS_SM_C_REQUESTS) == 0u) {
        if (out_reason != NULL)
            *out_reason = "request refused: not a single request bit";
        return -EINVAL;
    }
    /* A software e-stop is honoured whatever the state, even a corrupted one. */
    if (request == PS_SM_C_REQ_ESTOP)
        return 0;
    if (!is_valid_state(state))
        return refuse(out_reason, "request refused: unknown state");

    const char *why;
    switch (request) {
    case PS_SM_C_REQ_START:
        if (state == PS_SM_ESTOP)
            return refuse(out_reason, "start refused: e-stop latched, reset first");
        if (state != PS_SM_STANDBY && state != PS_SM_HOLD)
            return refuse(out_reason, "start refused: only allowed from STANDBY or HOLD");
        why = blocked_by(
            START_REASONS, sizeof START_REASONS / sizeof START_REASONS[0],
            cond & (state == PS_SM_HOLD ? PS_SM_C_RESUME_BLOCKERS : PS_SM_C_START_BLOCKERS));
        return why != NULL ? refuse(out_reason, why) : 0;
    case PS_SM_C_REQ_STOP:
        if (state == PS_SM_STANDBY)
            return refuse(out_reason, "stop refused: nothing to stop in STANDBY");
        if (state == PS_SM_DAMPING)
            return refuse(out_reason, "stop refused: already DAMPING");
        if (state == PS_SM_ESTOP)
            return refuse(out_reason, "stop refused: e-stop latched");
        return 0; /* RAMP, ACTIVE, HOLD; with a hard fault present it ends in ESTOP instead */
    case PS_SM_C_REQ_RESET:
        if (state != PS_SM_ESTOP)
            return refuse(out_reason, "reset refused: not in ESTOP");
        why = blocked_by(RESET_REASONS, sizeof RESET_REASONS / sizeof RESET_REASONS[0], cond);
        return why != NULL ? refuse(out_reason, why) : 0;
    default:
        break;
    }
    /* Unreachable: every request bit is handled above. */
    return refuse(out_reason, "request refused: unknown request");
}

const ps_sm_edge_t *ps_sm_edges(unsigned *out_n)
{
    if (out_n != NULL)
        *out_n = (unsigned)N_EDGES;
    return EDGES;
}

const char *ps_sm_state_name(ps_sm_state_t s)
{
    return is_valid_state(s) ? STATE_NAMES[s] : "?";
}

const char *ps_sm_cond_name(uint32_t bit)
{
    if (bit == 0u)
        return "?";
    unsigned idx = 0;
    while ((bit & (1u << idx)) == 0u)
        idx++;
    return idx < PS_SM_COND_COUNT ? COND_NAMES[idx] : "?";
}
