#include "ps_mit.h"

#include <math.h>
#include <stdbool.h>
#include <string.h>

#include "../rt/ps_err.h"

/* The mapping is computed in double: a 16-bit field's half-step boundaries
 * (e.g. p = 0 on a symmetric range maps to exactly 32767.5) must round the
 * same way a hand computation does, and float's 24-bit mantissa leaves too
 * little headroom once (x - min) * 65535 is formed. Still O(1). */
uint32_t ps_mit_float_to_uint(float x, float min, float max, unsigned bits)
{
    const uint32_t top = (bits >= 32u) ? UINT32_MAX : ((1u << bits) - 1u);
    if (isnan(x) || !(max > min))
        return 0u;
    if (x <= min)
        return 0u;
    if (x >= max)
        return top;
    const double scaled = ((double)x - (double)min) * (double)top / ((double)max - (double)min);
    /* Round half up; scaled >= 0 here, so this equals roundf's half away
     * from zero. The reference firmware truncates instead, which biases every
     * set-point by up to one LSB downwards. */
    const double r = floor(scaled + 0.5);
    if (r >= (double)top)
        return top;
    return (uint32_t)r;
}

float ps_mit_uint_to_float(uint32_t u, float min, float max, unsigned bits)
{
    const uint32_t top = (bits >= 32u) ? UINT32_MAX : ((1u << bits) - 1u);
    if (u > top)
        u = top;
    return (float)((double)u * ((double)max - (double)min) / (double)top + (double)min);
}

static bool range_ok(float lo, float hi)
{
    return isfinite(lo) && isfinite(hi) && lo < hi;
}

int ps_mit_check_range(const ps_act_range_t *r)
{
    if (r == NULL)
        return -EINVAL;
    if (!range_ok(r->p_min_rad, r->p_max_rad) || !range_ok(r->v_min_rad_s, r->v_max_rad_s) ||
        !range_ok(0.0f, r->kp_max_nm_rad) || !range_ok(0.0f, r->kd_max_nm_s_rad) ||
        !range_ok(r->t_min_nm, r->t_max_nm) || !range_ok(r->i_min_a, r->i_max_a))
        return -EINVAL;
    return 0;
}

/* Inclusive wire-range test; NaN fails every comparison and is refused. */
static bool in_wire(float x, float lo, float hi)
{
    return isfinite(x) && x >= lo && x <= hi;
}

int ps_mit_encode_cmd(const ps_act_range_t *r, const ps_mit_cmd_t *cmd,
                      uint8_t out[PS_MIT_FRAME_LEN])
{
    if (!in_wire(cmd->p_rad, r->p_min_rad, r->p_max_rad) ||
        !in_wire(cmd->v_rad_s, r->v_min_rad_s, r->v_max_rad_s) ||
        !in_wire(cmd->kp_nm_rad, 0.0f, r->kp_max_nm_rad) ||
        !in_wire(cmd->kd_nm_s_rad, 0.0f, r->kd_max_nm_s_rad) ||
        !in_wire(cmd->t_ff_nm, r->t_min_nm, r->t_max_nm))
        return -PS_ERR_LIMIT;

    const uint32_t p = ps_mit_float_to_uint(cmd->p_rad, r->p_min_rad, r->p_max_rad, PS_MIT_P_BITS);
    const uint32_t v =
        ps_mit_float_to_uint(cmd->v_rad_s, r->v_min_rad_s, r->v_max_rad_s, PS_MIT_V_BITS);
    const uint32_t kp =
        ps_mit_float_to_uint(cmd->kp_nm_rad, 0.0f, r->kp_max_nm_rad, PS_MIT_KP_BITS);
    const uint32_t kd =
        ps_mit_float_to_uint(cmd->kd_nm_s_rad, 0.0f, r->kd_max_nm_s_rad, PS_MIT_KD_BITS);
    const uint32_t t = ps_mit_float_to_uint(cmd->t_ff_nm, r->t_min_nm, r->t_max_nm, PS_MIT_T_BITS);

    uint8_t buf[PS_MIT_FRAME_LEN];
    buf[0] = (uint8_t)(p >> 8);
    buf[1] = (uint8_t)(p & 0xFFu);
    buf[2] = (uint8_t)(v >> 4);
    buf[3] = (uint8_t)(((v & 0xFu) << 4) | (kp >> 8));
    buf[4] = (uint8_t)(kp & 0xFFu);
    buf[5] = (uint8_t)(kd >> 4);
    buf[6] = (uint8_t)(((kd & 0xFu) << 4) | (t >> 8));
    buf[7] = (uint8_t)(t & 0xFFu);

    /* A command at p, v, kp, kd all at their maxima and t within 3 LSB of its
     * maximum packs to FF..FC/FD/FE, which every driver reads as a mode
     * change instead of a set-point. Refuse rather than send it. */
    if (ps_mit_classify_special(buf, PS_MIT_FRAME_LEN) != 0)
        return -PS_ERR_LIMIT;
    memcpy(out, buf, sizeof buf);
    return 0;
}

