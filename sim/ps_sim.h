/*
 * ps_sim: the simulated robot the loop runs against on board `sim`.
 *
 * A MuJoCo plant (sim/ps_plant.c, the model named in the robot file) plus
 * emulated devices that sit on simulated CAN buses (sim/ps_can_sim.c) and a
 * simulated GPIO port, exactly where real hardware would sit: each actuator
 * consumes the command frames of its joint's protocol and answers with
 * that protocol's replies (quantised, on-drive PD, torque limit, temperature
 * model); the IMU sends its two
 * frames per sample with noise and bias. The loop sees only ps_can_port_t,
 * ps_gpio_port_t and ps_clock_t, and does not know it runs on a simulation.
 *
 * Two modes:
 *  - real time: the plant runs on its own thread, paced by CLOCK_MONOTONIC
 *    at the servo period like hardware, exchanging frames through the buses;
 *    ps_sim_clock() is the monotonic clock.
 *  - lockstep: no thread; ps_sim_clock() is a simulated clock whose
 *    sleep_until advances the plant to the deadline. Deterministic for a seed.
 *
 * The scenario drives pushes, the harness, e-stop presses and injected
 * faults at simulated times (relative to ps_sim_start's start_ns).
 *
 * Emulated drives start in motor mode OFF, like real drives: commands are
 * answered but not obeyed until the loop enables the joint
 * (sim/ps_devices.h). They go limp with COMMS_LOST after 100 ms without a
 * command in motor mode.
 *
 * Layering: sim/ includes the base and drivers/ only. What it needs from the
 * application (thread setup, the allocation guard's pause) it gets through
 * ps_sim_hooks_t; operator requests from the scenario leave as PS_SIM_REQ_*
 * bits that the application maps to its state machine.
 *
 * Drive power: the drives' power stage is fed through an emulated watchdog
 * relay on the GPIO heartbeat (sim/ps_gpio_sim.h, drivers/ps_gpio.h): at each
 * physics step, unless the heartbeat changed level within the last
 * PS_GPIO_SIM_RELAY_TIMEOUT_NS (10 ms), every joint gets zero torque, like a
 * cut power stage (the drives' logic stays powered: they still decode
 * commands and answer). Power is off until the loop's first heartbeat edge.
 *
 * Timing: each servo period runs the model's physics steps (the model's
 * timestep must divide the period). At each physics step the devices take the
 * frames whose end-of-frame time has come, reply, and set torques; the IMU
 * samples on the period grid. In lockstep the period [t, t + period) is run
 * by sleep_until(t + period), so commands the loop sends at t act from the
 * first physics step after they are on the wire. In real time the plant
 * thread runs the period at start + period/2 + k period (half a period after
 * the loop's tick) so commands sent early in a tick act in the same period.
 *
 * Falling behind (real time): when the physics of a period takes longer than
 * the period, the plant thread skips slots of its grid (n_plant_overruns)
 * while the devices keep stamping frames with the wall clock, so simulated
 * time lags the wall clock from then on (max_plant_lag_ns); the run is then
 * not faithful, and pushstep --require-rt fails it.
 *
 * Test knob: the environment variable PUSHSTEP_SIM_SLOW_NS (read at create,
 * real time only, 0 to 1e9) makes the plant thread sleep that many ns after
 * each period's physics, to emulate a plant too slow for real time. Unset
 * in normal use.
 *
 * Threads: create/destroy on the main thread; ports used by the loop thread;
 * the plant thread is internal. Allocation: all at create.
 */
#ifndef PS_SIM_H
#define PS_SIM_H

#include <limits.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "../drivers/ps_actuator.h"
#include "../drivers/ps_can.h"
#include "../drivers/ps_canbus.h"
#include "../drivers/ps_gpio.h"
#include "../drivers/ps_imu_msg.h"
#include "../rt/ps_clock.h"
#include "../rt/ps_limits.h"
#include "../rt/ps_ring.h"
#include "ps_crowd.h"
#include "ps_devices.h"
#include "ps_scenario.h"

typedef struct ps_sim ps_sim_t;

