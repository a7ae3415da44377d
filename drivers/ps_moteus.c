/*
 * ps_moteus: moteus register frames. See ps_moteus.h for the layout and its
 * source. The host side writes one fixed layout; both sides read any layout
 * the register protocol allows (the firmware need not mirror the query's
 * grouping in its reply, mjlib multiplex/format.h), through one subframe
 * walker.
 */
#include "ps_moteus.h"

#include <math.h>
#include <stdbool.h>
#include <string.h>

#include "../rt/ps_err.h"

_Static_assert(sizeof(float) == 4, "moteus floats are IEEE 754 binary32");

#define LEN       PS_MOTEUS_FRAME_LEN
#define TWO_PI    6.28318548f /* float(2 pi): float(pi/2) / TWO_PI is exactly 0.25 */
#define RES_BITS  23u
#define NAN_BITS  0x7fc00000u /* the quiet NaN the enable frame sends */
#define BASE_MASK 0xf0u
#define WRITE     0x00u
#define READ      0x10u
#define REPLY     0x20u
#define TYPE_INT8 0u
#define TYPE_F32  3u

/* How a register's integer forms map onto its value (registers.md,
 * "Mappings"); floats carry the value itself. */
typedef enum {
    MAP_INT = 0, /* the integer itself: mode, fault code */
    MAP_POSITION,
    MAP_VELOCITY,
    MAP_TORQUE,
    MAP_TEMP,
    MAP_VOLTAGE,
    MAP_SCALE, /* kp / kd scale: the PWM mapping */
    MAP_COUNT
} map_t;

/* LSB of int8, int16, int32 per mapping. */
static const float LSB[MAP_COUNT][3] = {
    [MAP_INT] = {1.0f, 1.0f, 1.0f},
    [MAP_POSITION] = {0.01f, 0.0001f, 0.00001f},
    [MAP_VELOCITY] = {0.1f, 0.00025f, 0.00001f},
    [MAP_TORQUE] = {0.5f, 0.01f, 0.001f},
    [MAP_TEMP] = {1.0f, 0.1f, 0.001f},
    [MAP_VOLTAGE] = {0.5f, 0.1f, 0.001f},
    [MAP_SCALE] = {1.0f / 127.0f, 1.0f / 32767.0f, 1.0f / 2147483647.0f},
};

/* The registers this table reads or writes: a slot each in a view. */
typedef enum {
    S_MODE = 0,
    S_POSITION,
    S_VELOCITY,
    S_TORQUE,
    S_MOTOR_TEMP,
    S_TEMP,
    S_FAULT,
    S_CMD_POSITION,
    S_CMD_VELOCITY,
    S_CMD_TORQUE,
    S_KP_SCALE,
    S_KD_SCALE,
    S_SET_OUTPUT_EXACT,
    S_COUNT
} slot_t;

static const struct {
    uint32_t reg;
    map_t map;
} SLOTS[S_COUNT] = {
    [S_MODE] = {PS_MOTEUS_REG_MODE, MAP_INT},
    [S_POSITION] = {PS_MOTEUS_REG_POSITION, MAP_POSITION},
    [S_VELOCITY] = {PS_MOTEUS_REG_VELOCITY, MAP_VELOCITY},
    [S_TORQUE] = {PS_MOTEUS_REG_TORQUE, MAP_TORQUE},
    [S_MOTOR_TEMP] = {PS_MOTEUS_REG_MOTOR_TEMP, MAP_TEMP},
    [S_TEMP] = {PS_MOTEUS_REG_TEMP, MAP_TEMP},
    [S_FAULT] = {PS_MOTEUS_REG_FAULT, MAP_INT},
    [S_CMD_POSITION] = {PS_MOTEUS_REG_CMD_POSITION, MAP_POSITION},
    [S_CMD_VELOCITY] = {PS_MOTEUS_REG_CMD_VELOCITY, MAP_VELOCITY},
    [S_CMD_TORQUE] = {PS_MOTEUS_REG_CMD_TORQUE, MAP_TORQUE},
    [S_KP_SCALE] = {PS_MOTEUS_REG_KP_SCALE, MAP_SCALE},
    [S_KD_SCALE] = {PS_MOTEUS_REG_KD_SCALE, MAP_SCALE},
    [S_SET_OUTPUT_EXACT] = {PS_MOTEUS_REG_SET_OUTPUT_EXACT, MAP_POSITION},
};

/* The command registers a mode write resets (the firmware starts a new
 * command from its defaults when the mode is written). */
