/* libFuzzer target: an Xsens MTi-600's CAN output (drivers/ps_imu_xsens.c)
 * through the IMU port (tests/fuzz/fuzz_imu.h): ids from 0x205 (tests/data/robots/ps1-xsens.yaml),
 * 2^-9 rad/s and 2^-8 m/s^2 per LSB; the status word maps onto
 * PS_IMU_STATUS_* bits only. */
#include "fuzz_imu.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const ps_imu_cfg_t cfg = {
        .bus_idx = 0, .base_id = 0x205, .rate_div = 1, .protocol = PS_IMU_PROTO_XSENS};
    fuzz_imu_run(&cfg, 32768.0f * PS_IMU_XSENS_GYRO_LSB_RAD_S,
                 32768.0f * PS_IMU_XSENS_ACCEL_LSB_M_S2, true, data, size);
    return 0;
}
