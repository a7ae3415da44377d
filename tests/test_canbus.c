/* Tests of drivers/ps_canbus: frame timing and the bus-load planner. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <stdio.h>
#include <string.h>

#include "../drivers/ps_canbus.h"
#include "../rt/ps_err.h"

/* ---- frame bits -------------------------------------------------------- */

static void test_frame_bits_every_len_matches_formula(void **state)
{
    (void)state;
    for (unsigned n = 0; n <= 8; n++) {
        /* 11-bit: 47 + 8n, 34 + 8n stuffable; 29-bit: 67 + 8n, 54 + 8n. */
        const unsigned sff_min = 47 + 8 * n, sff_stuff = 34 + 8 * n;
        const unsigned eff_min = 67 + 8 * n, eff_stuff = 54 + 8 * n;
        assert_int_equal(ps_canbus_frame_bits_min((uint8_t)n, false), sff_min);
        assert_int_equal(ps_canbus_frame_bits_max((uint8_t)n, false),
                         sff_min + (sff_stuff - 1) / 4);
        assert_int_equal(ps_canbus_frame_bits_min((uint8_t)n, true), eff_min);
        assert_int_equal(ps_canbus_frame_bits_max((uint8_t)n, true), eff_min + (eff_stuff - 1) / 4);
    }
}

static void test_frame_bits_known_anchors(void **state)
{
    (void)state;
    assert_int_equal(ps_canbus_frame_bits_min(8, false), 111);
    assert_int_equal(ps_canbus_frame_bits_max(8, false), 135);
    assert_int_equal(ps_canbus_frame_bits_min(8, true), 131);
    assert_int_equal(ps_canbus_frame_bits_max(8, true), 160);
    assert_int_equal(ps_canbus_frame_bits_min(0, false), 47);
    assert_int_equal(ps_canbus_frame_bits_max(0, false), 55); /* 47 + 33/4 */
    assert_int_equal(ps_canbus_frame_bits_max(0, true), 80);  /* 67 + 53/4 */
}

static void test_frame_bits_len_above_8_counts_as_8(void **state)
{
    (void)state;
    assert_int_equal(ps_canbus_frame_bits_max(15, false), 135);
    assert_int_equal(ps_canbus_frame_bits_min(9, true), 131);
}

static void test_bits_to_ns_common_rates(void **state)
{
    (void)state;
    assert_int_equal(ps_canbus_bits_to_ns(135, 1000000), 135000);
    assert_int_equal(ps_canbus_bits_to_ns(135, 500000), 270000);
    assert_int_equal(ps_canbus_bits_to_ns(111, 500000), 222000);
    assert_int_equal(ps_canbus_bits_to_ns(0, 1000000), 0);
}

static void test_bits_to_ns_fraction_rounds_up(void **state)
{
    (void)state;
    /* 1 bit at 300 kbit/s = 3333.33 ns -> 3334; 3 bits = 10000 exactly. */
    assert_int_equal(ps_canbus_bits_to_ns(1, 300000), 3334);
    assert_int_equal(ps_canbus_bits_to_ns(3, 300000), 10000);
    /* 1 bit at 3 bit/s = 333333333.3 ns -> 333333334 */
    assert_int_equal(ps_canbus_bits_to_ns(1, 3), 333333334);
    assert_int_equal(ps_canbus_bits_to_ns(1, 0), 0);
}

/* ---- CAN FD timing (values computed by hand from ISO 11898-1:2015) ------- */

static void test_fd_frame_bits_hand_computed(void **state)
{
    (void)state;
    unsigned nom = 0, dat = 0;
    /* 11-bit, 64 bytes, BRS: arbitration 17 + its 5 stuff bits + end 13 = 35;
     * data phase ESI+DLC+512 = 517, 128 more dynamic stuff bits
     * ((17 + 517 - 1) / 4 = 133, minus the arbitration's 5), stuff count 4 +
     * CRC 21 + 7 fixed stuff bits = 32: 677. */
    ps_canbus_fd_frame_bits_max(64, false, true, &nom, &dat);
    assert_int_equal(nom, 35);
    assert_int_equal(dat, 677);
    /* 8 bytes: 69 + 16 + (4 + 17 + 6) = 112 */
    ps_canbus_fd_frame_bits_max(8, false, true, &nom, &dat);
    assert_int_equal(nom, 35);
    assert_int_equal(dat, 112);
    /* without BRS everything runs at the nominal rate */
    ps_canbus_fd_frame_bits_max(8, false, false, &nom, &dat);
    assert_int_equal(nom, 147);
    assert_int_equal(dat, 0);
    /* 29-bit: arbitration 36 + 9 stuff + 13 = 58; data 69 + 17 + 27 = 113 */
    ps_canbus_fd_frame_bits_max(8, true, true, &nom, &dat);
    assert_int_equal(nom, 58);
    assert_int_equal(dat, 113);
    /* 9 bytes is no FD length: counted as the next one, 12 */
    unsigned nom12 = 0, dat12 = 0;
    ps_canbus_fd_frame_bits_max(9, false, true, &nom, &dat);
    ps_canbus_fd_frame_bits_max(12, false, true, &nom12, &dat12);
    assert_int_equal(nom, nom12);
    assert_int_equal(dat, dat12);
}

