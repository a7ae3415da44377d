/*
 * fuzz_act: the actuator protocols' decoders under one harness (included by
 * fuzz_mit.c, fuzz_robstride.c, fuzz_moteus.c, each with its protocol and a
 * drive configuration like the tests').
 *
 * Input: byte 0 picks the joint's mounting (bit 0: direct, or geared 9:1,
 * reversed, with a zero offset), then frame records (tests/fuzz/fuzz.h).
 * Every frame goes through the host side (match_reply, decode_reply,
 * ps_act_decode_reply, decode_fault) and the device side the emulated drives
 * use (is_for_drive, classify_request, decode_cmd). Contract checked:
 *   - return codes are the documented ones; outputs untouched on failure;
 *   - a decoded reply is finite, and for protocols with a packing range
 *     (MIT, RobStride) q, qd and torque lie inside the wire range;
 *     its joint-side image is finite; fault bits are ps_act_fault_t bits;
 *   - a decoded command is finite, with kp and kd in [0, max], and for the
 *     packed protocols every field inside the wire range;
 *   - a decoded reply, encoded again by the device side and decoded, gives
 *     q and qd back within one LSB (a float protocol: exactly);
 *   - nothing past f->len is read: the same frame with other bytes past len
 *     decodes the same.
 */
#ifndef PS_FUZZ_ACT_H
#define PS_FUZZ_ACT_H

#include <errno.h>

#include "../../drivers/ps_actuator.h"
#include "../../rt/ps_err.h"
#include "fuzz.h"

#define FUZZ_ACT_ALL_FAULTS ((PS_ACT_FAULT_OTHER << 1) - 1u)

typedef struct {
    int rc_reply, rc_joint, rc_fault, rc_req, rc_cmd;
    bool is_match, is_for_drive;
    ps_act_meas_t reply, joint;
    uint32_t fault_bits;
    ps_act_cmd_t cmd;
} fuzz_act_res_t;

static void fuzz_act_decode(const ps_act_cfg_t *a, const ps_can_frame_t *f, fuzz_act_res_t *r)
{
    const ps_act_proto_t *p = ps_act_proto_get(a->protocol);
    memset(r, 0, sizeof(*r));
    const ps_act_meas_t sentinel = {-1.0f, -2.0f, -3.0f, -4.0f, 0xdeadu, 77};
    const ps_act_cmd_t cmd_sentinel = {-1.0f, -2.0f, -3.0f, -4.0f, -5.0f};

    r->is_match = p->match_reply(a, f);
    r->reply = sentinel;
    r->rc_reply = r->is_match ? p->decode_reply(a, f, &r->reply) : -ENOENT;
    r->joint = sentinel;
    r->rc_joint = ps_act_decode_reply(a, f, &r->joint);
    r->fault_bits = 0xdeadu;
    r->rc_fault = ps_act_decode_fault(a, f, &r->fault_bits);
    r->is_for_drive = p->is_for_drive(a, f);
    r->rc_req = r->is_for_drive ? p->classify_request(a, f) : -ENOENT;
    r->cmd = cmd_sentinel;
    r->rc_cmd = r->is_for_drive && r->rc_req < 0 ? p->decode_cmd(a, f, &r->cmd) : -ENOENT;

    /* return codes and untouched outputs */
    FUZZ_CHECK(r->rc_reply == 0 || r->rc_reply == -ENOENT || r->rc_reply == -PS_ERR_PROTOCOL,
               "decode_reply returned %d", r->rc_reply);
    /* the joint side refuses what is not finite once geared (ps_act_decode_reply) */
    FUZZ_CHECK(r->rc_joint == (r->is_match ? r->rc_reply : -ENOENT) ||
                   (r->rc_reply == 0 && r->rc_joint == -PS_ERR_PROTOCOL),
               "ps_act_decode_reply returned %d, the protocol's decode %d (match %d)", r->rc_joint,
               r->rc_reply, r->is_match);
    if (r->rc_reply < 0)
        FUZZ_CHECK(!memcmp(&r->reply, &sentinel, sizeof sentinel), "reply written on failure");
    if (r->rc_joint < 0)
        FUZZ_CHECK(!memcmp(&r->joint, &sentinel, sizeof sentinel), "joint written on failure");
    FUZZ_CHECK(r->rc_fault == 0 || r->rc_fault == -ENOENT || r->rc_fault == -PS_ERR_PROTOCOL,
               "decode_fault returned %d", r->rc_fault);
    if (r->rc_fault == 0)
        FUZZ_CHECK((r->fault_bits & ~FUZZ_ACT_ALL_FAULTS) == 0u, "fault report bits 0x%x",
                   r->fault_bits);
    else
        FUZZ_CHECK(r->fault_bits == 0xdeadu, "fault bits written on failure");
    FUZZ_CHECK(r->rc_req == -ENOENT || (r->rc_req >= 0 && r->rc_req < PS_ACT_REQ_COUNT),
               "classify_request returned %d", r->rc_req);
    FUZZ_CHECK(r->rc_cmd == 0 || r->rc_cmd == -ENOENT || r->rc_cmd == -PS_ERR_PROTOCOL,
               "decode_cmd returned %d", r->rc_cmd);
    if (r->rc_cmd < 0)
        FUZZ_CHECK(!memcmp(&r->cmd, &cmd_sentinel, sizeof cmd_sentinel), "cmd written on failure");
}

