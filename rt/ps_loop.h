/*
 * ps_loop: the fixed-step control loop, one tick at a time.
 *
 * Each tick: READ (drain every CAN bus, decode actuator replies and IMU
 * samples, sample the e-stop input) -> ESTIMATE -> safety state machine ->
 * POLICY (every servo_hz / policy_hz ticks, and on the tick RAMP is entered,
 * right after the policy's reset) -> SERVO (a neutral joint
 * command for every joint due on this tick per the bus plan) -> WRITE (one
 * batch per bus, heartbeat output, LED) -> latency accounting. Records for the
 * non-RT side (status, state transitions, refused requests) go through an
 * SPSC ring; nothing here prints, allocates, locks or blocks.
 *
 * The loop sees only ports (ps_can_port_t, ps_gpio_port_t), a clock and a
 * policy: it does not know whether it runs on hardware or the simulation.
 *
 * The state machine sees this tick's measurements and estimate, and the
 * policy's lateness and target validity of its last run (up to servo_hz /
 * policy_hz ticks earlier; an invalid target is never sent, the servo layer
 * damps that joint meanwhile).
 * Overruns: OVERRUN when control.overrun_limit ticks ended after their next
 * deadline within control.overrun_window_s. TX_REFUSED when a bus refused
 * frames in the last write. HOLD holds the position targets of the last
 * valid policy step (the measured pose if there was none).
 *
 * Neighbours (cfg.neighbours): each tick's READ takes the newest list the
 * perception thread published (rt/ps_perception.h, ps_perception_take) into
 * meas.neighbours, which the policy sees, and ages it on the loop's clock;
 * older than the board's camera.max_age_s it is emptied (no neighbour
 * information). Never a wait: one atomic exchange at most.
 *
 * GPIO: an e-stop input that cannot be read counts as pressed, and so does a
 * heartbeat that cannot be written (the relay is cutting the drives' power):
 * both raise ESTOP_INPUT. In ESTOP the heartbeat is not written, so its
 * fault clears there; after a reset the next write tells again.
 *
 * Hot drives: a joint whose last reply reports a temperature within
 * control.derate_band_c of its temp_max_c is commanded with a derated torque
 * budget (ps_loop_torque_scale); within control.hot_margin_c it raises
 * DRIVE_HOT, which damps.
 *
 * Implausible replies (payload corruption that keeps a valid length): a
 * reply whose position moved farther since the joint's last taken reply than
 * PS_LOOP_REPLY_VEL_FACTOR times the joint's fastest plausible speed allows
 * (the largest of its vel_max_rad_s, its driver's wire velocity range and
 * no-load speed, seen from the joint) in the time between them plus one
 * servo period, with PS_LOOP_REPLY_MARGIN_LSB position LSB of slack, or whose
 * velocity is beyond that speed, is counted (n_reply_implausible, n_rx_bad)
 * and not used: a run of them leaves the joint without a fresh reply, so
 * REPLY_STALE, exactly as a silent drive. The first reply (and the first
 * after ESTOP's reset) is taken as it is.
 *
 * Stale-data rule: a joint's reply is stale when older than
 * control.reply_timeout_s + rate_div servo periods (a joint commanded every
 * rate_div ticks can only answer that often); the IMU likewise with
 * imu_timeout_s and imu.rate_div.
 *
 * Threads: ps_loop_init/deinit on the main thread, ps_loop_tick and
 * ps_loop_run on the loop thread, ps_loop_request_stop from any thread
 * (signal handlers included). Allocation: none; ps_loop_t is caller-owned
 * (large: keep it static or on the heap, not on a small stack).
 */
#ifndef PS_LOOP_H
#define PS_LOOP_H

#include <stdatomic.h>
#include <stdbool.h>
#include <stdint.h>

#include "../drivers/ps_actuator.h"
#include "../drivers/ps_can.h"
#include "../drivers/ps_canbus.h"
#include "../drivers/ps_gpio.h"
#include "../drivers/ps_imu.h"
#include "../policy/ps_estimate.h"
#include "../policy/ps_policy.h"
#include "../policy/ps_servo.h"
#include "ps_clock.h"
#include "ps_limits.h"
#include "ps_mailbox.h"
#include "ps_pacer.h"
#include "ps_perf.h"
#include "ps_ring.h"
#include "ps_sm.h"
#include "ps_trace.h"

/* Board and robot configuration: rt/ps_config.h (the loader composes them). */
typedef struct ps_board_cfg ps_board_cfg_t;
typedef struct ps_robot_cfg ps_robot_cfg_t;

