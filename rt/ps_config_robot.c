/*
 * ps_config_robot: the robot file (robots/<name>.yaml): joint map, drivers'
 * wire ranges, gains, limits, geometry and the `sim:` section. Shared
 * machinery: ps_config_common.h. Part of the composition root: it fills
 * sim's ps_sim_devices_cfg_t, so it includes rt/ps_config_sim.h.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ps_config_common.h"
#include "../drivers/ps_imu.h"
#include "ps_config_sim.h"
#include "ps_err.h"

#define MAX_DRIVERS       8u
#define MAX_RATE_DIV      64u
#define MAX_CAN_ID        0x7ffu
#define MAX_OVERRUN_LIMIT PS_LOOP_MAX_OVERRUN_LIMIT
/* Stale data is judged within a few command periods, never seconds: a
 * timeout above this many periods of the fastest joint (or of the IMU) is
 * refused. */
#define MAX_TIMEOUT_PERIODS 10u

typedef struct {
    char name[PS_NAME_LEN];
    ps_act_range_t r;
    ps_act_motor_t m; /* optional dynamics; all 0: not modelled */
} driver_raw_t;

/* The robot file's own shape, flat as written; checked here, then composed
 * into the modules' structs (ps_act_cfg_t, ps_servo_joint_cfg_t, ...). */
typedef struct {
    uint32_t servo_hz, policy_hz;
    float ramp_s, damping_s, damping_kd_nm_s_rad, still_vel_rad_s;
    float reply_timeout_s, imu_timeout_s, policy_deadline_s;
    uint32_t overrun_limit;
    float overrun_window_s, hold_s;
    float derate_band_c, hot_margin_c, derate_min; /* defaults PS_LOOP_DEFAULT_* */
} control_file_t;

/* The file's `control:` as libcyaml loads it: the optional fields as pointers. */
typedef struct {
    control_file_t c; /* everything but the optional fields */
    float *derate_band_c, *hot_margin_c, *derate_min; /* NULL when absent */
} control_raw_t;

/* The file's `imu:`: frozen_samples is optional, its default from the rate. */
typedef struct {
    ps_imu_cfg_t imu;
    uint32_t *frozen_samples; /* NULL when absent */
} imu_raw_t;

typedef struct {
    char name[PS_NAME_LEN];
    uint32_t bus_idx, can_id, reply_id;
    ps_act_proto_id_t protocol;
    ps_act_range_t wire;  /* the driver's, motor side */
    ps_act_motor_t motor; /* the driver's dynamics, motor side */
    float pos_min_rad, pos_max_rad, vel_max_rad_s, torque_max_nm;
    float kp_nm_rad, kd_nm_s_rad, kp_max_nm_rad, kd_max_nm_s_rad;
    float stance_rad, kt_nm_a, temp_max_c;
    uint32_t rate_div;
    float gear_ratio, direction, zero_offset_rad; /* defaults 1, +1, 0 */
} joint_file_t;

typedef struct {
    char controller[PS_NAME_LEN];
    char weights[PS_PATH_LEN];
} policy_file_t;

typedef struct {
    char name[PS_NAME_LEN];
    char model[PS_PATH_LEN];
    control_file_t control;
    uint32_t n_joints;
    joint_file_t joints[PS_MAX_JOINTS];
    ps_imu_cfg_t imu;
    ps_kinematics_cfg_t kin;
    ps_sim_devices_cfg_t sim;
    policy_file_t policy;
} robot_file_t;

typedef struct {
    joint_file_t j; /* everything except `wire` and the optional fields comes from here */
    char driver[PS_NAME_LEN];
    float *gear_ratio, *direction, *zero_offset_rad; /* optional: NULL when absent */
} joint_raw_t;

typedef struct {
    char name[PS_NAME_LEN];
    char model[PS_PATH_LEN];
    control_raw_t control;
    imu_raw_t imu;
    ps_kinematics_cfg_t kin;
    ps_sim_devices_cfg_t sim;
    policy_file_t *policy; /* optional */
    driver_raw_t *drivers;
    uint32_t n_drivers;
    joint_raw_t *joints;
    uint32_t n_joints;
} robot_raw_t;

/* One CAN identifier in use on a bus, and which field claimed it. */
typedef struct {
    uint32_t bus_idx;
    uint32_t id;
    bool is_ext;
    char field[PS_CFG_FIELD_PATH_LEN];
} id_use_t;

/* The file's struct plus what only the checks need. */
typedef struct {
    robot_file_t cfg;
    uint32_t n_drivers;
    driver_raw_t drivers[MAX_DRIVERS];
    char joint_driver[PS_MAX_JOINTS][PS_NAME_LEN];
    id_use_t
        id_uses[2u * PS_MAX_JOINTS + PS_IMU_MAX_FRAMES]; /* command + reply per joint, the IMU's */
} robot_work_t;

/* The protocol words of the robot file are the protocols' own names
 * (ps_act_proto_t.name): the loader names no protocol itself. Filled before
 * each load (INIT, main thread; the same every time). */
static cyaml_strval_t PROTOCOLS[PS_ACT_PROTO_COUNT];

static void fill_protocol_names(void)
{
    for (unsigned i = 0; i < PS_ACT_PROTO_COUNT; i++)
        PROTOCOLS[i] = (cyaml_strval_t){ps_act_proto_get((ps_act_proto_id_t)i)->name, (int64_t)i};
}