int ps_mit_decode_cmd(const ps_act_range_t *r, const uint8_t *data, uint8_t len, ps_mit_cmd_t *out)
{
    if (len != PS_MIT_FRAME_LEN || ps_mit_classify_special(data, len) != 0)
        return -PS_ERR_PROTOCOL;
    const uint32_t p = ((uint32_t)data[0] << 8) | data[1];
    const uint32_t v = ((uint32_t)data[2] << 4) | ((uint32_t)data[3] >> 4);
    const uint32_t kp = (((uint32_t)data[3] & 0xFu) << 8) | data[4];
    const uint32_t kd = ((uint32_t)data[5] << 4) | ((uint32_t)data[6] >> 4);
    const uint32_t t = (((uint32_t)data[6] & 0xFu) << 8) | data[7];
    out->p_rad = ps_mit_uint_to_float(p, r->p_min_rad, r->p_max_rad, PS_MIT_P_BITS);
    out->v_rad_s = ps_mit_uint_to_float(v, r->v_min_rad_s, r->v_max_rad_s, PS_MIT_V_BITS);
    out->kp_nm_rad = ps_mit_uint_to_float(kp, 0.0f, r->kp_max_nm_rad, PS_MIT_KP_BITS);
    out->kd_nm_s_rad = ps_mit_uint_to_float(kd, 0.0f, r->kd_max_nm_s_rad, PS_MIT_KD_BITS);
    out->t_ff_nm = ps_mit_uint_to_float(t, r->t_min_nm, r->t_max_nm, PS_MIT_T_BITS);
    return 0;
}

void ps_mit_encode_special(ps_mit_special_t which, uint8_t out[PS_MIT_FRAME_LEN])
{
    memset(out, 0xFF, PS_MIT_FRAME_LEN - 1u);
    out[PS_MIT_FRAME_LEN - 1u] = (uint8_t)which;
}

int ps_mit_classify_special(const uint8_t *data, uint8_t len)
{
    if (data == NULL || len != PS_MIT_FRAME_LEN)
        return 0;
    for (unsigned i = 0; i + 1u < PS_MIT_FRAME_LEN; i++) {
        if (data[i] != 0xFFu)
            return 0;
    }
    const uint8_t last = data[PS_MIT_FRAME_LEN - 1u];
    if (last == PS_MIT_SPECIAL_ENTER || last == PS_MIT_SPECIAL_EXIT || last == PS_MIT_SPECIAL_ZERO)
        return last;
    return 0;
}