/* Values of a successful decode. packed: the protocol packs into the wire range. */
static void fuzz_act_check_values(const ps_act_cfg_t *a, const fuzz_act_res_t *r, bool is_packed)
{
    const ps_act_range_t *w = &a->wire;
    if (r->rc_reply == 0) {
        const ps_act_meas_t *m = &r->reply;
        FUZZ_CHECK(isfinite(m->q_rad) && isfinite(m->qd_rad_s) && isfinite(m->tau_nm) &&
                       isfinite(m->temp_c),
                   "reply not finite: q %g qd %g tau %g temp %g", m->q_rad, m->qd_rad_s, m->tau_nm,
                   m->temp_c);
        FUZZ_CHECK((m->fault_bits & ~FUZZ_ACT_ALL_FAULTS) == 0u, "reply fault bits 0x%x",
                   m->fault_bits);
        FUZZ_CHECK(m->t_ns == 77, "decode_reply wrote t_ns");
        if (is_packed) {
            const float i_abs = fmaxf(fabsf(w->i_min_a), fabsf(w->i_max_a));
            const float t_abs =
                fmaxf(fmaxf(fabsf(w->t_min_nm), fabsf(w->t_max_nm)), i_abs * fabsf(a->kt_nm_a));
            FUZZ_CHECK(fuzz_in_range(m->q_rad, w->p_min_rad, w->p_max_rad),
                       "reply q %.9g outside [%g, %g]", m->q_rad, w->p_min_rad, w->p_max_rad);
            FUZZ_CHECK(fuzz_in_range(m->qd_rad_s, w->v_min_rad_s, w->v_max_rad_s),
                       "reply qd %.9g outside [%g, %g]", m->qd_rad_s, w->v_min_rad_s,
                       w->v_max_rad_s);
            FUZZ_CHECK(fuzz_in_range(m->tau_nm, -t_abs, t_abs), "reply tau %.9g beyond %g",
                       m->tau_nm, t_abs);
        }
        FUZZ_CHECK(r->rc_joint == 0 || !is_packed, "a packed reply refused on the joint side");
    }
    if (r->rc_joint == 0) {
        const ps_act_meas_t *j = &r->joint;
        FUZZ_CHECK(isfinite(j->q_rad) && isfinite(j->qd_rad_s) && isfinite(j->tau_nm),
                   "joint measurement not finite");
        FUZZ_CHECK(j->t_ns == 77, "ps_act_decode_reply wrote t_ns");
    }
    if (r->rc_cmd == 0) {
        const ps_act_cmd_t *c = &r->cmd;
        FUZZ_CHECK(isfinite(c->q_rad) && isfinite(c->qd_rad_s) && isfinite(c->tau_ff_nm),
                   "command not finite: q %g qd %g tau %g", c->q_rad, c->qd_rad_s, c->tau_ff_nm);
        FUZZ_CHECK(fuzz_in_range(c->kp_nm_rad, 0.0f, w->kp_max_nm_rad) || !is_packed,
                   "command kp %.9g outside [0, %g]", c->kp_nm_rad, w->kp_max_nm_rad);
        FUZZ_CHECK(fuzz_in_range(c->kd_nm_s_rad, 0.0f, w->kd_max_nm_s_rad) || !is_packed,
                   "command kd %.9g outside [0, %g]", c->kd_nm_s_rad, w->kd_max_nm_s_rad);
        FUZZ_CHECK(isfinite(c->kp_nm_rad) && isfinite(c->kd_nm_s_rad), "command gains not finite");
        if (is_packed) {
            FUZZ_CHECK(fuzz_in_range(c->q_rad, w->p_min_rad, w->p_max_rad),
                       "command q %.9g outside [%g, %g]", c->q_rad, w->p_min_rad, w->p_max_rad);
            FUZZ_CHECK(fuzz_in_range(c->qd_rad_s, w->v_min_rad_s, w->v_max_rad_s),
                       "command qd %.9g outside the wire range", c->qd_rad_s);
            FUZZ_CHECK(fuzz_in_range(c->tau_ff_nm, w->t_min_nm, w->t_max_nm),
                       "command tau %.9g outside the wire range", c->tau_ff_nm);
        }
    }
}