/** The robot as the simulation needs it (the composition root fills it). */
typedef struct {
    char name[PS_NAME_LEN]; /**< for messages */
    uint32_t n_joints;
    char joint_name[PS_MAX_JOINTS][PS_NAME_LEN]; /**< hinge and motor names in the model */
    ps_act_cfg_t act[PS_MAX_JOINTS];             /**< protocol, ids, bus, gear of each drive */
    ps_act_limits_t lim[PS_MAX_JOINTS];          /**< for counting commands out of limits */
    float stance_rad[PS_MAX_JOINTS];             /**< initial pose */
    ps_imu_cfg_t imu;
    ps_sim_devices_cfg_t devices;
    /* Where the robot file names the model and each joint, for the plant's
     * errors (FILE:LINE: FIELD:); empty or 0: unknown. */
    char src_path[PATH_MAX];
    uint32_t joint_name_line[PS_MAX_JOINTS];
    uint32_t model_line;
} ps_sim_robot_t;

/** The board as the simulation needs it. */
typedef struct {
    char name[PS_NAME_LEN];
    uint32_t n_buses;
    ps_canbus_bus_cfg_t buses[PS_MAX_BUSES];
    uint32_t plant_priority; /**< SCHED_FIFO priority of the plant thread, 0: none */
    int32_t plant_cpu;       /**< CPU of the plant thread, -1: any */
} ps_sim_board_t;

/** What the simulation needs from the application; every member may be NULL. */
typedef struct {
    void *ctx;
    /** Real time: called first on the plant thread (priority, CPU; best effort). */
    void (*setup_thread)(void *ctx, unsigned priority, int cpu);
    /** Lockstep: around the plant's work on the loop thread, so that an
     *  allocation guard on that thread does not count it. */
    void (*pause_guard)(void *ctx);
    void (*resume_guard)(void *ctx);
    /** Whether the controller is in charge of the robot now (the runtime: state
     *  RAMP or ACTIVE), for the truth's lowest CoM. Called once per servo period
     *  on the thread that steps the plant (the plant thread, or the loop thread
     *  inside sleep_until in lockstep), so it must be RT-SAFE and thread-safe
     *  (an atomic load). NULL: never active. */
    bool (*is_controller_active)(void *ctx);
} ps_sim_hooks_t;

/** Operator requests a scenario makes (ps_sim_take_requests). */
typedef enum {
    PS_SIM_REQ_START = 1u << 0,
    PS_SIM_REQ_STOP = 1u << 1,
    PS_SIM_REQ_RESET = 1u << 2,
} ps_sim_request_t;

typedef struct {
    const ps_sim_board_t *board;
    const ps_sim_robot_t *robot;
    const ps_scenario_cfg_t *scenario;
    const char *model_path; /**< resolved MJCF path */
    bool is_lockstep;
    int64_t period_ns; /**< servo period; plant paced at this */
    ps_sim_hooks_t hooks;
} ps_sim_cfg_t;

/** Ground truth from the plant, for tests and the summary. */
typedef struct {
    double t_s;                   /**< simulated time */
    double com_m[3];              /**< whole-body CoM, world */
    double head_height_m;         /**< height of the head/trunk top */
    bool is_fallen;               /**< a robot body other than the feet touches the ground */
    uint64_t n_steps;             /**< physics steps taken */
    uint64_t n_cmd_frames;        /**< command frames the emulated drivers consumed */
    uint64_t n_cmd_out_of_limits; /**< commands outside the joint's configured limits */
    uint64_t n_bad_frames;        /**< frames the emulated devices rejected */
    double max_temp_c;
    /* Added by sim/ps_sim.c (documented extensions): */
    double pelvis_m[3];             /**< pelvis origin, world */
    double first_fall_t_s;          /**< simulated time since start of the first fall, -1: none */
    uint64_t n_plant_overruns;      /**< real time: plant periods skipped because physics
                                         fell behind the clock (0 in lockstep) */
    int64_t max_plant_lag_ns;       /**< real time: most that simulated time lagged
                                         the wall clock at the end of a period (0
                                         when never behind; 0 in lockstep) */
    uint64_t n_cmd_ignored;         /**< command frames received outside motor mode */
    uint64_t n_reply_frames;        /**< replies the emulated drivers put on the buses */
    uint64_t n_imu_samples;         /**< IMU samples sent (two frames each) */
    uint64_t n_dev_tx_dropped;      /**< device frames refused by a full bus queue */
    uint64_t n_unrouted_frames;     /**< frames on a bus that no device's id matches
                                         (also counted in n_bad_frames) */
    int plant_err;                  /**< 0, or the first ps_plant_step error; physics
                                         stops advancing after it */
    const char *plant_err_reason;   /**< why (ps_plant_error_reason, a static
                                         string), NULL when plant_err is 0 */
    double plant_err_t_s;           /**< simulated time of plant_err, -1: none */
    bool is_drive_power_on;         /**< the watchdog relay feeds the drives now */
    uint64_t n_power_cuts;          /**< times the relay dropped the drives' power */
    double tau_abs_sum_nm;          /**< sum of |torque| applied to the plant at the
                                         last physics step (0 with power off) */
    double heading_dev_max_rad;     /**< largest |yaw| of the floating base since
                                         start (it starts facing +x) */
    double foot_slide_m;            /**< horizontal travel of the feet while they
                                         carry weight (> 20 N at both ends of a
                                         servo period), summed over both */
    double kinetic_energy_max_j;    /**< largest kinetic energy of the model */
    double min_com_height_active_m; /**< lowest CoM z at the end of a servo period
                                         while hooks.is_controller_active said so,
                                         on simulated time (deterministic in
                                         lockstep); -1: never active */
    bool has_crowd;                 /**< the scenario has a crowd: crowd is valid */
    ps_crowd_stats_t crowd;         /**< its measurements at the end of the last period */
    double crowd_local_density_max_m2; /**< largest local density around the robot */
    double push_force_n[3];         /**< sum of the scenario's pushes acting now, world */
} ps_sim_truth_t;