void ps_mit_encode_reply(const ps_act_range_t *r, const ps_mit_reply_t *rep,
                         uint8_t out[PS_MIT_FRAME_LEN])
{
    const uint32_t p = ps_mit_float_to_uint(rep->p_rad, r->p_min_rad, r->p_max_rad, PS_MIT_P_BITS);
    const uint32_t v =
        ps_mit_float_to_uint(rep->v_rad_s, r->v_min_rad_s, r->v_max_rad_s, PS_MIT_V_BITS);
    const uint32_t i = ps_mit_float_to_uint(rep->i_a, r->i_min_a, r->i_max_a, PS_MIT_I_BITS);
    out[0] = (uint8_t)((rep->motor_id & 0xFu) | ((rep->fault & 0xFu) << 4));
    out[1] = (uint8_t)(p >> 8);
    out[2] = (uint8_t)(p & 0xFFu);
    out[3] = (uint8_t)(v >> 4);
    out[4] = (uint8_t)(((v & 0xFu) << 4) | (i >> 8));
    out[5] = (uint8_t)(i & 0xFFu);
    out[6] = (uint8_t)rep->temp_mos_c;
    out[7] = (uint8_t)rep->temp_rotor_c;
}

int ps_mit_decode_reply(const ps_act_range_t *r, const uint8_t *data, uint8_t len,
                        ps_mit_reply_t *out)
{
    if (len != PS_MIT_FRAME_LEN)
        return -PS_ERR_PROTOCOL;
    const uint32_t p = ((uint32_t)data[1] << 8) | data[2];
    const uint32_t v = ((uint32_t)data[3] << 4) | ((uint32_t)data[4] >> 4);
    const uint32_t i = (((uint32_t)data[4] & 0xFu) << 8) | data[5];
    out->motor_id = (uint8_t)(data[0] & 0xFu);
    out->fault = (uint8_t)(data[0] >> 4);
    out->p_rad = ps_mit_uint_to_float(p, r->p_min_rad, r->p_max_rad, PS_MIT_P_BITS);
    out->v_rad_s = ps_mit_uint_to_float(v, r->v_min_rad_s, r->v_max_rad_s, PS_MIT_V_BITS);
    out->i_a = ps_mit_uint_to_float(i, r->i_min_a, r->i_max_a, PS_MIT_I_BITS);
    /* int8 on the wire: a two's-complement byte, so -5 degC is 0xFB. */
    out->temp_mos_c = (int8_t)data[6];
    out->temp_rotor_c = (int8_t)data[7];
    return 0;
}

/* ---- MIT mode as an actuator protocol --------------------------------- */

static const struct {
    uint8_t code;
    uint32_t bit;
} FAULT_MAP[] = {
    {PS_MIT_FAULT_OVERVOLTAGE, PS_ACT_FAULT_OVERVOLTAGE},
    {PS_MIT_FAULT_UNDERVOLTAGE, PS_ACT_FAULT_UNDERVOLTAGE},
    {PS_MIT_FAULT_OVERCURRENT, PS_ACT_FAULT_OVERCURRENT},
    {PS_MIT_FAULT_MOS_OVERTEMP, PS_ACT_FAULT_DRIVER_OVERTEMP},
    {PS_MIT_FAULT_ROTOR_OVERTEMP, PS_ACT_FAULT_MOTOR_OVERTEMP},
    {PS_MIT_FAULT_COMMS_LOST, PS_ACT_FAULT_COMMS_LOST},
    {PS_MIT_FAULT_OVERLOAD, PS_ACT_FAULT_OVERLOAD},
};

uint32_t ps_mit_fault_bits(uint8_t code)
{
    if (code == PS_MIT_FAULT_NONE)
        return 0u;
    for (unsigned i = 0; i < sizeof(FAULT_MAP) / sizeof(FAULT_MAP[0]); i++)
        if (FAULT_MAP[i].code == code)
            return FAULT_MAP[i].bit;
    return PS_ACT_FAULT_OTHER;
}

uint8_t ps_mit_fault_code(uint32_t bits)
{
    for (unsigned i = 0; i < sizeof(FAULT_MAP) / sizeof(FAULT_MAP[0]); i++)
        if (bits & FAULT_MAP[i].bit)
            return FAULT_MAP[i].code;
    return bits != 0u ? PS_MIT_FAULT_OVERLOAD : PS_MIT_FAULT_NONE;
}

static void mit_frame(uint32_t id, const uint8_t data[PS_MIT_FRAME_LEN], ps_can_frame_t *out)
{
    memset(out, 0, sizeof *out);
    out->id = id;
    out->len = PS_MIT_FRAME_LEN;
    memcpy(out->data, data, PS_MIT_FRAME_LEN);
}