static const cyaml_schema_field_t CONTROL_FIELDS[] = {
    CYAML_FIELD_UINT("servo_hz", CYAML_FLAG_DEFAULT, control_raw_t, c.servo_hz),
    CYAML_FIELD_UINT("policy_hz", CYAML_FLAG_DEFAULT, control_raw_t, c.policy_hz),
    CYAML_FIELD_FLOAT("ramp_s", CYAML_FLAG_DEFAULT, control_raw_t, c.ramp_s),
    CYAML_FIELD_FLOAT("damping_s", CYAML_FLAG_DEFAULT, control_raw_t, c.damping_s),
    CYAML_FIELD_FLOAT("damping_kd_nm_s_rad", CYAML_FLAG_DEFAULT, control_raw_t,
                      c.damping_kd_nm_s_rad),
    CYAML_FIELD_FLOAT("still_vel_rad_s", CYAML_FLAG_DEFAULT, control_raw_t, c.still_vel_rad_s),
    CYAML_FIELD_FLOAT("reply_timeout_s", CYAML_FLAG_DEFAULT, control_raw_t, c.reply_timeout_s),
    CYAML_FIELD_FLOAT("imu_timeout_s", CYAML_FLAG_DEFAULT, control_raw_t, c.imu_timeout_s),
    CYAML_FIELD_FLOAT("policy_deadline_s", CYAML_FLAG_DEFAULT, control_raw_t, c.policy_deadline_s),
    CYAML_FIELD_UINT("overrun_limit", CYAML_FLAG_DEFAULT, control_raw_t, c.overrun_limit),
    CYAML_FIELD_FLOAT("overrun_window_s", CYAML_FLAG_DEFAULT, control_raw_t, c.overrun_window_s),
    CYAML_FIELD_FLOAT("hold_s", CYAML_FLAG_DEFAULT, control_raw_t, c.hold_s),
    CYAML_FIELD_FLOAT_PTR("derate_band_c", CYAML_FLAG_OPTIONAL, control_raw_t, derate_band_c),
    CYAML_FIELD_FLOAT_PTR("hot_margin_c", CYAML_FLAG_OPTIONAL, control_raw_t, hot_margin_c),
    CYAML_FIELD_FLOAT_PTR("derate_min", CYAML_FLAG_OPTIONAL, control_raw_t, derate_min),
    CYAML_FIELD_END,
};
static const cyaml_strval_t IMU_PROTOCOLS[] = {
    {"pushstep", PS_IMU_PROTO_PUSHSTEP},
    {"xsens", PS_IMU_PROTO_XSENS},
};
static const cyaml_schema_field_t IMU_FIELDS[] = {
    CYAML_FIELD_ENUM("protocol", CYAML_FLAG_OPTIONAL | CYAML_FLAG_STRICT, imu_raw_t, imu.protocol,
                     IMU_PROTOCOLS, CYAML_ARRAY_LEN(IMU_PROTOCOLS)),
    CYAML_FIELD_UINT("bus", CYAML_FLAG_DEFAULT, imu_raw_t, imu.bus_idx),
    CYAML_FIELD_UINT("base_id", CYAML_FLAG_DEFAULT, imu_raw_t, imu.base_id),
    CYAML_FIELD_UINT("rate_div", CYAML_FLAG_DEFAULT, imu_raw_t, imu.rate_div),
    CYAML_FIELD_UINT_PTR("frozen_samples", CYAML_FLAG_OPTIONAL, imu_raw_t, frozen_samples),
    CYAML_FIELD_END,
};
static const cyaml_schema_field_t KIN_FIELDS[] = {
    CYAML_FIELD_FLOAT("mass_kg", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, mass_kg),
    CYAML_FIELD_FLOAT("hip_offset_y_m", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, hip_offset_y_m),
    CYAML_FIELD_FLOAT("hip_offset_z_m", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, hip_offset_z_m),
    CYAML_FIELD_FLOAT("thigh_m", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, thigh_m),
    CYAML_FIELD_FLOAT("shank_m", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, shank_m),
    CYAML_FIELD_FLOAT("ankle_height_m", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, ankle_height_m),
    CYAML_FIELD_FLOAT("foot_length_m", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, foot_length_m),
    CYAML_FIELD_FLOAT("foot_width_m", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, foot_width_m),
    CYAML_FIELD_FLOAT("foot_offset_x_m", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, foot_offset_x_m),
    CYAML_FIELD_FLOAT("com_offset_z_m", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, com_offset_z_m),
    CYAML_FIELD_FLOAT("fall_tilt_rad", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, fall_tilt_rad),
    CYAML_FIELD_FLOAT("fall_com_height_m", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t,
                      fall_com_height_m),
#define KIN_OPT(key, field)                                                                        \
    CYAML_FIELD_FLOAT(key, CYAML_FLAG_OPTIONAL, ps_kinematics_cfg_t, field)
    KIN_OPT("trunk_mass_kg", trunk_mass_kg),
    KIN_OPT("trunk_com_x_m", trunk_com_x_m),
    KIN_OPT("trunk_com_y_m", trunk_com_y_m),
    KIN_OPT("trunk_com_z_m", trunk_com_z_m),
    KIN_OPT("hip_mass_kg", hip_mass_kg),
    KIN_OPT("thigh_mass_kg", thigh_mass_kg),
    KIN_OPT("thigh_com_m", thigh_com_m),
    KIN_OPT("shank_mass_kg", shank_mass_kg),
    KIN_OPT("shank_com_m", shank_com_m),
    KIN_OPT("foot_mass_kg", foot_mass_kg),
    KIN_OPT("foot_com_x_m", foot_com_x_m),
    KIN_OPT("foot_com_z_m", foot_com_z_m),
#undef KIN_OPT
    CYAML_FIELD_END,
};
static const cyaml_schema_field_t SIM_FIELDS[] = {
    CYAML_FIELD_FLOAT("gyro_noise_rad_s", CYAML_FLAG_DEFAULT, ps_sim_devices_cfg_t,
                      gyro_noise_rad_s),
    CYAML_FIELD_FLOAT("gyro_bias_rad_s", CYAML_FLAG_DEFAULT, ps_sim_devices_cfg_t, gyro_bias_rad_s),
    CYAML_FIELD_FLOAT("accel_noise_m_s2", CYAML_FLAG_DEFAULT, ps_sim_devices_cfg_t,
                      accel_noise_m_s2),
    CYAML_FIELD_FLOAT("accel_bias_m_s2", CYAML_FLAG_DEFAULT, ps_sim_devices_cfg_t, accel_bias_m_s2),
    CYAML_FIELD_FLOAT("reply_latency_s", CYAML_FLAG_DEFAULT, ps_sim_devices_cfg_t, reply_latency_s),
    CYAML_FIELD_FLOAT("thermal_r_c_w", CYAML_FLAG_DEFAULT, ps_sim_devices_cfg_t, thermal_r_c_w),
    CYAML_FIELD_FLOAT("thermal_tau_s", CYAML_FLAG_DEFAULT, ps_sim_devices_cfg_t, thermal_tau_s),
    CYAML_FIELD_FLOAT("winding_r_ohm", CYAML_FLAG_DEFAULT, ps_sim_devices_cfg_t, winding_r_ohm),
    CYAML_FIELD_FLOAT("ambient_c", CYAML_FLAG_DEFAULT, ps_sim_devices_cfg_t, ambient_c),
    CYAML_FIELD_END,
};
static const cyaml_schema_field_t DRIVER_FIELDS[] = {
    CYAML_FIELD_STRING("name", CYAML_FLAG_DEFAULT, driver_raw_t, name, 1),
    CYAML_FIELD_FLOAT("p_min_rad", CYAML_FLAG_DEFAULT, driver_raw_t, r.p_min_rad),
    CYAML_FIELD_FLOAT("p_max_rad", CYAML_FLAG_DEFAULT, driver_raw_t, r.p_max_rad),
    CYAML_FIELD_FLOAT("v_min_rad_s", CYAML_FLAG_DEFAULT, driver_raw_t, r.v_min_rad_s),
    CYAML_FIELD_FLOAT("v_max_rad_s", CYAML_FLAG_DEFAULT, driver_raw_t, r.v_max_rad_s),
    CYAML_FIELD_FLOAT("kp_max_nm_rad", CYAML_FLAG_DEFAULT, driver_raw_t, r.kp_max_nm_rad),
    CYAML_FIELD_FLOAT("kd_max_nm_s_rad", CYAML_FLAG_DEFAULT, driver_raw_t, r.kd_max_nm_s_rad),
    CYAML_FIELD_FLOAT("t_min_nm", CYAML_FLAG_DEFAULT, driver_raw_t, r.t_min_nm),
    CYAML_FIELD_FLOAT("t_max_nm", CYAML_FLAG_DEFAULT, driver_raw_t, r.t_max_nm),
    CYAML_FIELD_FLOAT("i_min_a", CYAML_FLAG_DEFAULT, driver_raw_t, r.i_min_a),
    CYAML_FIELD_FLOAT("i_max_a", CYAML_FLAG_DEFAULT, driver_raw_t, r.i_max_a),
    CYAML_FIELD_FLOAT("peak_torque_nm", CYAML_FLAG_OPTIONAL, driver_raw_t, m.peak_torque_nm),
    CYAML_FIELD_FLOAT("rated_torque_nm", CYAML_FLAG_OPTIONAL, driver_raw_t, m.rated_torque_nm),
    CYAML_FIELD_FLOAT("rated_speed_rad_s", CYAML_FLAG_OPTIONAL, driver_raw_t, m.rated_speed_rad_s),
    CYAML_FIELD_FLOAT("no_load_speed_rad_s", CYAML_FLAG_OPTIONAL, driver_raw_t,
                      m.no_load_speed_rad_s),
    CYAML_FIELD_FLOAT("armature_kg_m2", CYAML_FLAG_OPTIONAL, driver_raw_t, m.armature_kg_m2),
    CYAML_FIELD_FLOAT("pd_hz", CYAML_FLAG_OPTIONAL, driver_raw_t, m.pd_hz),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t DRIVER_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_DEFAULT, driver_raw_t, DRIVER_FIELDS),
};
static const cyaml_schema_field_t JOINT_FIELDS[] = {
    CYAML_FIELD_STRING("name", CYAML_FLAG_DEFAULT, joint_raw_t, j.name, 1),
    CYAML_FIELD_UINT("bus", CYAML_FLAG_DEFAULT, joint_raw_t, j.bus_idx),
    CYAML_FIELD_UINT("can_id", CYAML_FLAG_DEFAULT, joint_raw_t, j.can_id),
    CYAML_FIELD_UINT("reply_id", CYAML_FLAG_DEFAULT, joint_raw_t, j.reply_id),
    CYAML_FIELD_ENUM("protocol", CYAML_FLAG_STRICT, joint_raw_t, j.protocol, PROTOCOLS,
                     CYAML_ARRAY_LEN(PROTOCOLS)),
    CYAML_FIELD_STRING("driver", CYAML_FLAG_DEFAULT, joint_raw_t, driver, 1),
    CYAML_FIELD_FLOAT("pos_min_rad", CYAML_FLAG_DEFAULT, joint_raw_t, j.pos_min_rad),
    CYAML_FIELD_FLOAT("pos_max_rad", CYAML_FLAG_DEFAULT, joint_raw_t, j.pos_max_rad),
    CYAML_FIELD_FLOAT("vel_max_rad_s", CYAML_FLAG_DEFAULT, joint_raw_t, j.vel_max_rad_s),
    CYAML_FIELD_FLOAT("torque_max_nm", CYAML_FLAG_DEFAULT, joint_raw_t, j.torque_max_nm),
    CYAML_FIELD_FLOAT("kp_nm_rad", CYAML_FLAG_DEFAULT, joint_raw_t, j.kp_nm_rad),
    CYAML_FIELD_FLOAT("kd_nm_s_rad", CYAML_FLAG_DEFAULT, joint_raw_t, j.kd_nm_s_rad),
    CYAML_FIELD_FLOAT("kp_max_nm_rad", CYAML_FLAG_DEFAULT, joint_raw_t, j.kp_max_nm_rad),
    CYAML_FIELD_FLOAT("kd_max_nm_s_rad", CYAML_FLAG_DEFAULT, joint_raw_t, j.kd_max_nm_s_rad),
    CYAML_FIELD_FLOAT("stance_rad", CYAML_FLAG_DEFAULT, joint_raw_t, j.stance_rad),
    CYAML_FIELD_FLOAT("kt_nm_a", CYAML_FLAG_DEFAULT, joint_raw_t, j.kt_nm_a),
    CYAML_FIELD_FLOAT("temp_max_c", CYAML_FLAG_DEFAULT, joint_raw_t, j.temp_max_c),
    CYAML_FIELD_UINT("rate_div", CYAML_FLAG_DEFAULT, joint_raw_t, j.rate_div),
    CYAML_FIELD_FLOAT_PTR("gear_ratio", CYAML_FLAG_OPTIONAL, joint_raw_t, gear_ratio),
    CYAML_FIELD_FLOAT_PTR("direction", CYAML_FLAG_OPTIONAL, joint_raw_t, direction),
    CYAML_FIELD_FLOAT_PTR("zero_offset_rad", CYAML_FLAG_OPTIONAL, joint_raw_t, zero_offset_rad),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t JOINT_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_DEFAULT, joint_raw_t, JOINT_FIELDS),
};
static const cyaml_schema_field_t POLICY_FIELDS[] = {
    CYAML_FIELD_STRING("controller", CYAML_FLAG_DEFAULT, policy_file_t, controller, 1),
    CYAML_FIELD_STRING("weights", CYAML_FLAG_OPTIONAL, policy_file_t, weights, 1),
    CYAML_FIELD_END,
};
static const cyaml_schema_field_t ROBOT_FIELDS[] = {
    CYAML_FIELD_STRING("name", CYAML_FLAG_DEFAULT, robot_raw_t, name, 1),
    CYAML_FIELD_STRING("model", CYAML_FLAG_DEFAULT, robot_raw_t, model, 1),
    CYAML_FIELD_MAPPING("control", CYAML_FLAG_DEFAULT, robot_raw_t, control, CONTROL_FIELDS),
    CYAML_FIELD_MAPPING("imu", CYAML_FLAG_DEFAULT, robot_raw_t, imu, IMU_FIELDS),
    CYAML_FIELD_MAPPING("kinematics", CYAML_FLAG_DEFAULT, robot_raw_t, kin, KIN_FIELDS),
    CYAML_FIELD_MAPPING("sim", CYAML_FLAG_DEFAULT, robot_raw_t, sim, SIM_FIELDS),
    CYAML_FIELD_MAPPING_PTR("policy", CYAML_FLAG_POINTER | CYAML_FLAG_OPTIONAL, robot_raw_t,
                            policy, POLICY_FIELDS),
    CYAML_FIELD_SEQUENCE_COUNT("drivers", CYAML_FLAG_POINTER, robot_raw_t, drivers, n_drivers,
                               &DRIVER_SCHEMA, 1, MAX_DRIVERS),
    CYAML_FIELD_SEQUENCE_COUNT("joints", CYAML_FLAG_POINTER, robot_raw_t, joints, n_joints,
                               &JOINT_SCHEMA, 1, PS_MAX_JOINTS),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t ROBOT_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_POINTER, robot_raw_t, ROBOT_FIELDS),
};

