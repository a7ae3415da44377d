/*
 * ps_crowd: the simulated crowd inside the MuJoCo plant. People are bodies of
 * the scene (sim/ps_scene.h generates them) that touch the robot, each other
 * and the walls through MuJoCo contacts; this module drives them and measures
 * what they do to the robot.
 *
 * Each agent is a planar base (slide x, slide y: the feet, 15 % of its mass)
 * carrying a capsule torso on two tilt hinges at its shin height (85 %): an
 * inverted pendulum that can lean, be pushed over and lie on the floor. Per
 * crowd update (crowd_dt_s, a multiple of the physics step) it computes:
 *  - the social force (sim/ps_social.h) over its neighbours from a cell grid,
 *    applied at the torso's centre of mass (the legs deliver it);
 *  - the ankle: a spring toward upright whose torque is capped at what a foot
 *    can take, m g bos_m (the centre of pressure stays inside the foot);
 *  - the stepping reflex: when the capture point x + v / sqrt(g / l) leaves
 *    the base of support (bos_m), the base steps toward it (length at most
 *    step_max_m, duration step_time_s, thesis 004: <= 0.73 m, 0.5-1 s) along
 *    a minimum-jerk path, the foot force capped by ground friction;
 *  - falling: tilted past fall_tilt_rad the agent falls (no ankle, no drive;
 *    the body lies on its hinge limit at floor level; the base drags with
 *    ground friction): an obstacle on the floor.
 * Crowd events (pushes with a force profile, rear-row surges, moving walls)
 * act at their times. Measurements (every physics step): contact force of
 * the crowd on each robot body, impulse the robot transmits to the agents
 * (Push-and-Step 000), deepest penetration, local density around the robot,
 * falls.
 *
 * Threads: the thread that steps the plant (plant thread, or the loop thread
 * in lockstep); ps_crowd_get_stats copies out for others under the caller's
 * synchronisation. Allocation: ps_crowd_create only (sim/ may allocate at
 * start-up); stepping allocates nothing.
 */
#ifndef PS_CROWD_H
#define PS_CROWD_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "../rt/ps_limits.h"
#include "ps_social.h"

#define PS_CROWD_MAX_AGENTS    300u
#define PS_CROWD_MAX_GROUPS    8u
#define PS_CROWD_MAX_WALLS     16u
#define PS_CROWD_MAX_OBSTACLES 16u
#define PS_CROWD_MAX_EVENTS    32u
#define PS_CROWD_MAX_PARTS     32u /**< robot bodies measured one by one */
#define PS_CROWD_MAX_ROBOT_CONTACTS 16u /**< contacts on the robot listed one by one */
#define PS_CROWD_NOT_AGENT     -1 /**< a robot contact with a wall or an obstacle */

typedef struct {
    float x_min_m, y_min_m, x_max_m, y_max_m;
} ps_crowd_rect_t;

typedef enum {
    PS_CROWD_LAYOUT_LATTICE = 0, /**< hexagonal lattice at the density, a little jitter */
    PS_CROWD_LAYOUT_RANDOM,      /**< uniform random, no overlap */
    PS_CROWD_LAYOUT_LINE,        /**< a queue: count agents along goal direction, spacing_m */
    PS_CROWD_LAYOUT_COUNT
} ps_crowd_layout_t;

typedef enum {
    PS_CROWD_GOAL_HOLD = 0,   /**< keep the place it starts at */
    PS_CROWD_GOAL_DIRECTION,  /**< walk along goal[] (a direction) */
    PS_CROWD_GOAL_POINT,      /**< walk to the point goal[] */
    PS_CROWD_GOAL_ROBOT,      /**< walk toward the robot (press it) */
    PS_CROWD_GOAL_COUNT
} ps_crowd_goal_t;

/** One population group. Sizes are drawn per agent from normal distributions
 *  (clamped to 2.5 sd), from the scenario's seed. */
typedef struct {
    char name[PS_NAME_LEN];
    uint32_t count;     /**< agents; 0: as many as density_m2 fills the region */
    float density_m2;   /**< persons per m^2 in the region; 0: count decides */
    ps_crowd_rect_t region;
    ps_crowd_layout_t layout;
    float spacing_m;    /**< line layout: centre distance */
    ps_crowd_goal_t goal;
    float goal_xy[2];   /**< direction or point */
    float speed_m_s;    /**< desired speed; 0: the social model's v0 */
    float speed_sd_m_s;
    float height_m, height_sd_m; /**< 1.70 m and 0.07 m (thesis 004: Canadian means) */
    float mass_kg, mass_sd_kg;
    float radius_m, radius_sd_m; /**< torso radius, 0.17 m (thesis 004: 0.1 h) */
    float clear_m;      /**< no agent placed closer than this to the robot's spawn */
} ps_crowd_group_cfg_t;

