#include "ps_devices.h"

#include <math.h>
#include <string.h>

#include "../drivers/ps_imu_msg.h"
#include "../rt/ps_clock.h"
#include "../rt/ps_err.h"

/* ---- actuator -------------------------------------------------------- */

void ps_devices_init_actuator(ps_devices_actuator_t *a, const ps_joint_cfg_t *j,
                              const ps_sim_devices_cfg_t *sim)
{
    memset(a, 0, sizeof *a);
    a->joint = *j;
    a->sim = *sim;
    a->temp_c = sim->ambient_c;
    a->fault = PS_MIT_FAULT_NONE;
}

static double clampd(double x, double lo, double hi)
{
    return x < lo ? lo : (x > hi ? hi : x);
}

/* The torque the driver applies for its current command at this joint state.
 * Both limits apply: the wire t range is what the firmware can represent, the
 * joint's torque_max is the drive's configured current limit. */
static double pd_torque(const ps_devices_actuator_t *a, double q_rad, double qd_rad_s)
{
    if (!a->is_motor_mode || !a->has_cmd)
        return 0.0;
    const ps_mit_cmd_t *c = &a->cmd;
    const double p = q_rad - a->zero_offset_rad;
    double tau = (double)c->kp_nm_rad * ((double)c->p_rad - p) +
                 (double)c->kd_nm_s_rad * ((double)c->v_rad_s - qd_rad_s) + (double)c->t_ff_nm;
    tau = clampd(tau, (double)a->joint.wire.t_min_nm, (double)a->joint.wire.t_max_nm);
    tau = clampd(tau, -(double)a->joint.torque_max_nm, (double)a->joint.torque_max_nm);
    return tau;
}

/* One LSB of an n-bit field over [lo, hi]: the slack a correctly clamped host
 * command may show after quantisation (rounding to nearest moves it by half). */
static float lsb(float lo, float hi, unsigned bits)
{
    return (hi - lo) / (float)((1u << bits) - 1u);
}