static const ps_cfg_array_t ROBOT_ARRAYS[] = {
    PS_CFG_ARRAY("joints", robot_work_t, cfg.joints, joint_file_t, cfg.n_joints),
    PS_CFG_ARRAY("drivers", robot_work_t, drivers, driver_raw_t, n_drivers),
};
enum { RA_JOINTS = 1, RA_DRIVERS = 2 };
static const ps_cfg_rule_t ROBOT_RANGES[] = {
    PS_CFG_RULE_U32(0, 0, "control.servo_hz", robot_work_t, cfg.control.servo_hz, 100.0, 4000.0),
    PS_CFG_RULE_U32(0, 0, "control.policy_hz", robot_work_t, cfg.control.policy_hz, 1.0, 1000.0),
    PS_CFG_RULE_F32(0, 0, "control.ramp_s", robot_work_t, cfg.control.ramp_s, 0.1, 10.0),
    PS_CFG_RULE_F32(0, 0, "control.damping_s", robot_work_t, cfg.control.damping_s, 0.2, 60.0),
    PS_CFG_RULE_F32(0, 0, "control.damping_kd_nm_s_rad", robot_work_t,
                    cfg.control.damping_kd_nm_s_rad, 0.0, 100.0),
    PS_CFG_RULE_F32(0, 0, "control.still_vel_rad_s", robot_work_t, cfg.control.still_vel_rad_s, 0.0,
                    10.0),
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "control.reply_timeout_s", robot_work_t,
                    cfg.control.reply_timeout_s, 0.0, 1.0),
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "control.imu_timeout_s", robot_work_t,
                    cfg.control.imu_timeout_s, 0.0, 1.0),
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "control.policy_deadline_s", robot_work_t,
                    cfg.control.policy_deadline_s, 0.0, 1.0),
    PS_CFG_RULE_U32(0, 0, "control.overrun_limit", robot_work_t, cfg.control.overrun_limit, 1.0,
                    MAX_OVERRUN_LIMIT),
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "control.overrun_window_s", robot_work_t,
                    cfg.control.overrun_window_s, 0.0, 10.0),
    PS_CFG_RULE_F32(0, 0, "control.hold_s", robot_work_t, cfg.control.hold_s, 0.0, 60.0),
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "control.derate_band_c", robot_work_t,
                    cfg.control.derate_band_c, 0.0, 100.0),
    PS_CFG_RULE_F32(0, 0, "control.hot_margin_c", robot_work_t, cfg.control.hot_margin_c, 0.0,
                    100.0),
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "control.derate_min", robot_work_t,
                    cfg.control.derate_min, 0.0, 1.0),
    PS_CFG_RULE_U32(0, 0, "imu.bus", robot_work_t, cfg.imu.bus_idx, 0.0, PS_MAX_BUSES - 1u),
    PS_CFG_RULE_U32(0, PS_CFG_RANGE_HEX, "imu.base_id", robot_work_t, cfg.imu.base_id, 1.0,
                    MAX_CAN_ID - 1u),
    PS_CFG_RULE_U32(0, 0, "imu.rate_div", robot_work_t, cfg.imu.rate_div, 1.0, MAX_RATE_DIV),
    PS_CFG_RULE_U32(0, 0, "imu.frozen_samples", robot_work_t, cfg.imu.frozen_samples, 0.0,
                    PS_IMU_FROZEN_SAMPLES_MAX),
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "kinematics.mass_kg", robot_work_t, cfg.kin.mass_kg,
                    0.0, 500.0),
    PS_CFG_RULE_F32(0, 0, "kinematics.hip_offset_y_m", robot_work_t, cfg.kin.hip_offset_y_m, 0.0,
                    1.0),
    PS_CFG_RULE_F32(0, 0, "kinematics.hip_offset_z_m", robot_work_t, cfg.kin.hip_offset_z_m, -1.0,
                    1.0),
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "kinematics.thigh_m", robot_work_t, cfg.kin.thigh_m,
                    0.0, 2.0),
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "kinematics.shank_m", robot_work_t, cfg.kin.shank_m,
                    0.0, 2.0),
    PS_CFG_RULE_F32(0, 0, "kinematics.ankle_height_m", robot_work_t, cfg.kin.ankle_height_m, 0.0,
                    1.0),
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "kinematics.foot_length_m", robot_work_t,
                    cfg.kin.foot_length_m, 0.0, 1.0),
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "kinematics.foot_width_m", robot_work_t,
                    cfg.kin.foot_width_m, 0.0, 1.0),
    PS_CFG_RULE_F32(0, 0, "kinematics.foot_offset_x_m", robot_work_t, cfg.kin.foot_offset_x_m, -0.5,
                    0.5),
    PS_CFG_RULE_F32(0, 0, "kinematics.com_offset_z_m", robot_work_t, cfg.kin.com_offset_z_m, -1.0,
                    1.0),
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "kinematics.fall_tilt_rad", robot_work_t,
                    cfg.kin.fall_tilt_rad, 0.0, 1.5708),
    PS_CFG_RULE_F32(0, 0, "kinematics.fall_com_height_m", robot_work_t, cfg.kin.fall_com_height_m,
                    0.0, 3.0),
    PS_CFG_RULE_F32(0, 0, "kinematics.trunk_mass_kg", robot_work_t, cfg.kin.trunk_mass_kg, 0.0,
                    1000.0),
    PS_CFG_RULE_F32(0, 0, "kinematics.trunk_com_x_m", robot_work_t, cfg.kin.trunk_com_x_m, -1.0,
                    1.0),
    PS_CFG_RULE_F32(0, 0, "kinematics.trunk_com_y_m", robot_work_t, cfg.kin.trunk_com_y_m, -1.0,
                    1.0),
    PS_CFG_RULE_F32(0, 0, "kinematics.trunk_com_z_m", robot_work_t, cfg.kin.trunk_com_z_m, -1.0,
                    2.0),
    PS_CFG_RULE_F32(0, 0, "kinematics.hip_mass_kg", robot_work_t, cfg.kin.hip_mass_kg, 0.0, 100.0),
    PS_CFG_RULE_F32(0, 0, "kinematics.thigh_mass_kg", robot_work_t, cfg.kin.thigh_mass_kg, 0.0,
                    100.0),
    PS_CFG_RULE_F32(0, 0, "kinematics.thigh_com_m", robot_work_t, cfg.kin.thigh_com_m, 0.0, 2.0),
    PS_CFG_RULE_F32(0, 0, "kinematics.shank_mass_kg", robot_work_t, cfg.kin.shank_mass_kg, 0.0,
                    100.0),
    PS_CFG_RULE_F32(0, 0, "kinematics.shank_com_m", robot_work_t, cfg.kin.shank_com_m, 0.0, 2.0),
    PS_CFG_RULE_F32(0, 0, "kinematics.foot_mass_kg", robot_work_t, cfg.kin.foot_mass_kg, 0.0,
                    100.0),
    PS_CFG_RULE_F32(0, 0, "kinematics.foot_com_x_m", robot_work_t, cfg.kin.foot_com_x_m, -1.0,
                    1.0),
    PS_CFG_RULE_F32(0, 0, "kinematics.foot_com_z_m", robot_work_t, cfg.kin.foot_com_z_m, -1.0,
                    1.0),
    PS_CFG_RULE_F32(0, 0, "sim.gyro_noise_rad_s", robot_work_t, cfg.sim.gyro_noise_rad_s, 0.0, 1.0),
    PS_CFG_RULE_F32(0, 0, "sim.gyro_bias_rad_s", robot_work_t, cfg.sim.gyro_bias_rad_s, 0.0, 1.0),
    PS_CFG_RULE_F32(0, 0, "sim.accel_noise_m_s2", robot_work_t, cfg.sim.accel_noise_m_s2, 0.0,
                    10.0),
    PS_CFG_RULE_F32(0, 0, "sim.accel_bias_m_s2", robot_work_t, cfg.sim.accel_bias_m_s2, 0.0, 10.0),
    PS_CFG_RULE_F32(0, 0, "sim.reply_latency_s", robot_work_t, cfg.sim.reply_latency_s, 0.0, 0.01),
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "sim.thermal_r_c_w", robot_work_t,
                    cfg.sim.thermal_r_c_w, 0.0, 100.0),
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "sim.thermal_tau_s", robot_work_t,
                    cfg.sim.thermal_tau_s, 0.0, 10000.0),
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "sim.winding_r_ohm", robot_work_t,
                    cfg.sim.winding_r_ohm, 0.0, 100.0),
    PS_CFG_RULE_F32(0, 0, "sim.ambient_c", robot_work_t, cfg.sim.ambient_c, -40.0, 85.0),
    PS_CFG_RULE_F32(RA_DRIVERS, 0, "p_min_rad", driver_raw_t, r.p_min_rad, -1000.0, 1000.0),
    PS_CFG_RULE_F32(RA_DRIVERS, 0, "p_max_rad", driver_raw_t, r.p_max_rad, -1000.0, 1000.0),
    PS_CFG_RULE_F32(RA_DRIVERS, 0, "v_min_rad_s", driver_raw_t, r.v_min_rad_s, -10000.0, 10000.0),
    PS_CFG_RULE_F32(RA_DRIVERS, 0, "v_max_rad_s", driver_raw_t, r.v_max_rad_s, -10000.0, 10000.0),
    PS_CFG_RULE_F32(RA_DRIVERS, PS_CFG_RANGE_OPEN_MIN, "kp_max_nm_rad", driver_raw_t,
                    r.kp_max_nm_rad, 0.0, 5000.0),
    PS_CFG_RULE_F32(RA_DRIVERS, PS_CFG_RANGE_OPEN_MIN, "kd_max_nm_s_rad", driver_raw_t,
                    r.kd_max_nm_s_rad, 0.0, 500.0),
    PS_CFG_RULE_F32(RA_DRIVERS, 0, "t_min_nm", driver_raw_t, r.t_min_nm, -1000.0, 1000.0),
    PS_CFG_RULE_F32(RA_DRIVERS, 0, "t_max_nm", driver_raw_t, r.t_max_nm, -1000.0, 1000.0),
    PS_CFG_RULE_F32(RA_DRIVERS, 0, "i_min_a", driver_raw_t, r.i_min_a, -1000.0, 1000.0),
    PS_CFG_RULE_F32(RA_DRIVERS, 0, "i_max_a", driver_raw_t, r.i_max_a, -1000.0, 1000.0),
    PS_CFG_RULE_F32(RA_DRIVERS, 0, "peak_torque_nm", driver_raw_t, m.peak_torque_nm, 0.0, 1000.0),
    PS_CFG_RULE_F32(RA_DRIVERS, 0, "rated_torque_nm", driver_raw_t, m.rated_torque_nm, 0.0,
                    1000.0),
    PS_CFG_RULE_F32(RA_DRIVERS, 0, "rated_speed_rad_s", driver_raw_t, m.rated_speed_rad_s, 0.0,
                    10000.0),
    PS_CFG_RULE_F32(RA_DRIVERS, 0, "no_load_speed_rad_s", driver_raw_t, m.no_load_speed_rad_s,
                    0.0, 10000.0),
    PS_CFG_RULE_F32(RA_DRIVERS, 0, "armature_kg_m2", driver_raw_t, m.armature_kg_m2, 0.0, 10.0),
    PS_CFG_RULE_F32(RA_DRIVERS, 0, "pd_hz", driver_raw_t, m.pd_hz, 0.0, 1000000.0),
    PS_CFG_RULE_U32(RA_JOINTS, 0, "bus", joint_file_t, bus_idx, 0.0, PS_MAX_BUSES - 1u),
    PS_CFG_RULE_U32(RA_JOINTS, PS_CFG_RANGE_HEX, "can_id", joint_file_t, can_id, 1.0,
                    PS_CAN_EFF_MASK),
    PS_CFG_RULE_U32(RA_JOINTS, PS_CFG_RANGE_HEX, "reply_id", joint_file_t, reply_id, 1.0,
                    PS_CAN_EFF_MASK),
    PS_CFG_RULE_F32(RA_JOINTS, 0, "pos_min_rad", joint_file_t, pos_min_rad, -1000.0, 1000.0),
    PS_CFG_RULE_F32(RA_JOINTS, 0, "pos_max_rad", joint_file_t, pos_max_rad, -1000.0, 1000.0),
    PS_CFG_RULE_F32(RA_JOINTS, PS_CFG_RANGE_OPEN_MIN, "vel_max_rad_s", joint_file_t, vel_max_rad_s,
                    0.0, 10000.0),
    PS_CFG_RULE_F32(RA_JOINTS, PS_CFG_RANGE_OPEN_MIN, "torque_max_nm", joint_file_t, torque_max_nm,
                    0.0, 1000.0),
    PS_CFG_RULE_F32(RA_JOINTS, 0, "kp_nm_rad", joint_file_t, kp_nm_rad, 0.0, 5000.0),
    PS_CFG_RULE_F32(RA_JOINTS, 0, "kd_nm_s_rad", joint_file_t, kd_nm_s_rad, 0.0, 500.0),
    PS_CFG_RULE_F32(RA_JOINTS, PS_CFG_RANGE_OPEN_MIN, "kp_max_nm_rad", joint_file_t, kp_max_nm_rad,
                    0.0, 5000.0),
    PS_CFG_RULE_F32(RA_JOINTS, PS_CFG_RANGE_OPEN_MIN, "kd_max_nm_s_rad", joint_file_t,
                    kd_max_nm_s_rad, 0.0, 500.0),
    PS_CFG_RULE_F32(RA_JOINTS, 0, "stance_rad", joint_file_t, stance_rad, -1000.0, 1000.0),
    PS_CFG_RULE_F32(RA_JOINTS, PS_CFG_RANGE_OPEN_MIN, "kt_nm_a", joint_file_t, kt_nm_a, 0.0, 100.0),
    PS_CFG_RULE_F32(RA_JOINTS, 0, "temp_max_c", joint_file_t, temp_max_c, 20.0, 200.0),
    PS_CFG_RULE_U32(RA_JOINTS, 0, "rate_div", joint_file_t, rate_div, 1.0, MAX_RATE_DIV),
    PS_CFG_RULE_F32(RA_JOINTS, PS_CFG_RANGE_OPEN_MIN, "gear_ratio", joint_file_t, gear_ratio, 0.0,
                    1000.0),
    PS_CFG_RULE_F32(RA_JOINTS, 0, "direction", joint_file_t, direction, -1.0, 1.0),
    PS_CFG_RULE_F32(RA_JOINTS, 0, "zero_offset_rad", joint_file_t, zero_offset_rad, -1000.0,
                    1000.0),
};

