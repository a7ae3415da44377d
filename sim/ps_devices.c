#include "ps_devices.h"

#include <math.h>
#include <string.h>

#include "../drivers/ps_imu.h"
#include "../rt/ps_clock.h"
#include "../rt/ps_err.h"

/* ---- actuator -------------------------------------------------------- */

void ps_devices_init_actuator(ps_devices_actuator_t *a, const ps_act_cfg_t *act,
                              const ps_act_limits_t *lim, const ps_sim_devices_cfg_t *sim)
{
    memset(a, 0, sizeof *a);
    a->act = *act;
    a->lim = *lim;
    a->sim = *sim;
    a->temp_c = sim->ambient_c;
    a->is_powered = true;
}

static double clampd(double x, double lo, double hi)
{
    return x < lo ? lo : (x > hi ? hi : x);
}

/* The torque the drive's PD asks for with its current command at this joint
 * state. Both limits apply: the wire t range is what the firmware can
 * represent, the joint's torque_max is the drive's configured current limit. */
static double pd_command_torque(const ps_devices_actuator_t *a, double q_rad, double qd_rad_s)
{
    if (!a->is_motor_mode || !a->has_cmd || !a->is_powered)
        return 0.0;
    const ps_act_cmd_t *c = &a->cmd;
    const double p = q_rad - a->zero_offset_rad;
    double tau = (double)c->kp_nm_rad * ((double)c->q_rad - p) +
                 (double)c->kd_nm_s_rad * ((double)c->qd_rad_s - qd_rad_s) + (double)c->tau_ff_nm;
    ps_act_range_t w;
    ps_act_joint_range(&a->act, &w);
    tau = clampd(tau, (double)w.t_min_nm, (double)w.t_max_nm);
    tau = clampd(tau, -(double)a->lim.torque_max_nm, (double)a->lim.torque_max_nm);
    return tau;
}

/* What the motor can deliver of a joint torque at the joint speed: the
 * drive's torque-speed limit, applied on the motor side (ps_act_motor_t). */
static double motor_torque(const ps_devices_actuator_t *a, double tau_nm, double qd_rad_s)
{
    const ps_act_cfg_t *c = &a->act;
    if (!ps_act_motor_is_modelled(&c->motor))
        return tau_nm;
    const double n = (double)c->gear_ratio, d = (double)c->direction;
    const float tau_m = (float)(d * tau_nm / n);
    const float omega_m = (float)(d * n * qd_rad_s);
    return d * n * (double)ps_act_motor_limit_torque(&c->motor, tau_m, omega_m);
}

static double pd_torque(const ps_devices_actuator_t *a, double q_rad, double qd_rad_s)
{
    return motor_torque(a, pd_command_torque(a, q_rad, qd_rad_s), qd_rad_s);
}

/* One LSB of each field (the protocol's resolution, seen from the joint): the
 * slack a correctly clamped host command may show after quantisation. */
static bool is_out_of_limits(const ps_devices_actuator_t *a, const ps_act_cmd_t *c)
{
    float d[5];
    ps_act_joint_lsb(&a->act, d);
    const ps_act_limits_t *l = &a->lim;
    return c->q_rad < l->pos_min_rad - d[0] || c->q_rad > l->pos_max_rad + d[0] ||
           fabsf(c->qd_rad_s) > l->vel_max_rad_s + d[1] || c->kp_nm_rad > l->kp_max_nm_rad + d[2] ||
           c->kd_nm_s_rad > l->kd_max_nm_s_rad + d[3] ||
           fabsf(c->tau_ff_nm) > l->torque_max_nm + d[4];
}

static int make_reply(const ps_devices_actuator_t *a, double q_rad, double qd_rad_s,
                      int64_t arrival_ns, ps_can_frame_t *out)
{
    const ps_act_meas_t joint = {
        .q_rad = (float)(q_rad - a->zero_offset_rad),
        .qd_rad_s = (float)qd_rad_s,
        .tau_nm = (float)pd_torque(a, q_rad, qd_rad_s),
        .temp_c = (float)a->temp_c,
        .fault_bits = a->fault_bits,
    };
    ps_act_meas_t motor;
    ps_act_meas_to_motor(&a->act, &joint, &motor);
    const int n = ps_act_proto_get(a->act.protocol)->encode_reply(&a->act, &motor, out, 1);
    if (n != 1)
        return -PS_ERR_PROTOCOL; /* protocols with multi-frame replies: not emulated yet */
    out->t_ns = arrival_ns + ps_s_to_ns((double)a->sim.reply_latency_s);
    return 0;
}

