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

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "../drivers/ps_mit.h"

#define PS_NAME_LEN    32u
#define PS_PATH_LEN    256u
#define PS_MAX_JOINTS  32u
#define PS_MAX_BUSES   8u
#define PS_MAX_PUSHES  64u
#define PS_MAX_EVENTS  32u
#define PS_ERR_MSG_LEN 512u

/* ---- board file: boards/<name>.yaml ---------------------------------- */

typedef enum {
    PS_BOARD_SIM = 0, /**< simulated plant and devices (sim/) */
    PS_BOARD_LINUX,   /**< real SocketCAN buses and libgpiod lines */
} ps_board_kind_t;

typedef struct {
    char ifname[PS_NAME_LEN]; /**< "can0"; for sim a label */
    uint32_t bitrate;         /**< nominal bit rate, bit/s, 10 k..1 M */
} ps_bus_cfg_t;

typedef struct {
    char chip[PS_NAME_LEN]; /**< "gpiochip0" */
    uint32_t estop_line;
    bool is_estop_active_low;
    uint32_t enable_line;
    uint32_t led_line;
} ps_gpio_cfg_t;

typedef struct {
    uint32_t priority;  /**< SCHED_FIFO priority of the loop thread, 1..98 */
    int32_t loop_cpu;   /**< CPU the loop is pinned to, -1: no pinning */
    int32_t plant_cpu;  /**< CPU of the sim plant thread, -1: no pinning */
    int32_t worker_cpu; /**< CPU of the non-RT logger thread, -1: no pinning */
} ps_rt_cfg_t;

typedef struct {
    char name[PS_NAME_LEN];
    ps_board_kind_t kind;
    uint32_t n_buses;
    ps_bus_cfg_t buses[PS_MAX_BUSES];
    float bus_budget; /**< max worst-case load per bus, 0..1, default 0.8 */
    ps_gpio_cfg_t gpio;
    ps_rt_cfg_t rt;
} ps_board_cfg_t;

/* ---- robot file: robots/<name>.yaml ---------------------------------- */

typedef enum {
    PS_PROTO_MIT = 0,
} ps_proto_t;

typedef struct {
    char name[PS_NAME_LEN]; /**< matches the joint name in the sim model */
    uint32_t bus_idx;       /**< index into the board's buses */
    uint32_t can_id;        /**< command identifier (motor id), 1..0x7ff */
    uint32_t reply_id;      /**< identifier its replies arrive on, 1..0x7ff */
    ps_proto_t protocol;
    ps_mit_range_t wire;            /**< the driver firmware's packing ranges */
    float pos_min_rad, pos_max_rad; /**< joint limits, inside the wire range */
    float vel_max_rad_s;
    float torque_max_nm; /**< |tau| any command may ask for */
    float kp_nm_rad;     /**< servo stiffness in ACTIVE */
    float kd_nm_s_rad;   /**< servo damping in ACTIVE */
    float kp_max_nm_rad; /**< no command exceeds these */
    float kd_max_nm_s_rad;
    float stance_rad;  /**< nominal standing pose */
    float kt_nm_a;     /**< torque constant, current -> torque */
    float temp_max_c;  /**< fault above this winding temperature */
    uint32_t rate_div; /**< command every rate_div servo ticks, 1.. */
} ps_joint_cfg_t;

typedef struct {
    uint32_t bus_idx;
    uint32_t base_id;  /**< gyro frame on base_id, accel frame on base_id + 1 */
    uint32_t rate_div; /**< one sample every rate_div servo ticks */
} ps_imu_cfg_t;

typedef struct {
    uint32_t servo_hz;         /**< loop rate, 100..4000 */
    uint32_t policy_hz;        /**< policy rate; servo_hz must be a multiple */
    float ramp_s;              /**< blend time from measured pose to targets */
    float damping_s;           /**< max time in DAMPING before STANDBY */
    float damping_kd_nm_s_rad; /**< kd of every joint in DAMPING */
    float still_vel_rad_s;     /**< DAMPING ends early when all |qd| below this */
    float reply_timeout_s;     /**< actuator reply older than this: stale */
    float imu_timeout_s;       /**< IMU sample older than this: stale */
    float policy_deadline_s;   /**< policy compute longer than this: missed */
} ps_control_cfg_t;