static bool is_in_wire(const ps_act_range_t *r, const ps_mit_cmd_t *c)
{
    return in_wire(c->p_rad, r->p_min_rad, r->p_max_rad) &&
           in_wire(c->v_rad_s, r->v_min_rad_s, r->v_max_rad_s) &&
           in_wire(c->kp_nm_rad, 0.0f, r->kp_max_nm_rad) &&
           in_wire(c->kd_nm_s_rad, 0.0f, r->kd_max_nm_s_rad) &&
           in_wire(c->t_ff_nm, r->t_min_nm, r->t_max_nm);
}

static int mit_encode_cmd(const ps_act_cfg_t *a, const ps_act_cmd_t *m, ps_can_frame_t *out,
                          size_t max)
{
    if (max < 1u)
        return -ENOSPC;
    ps_mit_cmd_t cmd = {
        .p_rad = m->q_rad,
        .v_rad_s = m->qd_rad_s,
        .kp_nm_rad = m->kp_nm_rad,
        .kd_nm_s_rad = m->kd_nm_s_rad,
        .t_ff_nm = m->tau_ff_nm,
    };
    uint8_t data[PS_MIT_FRAME_LEN];
    int rc = ps_mit_encode_cmd(&a->wire, &cmd, data);
    if (rc == -PS_ERR_LIMIT && is_in_wire(&a->wire, &cmd)) {
        /* In range but refused: the corner that packs into a special frame
         * (p, v, kp, kd at their maxima, t near its maximum). Step kd down two
         * LSB (0.05 % of its range) so it is sent as the set-point it is. */
        const ps_act_range_t *w = &a->wire;
        cmd.kd_nm_s_rad -= 2.0f * w->kd_max_nm_s_rad / (float)((1u << PS_MIT_KD_BITS) - 1u);
        rc = ps_mit_encode_cmd(w, &cmd, data);
    }
    if (rc < 0)
        return rc;
    mit_frame(a->can_id, data, out);
    return 1;
}

static int mit_encode_request(const ps_act_cfg_t *a, ps_act_request_t req, ps_can_frame_t *out,
                              size_t max)
{
    static const ps_mit_special_t SPECIAL[PS_ACT_REQ_COUNT] = {
        [PS_ACT_REQ_ENABLE] = PS_MIT_SPECIAL_ENTER,
        [PS_ACT_REQ_DISABLE] = PS_MIT_SPECIAL_EXIT,
        [PS_ACT_REQ_SET_ZERO] = PS_MIT_SPECIAL_ZERO,
        [PS_ACT_REQ_CLEAR_FAULT] = PS_MIT_SPECIAL_ENTER,
    };
    if ((unsigned)req >= PS_ACT_REQ_COUNT)
        return -ENOTSUP;
    if (max < 1u)
        return -ENOSPC;
    uint8_t data[PS_MIT_FRAME_LEN];
    ps_mit_encode_special(SPECIAL[req], data);
    mit_frame(a->can_id, data, out);
    return 1;
}

static bool mit_match_reply(const ps_act_cfg_t *a, const ps_can_frame_t *f)
{
    return !f->is_ext && !f->is_fd && f->id == a->reply_id;
}

static void mit_reply_filter(const ps_act_cfg_t *a, uint32_t *out_id, uint32_t *out_mask)
{
    *out_id = a->reply_id;
    *out_mask = 0x7ffu;
}

static int mit_decode_reply(const ps_act_cfg_t *a, const ps_can_frame_t *f, ps_act_meas_t *out)
{
    ps_mit_reply_t rep;
    if (ps_mit_decode_reply(&a->wire, f->data, f->len, &rep) < 0 ||
        rep.motor_id != (a->can_id & 0x0fu) || !isfinite(rep.p_rad))
        return -PS_ERR_PROTOCOL;
    out->q_rad = rep.p_rad;
    out->qd_rad_s = rep.v_rad_s;
    out->tau_nm = rep.i_a * a->kt_nm_a;
    out->temp_c = (float)(rep.temp_mos_c > rep.temp_rotor_c ? rep.temp_mos_c : rep.temp_rotor_c);
    out->fault_bits = ps_mit_fault_bits(rep.fault);
    return 0;
}

