/*
 * ps_sm: the safety state machine, as a table.
 *
 * States: STANDBY (drives limp, heartbeat on), RAMP (blend from the measured
 * pose to the controller's targets over control.ramp_s), ACTIVE (controller
 * in charge), HOLD (the controller's output or data cannot be trusted but the
 * drives still take commands: the last safe pose is held stiffly for up to
 * control.hold_s, until the operator stops or restarts), DAMPING (zero
 * stiffness, configured damping, until the time runs out or the robot is
 * still), ESTOP (latched; heartbeat stopped; only an explicit reset, with the
 * e-stop input released, leaves it).
 *
 * Each tick the loop gathers a condition bitmask (operator requests, watchdog
 * findings, timers) and calls ps_sm_next(), which is pure: the first edge of
 * the current state whose trigger bits intersect the conditions and whose
 * blocker bits do not wins; no match means stay. Entry actions are the loop's
 * business, run after the transition.
 *
 * Watchdog rule (docs/safety.md, one row per fault): a fault that means the
 * *controller's output or its data* cannot be trusted while the drives still
 * take commands (stale actuator reply, stale IMU, missed policy deadline,
 * repeated overruns, NaN or out-of-range target, frames the bus refused)
 * leads from ACTIVE to HOLD, then to DAMPING when the hold ends; a fall
 * leads to DAMPING at once (holding a robot on the floor stiffly helps
 * nobody); a fault that means the *hardware* cannot be trusted (e-stop
 * input, bus off, drive fault or over-temperature) leads to ESTOP. In RAMP
 * every soft fault damps.
 *
 * Threads: pure functions, any thread. Allocation: none.
 */
#ifndef PS_SM_H
#define PS_SM_H

#include <stdint.h>

typedef enum {
    PS_SM_STANDBY = 0,
    PS_SM_RAMP,
    PS_SM_ACTIVE,
    PS_SM_DAMPING,
    PS_SM_ESTOP,
    PS_SM_HOLD, /**< last, so the older states keep their numbers in logs */
    PS_SM_STATE_COUNT
} ps_sm_state_t;

/** Condition bits. Requests (REQ_*) come from the operator; the rest from the loop. */
typedef enum {
    PS_SM_C_REQ_START = 1u << 0,       /**< operator: STANDBY or HOLD -> RAMP */
    PS_SM_C_REQ_STOP = 1u << 1,        /**< operator: RAMP/ACTIVE/HOLD -> DAMPING */
    PS_SM_C_REQ_RESET = 1u << 2,       /**< operator: ESTOP -> STANDBY */
    PS_SM_C_REQ_ESTOP = 1u << 3,       /**< operator: software e-stop */
    PS_SM_C_ESTOP_INPUT = 1u << 4,     /**< e-stop GPIO reads pressed */
    PS_SM_C_RAMP_DONE = 1u << 5,       /**< ramp time elapsed */
    PS_SM_C_DAMP_DONE = 1u << 6,       /**< damping time elapsed or robot still */
    PS_SM_C_REPLY_STALE = 1u << 7,     /**< an actuator reply is older than allowed */
    PS_SM_C_IMU_STALE = 1u << 8,       /**< IMU sample older than allowed */
    PS_SM_C_POLICY_LATE = 1u << 9,     /**< policy missed its deadline */
    PS_SM_C_TARGET_INVALID = 1u << 10, /**< NaN or out-of-range joint target */
    PS_SM_C_FALL = 1u << 11,           /**< estimator says fallen */
    PS_SM_C_DRIVE_FAULT = 1u << 12,    /**< driver fault bits or over-temperature */
    PS_SM_C_BUS_OFF = 1u << 13,        /**< a CAN controller went bus-off */
    PS_SM_C_OVERRUN = 1u << 14,        /**< overrun_limit overruns within overrun_window_s */
    PS_SM_C_TX_REFUSED = 1u << 15,     /**< a bus refused frames this loop wanted to send */
    PS_SM_C_HOLD_DONE = 1u << 16,      /**< hold_s elapsed in HOLD */
    PS_SM_C_DRIVE_HOT = 1u << 17,      /**< a drive nears its temp_max_c: damp before its own
                                            protection trips (docs/safety.md) */
} ps_sm_cond_t;

/** Soft faults where the drives still take commands: ACTIVE holds. */
#define PS_SM_C_HOLD_FAULTS                                                                        \
    (PS_SM_C_REPLY_STALE | PS_SM_C_IMU_STALE | PS_SM_C_POLICY_LATE | PS_SM_C_TARGET_INVALID |      \
     PS_SM_C_OVERRUN | PS_SM_C_TX_REFUSED)
/** Soft faults: the hold faults, and those that damp at once (a fall, a drive
 *  about to overheat). */
#define PS_SM_C_SOFT_FAULTS (PS_SM_C_HOLD_FAULTS | PS_SM_C_FALL | PS_SM_C_DRIVE_HOT)
#define PS_SM_C_HARD_FAULTS                                                                        \
    (PS_SM_C_REQ_ESTOP | PS_SM_C_ESTOP_INPUT | PS_SM_C_DRIVE_FAULT | PS_SM_C_BUS_OFF)