/* Field name pairs that must satisfy min < max, per driver. */
static int check_drivers(ps_cfg_ctx_t *c, const robot_work_t *w)
{
    char field[PS_CFG_FIELD_PATH_LEN];
    for (uint32_t i = 0; i < w->n_drivers; i++) {
        const driver_raw_t *d = &w->drivers[i];
        for (uint32_t k = 0; k < i; k++) {
            if (strcmp(d->name, w->drivers[k].name) == 0) {
                (void)snprintf(field, sizeof(field), "drivers[%u].name", i);
                return ps_cfg_fail_field(
                    c, field, "duplicate driver name \"%s\" (also drivers[%u])", d->name, k);
            }
        }
        const struct {
            const char *min_key, *max_key;
            float min, max;
        } pairs[] = {
            {"p_min_rad", "p_max_rad", d->r.p_min_rad, d->r.p_max_rad},
            {"v_min_rad_s", "v_max_rad_s", d->r.v_min_rad_s, d->r.v_max_rad_s},
            {"t_min_nm", "t_max_nm", d->r.t_min_nm, d->r.t_max_nm},
            {"i_min_a", "i_max_a", d->r.i_min_a, d->r.i_max_a},
        };
        for (size_t p = 0; p < sizeof(pairs) / sizeof(pairs[0]); p++) {
            if (!(pairs[p].min < pairs[p].max)) {
                (void)snprintf(field, sizeof(field), "drivers[%u].%s", i, pairs[p].max_key);
                return ps_cfg_fail_field(c, field, "value %g not above %s %g", (double)pairs[p].max,
                                         pairs[p].min_key, (double)pairs[p].min);
            }
        }
        /* The dynamics: all or nothing, consistent; the message starts with the key. */
        char why[PS_ERR_MSG_LEN];
        if (ps_act_check_motor(&d->m, why, sizeof(why)) != 0) {
            const char *colon = strchr(why, ':');
            const int key_len = colon != NULL ? (int)(colon - why) : (int)strlen(why);
            (void)snprintf(field, sizeof(field), "drivers[%u].%.*s", i, key_len, why);
            /* an absent key has no line: the driver's entry has one */
            char entry[PS_CFG_FIELD_PATH_LEN];
            (void)snprintf(entry, sizeof(entry), "drivers[%u].name", i);
            const uint32_t line = ps_cfg_line_of(c, field) ? ps_cfg_line_of(c, field)
                                                           : ps_cfg_line_of(c, entry);
            return ps_cfg_fail_at(c, line, field,
                                  "%s (give all six of peak_torque_nm, rated_torque_nm, "
                                  "rated_speed_rad_s, no_load_speed_rad_s, armature_kg_m2, "
                                  "pd_hz, or none)",
                                  colon != NULL ? colon + 2 : why);
        }
    }
    return 0;
}

