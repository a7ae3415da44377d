/*
 * `pushstep doctor`'s live queries (rt/ps_doctor with PS_DOCTOR_LIVE_OPS:
 * rtnetlink through drivers/ps_can_socket, line info through
 * drivers/ps_gpio_gpiod's probe), run inside the qemu VM of `make test-hw`
 * on the VM's board (tests/data/boards/vm-vxcan.yaml: vxcan pairs and
 * gpio-mockup's gpiochip0). The fake-tree tests are tests/test_doctor.c.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../drivers/ps_gpio_gpiod.h"
#include "../../rt/ps_app.h"
#include "../../rt/ps_doctor.h"
#include "../../rt/ps_err.h"

static ps_board_cfg_t g_board;
static ps_robot_cfg_t g_robot;
static ps_canbus_plan_t g_plan;
static ps_doctor_report_t g_report;
static char g_err[PS_ERR_MSG_LEN];

static int setup(void **state)
{
    (void)state;
    if (ps_config_load_board("tests/data/boards/vm-vxcan.yaml", &g_board, g_err,
                             sizeof(g_err)) != 0 ||
        ps_config_load_robot("tests/data/robots/ps1-mixed-vm.yaml", &g_robot, g_err,
                             sizeof(g_err)) != 0 ||
        ps_app_plan_buses(&g_board, &g_robot, &g_plan, g_err, sizeof(g_err)) != 0) {
        print_error("%s\n", g_err);
        return -1;
    }
    return 0;
}

static const ps_doctor_item_t *item(const char *what)
{
    for (uint32_t i = 0; i < g_report.n_items; i++)
        if (strcmp(g_report.items[i].what, what) == 0)
            return &g_report.items[i];
    fail_msg("no item \"%s\"", what);
    return NULL;
}

static void run_live(void)
{
    ps_doctor_cfg_t cfg = {.root = "/", .board = &g_board, .plan = &g_plan,
                           .ops = PS_DOCTOR_LIVE_OPS};
    for (uint32_t b = 0; b < g_board.n_buses; b++)
        cfg.min_txqueuelen[b] = ps_app_min_txqueuelen(&g_robot, b);
    (void)ps_doctor_run(&cfg, &g_report);
    ps_doctor_print(&g_report, stdout);
}

/* Every bus and line of the VM's board is there and free. */
static void test_hw_doctor_vm_board_can_and_gpio_fine(void **state)
{
    (void)state;
    run_live();
    static const char *const BUSES[] = {"can vxcan0", "can vxcan2", "can vxcan4", "can vxcan6"};
    for (size_t i = 0; i < 4; i++) {
        const ps_doctor_item_t *it = item(BUSES[i]);
        assert_int_equal(it->level, PS_DOCTOR_OK);
        assert_non_null(strstr(it->found, "up, vxcan"));
        assert_non_null(strstr(it->found, "virtual (vxcan), bitrate not checked"));
    }
    static const char *const LINES[] = {"gpio e-stop", "gpio heartbeat", "gpio LED"};
    for (size_t i = 0; i < 3; i++) {
        const ps_doctor_item_t *it = item(LINES[i]);
        assert_int_equal(it->level, PS_DOCTOR_OK);
        char want[64];
        (void)snprintf(want, sizeof(want), "line %zu \"gpio-mockup-A-%zu\", free", i, i);
        assert_non_null(strstr(it->found, want));
    }
}

/* With the port open (a running pushstep), the doctor says whose the lines
 * are, and the probe itself requested nothing. */
static void test_hw_doctor_lines_in_use_named(void **state)
{
    (void)state;
    static ps_gpio_gpiod_t port;
    assert_int_equal(ps_gpio_gpiod_open(&port, &g_board.gpio, g_err, sizeof(g_err)), 0);
    run_live();
    const ps_doctor_item_t *it = item("gpio heartbeat");
    assert_int_equal(it->level, PS_DOCTOR_FAIL);
    assert_non_null(strstr(it->found, "in use by \"pushstep-heartbeat\""));
    assert_non_null(strstr(it->fix, "pushstep already runs"));
    ps_gpio_gpiod_close(&port);
    run_live();
    assert_int_equal(item("gpio heartbeat")->level, PS_DOCTOR_OK);
}

/* A downed interface: the start-up check's `ip link` command. */
static void test_hw_doctor_down_interface_fix_named(void **state)
{
    (void)state;
    assert_int_equal(system("ip link set vxcan6 down"), 0);
    run_live();
    const int rc = system("ip link set vxcan6 up");
    const ps_doctor_item_t *it = item("can vxcan6");
    assert_int_equal(it->level, PS_DOCTOR_FAIL);
    assert_non_null(strstr(it->found, "down"));
    assert_non_null(strstr(it->fix, "`sudo ip link set vxcan6 up`"));
    assert_int_equal(rc, 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_hw_doctor_vm_board_can_and_gpio_fine),
        cmocka_unit_test(test_hw_doctor_lines_in_use_named),
        cmocka_unit_test(test_hw_doctor_down_interface_fix_named),
    };
    return cmocka_run_group_tests_name("hw_doctor", tests, setup, NULL);
}
