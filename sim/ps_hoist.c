#include "ps_hoist.h"

#include <errno.h>
#include <string.h>

#include "../rt/ps_err.h"

#define GRAVITY_M_S2 9.81

void ps_hoist_init(ps_hoist_t *h, const ps_sim_robot_t *robot, uint64_t seed)
{
    memset(h, 0, sizeof(*h));
    h->n_joints = robot->n_joints;
    for (uint32_t j = 0; j < robot->n_joints; j++) {
        ps_devices_init_actuator(&h->act[j], &robot->act[j], &robot->lim[j], &robot->devices);
        h->q_rad[j] = robot->stance_rad[j];
    }
    ps_devices_init_imu(&h->imu, &robot->imu, &robot->devices, seed);
    h->imu_bus_idx = robot->imu.bus_idx;
}

int ps_hoist_take_frame(ps_hoist_t *h, uint32_t bus_idx, const ps_can_frame_t *f,
                        ps_can_frame_t *out_reply, int *out_joint)
{
    h->n_frames++;
    const int rc = ps_devices_route_frame(h->act, h->n_joints, bus_idx, f, h->q_rad, h->qd_rad_s,
                                          out_reply, out_joint);
    if (rc == -ENOENT)
        h->n_unclaimed++;
    else if (rc == -PS_ERR_PROTOCOL)
        h->n_bad_frames++;
    else if (rc == 1)
        h->n_replies++;
    return rc;
}

int ps_hoist_step(ps_hoist_t *h, int64_t now_ns, double dt_s,
                  ps_can_frame_t out_imu[PS_IMU_MAX_FRAMES])
{
    for (uint32_t j = 0; j < h->n_joints; j++) {
        const double tau =
            ps_devices_step_actuator(&h->act[j], h->q_rad[j], h->qd_rad_s[j], now_ns, dt_s);
        const double qdd =
            (tau - PS_HOIST_DAMPING_NM_S_RAD * h->qd_rad_s[j]) / PS_HOIST_INERTIA_KG_M2;
        h->qd_rad_s[j] += qdd * dt_s; /* semi-implicit Euler: velocity first */
        h->q_rad[j] += h->qd_rad_s[j] * dt_s;
    }
    static const double GYRO_RAD_S[3] = {0.0, 0.0, 0.0};
    static const double ACCEL_M_S2[3] = {0.0, 0.0, GRAVITY_M_S2}; /* upright, still */
    return ps_devices_tick_imu(&h->imu, h->tick++, GYRO_RAD_S, ACCEL_M_S2, now_ns, out_imu);
}

void ps_hoist_set_power(ps_hoist_t *h, bool is_powered)
{
    for (uint32_t j = 0; j < h->n_joints; j++)
        h->act[j].is_powered = is_powered;
}
