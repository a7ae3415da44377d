/*
 * ps_app: builds a runnable system from the three configuration files, in
 * one place: loads and cross-checks board, robot and scenario, plans the CAN
 * buses, wires the ports of the board's kind (the simulated plant for `sim`;
 * SocketCAN and libgpiod for `linux`, each interface checked first; with
 * replay_path, on any board, ports fed from a candump log:
 * drivers/ps_can_replay.h), the policy slot (standing, capture-point or
 * trained MLP controller, from the robot file or the command line), the
 * record ring and the loop. main() and the end-to-end tests both start the
 * system through here. It is the composition root (with rt/main.c and the
 * config loader): the only application code that includes sim/
 * (docs/architecture.md).
 *
 * Threads: main thread. Allocation: INIT only (the sim allocates at create);
 * ps_app_t is large: keep it static or on the heap.
 */
#ifndef PS_APP_H
#define PS_APP_H

#include <limits.h>
#include <stdbool.h>

#include "../drivers/ps_camera_files.h"
#include "../drivers/ps_camera_libcamera.h"
#include "../drivers/ps_can_replay.h"
#include "../drivers/ps_can_socket.h"
#include "../drivers/ps_canbus.h"
#include "../drivers/ps_gpio_gpiod.h"
#include "../policy/ps_capture.h"
#include "../policy/ps_mlp_policy.h"
#include "../policy/ps_stand.h"
#include "../sim/ps_camera_sim.h"
#include "../policy/ps_weights.h"
#include "../sim/ps_sim.h"
#include "ps_config.h"
#include "ps_config_sim.h"
#include "ps_loop.h"
#include "ps_perception.h"
#include "ps_recorder.h"
#include "ps_ring.h"

#define PS_APP_RING_SLOTS   1024u
#define PS_APP_STATUS_EVERY 100u /**< ticks between status records */

typedef struct {
    const char *data_dir; /**< where boards/, robots/, scenarios/ live */
    const char *board;    /**< NAME (boards/NAME.yaml) or a file path */
    const char *robot;    /**< file path or NAME; NULL: ps1 */
    const char *scenario; /**< file path or NAME; NULL: crowd on sim, none otherwise */
    bool is_lockstep;
    uint32_t wake_hist_us; /**< 1-us wake-up histogram size; 0: 1000 */
    ps_trace_t *trace;     /**< trace_marker points for the loop; NULL: off */
    ps_ring_t *frame_ring; /**< every frame the loop reads and sends; NULL: off */
    /** --replay: buses fed from this candump -L log, its clock, no GPIO, no
     *  plant (any board); NULL: off */
    const char *replay_path;
    /** `pushstep camera`: load the files and open the board's camera only (on
     *  board sim, with a plant that is not started: the scene at rest); no
     *  buses, GPIO or loop. The perception keeps its snapshot. */
    bool is_camera_only;
    /** The policy slot's controller: "stand", "capture" or "mlp"; NULL: the
     *  robot file's `policy.controller`, else "stand" */
    const char *policy;
    /** "mlp": the policy file; NULL: the robot file's `policy.weights` */
    const char *weights;
} ps_app_opts_t;

typedef struct {
    char board_path[PATH_MAX], robot_path[PATH_MAX], scenario_path[PATH_MAX];
    char model_path[PATH_MAX];
    bool is_lockstep;
    ps_board_cfg_t board;
    ps_robot_cfg_t robot;
    ps_sim_devices_cfg_t robot_sim; /**< the robot file's `sim:` section */
    ps_scenario_cfg_t scenario;
    ps_canbus_plan_t plan;
    ps_sim_board_t sim_board;
    ps_sim_robot_t sim_robot;
    ps_sim_t *sim;                         /**< NULL on real boards */
    ps_can_socket_t sockets[PS_MAX_BUSES]; /**< linux boards: one per bus */
    uint32_t n_sockets_open;
    ps_gpio_gpiod_t gpiod; /**< linux boards */
    bool is_gpiod_open;
    ps_can_replay_t replay;                /**< --replay: the log's ports and clock */
    ps_can_replay_entry_t *replay_entries; /**< --replay: storage, heap, sized at start-up */
    uint8_t *replay_data;                  /**< --replay: the frames' payload bytes */
    bool is_replay;
    char notes[512]; /**< what start-up did not check (virtual CAN interfaces) */
    /* camera perception, when the board has a camera: section */
    char camera_dir[PATH_MAX]; /**< camera.dir resolved against the board file */
    ps_camera_files_t camera_files;
    ps_camera_libcamera_t *camera_libcamera;
    ps_camera_sim_t *camera_sim;
    ps_perception_t perception;
    bool has_perception;
    char bus_names[PS_MAX_BUSES][PS_NAME_LEN]; /**< the board's interfaces, by bus */
    ps_stand_t stand;
    ps_capture_t capture;
    ps_weights_t weights;
    ps_mlp_policy_t mlp;
    char policy_name[PS_NAME_LEN];     /**< the controller in the slot */
    char weights_path[PATH_MAX];       /**< "mlp": its policy file */
    ps_ring_t ring;
    ps_loop_rec_t ring_storage[PS_APP_RING_SLOTS];
    ps_loop_t loop;
    struct {
        ps_sim_t *sim;
        const ps_clock_t *clock;
        _Atomic int64_t start_request_ns; /**< 0: none */
    } op;
} ps_app_t;