static void test_fd_frame_ns_data_phase_at_data_bitrate(void **state)
{
    (void)state;
    const ps_canbus_bus_cfg_t fd = {.bitrate = 1000000, .is_fd = true, .data_bitrate = 5000000};
    const ps_canbus_frame_shape_t f64 = {.len = 64, .is_fd = true, .is_brs = true};
    /* 35 bits at 1 Mbit/s + 677 bits at 5 Mbit/s (135.4 us, rounded up) */
    assert_int_equal(ps_canbus_frame_ns_max(&f64, &fd), 35000 + 135400);
    /* in nominal bit times: 35 + ceil(677 / 5) */
    assert_int_equal(ps_canbus_frame_nominal_bits_max(&f64, &fd), 35 + 136);
    /* a classical frame on the same bus: 135 bits at the nominal rate */
    const ps_canbus_frame_shape_t c8 = {.len = 8};
    assert_int_equal(ps_canbus_frame_ns_max(&c8, &fd), 135000);
    assert_int_equal(ps_canbus_frame_nominal_bits_max(&c8, &fd), 135);
}

/* ---- planner ------------------------------------------------------------ */

/* A board and a robot in the shape the planner's caller (rt/ps_app.c) turns
 * into buses and sources: each joint an MIT-sized source (command and reply,
 * two classical 8-byte 11-bit frames), the IMU two 8-byte frames. */
typedef struct {
    char name[PS_NAME_LEN];
    uint32_t bus_idx, rate_div;
} test_joint_t;

typedef struct {
    struct {
        char name[PS_NAME_LEN];
        uint32_t n_buses;
        ps_canbus_bus_cfg_t buses[PS_MAX_BUSES];
        float bus_budget;
    } board;
    struct {
        char name[PS_NAME_LEN];
        struct {
            uint32_t servo_hz;
        } control;
        struct {
            uint32_t bus_idx, base_id, rate_div;
        } imu;
        uint32_t n_joints;
        test_joint_t joints[PS_MAX_JOINTS];
    } robot;
    char err[PS_ERR_MSG_LEN];
} fixture_t;

static int plan(fixture_t *f, ps_canbus_plan_t *out, char *err, size_t err_len)
{
    static char names[PS_CANBUS_MAX_SOURCES][PS_NAME_LEN + 16]; /* outlive the call's messages */
    ps_canbus_source_t src[PS_CANBUS_MAX_SOURCES];
    memset(src, 0, sizeof src);
    const ps_canbus_frame_shape_t classic8 = {.len = 8};
    const ps_canbus_frame_shape_t reply8 = {.len = 8, .is_rx = true};
    uint32_t n = 0;
    for (; n < f->robot.n_joints; n++) {
        snprintf(names[n], sizeof names[n], "joint %u (%s)", n, f->robot.joints[n].name);
        src[n] = (ps_canbus_source_t){.bus_idx = f->robot.joints[n].bus_idx,
                                      .rate_div = f->robot.joints[n].rate_div,
                                      .n_frames = 2,
                                      .frames = {classic8, reply8},
                                      .name = names[n]};
    }
    src[n++] = (ps_canbus_source_t){.bus_idx = f->robot.imu.bus_idx,
                                    .rate_div = f->robot.imu.rate_div,
                                    .n_frames = 2,
                                    .frames = {reply8, reply8},
                                    .name = "imu"};
    const ps_canbus_cfg_t cfg = {.n_buses = f->board.n_buses,
                                 .buses = f->board.buses,
                                 .bus_budget = f->board.bus_budget,
                                 .servo_hz = f->robot.control.servo_hz};
    return ps_canbus_plan(&cfg, src, n, out, err, err_len);
}

