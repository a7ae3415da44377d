/*
 * ps_robstride: RobStride / CyberGear frames. See ps_robstride.h for the
 * layout; the linear mapping is MIT mode's (ps_mit_float_to_uint), with
 * 16 bits for every field.
 */
#include "ps_robstride.h"

#include <math.h>
#include <stdbool.h>
#include <string.h>

#include "../rt/ps_err.h"
#include "ps_mit.h"

#define BITS     16u
#define LEN      8u
#define ID_MAX   0xffu
#define RUN_MODE 2u /* feedback mode status: 0 reset, 1 calibration, 2 run */

/* Feedback fault field (identifier bits 16..21) <-> neutral fault bits. */
static const struct {
    uint32_t id_bit;
    uint32_t fault;
} FAULT_MAP[] = {
    {1u << 16, PS_ACT_FAULT_UNDERVOLTAGE},
    {1u << 17, PS_ACT_FAULT_OVERCURRENT},
    {1u << 18, PS_ACT_FAULT_MOTOR_OVERTEMP},
    {1u << 19, PS_ACT_FAULT_ENCODER}, /* magnetic encoder */
    {1u << 20, PS_ACT_FAULT_ENCODER}, /* HALL encoder */
    {1u << 21, PS_ACT_FAULT_OTHER},   /* not calibrated */
};
#define N_FAULTS (sizeof(FAULT_MAP) / sizeof(FAULT_MAP[0]))

/* Fault report (type 21) fault value, bytes 0..3 <-> neutral fault bits
 * (CyberGear manual 4.1.10). Bits 8..15 are the overload fault's. */
static const struct {
    uint32_t mask;
    uint32_t fault;
} REPORT_MAP[] = {
    {1u << 0, PS_ACT_FAULT_MOTOR_OVERTEMP}, {1u << 1, PS_ACT_FAULT_OTHER}, /* driver chip */
    {1u << 2, PS_ACT_FAULT_UNDERVOLTAGE},   {1u << 3, PS_ACT_FAULT_OVERVOLTAGE},
    {1u << 4, PS_ACT_FAULT_OVERCURRENT}, /* phase B current sampling */
    {1u << 5, PS_ACT_FAULT_OVERCURRENT}, /* phase C */
    {1u << 7, PS_ACT_FAULT_ENCODER},     /* encoder not calibrated */
    {0xffu << 8, PS_ACT_FAULT_OVERLOAD},    {1u << 16, PS_ACT_FAULT_OVERCURRENT}, /* phase A */
};
#define N_REPORT (sizeof(REPORT_MAP) / sizeof(REPORT_MAP[0]))
/* Bits the manual names; any other set bit is still a fault: OTHER. */
#define REPORT_KNOWN 0x0001ffbfu

uint32_t ps_robstride_fault_bits(uint32_t id)
{
    uint32_t bits = 0u;
    for (unsigned i = 0; i < N_FAULTS; i++)
        if (id & FAULT_MAP[i].id_bit)
            bits |= FAULT_MAP[i].fault;
    return bits;
}

/* The feedback field for neutral bits (the emulated drive's reply): the first
 * field bit of each fault; a power-stage over-temperature reads as the
 * drive's one over-temperature bit. Faults it has no bit for (comms lost,
 * overload) show only as the mode leaving run. */
static uint32_t fault_field(uint32_t bits)
{
    if (bits & PS_ACT_FAULT_DRIVER_OVERTEMP)
        bits |= PS_ACT_FAULT_MOTOR_OVERTEMP;
    uint32_t field = 0u, seen = 0u;
    for (unsigned i = 0; i < N_FAULTS; i++) {
        if ((bits & FAULT_MAP[i].fault) && !(seen & FAULT_MAP[i].fault)) {
            field |= FAULT_MAP[i].id_bit;
            seen |= FAULT_MAP[i].fault;
        }
    }
    return field;
}

static uint32_t type_of(uint32_t id)
{
    return (id >> 24) & 0x1fu;
}

static void put_u16(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)(v >> 8);
    p[1] = (uint8_t)(v & 0xffu);
}

static uint32_t get_u16(const uint8_t *p)
{
    return ((uint32_t)p[0] << 8) | p[1];
}

