/*
 * ps_config_scenario: the scenario file (scenarios/<name>.yaml, simulation
 * only) and its check against the robot. Shared machinery:
 * ps_config_common.h. Fills sim's ps_scenario_cfg_t: composition root.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ps_config_common.h"
#include "ps_config_sim.h"
#include "ps_err.h"

typedef struct {
    float x_m, y_m, yaw_rad;
} spawn_raw_t;

typedef struct {
    char name[PS_NAME_LEN];
    float duration_s;
    uint32_t seed;
    ps_event_cfg_t *events;
    uint32_t n_events;
    ps_push_cfg_t *pushes;
    uint32_t n_pushes;
    spawn_raw_t robot;
    ps_crowd_cfg_t crowd;
} scenario_raw_t;

static const cyaml_schema_value_t FLOAT_SCHEMA = {
    CYAML_VALUE_FLOAT(CYAML_FLAG_DEFAULT, float),
};

/* ---- the crowd section --------------------------------------------------- */

static const cyaml_strval_t LAYOUTS[] = {
    {"lattice", PS_CROWD_LAYOUT_LATTICE},
    {"random", PS_CROWD_LAYOUT_RANDOM},
    {"line", PS_CROWD_LAYOUT_LINE},
};
static_assert(sizeof(LAYOUTS) / sizeof(LAYOUTS[0]) == PS_CROWD_LAYOUT_COUNT, "one name per layout");
static const cyaml_strval_t GOALS[] = {
    {"hold", PS_CROWD_GOAL_HOLD},
    {"direction", PS_CROWD_GOAL_DIRECTION},
    {"point", PS_CROWD_GOAL_POINT},
    {"robot", PS_CROWD_GOAL_ROBOT},
};
static_assert(sizeof(GOALS) / sizeof(GOALS[0]) == PS_CROWD_GOAL_COUNT, "one name per goal");
static const cyaml_strval_t CROWD_EVENT_KINDS[] = {
    {"push", PS_CROWD_EVENT_PUSH},
    {"surge", PS_CROWD_EVENT_SURGE},
    {"wall", PS_CROWD_EVENT_WALL},
};
static_assert(sizeof(CROWD_EVENT_KINDS) / sizeof(CROWD_EVENT_KINDS[0]) == PS_CROWD_EVENT_COUNT,
              "one name per crowd event");
static const cyaml_strval_t PROFILES[] = {
    {"constant", PS_CROWD_PROFILE_CONSTANT},
    {"half_sine", PS_CROWD_PROFILE_HALF_SINE},
};
static_assert(sizeof(PROFILES) / sizeof(PROFILES[0]) == PS_CROWD_PROFILE_COUNT,
              "one name per profile");