/* Two 1 Mbit/s buses, 1 kHz loop: 1000 bits per tick per bus. No joints; the
 * IMU every tick on bus 0. Tests add joints. */
static int setup(void **state)
{
    fixture_t *f = test_calloc(1, sizeof *f);
    if (f == NULL)
        return -1;
    snprintf(f->board.name, sizeof f->board.name, "test");
    f->board.n_buses = 2;
    for (unsigned i = 0; i < 2; i++) {
        snprintf(f->board.buses[i].ifname, sizeof f->board.buses[i].ifname, "can%u", i);
        f->board.buses[i].bitrate = 1000000;
    }
    f->board.bus_budget = 0.8f;
    snprintf(f->robot.name, sizeof f->robot.name, "bot");
    f->robot.control.servo_hz = 1000;
    f->robot.imu.bus_idx = 0;
    f->robot.imu.base_id = 0x100;
    f->robot.imu.rate_div = 1;
    *state = f;
    return 0;
}

static int teardown(void **state)
{
    test_free(*state);
    return 0;
}

static void add_joint(fixture_t *f, const char *name, uint32_t bus_idx, uint32_t rate_div)
{
    test_joint_t *j = &f->robot.joints[f->robot.n_joints++];
    snprintf(j->name, sizeof j->name, "%s", name);
    j->bus_idx = bus_idx;
    j->rate_div = rate_div;
}

static void test_plan_two_joints_div2_spread_peak_half(void **state)
{
    fixture_t *f = *state;
    add_joint(f, "a", 1, 2);
    add_joint(f, "b", 1, 2);
    ps_canbus_plan_t p;
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), 0);
    assert_string_equal(f->err, "");
    assert_int_equal(p.n_buses, 2);
    assert_int_equal(p.n_sources[1], 2);
    assert_int_not_equal(p.phase[0], p.phase[1]);
    /* Both on one tick would be 540 bits; spread, each tick carries one joint. */
    assert_int_equal(p.tick_bits_max[1], 270);
    assert_int_equal(p.tick_capacity_bits[1], 1000);
    assert_float_equal(p.load_peak[1], 0.27, 1e-12);
    /* 2 joints x 270 bits x 500 Hz / 1e6 bit/s */
    assert_float_equal(p.load_avg[1], 0.27, 1e-12);
    /* Bus 0 holds only the IMU: 270 bits every tick. */
    assert_int_equal(p.n_sources[0], 1);
    assert_int_equal(p.tick_bits_max[0], 270);
    assert_float_equal(p.load_avg[0], 0.27, 1e-12);
}

/* Received frames per tick, with the phases the planner chose: the IMU's two
 * every tick and one of the two div-2 joints' replies. */
static void test_plan_rx_frames_counted_per_tick(void **state)
{
    fixture_t *f = *state;
    add_joint(f, "a", 0, 2);
    add_joint(f, "b", 0, 2);
    ps_canbus_plan_t p;
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), 0);
    assert_int_equal(p.rx_frames_max[0], 3);
    assert_int_equal(p.rx_frame_ns_min[0], 111000); /* 8 bytes, no stuff bits, 1 Mbit/s */
    assert_int_equal(p.rx_frames_max[1], 0);        /* nothing on bus 1 */
    assert_int_equal(p.rx_frame_ns_min[1], 0);
    /* a third div-2 joint shares a tick with one of them: 4 on that tick */
    f->board.bus_budget = 1.0f;
    add_joint(f, "c", 0, 2);
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), 0);
    assert_int_equal(p.rx_frames_max[0], 4);
}

/* A controller that holds fewer frames than a tick brings is named with both
 * figures; one with a FIFO, or a tick within its buffers, is not. */
