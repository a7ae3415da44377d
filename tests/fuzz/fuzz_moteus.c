/* libFuzzer target: moteus register frames over CAN FD (drivers/ps_moteus.c)
 * through the actuator port, host and device side (tests/fuzz/fuzz_act.h).
 * moteus sends floats with no packing range: replies and commands must be
 * finite (gains in [0, max] are not the protocol's: a kp scale may exceed 1),
 * and whatever lies inside the wire range survives a round trip. Drive 0x0B
 * replying to host 0x01 (l_knee of tests/data/robots/ps1-moteus.yaml). */
#include "../fakes/ps_test_wire.h"
#include "fuzz_act.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    ps_act_cfg_t a = ps_test_wire_moteus();
    a.reply_id = 0x01;
    return fuzz_act_run(&a, false, data, size);
}