#define F32(key, S, m) CYAML_FIELD_FLOAT(key, CYAML_FLAG_OPTIONAL, S, m)
static const cyaml_schema_field_t RECT_FIELDS[] = {
    F32("x_min_m", ps_crowd_rect_t, x_min_m), F32("y_min_m", ps_crowd_rect_t, y_min_m),
    F32("x_max_m", ps_crowd_rect_t, x_max_m), F32("y_max_m", ps_crowd_rect_t, y_max_m),
    CYAML_FIELD_END,
};
static const cyaml_schema_field_t SOCIAL_FIELDS[] = {
    F32("v0_m_s", ps_social_params_t, v0_m_s),
    F32("tau_s", ps_social_params_t, tau_s),
    F32("a_n", ps_social_params_t, a_n),
    F32("b_m", ps_social_params_t, b_m),
    F32("wall_a_n", ps_social_params_t, wall_a_n),
    F32("wall_b_m", ps_social_params_t, wall_b_m),
    F32("lambda", ps_social_params_t, lambda),
    F32("range_m", ps_social_params_t, range_m),
    F32("evasive_n", ps_social_params_t, evasive_n),
    F32("evasive_range_m", ps_social_params_t, evasive_range_m),
    CYAML_FIELD_END,
};
static const cyaml_schema_field_t BODY_FIELDS[] = {
    F32("body_k_n_m", ps_crowd_body_cfg_t, body_k_n_m),
    F32("body_damping", ps_crowd_body_cfg_t, body_damping),
    F32("friction", ps_crowd_body_cfg_t, friction),
    F32("sliding_kappa", ps_crowd_body_cfg_t, sliding_kappa),
    F32("bos_m", ps_crowd_body_cfg_t, bos_m),
    F32("ankle_k_ratio", ps_crowd_body_cfg_t, ankle_k_ratio),
    F32("step_time_s", ps_crowd_body_cfg_t, step_time_s),
    F32("step_max_m", ps_crowd_body_cfg_t, step_max_m),
    F32("fall_tilt_rad", ps_crowd_body_cfg_t, fall_tilt_rad),
    F32("ground_mu", ps_crowd_body_cfg_t, ground_mu),
    CYAML_FIELD_END,
};
static const cyaml_schema_field_t GROUP_FIELDS[] = {
    CYAML_FIELD_STRING("name", CYAML_FLAG_DEFAULT, ps_crowd_group_cfg_t, name, 1),
    CYAML_FIELD_UINT("count", CYAML_FLAG_OPTIONAL, ps_crowd_group_cfg_t, count),
    F32("density_m2", ps_crowd_group_cfg_t, density_m2),
    CYAML_FIELD_MAPPING("region", CYAML_FLAG_DEFAULT, ps_crowd_group_cfg_t, region, RECT_FIELDS),
    CYAML_FIELD_ENUM("layout", CYAML_FLAG_OPTIONAL | CYAML_FLAG_STRICT, ps_crowd_group_cfg_t,
                     layout, LAYOUTS, CYAML_ARRAY_LEN(LAYOUTS)),
    F32("spacing_m", ps_crowd_group_cfg_t, spacing_m),
    CYAML_FIELD_ENUM("goal", CYAML_FLAG_OPTIONAL | CYAML_FLAG_STRICT, ps_crowd_group_cfg_t, goal,
                     GOALS, CYAML_ARRAY_LEN(GOALS)),
    CYAML_FIELD_SEQUENCE_FIXED("goal_xy", CYAML_FLAG_OPTIONAL, ps_crowd_group_cfg_t, goal_xy,
                               &FLOAT_SCHEMA, 2),
    F32("speed_m_s", ps_crowd_group_cfg_t, speed_m_s),
    F32("speed_sd_m_s", ps_crowd_group_cfg_t, speed_sd_m_s),
    F32("height_m", ps_crowd_group_cfg_t, height_m),
    F32("height_sd_m", ps_crowd_group_cfg_t, height_sd_m),
    F32("mass_kg", ps_crowd_group_cfg_t, mass_kg),
    F32("mass_sd_kg", ps_crowd_group_cfg_t, mass_sd_kg),
    F32("radius_m", ps_crowd_group_cfg_t, radius_m),
    F32("radius_sd_m", ps_crowd_group_cfg_t, radius_sd_m),
    F32("clear_m", ps_crowd_group_cfg_t, clear_m),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t GROUP_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_DEFAULT, ps_crowd_group_cfg_t, GROUP_FIELDS),
};
static const cyaml_schema_field_t WALL_FIELDS[] = {
    CYAML_FIELD_FLOAT("x0_m", CYAML_FLAG_DEFAULT, ps_crowd_wall_cfg_t, x0_m),
    CYAML_FIELD_FLOAT("y0_m", CYAML_FLAG_DEFAULT, ps_crowd_wall_cfg_t, y0_m),
    CYAML_FIELD_FLOAT("x1_m", CYAML_FLAG_DEFAULT, ps_crowd_wall_cfg_t, x1_m),
    CYAML_FIELD_FLOAT("y1_m", CYAML_FLAG_DEFAULT, ps_crowd_wall_cfg_t, y1_m),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t WALL_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_DEFAULT, ps_crowd_wall_cfg_t, WALL_FIELDS),
};
static const cyaml_schema_field_t OBSTACLE_FIELDS[] = {
    CYAML_FIELD_FLOAT("x_m", CYAML_FLAG_DEFAULT, ps_crowd_obstacle_cfg_t, x_m),
    CYAML_FIELD_FLOAT("y_m", CYAML_FLAG_DEFAULT, ps_crowd_obstacle_cfg_t, y_m),
    CYAML_FIELD_FLOAT("radius_m", CYAML_FLAG_DEFAULT, ps_crowd_obstacle_cfg_t, radius_m),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t OBSTACLE_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_DEFAULT, ps_crowd_obstacle_cfg_t, OBSTACLE_FIELDS),
};
static const cyaml_schema_field_t CROWD_EVENT_FIELDS[] = {
    CYAML_FIELD_FLOAT("t_s", CYAML_FLAG_DEFAULT, ps_crowd_event_cfg_t, t_s),
    CYAML_FIELD_FLOAT("duration_s", CYAML_FLAG_DEFAULT, ps_crowd_event_cfg_t, duration_s),
    CYAML_FIELD_ENUM("kind", CYAML_FLAG_STRICT, ps_crowd_event_cfg_t, kind, CROWD_EVENT_KINDS,
                     CYAML_ARRAY_LEN(CROWD_EVENT_KINDS)),
    CYAML_FIELD_STRING("group", CYAML_FLAG_OPTIONAL, ps_crowd_event_cfg_t, group, 1),
    CYAML_FIELD_INT("agent", CYAML_FLAG_OPTIONAL, ps_crowd_event_cfg_t, agent),
    CYAML_FIELD_SEQUENCE_FIXED("force_n", CYAML_FLAG_OPTIONAL, ps_crowd_event_cfg_t, force_n,
                               &FLOAT_SCHEMA, 3),
    CYAML_FIELD_ENUM("profile", CYAML_FLAG_OPTIONAL | CYAML_FLAG_STRICT, ps_crowd_event_cfg_t,
                     profile, PROFILES, CYAML_ARRAY_LEN(PROFILES)),
    CYAML_FIELD_UINT("rows", CYAML_FLAG_OPTIONAL, ps_crowd_event_cfg_t, rows),
    F32("speed_m_s", ps_crowd_event_cfg_t, speed_m_s),
    CYAML_FIELD_SEQUENCE_FIXED("direction", CYAML_FLAG_OPTIONAL, ps_crowd_event_cfg_t, direction,
                               &FLOAT_SCHEMA, 2),
    CYAML_FIELD_SEQUENCE_FIXED("wall", CYAML_FLAG_OPTIONAL, ps_crowd_event_cfg_t, wall,
                               &FLOAT_SCHEMA, 4),
    CYAML_FIELD_END,
};
static const cyaml_strval_t TAGS[] = {
    {"auto", PS_CROWD_TAGS_AUTO},
    {"true", PS_CROWD_TAGS_ON},
    {"false", PS_CROWD_TAGS_OFF},
};
static_assert(sizeof(TAGS) / sizeof(TAGS[0]) == PS_CROWD_TAGS_COUNT, "one name per tags mode");
static const cyaml_schema_value_t CROWD_EVENT_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_DEFAULT, ps_crowd_event_cfg_t, CROWD_EVENT_FIELDS),
};
static const cyaml_schema_field_t CROWD_FIELDS[] = {
    CYAML_FIELD_MAPPING("arena", CYAML_FLAG_DEFAULT, ps_crowd_cfg_t, arena, RECT_FIELDS),
    CYAML_FIELD_BOOL("arena_walls", CYAML_FLAG_OPTIONAL | CYAML_FLAG_STRICT, ps_crowd_cfg_t,
                     has_arena_walls),
    CYAML_FIELD_BOOL("periodic_x", CYAML_FLAG_OPTIONAL | CYAML_FLAG_STRICT, ps_crowd_cfg_t,
                     is_periodic_x),
    CYAML_FIELD_BOOL("gate_capsules", CYAML_FLAG_OPTIONAL | CYAML_FLAG_STRICT, ps_crowd_cfg_t,
                     gate_capsules),
    CYAML_FIELD_MAPPING("measure", CYAML_FLAG_OPTIONAL, ps_crowd_cfg_t, measure, RECT_FIELDS),
    F32("local_radius_m", ps_crowd_cfg_t, local_radius_m),
    F32("robot_radius_m", ps_crowd_cfg_t, robot_radius_m),
    F32("robot_a_n", ps_crowd_cfg_t, robot_a_n),
    F32("crowd_dt_s", ps_crowd_cfg_t, crowd_dt_s),
    F32("timestep_s", ps_crowd_cfg_t, timestep_s),
    CYAML_FIELD_ENUM("tags", CYAML_FLAG_OPTIONAL | CYAML_FLAG_STRICT, ps_crowd_cfg_t, tags, TAGS,
                     CYAML_ARRAY_LEN(TAGS)),
    CYAML_FIELD_MAPPING("social", CYAML_FLAG_OPTIONAL, ps_crowd_cfg_t, social, SOCIAL_FIELDS),
    CYAML_FIELD_MAPPING("body", CYAML_FLAG_OPTIONAL, ps_crowd_cfg_t, body, BODY_FIELDS),
    CYAML_FIELD_SEQUENCE_COUNT("groups", CYAML_FLAG_OPTIONAL, ps_crowd_cfg_t, groups, n_groups,
                               &GROUP_SCHEMA, 0, PS_CROWD_MAX_GROUPS),
    CYAML_FIELD_SEQUENCE_COUNT("walls", CYAML_FLAG_OPTIONAL, ps_crowd_cfg_t, walls, n_walls,
                               &WALL_SCHEMA, 0, PS_CROWD_MAX_WALLS),
    CYAML_FIELD_SEQUENCE_COUNT("obstacles", CYAML_FLAG_OPTIONAL, ps_crowd_cfg_t, obstacles,
                               n_obstacles, &OBSTACLE_SCHEMA, 0, PS_CROWD_MAX_OBSTACLES),
    CYAML_FIELD_SEQUENCE_COUNT("events", CYAML_FLAG_OPTIONAL, ps_crowd_cfg_t, events, n_events,
                               &CROWD_EVENT_SCHEMA, 0, PS_CROWD_MAX_EVENTS),
    CYAML_FIELD_END,
};
static const cyaml_schema_field_t SPAWN_FIELDS[] = {
    F32("x_m", spawn_raw_t, x_m),
    F32("y_m", spawn_raw_t, y_m),
    F32("yaw_rad", spawn_raw_t, yaw_rad),
    CYAML_FIELD_END,
};

