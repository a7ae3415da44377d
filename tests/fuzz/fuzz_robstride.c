/* libFuzzer target: RobStride / CyberGear frames (drivers/ps_robstride.c,
 * 29-bit ids) through the actuator port, host and device side
 * (tests/fuzz/fuzz_act.h). Drive 0x01 of host 0xFD, CyberGear ranges. */
#include "../fakes/ps_test_wire.h"
#include "fuzz_act.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const ps_act_cfg_t a = ps_test_wire_cybergear();
    return fuzz_act_run(&a, true, data, size);
}