#define CMD_SLOTS                                                                                  \
    ((1u << S_CMD_POSITION) | (1u << S_CMD_VELOCITY) | (1u << S_CMD_TORQUE) | (1u << S_KP_SCALE) | \
     (1u << S_KD_SCALE))

/* What one frame says about the registers we know. */
typedef struct {
    uint32_t has; /* bit per slot_t */
    float v[S_COUNT];
} view_t;

/* ---- bytes ------------------------------------------------------------ */

static uint32_t get_le(const uint8_t *p, unsigned n)
{
    uint32_t v = 0;
    for (unsigned i = 0; i < n; i++)
        v |= (uint32_t)p[i] << (8u * i);
    return v;
}

static float get_f32(const uint8_t *p)
{
    const uint32_t u = get_le(p, 4);
    float x;
    memcpy(&x, &u, sizeof x);
    return x;
}

static uint8_t *put_f32(uint8_t *p, float x)
{
    uint32_t u;
    memcpy(&u, &x, sizeof u);
    for (unsigned i = 0; i < 4u; i++)
        p[i] = (uint8_t)(u >> (8u * i));
    return p + 4;
}

static uint8_t *put3(uint8_t *p, uint8_t a, uint8_t b, uint8_t c)
{
    p[0] = a;
    p[1] = b;
    p[2] = c;
    return p + 3;
}

/* One varuint (7 bits a byte, least significant first, at most 5 bytes). */
static int get_varuint(const ps_can_frame_t *f, size_t *at, uint32_t *out)
{
    uint32_t v = 0;
    for (unsigned i = 0; i < 5u; i++) {
        if (*at >= f->len)
            return -PS_ERR_PROTOCOL;
        const uint8_t b = f->data[(*at)++];
        v |= (uint32_t)(b & 0x7fu) << (7u * i);
        if ((b & 0x80u) == 0) {
            *out = v;
            return 0;
        }
    }
    return -PS_ERR_PROTOCOL;
}

/* ---- the subframe walker ---------------------------------------------- */

static int slot_of(uint32_t reg)
{
    for (int s = 0; s < S_COUNT; s++)
        if (SLOTS[s].reg == reg)
            return s;
    return -1;
}

/* A value of 1 << type bytes (a 4-byte float for type 3) on its register's
 * mapping; the most negative integer is the firmware's "not available". */
static float value_of(unsigned type, const uint8_t *p, map_t map)
{
    if (type == TYPE_F32)
        return get_f32(p);
    const unsigned n = 1u << type;
    const uint32_t u = get_le(p, n);
    const uint32_t sign = 1u << (8u * n - 1u);
    const int64_t i = (u & sign) ? (int64_t)u - ((int64_t)sign << 1) : (int64_t)u;
    if (map != MAP_INT && i == -(int64_t)sign)
        return NAN;
    return (float)i * LSB[map][type];
}

/* Walk every subframe of f. Values of subframes of kind `want` (WRITE or
 * REPLY) land in *out; reads (in a command) are skipped; error subframes,
 * unknown subframes, values of the other kind and truncation are malformed.
 * A mode write resets the command registers, as in the firmware. */
static int walk(const ps_can_frame_t *f, uint32_t want, view_t *out)
{
    memset(out, 0, sizeof *out);
    if (f->len > PS_CAN_FD_MAX_DLEN)
        return -PS_ERR_PROTOCOL;
    size_t at = 0;
    while (at < f->len) {
        const uint8_t t = f->data[at++];
        if (t == PS_MOTEUS_NOP)
            continue;
        const uint32_t base = t & BASE_MASK;
        if (base != WRITE && base != READ && base != REPLY)
            return -PS_ERR_PROTOCOL; /* errors 0x30/0x31, streams, unknown types */
        if (base != READ && base != want)
            return -PS_ERR_PROTOCOL;
        if (base == READ && want != WRITE)
            return -PS_ERR_PROTOCOL; /* a reply asks nothing */
        const unsigned type = (t >> 2) & 3u;
        uint32_t count = t & 3u, reg;
        if (count == 0 && get_varuint(f, &at, &count) < 0)
            return -PS_ERR_PROTOCOL;
        if (get_varuint(f, &at, &reg) < 0)
            return -PS_ERR_PROTOCOL;
        if (base == READ)
            continue;
        const size_t width = type == TYPE_F32 ? 4u : 1u << type; /* 1, 2, 4, 4 bytes */
        if (count > (f->len - at) / width)
            return -PS_ERR_PROTOCOL;
        for (uint32_t k = 0; k < count; k++, at += width) {
            const int s = slot_of(reg + k);
            if (s < 0)
                continue; /* a register we do not use */
            if (s == S_MODE && want == WRITE)
                out->has &= ~CMD_SLOTS;
            out->v[s] = value_of(type, &f->data[at], SLOTS[s].map);
            out->has |= 1u << s;
        }
    }
    return 0;
}