static void test_rx_risk_only_when_buffers_overflow(void **state)
{
    fixture_t *f = *state;
    ps_canbus_plan_t p;
    char note[200];
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), 0); /* the IMU alone: 2 frames */
    f->board.buses[0].controller = PS_CANBUS_CTRL_MCP2515;
    assert_int_equal(ps_canbus_rx_risk(&f->board.buses[0], &p, 0, note, sizeof note), 0);
    add_joint(f, "a", 0, 2);
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), 0);
    assert_int_equal(ps_canbus_rx_risk(&f->board.buses[0], &p, 0, note, sizeof note), 1);
    assert_string_equal(note, "can0 (mcp2515): up to 3 frames arrive in one tick, the controller "
                              "holds 2: the host must read each within 111 us or lose the next");
    for (int c = PS_CANBUS_CTRL_ANY; c < PS_CANBUS_CTRL_COUNT; c++) {
        f->board.buses[0].controller = (ps_canbus_ctrl_t)c;
        const int want = c == PS_CANBUS_CTRL_MCP2515;
        assert_int_equal(ps_canbus_rx_risk(&f->board.buses[0], &p, 0, note, sizeof note), want);
    }
    assert_int_equal(ps_canbus_rx_risk(&f->board.buses[0], &p, PS_MAX_BUSES, note, sizeof note), 0);
}

/* Every controller has a name; the SoC and SPI ones a kernel driver. */
static void test_ctrl_info_table_complete(void **state)
{
    (void)state;
    for (int c = 0; c < PS_CANBUS_CTRL_COUNT; c++)
        assert_non_null(ps_canbus_ctrl_info((ps_canbus_ctrl_t)c)->name);
    assert_string_equal(ps_canbus_ctrl_info(PS_CANBUS_CTRL_MCP2515)->driver, "mcp251x");
    assert_false(ps_canbus_ctrl_info(PS_CANBUS_CTRL_MCP2515)->is_fd_capable);
    assert_true(ps_canbus_ctrl_info(PS_CANBUS_CTRL_MTTCAN)->is_fd_capable);
    assert_null(ps_canbus_ctrl_info(PS_CANBUS_CTRL_VIRTUAL)->driver);
    assert_ptr_equal(ps_canbus_ctrl_info(PS_CANBUS_CTRL_COUNT),
                     ps_canbus_ctrl_info(PS_CANBUS_CTRL_ANY));
}

static void test_plan_phases_follow_is_due_convention(void **state)
{
    fixture_t *f = *state;
    /* 4 joints at div 4 plus the IMU every tick on bus 0: best is one joint
     * per tick, peak 270 + 270. Check by replaying the plan with is_due. */
    for (unsigned k = 0; k < 4; k++)
        add_joint(f, "j", 0, 4);
    ps_canbus_plan_t p;
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), 0);
    assert_int_equal(p.tick_bits_max[0], 540);
    for (uint64_t t = 0; t < 8; t++) {
        unsigned n_due = 0;
        for (unsigned k = 0; k < 4; k++)
            n_due += ps_canbus_is_due(t, 4, p.phase[k]);
        assert_int_equal(n_due, 1);
        assert_true(ps_canbus_is_due(t, 1, p.phase[f->robot.n_joints]));
    }
    assert_float_equal(p.load_avg[0], (4 * 270 * 250 + 270 * 1000) / 1e6, 1e-12);
}

static void test_plan_mixed_divisors_greedy_optimal(void **state)
{
    fixture_t *f = *state;
    /* Bus 1: one joint every tick, two every other tick. Alternating the
     * slow pair gives 270 + 270 = 540 on every tick; putting both on the same
     * phase would give 810. */
    add_joint(f, "fast", 1, 1);
    add_joint(f, "m1", 1, 2);
    add_joint(f, "m2", 1, 2);
    ps_canbus_plan_t p;
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), 0);
    assert_int_equal(p.tick_bits_max[1], 540);
    assert_int_not_equal(p.phase[1], p.phase[2]);
}

static void test_plan_over_budget_refused_naming_bus(void **state)
{
    fixture_t *f = *state;
    /* Three joints every tick on can1: 810 of 1000 bits = 81% > 80%. */
    add_joint(f, "hip", 1, 1);
    add_joint(f, "knee", 1, 1);
    add_joint(f, "ankle", 1, 1);
    ps_canbus_plan_t p;
    memset(&p, 0, sizeof p);
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), -PS_ERR_BUS_BUDGET);
    assert_non_null(strstr(f->err, "bus 1 (can1)"));
    assert_non_null(strstr(f->err, "81.0%"));
    assert_non_null(strstr(f->err, "810 of 1000 bits at 1000 Hz"));
    assert_non_null(strstr(f->err, "budget 80%"));
    /* The plan is still written so the caller can report every bus. */
    assert_int_equal(p.tick_bits_max[1], 810);
    assert_float_equal(p.load_peak[1], 0.81, 1e-12);
    assert_int_equal(p.tick_bits_max[0], 270);

    /* The same joints at div 2 fit: phases put at most 2 on a tick. */
    for (unsigned j = 0; j < 3; j++)
        f->robot.joints[j].rate_div = 2;
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), 0);
    assert_int_equal(p.tick_bits_max[1], 540);
}

