/*
 * ps_config: board and robot configuration, loaded from YAML with libcyaml
 * into the fixed-size structs below and range-checked field by field. What
 * needs sim/ types (the scenario file, the robot file's `sim:` section) is in
 * rt/ps_config_sim.h, for the composition root only.
 *
 * Every error message names the file, the line (where it can be found), the
 * field path, the value and the allowed range, e.g.
 *   boards/sim.yaml:7: buses[1].bitrate: value 2000000 outside [10000, 1000000]
 * Checks between two files name the file and line of the offending field.
 *
 * Threads: INIT only (main thread). Allocation: libcyaml allocates while
 * loading; everything is copied into the caller's structs and freed before
 * return, so the loaded config owns no heap memory.
 */
#ifndef PS_CONFIG_H
#define PS_CONFIG_H

/* Layering: this header includes the base, drivers/, policy/ and rt/ only,
 * never sim/, so application modules (rt/ps_loop.c, rt/ps_summary.c) may
 * include it. The loader itself, which also fills sim's structs, is part of
 * the composition root (docs/architecture.md). */
#include <limits.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "../drivers/ps_actuator.h"
#include "../drivers/ps_canbus.h"
#include "../drivers/ps_gpio.h"
#include "../drivers/ps_imu_msg.h"
#include "../policy/ps_estimate.h"
#include "../policy/ps_servo.h"
#include "ps_limits.h"
#include "ps_loop.h"
#include "ps_perception.h"
#include "ps_rtsetup.h"

/* ---- board file: boards/<name>.yaml ---------------------------------- */

typedef enum {
    PS_BOARD_SIM = 0, /**< simulated plant and devices (sim/) */
    PS_BOARD_LINUX,   /**< real SocketCAN buses and libgpiod lines */
} ps_board_kind_t;

/** The board's camera (optional `camera:`), for `pushstep doctor`: a V4L2
 *  device or sub-device whose name (/sys/class/video4linux/STAR/name)
 *  contains `sensor`, e.g. "imx708" (empty: any). Camera perception, when
 *  the section also gives `source`, is ps_board_cfg_t.perception. */
typedef struct {
    char sensor[PS_NAME_LEN];
} ps_board_camera_t;

struct ps_board_cfg {
    char name[PS_NAME_LEN];
    ps_board_kind_t kind;
    uint32_t n_buses;
    ps_canbus_bus_cfg_t buses[PS_MAX_BUSES];
    float bus_budget; /**< max worst-case load per bus, 0..1, default 0.8 */
    ps_gpio_cfg_t gpio;
    ps_rt_cfg_t rt;
    bool has_camera; /**< camera given (the optional `camera:` section) */
    ps_board_camera_t camera;
    bool has_perception;            /**< camera perception configured (`camera.source` given) */
    ps_perception_cfg_t perception; /**< camera.dir as written (relative to the board file) */
    uint32_t camera_line; /**< first line of the `camera:` mapping, for messages; 0: none */
};

/* ---- robot file: robots/<name>.yaml ---------------------------------- */

/** Where the robot file's fields are, for the checks against another file
 *  (ps_config_check_pair). Lines are 1-based; 0 or an empty path: unknown
 *  (a struct built in code). */
typedef struct {
    char path[PATH_MAX]; /**< the file as passed to the loader */
    uint32_t joint_name_line[PS_MAX_JOINTS];
    uint32_t joint_bus_line[PS_MAX_JOINTS];
    uint32_t joint_protocol_line[PS_MAX_JOINTS];
    uint32_t imu_bus_line;
    uint32_t model_line;
} ps_robot_src_t;

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
    /** The file's optional `policy:` section: the controller in the policy
     *  slot (PS_CONFIG_POLICY_NAMES; empty: "stand") and, for "mlp", the
     *  policy file (relative to the robot file, as written). */
    char policy[PS_NAME_LEN];
    char policy_weights[PS_PATH_LEN];
    ps_robot_src_t src; /**< for messages only */
    /* The file's `sim:` section: ps_config_load_robot_sim (rt/ps_config_sim.h). */
};

/** The controllers the policy slot can hold (robot file `policy.controller`,
 *  pushstep --policy). */
#define PS_CONFIG_POLICY_NAMES "stand, capture, mlp"

/** @return 0 stand, 1 capture, 2 mlp; -ENOENT for any other name  @rt INIT */
int ps_config_policy_find(const char *name);

/* ---- loading ---------------------------------------------------------- */

/** The path of a config argument: a path as given (it has a '/' or ends in
 *  .yaml), else data_dir/dir/NAME.yaml (NAME = arg, or fallback when arg is
 *  NULL).  @rt INIT */
void ps_config_resolve(const char *data_dir, const char *arg, const char *dir, const char *fallback,
                       char *out, size_t len);

/** Load and check a board file. @pre path != NULL
 *  @post *out fully written on success, untouched on failure; err (if not NULL)
 *        holds a one-line message "FILE[:LINE]: [FIELD: ]problem" on failure
 *        ("FILE: is a directory" for a directory)
 *  @return 0 | -PS_ERR_CONFIG | -ENOENT | -EINVAL (NULL path/out) | -ENOMEM
 *  @rt INIT, main thread */
int ps_config_load_board(const char *path, ps_board_cfg_t *out, char *err, size_t err_len);

/** Load and check a robot file (joint map, ranges, gains, limits). Each
 *  joint's `driver` is resolved by name and its ranges copied into `wire`;
 *  `model` is stored as written (relative to the robot file; the caller
 *  resolves). The `sim:` section is checked but not returned (see
 *  ps_config_load_robot_sim). out->src records path and lines.
 *  @pre path != NULL  @post as ps_config_load_board
 *  @return 0 | -PS_ERR_CONFIG | -ENOENT | -EINVAL | -ENOMEM  @rt INIT */
int ps_config_load_robot(const char *path, ps_robot_cfg_t *out, char *err, size_t err_len);

/** Checks of a robot against a board: every joint's bus and the IMU's bus
 *  exist on the board, and a protocol that needs CAN FD is on an FD bus. (Ids
 *  per bus and rates are already checked by ps_config_load_robot.) A message
 *  names the robot file and the line of the field (r->src), e.g.
 *    robots/x.yaml:14: joints[2].bus: bus 2 not on board bench (buses 0..1)
 *  or "robot NAME: ..." when r->src.path is empty.
 *  @pre b, r loaded  @post err holds a message on failure
 *  @return 0 | -PS_ERR_CONFIG | -EINVAL (b or r NULL)  @rt INIT */
int ps_config_check_pair(const ps_board_cfg_t *b, const ps_robot_cfg_t *r, char *err,
                         size_t err_len);

/** @return joint index with that name, or -ENOENT (also for r or name NULL)
 *  @rt RT-SAFE O(n) */
int ps_config_find_joint(const ps_robot_cfg_t *r, const char *name);

#endif /* PS_CONFIG_H */