/** One servo period of the crowd's measurements, for the non-real-time side
 *  (ps_sim_take_crowd_sample). */
typedef struct {
    double t_s;                /**< simulated time since start */
    uint32_t n_fallen;
    uint32_t n_stepping;
    float local_density_m2;
    float robot_force_n;
    float transmitted_impulse_ns; /**< cumulative */
    float penetration_m;
    uint32_t n_parts;
    float part_force_n[PS_CROWD_MAX_PARTS];
} ps_sim_crowd_sample_t;

#define PS_SIM_CROWD_RING_SLOTS 1024u

/** Load the model, build devices and buses, apply the scenario's initial
 *  state (robot in stance, harness engaged unless the scenario says otherwise:
 *  a harness_release event at t 0 acts on the first physics step).
 *  cfg->board, robot and scenario are copied; scenario may be NULL (none).
 *  IMU noise and bias are seeded from scenario->seed.
 *  @post *out_sim owned by the caller until ps_sim_destroy; untouched on error
 *  @return 0 | -EINVAL (cfg, board, robot, model_path NULL or period_ns <= 0)
 *          | -PS_ERR_PLANT (err says why) | -PS_ERR_CONFIG (joint missing in
 *          the model; a joint's or the IMU's bus not on the board; the model
 *          timestep does not divide period_ns; a push body not in the model or
 *          a drop_replies joint not in the robot, err names it) | -ENOMEM
 *  @rt INIT */
int ps_sim_create(const ps_sim_cfg_t *cfg, ps_sim_t **out_sim, char *err, size_t err_len);

/** @return the CAN port of bus bus_idx (loop side); a zeroed port (ops NULL)
 *  when bus_idx is not on the board  @rt INIT */
ps_can_port_t ps_sim_can_port(ps_sim_t *s, unsigned bus_idx);

/** @return the GPIO port (loop side)  @rt INIT */
ps_gpio_port_t ps_sim_gpio_port(ps_sim_t *s);

/** @return the clock the loop must use (simulated in lockstep)  @rt INIT */
const ps_clock_t *ps_sim_clock(ps_sim_t *s);

/** Real-time mode: start the plant thread, which runs period k at
 *  start_ns + period_ns/2 + k period_ns. Lockstep: set simulated
 *  time to start_ns. Scenario times count from start_ns. Also sets every
 *  bus's tick epoch to start_ns. The plant thread's priority and CPU come
 *  from the board (plant_priority, plant_cpu) through hooks.setup_thread.
 *  @return 0 | -EBUSY already started | -errno (pthread_create)  @rt INIT */
int ps_sim_start(ps_sim_t *s, int64_t start_ns);

/** Stop the plant thread (no-op in lockstep). Safe to call twice. @rt INIT */
void ps_sim_stop(ps_sim_t *s);

