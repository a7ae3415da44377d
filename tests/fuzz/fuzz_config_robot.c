/* libFuzzer target: robot files (rt/ps_config_robot.c, robots/ *.yaml) through
 * ps_config_load_robot_sim, the loader of the robot and its `sim:` section in
 * one load (tests/fuzz/fuzz_config.h). A loaded robot has at most
 * PS_MAX_JOINTS joints, each actuator accepted by ps_act_check_cfg, joint
 * limits finite and ordered with kp and kd limits positive. */
#include "../../drivers/ps_actuator.h"
#include "../../rt/ps_config_sim.h"
#include "fuzz_config.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static ps_robot_cfg_t r;
    static ps_sim_devices_cfg_t sim;
    char path[64], err[FUZZ_CONFIG_ERR_LEN], why[160];
    const int fd = fuzz_memfd(data, size, path, sizeof path);
    if (fd < 0)
        return 0;
    const int rc = ps_config_load_robot_sim(path, &r, &sim, err, sizeof err);
    close(fd);
    fuzz_config_check_err(rc, path, err);
    if (rc == 0) {
        FUZZ_CHECK(r.n_joints <= PS_MAX_JOINTS, "n_joints %u", r.n_joints);
        for (uint32_t j = 0; j < r.n_joints; j++) {
            FUZZ_CHECK(ps_act_check_cfg(&r.act[j], why, sizeof why) == 0,
                       "joint %u accepted with an actuator refused by its check: %s", j, why);
            const ps_act_limits_t *l = &r.servo[j].lim;
            FUZZ_CHECK(isfinite(l->pos_min_rad) && isfinite(l->pos_max_rad) &&
                           l->pos_min_rad < l->pos_max_rad,
                       "joint %u position limits [%g, %g]", j, l->pos_min_rad, l->pos_max_rad);
            FUZZ_CHECK(fuzz_in_range(l->vel_max_rad_s, 0.0f, INFINITY) &&
                           fuzz_in_range(l->torque_max_nm, 0.0f, INFINITY) &&
                           fuzz_in_range(l->kp_max_nm_rad, 0.0f, INFINITY) &&
                           fuzz_in_range(l->kd_max_nm_s_rad, 0.0f, INFINITY),
                       "joint %u limits not finite and positive", j);
        }
    }
    return 0;
}