/** Load, check, plan and wire. On a bus budget error the plan in app->plan is
 *  still filled so the caller can show it. With a camera: section on the
 *  board, the camera is opened and the perception thread started here (on
 *  the board's worker CPU), its mailbox wired into the loop.
 *  @post err holds one line naming the file/field/bus on failure
 *  @return 0 | -PS_ERR_CONFIG (also: a CAN interface not set up as the board
 *          says; err names the `ip link` fix) | -PS_ERR_BUS_BUDGET | -ENOENT
 *          | -ENODEV, -EPERM, -EBUSY (a CAN socket or GPIO line could not be had)
 *          | -PS_ERR_PLANT | -ENOMEM | replay: as ps_can_replay_init (a bad log
 *          line, an interface that is not a board bus)  @rt INIT, main thread */
int ps_app_init(ps_app_t *app, const ps_app_opts_t *opts, char *err, size_t err_len);

/** Plan the board's buses for the robot: one source per joint (its
 *  protocol's command and reply frames, at its rate_div; source index = joint
 *  index) and one for the IMU (its protocol's frames of one sample; source
 *  index = n_joints). @return as ps_canbus_plan  @rt INIT */
int ps_app_plan_buses(const ps_board_cfg_t *b, const ps_robot_cfg_t *r, ps_canbus_plan_t *out,
                      char *err, size_t err_len);

/** The board and robot as the simulation needs them (plant thread one
 *  priority below the loop; devices: the robot file's `sim:` section, from
 *  ps_config_load_robot_sim).  @pre devices != NULL  @rt INIT */
void ps_app_sim_board(const ps_board_cfg_t *b, ps_sim_board_t *out);
void ps_app_sim_robot(const ps_robot_cfg_t *r, const ps_sim_devices_cfg_t *devices,
                      ps_sim_robot_t *out);

/** Hooks the simulation calls back into the application: RT setup of the
 *  plant thread, the allocation guard's pause, whether the loop is in charge
 *  (RAMP or ACTIVE; never when loop is NULL).  @pre loop outlives the sim
 *  @rt INIT */
ps_sim_hooks_t ps_app_sim_hooks(ps_loop_t *loop);

/** Request START at an absolute loop time (real boards without an operator).
 *  @rt any thread */
void ps_app_request_start_at(ps_app_t *app, int64_t t_ns);

/** The receive filters of one bus: every joint's replies (its protocol's
 *  reply_filter) and each frame of the IMU's message.  @rt INIT */
void ps_app_bus_filters(const ps_robot_cfg_t *r, uint32_t bus_idx, ps_can_socket_cfg_t *out);

/** Frames a bus's kernel queue must hold: twice the most the loop sends on it
 *  in one tick (every joint's command frames plus a mode request each), at
 *  least 16.  @rt INIT */
uint32_t ps_app_min_txqueuelen(const ps_robot_cfg_t *r, uint32_t bus_idx);

/** The recorder's description of the run from the loaded configuration
 *  (board, robot, scenario, joint and bus names, servo rate, foot size,
 *  clock); the caller sets paths, windows and compression.  @rt INIT */
void ps_app_recorder_cfg(const ps_app_t *app, ps_recorder_cfg_t *out);

/** Tap the loop into the recorder (every tick) and, on the simulation, give
 *  it the plant's ground truth (lock-free, ps_sim_read_truth_rt).
 *  @pre both initialised, loop not running  @rt INIT */
void ps_app_attach_recorder(ps_app_t *app, ps_recorder_t *rec);

/** Stop camera perception, free the sim, close sockets and GPIO lines
 *  (heartbeat low). Safe twice and on a failed init.  @rt INIT */
void ps_app_deinit(ps_app_t *app);

#endif /* PS_APP_H */