static bool has(const view_t *v, slot_t s)
{
    return (v->has & (1u << s)) != 0;
}

/* A mode value: a whole number 0..127 in whichever width it came. */
static int mode_of(float m)
{
    if (!(m >= 0.0f && m <= 127.0f) || m != floorf(m))
        return -1;
    return (int)m;
}

/* ---- ids and frames ----------------------------------------------------- */

static uint32_t cmd_id(const ps_act_cfg_t *a)
{
    return ps_moteus_id(PS_MOTEUS_REPLY_FLAG | (a->reply_id & 0x7fu), a->can_id & 0x7fu);
}

static uint32_t reply_id(const ps_act_cfg_t *a)
{
    return ps_moteus_id(a->can_id & 0x7fu, a->reply_id & 0x7fu);
}

static void frame(uint32_t id, ps_can_frame_t *out)
{
    memset(out, 0, sizeof *out);
    out->id = id;
    out->is_ext = 1;
    out->is_fd = 1;
    out->is_brs = 1; /* moteus answers with BRS when asked with it */
    out->len = LEN;
    memset(out->data, PS_MOTEUS_NOP, LEN);
}

/* The query every host frame ends with: mode, position, velocity, torque as
 * floats, then motor temperature .. fault code as int8. */
static uint8_t *put_query(uint8_t *p)
{
    p = put3(p, READ | (TYPE_F32 << 2), 4, PS_MOTEUS_REG_MODE);
    return put3(p, READ | (TYPE_INT8 << 2), 6, PS_MOTEUS_REG_MOTOR_TEMP);
}

/* Mode 10 and the five command registers, as floats. */
static uint8_t *put_position_cmd(uint8_t *p, const float v[5])
{
    p = put3(p, WRITE | (TYPE_INT8 << 2) | 1u, PS_MOTEUS_REG_MODE, PS_MOTEUS_MODE_POSITION);
    p = put3(p, WRITE | (TYPE_F32 << 2), 5, PS_MOTEUS_REG_CMD_POSITION);
    for (unsigned k = 0; k < 5u; k++)
        p = put_f32(p, v[k]);
    return p;
}

/* Inclusive; NaN and infinities fail. */
static bool in_range(float x, float lo, float hi)
{
    return isfinite(x) && x >= lo && x <= hi;
}

/* ---- faults ------------------------------------------------------------- */

static const struct {
    uint8_t code;
    uint32_t fault;
} CODES[] = {
    {32, PS_ACT_FAULT_ENCODER},        /* calibration: no magnet sensed */
    {34, PS_ACT_FAULT_OVERVOLTAGE},    /* bus above servo.max_voltage */
    {35, PS_ACT_FAULT_ENCODER},        /* encoder readings inconsistent */
    {38, PS_ACT_FAULT_MOTOR_OVERTEMP}, /* board or motor above its fault temperature */
    {40, PS_ACT_FAULT_UNDERVOLTAGE},   {42, PS_ACT_FAULT_ENCODER}, /* theta invalid */
    {43, PS_ACT_FAULT_ENCODER},                                    /* position invalid */
};
#define N_CODES      (sizeof(CODES) / sizeof(CODES[0]))
#define FIRST_LIMIT  96u /* codes from here on: limits at work, not faults */
#define CODE_GENERIC 33u /* motor driver fault: the emulated drive's catch-all */

uint32_t ps_moteus_fault_bits(uint32_t mode, uint32_t code)
{
    uint32_t bits = mode == PS_MOTEUS_MODE_TIMEOUT ? PS_ACT_FAULT_COMMS_LOST : 0u;
    if (code != 0u && code < FIRST_LIMIT) {
        uint32_t named = PS_ACT_FAULT_OTHER;
        for (unsigned i = 0; i < N_CODES; i++)
            if (CODES[i].code == code)
                named = CODES[i].fault;
        bits |= named;
    }
    if (mode == PS_MOTEUS_MODE_FAULT && bits == 0u)
        bits = PS_ACT_FAULT_OTHER;
    return bits;
}