/* Decoded reply -> device encode -> host decode: q and qd come back. */
static void fuzz_act_round_trip(const ps_act_cfg_t *a, const fuzz_act_res_t *r)
{
    const ps_act_range_t *w = &a->wire;
    if (r->rc_reply != 0 || !fuzz_in_range(r->reply.q_rad, w->p_min_rad, w->p_max_rad) ||
        !fuzz_in_range(r->reply.qd_rad_s, w->v_min_rad_s, w->v_max_rad_s))
        return; /* the device saturates what lies outside the wire range */
    const ps_act_proto_t *p = ps_act_proto_get(a->protocol);
    ps_can_frame_t f[PS_ACT_MAX_FRAMES];
    const int n = p->encode_reply(a, &r->reply, f, PS_ACT_MAX_FRAMES);
    FUZZ_CHECK(n >= 1, "encode_reply of a decoded reply returned %d", n);
    ps_act_meas_t m = {0};
    int rc = -ENOENT;
    for (int k = 0; k < n && rc != 0; k++)
        if (p->match_reply(a, &f[k]))
            rc = p->decode_reply(a, &f[k], &m);
    FUZZ_CHECK(rc == 0, "the device's reply to a decoded reply does not decode (%d)", rc);
    const uint32_t *bits = p->resolution_bits;
    const float lsb_q = (w->p_max_rad - w->p_min_rad) / (float)((1u << bits[0]) - 1u);
    const float lsb_v = (w->v_max_rad_s - w->v_min_rad_s) / (float)((1u << bits[1]) - 1u);
    FUZZ_CHECK(fabsf(m.q_rad - r->reply.q_rad) <= lsb_q * 1.01f, "q %.9g came back as %.9g",
               r->reply.q_rad, m.q_rad);
    FUZZ_CHECK(fabsf(m.qd_rad_s - r->reply.qd_rad_s) <= lsb_v * 1.01f, "qd %.9g came back as %.9g",
               r->reply.qd_rad_s, m.qd_rad_s);
}

/* Two mountings of the same drive: direct, and geared 9:1, reversed, offset. */
static ps_act_cfg_t fuzz_act_mount(ps_act_cfg_t a, uint8_t sel)
{
    if (sel & 1u) {
        a.gear_ratio = 9.0f;
        a.direction = -1.0f;
        a.zero_offset_rad = 0.3f;
        a.kt_nm_a = 0.1f;
    }
    return a;
}

static int fuzz_act_run(const ps_act_cfg_t *base, bool is_packed, const uint8_t *data, size_t size)
{
    fuzz_in_t in = {data, size};
    const ps_act_cfg_t a = fuzz_act_mount(*base, fuzz_u8(&in));
    char err[160];
    FUZZ_CHECK(ps_act_check_cfg(&a, err, sizeof err) == 0, "harness configuration: %s", err);
    ps_can_frame_t f;
    while (fuzz_next_frame(&in, &f, 0)) {
        fuzz_act_res_t r1, r2;
        fuzz_frame_poison(&f, 0xa5u);
        fuzz_act_decode(&a, &f, &r1);
        fuzz_frame_poison(&f, 0x5au);
        fuzz_act_decode(&a, &f, &r2);
        FUZZ_CHECK(!memcmp(&r1, &r2, sizeof r1),
                   "the result depends on bytes past the frame's length %u", f.len);
        fuzz_act_check_values(&a, &r1, is_packed);
        fuzz_act_round_trip(&a, &r1);
    }
    return 0;
}

#endif /* PS_FUZZ_ACT_H */
