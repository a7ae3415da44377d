/*
 * Tests of rt/ps_monitor's decoder: frames made by the runtime's own encoders
 * for the mixed-protocol test robot (RobStride legs, MIT waist and arms) are
 * named by joint and decoded back to the values encoded; IMU halves pair into
 * samples; anything else is unknown, and a frame addressed to a joint that
 * does not decode is malformed.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <string.h>

#include "../drivers/ps_actuator.h"
#include "../rt/ps_config.h"
#include "../rt/ps_monitor.h"

static ps_robot_cfg_t g_robot;

static int setup(void **state)
{
    (void)state;
    char err[256];
    return ps_config_load_robot("tests/data/robots/ps1-mixed.yaml", &g_robot, err, sizeof err);
}

static int joint(const char *name)
{
    for (uint32_t j = 0; j < g_robot.n_joints; j++)
        if (strcmp(g_robot.joint_name[j], name) == 0)
            return (int)j;
    fail_msg("no joint %s", name);
    return -1;
}

static ps_monitor_kind_t describe(const ps_can_frame_t *f, uint32_t bus, int *j, char *text)
{
    ps_monitor_t m;
    ps_monitor_init(&m, &g_robot);
    return ps_monitor_describe(&m, &g_robot, bus, f, j, text, 256);
}

static void check_command(const char *name, const char *want)
{
    const int j = joint(name);
    const ps_act_cmd_t cmd = {.q_rad = 0.25f,
                              .qd_rad_s = 0.0f,
                              .kp_nm_rad = 100.0f,
                              .kd_nm_s_rad = 2.0f,
                              .tau_ff_nm = 1.5f};
    ps_can_frame_t f[PS_ACT_MAX_FRAMES];
    assert_true(ps_act_encode_command(&g_robot.act[j], &cmd, f, PS_ACT_MAX_FRAMES) >= 1);
    int got_j;
    char text[256];
    assert_int_equal(describe(&f[0], g_robot.act[j].bus_idx, &got_j, text), PS_MONITOR_COMMAND);
    assert_int_equal(got_j, j);
    if (strstr(text, want) == NULL)
        fail_msg("'%s' lacks '%s'", text, want);
}

static void test_commands_of_both_protocols_are_named_and_decoded(void **state)
{
    (void)state;
    /* 0.25 rad comes back within the wire's resolution (16 and 12 bits) */
    check_command("l_knee", "l_knee cmd q=+0.2");       /* RobStride */
    check_command("waist_yaw", "waist_yaw cmd q=+0.2"); /* MIT */
    check_command("l_knee", "kp=100.0 kd=2.00 tau=+1.50 Nm");
}

static void test_replies_and_requests_are_named(void **state)
{
    (void)state;
    const int j = joint("r_knee");
    const ps_act_proto_t *p = ps_act_proto_get(g_robot.act[j].protocol);
    ps_act_meas_t m = {.q_rad = -0.5f, .temp_c = 41.0f};
    ps_can_frame_t f[PS_ACT_MAX_FRAMES];
    assert_true(p->encode_reply(&g_robot.act[j], &m, f, PS_ACT_MAX_FRAMES) >= 1);
    int got_j;
    char text[256];
    assert_int_equal(describe(&f[0], g_robot.act[j].bus_idx, &got_j, text), PS_MONITOR_REPLY);
    assert_int_equal(got_j, j);
    assert_non_null(strstr(text, "r_knee reply"));
    assert_non_null(strstr(text, "T=41 C faults none"));
    assert_true(ps_act_encode_request(&g_robot.act[j], PS_ACT_REQ_ENABLE, f, PS_ACT_MAX_FRAMES) >=
                1);
    assert_int_equal(describe(&f[0], g_robot.act[j].bus_idx, &got_j, text), PS_MONITOR_REQUEST);
    assert_string_equal(text, "r_knee request enable");
    /* The same request to a drive id no joint of that bus has: unknown. */
    f[0].id = (f[0].id & ~0xffu) | 0x7eu;
    assert_int_equal(describe(&f[0], g_robot.act[j].bus_idx, &got_j, text), PS_MONITOR_UNKNOWN);
    assert_int_equal(got_j, -1);
}