static const cyaml_strval_t EVENT_KINDS[] = {
    {"start", PS_EVENT_START},
    {"stop", PS_EVENT_STOP},
    {"estop_press", PS_EVENT_ESTOP_PRESS},
    {"estop_release", PS_EVENT_ESTOP_RELEASE},
    {"reset", PS_EVENT_RESET},
    {"harness_release", PS_EVENT_HARNESS_RELEASE},
    {"drop_replies", PS_EVENT_DROP_REPLIES},
    {"drive_fault", PS_EVENT_DRIVE_FAULT},
    {"record_button", PS_EVENT_RECORD_BUTTON},
};
static_assert(sizeof(EVENT_KINDS) / sizeof(EVENT_KINDS[0]) == PS_EVENT_COUNT,
              "one YAML name per event kind");

static const cyaml_schema_field_t EVENT_FIELDS[] = {
    CYAML_FIELD_FLOAT("t_s", CYAML_FLAG_DEFAULT, ps_event_cfg_t, t_s),
    CYAML_FIELD_ENUM("kind", CYAML_FLAG_STRICT, ps_event_cfg_t, kind, EVENT_KINDS,
                     CYAML_ARRAY_LEN(EVENT_KINDS)),
    CYAML_FIELD_STRING("joint", CYAML_FLAG_OPTIONAL, ps_event_cfg_t, joint, 1),
    CYAML_FIELD_FLOAT("duration_s", CYAML_FLAG_OPTIONAL, ps_event_cfg_t, duration_s),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t EVENT_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_DEFAULT, ps_event_cfg_t, EVENT_FIELDS),
};
static const cyaml_schema_field_t PUSH_FIELDS[] = {
    CYAML_FIELD_FLOAT("t_s", CYAML_FLAG_DEFAULT, ps_push_cfg_t, t_s),
    CYAML_FIELD_FLOAT("duration_s", CYAML_FLAG_DEFAULT, ps_push_cfg_t, duration_s),
    CYAML_FIELD_STRING("body", CYAML_FLAG_DEFAULT, ps_push_cfg_t, body, 1),
    CYAML_FIELD_ENUM("profile", CYAML_FLAG_OPTIONAL | CYAML_FLAG_STRICT, ps_push_cfg_t, profile,
                     PROFILES, CYAML_ARRAY_LEN(PROFILES)),
    CYAML_FIELD_SEQUENCE_FIXED("force_n", CYAML_FLAG_DEFAULT, ps_push_cfg_t, force_n, &FLOAT_SCHEMA,
                               3),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t PUSH_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_DEFAULT, ps_push_cfg_t, PUSH_FIELDS),
};
static const cyaml_schema_field_t SCENARIO_FIELDS[] = {
    CYAML_FIELD_STRING("name", CYAML_FLAG_DEFAULT, scenario_raw_t, name, 1),
    CYAML_FIELD_FLOAT("duration_s", CYAML_FLAG_DEFAULT, scenario_raw_t, duration_s),
    CYAML_FIELD_UINT("seed", CYAML_FLAG_DEFAULT, scenario_raw_t, seed),
    CYAML_FIELD_SEQUENCE_COUNT("events", CYAML_FLAG_POINTER | CYAML_FLAG_OPTIONAL, scenario_raw_t,
                               events, n_events, &EVENT_SCHEMA, 0, PS_MAX_EVENTS),
    CYAML_FIELD_SEQUENCE_COUNT("pushes", CYAML_FLAG_POINTER | CYAML_FLAG_OPTIONAL, scenario_raw_t,
                               pushes, n_pushes, &PUSH_SCHEMA, 0, PS_MAX_PUSHES),
    CYAML_FIELD_MAPPING("robot", CYAML_FLAG_OPTIONAL, scenario_raw_t, robot, SPAWN_FIELDS),
    CYAML_FIELD_MAPPING("crowd", CYAML_FLAG_OPTIONAL, scenario_raw_t, crowd, CROWD_FIELDS),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t SCENARIO_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_POINTER, scenario_raw_t, SCENARIO_FIELDS),
};