static bool mit_is_for_drive(const ps_act_cfg_t *a, const ps_can_frame_t *f)
{
    return !f->is_ext && f->id == a->can_id;
}

static int mit_classify_request(const ps_act_cfg_t *a, const ps_can_frame_t *f)
{
    (void)a;
    switch (ps_mit_classify_special(f->data, f->len)) {
    case PS_MIT_SPECIAL_ENTER:
        return PS_ACT_REQ_ENABLE; /* also clears a latched fault */
    case PS_MIT_SPECIAL_EXIT:
        return PS_ACT_REQ_DISABLE;
    case PS_MIT_SPECIAL_ZERO:
        return PS_ACT_REQ_SET_ZERO;
    default:
        return -ENOENT;
    }
}

static int mit_decode_cmd(const ps_act_cfg_t *a, const ps_can_frame_t *f, ps_act_cmd_t *out)
{
    if (f->is_fd)
        return -PS_ERR_PROTOCOL;
    ps_mit_cmd_t c;
    const int rc = ps_mit_decode_cmd(&a->wire, f->data, f->len, &c);
    if (rc < 0)
        return rc;
    out->q_rad = c.p_rad;
    out->qd_rad_s = c.v_rad_s;
    out->kp_nm_rad = c.kp_nm_rad;
    out->kd_nm_s_rad = c.kd_nm_s_rad;
    out->tau_ff_nm = c.t_ff_nm;
    return 0;
}

static int8_t to_int8_c(float t_c)
{
    const float r = nearbyintf(t_c);
    if (!(r > -128.0f))
        return -128;
    return r > 127.0f ? 127 : (int8_t)r;
}

/* MIT carries two temperatures (power stage, rotor); the neutral measurement
 * holds only the hottest, which goes in both bytes, so the host reads it back. */
static int mit_encode_reply(const ps_act_cfg_t *a, const ps_act_meas_t *m, ps_can_frame_t *out,
                            size_t max)
{
    if (max < 1u)
        return -ENOSPC;
    const float kt = a->kt_nm_a > 0.0f ? a->kt_nm_a : 1.0f;
    const ps_mit_reply_t rep = {
        .motor_id = (uint8_t)(a->can_id & 0xFu),
        .fault = ps_mit_fault_code(m->fault_bits),
        .p_rad = m->q_rad,
        .v_rad_s = m->qd_rad_s,
        .i_a = m->tau_nm / kt,
        .temp_mos_c = to_int8_c(m->temp_c),
        .temp_rotor_c = to_int8_c(m->temp_c),
    };
    uint8_t data[PS_MIT_FRAME_LEN];
    ps_mit_encode_reply(&a->wire, &rep, data);
    mit_frame(a->reply_id, data, out);
    return 1;
}

const ps_act_proto_t ps_mit_proto = {
    .name = "mit",
    .id_bits = 11,
    .is_fd = false,
    .cmd_len = PS_MIT_FRAME_LEN,
    .reply_len = PS_MIT_FRAME_LEN,
    .n_cmd = 1,
    .n_reply = 1,
    .id_max = 0x7ffu,
    .resolution_bits = {PS_MIT_P_BITS, PS_MIT_V_BITS, PS_MIT_KP_BITS, PS_MIT_KD_BITS,
                        PS_MIT_T_BITS},
    .encode_cmd = mit_encode_cmd,
    .encode_request = mit_encode_request,
    .match_reply = mit_match_reply,
    .reply_filter = mit_reply_filter,
    .decode_reply = mit_decode_reply,
    .is_for_drive = mit_is_for_drive,
    .classify_request = mit_classify_request,
    .decode_cmd = mit_decode_cmd,
    .encode_reply = mit_encode_reply,
};