static bool is_out_of_limits(const ps_joint_cfg_t *j, const ps_mit_cmd_t *c)
{
    const ps_mit_range_t *w = &j->wire;
    const float dp = lsb(w->p_min_rad, w->p_max_rad, PS_MIT_P_BITS);
    const float dv = lsb(w->v_min_rad_s, w->v_max_rad_s, PS_MIT_V_BITS);
    const float dkp = lsb(0.0f, w->kp_max_nm_rad, PS_MIT_KP_BITS);
    const float dkd = lsb(0.0f, w->kd_max_nm_s_rad, PS_MIT_KD_BITS);
    const float dt = lsb(w->t_min_nm, w->t_max_nm, PS_MIT_T_BITS);
    return c->p_rad < j->pos_min_rad - dp || c->p_rad > j->pos_max_rad + dp ||
           fabsf(c->v_rad_s) > j->vel_max_rad_s + dv || c->kp_nm_rad > j->kp_max_nm_rad + dkp ||
           c->kd_nm_s_rad > j->kd_max_nm_s_rad + dkd || fabsf(c->t_ff_nm) > j->torque_max_nm + dt;
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

static void make_reply(const ps_devices_actuator_t *a, double q_rad, double qd_rad_s,
                       int64_t arrival_ns, ps_can_frame_t *out)
{
    const double tau = pd_torque(a, q_rad, qd_rad_s);
    const double kt = a->joint.kt_nm_a > 0.0f ? (double)a->joint.kt_nm_a : 1.0;
    /* The MOSFETs sit on the same housing: half the winding's rise is a crude
     * but monotonic coupling, enough for a reply byte the host only logs. */
    const double mos_c = a->sim.ambient_c + 0.5 * (a->temp_c - a->sim.ambient_c);
    const ps_mit_reply_t rep = {
        .motor_id = (uint8_t)(a->joint.can_id & 0xFu),
        .fault = a->fault,
        .p_rad = (float)(q_rad - a->zero_offset_rad),
        .v_rad_s = (float)qd_rad_s,
        .i_a = (float)(tau / kt),
        .temp_mos_c = to_int8_c(mos_c),
        .temp_rotor_c = to_int8_c(a->temp_c),
    };
    memset(out, 0, sizeof *out);
    out->id = a->joint.reply_id;
    out->len = PS_MIT_FRAME_LEN;
    ps_mit_encode_reply(&a->joint.wire, &rep, out->data);
    out->t_ns = arrival_ns + ps_s_to_ns((double)a->sim.reply_latency_s);
}

int ps_devices_handle_frame(ps_devices_actuator_t *a, const ps_can_frame_t *f, double q_rad,
                            double qd_rad_s, ps_can_frame_t *out_reply)
{
    if (f->id != a->joint.can_id)
        return -ENOENT;
    if (f->is_ext || f->len != PS_MIT_FRAME_LEN) {
        a->n_bad_frames++;
        return -PS_ERR_PROTOCOL;
    }
    const int special = ps_mit_classify_special(f->data, f->len);
    if (special == PS_MIT_SPECIAL_ENTER) {
        const bool is_hot = a->temp_c >= (double)a->joint.temp_max_c - PS_DEVICES_TEMP_HYST_C;
        if (!is_hot) {
            a->is_motor_mode = true;
            a->has_cmd = false; /* limp until the first set-point */
            a->fault = PS_MIT_FAULT_NONE;
            a->last_cmd_ns = f->t_ns; /* the comms timeout runs from here */
        }
    } else if (special == PS_MIT_SPECIAL_EXIT) {
        a->is_motor_mode = false;
        a->has_cmd = false;
    } else if (special == PS_MIT_SPECIAL_ZERO) {
        a->zero_offset_rad = q_rad;
    } else {
        ps_mit_cmd_t c;
        if (ps_mit_decode_cmd(&a->joint.wire, f->data, f->len, &c) != 0) {
            a->n_bad_frames++; /* unreachable with len 8 and not special; kept for safety */
            return -PS_ERR_PROTOCOL;
        }
        a->n_cmd_frames++;
        if (is_out_of_limits(&a->joint, &c))
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
    make_reply(a, q_rad, qd_rad_s, f->t_ns, out_reply);
    a->n_replies++;
    return 1;
}

double ps_devices_step_actuator(ps_devices_actuator_t *a, double q_rad, double qd_rad_s,
                                int64_t now_ns, double dt_s)
{
    if (a->is_motor_mode && now_ns - a->last_cmd_ns > PS_DEVICES_COMMS_TIMEOUT_NS) {
        a->is_motor_mode = false;
        a->has_cmd = false;
        a->fault = PS_MIT_FAULT_COMMS_LOST;
    }
    const double tau = pd_torque(a, q_rad, qd_rad_s);

    /* Exact discretisation of the first-order model for a power held constant
     * over the step: stable for any dt, unlike explicit Euler. */
    const double kt = a->joint.kt_nm_a > 0.0f ? (double)a->joint.kt_nm_a : 1.0;
    const double i_a = tau / kt;
    const double p_w = i_a * i_a * (double)a->sim.winding_r_ohm;
    const double t_ss_c = (double)a->sim.ambient_c + p_w * (double)a->sim.thermal_r_c_w;
    const double tau_s = (double)a->sim.thermal_tau_s;
    const double alpha = tau_s > 0.0 ? 1.0 - exp(-dt_s / tau_s) : 1.0;
    a->temp_c += (t_ss_c - a->temp_c) * alpha;

    if (a->temp_c > (double)a->joint.temp_max_c) {
        a->fault = PS_MIT_FAULT_ROTOR_OVERTEMP;
        a->is_motor_mode = false;
        a->has_cmd = false;
    }
    a->tau_nm = tau;
    return tau;
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
                        const double accel_m_s2[3], int64_t t_ns, ps_can_frame_t out[2])
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
    ps_imu_msg_encode(imu->cfg.base_id, &s, out);
    out[0].t_ns = t_ns;
    out[1].t_ns = t_ns;
    imu->seq++;
    imu->n_samples++;
    return 2;
}