static void handle_request(ps_devices_actuator_t *a, int req, const ps_can_frame_t *f, double q_rad)
{
    if (req == PS_ACT_REQ_ENABLE || req == PS_ACT_REQ_CLEAR_FAULT) {
        const bool is_hot = a->temp_c >= (double)a->act.temp_max_c - PS_DEVICES_TEMP_HYST_C;
        if (!is_hot) {
            a->fault_bits = 0u;
            if (req == PS_ACT_REQ_ENABLE) {
                a->is_motor_mode = true;
                a->has_cmd = false;       /* limp until the first set-point */
                a->last_cmd_ns = f->t_ns; /* the comms timeout runs from here */
            }
        }
    } else if (req == PS_ACT_REQ_DISABLE) {
        a->is_motor_mode = false;
        a->has_cmd = false;
    } else if (req == PS_ACT_REQ_SET_ZERO) {
        /* The motor reads 0 here from now on: the host, which adds the
         * configured zero offset, sees the joint at zero_offset_rad. */
        a->zero_offset_rad = q_rad - (double)a->act.zero_offset_rad;
    }
}

int ps_devices_handle_frame(ps_devices_actuator_t *a, const ps_can_frame_t *f, double q_rad,
                            double qd_rad_s, ps_can_frame_t *out_reply)
{
    const ps_act_proto_t *p = ps_act_proto_get(a->act.protocol);
    if (!p->is_for_drive(&a->act, f))
        return -ENOENT;
    if (f->len != p->cmd_len || (f->is_fd != 0) != p->is_fd) {
        a->n_bad_frames++;
        return -PS_ERR_PROTOCOL;
    }
    const int req = p->classify_request(&a->act, f);
    if (req >= 0) {
        handle_request(a, req, f, q_rad);
    } else {
        ps_act_cmd_t motor, c;
        if (p->decode_cmd(&a->act, f, &motor) != 0) {
            a->n_bad_frames++;
            return -PS_ERR_PROTOCOL;
        }
        ps_act_cmd_from_motor(&a->act, &motor, &c);
        a->n_cmd_frames++;
        if (is_out_of_limits(a, &c))
            a->n_cmd_out_of_limits++;
        if (a->is_motor_mode) {
            a->cmd = c;
            a->has_cmd = true;
            a->last_cmd_ns = f->t_ns;
        } else {
            a->n_cmd_ignored++;
        }
    }
    if (f->t_ns < a->drop_replies_until_ns) {
        a->n_replies_dropped++;
        return 0;
    }
    if (make_reply(a, q_rad, qd_rad_s, f->t_ns, out_reply) < 0)
        return -PS_ERR_PROTOCOL;
    a->n_replies++;
    return 1;
}

double ps_devices_step_actuator(ps_devices_actuator_t *a, double q_rad, double qd_rad_s,
                                int64_t now_ns, double dt_s)
{
    if (a->is_motor_mode && now_ns - a->last_cmd_ns > PS_DEVICES_COMMS_TIMEOUT_NS) {
        a->is_motor_mode = false;
        a->has_cmd = false;
        a->fault_bits |= PS_ACT_FAULT_COMMS_LOST;
    }
    /* The drive's PD runs at its own rate (pd_hz; every step when it is
     * not modelled or faster than the physics): its torque is held in
     * between, while the torque-speed limit acts on the speed of each step. */
    const float pd_hz = a->act.motor.pd_hz;
    if (!ps_act_motor_is_modelled(&a->act.motor) || !(pd_hz > 0.0f) || now_ns >= a->pd_due_ns) {
        a->pd_tau_nm = pd_command_torque(a, q_rad, qd_rad_s);
        if (ps_act_motor_is_modelled(&a->act.motor) && pd_hz > 0.0f) {
            const int64_t period_ns = (int64_t)(1e9 / (double)pd_hz);
            if (a->pd_due_ns == 0)
                a->pd_due_ns = now_ns;
            while (a->pd_due_ns <= now_ns)
                a->pd_due_ns += period_ns > 0 ? period_ns : 1;
        }
    }
    const double tau = motor_torque(a, a->pd_tau_nm, qd_rad_s);

    /* Exact discretisation of the first-order model for a power held constant
     * over the step: stable for any dt, unlike explicit Euler. The current is
     * the motor's: joint torque / (gear ratio * kt). */
    const double kt = a->act.kt_nm_a > 0.0f ? (double)a->act.kt_nm_a : 1.0;
    const double i_a = tau / ((double)a->act.gear_ratio * kt);
    const double p_w = i_a * i_a * (double)a->sim.winding_r_ohm;
    const double t_ss_c = (double)a->sim.ambient_c + p_w * (double)a->sim.thermal_r_c_w;
    const double tau_s = (double)a->sim.thermal_tau_s;
    const double alpha = tau_s > 0.0 ? 1.0 - exp(-dt_s / tau_s) : 1.0;
    a->temp_c += (t_ss_c - a->temp_c) * alpha;

    if (a->temp_c > (double)a->act.temp_max_c) {
        a->fault_bits |= PS_ACT_FAULT_MOTOR_OVERTEMP;
        a->is_motor_mode = false;
        a->has_cmd = false;
    }
    a->tau_nm = tau;
    return tau;
}

static int8_t to_int8_c(double t_c)
{
    const double r = nearbyint(t_c);
    if (r > 127.0)
        return 127;
    if (r < -128.0)
        return -128;
    return (int8_t)r;
}

/* ---- IMU -------------------------------------------------------------- */