static void frame(uint32_t id, ps_can_frame_t *out)
{
    memset(out, 0, sizeof *out);
    out->id = id;
    out->is_ext = 1;
    out->len = LEN;
}

/* Inclusive; NaN and infinities fail. */
static bool in_range(float x, float lo, float hi)
{
    return isfinite(x) && x >= lo && x <= hi;
}

static int rs_encode_cmd(const ps_act_cfg_t *a, const ps_act_cmd_t *m, ps_can_frame_t *out,
                         size_t max)
{
    if (max < 1u)
        return -ENOSPC;
    const ps_act_range_t *w = &a->wire;
    if (!in_range(m->q_rad, w->p_min_rad, w->p_max_rad) ||
        !in_range(m->qd_rad_s, w->v_min_rad_s, w->v_max_rad_s) ||
        !in_range(m->kp_nm_rad, 0.0f, w->kp_max_nm_rad) ||
        !in_range(m->kd_nm_s_rad, 0.0f, w->kd_max_nm_s_rad) ||
        !in_range(m->tau_ff_nm, w->t_min_nm, w->t_max_nm))
        return -PS_ERR_LIMIT;
    const uint32_t t = ps_mit_float_to_uint(m->tau_ff_nm, w->t_min_nm, w->t_max_nm, BITS);
    frame(ps_robstride_id(PS_ROBSTRIDE_TYPE_MOTION, t, a->can_id), out);
    put_u16(&out->data[0], ps_mit_float_to_uint(m->q_rad, w->p_min_rad, w->p_max_rad, BITS));
    put_u16(&out->data[2], ps_mit_float_to_uint(m->qd_rad_s, w->v_min_rad_s, w->v_max_rad_s, BITS));
    put_u16(&out->data[4], ps_mit_float_to_uint(m->kp_nm_rad, 0.0f, w->kp_max_nm_rad, BITS));
    put_u16(&out->data[6], ps_mit_float_to_uint(m->kd_nm_s_rad, 0.0f, w->kd_max_nm_s_rad, BITS));
    return 1;
}

static int rs_encode_request(const ps_act_cfg_t *a, ps_act_request_t req, ps_can_frame_t *out,
                             size_t max)
{
    if (max < 1u)
        return -ENOSPC;
    uint32_t type;
    uint8_t byte0 = 0u;
    switch (req) {
    case PS_ACT_REQ_ENABLE:
        type = PS_ROBSTRIDE_TYPE_ENABLE;
        break;
    case PS_ACT_REQ_DISABLE:
        type = PS_ROBSTRIDE_TYPE_STOP;
        break;
    case PS_ACT_REQ_CLEAR_FAULT:
        type = PS_ROBSTRIDE_TYPE_STOP; /* stop with data[0] = 1 also clears faults */
        byte0 = 1u;
        break;
    case PS_ACT_REQ_SET_ZERO:
        type = PS_ROBSTRIDE_TYPE_ZERO;
        byte0 = 1u;
        break;
    default:
        return -ENOTSUP;
    }
    frame(ps_robstride_id(type, a->reply_id & 0xffu, a->can_id), out); /* host: id bits 15..8 */
    out->data[0] = byte0;
    return 1;
}

/* A feedback frame from this drive to this host. */
static bool rs_match_reply(const ps_act_cfg_t *a, const ps_can_frame_t *f)
{
    return f->is_ext && !f->is_fd && type_of(f->id) == PS_ROBSTRIDE_TYPE_FEEDBACK &&
           ((f->id >> 8) & 0xffu) == (a->can_id & 0xffu) &&
           (f->id & 0xffu) == (a->reply_id & 0xffu);
}

/* Type, drive id and host id fixed; the mode and fault bits (23..16) free. */
static void rs_reply_filter(const ps_act_cfg_t *a, uint32_t *out_id, uint32_t *out_mask)
{
    *out_id = ps_robstride_id(PS_ROBSTRIDE_TYPE_FEEDBACK, (a->can_id & 0xffu), a->reply_id);
    *out_mask = ps_robstride_id(0x1fu, 0xffu, 0xffu);
}

