/*
 * ps_config: board, robot and scenario configuration, loaded from YAML with
 * libcyaml into the fixed-size structs below and range-checked field by field.
 *
 * Every error message names the file, the line (where it can be found), the
 * field path, the value and the allowed range, e.g.
 *   boards/sim.yaml:7: buses[1].bitrate: value 2000000 outside [10000, 1000000]
 *
 * Threads: INIT only (main thread). Allocation: libcyaml allocates while
 * loading; everything is copied into the caller's structs and freed before
 * return, so the loaded config owns no heap memory.
 */
#ifndef PS_CONFIG_H
#define PS_CONFIG_H

/* The loader composes every module's own configuration struct from the files:
 * it is part of the composition root (with rt/ps_app.c and rt/main.c), the
 * only application code that includes sim/ (docs/architecture.md). */
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "../drivers/ps_actuator.h"
#include "../drivers/ps_canbus.h"
#include "../drivers/ps_gpio.h"
#include "../drivers/ps_imu_msg.h"
#include "../policy/ps_estimate.h"
#include "../policy/ps_servo.h"
#include "../sim/ps_devices.h"
#include "../sim/ps_scenario.h"
#include "ps_limits.h"
#include "ps_loop.h"
#include "ps_rtsetup.h"

/* ---- board file: boards/<name>.yaml ---------------------------------- */

typedef enum {
    PS_BOARD_SIM = 0, /**< simulated plant and devices (sim/) */
    PS_BOARD_LINUX,   /**< real SocketCAN buses and libgpiod lines */
} ps_board_kind_t;

struct ps_board_cfg {
    char name[PS_NAME_LEN];
    ps_board_kind_t kind;
    uint32_t n_buses;
    ps_canbus_bus_cfg_t buses[PS_MAX_BUSES];
    float bus_budget; /**< max worst-case load per bus, 0..1, default 0.8 */
    ps_gpio_cfg_t gpio;
    ps_rt_cfg_t rt;
};

/* ---- robot file: robots/<name>.yaml ---------------------------------- */

/** A robot, as the modules consume it: one array per module, indexed by joint
 *  (the order of the robot file's joints). */
struct ps_robot_cfg {
    char name[PS_NAME_LEN];
    char model[PS_PATH_LEN]; /**< MJCF file for the sim, relative to the robot file */
    ps_control_cfg_t control;
    ps_servo_cfg_t servo_common;
    uint32_t n_joints;
    char joint_name[PS_MAX_JOINTS][PS_NAME_LEN]; /**< matches the joint name in the sim model */
    ps_act_cfg_t act[PS_MAX_JOINTS];             /**< the actuator port's view */
    ps_servo_joint_cfg_t servo[PS_MAX_JOINTS];   /**< the servo layer's view */
    ps_imu_cfg_t imu;
    ps_kinematics_cfg_t kin;
    ps_sim_devices_cfg_t sim;
};

/* ---- scenario file: scenarios/<name>.yaml (simulation only) ----------- */
/* ps_scenario_cfg_t: sim/ps_scenario.h */

/* ---- loading ---------------------------------------------------------- */

/** Load and check a board file. @pre path != NULL
 *  @post *out fully written on success, untouched on failure; err (if not NULL)
 *        holds a one-line message "FILE[:LINE]: [FIELD: ]problem" on failure
 *  @return 0 | -PS_ERR_CONFIG | -ENOENT | -EINVAL (NULL path/out) | -ENOMEM
 *  @rt INIT, main thread */
int ps_config_load_board(const char *path, ps_board_cfg_t *out, char *err, size_t err_len);

/** Load and check a robot file (joint map, ranges, gains, limits). Each
 *  joint's `driver` is resolved by name and its ranges copied into `wire`;
 *  `model` is stored as written (relative to the robot file; the caller resolves).
 *  @pre path != NULL  @post as ps_config_load_board
 *  @return 0 | -PS_ERR_CONFIG | -ENOENT | -EINVAL | -ENOMEM  @rt INIT */
int ps_config_load_robot(const char *path, ps_robot_cfg_t *out, char *err, size_t err_len);

/** Load and check a scenario file. @pre path != NULL  @post as ps_config_load_board
 *  @return 0 | -PS_ERR_CONFIG | -ENOENT | -EINVAL | -ENOMEM  @rt INIT */
int ps_config_load_scenario(const char *path, ps_scenario_cfg_t *out, char *err, size_t err_len);

/** Cross-file checks: every joint's bus and the IMU's bus exist on the board,
 *  every drop_replies joint of the scenario is a joint of the robot. (Ids per
 *  bus and rates are already checked by ps_config_load_robot; push bodies name
 *  model bodies, which only the sim can check.)
 *  @pre b, r loaded; s may be NULL (no scenario)  @post err holds a message on failure
 *  @return 0 | -PS_ERR_CONFIG | -EINVAL (b or r NULL)  @rt INIT */
int ps_config_check_pair(const ps_board_cfg_t *b, const ps_robot_cfg_t *r,
                         const ps_scenario_cfg_t *s, char *err, size_t err_len);

/** @return joint index with that name, or -ENOENT (also for r or name NULL)
 *  @rt RT-SAFE O(n) */
int ps_config_find_joint(const ps_robot_cfg_t *r, const char *name);

/** Name of an event kind as written in scenario files, for logs; "unknown"
 *  outside the enum. @rt RT-SAFE */
const char *ps_config_event_name(ps_event_kind_t k);

#endif /* PS_CONFIG_H */
