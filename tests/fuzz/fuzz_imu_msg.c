/* libFuzzer target: pushstep's own two-frame IMU message
 * (drivers/ps_imu_msg.c) through the IMU port (tests/fuzz/fuzz_imu.h):
 * base id 0x080 (robots/ps1.yaml), +-32.767 rad/s, +-65.534 m/s^2. The status byte is the
 * gyro frame's, passed on as sent. */
#include "fuzz_imu.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const ps_imu_cfg_t cfg = {
        .bus_idx = 0, .base_id = 0x080, .rate_div = 1, .protocol = PS_IMU_PROTO_PUSHSTEP};
    fuzz_imu_run(&cfg, 32767.0f * PS_IMU_GYRO_LSB_RAD_S, 32767.0f * PS_IMU_ACCEL_LSB_M_S2, false,
                 data, size);
    return 0;
}
