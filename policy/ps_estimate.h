/*
 * ps_estimate: state estimation from joint replies and the IMU.
 *
 * Trunk roll/pitch: complementary filter of gyro integration and the
 * accelerometer's gravity direction. Feet: forward kinematics of each 6-DoF
 * leg (hip yaw, roll, pitch, knee, ankle pitch, roll; lengths from the robot
 * file) rotated by the trunk tilt. Contact: a foot is in contact when its sole
 * is within a threshold of the lowest sole. CoM: lumped trunk model, the
 * pelvis plus com_offset_z_m along the trunk axis, placed above the contact
 * feet. CoP: from the ankle torques of the feet in contact (x = +tau_pitch /
 * F_z, y = -tau_roll / F_z from the ankle per foot, weight shared by contact),
 * each clamped to its sole rectangle, then load-weighted; with less than
 * PS_ESTIMATE_COP_MIN_FORCE_N of load in all (no contact, mass 0) the CoP is
 * the ground origin, the midpoint of the soles. Fallen: tilt beyond
 * fall_tilt_rad or CoM below fall_com_height_m.
 *
 * Sign conventions, limits of the lumped model and the sources followed are in
 * docs/estimation.md. Joint torques are read as the actuator torque on the
 * child link about the joint's positive axis (the drive's reply, MuJoCo
 * qfrc_actuator); the signs above hold for that convention (derivation in
 * ps_estimate.c, checked against MuJoCo contact forces in docs/estimation.md).
 *
 * Threads: loop thread. Allocation: none.
 */
#ifndef PS_ESTIMATE_H
#define PS_ESTIMATE_H

#include "ps_state.h"

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
    /* Optional mass model (all 0: none) for the whole-body CoM and momentum
     * of policy/ps_balance: the trunk (pelvis, torso, head, arms at their
     * stance) as one point in the pelvis frame, and per leg point masses:
     * hip links at the hip centre, thigh and shank on their segment axes,
     * ankle link and foot together in the foot frame. Their sum is mass_kg. */
    float trunk_mass_kg;
    float trunk_com_x_m, trunk_com_y_m, trunk_com_z_m; /**< pelvis frame */
    float hip_mass_kg;                                 /**< per leg, at the hip centre */
    float thigh_mass_kg, thigh_com_m; /**< CoM this far below the hip along the thigh */
    float shank_mass_kg, shank_com_m; /**< CoM this far below the knee along the shank */
    float foot_mass_kg;               /**< ankle link + foot */
    float foot_com_x_m, foot_com_z_m; /**< from the ankle centre, foot frame */
} ps_kinematics_cfg_t;

/** Leg joints in chain order, hip yaw to ankle roll. */
enum {
    PS_LEG_HIP_YAW,
    PS_LEG_HIP_ROLL,
    PS_LEG_HIP_PITCH,
    PS_LEG_KNEE,
    PS_LEG_ANKLE_PITCH,
    PS_LEG_ANKLE_ROLL,
    PS_LEG_N_JOINTS
};

#define PS_ESTIMATE_FILTER_TAU_S 0.5f  /**< default complementary filter time constant */
#define PS_ESTIMATE_CONTACT_M    0.02f /**< sole within this of the lowest sole: contact */
#define PS_ESTIMATE_VEL_TAU_S    0.02f /**< low-pass time constant of the CoM velocity */
#define PS_ESTIMATE_IMU_GAP_S    0.1f  /**< IMU gap longer than this: re-initialise tilt */
#define PS_ESTIMATE_G_M_S2       9.81f /**< gravity, also the accelerometer gate centre */
#define PS_ESTIMATE_ACCEL_GATE   0.2f  /**< accel used for tilt only if | |a|/g - 1 | <= this */
#define PS_ESTIMATE_COP_MIN_FORCE_N                                                                \
    1.0f /**< total contact load below this (or NaN): CoP = midpoint of the soles */

typedef struct {
    ps_kinematics_cfg_t kin;         /**< copy (read-only) */
    int leg_idx[2][PS_LEG_N_JOINTS]; /**< joint index of each leg joint, [0] left */
    float dt_s;
    float filter_tau_s; /**< complementary filter time constant; user may modify */
    bool has_tilt;      /**< read-only: a valid accelerometer sample has set the tilt */
    ps_estimate_t est;  /**< read-only: the latest estimate */
    float prev_com_m[3];
    int64_t last_imu_t_ns; /**< time of the last IMU sample used; 0: none */
    bool has_prev_com;     /**< prev_com_m holds the previous update's CoM */
} ps_estimator_t;

/** Finds the leg joints by name ("l_hip_yaw" ... "r_ankle_roll") among
 *  joint_name[0..n_joints), copies kin, zeroes the estimate, sets
 *  filter_tau_s to PS_ESTIMATE_FILTER_TAU_S.
 *  @pre joint_name indexed like the measurements  @post e ready; no tilt until
 *       the first IMU sample; nothing of the arguments is kept
 *  @units dt_s: seconds between ps_estimate_update calls (the servo tick)
 *  @return 0 | -EINVAL e, kin or joint_name NULL, n_joints > PS_MAX_JOINTS,
 *          dt_s <= 0 or mass_kg <= 0 | -ENOENT a leg joint is missing  @rt INIT */
int ps_estimate_init(ps_estimator_t *e, const ps_kinematics_cfg_t *kin,
                     const char (*joint_name)[PS_NAME_LEN], uint32_t n_joints, float dt_s);

/** @pre init ok, m->joints indexed like joint_name at init
 *  @post e->est updated from m: tilt from an IMU sample newer than the last
 *  used one (t_ns == 0 or not newer: tilt kept), feet/contact/CoM/CoP from the
 *  joints. No-op when e or m is NULL.  @rt RT-SAFE O(joints), loop thread */
void ps_estimate_update(ps_estimator_t *e, const ps_meas_t *m);

/** Wrap an angle into [-pi, pi].
 *  @return a_rad for a_rad in [-pi, pi]; a_rad - 2 pi k otherwise (one
 *  remainderf, bounded time for any finite input); NaN for +-inf or NaN
 *  (no angle: the tilt becomes NaN, which the fall check treats as fallen)
 *  @units rad  @rt RT-SAFE O(1) */
float ps_estimate_wrap_pi(float a_rad);

/** Forward kinematics of one leg, exposed for tests: sole centre in the pelvis
 *  frame (convention in docs/estimation.md).
 *  @pre side 0 left, 1 right (any other value: right), all pointers valid
 *  @units rad in, m out  @rt RT-SAFE */
void ps_estimate_leg_fk(const ps_kinematics_cfg_t *k, int side, const float q_rad[PS_LEG_N_JOINTS],
                        float out_sole_m[3]);

/** Forward kinematics with the ankle centre and the foot orientation.
 *  @pre as ps_estimate_leg_fk; out_ankle_m / out_rot may be NULL
 *  @post out_rot[r][c]: foot axes (columns) in the pelvis frame
 *  @units rad in, m out  @rt RT-SAFE */
void ps_estimate_leg_fk_pose(const ps_kinematics_cfg_t *k, int side,
                             const float q_rad[PS_LEG_N_JOINTS], float out_sole_m[3],
                             float out_ankle_m[3], float out_rot[3][3]);

#endif /* PS_ESTIMATE_H */
