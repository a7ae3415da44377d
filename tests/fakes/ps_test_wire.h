/*
 * ps_test_wire: the AK-style MIT wire ranges the driver, servo and emulated
 * drive tests share, so that their hand-computed frame bytes agree:
 * p +-12.5 rad, v +-45 rad/s, kp 0..500 Nm/rad, kd 0..5 Nm s/rad,
 * t +-18 Nm, i +-40 A. One LSB: p 25/65535 rad, v 90/4095 rad/s,
 * kp 500/4095, kd 5/4095, t 36/4095 Nm, i 80/4095 A.
 * Also two whole drives the protocol tests and the fuzz targets share: a
 * CyberGear (RobStride protocol) and a moteus, direct drive.
 */
#ifndef PS_TEST_WIRE_H
#define PS_TEST_WIRE_H

#include <string.h>

#include "../../drivers/ps_actuator.h"

/* An initializer, for a file-scope const range; ps_test_wire_ak() for a value. */
#define PS_TEST_WIRE_AK_INIT                                                                       \
    {                                                                                              \
        .p_min_rad = -12.5f, .p_max_rad = 12.5f, .v_min_rad_s = -45.0f, .v_max_rad_s = 45.0f,      \
        .kp_max_nm_rad = 500.0f, .kd_max_nm_s_rad = 5.0f, .t_min_nm = -18.0f, .t_max_nm = 18.0f,   \
        .i_min_a = -40.0f, .i_max_a = 40.0f,                                                       \
    }

static inline ps_act_range_t ps_test_wire_ak(void)
{
    const ps_act_range_t r = PS_TEST_WIRE_AK_INIT;
    return r;
}

/* A direct drive of protocol proto, can_id and reply_id, on these ranges. */
static inline ps_act_cfg_t ps_test_wire_drive(ps_act_proto_id_t proto, uint32_t can_id,
                                              uint32_t reply_id, ps_act_range_t wire)
{
    ps_act_cfg_t a;
    memset(&a, 0, sizeof a);
    a.protocol = proto;
    a.can_id = can_id;
    a.reply_id = reply_id;
    a.wire = wire;
    a.gear_ratio = 1.0f;
    a.direction = 1.0f;
    a.kt_nm_a = 1.0f;
    a.temp_max_c = 80.0f;
    a.rate_div = 1;
    return a;
}

/* CyberGear: drive 0x01 of host 0xFD; angle +-4 pi, 30 rad/s, 12 Nm, 27 A. */
static inline ps_act_cfg_t ps_test_wire_cybergear(void)
{
    const float pi = 3.14159265f;
    return ps_test_wire_drive(PS_ACT_PROTO_ROBSTRIDE, 0x01, 0xFD,
                              (ps_act_range_t){.p_min_rad = -4.0f * pi,
                                               .p_max_rad = 4.0f * pi,
                                               .v_min_rad_s = -30.0f,
                                               .v_max_rad_s = 30.0f,
                                               .kp_max_nm_rad = 500.0f,
                                               .kd_max_nm_s_rad = 5.0f,
                                               .t_min_nm = -12.0f,
                                               .t_max_nm = 12.0f,
                                               .i_min_a = -27.0f,
                                               .i_max_a = 27.0f});
}

/* moteus: drive 0x0B replying to host 0x05; +-4 pi, 20 rad/s, 30 Nm. */
static inline ps_act_cfg_t ps_test_wire_moteus(void)
{
    const float pi = 3.14159265f;
    return ps_test_wire_drive(PS_ACT_PROTO_MOTEUS, 0x0B, 0x05,
                              (ps_act_range_t){.p_min_rad = -4.0f * pi,
                                               .p_max_rad = 4.0f * pi,
                                               .v_min_rad_s = -20.0f,
                                               .v_max_rad_s = 20.0f,
                                               .kp_max_nm_rad = 200.0f,
                                               .kd_max_nm_s_rad = 5.0f,
                                               .t_min_nm = -30.0f,
                                               .t_max_nm = 30.0f,
                                               .i_min_a = -60.0f,
                                               .i_max_a = 60.0f});
}

#endif /* PS_TEST_WIRE_H */
