/*
 * ps_plant: the MuJoCo 2.2.2 plant (libmujoco-dev). Loads the MJCF model
 * named by the robot file, maps the robot's joints to the model's hinge
 * joints and torque actuators by name, and steps physics. Knows nothing about
 * CAN: the emulated devices (sim/ps_devices.c) turn frames into torques.
 *
 * Units: SI, double (MuJoCo's mjtNum). Joint arrays are indexed like the
 * robot file's joints. World frame: z up, robot initially facing +x.
 *
 * Model requirements (sim/models/ps1.xml meets them): a body named
 * PS_PLANT_ROOT_BODY_NAME ("pelvis") with a free joint, the robot's floating
 * base; the robot is that body and its descendants (its subtree), and the
 * model may hold other bodies, free ones included, anywhere in worldbody
 * (crowd, props); per robot joint a hinge and a motor actuator of the same
 * name; a body "head"; foot bodies in the robot's subtree whose names end in
 * "foot" (a contact between a world-body geom, the floor, and a geom of any
 * other body of the robot's subtree counts as a fall; other bodies touching
 * the floor do not); a site "imu" with a gyro sensor "imu_gyro" and an
 * accelerometer "imu_accel" on it.
 *
 * Crowd: with robot->crowd enabled the plant places the agents
 * (sim/ps_scene.h, from robot->seed), writes the scene around the robot's
 * model file (which it loads unchanged), loads it through MuJoCo's virtual
 * file system and steps the crowd (sim/ps_crowd.h) with the physics: its
 * forces before each step, its measurements after.
 *
 * Harness: spring 20 kN/m + 1.5 kN s/m and 1.5 kN m/rad + 100 N m s/rad on
 * the pelvis toward its pose at create (holds the limp robot within ~2 cm).
 *
 * Threads: one thread at a time (the plant thread, or the loop thread in
 * lockstep). Allocation: at create only (mj_loadXML, mj_makeData). The first
 * create installs a silent MuJoCo warning handler (if none is installed) so
 * the library never prints; what MuJoCo warns about is read from its warning
 * counters instead and reported as a plant error (ps_plant_step, with a
 * reason from ps_plant_error_reason): instability (bad qpos/qvel/qacc, which
 * MuJoCo answers by resetting the state) and contacts or constraints dropped
 * because the model's <size nconmax/njmax> is too small for them.
 */
#ifndef PS_PLANT_H
#define PS_PLANT_H

#include <stdbool.h>
#include <stddef.h>

#include <stdint.h>

#include "../rt/ps_limits.h"
#include "ps_crowd.h"

/** Name of the robot's root body, whose free joint is the floating base. */
#define PS_PLANT_ROOT_BODY_NAME "pelvis"

typedef struct ps_plant ps_plant_t;

/** What the plant needs of the robot. Nothing is kept after create. */
typedef struct {
    const char *model_path;                /**< MJCF file */
    uint32_t n_joints;                     /**< robot joints, <= PS_MAX_JOINTS */
    const char (*joint_name)[PS_NAME_LEN]; /**< hinge and motor names, by joint */
    const float *stance_rad;               /**< initial pose, by joint */
    /* Where the robot file names the model and the joints, so that an error
     * says FILE:LINE: FIELD: as every configuration error does. NULL or 0:
     * unknown (a robot built in code), the message goes without. */
    const char *src_path;
    const uint32_t *joint_name_line; /**< by joint */
    uint32_t model_line;
    /* Scene: where the robot stands, and the crowd around it. */
    double spawn_xy_m[2];           /**< robot's start on the floor */
    double spawn_yaw_rad;           /**< robot's heading, 0: facing +x */
    const ps_crowd_cfg_t *crowd;    /**< NULL or !is_enabled: the robot model alone */
    uint32_t seed;                  /**< agent placement and sizes */
} ps_plant_cfg_t;

typedef struct {
    double t_s;
    double com_m[3];      /**< whole-body centre of mass, world */
    double head_height_m; /**< world z of the head body */
    double pelvis_m[3];
    bool is_fallen; /**< a robot body (root subtree) other than the feet touches the floor */
} ps_plant_truth_t;

/** Load the model and place the robot in its stance (robot->stance_rad)
 *  with the soles on the floor (lowest foot point at z = 0), upright at
 *  spawn_xy_m facing spawn_yaw_rad, at rest; the harness is engaged. With a
 *  crowd, the scene is the robot's model plus the crowd (see above).
 *  @pre robot->n_joints <= PS_MAX_JOINTS  @post *out set only on success;
 *       err holds a one-line message on failure
 *  @return 0 | -PS_ERR_PLANT (model fails to load, err has MuJoCo's message;
 *            or the stance already needs more contacts or constraints than
 *            the model's nconmax/njmax, err says which)
 *          | -PS_ERR_CONFIG (a robot joint or actuator is missing in the model,
 *            or the model lacks the root body PS_PLANT_ROOT_BODY_NAME, its free
 *            joint, head, feet or IMU; err names it)
 *          | -EINVAL (NULL argument) | -ENOMEM  @rt INIT */
int ps_plant_create(const ps_plant_cfg_t *robot, ps_plant_t **out, char *err, size_t err_len);

/** @return physics time step (the model's option timestep)  @units s */
double ps_plant_timestep_s(const ps_plant_t *p);

/** Joint torques to apply from now on (clamped to the model's ctrlrange;
 *  a non-finite entry applies 0).  @pre tau_nm has n_joints entries */
void ps_plant_set_torques(ps_plant_t *p, const double *tau_nm);

/** @post q and qd of every robot joint  @units rad, rad/s */
void ps_plant_get_joints(const ps_plant_t *p, double *out_q_rad, double *out_qd_rad_s);