/** @post *out = current truth (thread-safe snapshot)  @rt NON-RT */
void ps_sim_get_truth(ps_sim_t *s, ps_sim_truth_t *out);

/** The same snapshot without a lock, for the loop thread (the flight
 *  recorder): a sequence-counted copy, retried a few times if the plant
 *  thread is writing it.  @return true when *out is a consistent copy
 *  @rt RT-SAFE O(sizeof truth), any thread */
bool ps_sim_read_truth_rt(ps_sim_t *s, ps_sim_truth_t *out);

/** Pending operator requests from the scenario (START, STOP, RESET) that fell
 *  due since the last call, as PS_SIM_REQ_* bits. @rt RT-SAFE, loop thread */
uint32_t ps_sim_take_requests(ps_sim_t *s);

/** Copy of one emulated driver's state (motor mode, fault, temperature,
 *  counters), for tests and the summary.
 *  @pre lockstep, or the plant thread stopped (no lock guards the devices)
 *  @return 0 | -EINVAL joint_idx out of range  @rt NON-RT */
int ps_sim_get_actuator(ps_sim_t *s, unsigned joint_idx, ps_devices_actuator_t *out);

/** Fault injection (tests): set one emulated drive's winding temperature,
 *  as if it had heated up; the drive's own model takes it from there (above
 *  its temp_max_c it leaves motor mode with MOTOR_OVERTEMP and reports it).
 *  @pre lockstep, or the plant thread stopped (no lock guards the devices)
 *  @return 0 | -EINVAL joint_idx out of range or temp_c not finite  @rt NON-RT */
int ps_sim_set_actuator_temp(ps_sim_t *s, unsigned joint_idx, double temp_c);

/** The oldest crowd sample not taken yet (one per servo period, pushed by
 *  the thread that steps the plant into a preallocated SPSC ring; when the
 *  taker falls behind, new samples are dropped and counted).
 *  @return 0 | -EAGAIN none waiting | -ENOENT no crowd
 *  @rt RT-SAFE, one consumer thread (NON-RT side) */
int ps_sim_take_crowd_sample(ps_sim_t *s, ps_sim_crowd_sample_t *out);

/** @return crowd samples dropped because the taker fell behind  @rt any */
uint64_t ps_sim_crowd_samples_dropped(ps_sim_t *s);

/** The plant, for rendering and tests: read its model and data only while
 *  it does not step (lockstep between sleeps, or the thread stopped).
 *  @rt INIT/NON-RT */
struct ps_plant;
const struct ps_plant *ps_sim_plant(const ps_sim_t *s);

/* ---- the scene, for a rendering camera (sim/ps_camera_sim) ---------------
 * At create and at the end of every servo period the sim publishes the
 * model's positions (qpos) with their simulated time into a latest-wins
 * mailbox (rt/ps_mailbox.h): the plant never waits for the camera. */

struct mjModel_;

/** @return a copy of the plant's MuJoCo model, or NULL (no memory); the
 *  caller frees it with mj_deleteModel  @rt INIT */
struct mjModel_ *ps_sim_copy_model(ps_sim_t *s);

/** @return the model's nq (positions per scene)  @rt any */
uint32_t ps_sim_scene_nq(const ps_sim_t *s);

/** The newest scene: qpos and its simulated time (the loop's clock; 0 before
 *  ps_sim_start) and its number (0 at create, then one per servo period).
 *  @return 0 | -EINVAL (nq is not the model's)
 *  @rt RT-SAFE O(nq), wait-free; one reader thread (the camera's) */
int ps_sim_read_scene(ps_sim_t *s, double *out_qpos, uint32_t nq, int64_t *out_t_ns,
                      uint64_t *out_seq);

/** Pictures: fn(ctx, plant) after each physics step that ends on the
 *  frame_ns grid of simulated time (sim/ps_render.h offers the state), on
 *  the thread that steps the plant; it must not block in real time. Set
 *  before ps_sim_start; fn NULL: none.
 *  @return 0 | -EINVAL (frame_ns not a positive multiple of the step)  @rt INIT */
int ps_sim_set_frame_hook(ps_sim_t *s, int64_t frame_ns,
                          void (*fn)(void *ctx, const struct ps_plant *p), void *ctx);

/** @post all resources freed; s invalid. Safe on NULL.  @rt INIT */
void ps_sim_destroy(ps_sim_t *s);

#endif /* PS_SIM_H */