/* Finds the driver of every joint and copies its wire ranges. */
static int resolve_drivers(ps_cfg_ctx_t *c, robot_work_t *w)
{
    char field[PS_CFG_FIELD_PATH_LEN];
    for (uint32_t i = 0; i < w->cfg.n_joints; i++) {
        uint32_t d = 0;
        while (d < w->n_drivers && strcmp(w->drivers[d].name, w->joint_driver[i]) != 0)
            d++;
        if (d < w->n_drivers) {
            w->cfg.joints[i].wire = w->drivers[d].r;
            w->cfg.joints[i].motor = w->drivers[d].m;
            continue;
        }
        char known[PS_ERR_MSG_LEN / 2] = "";
        size_t used = 0;
        for (uint32_t k = 0; k < w->n_drivers && used < sizeof(known); k++) {
            const int n = snprintf(known + used, sizeof(known) - used, "%s%s", k > 0 ? ", " : "",
                                   w->drivers[k].name);
            if (n < 0)
                break;
            used += (size_t)n;
        }
        (void)snprintf(field, sizeof(field), "joints[%u].driver", i);
        return ps_cfg_fail_field(c, field, "unknown driver \"%s\" (known: %s)", w->joint_driver[i],
                                 known);
    }
    return 0;
}

/* Limits of one joint against each other and against its driver's wire range. */
/* The actuator part of a joint as the modules see it. */
static ps_act_cfg_t act_of(const joint_file_t *j)
{
    const ps_act_cfg_t a = {
        .bus_idx = j->bus_idx,
        .can_id = j->can_id,
        .reply_id = j->reply_id,
        .protocol = j->protocol,
        .wire = j->wire,
        .gear_ratio = j->gear_ratio,
        .direction = j->direction,
        .zero_offset_rad = j->zero_offset_rad,
        .kt_nm_a = j->kt_nm_a,
        .temp_max_c = j->temp_max_c,
        .rate_div = j->rate_div,
        .motor = j->motor,
    };
    return a;
}

/* Limits of one joint against each other and against its driver's wire
 * range seen from the joint (gear ratio, direction and zero offset applied). */
