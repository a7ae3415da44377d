/*
 * Tests of drivers/ps_can_replay: CAN ports fed from a candump -L log, on a
 * small log written out by hand below. The robot: two MIT drives on can0
 * (ids 1 and 2, replies 0x101 and 0x102), one on can1 (id 3, reply 0x103)
 * and the IMU on can1 (0x080 gyro, 0x081 accel), ticking at 1 kHz. Checked:
 * which frames are fed, expected or unknown; frames handed over when due on
 * the replay clock, in file order per bus, with their logged times; the
 * clock's start; the comparison of sent commands with the logged ones; the
 * refusals (a bad line with its line and column, an interface the board
 * does not have, storage too small, an empty or missing file).
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../drivers/ps_can_replay.h"
#include "../drivers/ps_candump.h"
#include "../rt/ps_err.h"
#include "fakes/ps_test_wire.h"

#define T0_NS     1000000000LL /* the log's first tick, 1.000000 s */
#define PERIOD_NS 1000000LL
#define US        1000LL

/* MIT command bytes (p 16 bits, v, kp, kd, t 12 bits each, over the ranges
 * of ps_test_wire.h): q 0 -> 0x8000, qd 0 -> 0x800, kp 100 -> 819 = 0x333,
 * kd 3 -> 2457 = 0x999, tau 0 -> 0x800. */
#define CMD_Q0 "8000800333999800"
/* The same with q 0.1 rad: (12.6 / 25) 65535 = 33029.6 -> 0x8106, 262 steps up. */
#define CMD_Q01 "8106800333999800"
#define ENABLE  "FFFFFFFFFFFFFFFC"
#define DISABLE "FFFFFFFFFFFFFFFD"

/* Line by line: what each frame is for the robot above. */
static const char LOG[] =
    "(0000000001.000000) can0 001#" CMD_Q0 "\n"       /*  1 expected: joint 0 command */
    "(0000000001.000000) can1 003#" ENABLE "\n"       /*  2 expected: joint 2 enable */
    "(0000000001.000300) can0 101#01820C8008001E1E\n" /*  3 fed: joint 0 reply */
    "(0000000001.000250) can1 080#E8030C0000002A00\n" /*  4 fed: IMU gyro */
    "(0000000001.000400) can1 081#0000000029132A2A\n" /*  5 fed: IMU accel */
    "(0000000001.001500) can0 102#02820C8008001E1E\n" /*  6 fed: joint 1 reply */
    "(0000000001.001200) can0 101#01820C8008001E1F\n" /*  7 fed, earlier than 6 */
    "(0000000001.000500) can0 7FF#DEAD\n"             /*  8 unknown */
    "(0000000001.001000) can0 001#" CMD_Q0 "\n"       /*  9 expected: joint 0 */
    "(0000000001.001000) can1 003#" CMD_Q0 "\n";      /* 10 expected: joint 2 */

typedef struct {
    char path[64];
    ps_act_cfg_t act[3];
    ps_can_replay_cfg_t cfg;
    ps_can_replay_entry_t entries[32];
    uint8_t data[256];
    ps_can_replay_t r;
    char err[PS_ERR_MSG_LEN];
} fixture_t;

static ps_act_cfg_t mit(uint32_t bus_idx, uint32_t can_id)
{
    ps_act_cfg_t a;
    memset(&a, 0, sizeof(a));
    a.bus_idx = bus_idx;
    a.protocol = PS_ACT_PROTO_MIT;
    a.can_id = can_id;
    a.reply_id = 0x100u + can_id;
    a.wire = ps_test_wire_ak();
    a.gear_ratio = 1.0f;
    a.direction = 1.0f;
    a.kt_nm_a = 1.0f;
    a.temp_max_c = 90.0f;
    a.rate_div = 1;
    return a;
}

static void write_log(fixture_t *fx, const char *text)
{
    snprintf(fx->path, sizeof(fx->path), "/tmp/ps_replay_XXXXXX.log");
    const int fd = mkstemps(fx->path, 4);
    assert_true(fd >= 0);
    FILE *f = fdopen(fd, "w");
    assert_non_null(f);
    assert_int_equal(fputs(text, f) >= 0, 1);
    assert_int_equal(fclose(f), 0);
}