/** The loop's own settings (robot file, `control:`). */
typedef struct {
    uint32_t servo_hz;       /**< loop rate, 100..4000 */
    uint32_t policy_hz;      /**< policy rate; servo_hz must be a multiple */
    float ramp_s;            /**< blend time from measured pose to targets */
    float damping_s;         /**< max time in DAMPING before STANDBY */
    float still_vel_rad_s;   /**< DAMPING ends early when all |qd| below this */
    float reply_timeout_s;   /**< actuator reply older than this: stale */
    float imu_timeout_s;     /**< IMU sample older than this: stale */
    float policy_deadline_s; /**< policy compute longer than this: missed; at most half
                                  a servo period (the policy runs inside one tick) */
    uint32_t overrun_limit;  /**< this many overruns within overrun_window_s: OVERRUN */
    float overrun_window_s;  /**< window of the overrun count */
    float hold_s;            /**< longest HOLD before DAMPING; 0: one tick of HOLD */
    /* Drive temperature (docs/safety.md "Hot drives"): from derate_band_c
     * below a joint's temp_max_c its torque budget (torque_max_nm of every
     * command) is derated linearly, down to derate_min of it at hot_margin_c
     * below temp_max_c, where DRIVE_HOT damps the robot before the drive's
     * own protection trips (above temp_max_c: DRIVE_FAULT, ESTOP). */
    float derate_band_c; /**< derating starts this far below temp_max_c; > hot_margin_c */
    float hot_margin_c;  /**< DRIVE_HOT from this far below temp_max_c; >= 0 */
    float derate_min;    /**< share of torque_max_nm left at hot_margin_c; (0, 1] */
} ps_control_cfg_t;

/** Defaults of the robot file's control.derate_band_c, hot_margin_c and
 *  derate_min (the loader applies them; the loop refuses other invalid sets). */
#define PS_LOOP_DEFAULT_DERATE_BAND_C 15.0f
#define PS_LOOP_DEFAULT_HOT_MARGIN_C  5.0f
#define PS_LOOP_DEFAULT_DERATE_MIN    0.5f

/** Reply plausibility (see the top comment): the factor on a joint's fastest
 *  plausible speed and the position slack in wire LSB. */
#define PS_LOOP_REPLY_VEL_FACTOR  2.0f
#define PS_LOOP_REPLY_MARGIN_LSB  4.0f

/** Largest control.overrun_limit: the loop keeps that many overrun times. */
#define PS_LOOP_MAX_OVERRUN_LIMIT 64u
/** Receive batches per bus per tick at most (of rx_buf's size). */
#define PS_LOOP_MAX_RX_BATCHES 4u
/** Frames one bus may be given in one tick: every joint's command frames. */
#define PS_LOOP_MAX_TX (PS_MAX_JOINTS * PS_ACT_MAX_FRAMES)

typedef enum {
    PS_STAGE_WAKE = 0, /**< wake-up latency: actual wake minus deadline */
    PS_STAGE_READ,
    PS_STAGE_ESTIMATE,
    PS_STAGE_POLICY, /**< recorded on policy ticks only */
    PS_STAGE_SERVO,  /**< includes the state machine */
    PS_STAGE_WRITE,
    PS_STAGE_TICK,        /**< read start to write end */
    PS_STAGE_TICK_PLAIN,  /**< PS_STAGE_TICK of ticks without a policy run */
    PS_STAGE_TICK_POLICY, /**< PS_STAGE_TICK of ticks with a policy run */
    PS_STAGE_REACTION,    /**< receive stamp of the newest reply taken to the end of the
                               write stage, on the loop's clock; ticks that took a reply
                               and sent frames */
    PS_STAGE_TAP,         /**< the tap after the tick (the flight recorder's copy); only
                               when a tap is set */
    PS_STAGE_COUNT
} ps_stage_t;

typedef struct ps_loop ps_loop_t;

/** Called at the end of every tick with the loop's state (the flight
 *  recorder copies its record here: rt/ps_recorder.h). */
typedef struct {
    /** @rt RT-SAFE, loop thread: must not allocate, lock or block */
    void (*on_tick)(void *ctx, const ps_loop_t *loop);
    void *ctx;
} ps_loop_tap_t;

/** Operator requests (PS_SM_C_REQ_* bits) from outside the loop. */
typedef struct {
    /** @return request bits that arrived since the last call  @rt RT-SAFE */
    uint32_t (*take)(void *ctx);
    void *ctx;
} ps_operator_t;