#define PS_SM_C_REQUESTS                                                                           \
    (PS_SM_C_REQ_START | PS_SM_C_REQ_STOP | PS_SM_C_REQ_RESET | PS_SM_C_REQ_ESTOP)

/** Number of condition bits (bit 0 .. PS_SM_COND_COUNT - 1); ps_sm_cond_name
 *  has one name per bit. */
#define PS_SM_COND_COUNT 18u
#define PS_SM_C_ALL      ((1u << PS_SM_COND_COUNT) - 1u)

/** What blocks STANDBY -> RAMP: every hard fault, and the soft faults that
 *  make *starting* unsafe (no fresh actuator or IMU data to ramp from, a
 *  drive too hot to carry the robot). The other soft faults (POLICY_LATE,
 *  TARGET_INVALID, FALL, ...) do not block a start: if they persist, RAMP
 *  drops to DAMPING on its first tick. */
#define PS_SM_C_START_BLOCKERS                                                                     \
    (PS_SM_C_HARD_FAULTS | PS_SM_C_REPLY_STALE | PS_SM_C_IMU_STALE | PS_SM_C_DRIVE_HOT)
/** What blocks HOLD -> RAMP (the operator resumes after a fault): the start
 *  blockers, every soft fault still present, and the hold's end (the robot
 *  is being damped in that tick). */
#define PS_SM_C_RESUME_BLOCKERS (PS_SM_C_START_BLOCKERS | PS_SM_C_SOFT_FAULTS | PS_SM_C_HOLD_DONE)
/** What blocks ESTOP -> STANDBY: e-stop input still pressed, bus still off,
 *  e-stop requested again. Not a drive fault: drives clear a latched fault
 *  only when they are enabled again, which happens in STANDBY; a
 *  drive that is still faulted then sends the robot straight back to ESTOP,
 *  with its cause logged, instead of making the reset impossible. */
#define PS_SM_C_RESET_BLOCKERS (PS_SM_C_REQ_ESTOP | PS_SM_C_ESTOP_INPUT | PS_SM_C_BUS_OFF)

/** One edge: leave `from` for `to` when (cond & trigger) && !(cond & blocker). */
typedef struct {
    ps_sm_state_t from;
    uint32_t trigger;
    uint32_t blocker;
    ps_sm_state_t to;
} ps_sm_edge_t;

/** @return the state after applying conditions (first matching edge, else state);
 *  a state outside the enum yields PS_SM_ESTOP (fail safe)
 *  @rt RT-SAFE O(edges), pure, any thread */
ps_sm_state_t ps_sm_next(ps_sm_state_t state, uint32_t cond);

/** The edge ps_sm_next() would take, so the loop can log *why* it moved
 *  (e.g. the lowest bit of cond & edge.trigger, via ps_sm_cond_name).
 *  A matching edge may lead back to the same state (ESTOP's latch edge).
 *  @pre none  @post none
 *  @return index into ps_sm_edges() | -1 no edge matches (stay), or state invalid
 *  @rt RT-SAFE O(edges), pure, any thread */
int ps_sm_find_edge(ps_sm_state_t state, uint32_t cond);

/** Would an operator request (one REQ_* bit) be accepted now, given the
 *  other conditions (e.g. e-stop input still pressed blocks a reset)?
 *  Accepted means ps_sm_next(state, cond | request) takes the request's edge:
 *  START from STANDBY unless PS_SM_C_START_BLOCKERS, from HOLD unless
 *  PS_SM_C_RESUME_BLOCKERS; STOP from RAMP/ACTIVE/HOLD; RESET from ESTOP
 *  unless PS_SM_C_RESET_BLOCKERS; ESTOP from every state.
 *  @pre out_reason may be NULL
 *  @post *out_reason set to a static sentence ("start refused: ...") when
 *        refused (also for -EINVAL); untouched when accepted
 *  @return 0 accepted | -PS_ERR_ILLEGAL_STATE | -EINVAL not a single request bit
 *  @rt RT-SAFE, pure */
int ps_sm_check_request(ps_sm_state_t state, uint32_t request, uint32_t cond,
                        const char **out_reason);

/** @pre out_n may be NULL  @post *out_n = number of edges
 *  @return the edge table and its length (for docs and tests)  @rt RT-SAFE */
const ps_sm_edge_t *ps_sm_edges(unsigned *out_n);

/** @return "STANDBY", ... or "?"  @rt RT-SAFE */
const char *ps_sm_state_name(ps_sm_state_t s);

/** @return name of the lowest set condition bit, e.g. "REPLY_STALE"; "?" when
 *  no bit below PS_SM_COND_COUNT is set  @rt RT-SAFE */
const char *ps_sm_cond_name(uint32_t bit);

#endif /* PS_SM_H */