/* Type 21, as the manual's table 4.1.10 lays it out: data area 2 bits 15..8
 * = the host's id, target = the drive's id (the other way round from the
 * feedback frame); fault value in bytes 0..3 and warning value in 4..7,
 * little-endian (the drive's MCU stores them so: the manual's own parameter
 * write example memcpy's a float into the data). */
static uint32_t report_id(const ps_act_cfg_t *a)
{
    return ps_robstride_id(PS_ROBSTRIDE_TYPE_FAULT, a->reply_id & 0xffu, a->can_id);
}

static void rs_fault_filter(const ps_act_cfg_t *a, uint32_t *out_id, uint32_t *out_mask)
{
    *out_id = report_id(a);
    *out_mask = ps_robstride_id(0x1fu, 0xffffu, 0xffu);
}

static uint32_t get_le32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

static void put_le32(uint8_t *p, uint32_t v)
{
    for (unsigned i = 0; i < 4; i++)
        p[i] = (uint8_t)(v >> (8u * i));
}

uint32_t ps_robstride_report_fault_bits(uint32_t fault_value)
{
    uint32_t bits = (fault_value & ~REPORT_KNOWN) ? PS_ACT_FAULT_OTHER : 0u;
    for (size_t i = 0; i < N_REPORT; i++)
        if (fault_value & REPORT_MAP[i].mask)
            bits |= REPORT_MAP[i].fault;
    return bits;
}

static int rs_decode_fault(const ps_act_cfg_t *a, const ps_can_frame_t *f, uint32_t *out_fault_bits)
{
    if (!f->is_ext || f->is_fd || f->id != report_id(a))
        return -ENOENT;
    if (f->len != LEN)
        return -PS_ERR_PROTOCOL;
    /* The warning value (bytes 4..7: over-temperature warning) is no fault. */
    *out_fault_bits = ps_robstride_report_fault_bits(get_le32(f->data));
    return 0;
}

static int rs_encode_fault(const ps_act_cfg_t *a, uint32_t fault_bits, ps_can_frame_t *out,
                           size_t max)
{
    if (max < 1)
        return -ENOSPC;
    /* Each neutral bit as the first wire bit the table gives it (OTHER as
     * the driver-chip fault); bits no entry has (COMMS_LOST: a drive does
     * not report its own timeout so) are left out. */
    uint32_t value = 0, done = 0;
    for (size_t i = 0; i < N_REPORT; i++) {
        const uint32_t fault = REPORT_MAP[i].fault;
        if ((fault_bits & fault) && !(done & fault)) {
            value |= REPORT_MAP[i].mask & (0u - REPORT_MAP[i].mask); /* its lowest bit */
            done |= fault;
        }
    }
    memset(out, 0, sizeof(*out));
    out->id = report_id(a);
    out->is_ext = 1;
    out->len = LEN;
    put_le32(out->data, value);
    return 1;
}

static int rs_decode_reply(const ps_act_cfg_t *a, const ps_can_frame_t *f, ps_act_meas_t *out)
{
    if (f->len != LEN)
        return -PS_ERR_PROTOCOL;
    const ps_act_range_t *w = &a->wire;
    out->q_rad = ps_mit_uint_to_float(get_u16(&f->data[0]), w->p_min_rad, w->p_max_rad, BITS);
    out->qd_rad_s =
        ps_mit_uint_to_float(get_u16(&f->data[2]), w->v_min_rad_s, w->v_max_rad_s, BITS);
    out->tau_nm = ps_mit_uint_to_float(get_u16(&f->data[4]), w->t_min_nm, w->t_max_nm, BITS);
    out->temp_c = (float)get_u16(&f->data[6]) / 10.0f;
    out->fault_bits = ps_robstride_fault_bits(f->id);
    return 0;
}

/* ---- the drive's side (emulated drives) ----------------------------------- */

static bool rs_is_for_drive(const ps_act_cfg_t *a, const ps_can_frame_t *f)
{
    const uint32_t type = type_of(f->id);
    return f->is_ext && (f->id & 0xffu) == (a->can_id & 0xffu) &&
           (type == PS_ROBSTRIDE_TYPE_MOTION || type == PS_ROBSTRIDE_TYPE_ENABLE ||
            type == PS_ROBSTRIDE_TYPE_STOP || type == PS_ROBSTRIDE_TYPE_ZERO);
}

