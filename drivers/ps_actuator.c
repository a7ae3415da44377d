/*
 * ps_actuator: protocol registry and the one place where gear ratio,
 * direction and zero offset are applied. See ps_actuator.h.
 */
#include "ps_actuator.h"

#include <math.h>
#include <string.h>

#include "../rt/ps_err.h"
#include "ps_mit.h"
#include "ps_moteus.h"
#include "ps_robstride.h"

static const ps_act_proto_t *const PROTOS[PS_ACT_PROTO_COUNT] = {
    [PS_ACT_PROTO_MIT] = &ps_mit_proto,
    [PS_ACT_PROTO_ROBSTRIDE] = &ps_robstride_proto,
    [PS_ACT_PROTO_MOTEUS] = &ps_moteus_proto,
};
_Static_assert(sizeof(PROTOS) / sizeof(PROTOS[0]) == PS_ACT_PROTO_COUNT, "one table per protocol");

const ps_act_proto_t *ps_act_proto_get(ps_act_proto_id_t id)
{
    return ((unsigned)id < PS_ACT_PROTO_COUNT) ? PROTOS[id] : NULL;
}

int ps_act_proto_find(const char *name)
{
    if (name == NULL)
        return -ENOENT;
    for (unsigned i = 0; i < PS_ACT_PROTO_COUNT; i++)
        if (strcmp(PROTOS[i]->name, name) == 0)
            return (int)i;
    return -ENOENT;
}

static bool is_ordered(float lo, float hi)
{
    return isfinite(lo) && isfinite(hi) && lo < hi;
}

int ps_act_check_cfg(const ps_act_cfg_t *a, char *err, size_t err_len)
{
    const ps_act_proto_t *p = a != NULL ? ps_act_proto_get(a->protocol) : NULL;
    if (p == NULL) {
        ps_err_format(err, err_len, "protocol: not one of the known protocols");
        return -EINVAL;
    }
    const ps_act_range_t *w = &a->wire;
    if (!is_ordered(w->p_min_rad, w->p_max_rad) || !is_ordered(w->v_min_rad_s, w->v_max_rad_s) ||
        !is_ordered(0.0f, w->kp_max_nm_rad) || !is_ordered(0.0f, w->kd_max_nm_s_rad) ||
        !is_ordered(w->t_min_nm, w->t_max_nm) || !is_ordered(w->i_min_a, w->i_max_a)) {
        ps_err_format(err, err_len, "wire: ranges must be finite with min < max, kp/kd max > 0");
        return -EINVAL;
    }
    if (!isfinite(a->gear_ratio) || !(a->gear_ratio > 0.0f)) {
        ps_err_format(err, err_len, "gear_ratio: %g is not > 0", (double)a->gear_ratio);
        return -EINVAL;
    }
    if (a->direction != 1.0f && a->direction != -1.0f) {
        ps_err_format(err, err_len, "direction: %g is not +1 or -1", (double)a->direction);
        return -EINVAL;
    }
    if (!isfinite(a->zero_offset_rad)) {
        ps_err_format(err, err_len, "zero_offset_rad: not finite");
        return -EINVAL;
    }
    const uint32_t can_id_min = p->can_id_min > 0u ? p->can_id_min : 1u;
    if (a->can_id < can_id_min || a->can_id > p->id_max || a->reply_id > p->id_max) {
        ps_err_format(err, err_len,
                      "can_id/reply_id: 0x%x/0x%x outside [0x%x, 0x%x] for protocol %s", a->can_id,
                      a->reply_id, can_id_min, p->id_max, p->name);
        return -EINVAL;
    }
    return 0;
}

bool ps_act_motor_is_modelled(const ps_act_motor_t *m)
{
    return m != NULL && m->peak_torque_nm > 0.0f;
}

int ps_act_check_motor(const ps_act_motor_t *m, char *err, size_t err_len)
{
    if (m == NULL) {
        ps_err_format(err, err_len, "motor: NULL");
        return -EINVAL;
    }
    const ps_act_motor_t zero = {0};
    if (memcmp(m, &zero, sizeof(zero)) == 0)
        return 0;
    if (!isfinite(m->peak_torque_nm) || !(m->peak_torque_nm > 0.0f)) {
        ps_err_format(err, err_len, "peak_torque_nm: %g is not > 0", (double)m->peak_torque_nm);
        return -EINVAL;
    }
    if (!isfinite(m->rated_torque_nm) || !(m->rated_torque_nm > 0.0f) ||
        m->rated_torque_nm > m->peak_torque_nm) {
        ps_err_format(err, err_len, "rated_torque_nm: %g is not in (0, peak_torque_nm %g]",
                      (double)m->rated_torque_nm, (double)m->peak_torque_nm);
        return -EINVAL;
    }
    if (!isfinite(m->no_load_speed_rad_s) || !isfinite(m->rated_speed_rad_s) ||
        !(m->rated_speed_rad_s >= 0.0f) || !(m->rated_speed_rad_s < m->no_load_speed_rad_s)) {
        ps_err_format(err, err_len, "rated_speed_rad_s: %g is not in [0, no_load_speed_rad_s %g)",
                      (double)m->rated_speed_rad_s, (double)m->no_load_speed_rad_s);
        return -EINVAL;
    }
    if (!isfinite(m->armature_kg_m2) || !(m->armature_kg_m2 >= 0.0f)) {
        ps_err_format(err, err_len, "armature_kg_m2: %g is not >= 0", (double)m->armature_kg_m2);
        return -EINVAL;
    }
    if (!isfinite(m->pd_hz) || !(m->pd_hz > 0.0f)) {
        ps_err_format(err, err_len, "pd_hz: %g is not > 0", (double)m->pd_hz);
        return -EINVAL;
    }
    return 0;
}

