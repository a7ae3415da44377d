/* libFuzzer target: MIT-mode frames (drivers/ps_mit.c) through the actuator
 * port, host and device side (tests/fuzz/fuzz_act.h), and the raw byte
 * decoders on a buffer of exactly the frame's length, so ASan sees any read
 * past it. Drive 0x01 replying on 0x101 (waist_yaw of tests/data/robots/ps1-mixed.yaml) (AK-style
 * ranges). */
#include "../../drivers/ps_mit.h"
#include "../fakes/ps_test_wire.h"
#include "fuzz_act.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    ps_act_cfg_t a = ps_test_wire_drive(PS_ACT_PROTO_MIT, 0x01, 0x101, ps_test_wire_ak());
    a.kt_nm_a = 0.09f;
    (void)fuzz_act_run(&a, true, data, size);

    /* The byte-level API on an exact-size copy of the whole input. */
    uint8_t *copy = malloc(size > 0 ? size : 1);
    if (copy == NULL)
        return 0;
    memcpy(copy, data, size);
    const uint8_t len = (uint8_t)(size > 255 ? 255 : size);
    ps_mit_reply_t rep;
    if (ps_mit_decode_reply(&a.wire, copy, len, &rep) == 0)
        FUZZ_CHECK(fuzz_in_range(rep.p_rad, a.wire.p_min_rad, a.wire.p_max_rad) &&
                       fuzz_in_range(rep.v_rad_s, a.wire.v_min_rad_s, a.wire.v_max_rad_s) &&
                       fuzz_in_range(rep.i_a, a.wire.i_min_a, a.wire.i_max_a) &&
                       rep.motor_id <= 0xfu && rep.fault <= 0xfu,
                   "raw reply p %.9g v %.9g i %.9g", rep.p_rad, rep.v_rad_s, rep.i_a);
    ps_mit_cmd_t cmd;
    if (ps_mit_decode_cmd(&a.wire, copy, len, &cmd) == 0)
        FUZZ_CHECK(fuzz_in_range(cmd.p_rad, a.wire.p_min_rad, a.wire.p_max_rad) &&
                       fuzz_in_range(cmd.v_rad_s, a.wire.v_min_rad_s, a.wire.v_max_rad_s) &&
                       fuzz_in_range(cmd.kp_nm_rad, 0.0f, a.wire.kp_max_nm_rad) &&
                       fuzz_in_range(cmd.kd_nm_s_rad, 0.0f, a.wire.kd_max_nm_s_rad) &&
                       fuzz_in_range(cmd.t_ff_nm, a.wire.t_min_nm, a.wire.t_max_nm),
                   "raw command outside the wire ranges");
    const int sp = ps_mit_classify_special(copy, len);
    FUZZ_CHECK(sp == 0 || (sp >= PS_MIT_SPECIAL_ENTER && sp <= PS_MIT_SPECIAL_ZERO),
               "classify_special returned %d", sp);
    free(copy);
    return 0;
}