static int setup(void **state)
{
    fixture_t *fx = calloc(1, sizeof(*fx));
    if (fx == NULL)
        return -1;
    fx->act[0] = mit(0, 1);
    fx->act[1] = mit(0, 2);
    fx->act[2] = mit(1, 3);
    fx->cfg = (ps_can_replay_cfg_t){
        .path = fx->path,
        .n_buses = 2,
        .ifname = {"can0", "can1"},
        .act = fx->act,
        .n_joints = 3,
        .imu_bus_idx = 1,
        .n_imu_ids = 2,
        .imu_ids = {0x080, 0x081},
        .period_ns = PERIOD_NS,
    };
    *state = fx;
    return 0;
}

static int teardown(void **state)
{
    fixture_t *fx = *state;
    ps_can_replay_deinit(&fx->r);
    if (fx->path[0] != '\0')
        unlink(fx->path);
    free(fx);
    return 0;
}

static int init_log(fixture_t *fx, const char *text)
{
    write_log(fx, text);
    return ps_can_replay_init(&fx->r, &fx->cfg, fx->entries, 32, fx->data, sizeof(fx->data),
                              fx->err, sizeof(fx->err));
}

static int recv_all(const ps_can_port_t *p, ps_can_frame_t *out, size_t max)
{
    const int n = ps_can_recv_batch(p, out, max);
    assert_true(n >= 0);
    return n;
}

static ps_can_frame_t frame_of_hex(uint32_t id, const char *hex)
{
    ps_can_frame_t f;
    memset(&f, 0, sizeof(f));
    f.id = id;
    f.len = (uint8_t)(strlen(hex) / 2u);
    for (uint8_t i = 0; i < f.len; i++) {
        unsigned byte = 0;
        assert_int_equal(sscanf(hex + 2u * i, "%2x", &byte), 1);
        f.data[i] = (uint8_t)byte;
    }
    return f;
}

/* ---- reading and classifying ----------------------------------------- */

static void test_measure_hand_log_counts_lines_frames_and_bytes(void **state)
{
    fixture_t *fx = *state;
    write_log(fx, LOG);
    ps_can_replay_size_t size;
    assert_int_equal(ps_can_replay_measure(&fx->cfg, &size, fx->err, sizeof(fx->err)), 0);
    assert_int_equal(size.n_lines, 10);
    assert_int_equal(size.n_entries, 9); /* all but the unknown 7FF */
    assert_int_equal(size.n_data, 9 * 8);
}

static void test_init_hand_log_classifies_fed_expected_unknown(void **state)
{
    fixture_t *fx = *state;
    assert_int_equal(init_log(fx, LOG), 0);
    ps_can_replay_stats_t st;
    ps_can_replay_get_stats(&fx->r, &st);
    assert_int_equal(st.n_lines, 10);
    assert_int_equal(st.n_fed_logged, 5); /* replies 3, 6, 7 and IMU 4, 5 */
    assert_int_equal(st.n_expected, 4);   /* commands and requests 1, 2, 9, 10 */
    assert_int_equal(st.n_unknown, 1);    /* 7FF */
    assert_int_equal(st.n_fed, 0);
    assert_int_equal(st.first_ns, T0_NS);
    assert_int_equal(st.last_ns, T0_NS + 1500 * US);
}

static void test_classify_reply_before_drive_and_imu_only_on_its_bus(void **state)
{
    fixture_t *fx = *state;
    uint32_t j = 99;
    ps_can_frame_t f = frame_of_hex(0x102, "02820C8008001E1E");
    assert_int_equal(ps_can_replay_classify(&fx->cfg, 0, &f, &j), PS_CAN_REPLAY_FED);
    assert_int_equal(j, 1);
    f = frame_of_hex(0x002, CMD_Q0);
    assert_int_equal(ps_can_replay_classify(&fx->cfg, 0, &f, &j), PS_CAN_REPLAY_EXPECTED);
    assert_int_equal(j, 1);
    /* joint 1 is on can0: its id on can1 is nobody's */
    assert_int_equal(ps_can_replay_classify(&fx->cfg, 1, &f, &j), PS_CAN_REPLAY_UNKNOWN);
    f = frame_of_hex(0x080, "E8030C0000002A00");
    assert_int_equal(ps_can_replay_classify(&fx->cfg, 1, &f, &j), PS_CAN_REPLAY_FED);
    assert_int_equal(ps_can_replay_classify(&fx->cfg, 0, &f, &j), PS_CAN_REPLAY_UNKNOWN);
    f.is_ext = 1; /* an IMU id as a 29-bit identifier is not the IMU */
    assert_int_equal(ps_can_replay_classify(&fx->cfg, 1, &f, &j), PS_CAN_REPLAY_UNKNOWN);
}