typedef struct {
    const ps_board_cfg_t *board;
    const ps_robot_cfg_t *robot;
    const ps_canbus_plan_t *plan;
    const ps_clock_t *clock;           /**< paces the loop (simulated time in lockstep) */
    const ps_clock_t *perf_clock;      /**< stage timestamps and the policy deadline; NULL: clock.
                                            In lockstep this is the real clock, so the figures
                                            are the loop's own compute time */
    const ps_clock_t *deadline_clock;  /**< judges the policy deadline; NULL: clock. In
                                            lockstep the thread's CPU time: a slow policy
                                            is late, a preempted one is not */
    ps_can_port_t buses[PS_MAX_BUSES]; /**< one per board bus */
    ps_gpio_port_t gpio;
    ps_policy_t policy;
    ps_operator_t op;      /**< .take may be NULL: no operator */
    ps_ring_t *ring;       /**< records to the non-RT side; may be NULL */
    uint32_t status_every; /**< ticks between status records (0: never) */
    uint32_t wake_hist_us; /**< 1-us wake-up histogram size (cyclictest -h N); 0: 1000 */
    ps_trace_t *trace;     /**< trace_marker points; NULL: off */
    ps_ring_t *frame_ring; /**< every frame read and sent (ps_loop_frame_rec_t), for a
                                candump log on the non-RT side; NULL: off */
    ps_mailbox_t *neighbours; /**< camera perception's neighbour lists (ps_neighbours_t),
                                   read each tick into meas.neighbours and aged against
                                   board->camera.max_age_s; NULL: no camera */
    ps_loop_tap_t tap;     /**< .on_tick may be NULL: none */
} ps_loop_cfg_t;

/** One CAN frame as the loop read or sent it (cfg.frame_ring). frame.t_ns:
 *  read, when it was complete on the wire; sent, the tick's deadline. */
typedef struct {
    ps_can_frame_t frame;
    uint8_t bus_idx;
    uint8_t is_tx; /**< 1: sent by the loop (and taken by the bus) */
} ps_loop_frame_rec_t;

typedef enum {
    PS_REC_STATUS = 1,
    PS_REC_TRANSITION,
    PS_REC_REFUSED,
} ps_rec_kind_t;

/** Fixed-size record sent to the non-RT side. */
typedef struct {
    uint8_t kind;       /**< ps_rec_kind_t */
    uint8_t state;      /**< ps_sm_state_t after this tick */
    uint8_t from_state; /**< TRANSITION: state before */
    uint8_t pad;
    uint32_t cond; /**< TRANSITION: conditions that caused it; REFUSED: the request */
    uint64_t tick;
    int64_t t_ns; /**< loop time of the tick's deadline */
    uint64_t n_overruns;
    uint64_t n_policy_runs;
    float com_height_m;
    float tilt_rad;
    const char *reason; /**< REFUSED: static string */
} ps_loop_rec_t;

/** Counters of the loop (read-only outside the loop thread; a torn read of one is accepted). */
typedef struct {
    uint64_t n_ticks;
    uint64_t n_policy_runs;
    uint64_t n_policy_late;
    uint64_t n_rx_frames;
    uint64_t n_rx_unknown;    /**< frames with an id nobody expects */
    uint64_t n_fault_reports; /**< drives' own fault reports taken (RobStride type 21) */
    uint64_t n_rx_bad;        /**< malformed replies or IMU frames */
    uint64_t n_imu_rejected;  /**< IMU samples with a saturated gyro or failed self-test */
    uint64_t n_rx_capped;     /**< ticks a bus still had frames after PS_LOOP_MAX_RX_BATCHES */
    uint64_t n_imu_repeated;  /**< IMU samples whose seq did not advance (ignored) */
    uint64_t n_imu_frozen;    /**< IMU samples refused as frozen values (drivers/ps_imu.h) */
    uint64_t n_reply_implausible; /**< replies refused as corrupt: a position jump or a
                                       velocity no drive makes (also in n_rx_bad) */
    uint64_t n_tx_frames;
    uint64_t n_tx_refused; /**< frames a bus would not queue */
    uint64_t n_bus_errors; /**< -errno from a port */
    uint64_t n_gpio_errors;
    uint64_t n_target_invalid; /**< targets refused by the servo layer */
    uint64_t n_cmd_replaced;   /**< commands outside limits replaced by damping (must stay 0) */
    uint64_t n_transitions;
    uint64_t n_refused;      /**< operator requests refused */
    uint64_t n_ring_dropped; /**< records the ring had no room for */
    uint64_t n_neighbour_lists;  /**< neighbour lists taken from perception's mailbox */
    uint64_t n_neighbour_stale;  /**< ticks with a camera but no valid neighbour list */
    bool has_fallen;         /**< estimator reported a fall in RAMP or ACTIVE */
} ps_loop_counters_t;