/* splitmix64 expands the 32-bit scenario seed into xoshiro's 256-bit state
 * (the seeding its authors recommend); xoshiro256** then gives a fast,
 * platform-independent stream, unlike rand(). */
static uint64_t splitmix64(uint64_t *x)
{
    uint64_t z = (*x += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

static uint64_t rotl(uint64_t x, int k)
{
    return (x << k) | (x >> (64 - k));
}

static uint64_t xoshiro_next(uint64_t s[4])
{
    const uint64_t result = rotl(s[1] * 5u, 7) * 9u;
    const uint64_t t = s[1] << 17;
    s[2] ^= s[0];
    s[3] ^= s[1];
    s[1] ^= s[2];
    s[0] ^= s[3];
    s[2] ^= t;
    s[3] = rotl(s[3], 45);
    return result;
}

/* Uniform in (0, 1]: the top 53 bits, shifted by one so log() never sees 0. */
static double uniform01(uint64_t s[4])
{
    return ((double)(xoshiro_next(s) >> 11) + 1.0) * 0x1.0p-53;
}

/* Box-Muller, one normal per call (the second is discarded to keep the
 * stream a pure function of the call count). */
static double gaussian(uint64_t s[4])
{
    const double u1 = uniform01(s);
    const double u2 = uniform01(s);
    return sqrt(-2.0 * log(u1)) * cos(2.0 * 3.14159265358979323846 * u2);
}

void ps_devices_init_imu(ps_devices_imu_t *imu, const ps_imu_cfg_t *cfg,
                         const ps_sim_devices_cfg_t *sim, uint64_t seed)
{
    memset(imu, 0, sizeof *imu);
    imu->cfg = *cfg;
    imu->sim = *sim;
    uint64_t x = seed ^ 0x494D5531ull; /* "IMU1": a stream of its own per seed */
    for (unsigned i = 0; i < 4; i++)
        imu->rng[i] = splitmix64(&x);
    for (unsigned ax = 0; ax < 3; ax++) {
        imu->gyro_bias_rad_s[ax] = (2.0 * uniform01(imu->rng) - 1.0) * (double)sim->gyro_bias_rad_s;
        imu->accel_bias_m_s2[ax] = (2.0 * uniform01(imu->rng) - 1.0) * (double)sim->accel_bias_m_s2;
    }
}

int ps_devices_tick_imu(ps_devices_imu_t *imu, uint64_t tick, const double gyro_rad_s[3],
                        const double accel_m_s2[3], int64_t t_ns,
                        ps_can_frame_t out[PS_IMU_MAX_FRAMES])
{
    const uint32_t div = imu->cfg.rate_div > 0 ? imu->cfg.rate_div : 1u;
    if (tick % div != 0)
        return 0;
    ps_imu_sample_t s = {.seq = imu->seq, .status = 0};
    for (unsigned ax = 0; ax < 3; ax++) {
        s.gyro_body_rad_s[ax] = (float)(gyro_rad_s[ax] + imu->gyro_bias_rad_s[ax] +
                                        (double)imu->sim.gyro_noise_rad_s * gaussian(imu->rng));
        s.accel_body_m_s2[ax] = (float)(accel_m_s2[ax] + imu->accel_bias_m_s2[ax] +
                                        (double)imu->sim.accel_noise_m_s2 * gaussian(imu->rng));
    }
    s.temp_c = to_int8_c((double)imu->sim.ambient_c);
    const int n = ps_imu_encode(&imu->cfg, &s, (uint32_t)imu->n_samples, t_ns, out);
    for (int i = 0; i < n; i++)
        out[i].t_ns = t_ns;
    imu->seq++;
    imu->n_samples++;
    return n;
}

int ps_devices_route_frame(ps_devices_actuator_t *acts, uint32_t n_joints, uint32_t bus_idx,
                           const ps_can_frame_t *f, const double *q_rad, const double *qd_rad_s,
                           ps_can_frame_t *out_reply, int *out_joint)
{
    if (out_joint != NULL)
        *out_joint = -1;
    for (uint32_t j = 0; j < n_joints; j++) {
        if (acts[j].act.bus_idx != bus_idx)
            continue;
        const int rc = ps_devices_handle_frame(&acts[j], f, q_rad[j], qd_rad_s[j], out_reply);
        if (rc != -ENOENT) {
            if (out_joint != NULL)
                *out_joint = (int)j;
            return rc;
        }
    }
    return -ENOENT;
}

int ps_devices_take_fault_report(ps_devices_actuator_t *a, int64_t now_ns, ps_can_frame_t *out)
{
    const ps_act_proto_t *p = ps_act_proto_get(a->act.protocol);
    a->fault_bits_reported &= a->fault_bits; /* cleared faults may come back */
    if (p == NULL || p->encode_fault == NULL || (a->fault_bits & ~a->fault_bits_reported) == 0u)
        return 0;
    if (p->encode_fault(&a->act, a->fault_bits, out, 1) != 1)
        return 0;
    out->t_ns = now_ns;
    a->fault_bits_reported = a->fault_bits;
    a->n_fault_reports++;
    return 1;
}