#define MAX_PUSH_FORCE_N 2000.0
#define MAX_RUN_S        86400.0
static const ps_cfg_array_t SCENARIO_ARRAYS[] = {
    PS_CFG_ARRAY("events", ps_scenario_cfg_t, events, ps_event_cfg_t, n_events),
    PS_CFG_ARRAY("pushes", ps_scenario_cfg_t, pushes, ps_push_cfg_t, n_pushes),
    PS_CFG_ARRAY("crowd.groups", ps_scenario_cfg_t, crowd.groups, ps_crowd_group_cfg_t,
                 crowd.n_groups),
    PS_CFG_ARRAY("crowd.events", ps_scenario_cfg_t, crowd.events, ps_crowd_event_cfg_t,
                 crowd.n_events),
    PS_CFG_ARRAY("crowd.obstacles", ps_scenario_cfg_t, crowd.obstacles, ps_crowd_obstacle_cfg_t,
                 crowd.n_obstacles),
};
enum { SA_EVENTS = 1, SA_PUSHES = 2, SA_GROUPS = 3, SA_CEVENTS = 4, SA_OBSTACLES = 5 };
#define ARENA_M 100.0
#define CR(key, m, lo, hi) PS_CFG_RULE_F32(0, 0, "crowd." key, ps_scenario_cfg_t, crowd.m, lo, hi)
#define CRO(key, m, lo, hi)                                                                        \
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "crowd." key, ps_scenario_cfg_t, crowd.m, lo, hi)
#define GR(key, m, lo, hi) PS_CFG_RULE_F32(SA_GROUPS, 0, key, ps_crowd_group_cfg_t, m, lo, hi)
#define GRO(key, m, lo, hi)                                                                        \
    PS_CFG_RULE_F32(SA_GROUPS, PS_CFG_RANGE_OPEN_MIN, key, ps_crowd_group_cfg_t, m, lo, hi)