/** What the last tick did, kept for the tap (read-only outside the loop). */
typedef struct {
    uint32_t cond;                         /**< conditions the state machine saw */
    ps_sm_state_t state_before;            /**< state when the tick began */
    bool is_policy_run;                    /**< the policy stepped this tick */
    bool is_estop_input;                   /**< the e-stop input read pressed */
    bool is_button_pressed;                /**< the record button read pressed */
    int64_t stage_ns[PS_STAGE_COUNT];      /**< this tick's stage times; -1: not run */
    ps_act_cmd_t cmd[PS_MAX_JOINTS];       /**< last command computed per joint */
    bool is_cmd_sent[PS_MAX_JOINTS];       /**< a command was queued this tick */
    ps_can_state_t bus[PS_MAX_BUSES];      /**< each bus's state as read this tick */
    uint16_t n_rx[PS_MAX_BUSES];           /**< frames read this tick */
    uint16_t n_tx[PS_MAX_BUSES];           /**< frames the bus took this tick */
    int64_t policy_dt_ns;                  /**< the last policy step's compute time */
    int8_t heartbeat;                      /**< level written this tick; -1: held still */
    uint8_t led;                           /**< ps_gpio_led_t written this tick */
} ps_loop_last_t;

struct ps_loop {
    ps_loop_cfg_t cfg;
    ps_pacer_t pacer;
    int64_t period_ns;
    uint32_t policy_div;
    ps_sm_state_t state;
    atomic_int published_state; /**< copy of state for other threads (ps_loop_get_state) */
    int64_t state_since_ns;
    uint32_t pending_requests;     /**< accepted requests waiting for ps_sm_next */
    atomic_uint external_requests; /**< from ps_loop_request (any thread) */
    atomic_uint n_stop_requests;   /**< from ps_loop_request_stop (any thread) */
    uint32_t n_stops_handled;
    bool is_ending; /**< end of the run reached: stopping, no operator request */
    ps_meas_t meas;
    ps_estimator_t estimator;
    ps_targets_t targets;
    bool has_targets;
    float ramp_from_q_rad[PS_MAX_JOINTS];
    float safe_q_rad[PS_MAX_JOINTS]; /**< position targets of the last valid policy step */
    float hold_q_rad[PS_MAX_JOINTS]; /**< pose held in HOLD (safe_q_rad at entry) */
    bool is_policy_reset;            /**< RAMP entered this tick: reset, then step at once */
    bool has_tx_refused;             /**< a bus refused frames in the last write */
    int64_t overrun_t_ns[PS_LOOP_MAX_OVERRUN_LIMIT]; /**< deadlines of the last overruns */
    uint32_t n_overrun_times;                        /**< entries written (ring index base) */
    bool is_entered[PS_MAX_JOINTS];                  /**< enable sent since the last disable */
    int64_t fault_grace_until_ns[PS_MAX_JOINTS];     /**< drive faults ignored until (enable) */
    uint32_t fault_report_bits[PS_MAX_JOINTS]; /**< faults the drive reported on its own, kept until
                                                  the next enable after ESTOP */
    bool has_policy_late;
    bool has_target_invalid;
    bool has_cmd_fault; /**< a command had to be replaced (TARGET_INVALID) */
    bool has_heartbeat_fault; /**< the last heartbeat write failed (ESTOP_INPUT until ESTOP) */
    uint32_t bus_off_mask;
    uint8_t bus_joint[PS_MAX_BUSES][PS_MAX_JOINTS]; /**< joints on each bus, in order */
    uint32_t n_bus_joints[PS_MAX_BUSES];
    float reply_max_vel_rad_s[PS_MAX_JOINTS]; /**< plausible |qd| bound per joint (init) */
    float reply_margin_rad[PS_MAX_JOINTS];    /**< position slack of the jump test (init) */
    int64_t reply_rx_ns[PS_MAX_JOINTS];       /**< receive stamp of the last reply taken */
    ps_imu_rx_t imu_rx;
    bool has_imu_seq;
    uint8_t imu_seq; /**< seq of the last IMU sample taken */
    ps_can_frame_t rx_buf[64];
    ps_can_frame_t tx_buf[PS_MAX_BUSES][PS_LOOP_MAX_TX];
    int8_t tx_mode_joint[PS_MAX_BUSES][PS_LOOP_MAX_TX]; /**< per tx frame: enable/disable
                                                             joint, -1 */
    bool tx_mode_prev[PS_MAX_BUSES][PS_LOOP_MAX_TX];    /**< is_entered before that request */
    uint32_t n_tx[PS_MAX_BUSES];
    int64_t t_deadline_ns; /**< deadline of the current tick */
    int64_t neighbours_max_age_ns; /**< board->camera.max_age_s */
    ps_perf_hist_t perf[PS_STAGE_COUNT];
    int64_t newest_reply_rx_ns; /**< this tick's newest reply stamp; 0: none */
    ps_perf_us_hist_t wake_us;  /**< wake-up latency, cyclictest's 1-us layout */
    ps_loop_counters_t counters;
    ps_loop_last_t last; /**< this tick, for the tap */
};