static int rs_classify_request(const ps_act_cfg_t *a, const ps_can_frame_t *f)
{
    (void)a;
    switch (type_of(f->id)) {
    case PS_ROBSTRIDE_TYPE_ENABLE:
        return PS_ACT_REQ_ENABLE;
    case PS_ROBSTRIDE_TYPE_STOP:
        return f->data[0] == 1u ? PS_ACT_REQ_CLEAR_FAULT : PS_ACT_REQ_DISABLE;
    case PS_ROBSTRIDE_TYPE_ZERO:
        return f->data[0] == 1u ? PS_ACT_REQ_SET_ZERO : -ENOENT;
    default:
        return -ENOENT;
    }
}

static int rs_decode_cmd(const ps_act_cfg_t *a, const ps_can_frame_t *f, ps_act_cmd_t *out)
{
    if (f->len != LEN || f->is_fd || type_of(f->id) != PS_ROBSTRIDE_TYPE_MOTION)
        return -PS_ERR_PROTOCOL;
    const ps_act_range_t *w = &a->wire;
    out->tau_ff_nm = ps_mit_uint_to_float((f->id >> 8) & 0xffffu, w->t_min_nm, w->t_max_nm, BITS);
    out->q_rad = ps_mit_uint_to_float(get_u16(&f->data[0]), w->p_min_rad, w->p_max_rad, BITS);
    out->qd_rad_s =
        ps_mit_uint_to_float(get_u16(&f->data[2]), w->v_min_rad_s, w->v_max_rad_s, BITS);
    out->kp_nm_rad = ps_mit_uint_to_float(get_u16(&f->data[4]), 0.0f, w->kp_max_nm_rad, BITS);
    out->kd_nm_s_rad = ps_mit_uint_to_float(get_u16(&f->data[6]), 0.0f, w->kd_max_nm_s_rad, BITS);
    return 0;
}

static int rs_encode_reply(const ps_act_cfg_t *a, const ps_act_meas_t *m, ps_can_frame_t *out,
                           size_t max)
{
    if (max < 1u)
        return -ENOSPC;
    const ps_act_range_t *w = &a->wire;
    const uint32_t mode = m->fault_bits == 0u ? RUN_MODE : 0u;
    const uint32_t area2 = (mode << 14) | (fault_field(m->fault_bits) >> 8) | (a->can_id & 0xffu);
    frame(ps_robstride_id(PS_ROBSTRIDE_TYPE_FEEDBACK, area2, a->reply_id), out);
    put_u16(&out->data[0], ps_mit_float_to_uint(m->q_rad, w->p_min_rad, w->p_max_rad, BITS));
    put_u16(&out->data[2], ps_mit_float_to_uint(m->qd_rad_s, w->v_min_rad_s, w->v_max_rad_s, BITS));
    put_u16(&out->data[4], ps_mit_float_to_uint(m->tau_nm, w->t_min_nm, w->t_max_nm, BITS));
    const float t10 = nearbyintf(m->temp_c * 10.0f);
    put_u16(&out->data[6], !(t10 > 0.0f) ? 0u : (t10 > 65535.0f ? 65535u : (uint32_t)t10));
    return 1;
}

const ps_act_proto_t ps_robstride_proto = {
    .name = "robstride",
    .id_bits = 29,
    .is_fd = false,
    .cmd_len = LEN,
    .reply_len = LEN,
    .n_cmd = 1,
    .n_reply = 1,
    .id_max = ID_MAX,
    .is_reply_id_shared = true,
    .resolution_bits = {BITS, BITS, BITS, BITS, BITS},
    .encode_cmd = rs_encode_cmd,
    .encode_request = rs_encode_request,
    .match_reply = rs_match_reply,
    .reply_filter = rs_reply_filter,
    .fault_filter = rs_fault_filter,
    .decode_fault = rs_decode_fault,
    .encode_fault = rs_encode_fault,
    .decode_reply = rs_decode_reply,
    .is_for_drive = rs_is_for_drive,
    .classify_request = rs_classify_request,
    .decode_cmd = rs_decode_cmd,
    .encode_reply = rs_encode_reply,
};