/* The emulated drive's mode and code for neutral bits: the drive reports one
 * code, the first that applies in this order; comms lost alone is the
 * timeout mode. Over-current and overload have no code of their own (the
 * firmware limits current instead) and read as a motor driver fault. */
static void fault_code(uint32_t bits, uint32_t *out_mode, uint32_t *out_code)
{
    static const struct {
        uint32_t bits;
        uint8_t code;
    } ORDER[] = {
        {PS_ACT_FAULT_MOTOR_OVERTEMP | PS_ACT_FAULT_DRIVER_OVERTEMP, 38},
        {PS_ACT_FAULT_OVERVOLTAGE, 34},
        {PS_ACT_FAULT_UNDERVOLTAGE, 40},
        {PS_ACT_FAULT_ENCODER, 35},
        {PS_ACT_FAULT_OVERCURRENT | PS_ACT_FAULT_OVERLOAD | PS_ACT_FAULT_OTHER, CODE_GENERIC},
    };
    *out_mode = PS_MOTEUS_MODE_POSITION;
    *out_code = 0u;
    for (unsigned i = 0; i < sizeof(ORDER) / sizeof(ORDER[0]); i++) {
        if (bits & ORDER[i].bits) {
            *out_mode = PS_MOTEUS_MODE_FAULT;
            *out_code = ORDER[i].code;
            return;
        }
    }
    if (bits & PS_ACT_FAULT_COMMS_LOST)
        *out_mode = PS_MOTEUS_MODE_TIMEOUT;
    else if (bits != 0u) {
        *out_mode = PS_MOTEUS_MODE_FAULT;
        *out_code = CODE_GENERIC;
    }
}

/* ---- the host's side ---------------------------------------------------- */

static int mo_encode_cmd(const ps_act_cfg_t *a, const ps_act_cmd_t *m, ps_can_frame_t *out,
                         size_t max)
{
    if (max < 1u)
        return -ENOSPC;
    const ps_act_range_t *w = &a->wire;
    if (!in_range(m->q_rad, w->p_min_rad, w->p_max_rad) ||
        !in_range(m->qd_rad_s, w->v_min_rad_s, w->v_max_rad_s) ||
        !in_range(m->kp_nm_rad, 0.0f, w->kp_max_nm_rad) ||
        !in_range(m->kd_nm_s_rad, 0.0f, w->kd_max_nm_s_rad) ||
        !in_range(m->tau_ff_nm, w->t_min_nm, w->t_max_nm) || !(w->kp_max_nm_rad > 0.0f) ||
        !(w->kd_max_nm_s_rad > 0.0f))
        return -PS_ERR_LIMIT;
    const float v[5] = {
        m->q_rad / TWO_PI,
        m->qd_rad_s / TWO_PI,
        m->tau_ff_nm,
        m->kp_nm_rad / w->kp_max_nm_rad,
        m->kd_nm_s_rad / w->kd_max_nm_s_rad,
    };
    frame(cmd_id(a), out);
    (void)put_query(put_position_cmd(out->data, v)); /* exactly LEN bytes */
    return 1;
}

static int mo_encode_request(const ps_act_cfg_t *a, ps_act_request_t req, ps_can_frame_t *out,
                             size_t max)
{
    if (max < 1u)
        return -ENOSPC;
    if ((unsigned)req >= PS_ACT_REQ_COUNT)
        return -ENOTSUP;
    frame(cmd_id(a), out);
    uint8_t *p = out->data;
    switch (req) {
    case PS_ACT_REQ_ENABLE: {
        float hold;
        const uint32_t nan_bits = NAN_BITS;
        memcpy(&hold, &nan_bits, sizeof hold);
        const float v[5] = {hold, 0.0f, 0.0f, 0.0f, 0.0f};
        p = put_position_cmd(p, v);
        break;
    }
    case PS_ACT_REQ_SET_ZERO:
        /* write float x1 at 0x131: the register's varuint is B1 02 */
        p[0] = WRITE | (TYPE_F32 << 2) | 1u;
        p[1] = (uint8_t)(0x80u | (PS_MOTEUS_REG_SET_OUTPUT_EXACT & 0x7fu));
        p[2] = (uint8_t)(PS_MOTEUS_REG_SET_OUTPUT_EXACT >> 7);
        p = put_f32(p + 3, 0.0f);
        break;
    default: /* disable and clear fault: stop, which clears a latched fault */
        p = put3(p, WRITE | (TYPE_INT8 << 2) | 1u, PS_MOTEUS_REG_MODE, PS_MOTEUS_MODE_STOPPED);
        break;
    }
    (void)put_query(p); /* the rest stays NOP */
    return 1;
}