static void test_plan_slow_bus_over_budget_refused(void **state)
{
    fixture_t *f = *state;
    /* 500 kbit/s at 1 kHz: 500 bits per tick; the IMU alone is 270 = 54%,
     * one joint more (every other tick) makes 540 = 108%. */
    f->board.buses[0].bitrate = 500000;
    ps_canbus_plan_t p;
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), 0);
    assert_float_equal(p.load_peak[0], 0.54, 1e-12);
    add_joint(f, "x", 0, 2);
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), -PS_ERR_BUS_BUDGET);
    assert_non_null(strstr(f->err, "bus 0 (can0)"));
    assert_non_null(strstr(f->err, "108.0%"));
    assert_non_null(strstr(f->err, "540 of 500 bits"));
}

static void test_plan_fd_source_on_classical_bus_config_error(void **state)
{
    fixture_t *f = *state;
    ps_canbus_source_t src = {.bus_idx = 1,
                              .rate_div = 1,
                              .n_frames = 1,
                              .frames = {{.len = 64, .is_fd = true, .is_brs = true}},
                              .name = "joint fd"};
    const ps_canbus_cfg_t cfg = {
        .n_buses = 2, .buses = f->board.buses, .bus_budget = 0.8f, .servo_hz = 1000};
    ps_canbus_plan_t p;
    assert_int_equal(ps_canbus_plan(&cfg, &src, 1, &p, f->err, sizeof f->err), -PS_ERR_CONFIG);
    assert_non_null(strstr(f->err, "joint fd"));
    assert_non_null(strstr(f->err, "classical"));
    /* the same bus made FD at 5 Mbit/s takes it: 171 of 1000 bits per tick */
    f->board.buses[1].is_fd = true;
    f->board.buses[1].data_bitrate = 5000000;
    assert_int_equal(ps_canbus_plan(&cfg, &src, 1, &p, f->err, sizeof f->err), 0);
    assert_int_equal(p.tick_bits_max[1], 171);
    /* an FD bus whose data rate is below its nominal rate is refused */
    f->board.buses[1].data_bitrate = 500000;
    assert_int_equal(ps_canbus_plan(&cfg, &src, 1, &p, f->err, sizeof f->err), -PS_ERR_CONFIG);
    assert_non_null(strstr(f->err, "data_bitrate"));
}

static void test_plan_joint_bad_bus_config_error(void **state)
{
    fixture_t *f = *state;
    add_joint(f, "l_knee", 2, 1);
    ps_canbus_plan_t p;
    memset(&p, 0x5A, sizeof p);
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), -PS_ERR_CONFIG);
    assert_non_null(strstr(f->err, "joint 0 (l_knee)"));
    assert_non_null(strstr(f->err, "bus 2 but"));
    assert_int_equal(p.n_buses, 0x5A5A5A5A); /* untouched */
}

static void test_plan_imu_bad_bus_config_error(void **state)
{
    fixture_t *f = *state;
    f->robot.imu.bus_idx = 5;
    ps_canbus_plan_t p;
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), -PS_ERR_CONFIG);
    assert_non_null(strstr(f->err, "imu"));
    assert_non_null(strstr(f->err, "bus 5 but"));
}

static void test_plan_bad_rate_div_config_error(void **state)
{
    fixture_t *f = *state;
    ps_canbus_plan_t p;
    add_joint(f, "zero", 1, 0);
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), -PS_ERR_CONFIG);
    assert_non_null(strstr(f->err, "rate_div 0"));
    f->robot.joints[0].rate_div = 65;
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), -PS_ERR_CONFIG);
    f->robot.joints[0].rate_div = 1;
    f->robot.imu.rate_div = 0;
    assert_int_equal(plan(f, &p, NULL, 0), -PS_ERR_CONFIG);
}

static void test_plan_hyperperiod_too_long_config_error(void **state)
{
    fixture_t *f = *state;
    ps_canbus_plan_t p;
    /* lcm(3, 5) = 15 is accepted; lcm(7, 11) = 77 > 64 is not. */
    add_joint(f, "a", 1, 3);
    add_joint(f, "b", 1, 5);
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), 0);
    assert_int_equal(p.tick_bits_max[1], 540); /* ticks where both are due exist */
    f->robot.joints[0].rate_div = 7;
    f->robot.joints[1].rate_div = 11;
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), -PS_ERR_CONFIG);
    assert_non_null(strstr(f->err, "bus 1 (can1)"));
}