/** Ideal IMU at the pelvis IMU site: angular velocity and specific force
 *  (gravity-compensated accelerometer reading) in the IMU frame. */
void ps_plant_get_imu(const ps_plant_t *p, double out_gyro_rad_s[3], double out_accel_m_s2[3]);

/** @return body index for a name, or -ENOENT */
int ps_plant_find_body(const ps_plant_t *p, const char *name);

/** External force on a body's CoM (world frame) until changed; added to the
 *  harness force when body_idx is the pelvis. An invalid body_idx is ignored. */
void ps_plant_set_external_force(ps_plant_t *p, int body_idx, const double force_n[3]);

/** Harness: a stiff spring-damper holding the pelvis at its initial pose
 *  (like a gantry on a real robot). Engaged at create. */
void ps_plant_set_harness(ps_plant_t *p, bool is_engaged);

/** Advance physics by one timestep.
 *  @return 0 | -PS_ERR_PLANT: NaN/instability (MuJoCo has then reset the
 *          state), or contacts beyond nconmax / constraints beyond njmax were
 *          dropped (mjWARN_CONTACTFULL / mjWARN_CNSTRFULL); the physics is
 *          wrong from then on, so stop stepping. ps_plant_error_reason says
 *          which. */
int ps_plant_step(ps_plant_t *p);

/** @return why the last failing ps_plant_step failed, a static string
 *  (valid for the program's life), or NULL when no step has failed
 *  @rt RT-SAFE O(1) */
const char *ps_plant_error_reason(const ps_plant_t *p);

/** @post *out = current truth */
void ps_plant_get_truth(const ps_plant_t *p, ps_plant_truth_t *out);

/** Total mass of the floating robot (the root body's subtree).
 *  @pre created  @return mass  @units kg  @rt RT-SAFE O(1) */
double ps_plant_total_mass_kg(const ps_plant_t *p);

/** Lowest world z of any geom of a foot body (a body whose name ends in
 *  "foot"), from the last computed kinematics (create, or the last step).
 *  @pre created  @return height above the floor plane z = 0  @units m
 *  @rt RT-SAFE O(ngeom) */
double ps_plant_foot_min_z_m(const ps_plant_t *p);

/** @return the crowd, NULL when the plant has none  @rt RT-SAFE */
ps_crowd_t *ps_plant_crowd(ps_plant_t *p);

/** The loaded model and data, for offscreen rendering and tests: read-only,
 *  and only while the plant is not stepping (or on the stepping thread).
 *  @rt RT-SAFE */
const struct mjModel_ *ps_plant_model(const ps_plant_t *p);
const struct mjData_ *ps_plant_data(const ps_plant_t *p);

/** Time spent so far in the crowd's work (forces, decisions, measurements)
 *  and in mj_step, CLOCK_MONOTONIC, for the bench.  @rt RT-SAFE */
void ps_plant_get_timing(const ps_plant_t *p, int64_t *out_crowd_ns, int64_t *out_mujoco_ns);

/** @return the robot's root body index  @rt RT-SAFE */
int ps_plant_root_body(const ps_plant_t *p);

/** @post out_qpos holds the model's nq position coordinates (for the
 *  simulated camera's scene mailbox)  @rt RT-SAFE O(nq) */
void ps_plant_get_qpos(const ps_plant_t *p, double *out_qpos);
/** World position of a body's frame origin (ps_plant_find_body), from the
 *  last computed kinematics. An invalid body_idx writes NaN.
 *  @units m  @rt RT-SAFE O(1) */
void ps_plant_get_body_pos(const ps_plant_t *p, int body_idx, double out_m[3]);

/** The feet on the floor, from the last step's contacts: per foot body
 *  (left, right: the bodies named "l_foot" and "r_foot") the normal force of
 *  its floor contacts and their force-weighted point (the foot's CoP, world;
 *  NaN when out_force_n is 0), and the whole CoP of both.
 *  @return 0 | -ENOENT the model has no l_foot/r_foot  @units N, m
 *  @rt RT-SAFE O(ncon) */
int ps_plant_get_feet_contact(const ps_plant_t *p, double out_force_n[2],
                              double out_cop_m[2][3]);

/** The floating base: position (world), orientation (quaternion w x y z),
 *  linear velocity (world) of the root body's frame.  @rt RT-SAFE */
void ps_plant_get_root(const ps_plant_t *p, double out_pos_m[3], double out_quat[4],
                       double out_vel_m_s[3]);

/** Kinetic energy of the whole model (crowd included), 0.5 qvel' M qvel;
 *  NaN beyond 4096 degrees of freedom.  @units J  @rt RT-SAFE O(nv^2) */
double ps_plant_kinetic_energy_j(ps_plant_t *p);

/** Domain randomisation (training only): scale the mass and inertia of a
 *  body by factor and move its centre of mass by com_offset_m (body frame;
 *  NULL: none), the friction of every geom of the robot's feet and of the
 *  floor by factor (relative to the model as loaded). A factor outside
 *  [0.1, 10] is ignored. The mass change recomputes the model's constants
 *  at its reference pose (mj_setConst), which moves the robot there: call
 *  ps_plant_reset after it.  @rt between episodes */
void ps_plant_scale_body_mass(ps_plant_t *p, int body_idx, double factor,
                              const double com_offset_m[3]);
void ps_plant_scale_friction(ps_plant_t *p, double factor);

/** Put the robot back in its stance at rest, harness as given; the model's
 *  masses and frictions stay as set.  @rt between episodes */
void ps_plant_reset(ps_plant_t *p, const float *stance_rad, bool is_harness_engaged);

/** Safe on NULL. */
void ps_plant_destroy(ps_plant_t *p);

#endif /* PS_PLANT_H */