/* An FD reply of this drive to this host, with no can prefix. */
static bool mo_match_reply(const ps_act_cfg_t *a, const ps_can_frame_t *f)
{
    return f->is_ext && f->is_fd && f->id == reply_id(a);
}

/* Every bit fixed: the reply id has no free field. */
static void mo_reply_filter(const ps_act_cfg_t *a, uint32_t *out_id, uint32_t *out_mask)
{
    *out_id = reply_id(a);
    *out_mask = PS_CAN_EFF_MASK;
}

static int mo_decode_reply(const ps_act_cfg_t *a, const ps_can_frame_t *f, ps_act_meas_t *out)
{
    (void)a;
    view_t v;
    if (!ps_can_is_valid_len(f->len, true) || walk(f, REPLY, &v) < 0)
        return -PS_ERR_PROTOCOL;
    if (!has(&v, S_MODE) || !has(&v, S_POSITION) || !has(&v, S_VELOCITY) || !has(&v, S_TORQUE) ||
        !has(&v, S_TEMP) || !has(&v, S_FAULT))
        return -PS_ERR_PROTOCOL;
    const int mode = mode_of(v.v[S_MODE]);
    const float code = v.v[S_FAULT];
    const float q = v.v[S_POSITION] * TWO_PI, qd = v.v[S_VELOCITY] * TWO_PI;
    if (mode < 0 || !(code >= 0.0f && code <= 255.0f) || !isfinite(q) || !isfinite(qd) ||
        !isfinite(v.v[S_TORQUE]) || !isfinite(v.v[S_TEMP]))
        return -PS_ERR_PROTOCOL;
    /* the hottest: the motor's only counts with a thermistor fitted */
    float temp = v.v[S_TEMP];
    if (has(&v, S_MOTOR_TEMP) && isfinite(v.v[S_MOTOR_TEMP]) && v.v[S_MOTOR_TEMP] > temp)
        temp = v.v[S_MOTOR_TEMP];
    out->q_rad = q;
    out->qd_rad_s = qd;
    out->tau_nm = v.v[S_TORQUE];
    out->temp_c = temp;
    out->fault_bits = ps_moteus_fault_bits((uint32_t)mode, (uint32_t)code);
    return 0;
}

/* ---- the drive's side (emulated drives) --------------------------------- */

/* Addressed to this drive with no can prefix, from any source. */
static bool mo_is_for_drive(const ps_act_cfg_t *a, const ps_can_frame_t *f)
{
    return f->is_ext && (f->id >> 16) == 0u && (f->id & 0xffu) == (a->can_id & 0x7fu);
}

static int mo_classify_request(const ps_act_cfg_t *a, const ps_can_frame_t *f)
{
    (void)a;
    view_t v;
    if (walk(f, WRITE, &v) < 0)
        return -ENOENT; /* not a request; decode_cmd calls it malformed */
    if (has(&v, S_MODE)) {
        const int mode = mode_of(v.v[S_MODE]);
        if (mode == (int)PS_MOTEUS_MODE_STOPPED)
            return PS_ACT_REQ_DISABLE;
        if (mode == (int)PS_MOTEUS_MODE_POSITION && has(&v, S_CMD_POSITION) &&
            isnan(v.v[S_CMD_POSITION]))
            return PS_ACT_REQ_ENABLE;
        return -ENOENT;
    }
    if (has(&v, S_SET_OUTPUT_EXACT) && v.v[S_SET_OUTPUT_EXACT] == 0.0f)
        return PS_ACT_REQ_SET_ZERO;
    return -ENOENT;
}