#define ER(key, m, lo, hi) PS_CFG_RULE_F32(SA_CEVENTS, 0, key, ps_crowd_event_cfg_t, m, lo, hi)
static const ps_cfg_rule_t SCENARIO_RANGES[] = {
    PS_CFG_RULE_F32(0, 0, "duration_s", ps_scenario_cfg_t, duration_s, 0.0, MAX_RUN_S),
    PS_CFG_RULE_U32(0, 0, "seed", ps_scenario_cfg_t, seed, 0.0, 4294967295.0),
    PS_CFG_RULE_F32(SA_EVENTS, 0, "t_s", ps_event_cfg_t, t_s, 0.0, MAX_RUN_S),
    PS_CFG_RULE_F32(SA_EVENTS, 0, "duration_s", ps_event_cfg_t, duration_s, 0.0, 3600.0),
    PS_CFG_RULE_F32(SA_PUSHES, 0, "t_s", ps_push_cfg_t, t_s, 0.0, MAX_RUN_S),
    PS_CFG_RULE_F32(SA_PUSHES, PS_CFG_RANGE_OPEN_MIN, "duration_s", ps_push_cfg_t, duration_s, 0.0,
                    10.0),
    PS_CFG_RULE_F32(SA_PUSHES, 0, "force_n[0]", ps_push_cfg_t, force_n[0], -MAX_PUSH_FORCE_N,
                    MAX_PUSH_FORCE_N),
    PS_CFG_RULE_F32(SA_PUSHES, 0, "force_n[1]", ps_push_cfg_t, force_n[1], -MAX_PUSH_FORCE_N,
                    MAX_PUSH_FORCE_N),
    PS_CFG_RULE_F32(SA_PUSHES, 0, "force_n[2]", ps_push_cfg_t, force_n[2], -MAX_PUSH_FORCE_N,
                    MAX_PUSH_FORCE_N),
    PS_CFG_RULE_F32(0, 0, "robot.x_m", ps_scenario_cfg_t, robot_xy_m[0], -ARENA_M, ARENA_M),
    PS_CFG_RULE_F32(0, 0, "robot.y_m", ps_scenario_cfg_t, robot_xy_m[1], -ARENA_M, ARENA_M),
    PS_CFG_RULE_F32(0, 0, "robot.yaw_rad", ps_scenario_cfg_t, robot_yaw_rad, -7.0, 7.0),
    CR("arena.x_min_m", arena.x_min_m, -ARENA_M, ARENA_M),
    CR("arena.y_min_m", arena.y_min_m, -ARENA_M, ARENA_M),
    CR("arena.x_max_m", arena.x_max_m, -ARENA_M, ARENA_M),
    CR("arena.y_max_m", arena.y_max_m, -ARENA_M, ARENA_M),
    CRO("local_radius_m", local_radius_m, 0.0, 10.0),
    CR("robot_radius_m", robot_radius_m, 0.0, 2.0),
    CR("robot_a_n", robot_a_n, 0.0, 10000.0),
    CRO("crowd_dt_s", crowd_dt_s, 0.0, 0.1),
    CR("timestep_s", timestep_s, 0.0, 0.002),
    CR("social.v0_m_s", social.v0_m_s, 0.0, 5.0),
    CRO("social.tau_s", social.tau_s, 0.0, 10.0),
    CR("social.a_n", social.a_n, 0.0, 10000.0),
    CRO("social.b_m", social.b_m, 0.0, 2.0),
    CR("social.wall_a_n", social.wall_a_n, 0.0, 10000.0),
    CRO("social.wall_b_m", social.wall_b_m, 0.0, 2.0),
    CR("social.lambda", social.lambda, 0.0, 1.0),
    CRO("social.range_m", social.range_m, 0.0, 5.0),
    CR("social.evasive_n", social.evasive_n, 0.0, 2000.0),
    CR("social.evasive_range_m", social.evasive_range_m, 0.0, 10.0),
    CRO("body.body_k_n_m", body.body_k_n_m, 0.0, 1e7),
    CRO("body.body_damping", body.body_damping, 0.0, 10.0),
    CR("body.friction", body.friction, 0.0, 2.0),
    CR("body.sliding_kappa", body.sliding_kappa, 0.0, 1e7),
    CRO("body.bos_m", body.bos_m, 0.0, 0.5),
    CRO("body.ankle_k_ratio", body.ankle_k_ratio, 0.0, 10.0),
    CR("body.step_time_s", body.step_time_s, 0.5, 1.0),
    CRO("body.step_max_m", body.step_max_m, 0.0, 0.7301), /* thesis 004: 0.73 (float) */
    CRO("body.fall_tilt_rad", body.fall_tilt_rad, 0.0, 1.5),
    CR("body.ground_mu", body.ground_mu, 0.0, 2.0),
    PS_CFG_RULE_U32(SA_GROUPS, 0, "count", ps_crowd_group_cfg_t, count, 0.0,
                    (double)PS_CROWD_MAX_AGENTS),
    GR("density_m2", density_m2, 0.0, 8.0),
    GR("spacing_m", spacing_m, 0.0, 10.0),
    GR("speed_m_s", speed_m_s, 0.0, 5.0),
    GR("speed_sd_m_s", speed_sd_m_s, 0.0, 1.0),
    GRO("height_m", height_m, 1.0, 2.2),
    GR("height_sd_m", height_sd_m, 0.0, 0.3),
    GRO("mass_kg", mass_kg, 20.0, 200.0),
    GR("mass_sd_kg", mass_sd_kg, 0.0, 40.0),
    GRO("radius_m", radius_m, 0.1, 0.35),
    GR("radius_sd_m", radius_sd_m, 0.0, 0.05),
    GR("clear_m", clear_m, 0.0, 10.0),
    ER("t_s", t_s, 0.0, MAX_RUN_S),
    PS_CFG_RULE_F32(SA_CEVENTS, PS_CFG_RANGE_OPEN_MIN, "duration_s", ps_crowd_event_cfg_t,
                    duration_s, 0.0, 3600.0),
    ER("force_n[0]", force_n[0], -MAX_PUSH_FORCE_N, MAX_PUSH_FORCE_N),
    ER("force_n[1]", force_n[1], -MAX_PUSH_FORCE_N, MAX_PUSH_FORCE_N),
    ER("force_n[2]", force_n[2], -MAX_PUSH_FORCE_N, MAX_PUSH_FORCE_N),
    ER("speed_m_s", speed_m_s, 0.0, 5.0),
    PS_CFG_RULE_I32(SA_CEVENTS, 0, "agent", ps_crowd_event_cfg_t, agent, -1.0,
                    (double)PS_CROWD_MAX_AGENTS - 1.0),
    PS_CFG_RULE_F32(SA_OBSTACLES, PS_CFG_RANGE_OPEN_MIN, "radius_m", ps_crowd_obstacle_cfg_t,
                    radius_m, 0.0, 10.0),
};

static int check_rect(ps_cfg_ctx_t *c, const char *field, const ps_crowd_rect_t *r,
                      bool is_line)
{
    if (r->x_min_m < r->x_max_m && r->y_min_m < r->y_max_m)
        return 0;
    if (is_line && (r->x_min_m != r->x_max_m || r->y_min_m != r->y_max_m))
        return 0; /* a line's two ends */
    return ps_cfg_fail_field(c, field, "empty rectangle: x %g..%g, y %g..%g", (double)r->x_min_m,
                             (double)r->x_max_m, (double)r->y_min_m, (double)r->y_max_m);
}

static int find_group(const ps_crowd_cfg_t *cr, const char *name)
{
    for (uint32_t g = 0; g < cr->n_groups; g++)
        if (strncmp(cr->groups[g].name, name, PS_NAME_LEN) == 0)
            return (int)g;
    return -1;
}