/* ---- the clock and the ports ---------------------------------------- */

static void test_recv_batch_frames_due_by_clock_in_file_order(void **state)
{
    fixture_t *fx = *state;
    assert_int_equal(init_log(fx, LOG), 0);
    const ps_clock_t *clk = ps_can_replay_clock(&fx->r);
    const ps_can_port_t can0 = ps_can_replay_port(&fx->r, 0);
    const ps_can_port_t can1 = ps_can_replay_port(&fx->r, 1);
    assert_string_equal(can1.name, "can1");
    ps_can_frame_t out[8];
    /* tick 0 at 1.000000: nothing received yet (the commands are not fed) */
    assert_int_equal(ps_clock_now_ns(clk), T0_NS);
    assert_int_equal(recv_all(&can0, out, 8), 0);
    assert_int_equal(recv_all(&can1, out, 8), 0);
    /* tick 1: the reply to tick 0 and the IMU sample, logged times kept */
    assert_int_equal(ps_clock_sleep_until_ns(clk, T0_NS + PERIOD_NS), 0);
    assert_int_equal(ps_clock_now_ns(clk), T0_NS + PERIOD_NS);
    assert_int_equal(recv_all(&can0, out, 8), 1);
    assert_int_equal(out[0].id, 0x101);
    assert_int_equal(out[0].t_ns, T0_NS + 300 * US);
    assert_int_equal(out[0].len, 8);
    assert_memory_equal(out[0].data, "\x01\x82\x0C\x80\x08\x00\x1E\x1E", 8);
    assert_int_equal(recv_all(&can1, out, 8), 2);
    assert_int_equal(out[0].id, 0x080);
    assert_int_equal(out[0].t_ns, T0_NS + 250 * US);
    assert_int_equal(out[1].id, 0x081);
    /* 1.0013: line 7 (1.0012) is due, but line 6 before it (1.0015) is not:
     * the file's order holds it back */
    assert_int_equal(ps_clock_sleep_until_ns(clk, T0_NS + 1300 * US), 0);
    assert_int_equal(recv_all(&can0, out, 8), 0);
    /* a sleep into the past does not move the clock back */
    assert_int_equal(ps_clock_sleep_until_ns(clk, T0_NS), 0);
    assert_int_equal(ps_clock_now_ns(clk), T0_NS + 1300 * US);
    /* tick 2: both, in file order, one per call when asked for one */
    assert_int_equal(ps_clock_sleep_until_ns(clk, T0_NS + 2 * PERIOD_NS), 0);
    assert_int_equal(recv_all(&can0, out, 1), 1);
    assert_int_equal(out[0].id, 0x102);
    assert_int_equal(out[0].t_ns, T0_NS + 1500 * US);
    assert_int_equal(recv_all(&can0, out, 8), 1);
    assert_int_equal(out[0].id, 0x101);
    assert_int_equal(out[0].data[7], 0x1F);
    /* the log is spent: nothing more, the commands and the unknown frame
     * never came out */
    assert_int_equal(ps_clock_sleep_until_ns(clk, T0_NS + 10 * PERIOD_NS), 0);
    assert_int_equal(recv_all(&can0, out, 8), 0);
    assert_int_equal(recv_all(&can1, out, 8), 0);
    ps_can_replay_stats_t st;
    ps_can_replay_get_stats(&fx->r, &st);
    assert_int_equal(st.n_fed, 5);
    assert_int_equal(st.n_buses_fed, 2);
    ps_can_state_t bus;
    assert_int_equal(ps_can_get_state(&can0, &bus), 0);
    assert_int_equal(bus.mode, PS_CAN_BUS_ERROR_ACTIVE);
    assert_int_equal(bus.n_rx_frames, 3);
    assert_int_equal(bus.n_tx_frames, 0);
}