static void test_plan_bad_board_or_control_config_error(void **state)
{
    fixture_t *f = *state;
    ps_canbus_plan_t p;
    f->robot.control.servo_hz = 0;
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), -PS_ERR_CONFIG);
    f->robot.control.servo_hz = 1000;
    f->board.bus_budget = 0.0f;
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), -PS_ERR_CONFIG);
    f->board.bus_budget = 1.5f;
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), -PS_ERR_CONFIG);
    f->board.bus_budget = 0.8f;
    f->board.n_buses = 0;
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), -PS_ERR_CONFIG);
    f->board.n_buses = PS_MAX_BUSES + 1;
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), -PS_ERR_CONFIG);
    f->board.n_buses = 2;
    f->board.buses[1].bitrate = 999; /* < 1 bit per tick at 1 kHz */
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), -PS_ERR_CONFIG);
    assert_non_null(strstr(f->err, "bus 1 (can1)"));
    f->board.buses[1].bitrate = 1000000;
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), 0);
}

static void test_plan_humanoid_12_joints_4_buses_fits(void **state)
{
    fixture_t *f = *state;
    /* The example of docs/can-protocols.md: 12 joints on 4 buses at div 2,
     * the IMU at div 2 on bus 0. Every bus: 4 sources at div 2 -> 2 per tick. */
    f->board.n_buses = 4;
    for (unsigned i = 2; i < 4; i++) {
        snprintf(f->board.buses[i].ifname, sizeof f->board.buses[i].ifname, "can%u", i);
        f->board.buses[i].bitrate = 1000000;
    }
    f->robot.imu.rate_div = 2;
    for (unsigned j = 0; j < 12; j++)
        add_joint(f, "j", j / 3, 2);
    ps_canbus_plan_t p;
    assert_int_equal(plan(f, &p, f->err, sizeof f->err), 0);
    assert_int_equal(p.tick_bits_max[0], 540);
    assert_float_equal(p.load_avg[0], 4 * 270 * 500 / 1e6, 1e-12);
    for (unsigned b = 1; b < 4; b++) {
        assert_int_equal(p.tick_bits_max[b], 540);
        assert_float_equal(p.load_avg[b], 3 * 270 * 500 / 1e6, 1e-12);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_frame_bits_every_len_matches_formula),
        cmocka_unit_test(test_frame_bits_known_anchors),
        cmocka_unit_test(test_frame_bits_len_above_8_counts_as_8),
        cmocka_unit_test(test_bits_to_ns_common_rates),
        cmocka_unit_test(test_bits_to_ns_fraction_rounds_up),
        cmocka_unit_test(test_fd_frame_bits_hand_computed),
        cmocka_unit_test(test_fd_frame_ns_data_phase_at_data_bitrate),
        cmocka_unit_test_setup_teardown(test_plan_two_joints_div2_spread_peak_half, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_plan_phases_follow_is_due_convention, setup, teardown),
        cmocka_unit_test_setup_teardown(test_plan_rx_frames_counted_per_tick, setup, teardown),
        cmocka_unit_test_setup_teardown(test_rx_risk_only_when_buffers_overflow, setup, teardown),
        cmocka_unit_test(test_ctrl_info_table_complete),
        cmocka_unit_test_setup_teardown(test_plan_mixed_divisors_greedy_optimal, setup, teardown),
        cmocka_unit_test_setup_teardown(test_plan_over_budget_refused_naming_bus, setup, teardown),
        cmocka_unit_test_setup_teardown(test_plan_slow_bus_over_budget_refused, setup, teardown),
        cmocka_unit_test_setup_teardown(test_plan_joint_bad_bus_config_error, setup, teardown),
        cmocka_unit_test_setup_teardown(test_plan_fd_source_on_classical_bus_config_error, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_plan_imu_bad_bus_config_error, setup, teardown),
        cmocka_unit_test_setup_teardown(test_plan_bad_rate_div_config_error, setup, teardown),
        cmocka_unit_test_setup_teardown(test_plan_hyperperiod_too_long_config_error, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_plan_bad_board_or_control_config_error, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_plan_humanoid_12_joints_4_buses_fits, setup, teardown),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