static int check_group(ps_cfg_ctx_t *c, const ps_crowd_cfg_t *cr, uint32_t i)
{
    const ps_crowd_group_cfg_t *g = &cr->groups[i];
    char field[PS_CFG_FIELD_PATH_LEN];
    (void)snprintf(field, sizeof(field), "crowd.groups[%u].region", i);
    int rc = check_rect(c, field, &g->region, g->layout == PS_CROWD_LAYOUT_LINE);
    if (rc != 0)
        return rc;
    if (find_group(cr, g->name) != (int)i) {
        (void)snprintf(field, sizeof(field), "crowd.groups[%u].name", i);
        return ps_cfg_fail_field(c, field, "\"%s\" names an earlier group too", g->name);
    }
    (void)snprintf(field, sizeof(field), "crowd.groups[%u]", i);
    if (g->count == 0 && g->density_m2 <= 0.0f)
        return ps_cfg_fail_field(c, field, "needs a count or a density_m2");
    if (g->layout == PS_CROWD_LAYOUT_LINE && (g->count == 0 || g->spacing_m <= 0.0f))
        return ps_cfg_fail_field(c, field, "a line needs a count and a spacing_m");
    const bool has_vec = g->goal_xy[0] != 0.0f || g->goal_xy[1] != 0.0f;
    if (g->goal == PS_CROWD_GOAL_DIRECTION && !has_vec) {
        (void)snprintf(field, sizeof(field), "crowd.groups[%u].goal_xy", i);
        return ps_cfg_fail_field(c, field, "goal direction needs a non-zero goal_xy");
    }
    return 0;
}

static int check_crowd_event(ps_cfg_ctx_t *c, const ps_crowd_cfg_t *cr, uint32_t i,
                             float run_s)
{
    const ps_crowd_event_cfg_t *e = &cr->events[i];
    char field[PS_CFG_FIELD_PATH_LEN];
    (void)snprintf(field, sizeof(field), "crowd.events[%u]", i);
    if (run_s > 0.0f && e->t_s > run_s) {
        (void)snprintf(field, sizeof(field), "crowd.events[%u].t_s", i);
        return ps_cfg_fail_field(c, field, "value %g after the end of the run (duration_s %g)",
                                 (double)e->t_s, (double)run_s);
    }
    const bool has_dir = e->direction[0] != 0.0f || e->direction[1] != 0.0f;
    if (e->kind != PS_CROWD_EVENT_WALL) {
        const int g = find_group(cr, e->group);
        if (g < 0) {
            (void)snprintf(field, sizeof(field), "crowd.events[%u].group", i);
            return ps_cfg_fail_field(c, field, "\"%s\" is not a group of the crowd", e->group);
        }
        if (e->agent >= 0 && cr->groups[g].count > 0 && (uint32_t)e->agent >= cr->groups[g].count) {
            (void)snprintf(field, sizeof(field), "crowd.events[%u].agent", i);
            return ps_cfg_fail_field(c, field, "value %d, group %s has %u agents", (int)e->agent,
                                     e->group, cr->groups[g].count);
        }
    }
    if (e->kind == PS_CROWD_EVENT_SURGE && (e->rows == 0 || e->speed_m_s <= 0.0f || !has_dir))
        return ps_cfg_fail_field(c, field, "a surge needs rows, speed_m_s and a direction");
    if (e->kind == PS_CROWD_EVENT_WALL && (e->speed_m_s <= 0.0f || !has_dir ||
                                           (e->wall[0] == e->wall[2] && e->wall[1] == e->wall[3])))
        return ps_cfg_fail_field(c, field, "a wall needs a wall [x0, y0, x1, y1], speed_m_s and "
                                           "a direction");
    if (e->kind == PS_CROWD_EVENT_PUSH && e->force_n[0] == 0.0f && e->force_n[1] == 0.0f &&
        e->force_n[2] == 0.0f)
        return ps_cfg_fail_field(c, field, "a push needs a non-zero force_n");
    return 0;
}

static int check_crowd(ps_cfg_ctx_t *c, const ps_crowd_cfg_t *cr, float run_s)
{
    if (!cr->is_enabled)
        return 0;
    int rc = check_rect(c, "crowd.arena", &cr->arena, false);
    if (rc == 0)
        rc = check_rect(c, "crowd.measure", &cr->measure, false);
    for (uint32_t i = 0; i < cr->n_groups && rc == 0; i++)
        rc = check_group(c, cr, i);
    for (uint32_t i = 0; i < cr->n_events && rc == 0; i++)
        rc = check_crowd_event(c, cr, i, run_s);
    return rc;
}

static int check_scenario(ps_cfg_ctx_t *c, const ps_scenario_cfg_t *s)
{
    int rc = ps_cfg_check_ranges(c, s);
    if (rc != 0)
        return rc;
    char field[PS_CFG_FIELD_PATH_LEN];
    for (uint32_t i = 0; i < s->n_events; i++) {
        const ps_event_cfg_t *e = &s->events[i];
        const bool is_drop = e->kind == PS_EVENT_DROP_REPLIES;
        const bool has_joint = is_drop || e->kind == PS_EVENT_DRIVE_FAULT;
        if (has_joint && e->joint[0] == '\0') {
            (void)snprintf(field, sizeof(field), "events[%u]", i);
            return ps_cfg_fail_field(c, field, "%s needs a \"joint\"",
                                     ps_config_event_name(e->kind));
        }
        if (!has_joint && e->joint[0] != '\0') {
            (void)snprintf(field, sizeof(field), "events[%u].joint", i);
            return ps_cfg_fail_field(c, field,
                                     "only drop_replies and drive_fault take a joint, not %s",
                                     ps_config_event_name(e->kind));
        }
        if (!is_drop && e->duration_s != 0.0f) {
            (void)snprintf(field, sizeof(field), "events[%u].duration_s", i);
            return ps_cfg_fail_field(c, field, "only drop_replies takes a duration, not %s",
                                     ps_config_event_name(e->kind));
        }
        if (s->duration_s > 0.0f && e->t_s > s->duration_s) {
            (void)snprintf(field, sizeof(field), "events[%u].t_s", i);
            return ps_cfg_fail_field(c, field, "value %g after the end of the run (duration_s %g)",
                                     (double)e->t_s, (double)s->duration_s);
        }
    }
    rc = check_crowd(c, &s->crowd, s->duration_s);
    if (rc != 0)
        return rc;
    for (uint32_t i = 0; i < s->n_pushes; i++) {
        const ps_push_cfg_t *p = &s->pushes[i];
        const double f =
            sqrt((double)p->force_n[0] * p->force_n[0] + (double)p->force_n[1] * p->force_n[1] +
                 (double)p->force_n[2] * p->force_n[2]);
        if (f > MAX_PUSH_FORCE_N) {
            (void)snprintf(field, sizeof(field), "pushes[%u].force_n", i);
            return ps_cfg_fail_field(c, field, "magnitude %g N outside [0, %g]", f,
                                     MAX_PUSH_FORCE_N);
        }
        if (s->duration_s > 0.0f && p->t_s > s->duration_s) {
            (void)snprintf(field, sizeof(field), "pushes[%u].t_s", i);
            return ps_cfg_fail_field(c, field, "value %g after the end of the run (duration_s %g)",
                                     (double)p->t_s, (double)s->duration_s);
        }
    }
    return 0;
}