static int check_joint_limits(ps_cfg_ctx_t *c, const robot_work_t *w, uint32_t i)
{
    const joint_file_t *j = &w->cfg.joints[i];
    char field[PS_CFG_FIELD_PATH_LEN];
    if (j->direction != 1.0f && j->direction != -1.0f) {
        (void)snprintf(field, sizeof(field), "joints[%u].direction", i);
        return ps_cfg_fail_field(c, field, "value %g is not 1 or -1", (double)j->direction);
    }
    const ps_act_cfg_t act = act_of(j);
    const ps_act_proto_t *proto = ps_act_proto_get(j->protocol);
    if (j->can_id > proto->id_max || j->reply_id > proto->id_max) {
        const bool is_cmd = j->can_id > proto->id_max;
        (void)snprintf(field, sizeof(field), "joints[%u].%s", i, is_cmd ? "can_id" : "reply_id");
        return ps_cfg_fail_field(c, field, "value 0x%x above protocol %s's largest id 0x%x",
                                 is_cmd ? j->can_id : j->reply_id, proto->name, proto->id_max);
    }
    if (j->can_id < proto->can_id_min) {
        (void)snprintf(field, sizeof(field), "joints[%u].can_id", i);
        return ps_cfg_fail_field(c, field, "value 0x%x below protocol %s's smallest drive id 0x%x",
                                 j->can_id, proto->name, proto->can_id_min);
    }
    ps_act_range_t wire_joint;
    ps_act_joint_range(&act, &wire_joint);
    const ps_act_range_t *r = &wire_joint;
    const char *drv = w->joint_driver[i];
#define JFIELD(key) ((void)snprintf(field, sizeof(field), "joints[%u]." key, i), field)
    if (!(j->pos_min_rad < j->pos_max_rad))
        return ps_cfg_fail_field(c, JFIELD("pos_max_rad"), "value %g not above pos_min_rad %g",
                                 (double)j->pos_max_rad, (double)j->pos_min_rad);
    if (j->pos_min_rad < r->p_min_rad || j->pos_min_rad > r->p_max_rad)
        return ps_cfg_fail_field(
            c, JFIELD("pos_min_rad"), "value %g outside driver \"%s\" wire range [%g, %g]",
            (double)j->pos_min_rad, drv, (double)r->p_min_rad, (double)r->p_max_rad);
    if (j->pos_max_rad < r->p_min_rad || j->pos_max_rad > r->p_max_rad)
        return ps_cfg_fail_field(
            c, JFIELD("pos_max_rad"), "value %g outside driver \"%s\" wire range [%g, %g]",
            (double)j->pos_max_rad, drv, (double)r->p_min_rad, (double)r->p_max_rad);
    if (j->stance_rad < j->pos_min_rad || j->stance_rad > j->pos_max_rad)
        return ps_cfg_fail_field(c, JFIELD("stance_rad"), "value %g outside joint limits [%g, %g]",
                                 (double)j->stance_rad, (double)j->pos_min_rad,
                                 (double)j->pos_max_rad);
    if (-j->vel_max_rad_s < r->v_min_rad_s || j->vel_max_rad_s > r->v_max_rad_s)
        return ps_cfg_fail_field(
            c, JFIELD("vel_max_rad_s"), "+/-%g outside driver \"%s\" wire range [%g, %g]",
            (double)j->vel_max_rad_s, drv, (double)r->v_min_rad_s, (double)r->v_max_rad_s);
    if (-j->torque_max_nm < r->t_min_nm || j->torque_max_nm > r->t_max_nm)
        return ps_cfg_fail_field(
            c, JFIELD("torque_max_nm"), "+/-%g outside driver \"%s\" wire range [%g, %g]",
            (double)j->torque_max_nm, drv, (double)r->t_min_nm, (double)r->t_max_nm);
    /* The drive's peak torque seen from the joint (gear ratio N multiplies torque). */
    const float peak_joint_nm = j->motor.peak_torque_nm * j->gear_ratio;
    if (ps_act_motor_is_modelled(&j->motor) && j->torque_max_nm > peak_joint_nm * (1.0f + 1e-6f))
        return ps_cfg_fail_field(c, JFIELD("torque_max_nm"),
                                 "value %g above driver \"%s\" peak torque %g at the joint",
                                 (double)j->torque_max_nm, drv, (double)peak_joint_nm);
    if (j->kp_max_nm_rad > r->kp_max_nm_rad)
        return ps_cfg_fail_field(c, JFIELD("kp_max_nm_rad"),
                                 "value %g above driver \"%s\" kp_max_nm_rad %g",
                                 (double)j->kp_max_nm_rad, drv, (double)r->kp_max_nm_rad);
    if (j->kd_max_nm_s_rad > r->kd_max_nm_s_rad)
        return ps_cfg_fail_field(c, JFIELD("kd_max_nm_s_rad"),
                                 "value %g above driver \"%s\" kd_max_nm_s_rad %g",
                                 (double)j->kd_max_nm_s_rad, drv, (double)r->kd_max_nm_s_rad);
    if (j->kp_nm_rad > j->kp_max_nm_rad)
        return ps_cfg_fail_field(c, JFIELD("kp_nm_rad"), "value %g above kp_max_nm_rad %g",
                                 (double)j->kp_nm_rad, (double)j->kp_max_nm_rad);
    if (j->kd_nm_s_rad > j->kd_max_nm_s_rad)
        return ps_cfg_fail_field(c, JFIELD("kd_nm_s_rad"), "value %g above kd_max_nm_s_rad %g",
                                 (double)j->kd_nm_s_rad, (double)j->kd_max_nm_s_rad);
    if (w->cfg.control.damping_kd_nm_s_rad > j->kd_max_nm_s_rad)
        return ps_cfg_fail_field(
            c, "control.damping_kd_nm_s_rad", "value %g above joints[%u].kd_max_nm_s_rad %g",
            (double)w->cfg.control.damping_kd_nm_s_rad, i, (double)j->kd_max_nm_s_rad);
#undef JFIELD
    return 0;
}

/* 11-bit and 29-bit identifiers are different frames even with one value. */
/* Timeouts in periods, not seconds: the policy runs inside one servo tick,
 * so its deadline is at most half the period (the other half is the rest of
 * the tick and the wake-up latency); a reply or IMU sample counts as stale
 * after at most MAX_TIMEOUT_PERIODS of its own period. */
static int check_timing(ps_cfg_ctx_t *c, const robot_work_t *w)
{
    const control_file_t *ctl = &w->cfg.control;
    const double period_s = 1.0 / (double)ctl->servo_hz;
    if ((double)ctl->policy_deadline_s > 0.5 * period_s * (1.0 + 1e-6))
        return ps_cfg_fail_field(
            c, "control.policy_deadline_s",
            "value %g does not fit in the servo period: at most half of 1/servo_hz "
            "= %g s",
            (double)ctl->policy_deadline_s, 0.5 * period_s);
    uint32_t min_div = UINT32_MAX;
    for (uint32_t i = 0; i < w->cfg.n_joints; i++)
        min_div = w->cfg.joints[i].rate_div < min_div ? w->cfg.joints[i].rate_div : min_div;
    const double reply_max_s = MAX_TIMEOUT_PERIODS * (double)min_div * period_s;
    if (w->cfg.n_joints > 0 && (double)ctl->reply_timeout_s > reply_max_s * (1.0 + 1e-6))
        return ps_cfg_fail_field(c, "control.reply_timeout_s",
                                 "value %g is more than %u command periods of the fastest joint "
                                 "(rate_div %u at %u Hz): at most %g s",
                                 (double)ctl->reply_timeout_s, MAX_TIMEOUT_PERIODS, min_div,
                                 ctl->servo_hz, reply_max_s);
    const double imu_max_s = MAX_TIMEOUT_PERIODS * (double)w->cfg.imu.rate_div * period_s;
    if ((double)ctl->imu_timeout_s > imu_max_s * (1.0 + 1e-6))
        return ps_cfg_fail_field(
            c, "control.imu_timeout_s",
            "value %g is more than %u IMU sample periods (rate_div %u at %u Hz): at "
            "most %g s",
            (double)ctl->imu_timeout_s, MAX_TIMEOUT_PERIODS, w->cfg.imu.rate_div, ctl->servo_hz,
            imu_max_s);
    return 0;
}

