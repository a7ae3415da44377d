/*
 * ps_balance: balance math shared by the runtime (observation builder,
 * capture-point controller) and training (the C environment in sim/):
 * gravity direction, whole-body CoM and momentum from a point-mass model,
 * capture point, base of support and CoP.
 *
 * Definitions follow the Push-and-Step seed paper (seed
 * 000_caaeae2d90dfe8b5.txt, "Stage 1: Encoding Biomechanical Balance
 * Principles into Rewards": CoM against the centre of the base of support,
 * CoP where the ground reaction acts) and the linear inverted pendulum's
 * capture point (Pratt et al. 2006; the "extrapolated centre of mass" of
 * Hof et al. 2005): xi = c + c_dot / omega0, omega0 = sqrt(g / z_c).
 *
 * Frames: whatever frame the caller uses for its points (the estimator's
 * ground frame in the runtime). The point-mass model is in the pelvis frame
 * (ps_kinematics_cfg_t's mass model); momentum neglects the links' own
 * rotational inertia (documented in docs/policy.md).
 *
 * Threads: any (pure functions). Allocation: none.
 */
#ifndef PS_BALANCE_H
#define PS_BALANCE_H

#include <stdbool.h>
#include <stdint.h>

#include "ps_estimate.h"

/** Points of the mass model: the trunk, then per leg (left, right) hip
 *  links, thigh, shank, ankle link + foot. */
#define PS_BALANCE_N_POINTS 9u
/** Corners of a support polygon: two rectangular soles. */
#define PS_BALANCE_MAX_POLY 8u

/** A point mass: position (m) and mass (kg). */
typedef struct {
    float pos_m[3];
    float mass_kg;
} ps_balance_point_t;

/** Unit gravity direction in the trunk frame for a trunk tilted by roll and
 *  pitch (R = Ry(pitch) Rx(roll), the estimator's convention):
 *  R^T (0, 0, -1) = (sin p, -sin r cos p, -cos r cos p).
 *  @units rad  @rt RT-SAFE, pure */
void ps_balance_gravity_body(float roll_rad, float pitch_rad, float out[3]);

/** @return true when k carries a mass model (trunk_mass_kg > 0) */
bool ps_balance_has_mass_model(const ps_kinematics_cfg_t *k);

/** The mass model's points in the pelvis frame for the legs' joint angles
 *  (q_leg[side][PS_LEG_*], side 0 left).
 *  @return PS_BALANCE_N_POINTS | -EINVAL k or an array NULL, or no mass model
 *  @units rad in, m and kg out  @rt RT-SAFE O(1) */
int ps_balance_points(const ps_kinematics_cfg_t *k, const float q_leg[2][PS_LEG_N_JOINTS],
                      ps_balance_point_t out[PS_BALANCE_N_POINTS]);

/** Mass-weighted mean of n points.
 *  @return 0 | -EINVAL (NULL, n 0, total mass <= 0 or not finite)  @rt RT-SAFE */
int ps_balance_com(const ps_balance_point_t *pts, uint32_t n, float out_com_m[3]);

/** Linear momentum p = sum m_i v_i and angular momentum about the CoM
 *  L = sum m_i (r_i - c) x v_i, the velocities from two sets of the same
 *  points dt_s apart (now and before; c is now's CoM).
 *  @return 0 | -EINVAL (NULL, n 0, dt <= 0, no mass)
 *  @units kg m/s, kg m^2/s  @rt RT-SAFE O(n) */
int ps_balance_momentum(const ps_balance_point_t *now, const ps_balance_point_t *before,
                        uint32_t n, float dt_s, float out_p[3], float out_l[3]);

/** CoM velocity over the ground by leg odometry: a sole that stays on the
 *  ground is the fixed point. With c and f the CoM and that sole in the
 *  trunk frame now and dt_s before, and w the trunk's angular velocity
 *  (gyro), the CoM moves relative to the sole at
 *    v = (c - c_before)/dt - (f - f_before)/dt + w x (c - f)
 *  in the trunk frame; out = R v with R the trunk's orientation in the
 *  ground frame. Unlike differencing ground-frame positions, it does not
 *  differentiate the tilt estimate (which a push's acceleration disturbs).
 *  @return 0 | -EINVAL NULL or dt <= 0  @units m, rad/s, s, m/s  @rt RT-SAFE */
int ps_balance_com_velocity_odometry(const float com_now[3], const float com_before[3],
                                     const float sole_now[3], const float sole_before[3],
                                     const float gyro_rad_s[3], const float (*rot)[3], float dt_s,
                                     float out_m_s[3]);

/** Capture point (instantaneous, LIPM) of a CoM at com_m (z: height above the
 *  ground) moving at vel_m_s: xi = c_xy + v_xy / sqrt(g / z).
 *  @return 0 | -EINVAL (NULL, z or g <= 0, not finite)  @units m, m/s, m/s^2
 *  @rt RT-SAFE */
int ps_balance_capture_point(const float com_m[3], const float vel_m_s[3], float g_m_s2,
                             float out_xy[2]);

/** The base of support: convex hull of the corners of the soles in contact,
 *  each a rectangle length x width centred at sole_xy[s] and turned by
 *  yaw_rad[s]. Counter-clockwise.
 *  @return corners written (4 with one foot, up to 8 with two) | 0 no foot in
 *          contact | -EINVAL NULL or non-positive size  @units m, rad
 *  @rt RT-SAFE O(1) */
int ps_balance_support_polygon(const float sole_xy[2][2], const float yaw_rad[2],
                               const bool is_contact[2], float length_m, float width_m,
                               float out_xy[PS_BALANCE_MAX_POLY][2]);

/** Signed distance from p to a convex counter-clockwise polygon: > 0 inside
 *  (distance to the nearest edge), < 0 outside (distance to the polygon).
 *  n 1: distance to the point, negated; n 0 or NULL: -INFINITY.
 *  @units m  @rt RT-SAFE O(n) */
float ps_balance_polygon_distance(const float (*poly)[2], int n, const float p[2]);

/** Centroid of a polygon's corners (the BoS centre the reward targets).
 *  @return 0 | -EINVAL n < 1  @rt RT-SAFE */
int ps_balance_polygon_centre(const float (*poly)[2], int n, float out_xy[2]);

/** CoP of several contacts: sum f_i p_i / sum f_i over the contacts' points
 *  and normal forces. @return 0 | -EINVAL (NULL, n 0, total force <= 0)
 *  @units m, N  @rt RT-SAFE */
int ps_balance_cop(const float (*point_xy)[2], const float *force_n, uint32_t n,
                   float out_xy[2]);

#endif /* PS_BALANCE_H */