float ps_act_motor_limit_torque(const ps_act_motor_t *m, float tau_nm, float omega_rad_s)
{
    if (!ps_act_motor_is_modelled(m))
        return tau_nm;
    if (isnan(tau_nm) || isnan(omega_rad_s))
        return NAN;
    const float w0 = m->no_load_speed_rad_s;
    const float stall = m->rated_torque_nm * w0 / (w0 - m->rated_speed_rad_s);
    const float peak = m->peak_torque_nm;
    /* The line tau = stall (s - w / w0) for s = +1 (upper bound) and -1 (lower). */
    float hi = stall * (1.0f - omega_rad_s / w0);
    float lo = stall * (-1.0f - omega_rad_s / w0);
    hi = hi > peak ? peak : (hi < -peak ? -peak : hi);
    lo = lo < -peak ? -peak : (lo > peak ? peak : lo);
    return tau_nm > hi ? hi : (tau_nm < lo ? lo : tau_nm);
}

/* Order a pair after a sign flip. */
static void ordered(float x, float y, float *lo, float *hi)
{
    *lo = x < y ? x : y;
    *hi = x < y ? y : x;
}

void ps_act_joint_range(const ps_act_cfg_t *a, ps_act_range_t *out)
{
    const float n = a->gear_ratio, d = a->direction, z = a->zero_offset_rad;
    const ps_act_range_t *w = &a->wire;
    ordered(z + w->p_min_rad / (d * n), z + w->p_max_rad / (d * n), &out->p_min_rad,
            &out->p_max_rad);
    ordered(w->v_min_rad_s / (d * n), w->v_max_rad_s / (d * n), &out->v_min_rad_s,
            &out->v_max_rad_s);
    out->kp_max_nm_rad = w->kp_max_nm_rad * n * n;
    out->kd_max_nm_s_rad = w->kd_max_nm_s_rad * n * n;
    ordered(w->t_min_nm * d * n, w->t_max_nm * d * n, &out->t_min_nm, &out->t_max_nm);
    ordered(w->i_min_a, w->i_max_a, &out->i_min_a, &out->i_max_a);
}

void ps_act_joint_lsb(const ps_act_cfg_t *a, float out_lsb[5])
{
    ps_act_range_t j;
    ps_act_joint_range(a, &j);
    const uint32_t *bits = ps_act_proto_get(a->protocol)->resolution_bits;
    const float span[5] = {
        j.p_max_rad - j.p_min_rad, j.v_max_rad_s - j.v_min_rad_s, j.kp_max_nm_rad,
        j.kd_max_nm_s_rad,         j.t_max_nm - j.t_min_nm,
    };
    for (unsigned k = 0; k < 5u; k++)
        out_lsb[k] = span[k] / (float)((1u << bits[k]) - 1u);
}

void ps_act_cmd_to_motor(const ps_act_cfg_t *a, const ps_act_cmd_t *j, ps_act_cmd_t *m)
{
    const float n = a->gear_ratio, d = a->direction;
    m->q_rad = d * n * (j->q_rad - a->zero_offset_rad);
    m->qd_rad_s = d * n * j->qd_rad_s;
    m->kp_nm_rad = j->kp_nm_rad / (n * n);
    m->kd_nm_s_rad = j->kd_nm_s_rad / (n * n);
    m->tau_ff_nm = d * j->tau_ff_nm / n;
}

void ps_act_cmd_from_motor(const ps_act_cfg_t *a, const ps_act_cmd_t *m, ps_act_cmd_t *j)
{
    const float n = a->gear_ratio, d = a->direction;
    j->q_rad = a->zero_offset_rad + m->q_rad / (d * n);
    j->qd_rad_s = m->qd_rad_s / (d * n);
    j->kp_nm_rad = m->kp_nm_rad * n * n;
    j->kd_nm_s_rad = m->kd_nm_s_rad * n * n;
    j->tau_ff_nm = m->tau_ff_nm * d * n;
}