static int claim_id(ps_cfg_ctx_t *c, id_use_t *uses, uint32_t *n_uses, uint32_t bus_idx,
                    uint32_t id, bool is_ext, const char *field, const char *yaml_field)
{
    for (uint32_t k = 0; k < *n_uses; k++) {
        if (uses[k].bus_idx == bus_idx && uses[k].id == id && uses[k].is_ext == is_ext)
            return ps_cfg_fail_field(c, yaml_field, "id 0x%03x on bus %u already used by %s", id,
                                     bus_idx, uses[k].field);
    }
    uses[*n_uses].bus_idx = bus_idx;
    uses[*n_uses].id = id;
    uses[*n_uses].is_ext = is_ext;
    (void)snprintf(uses[*n_uses].field, sizeof(uses[0].field), "%s", field);
    (*n_uses)++;
    return 0;
}

static int check_robot(ps_cfg_ctx_t *c, robot_work_t *w)
{
    int rc = ps_cfg_check_ranges(c, w);
    if (rc == 0)
        rc = check_drivers(c, w);
    if (rc == 0)
        rc = resolve_drivers(c, w);
    if (rc != 0)
        return rc;

    const control_file_t *ctl = &w->cfg.control;
    if (ctl->policy_hz > ctl->servo_hz || ctl->servo_hz % ctl->policy_hz != 0)
        return ps_cfg_fail_field(c, "control.policy_hz",
                                 "servo_hz %u is not a multiple of policy_hz %u", ctl->servo_hz,
                                 ctl->policy_hz);
    const int trc = check_timing(c, w);
    if (trc != 0)
        return trc;
    /* The derating band needs a width; the message names a field the file
     * has (either may be left at its default). */
    if (!(ctl->derate_band_c > ctl->hot_margin_c)) {
        if (ps_cfg_line_of(c, "control.derate_band_c") == 0)
            return ps_cfg_fail_field(c, "control.hot_margin_c",
                                     "value %g not below derate_band_c %g (its default): "
                                     "derating must start before the drive is hot",
                                     (double)ctl->hot_margin_c, (double)ctl->derate_band_c);
        return ps_cfg_fail_field(c, "control.derate_band_c",
                                 "value %g not above hot_margin_c %g: derating must start "
                                 "before the drive is hot",
                                 (double)ctl->derate_band_c, (double)ctl->hot_margin_c);
    }
    if (w->cfg.imu.frozen_samples == 1u)
        return ps_cfg_fail_field(c, "imu.frozen_samples",
                                 "value 1 is neither 0 (off) nor a run of at least 2 samples");
    const policy_file_t *pol = &w->cfg.policy;
    if (pol->controller[0] != '\0' && ps_config_policy_find(pol->controller) < 0)
        return ps_cfg_fail_field(c, "policy.controller", "\"%s\" is not one of %s",
                                 pol->controller, PS_CONFIG_POLICY_NAMES);
    if (strcmp(pol->controller, "mlp") == 0 && pol->weights[0] == '\0')
        return ps_cfg_fail_field(c, "policy.weights",
                                 "controller mlp needs a policy file (weights: PATH)");
    /* The mass model, when given, accounts for the whole mass. */
    const ps_kinematics_cfg_t *kin = &w->cfg.kin;
    const float parts = kin->trunk_mass_kg + 2.0f * (kin->hip_mass_kg + kin->thigh_mass_kg +
                                                     kin->shank_mass_kg + kin->foot_mass_kg);
    if (parts > 0.0f &&
        (kin->trunk_mass_kg <= 0.0f || fabsf(parts - kin->mass_kg) > 0.01f * kin->mass_kg))
        return ps_cfg_fail_field(c, "kinematics.trunk_mass_kg",
                                 "the mass model (trunk %g + 2 x legs %g = %g kg) does not add up "
                                 "to mass_kg %g within 1 %%",
                                 (double)kin->trunk_mass_kg,
                                 (double)(parts - kin->trunk_mass_kg) / 2.0, (double)parts,
                                 (double)kin->mass_kg);
    /* Every device is sampled on every policy tick only if its divider
     * divides the number of servo ticks per policy tick. */
    const uint32_t ticks_per_policy = ctl->servo_hz / ctl->policy_hz;
    if (ticks_per_policy % w->cfg.imu.rate_div != 0)
        return ps_cfg_fail_field(c, "imu.rate_div",
                                 "value %u does not divide servo_hz/policy_hz = %u",
                                 w->cfg.imu.rate_div, ticks_per_policy);

    char field[PS_CFG_FIELD_PATH_LEN];
    id_use_t *uses = w->id_uses;
    uint32_t n_uses = 0;
    /* Every frame of the IMU's message has an identifier of its own. */
    uint32_t imu_ids[PS_IMU_MAX_FRAMES];
    uint8_t imu_lens[PS_IMU_MAX_FRAMES];
    const unsigned n_imu = ps_imu_frames(&w->cfg.imu, imu_ids, imu_lens);
    for (unsigned k = 0; k < n_imu && rc == 0; k++) {
        char owner[PS_CFG_FIELD_PATH_LEN];
        (void)snprintf(owner, sizeof(owner), "imu.base_id+%u", imu_ids[k] - w->cfg.imu.base_id);
        if (imu_ids[k] > MAX_CAN_ID)
            return ps_cfg_fail_field(c, "imu.base_id",
                                     "value 0x%x puts the %s IMU's frame %s at 0x%x, beyond 11 "
                                     "bits",
                                     w->cfg.imu.base_id, ps_imu_proto_name(w->cfg.imu.protocol),
                                     owner, imu_ids[k]);
        rc = claim_id(c, uses, &n_uses, w->cfg.imu.bus_idx, imu_ids[k], false,
                      k ? owner : "imu.base_id", "imu.base_id");
    }
    for (uint32_t i = 0; i < w->cfg.n_joints && rc == 0; i++) {
        const joint_file_t *j = &w->cfg.joints[i];
        const bool is_ext = ps_act_proto_get(j->protocol)->id_bits > 11u;
        for (uint32_t k = 0; k < i; k++) {
            if (strcmp(j->name, w->cfg.joints[k].name) == 0) {
                (void)snprintf(field, sizeof(field), "joints[%u].name", i);
                return ps_cfg_fail_field(c, field, "duplicate joint name \"%s\" (also joints[%u])",
                                         j->name, k);
            }
        }
        rc = check_joint_limits(c, w, i);
        if (rc != 0)
            return rc;
        if (ticks_per_policy % j->rate_div != 0) {
            (void)snprintf(field, sizeof(field), "joints[%u].rate_div", i);
            return ps_cfg_fail_field(c, field, "value %u does not divide servo_hz/policy_hz = %u",
                                     j->rate_div, ticks_per_policy);
        }
        char owner[PS_CFG_FIELD_PATH_LEN];
        (void)snprintf(owner, sizeof(owner), "joints[%u].can_id", i);
        rc = claim_id(c, uses, &n_uses, j->bus_idx, j->can_id, is_ext, owner, owner);
        /* A host id shared by every drive (reply_id of such a protocol) is no
         * identifier of its own: the drive id inside the frames tells them apart. */
        if (rc == 0 && !ps_act_proto_get(j->protocol)->is_reply_id_shared) {
            (void)snprintf(owner, sizeof(owner), "joints[%u].reply_id", i);
            rc = claim_id(c, uses, &n_uses, j->bus_idx, j->reply_id, is_ext, owner, owner);
        }
    }
    return rc;
}