typedef struct {
    float x0_m, y0_m, x1_m, y1_m;
} ps_crowd_wall_cfg_t;

typedef struct {
    float x_m, y_m, radius_m;
} ps_crowd_obstacle_cfg_t;

typedef enum {
    PS_CROWD_EVENT_PUSH = 0, /**< force (profile) on the torso of chosen agents */
    PS_CROWD_EVENT_SURGE,    /**< the rear rows of a group walk at speed along direction */
    PS_CROWD_EVENT_WALL,     /**< a wall segment moves at speed along direction */
    PS_CROWD_EVENT_COUNT
} ps_crowd_event_kind_t;

typedef enum {
    PS_CROWD_PROFILE_CONSTANT = 0,
    PS_CROWD_PROFILE_HALF_SINE, /**< peak force_n at mid-duration; impulse 2/pi F T */
    PS_CROWD_PROFILE_COUNT
} ps_crowd_profile_t;

typedef struct {
    float t_s, duration_s;
    ps_crowd_event_kind_t kind;
    char group[PS_NAME_LEN]; /**< push, surge: the group */
    int32_t agent;           /**< push: index within the group, -1: all of it */
    float force_n[3];        /**< push: (peak) force, world */
    ps_crowd_profile_t profile;
    uint32_t rows;           /**< surge: rear rows taking part */
    float speed_m_s;         /**< surge, wall */
    float direction[2];      /**< surge, wall: unit after loading */
    float wall[4];           /**< wall: x0 y0 x1 y1 at t_s */
    uint32_t group_line;     /**< where `group` is in the scenario file, 0: unknown */
} ps_crowd_event_cfg_t;

/** Agent dynamics (biomechanics); defaults in ps_crowd_default_cfg. */
typedef struct {
    float body_k_n_m;     /**< body compression stiffness (Helbing 2000: 1.2e5 N/m) */
    float body_damping;   /**< contact damping ratio of that spring (1: critical) */
    float friction;       /**< Coulomb friction of agents on the robot and walls */
    float sliding_kappa;  /**< sliding friction between agents, Helbing 2000's kappa
                               g dv_t on the MuJoCo contact's overlap g (2.4e5 kg/(m s)) */
    float bos_m;          /**< base of support radius, half a foot (0.075 h, 0.13 m) */
    float ankle_k_ratio;  /**< ankle stiffness over m g l (1.2; see docs/crowd.md) */
    float step_time_s;    /**< reflex step duration, [0.5, 1] (thesis 004) */
    float step_max_m;     /**< longest step (thesis 004: 0.73 m) */
    float fall_tilt_rad;  /**< tilted past this an agent falls */
    float ground_mu;      /**< foot-floor friction, caps the stepping force */
} ps_crowd_body_cfg_t;

typedef struct {
    bool is_enabled;      /**< false: no crowd section, no scene (the robot model alone) */
    ps_social_params_t social;
    ps_crowd_body_cfg_t body;
    ps_crowd_rect_t arena;
    bool has_arena_walls; /**< walls on the arena's four sides */
    bool is_periodic_x;   /**< leaving at x_max re-enters at x_min (corridor) */
    ps_crowd_rect_t measure; /**< measuring area for density and speed; zero: arena */
    float local_radius_m; /**< radius of the local density around the robot (1 m) */
    float robot_radius_m; /**< the robot as a neighbour in the social force (0.2 m) */
    float robot_a_n;      /**< its repulsion strength; 0: agents do not shy from it */
    float crowd_dt_s;     /**< crowd update period (0.002 s) */
    float timestep_s;     /**< physics step of the scene (0.001 s); 0: the robot model's own */
    uint32_t n_groups;
    ps_crowd_group_cfg_t groups[PS_CROWD_MAX_GROUPS];
    uint32_t n_walls;
    ps_crowd_wall_cfg_t walls[PS_CROWD_MAX_WALLS];
    uint32_t n_obstacles;
    ps_crowd_obstacle_cfg_t obstacles[PS_CROWD_MAX_OBSTACLES];
    uint32_t n_events;
    ps_crowd_event_cfg_t events[PS_CROWD_MAX_EVENTS];
} ps_crowd_cfg_t;

/** One placed agent (sim/ps_scene.c draws them). */
typedef struct {
    double x_m, y_m;
    double height_m, mass_kg, radius_m, v0_m_s;
    uint32_t group_idx;
} ps_crowd_agent_spec_t;

/** One contact of the crowd (an agent, a wall, an obstacle) on the robot
 *  at the last physics step, world frame. */
typedef struct {
    int32_t agent;      /**< agent index, or PS_CROWD_NOT_AGENT */
    uint32_t part;      /**< robot part (ps_crowd_stats_t.part_name) */
    double force_n[3];  /**< force on the robot */
    double pos_m[3];    /**< contact point */
} ps_crowd_robot_contact_t;

