/* libFuzzer target: RobStride / CyberGear frames (drivers/ps_robstride.c,
 * 29-bit ids) through the actuator port, host and device side
 * (tests/fuzz/fuzz_act.h). Drive 0x01 of host 0xFD, CyberGear ranges. */
#include "fuzz_act.h"

#define PI_F 3.14159265f

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    ps_act_cfg_t a;
    memset(&a, 0, sizeof a);
    a.protocol = PS_ACT_PROTO_ROBSTRIDE;
    a.can_id = 0x01;
    a.reply_id = 0xFD;
    a.wire = (ps_act_range_t){.p_min_rad = -4.0f * PI_F,
                              .p_max_rad = 4.0f * PI_F,
                              .v_min_rad_s = -30.0f,
                              .v_max_rad_s = 30.0f,
                              .kp_max_nm_rad = 500.0f,
                              .kd_max_nm_s_rad = 5.0f,
                              .t_min_nm = -12.0f,
                              .t_max_nm = 12.0f,
                              .i_min_a = -27.0f,
                              .i_max_a = 27.0f};
    a.gear_ratio = 1.0f;
    a.direction = 1.0f;
    a.kt_nm_a = 1.0f;
    a.temp_max_c = 80.0f;
    a.rate_div = 1;
    return fuzz_act_run(&a, true, data, size);
}