static int mo_decode_cmd(const ps_act_cfg_t *a, const ps_can_frame_t *f, ps_act_cmd_t *out)
{
    view_t v;
    if (!f->is_fd || !ps_can_is_valid_len(f->len, true) || walk(f, WRITE, &v) < 0 ||
        !has(&v, S_MODE) || mode_of(v.v[S_MODE]) != (int)PS_MOTEUS_MODE_POSITION)
        return -PS_ERR_PROTOCOL;
    /* registers.md's defaults for what the frame leaves out; a NaN velocity
     * counts as 0 there, a NaN position is the enable request's hold */
    const float q = has(&v, S_CMD_POSITION) ? v.v[S_CMD_POSITION] : 0.0f;
    float qd = has(&v, S_CMD_VELOCITY) ? v.v[S_CMD_VELOCITY] : 0.0f;
    if (isnan(qd))
        qd = 0.0f;
    const float tau = has(&v, S_CMD_TORQUE) ? v.v[S_CMD_TORQUE] : 0.0f;
    const float kp = has(&v, S_KP_SCALE) ? v.v[S_KP_SCALE] : 1.0f;
    const float kd = has(&v, S_KD_SCALE) ? v.v[S_KD_SCALE] : 1.0f;
    /* finite after the scaling too: a float beyond 5e37 rev is inf in rad */
    const float q_rad = q * TWO_PI, qd_rad_s = qd * TWO_PI;
    const float kp_nm_rad = kp * a->wire.kp_max_nm_rad, kd_nm_s_rad = kd * a->wire.kd_max_nm_s_rad;
    if (!isfinite(q_rad) || !isfinite(qd_rad_s) || !isfinite(tau) || !isfinite(kp_nm_rad) ||
        !isfinite(kd_nm_s_rad))
        return -PS_ERR_PROTOCOL;
    out->q_rad = q_rad;
    out->qd_rad_s = qd_rad_s;
    out->tau_ff_nm = tau;
    out->kp_nm_rad = kp_nm_rad;
    out->kd_nm_s_rad = kd_nm_s_rad;
    return 0;
}

static float clampf(float x, float lo, float hi)
{
    return fminf(fmaxf(x, lo), hi); /* NaN -> lo */
}

/* 1 degC per LSB, saturating at +-127 as the firmware does; -128 is its
 * "not available". */
static uint8_t temp_int8(float t_c)
{
    if (isnan(t_c))
        return 0x80u;
    const float r = nearbyintf(clampf(t_c, -127.0f, 127.0f));
    return (uint8_t)(int8_t)r;
}

/* The reply to this table's query; values outside the wire range saturate
 * (the contract of ps_actuator.h; a real drive's floats do not). The
 * emulation has one temperature for motor and board and no supply voltage. */
static int mo_encode_reply(const ps_act_cfg_t *a, const ps_act_meas_t *m, ps_can_frame_t *out,
                           size_t max)
{
    if (max < 1u)
        return -ENOSPC;
    const ps_act_range_t *w = &a->wire;
    uint32_t mode, code;
    fault_code(m->fault_bits, &mode, &code);
    frame(reply_id(a), out);
    uint8_t *p = put3(out->data, REPLY | (TYPE_F32 << 2), 4, PS_MOTEUS_REG_MODE);
    p = put_f32(p, (float)mode);
    p = put_f32(p, clampf(m->q_rad, w->p_min_rad, w->p_max_rad) / TWO_PI);
    p = put_f32(p, clampf(m->qd_rad_s, w->v_min_rad_s, w->v_max_rad_s) / TWO_PI);
    p = put_f32(p, clampf(m->tau_nm, w->t_min_nm, w->t_max_nm));
    p = put3(p, REPLY | (TYPE_INT8 << 2), 6, PS_MOTEUS_REG_MOTOR_TEMP);
    const uint8_t tail[6] = {temp_int8(m->temp_c), 0u,           0u, 0x80u,
                             temp_int8(m->temp_c), (uint8_t)code};
    memcpy(p, tail, sizeof tail); /* NOP padding after: 28 of 32 bytes used */
    return 1;
}

const ps_act_proto_t ps_moteus_proto = {
    .name = "moteus",
    .id_bits = 29,
    .is_fd = true,
    .cmd_len = LEN,
    .reply_len = LEN,
    .n_cmd = 1,
    .n_reply = 1,
    .can_id_min = PS_MOTEUS_ID_MIN,
    .id_max = PS_MOTEUS_ID_MAX,
    .is_reply_id_shared = true,
    .resolution_bits = {RES_BITS, RES_BITS, RES_BITS, RES_BITS, RES_BITS},
    .encode_cmd = mo_encode_cmd,
    .encode_request = mo_encode_request,
    .match_reply = mo_match_reply,
    .reply_filter = mo_reply_filter,
    .decode_reply = mo_decode_reply,
    .is_for_drive = mo_is_for_drive,
    .classify_request = mo_classify_request,
    .decode_cmd = mo_decode_cmd,
    .encode_reply = mo_encode_reply,
};