static void test_imu_halves_pair_and_strangers_are_unknown(void **state)
{
    (void)state;
    ps_imu_sample_t s = {.accel_body_m_s2 = {0.0f, 0.0f, 9.81f}, .seq = 7};
    ps_can_frame_t f[2];
    ps_imu_msg_encode(g_robot.imu.base_id, &s, f);
    ps_monitor_t m;
    ps_monitor_init(&m, &g_robot);
    int j;
    char text[256];
    /* A capture that begins between a sample's halves sees the accel half
     * first: the rest of a sample, not a malformed frame. */
    assert_int_equal(ps_monitor_describe(&m, &g_robot, g_robot.imu.bus_idx, &f[1], &j, text, 256),
                     PS_MONITOR_IMU);
    assert_non_null(strstr(text, "of a sample begun before the capture"));
    assert_int_equal(ps_monitor_describe(&m, &g_robot, g_robot.imu.bus_idx, &f[0], &j, text, 256),
                     PS_MONITOR_IMU);
    assert_string_equal(text, "imu gyro half (seq 7)");
    assert_int_equal(ps_monitor_describe(&m, &g_robot, g_robot.imu.bus_idx, &f[1], &j, text, 256),
                     PS_MONITOR_IMU);
    assert_non_null(strstr(text, "imu sample 7"));
    assert_non_null(strstr(text, "+9.810 m/s2"));
    /* After that, an accel half with no gyro half before it does not pair,
     * nor does a frame of the wrong length at the start of a capture. */
    assert_int_equal(ps_monitor_describe(&m, &g_robot, g_robot.imu.bus_idx, &f[1], &j, text, 256),
                     PS_MONITOR_MALFORMED);
    ps_monitor_t fresh;
    ps_monitor_init(&fresh, &g_robot);
    ps_can_frame_t short_accel = f[1];
    short_accel.len = 7;
    assert_int_equal(
        ps_monitor_describe(&fresh, &g_robot, g_robot.imu.bus_idx, &short_accel, &j, text, 256),
        PS_MONITOR_MALFORMED);
    ps_can_frame_t x = {.id = 0x7f0, .len = 2, .data = {0xde, 0xad}};
    assert_int_equal(describe(&x, 0, &j, text), PS_MONITOR_UNKNOWN);
    assert_string_equal(text, "unknown 7F0 [2] DE AD");
}

/* The same six values imu.frozen_samples times in a row, the seq going on:
 * the monitor says the sample was refused as frozen. */
static void test_imu_frozen_values_named(void **state)
{
    (void)state;
    ps_monitor_t m;
    ps_monitor_init(&m, &g_robot);
    const uint32_t n = g_robot.imu.frozen_samples;
    assert_true(n >= 2);
    int j;
    char text[256];
    ps_monitor_kind_t kind = PS_MONITOR_IMU;
    for (uint32_t i = 0; i < n; i++) {
        ps_imu_sample_t s = {.accel_body_m_s2 = {0.0f, 0.0f, 9.81f}, .seq = (uint8_t)i};
        ps_can_frame_t f[2];
        ps_imu_msg_encode(g_robot.imu.base_id, &s, f);
        (void)ps_monitor_describe(&m, &g_robot, g_robot.imu.bus_idx, &f[0], &j, text, 256);
        kind = ps_monitor_describe(&m, &g_robot, g_robot.imu.bus_idx, &f[1], &j, text, 256);
        if (i + 1u < n)
            assert_int_equal(kind, PS_MONITOR_IMU);
    }
    assert_int_equal(kind, PS_MONITOR_MALFORMED);
    char want[128];
    snprintf(want, sizeof(want),
             "imu sample %u refused: the same six values %u times in a row (frozen)",
             (unsigned)(uint8_t)(n - 1u), n);
    assert_string_equal(text, want);
}

static void test_a_short_frame_to_a_joint_is_malformed(void **state)
{
    (void)state;
    const int j = joint("waist_yaw");
    const ps_act_cmd_t cmd = {.q_rad = 0.1f};
    ps_can_frame_t f[PS_ACT_MAX_FRAMES];
    assert_true(ps_act_encode_command(&g_robot.act[j], &cmd, f, PS_ACT_MAX_FRAMES) >= 1);
    f[0].len = 5;
    int got_j;
    char text[256];
    assert_int_equal(describe(&f[0], g_robot.act[j].bus_idx, &got_j, text), PS_MONITOR_MALFORMED);
    assert_int_equal(got_j, j);
    assert_non_null(strstr(text, "waist_yaw malformed"));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_commands_of_both_protocols_are_named_and_decoded),
        cmocka_unit_test(test_replies_and_requests_are_named),
        cmocka_unit_test(test_imu_halves_pair_and_strangers_are_unknown),
        cmocka_unit_test(test_imu_frozen_values_named),
        cmocka_unit_test(test_a_short_frame_to_a_joint_is_malformed),
    };
    return cmocka_run_group_tests(tests, setup, NULL);
}