static void test_init_first_frame_mid_tick_clock_starts_on_the_tick(void **state)
{
    fixture_t *fx = *state;
    assert_int_equal(init_log(fx, "(0000000002.000700) can0 101#01820C8008001E1E\n"
                                  "(0000000002.000300) can1 080#E8030C0000002A00\n"),
                     0);
    /* the earliest frame (1 s + 300 us, on the second line) rounded down */
    assert_int_equal(ps_can_replay_start_ns(&fx->r), 2 * T0_NS);
    assert_int_equal(ps_clock_now_ns(ps_can_replay_clock(&fx->r)), 2 * T0_NS);
    assert_int_equal(ps_can_replay_last_ns(&fx->r), 2 * T0_NS + 700 * US);
}

static void test_init_log_near_time_zero_clock_starts_one_tick_in(void **state)
{
    fixture_t *fx = *state;
    assert_int_equal(init_log(fx, "(0000000000.000200) can0 101#01820C8008001E1E\n"), 0);
    /* time 0 means "never" to the loop: the first tick is one period in */
    assert_int_equal(ps_can_replay_start_ns(&fx->r), PERIOD_NS);
    ps_can_frame_t out[2];
    const ps_can_port_t can0 = ps_can_replay_port(&fx->r, 0);
    assert_int_equal(recv_all(&can0, out, 2), 1);
}

/* ---- comparing what the loop sends ---------------------------------- */

static void test_send_batch_same_command_matches_with_no_difference(void **state)
{
    fixture_t *fx = *state;
    assert_int_equal(init_log(fx, LOG), 0);
    const ps_can_port_t can0 = ps_can_replay_port(&fx->r, 0);
    /* the command ps_act_encode_command writes for q 0, kp 100, kd 3 is the
     * hand-written CMD_Q0 */
    const ps_act_cmd_t cmd = {.q_rad = 0.0f, .kp_nm_rad = 100.0f, .kd_nm_s_rad = 3.0f};
    ps_can_frame_t f[PS_ACT_MAX_FRAMES];
    assert_int_equal(ps_act_encode_command(&fx->act[0], &cmd, f, PS_ACT_MAX_FRAMES), 1);
    const ps_can_frame_t hand = frame_of_hex(0x001, CMD_Q0);
    assert_memory_equal(f[0].data, hand.data, 8);
    assert_int_equal(ps_can_send_batch(&can0, f, 1), 1);
    ps_can_replay_stats_t st;
    ps_can_replay_get_stats(&fx->r, &st);
    assert_int_equal(st.n_sent, 1);
    assert_int_equal(st.n_matched, 1);
    assert_int_equal(st.n_cmd_compared, 1);
    assert_int_equal(st.n_unmatched, 0);
    for (unsigned k = 0; k < PS_CAN_REPLAY_N_FIELDS; k++)
        assert_true(st.max_diff[k] == 0.0f && st.max_diff_lsb[k] == 0.0f);
}