/** @pre every pointer in cfg valid and outliving loop; estimator geometry in robot
 *  @post loop in STANDBY, histograms zeroed and touched (prefaulted)
 *  @return 0 | -EINVAL (also: thermal settings not 0 <= hot_margin_c <
 *          derate_band_c, derate_min in (0, 1]) | -ENOENT (a leg joint missing for the estimator)  @rt INIT */
int ps_loop_init(ps_loop_t *loop, const ps_loop_cfg_t *cfg);

/** Run one tick now, at the given deadline (no waiting).  @rt RT-SAFE, loop thread */
void ps_loop_tick(ps_loop_t *loop, int64_t deadline_ns);

/** Paced loop: ps_loop_start, then ps_loop_step until end_ns (loop time;
 *  <= 0: no end) or a stop request, then keep ticking through DAMPING until
 *  the robot is in STANDBY or ESTOP; then ps_loop_release_drives. If the
 *  clock fails, one last unpaced tick in ESTOP before returning its error.
 *  @return 0 | -errno from the clock  @rt RT-SAFE, loop thread */
int ps_loop_run(ps_loop_t *loop, int64_t start_ns, int64_t end_ns);

/** Set up pacing: tick 0's deadline is start_ns.  @return 0 | -EINVAL  @rt INIT */
int ps_loop_start(ps_loop_t *loop, int64_t start_ns);

/** Wait for the next deadline, then handle stop requests and run the tick;
 *  overruns are counted by the pacer, and with a deadline_clock other than
 *  clock (lockstep) a tick of a period or more on the deadline clock also
 *  counts one (pacer.n_overruns; n_missed unchanged). @return 0 | -errno from the clock
 *  @rt RT-SAFE, loop thread */
int ps_loop_step(ps_loop_t *loop);

/** @return true once a stop was handled and the robot is in STANDBY or ESTOP  @rt RT-SAFE */
bool ps_loop_is_stopped(const ps_loop_t *loop);

/** Leave the drives safe at the end of a run: a disable request to every
 *  drive (its protocol's frames), the heartbeat left still (the relay cuts
 *  power) and the LED off. The state is left as it is (STANDBY or ESTOP).
 *  @rt RT-SAFE, loop thread, after the last tick */
void ps_loop_release_drives(ps_loop_t *loop);

/** @return the loop's state as last published (relaxed atomic)
 *  @rt RT-SAFE, any thread */
ps_sm_state_t ps_loop_get_state(const ps_loop_t *loop);

/** Ask the loop to stop (it goes through DAMPING to STANDBY first); a second
 *  call while stopping asks for e-stop.  @rt async-signal-safe, any thread */
void ps_loop_request_stop(ps_loop_t *loop);

/** Post operator request bits (PS_SM_C_REQ_*). @rt async-signal-safe, any thread */
void ps_loop_request(ps_loop_t *loop, uint32_t request_bits);

/** The share of a joint's torque_max_nm it may be commanded at temp_c: 1 up
 *  to temp_max_c - c->derate_band_c, then linearly down to c->derate_min at
 *  temp_max_c - c->hot_margin_c and beyond; 1 for a temperature that is not a
 *  number (never reported).
 *  @pre c's thermal fields valid (ps_loop_init checks)  @units degC
 *  @rt RT-SAFE O(1), pure */
float ps_loop_torque_scale(const ps_control_cfg_t *c, float temp_c, float temp_max_c);

/** @return name of a stage, e.g. "wake"  @rt RT-SAFE */
const char *ps_loop_stage_name(ps_stage_t s);

/** Release nothing (no resources) but zero the struct. Safe twice. @rt INIT */
void ps_loop_deinit(ps_loop_t *loop);

#endif /* PS_LOOP_H */
