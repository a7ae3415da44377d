/*
 * ps_test_wire: the AK-style MIT wire ranges the driver, servo and emulated
 * drive tests share, so that their hand-computed frame bytes agree:
 * p +-12.5 rad, v +-45 rad/s, kp 0..500 Nm/rad, kd 0..5 Nm s/rad,
 * t +-18 Nm, i +-40 A. One LSB: p 25/65535 rad, v 90/4095 rad/s,
 * kp 500/4095, kd 5/4095, t 36/4095 Nm, i 80/4095 A.
 */
#ifndef PS_TEST_WIRE_H
#define PS_TEST_WIRE_H

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

#endif /* PS_TEST_WIRE_H */