static void test_send_batch_other_q_difference_in_joint_units_and_steps(void **state)
{
    fixture_t *fx = *state;
    assert_int_equal(init_log(fx, LOG), 0);
    const ps_clock_t *clk = ps_can_replay_clock(&fx->r);
    const ps_can_port_t can0 = ps_can_replay_port(&fx->r, 0);
    const ps_can_port_t can1 = ps_can_replay_port(&fx->r, 1);
    assert_int_equal(ps_clock_sleep_until_ns(clk, T0_NS + PERIOD_NS), 0);
    /* tick 1: line 1 (tick 0) is still inside the one-tick window and is
     * taken first, the oldest; the next send takes line 9 */
    ps_can_frame_t f[2] = {frame_of_hex(0x001, CMD_Q0), frame_of_hex(0x001, CMD_Q01)};
    assert_int_equal(ps_can_send_batch(&can0, f, 2), 2);
    /* a disable where the log has joint 2's enable: differs in kind */
    ps_can_frame_t req = frame_of_hex(0x003, DISABLE);
    assert_int_equal(ps_can_send_batch(&can1, &req, 1), 1);
    ps_can_replay_stats_t st;
    ps_can_replay_get_stats(&fx->r, &st);
    assert_int_equal(st.n_matched, 3);
    assert_int_equal(st.n_differ, 1);
    assert_int_equal(st.n_cmd_compared, 2);
    /* 262 position steps of 25/65535 rad: 0.09995 rad */
    assert_float_equal(st.max_diff[PS_CAN_REPLAY_Q], 262.0f * 25.0f / 65535.0f, 1e-5f);
    assert_float_equal(st.max_diff_lsb[PS_CAN_REPLAY_Q], 262.0f, 0.01f);
    assert_true(st.max_diff[PS_CAN_REPLAY_KP] == 0.0f && st.max_diff[PS_CAN_REPLAY_TAU] == 0.0f);
}

static void test_send_batch_nothing_logged_near_now_unmatched(void **state)
{
    fixture_t *fx = *state;
    assert_int_equal(init_log(fx, LOG), 0);
    const ps_clock_t *clk = ps_can_replay_clock(&fx->r);
    const ps_can_port_t can0 = ps_can_replay_port(&fx->r, 0);
    /* tick 1: the log has joint 0's commands about now, none of joint 1's */
    assert_int_equal(ps_clock_sleep_until_ns(clk, T0_NS + PERIOD_NS), 0);
    ps_can_frame_t g = frame_of_hex(0x002, CMD_Q0);
    assert_int_equal(ps_can_send_batch(&can0, &g, 1), 1); /* accepted all the same */
    /* tick 5: joint 0's logged commands are more than a tick old */
    assert_int_equal(ps_clock_sleep_until_ns(clk, T0_NS + 5 * PERIOD_NS), 0);
    ps_can_frame_t f = frame_of_hex(0x001, CMD_Q0);
    assert_int_equal(ps_can_send_batch(&can0, &f, 1), 1);
    ps_can_replay_stats_t st;
    ps_can_replay_get_stats(&fx->r, &st);
    assert_int_equal(st.n_sent, 2);
    assert_int_equal(st.n_matched, 0);
    assert_int_equal(st.n_unmatched, 2);
}

/* ---- refusals --------------------------------------------------------- */

static void test_init_bad_line_names_file_line_and_column(void **state)
{
    fixture_t *fx = *state;
    assert_int_equal(init_log(fx, "(0000000001.000000) can0 001#" CMD_Q0 "\n"
                                  "(0000000001.000300) can0 101#01820C8008001E1E\n"
                                  "(0000000001.000400) can0 1G1#01\n"),
                     -PS_ERR_PROTOCOL);
    char want[160];
    /* "(0000000001.000400) can0 " is 25 characters: the identifier that
     * is not hex starts in column 26 */
    snprintf(want, sizeof(want), "%s:3:26: identifier", fx->path);
    if (strncmp(fx->err, want, strlen(want)) != 0)
        fail_msg("want \"%s...\", got \"%s\"", want, fx->err);
    /* measuring says the same */
    ps_can_replay_size_t size;
    assert_int_equal(ps_can_replay_measure(&fx->cfg, &size, fx->err, sizeof(fx->err)),
                     -PS_ERR_PROTOCOL);
    assert_int_equal(strncmp(fx->err, want, strlen(want)), 0);
}

static void test_init_interface_not_on_board_refused_with_line(void **state)
{
    fixture_t *fx = *state;
    assert_int_equal(init_log(fx, "(0000000001.000000) can0 001#" CMD_Q0 "\n"
                                  "(0000000001.000300) vcan9 101#01820C8008001E1E\n"),
                     -PS_ERR_CONFIG);
    char want[256];
    snprintf(want, sizeof(want),
             "%s:2: interface \"vcan9\" is not a bus of the board (its "
             "buses: can0, can1)",
             fx->path);
    assert_string_equal(fx->err, want);
}