/* Where the fields that the robot and the model are checked against are. */
static void record_src(const ps_cfg_ctx_t *c, ps_scenario_cfg_t *s)
{
    (void)snprintf(s->path, sizeof(s->path), "%s", c->path); /* truncation is acceptable */
    char field[PS_CFG_FIELD_PATH_LEN];
    for (uint32_t i = 0; i < s->n_events; i++) {
        (void)snprintf(field, sizeof(field), "events[%u].joint", i);
        s->events[i].joint_line = ps_cfg_line_of(c, field);
    }
    for (uint32_t i = 0; i < s->n_pushes; i++) {
        (void)snprintf(field, sizeof(field), "pushes[%u].body", i);
        s->pushes[i].body_line = ps_cfg_line_of(c, field);
    }
}

/* A field of the crowd section that takes its default when the file leaves
 * it out (zero is a meaningful value for most). */
typedef struct {
    const char *key; /**< below "crowd." */
    size_t off;      /**< in ps_crowd_cfg_t */
} crowd_opt_t;

#define CROWD_OPT(key, m)                                                                          \
    {                                                                                              \
        key, PS_CFG_TYPED_OFF(float, ps_crowd_cfg_t, m)                                            \
    }
static const crowd_opt_t CROWD_OPTS[] = {
    CROWD_OPT("local_radius_m", local_radius_m),
    CROWD_OPT("robot_radius_m", robot_radius_m),
    CROWD_OPT("robot_a_n", robot_a_n),
    CROWD_OPT("crowd_dt_s", crowd_dt_s),
    CROWD_OPT("timestep_s", timestep_s),
    CROWD_OPT("social.v0_m_s", social.v0_m_s),
    CROWD_OPT("social.tau_s", social.tau_s),
    CROWD_OPT("social.a_n", social.a_n),
    CROWD_OPT("social.b_m", social.b_m),
    CROWD_OPT("social.wall_a_n", social.wall_a_n),
    CROWD_OPT("social.wall_b_m", social.wall_b_m),
    CROWD_OPT("social.lambda", social.lambda),
    CROWD_OPT("social.range_m", social.range_m),
    CROWD_OPT("social.evasive_n", social.evasive_n),
    CROWD_OPT("social.evasive_range_m", social.evasive_range_m),
    CROWD_OPT("body.body_k_n_m", body.body_k_n_m),
    CROWD_OPT("body.body_damping", body.body_damping),
    CROWD_OPT("body.friction", body.friction),
    CROWD_OPT("body.sliding_kappa", body.sliding_kappa),
    CROWD_OPT("body.bos_m", body.bos_m),
    CROWD_OPT("body.ankle_k_ratio", body.ankle_k_ratio),
    CROWD_OPT("body.step_time_s", body.step_time_s),
    CROWD_OPT("body.step_max_m", body.step_max_m),
    CROWD_OPT("body.fall_tilt_rad", body.fall_tilt_rad),
    CROWD_OPT("body.ground_mu", body.ground_mu),
};

/* Group fields with population defaults (thesis 004: Canadian adult means,
 * 1.70 m; 0.1 h = 0.17 m torso radius). */
typedef struct {
    const char *key;
    size_t off;
    float value;
} group_opt_t;

#define GROUP_OPT(key, m, v)                                                                       \
    {                                                                                              \
        key, PS_CFG_TYPED_OFF(float, ps_crowd_group_cfg_t, m), v                                   \
    }
static const group_opt_t GROUP_OPTS[] = {
    GROUP_OPT("height_m", height_m, 1.70f),   GROUP_OPT("height_sd_m", height_sd_m, 0.07f),
    GROUP_OPT("mass_kg", mass_kg, 70.0f),     GROUP_OPT("mass_sd_kg", mass_sd_kg, 10.0f),
    GROUP_OPT("radius_m", radius_m, 0.17f),   GROUP_OPT("radius_sd_m", radius_sd_m, 0.01f),
    GROUP_OPT("clear_m", clear_m, 0.6f),
};

