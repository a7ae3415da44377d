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

int ps_mit_check_range(const ps_mit_range_t *r)
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

int ps_mit_encode_cmd(const ps_mit_range_t *r, const ps_mit_cmd_t *cmd,
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

int ps_mit_decode_cmd(const ps_mit_range_t *r, const uint8_t *data, uint8_t len, ps_mit_cmd_t *out)
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

void ps_mit_encode_reply(const ps_mit_range_t *r, const ps_mit_reply_t *rep,
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

int ps_mit_decode_reply(const ps_mit_range_t *r, const uint8_t *data, uint8_t len,
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