static void test_init_line_too_long_refused_with_line(void **state)
{
    fixture_t *fx = *state;
    char text[PS_CANDUMP_LINE_MAX + 64];
    memset(text, 'A', sizeof(text));
    memcpy(text, "(0000000001.000000) can0 001#", 29);
    text[sizeof(text) - 2] = '\n';
    text[sizeof(text) - 1] = '\0';
    assert_int_equal(init_log(fx, text), -PS_ERR_PROTOCOL);
    char want[160];
    snprintf(want, sizeof(want), "%s:1: longer than", fx->path);
    assert_int_equal(strncmp(fx->err, want, strlen(want)), 0);
}

static void test_init_storage_too_small_enospc(void **state)
{
    fixture_t *fx = *state;
    write_log(fx, LOG);
    assert_int_equal(ps_can_replay_init(&fx->r, &fx->cfg, fx->entries, 8, fx->data,
                                        sizeof(fx->data), fx->err, sizeof(fx->err)),
                     -ENOSPC);
    assert_int_equal(ps_can_replay_init(&fx->r, &fx->cfg, fx->entries, 32, fx->data, 8 * 8, fx->err,
                                        sizeof(fx->err)),
                     -ENOSPC);
    assert_non_null(strstr(fx->err, "storage is full"));
}

static void test_init_empty_or_missing_log_refused(void **state)
{
    fixture_t *fx = *state;
    assert_int_equal(init_log(fx, ""), -PS_ERR_CONFIG);
    assert_non_null(strstr(fx->err, "holds no frames"));
    unlink(fx->path);
    assert_int_equal(ps_can_replay_init(&fx->r, &fx->cfg, fx->entries, 32, fx->data,
                                        sizeof(fx->data), fx->err, sizeof(fx->err)),
                     -ENOENT);
    assert_non_null(strstr(fx->err, "No such file"));
    fx->path[0] = '\0';
}

static void test_init_bad_cfg_einval(void **state)
{
    fixture_t *fx = *state;
    fx->cfg.period_ns = 0;
    assert_int_equal(ps_can_replay_init(&fx->r, &fx->cfg, fx->entries, 32, fx->data,
                                        sizeof(fx->data), fx->err, sizeof(fx->err)),
                     -EINVAL);
    fx->cfg.period_ns = PERIOD_NS;
    fx->cfg.n_buses = 0;
    ps_can_replay_size_t size;
    assert_int_equal(ps_can_replay_measure(&fx->cfg, &size, fx->err, sizeof(fx->err)), -EINVAL);
}

/* ---- the GPIO port without lines ------------------------------------- */

static void test_gpio_port_never_pressed_outputs_ignored(void **state)
{
    (void)state;
    ps_gpio_port_t g = ps_can_replay_gpio_port();
    bool is_pressed = true;
    assert_int_equal(ps_gpio_read_estop(&g, &is_pressed), 0);
    assert_false(is_pressed);
    assert_int_equal(ps_gpio_set_heartbeat(&g, true), 0);
    assert_int_equal(ps_gpio_set_led(&g, PS_GPIO_LED_ON), 0);
    ps_gpio_close(&g); /* no close op: nothing to release */
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_measure_hand_log_counts_lines_frames_and_bytes, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_init_hand_log_classifies_fed_expected_unknown, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_classify_reply_before_drive_and_imu_only_on_its_bus,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_recv_batch_frames_due_by_clock_in_file_order, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_init_first_frame_mid_tick_clock_starts_on_the_tick,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_init_log_near_time_zero_clock_starts_one_tick_in,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_send_batch_same_command_matches_with_no_difference,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_send_batch_other_q_difference_in_joint_units_and_steps,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_send_batch_nothing_logged_near_now_unmatched, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_init_bad_line_names_file_line_and_column, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_init_interface_not_on_board_refused_with_line, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_init_line_too_long_refused_with_line, setup, teardown),
        cmocka_unit_test_setup_teardown(test_init_storage_too_small_enospc, setup, teardown),
        cmocka_unit_test_setup_teardown(test_init_empty_or_missing_log_refused, setup, teardown),
        cmocka_unit_test_setup_teardown(test_init_bad_cfg_einval, setup, teardown),
        cmocka_unit_test(test_gpio_port_never_pressed_outputs_ignored),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