void ps_act_meas_from_motor(const ps_act_cfg_t *a, const ps_act_meas_t *m, ps_act_meas_t *j)
{
    const float n = a->gear_ratio, d = a->direction;
    *j = *m;
    j->q_rad = a->zero_offset_rad + m->q_rad / (d * n);
    j->qd_rad_s = m->qd_rad_s / (d * n);
    j->tau_nm = m->tau_nm * d * n;
}

void ps_act_meas_to_motor(const ps_act_cfg_t *a, const ps_act_meas_t *j, ps_act_meas_t *m)
{
    const float n = a->gear_ratio, d = a->direction;
    *m = *j;
    m->q_rad = d * n * (j->q_rad - a->zero_offset_rad);
    m->qd_rad_s = d * n * j->qd_rad_s;
    m->tau_nm = d * j->tau_nm / n;
}

/* A joint command at the edge of the joint-side wire range can land a few
 * ulps outside the motor-side range after the conversion (kp / (N N) against
 * (kp_max N) N, and so on). Such a value is put back on the edge; anything
 * further out is left for the encoder to refuse. NaN stays NaN. */
static float snap_into(float x, float lo, float hi)
{
    const float tol = 1e-5f * (hi - lo);
    if (x < lo && x >= lo - tol)
        return lo;
    if (x > hi && x <= hi + tol)
        return hi;
    return x;
}

int ps_act_encode_command(const ps_act_cfg_t *a, const ps_act_cmd_t *joint, ps_can_frame_t *out,
                          size_t max)
{
    const ps_act_proto_t *p = a != NULL ? ps_act_proto_get(a->protocol) : NULL;
    if (p == NULL || joint == NULL || out == NULL)
        return -EINVAL;
    ps_act_cmd_t m;
    ps_act_cmd_to_motor(a, joint, &m);
    const ps_act_range_t *w = &a->wire;
    m.q_rad = snap_into(m.q_rad, w->p_min_rad, w->p_max_rad);
    m.qd_rad_s = snap_into(m.qd_rad_s, w->v_min_rad_s, w->v_max_rad_s);
    m.kp_nm_rad = snap_into(m.kp_nm_rad, 0.0f, w->kp_max_nm_rad);
    m.kd_nm_s_rad = snap_into(m.kd_nm_s_rad, 0.0f, w->kd_max_nm_s_rad);
    m.tau_ff_nm = snap_into(m.tau_ff_nm, w->t_min_nm, w->t_max_nm);
    return p->encode_cmd(a, &m, out, max);
}

int ps_act_encode_request(const ps_act_cfg_t *a, ps_act_request_t req, ps_can_frame_t *out,
                          size_t max)
{
    const ps_act_proto_t *p = a != NULL ? ps_act_proto_get(a->protocol) : NULL;
    if (p == NULL || out == NULL || (unsigned)req >= PS_ACT_REQ_COUNT)
        return -EINVAL;
    return p->encode_request(a, req, out, max);
}

int ps_act_decode_fault(const ps_act_cfg_t *a, const ps_can_frame_t *f, uint32_t *out_fault_bits)
{
    const ps_act_proto_t *p = a != NULL ? ps_act_proto_get(a->protocol) : NULL;
    if (p == NULL || f == NULL || out_fault_bits == NULL)
        return -EINVAL;
    return p->decode_fault != NULL ? p->decode_fault(a, f, out_fault_bits) : -ENOENT;
}

int ps_act_decode_reply(const ps_act_cfg_t *a, const ps_can_frame_t *f, ps_act_meas_t *out_joint)
{
    const ps_act_proto_t *p = a != NULL ? ps_act_proto_get(a->protocol) : NULL;
    if (p == NULL || f == NULL || out_joint == NULL)
        return -EINVAL;
    if (!p->match_reply(a, f))
        return -ENOENT;
    ps_act_meas_t m = {0};
    const int rc = p->decode_reply(a, f, &m);
    if (rc < 0)
        return rc;
    ps_act_meas_t j;
    ps_act_meas_from_motor(a, &m, &j);
    /* A protocol without a packing range (moteus floats) can report a value
     * that is finite on the motor side and not once geared to the joint. */
    if (!isfinite(j.q_rad) || !isfinite(j.qd_rad_s) || !isfinite(j.tau_nm))
        return -PS_ERR_PROTOCOL;
    j.t_ns = out_joint->t_ns;
    *out_joint = j;
    return 0;
}

const char *ps_act_fault_name(uint32_t bits)
{
    static const char *const NAMES[] = {
        "OVERVOLTAGE", "UNDERVOLTAGE", "OVERCURRENT", "DRIVER_OVERTEMP", "MOTOR_OVERTEMP",
        "COMMS_LOST",  "OVERLOAD",     "ENCODER",     "OTHER",
    };
    if (bits == 0u)
        return "none";
    for (unsigned i = 0; i < sizeof(NAMES) / sizeof(NAMES[0]); i++)
        if (bits & (1u << i))
            return NAMES[i];
    return "OTHER";
}