/** Geometry the estimator needs (a 6-DoF leg per side, lumped trunk CoM). */
typedef struct {
    float mass_kg;
    float hip_offset_y_m; /**< pelvis origin (IMU) to hip joint, lateral */
    float hip_offset_z_m; /**< pelvis origin to hip joint, down (positive) */
    float thigh_m;        /**< hip pitch to knee */
    float shank_m;        /**< knee to ankle */
    float ankle_height_m; /**< ankle axis to sole */
    float foot_length_m, foot_width_m;
    float foot_offset_x_m;   /**< sole centre ahead of the ankle axis */
    float com_offset_z_m;    /**< CoM above the pelvis origin, trunk frame */
    float fall_tilt_rad;     /**< trunk tilt beyond this: fallen */
    float fall_com_height_m; /**< CoM lower than this: fallen */
} ps_kinematics_cfg_t;

/** Parameters of the emulated devices (board `sim` only). */
typedef struct {
    float gyro_noise_rad_s; /**< white noise sigma per sample */
    float gyro_bias_rad_s;  /**< bias magnitude drawn per axis at start */
    float accel_noise_m_s2;
    float accel_bias_m_s2;
    float reply_latency_s; /**< driver turnaround before its reply */
    float thermal_r_c_w;   /**< winding thermal resistance, degC per W */
    float thermal_tau_s;   /**< winding thermal time constant */
    float winding_r_ohm;   /**< phase resistance for copper loss */
    float ambient_c;
} ps_sim_devices_cfg_t;

typedef struct {
    char name[PS_NAME_LEN];
    char model[PS_PATH_LEN]; /**< MJCF file for the sim, relative to the robot file */
    ps_control_cfg_t control;
    uint32_t n_joints;
    ps_joint_cfg_t joints[PS_MAX_JOINTS];
    ps_imu_cfg_t imu;
    ps_kinematics_cfg_t kin;
    ps_sim_devices_cfg_t sim;
} ps_robot_cfg_t;

/* ---- scenario file: scenarios/<name>.yaml (simulation only) ----------- */

typedef struct {
    float t_s; /**< start, simulated seconds since start */
    float duration_s;
    char body[PS_NAME_LEN]; /**< body of the model the force acts on */
    float force_n[3];       /**< world frame */
} ps_push_cfg_t;

typedef enum {
    PS_EVENT_START = 0,   /**< operator asks STANDBY -> RAMP */
    PS_EVENT_STOP,        /**< operator asks for damping */
    PS_EVENT_ESTOP_PRESS, /**< e-stop input goes active */
    PS_EVENT_ESTOP_RELEASE,
    PS_EVENT_RESET,           /**< operator resets a latched e-stop */
    PS_EVENT_HARNESS_RELEASE, /**< sim harness lets go of the pelvis */
    PS_EVENT_DROP_REPLIES,    /**< `joint` stops replying for duration_s */
    PS_EVENT_COUNT
} ps_event_kind_t;

typedef struct {
    float t_s;
    ps_event_kind_t kind;
    char joint[PS_NAME_LEN]; /**< for DROP_REPLIES */
    float duration_s;
} ps_event_cfg_t;

typedef struct {
    char name[PS_NAME_LEN];
    float duration_s; /**< default run length, 0: until Ctrl-C */
    uint32_t seed;    /**< noise seed; same seed, same lockstep run */
    uint32_t n_pushes;
    ps_push_cfg_t pushes[PS_MAX_PUSHES];
    uint32_t n_events;
    ps_event_cfg_t events[PS_MAX_EVENTS];
} ps_scenario_cfg_t;

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