/** What the crowd did, cumulative since create or current. */
typedef struct {
    uint32_t n_agents;
    uint32_t n_fallen;
    uint32_t n_stepping;          /**< agents in a reflex step now */
    uint64_t n_steps_taken;       /**< reflex steps started */
    double local_density_m2;      /**< agents per m^2 within local_radius_m of the robot */
    double measure_density_m2;    /**< agents per m^2 in the measuring area */
    double measure_speed_m_s;     /**< mean speed of the agents in the measuring area */
    double robot_force_n;         /**< |sum of crowd contact forces| on the robot now */
    double robot_force_max_n;     /**< largest robot_force_n so far */
    double transmitted_impulse_ns; /**< integral of normal force robot<->agents */
    double penetration_m;         /**< deepest contact penetration now */
    double penetration_max_m;     /**< deepest so far */
    uint32_t n_parts;
    char part_name[PS_CROWD_MAX_PARTS][PS_NAME_LEN];
    double part_force_n[PS_CROWD_MAX_PARTS];     /**< crowd force on each robot body now */
    double part_force_max_n[PS_CROWD_MAX_PARTS]; /**< largest so far */
    double part_impulse_ns[PS_CROWD_MAX_PARTS];
    /** the contacts on the robot now, in MuJoCo's order; past
     *  PS_CROWD_MAX_ROBOT_CONTACTS only counted (n_robot_contacts_total) */
    uint32_t n_robot_contacts;
    uint32_t n_robot_contacts_total;
    ps_crowd_robot_contact_t robot_contact[PS_CROWD_MAX_ROBOT_CONTACTS];
} ps_crowd_stats_t;

typedef struct ps_crowd ps_crowd_t;

/** What one agent is doing (tests, pictures). */
typedef struct {
    double base_m[2];   /**< feet, world */
    double com_m[3];    /**< torso centre of mass, world */
    double vel_m_s[2];  /**< centre of mass velocity */
    double tilt_rad;    /**< torso axis from vertical */
    bool is_stepping, is_fallen;
    uint32_t group_idx;
} ps_crowd_agent_state_t;

struct mjModel_;
struct mjData_;

/** @post *out holds every default (crowd disabled, no groups)  @rt any */
void ps_crowd_default_cfg(ps_crowd_cfg_t *out);

/** Bind to a loaded scene (sim/ps_scene.h wrote it from the same cfg and
 *  agents): finds each agent's joints and bodies by name, the moving walls,
 *  the robot's bodies (is_robot_body, nbody entries), and sets each agent
 *  geom's contact stiffness so that two agents pressed together compress as
 *  body_k_n_m says (writes m->geom_solref, INIT only).
 *  @pre timestep_s divides cfg->crowd_dt_s within 1 %  @post *out owned by
 *       the caller  @return 0 | -PS_ERR_CONFIG (an agent or wall missing in
 *       the model, err says which) | -ENOMEM | -EINVAL  @rt INIT */
int ps_crowd_create(const ps_crowd_cfg_t *cfg, const ps_crowd_agent_spec_t *agents,
                    uint32_t n_agents, struct mjModel_ *m, const unsigned char *is_robot_body,
                    int robot_root_body, ps_crowd_t **out, char *err, size_t err_len);

/** Before a physics step at simulated time t_s since start: every
 *  crowd_dt_s the decisions (social force, ankle, steps, falls, events),
 *  then their forces written into d->qfrc_applied as generalised forces on
 *  the agents' joints (qfrc_applied is the crowd's; the robot's forces go
 *  through xfrc_applied) and the moving walls' mocap positions.
 *  @rt RT-SAFE O(agents * neighbours), no allocation, plant thread */
void ps_crowd_before_step(ps_crowd_t *c, const struct mjModel_ *m, struct mjData_ *d,
                          double t_s);

/** After a physics step of dt_s: contact forces on the robot, transmitted
 *  impulse, penetration, densities.  @rt RT-SAFE O(ncon + agents) */
void ps_crowd_after_step(ps_crowd_t *c, const struct mjModel_ *m, const struct mjData_ *d,
                         double dt_s);

/** @post *out = the measurements  @rt RT-SAFE O(parts), plant thread (or
 *  any thread when the plant is not stepping) */
void ps_crowd_get_stats(const ps_crowd_t *c, ps_crowd_stats_t *out);

/** @return 0 | -EINVAL idx out of range  @rt RT-SAFE, as ps_crowd_get_stats */
int ps_crowd_get_agent(const ps_crowd_t *c, uint32_t idx, ps_crowd_agent_state_t *out);

/** @return agents  @rt any */
uint32_t ps_crowd_agent_count(const ps_crowd_t *c);

/** Safe on NULL.  @rt INIT */
void ps_crowd_destroy(ps_crowd_t *c);

#endif /* PS_CROWD_H */
