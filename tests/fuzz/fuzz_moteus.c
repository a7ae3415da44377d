/* libFuzzer target: moteus register frames over CAN FD (drivers/ps_moteus.c)
 * through the actuator port, host and device side (tests/fuzz/fuzz_act.h).
 * moteus sends floats with no packing range: replies and commands must be
 * finite (gains in [0, max] are not the protocol's: a kp scale may exceed 1),
 * and whatever lies inside the wire range survives a round trip. Drive 0x0B
 * replying to host 0x01 (l_knee of tests/data/robots/ps1-moteus.yaml). */
#include "fuzz_act.h"

#define PI_F 3.14159265f

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    ps_act_cfg_t a;
    memset(&a, 0, sizeof a);
    a.protocol = PS_ACT_PROTO_MOTEUS;
    a.can_id = 0x0B;
    a.reply_id = 0x01;
    a.wire = (ps_act_range_t){.p_min_rad = -4.0f * PI_F,
                              .p_max_rad = 4.0f * PI_F,
                              .v_min_rad_s = -20.0f,
                              .v_max_rad_s = 20.0f,
                              .kp_max_nm_rad = 200.0f,
                              .kd_max_nm_s_rad = 5.0f,
                              .t_min_nm = -30.0f,
                              .t_max_nm = 30.0f,
                              .i_min_a = -60.0f,
                              .i_max_a = 60.0f};
    a.gear_ratio = 1.0f;
    a.direction = 1.0f;
    a.kt_nm_a = 1.0f;
    a.temp_max_c = 80.0f;
    a.rate_div = 1;
    return fuzz_act_run(&a, false, data, size);
}