static void copy_crowd(const ps_cfg_ctx_t *c, const ps_crowd_cfg_t *raw, ps_crowd_cfg_t *out)
{
    ps_crowd_default_cfg(out);
    if (ps_cfg_line_of(c, "crowd") == 0)
        return;
    const ps_crowd_cfg_t defaults = *out;
    *out = *raw;
    out->is_enabled = true;
    out->tag_size_m = defaults.tag_size_m; /* not in the file: the board's camera sets it */
    char field[PS_CFG_FIELD_PATH_LEN];
    for (size_t k = 0; k < sizeof(CROWD_OPTS) / sizeof(CROWD_OPTS[0]); k++) {
        (void)snprintf(field, sizeof(field), "crowd.%s", CROWD_OPTS[k].key);
        if (ps_cfg_line_of(c, field) == 0)
            memcpy((char *)out + CROWD_OPTS[k].off, (const char *)&defaults + CROWD_OPTS[k].off,
                   sizeof(float));
    }
    if (ps_cfg_line_of(c, "crowd.gate_capsules") == 0)
        out->gate_capsules = defaults.gate_capsules;
    if (ps_cfg_line_of(c, "crowd.measure") == 0)
        out->measure = out->arena;
    for (uint32_t g = 0; g < out->n_groups; g++) {
        for (size_t k = 0; k < sizeof(GROUP_OPTS) / sizeof(GROUP_OPTS[0]); k++) {
            (void)snprintf(field, sizeof(field), "crowd.groups[%u].%s", g, GROUP_OPTS[k].key);
            if (ps_cfg_line_of(c, field) == 0)
                memcpy((char *)&out->groups[g] + GROUP_OPTS[k].off, &GROUP_OPTS[k].value,
                       sizeof(float));
        }
    }
    for (uint32_t e = 0; e < out->n_events; e++) {
        ps_crowd_event_cfg_t *ev = &out->events[e];
        (void)snprintf(field, sizeof(field), "crowd.events[%u].agent", e);
        if (ps_cfg_line_of(c, field) == 0)
            ev->agent = -1;
        (void)snprintf(field, sizeof(field), "crowd.events[%u].group", e);
        ev->group_line = ps_cfg_line_of(c, field);
        const double n = sqrt((double)ev->direction[0] * ev->direction[0] +
                              (double)ev->direction[1] * ev->direction[1]);
        if (n > 0.0) {
            ev->direction[0] = (float)(ev->direction[0] / n);
            ev->direction[1] = (float)(ev->direction[1] / n);
        }
    }
}

int ps_config_load_scenario(const char *path, ps_scenario_cfg_t *out, char *err, size_t err_len)
{
    if (path == NULL || out == NULL)
        return -EINVAL;
    ps_cfg_ctx_t c;
    int rc = ps_cfg_ctx_open(&c, path, err, err_len, SCENARIO_ARRAYS, SCENARIO_RANGES,
                             PS_CFG_COUNT(SCENARIO_RANGES));
    scenario_raw_t *raw = NULL;
    if (rc == 0)
        rc = ps_cfg_load_file(&c, &SCENARIO_SCHEMA, (void **)&raw);

    ps_scenario_cfg_t *s = rc == 0 ? calloc(1, sizeof(*s)) : NULL;
    if (rc == 0 && s == NULL)
        rc = -ENOMEM;
    if (rc == 0) {
        memcpy(s->name, raw->name, sizeof(s->name));
        s->duration_s = raw->duration_s;
        s->seed = raw->seed;
        s->n_events = raw->n_events; /* libcyaml enforced the maxima */
        if (raw->n_events > 0)
            memcpy(s->events, raw->events, raw->n_events * sizeof(s->events[0]));
        s->n_pushes = raw->n_pushes;
        if (raw->n_pushes > 0)
            memcpy(s->pushes, raw->pushes, raw->n_pushes * sizeof(s->pushes[0]));
        s->robot_xy_m[0] = raw->robot.x_m;
        s->robot_xy_m[1] = raw->robot.y_m;
        s->robot_yaw_rad = raw->robot.yaw_rad;
        copy_crowd(&c, &raw->crowd, &s->crowd);
    }
    if (raw != NULL)
        (void)cyaml_free(&c.cyaml, &SCENARIO_SCHEMA, raw, 0); /* only fails on a NULL schema */
    if (rc == 0)
        rc = check_scenario(&c, s);
    if (rc == 0) {
        record_src(&c, s);
        *out = *s;
    }
    free(s);
    ps_cfg_ctx_close(&c);
    return rc;
}

int ps_config_check_scenario(const ps_robot_cfg_t *r, const ps_scenario_cfg_t *s, char *err,
                             size_t err_len)
{
    if (r == NULL || s == NULL)
        return -EINVAL;
    if (err != NULL && err_len > 0)
        err[0] = '\0';
    for (uint32_t i = 0; i < s->n_events && i < PS_MAX_EVENTS; i++) {
        const ps_event_cfg_t *e = &s->events[i];
        if ((e->kind != PS_EVENT_DROP_REPLIES && e->kind != PS_EVENT_DRIVE_FAULT) ||
            ps_config_find_joint(r, e->joint) >= 0)
            continue;
        if (s->path[0] == '\0')
            ps_err_format(err, err_len,
                          "scenario %s: events[%u].joint: no joint \"%s\" in robot %s", s->name, i,
                          e->joint, r->name);
        else if (e->joint_line == 0)
            ps_err_format(err, err_len, "%s: events[%u].joint: no joint \"%s\" in robot %s",
                          s->path, i, e->joint, r->name);
        else
            ps_err_format(err, err_len, "%s:%u: events[%u].joint: no joint \"%s\" in robot %s",
                          s->path, e->joint_line, i, e->joint, r->name);
        return -PS_ERR_CONFIG;
    }
    return 0;
}

const char *ps_config_event_name(ps_event_kind_t k)
{
    if ((unsigned)k >= (unsigned)PS_EVENT_COUNT)
        return "unknown";
    return EVENT_KINDS[k].str; /* static_assert above keeps the table complete */
}