/* The checked file into the modules' structs. */
static void compose_robot(const robot_file_t *f, ps_robot_cfg_t *out)
{
    memset(out, 0, sizeof(*out));
    memcpy(out->name, f->name, sizeof(out->name));
    memcpy(out->model, f->model, sizeof(out->model));
    const control_file_t *c = &f->control;
    out->control = (ps_control_cfg_t){
        .servo_hz = c->servo_hz,
        .policy_hz = c->policy_hz,
        .ramp_s = c->ramp_s,
        .damping_s = c->damping_s,
        .still_vel_rad_s = c->still_vel_rad_s,
        .reply_timeout_s = c->reply_timeout_s,
        .imu_timeout_s = c->imu_timeout_s,
        .policy_deadline_s = c->policy_deadline_s,
        .overrun_limit = c->overrun_limit,
        .overrun_window_s = c->overrun_window_s,
        .hold_s = c->hold_s,
        .derate_band_c = c->derate_band_c,
        .hot_margin_c = c->hot_margin_c,
        .derate_min = c->derate_min,
    };
    out->servo_common.damping_kd_nm_s_rad = c->damping_kd_nm_s_rad;
    out->n_joints = f->n_joints;
    for (uint32_t i = 0; i < f->n_joints; i++) {
        const joint_file_t *j = &f->joints[i];
        memcpy(out->joint_name[i], j->name, PS_NAME_LEN);
        out->act[i] = act_of(j);
        ps_servo_joint_cfg_t *s = &out->servo[i];
        s->lim = (ps_act_limits_t){
            .pos_min_rad = j->pos_min_rad,
            .pos_max_rad = j->pos_max_rad,
            .vel_max_rad_s = j->vel_max_rad_s,
            .torque_max_nm = j->torque_max_nm,
            .kp_max_nm_rad = j->kp_max_nm_rad,
            .kd_max_nm_s_rad = j->kd_max_nm_s_rad,
        };
        s->kp_nm_rad = j->kp_nm_rad;
        s->kd_nm_s_rad = j->kd_nm_s_rad;
        s->stance_rad = j->stance_rad;
        ps_act_joint_range(&out->act[i], &s->wire);
    }
    out->imu = f->imu;
    out->kin = f->kin;
    memcpy(out->policy, f->policy.controller, sizeof(out->policy));
    memcpy(out->policy_weights, f->policy.weights, sizeof(out->policy_weights));
}

int ps_config_policy_find(const char *name)
{
    static const char *const NAMES[] = {"stand", "capture", "mlp"};
    for (int i = 0; name != NULL && i < 3; i++)
        if (strcmp(name, NAMES[i]) == 0)
            return i;
    return -ENOENT;
}

/* Where the fields that other files refer to are (ps_config_check_pair). */
static void record_src(const ps_cfg_ctx_t *c, ps_robot_cfg_t *out)
{
    ps_robot_src_t *src = &out->src;
    (void)snprintf(src->path, sizeof(src->path), "%s", c->path); /* truncation is acceptable */
    char field[PS_CFG_FIELD_PATH_LEN];
    for (uint32_t i = 0; i < out->n_joints && i < PS_MAX_JOINTS; i++) {
        (void)snprintf(field, sizeof(field), "joints[%u].name", i);
        src->joint_name_line[i] = ps_cfg_line_of(c, field);
        (void)snprintf(field, sizeof(field), "joints[%u].bus", i);
        src->joint_bus_line[i] = ps_cfg_line_of(c, field);
        (void)snprintf(field, sizeof(field), "joints[%u].protocol", i);
        src->joint_protocol_line[i] = ps_cfg_line_of(c, field);
    }
    src->imu_bus_line = ps_cfg_line_of(c, "imu.bus");
    src->model_line = ps_cfg_line_of(c, "model");
}

/* One load of a robot file; out_sim (if not NULL) gets its `sim:` section. */
static int load_robot_file(const char *path, ps_robot_cfg_t *out, ps_sim_devices_cfg_t *out_sim,
                           char *err, size_t err_len);

static int load_robot(const char *path, ps_robot_cfg_t *out, ps_sim_devices_cfg_t *out_sim,
                      char *err, size_t err_len)
{
    fill_protocol_names();
    return load_robot_file(path, out, out_sim, err, err_len);
}

static int load_robot_file(const char *path, ps_robot_cfg_t *out, ps_sim_devices_cfg_t *out_sim,
                           char *err, size_t err_len)
{
    ps_cfg_ctx_t c;
    int rc = ps_cfg_ctx_open(&c, path, err, err_len, ROBOT_ARRAYS, ROBOT_RANGES,
                             PS_CFG_COUNT(ROBOT_RANGES));
    robot_raw_t *raw = NULL;
    if (rc == 0)
        rc = ps_cfg_load_file(&c, &ROBOT_SCHEMA, (void **)&raw);

    /* ~6 KB: heap, not the caller's (possibly small) stack. */
    robot_work_t *w = rc == 0 ? calloc(1, sizeof(*w)) : NULL;
    if (rc == 0 && w == NULL)
        rc = -ENOMEM;
    if (rc == 0) {
        robot_file_t *r = &w->cfg;
        memcpy(r->name, raw->name, sizeof(r->name));
        memcpy(r->model, raw->model, sizeof(r->model));
        r->control = raw->control.c;
        const control_raw_t *cr = &raw->control;
        r->control.derate_band_c =
            cr->derate_band_c != NULL ? *cr->derate_band_c : PS_LOOP_DEFAULT_DERATE_BAND_C;
        r->control.hot_margin_c =
            cr->hot_margin_c != NULL ? *cr->hot_margin_c : PS_LOOP_DEFAULT_HOT_MARGIN_C;
        r->control.derate_min =
            cr->derate_min != NULL ? *cr->derate_min : PS_LOOP_DEFAULT_DERATE_MIN;
        r->imu = raw->imu.imu;
        /* Default: as many samples as the IMU sends in PS_IMU_FROZEN_DEFAULT_S
         * (servo_hz and rate_div are range-checked later; guard the division). */
        const uint32_t imu_div = raw->imu.imu.rate_div > 0 ? raw->imu.imu.rate_div : 1u;
        r->imu.frozen_samples =
            raw->imu.frozen_samples != NULL
                ? *raw->imu.frozen_samples
                : ps_imu_frozen_default(raw->control.c.servo_hz / imu_div);
        r->kin = raw->kin;
        r->sim = raw->sim;
        if (raw->policy != NULL)
            r->policy = *raw->policy;
        w->n_drivers = raw->n_drivers; /* libcyaml enforced the maxima */
        memcpy(w->drivers, raw->drivers, raw->n_drivers * sizeof(w->drivers[0]));
        r->n_joints = raw->n_joints;
        for (uint32_t i = 0; i < raw->n_joints; i++) {
            const joint_raw_t *jr = &raw->joints[i];
            r->joints[i] = jr->j;
            r->joints[i].gear_ratio = jr->gear_ratio != NULL ? *jr->gear_ratio : 1.0f;
            r->joints[i].direction = jr->direction != NULL ? *jr->direction : 1.0f;
            r->joints[i].zero_offset_rad =
                jr->zero_offset_rad != NULL ? *jr->zero_offset_rad : 0.0f;
            memcpy(w->joint_driver[i], jr->driver, PS_NAME_LEN);
        }
    }
    if (raw != NULL)
        (void)cyaml_free(&c.cyaml, &ROBOT_SCHEMA, raw, 0); /* only fails on a NULL schema */
    if (rc == 0)
        rc = check_robot(&c, w);
    if (rc == 0) {
        compose_robot(&w->cfg, out);
        record_src(&c, out);
        if (out_sim != NULL)
            *out_sim = w->cfg.sim;
    }
    free(w);
    ps_cfg_ctx_close(&c);
    return rc;
}

int ps_config_load_robot(const char *path, ps_robot_cfg_t *out, char *err, size_t err_len)
{
    if (path == NULL || out == NULL)
        return -EINVAL;
    return load_robot(path, out, NULL, err, err_len);
}

int ps_config_load_robot_sim(const char *path, ps_robot_cfg_t *out, ps_sim_devices_cfg_t *out_sim,
                             char *err, size_t err_len)
{
    if (path == NULL || out == NULL || out_sim == NULL)
        return -EINVAL;
    return load_robot(path, out, out_sim, err, err_len);
}

int ps_config_find_joint(const ps_robot_cfg_t *r, const char *name)
{
    if (r == NULL || name == NULL)
        return -ENOENT;
    for (uint32_t i = 0; i < r->n_joints && i < PS_MAX_JOINTS; i++) {
        if (strncmp(r->joint_name[i], name, PS_NAME_LEN) == 0)
            return (int)i;
    }
    return -ENOENT;
}
