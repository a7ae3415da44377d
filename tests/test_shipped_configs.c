/*
 * Every shipped board file with every shipped robot file: loads, passes the
 * cross-file checks and the bus-load plan under the board's budget; every
 * shipped scenario loads and fits the default robot. New files in boards/,
 * robots/ or scenarios/ are picked up by the glob, so none can ship broken.
 * Each real board states its controllers and camera, and where a controller
 * cannot hold what the default robot's plan makes it receive in one tick
 * (rpi4's MCP2515s), the figures are the ones docs/deploy.md gives.
 */
#include <glob.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include <cmocka.h>

#include "../drivers/ps_canbus.h"
#include "../rt/ps_app.h"
#include "../rt/ps_config.h"
#include "../rt/ps_config_sim.h"

static void load_or_fail(const char *what, int rc, const char *err)
{
    if (rc != 0)
        fail_msg("%s: %s", what, err);
}

static size_t glob_or_fail(const char *pattern, glob_t *g)
{
    assert_int_equal(glob(pattern, 0, NULL, g), 0);
    assert_true(g->gl_pathc > 0);
    return g->gl_pathc;
}

static void test_shipped_boards_and_robots_fit_the_bus_budget(void **state)
{
    (void)state;
    glob_t boards, robots;
    size_t nb = glob_or_fail("boards/*.yaml", &boards);
    size_t nr = glob_or_fail("robots/*.yaml", &robots);
    assert_true(nb >= 5);
    char err[PS_ERR_MSG_LEN];
    for (size_t r = 0; r < nr; r++) {
        ps_robot_cfg_t robot;
        load_or_fail(robots.gl_pathv[r],
                     ps_config_load_robot(robots.gl_pathv[r], &robot, err, sizeof(err)), err);
        for (size_t b = 0; b < nb; b++) {
            ps_board_cfg_t board;
            load_or_fail(boards.gl_pathv[b],
                         ps_config_load_board(boards.gl_pathv[b], &board, err, sizeof(err)), err);
            load_or_fail(boards.gl_pathv[b], ps_config_check_pair(&board, &robot, err, sizeof(err)),
                         err);
            ps_canbus_plan_t plan;
            load_or_fail(boards.gl_pathv[b],
                         ps_app_plan_buses(&board, &robot, &plan, err, sizeof(err)), err);
            for (uint32_t i = 0; i < plan.n_buses; i++)
                assert_true(plan.load_peak[i] <= board.bus_budget);
        }
    }
    globfree(&boards);
    globfree(&robots);
}

/* The default robot on each shipped board: which buses' controllers it
 * overruns (ps_canbus_rx_risk), with the figures. Only rpi4's bus 3 (the
 * IMU's two frames and an arm joint's reply each tick; an MCP2515 holds 2). */
static void test_shipped_boards_default_robot_rx_risk(void **state)
{
    (void)state;
    glob_t boards;
    size_t nb = glob_or_fail("boards/*.yaml", &boards);
    char err[PS_ERR_MSG_LEN], note[200];
    ps_robot_cfg_t robot;
    load_or_fail("robots/ps1.yaml",
                 ps_config_load_robot("robots/ps1.yaml", &robot, err, sizeof(err)), err);
    unsigned n_risks = 0;
    for (size_t b = 0; b < nb; b++) {
        ps_board_cfg_t board;
        load_or_fail(boards.gl_pathv[b],
                     ps_config_load_board(boards.gl_pathv[b], &board, err, sizeof(err)), err);
        ps_canbus_plan_t plan;
        load_or_fail(boards.gl_pathv[b], ps_app_plan_buses(&board, &robot, &plan, err, sizeof(err)),
                     err);
        for (uint32_t i = 0; i < board.n_buses; i++) {
            if (ps_canbus_rx_risk(&board.buses[i], &plan, i, note, sizeof(note)) == 0)
                continue;
            n_risks++;
            assert_string_equal(board.name, "rpi4");
            assert_int_equal(i, 3);
            assert_string_equal(note, "can3 (mcp2515): up to 3 frames arrive in one tick, the "
                                      "controller holds 2: the host must read each within 111 us "
                                      "or lose the next");
        }
        if (board.kind == PS_BOARD_LINUX) { /* a real board says what it has */
            for (uint32_t i = 0; i < board.n_buses; i++)
                assert_int_not_equal(board.buses[i].controller, PS_CANBUS_CTRL_ANY);
            assert_true(board.has_camera);
            assert_true(board.rt.priority > 0 && board.rt.loop_cpu > 0);
        }
    }
    assert_int_equal(n_risks, 1);
    globfree(&boards);
}

static void test_shipped_scenarios_fit_the_default_robot(void **state)
{
    (void)state;
    glob_t scenarios;
    size_t ns = glob_or_fail("scenarios/*.yaml", &scenarios);
    char err[PS_ERR_MSG_LEN];
    ps_board_cfg_t board;
    ps_robot_cfg_t robot;
    load_or_fail("boards/sim.yaml",
                 ps_config_load_board("boards/sim.yaml", &board, err, sizeof(err)), err);
    load_or_fail("robots/ps1.yaml",
                 ps_config_load_robot("robots/ps1.yaml", &robot, err, sizeof(err)), err);
    for (size_t i = 0; i < ns; i++) {
        ps_scenario_cfg_t sc;
        load_or_fail(scenarios.gl_pathv[i],
                     ps_config_load_scenario(scenarios.gl_pathv[i], &sc, err, sizeof(err)), err);
        load_or_fail(scenarios.gl_pathv[i], ps_config_check_pair(&board, &robot, err, sizeof(err)),
                     err);
        load_or_fail(scenarios.gl_pathv[i], ps_config_check_scenario(&robot, &sc, err, sizeof(err)),
                     err);
    }
    globfree(&scenarios);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_shipped_boards_and_robots_fit_the_bus_budget),
        cmocka_unit_test(test_shipped_boards_default_robot_rx_risk),
        cmocka_unit_test(test_shipped_scenarios_fit_the_default_robot),
    };
    return cmocka_run_group_tests_name("shipped_configs", tests, NULL, NULL);
}
