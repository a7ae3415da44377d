/*
 * Tests of rt/ps_doctor (`pushstep doctor`) against fake /proc, /sys and
 * /dev trees (tests/data/doctor/): rt-target is a Raspberry Pi 5 set up as
 * docs/deploy.md says, plain a fresh Debian 12 machine nothing was done to.
 * rtnetlink's and the GPIO chip's answers come from fakes here; the live
 * ones are checked in the VM (tests/hw/test_hw_gpio.c, test_hw_doctor.c).
 * Run from the repository root; the command-line test runs $PUSHSTEP_BIN
 * (default build/pushstep).
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>

#include "../rt/ps_app.h"
#include "../rt/ps_doctor.h"
#include "../rt/ps_err.h"

#define RT_TARGET "tests/data/doctor/rt-target"
#define PLAIN     "tests/data/doctor/plain"

/* What the fakes answer, per interface name and for the chip. */
typedef struct {
    ps_can_socket_iface_t ifaces[4];
    const char *names[4];
    int gpio_rc;
    ps_gpio_gpiod_probe_t gpio;
    unsigned n_can_queries, n_gpio_probes;
} fakes_t;

typedef struct {
    ps_board_cfg_t board;
    ps_robot_cfg_t robot;
    ps_canbus_plan_t plan;
    ps_doctor_cfg_t cfg;
    ps_doctor_report_t report;
    fakes_t fakes;
    char err[PS_ERR_MSG_LEN];
} fx_t;

static int fake_query(void *ctx, const char *ifname, ps_can_socket_iface_t *out, char *err,
                      size_t err_len)
{
    fakes_t *f = ctx;
    f->n_can_queries++;
    memset(out, 0, sizeof(*out));
    out->can_state = -1;
    for (int i = 0; i < 4; i++) {
        if (f->names[i] != NULL && strcmp(f->names[i], ifname) == 0) {
            *out = f->ifaces[i];
            return 0;
        }
    }
    (void)err;
    (void)err_len;
    return 0; /* exists false: the kernel knows no such name */
}

static int fake_probe(void *ctx, const ps_gpio_cfg_t *cfg, ps_gpio_gpiod_probe_t *out, char *err,
                      size_t err_len)
{
    fakes_t *f = ctx;
    f->n_gpio_probes++;
    if (f->gpio_rc < 0) {
        (void)snprintf(err, err_len, "gpio chip \"%s\": cannot open: %s", cfg->chip,
                       strerror(-f->gpio_rc));
        return f->gpio_rc;
    }
    *out = f->gpio;
    return 0;
}

/* A real controller as the board wants it: up, its bit rates, restart-ms. */
static ps_can_socket_iface_t good_iface(const ps_canbus_bus_cfg_t *bus)
{
    return (ps_can_socket_iface_t){.exists = true,
                                   .is_can = true,
                                   .is_up = true,
                                   .kind = "can",
                                   .mtu = bus->is_fd ? 72u : 16u,
                                   .txqueuelen = 128,
                                   .has_bittiming = true,
                                   .bitrate = bus->bitrate,
                                   .is_fd_mode = bus->is_fd,
                                   .data_bitrate = bus->is_fd ? bus->data_bitrate : 0u,
                                   .restart_ms = 100,
                                   .can_state = 0};
}

static void good_gpio(ps_gpio_gpiod_probe_t *p)
{
    memset(p, 0, sizeof(*p));
    snprintf(p->chip_name, sizeof(p->chip_name), "gpiochip0");
    snprintf(p->chip_label, sizeof(p->chip_label), "pinctrl-rp1");
    p->n_lines = 54;
    static const char *const ROLES[] = {"e-stop", "heartbeat", "LED"};
    static const char *const NAMES[] = {"GPIO5", "GPIO6", "GPIO27"};
    static const uint32_t OFFSETS[] = {5, 6, 27};
    for (int i = 0; i < 3; i++) {
        snprintf(p->lines[i].role, sizeof(p->lines[i].role), "%s", ROLES[i]);
        snprintf(p->lines[i].name, sizeof(p->lines[i].name), "%s", NAMES[i]);
        p->lines[i].offset = OFFSETS[i];
        p->lines[i].is_found = true;
    }
}

/* Loads a board with the default robot, plans it and points the doctor at
 * root with the fakes, which answer every bus as the board wants it. */
static void prepare(fx_t *f, const char *board, const char *root)
{
    memset(f, 0, sizeof(*f));
    assert_int_equal(ps_config_load_board(board, &f->board, f->err, sizeof(f->err)), 0);
    assert_int_equal(ps_config_load_robot("robots/ps1.yaml", &f->robot, f->err, sizeof(f->err)),
                     0);
    assert_int_equal(ps_app_plan_buses(&f->board, &f->robot, &f->plan, f->err, sizeof(f->err)),
                     0);
    for (uint32_t b = 0; b < f->board.n_buses && b < 4; b++) {
        f->fakes.names[b] = f->board.buses[b].ifname;
        f->fakes.ifaces[b] = good_iface(&f->board.buses[b]);
        f->cfg.min_txqueuelen[b] = ps_app_min_txqueuelen(&f->robot, b);
    }
    good_gpio(&f->fakes.gpio);
    f->cfg.root = root;
    f->cfg.board = &f->board;
    f->cfg.plan = &f->plan;
    f->cfg.ops = (ps_doctor_ops_t){fake_query, fake_probe, &f->fakes};
}

static const ps_doctor_item_t *item(const fx_t *f, const char *what)
{
    for (uint32_t i = 0; i < f->report.n_items; i++)
        if (strcmp(f->report.items[i].what, what) == 0)
            return &f->report.items[i];
    fail_msg("no item \"%s\"", what);
    return NULL;
}

static void expect(const fx_t *f, const char *what, ps_doctor_level_t level, const char *in_found,
                   const char *in_fix)
{
    const ps_doctor_item_t *it = item(f, what);
    if (it->level != level)
        fail_msg("%s: level %d, want %d (%s)", what, (int)it->level, (int)level, it->found);
    if (in_found != NULL && strstr(it->found, in_found) == NULL)
        fail_msg("%s: found \"%s\" lacks \"%s\"", what, it->found, in_found);
    if (in_fix != NULL && strstr(it->fix, in_fix) == NULL)
        fail_msg("%s: fix \"%s\" lacks \"%s\"", what, it->fix, in_fix);
    if (level <= PS_DOCTOR_NOTE && it->fix[0] != '\0')
        fail_msg("%s: fine, yet a fix \"%s\"", what, it->fix);
}

static int setup(void **state)
{
    fx_t *f = calloc(1, sizeof(*f));
    *state = f;
    return f != NULL ? 0 : -1;
}

static int teardown(void **state)
{
    free(*state);
    return 0;
}

/* ---- a target set up as docs/deploy.md says ------------------------------- */

static void test_doctor_rt_target_every_item_fine(void **state)
{
    fx_t *f = *state;
    prepare(f, "boards/rpi5.yaml", RT_TARGET);
    assert_int_equal(ps_doctor_run(&f->cfg, &f->report), 0);
    expect(f, "kernel", PS_DOCTOR_OK, "6.6.31-rt32-v8-16k+, PREEMPT_RT", NULL);
    expect(f, "rt priority", PS_DOCTOR_OK, "SCHED_FIFO 80 permitted (RLIMIT_RTPRIO)", NULL);
    expect(f, "memlock", PS_DOCTOR_OK, "RLIMIT_MEMLOCK unlimited", NULL);
    expect(f, "loop cpu", PS_DOCTOR_OK, "CPU 3 online and allowed", NULL);
    expect(f, "isolation", PS_DOCTOR_OK, "CPU 3 isolated (isolcpus), nohz_full", NULL);
    expect(f, "governor", PS_DOCTOR_OK, "performance", NULL);
    expect(f, "clock source", PS_DOCTOR_OK, "arch_sys_counter", NULL);
    expect(f, "cpu latency", PS_DOCTOR_OK, "writable", NULL);
    expect(f, "can can0", PS_DOCTOR_OK, "up, can, mtu 72, txqueuelen 128, 1000000 bit/s FD", NULL);
    expect(f, "can3 driver", PS_DOCTOR_OK, "mcp251xfd on spi1.1", NULL);
    expect(f, "gpio e-stop", PS_DOCTOR_OK, "gpiochip0 [pinctrl-rp1] line 5 \"GPIO5\", free", NULL);
    expect(f, "gpio LED", PS_DOCTOR_OK, "line 27", NULL);
    expect(f, "camera", PS_DOCTOR_OK, "v4l-subdev0: \"imx708\" (/dev/v4l-subdev0)", NULL);
    assert_int_equal(f->report.n_fail, 0);
    assert_int_equal(f->report.n_warn, 0);
    assert_int_equal(f->fakes.n_can_queries, 4);
    assert_int_equal(f->fakes.n_gpio_probes, 1);
}

/* ---- a fresh machine: every item names its fix ----------------------------- */

static void test_doctor_plain_target_every_fix_named(void **state)
{
    fx_t *f = *state;
    prepare(f, "boards/rpi5.yaml", PLAIN);
    f->fakes.ifaces[0].is_up = false;          /* can0 down */
    f->fakes.ifaces[1].bitrate = 500000;       /* can1 at the wrong rate */
    f->fakes.names[2] = NULL;                  /* can2 absent */
    f->fakes.ifaces[3].txqueuelen = 10;        /* can3 queue too short */
    f->fakes.gpio.lines[1].is_used = true;     /* heartbeat taken */
    snprintf(f->fakes.gpio.lines[1].consumer, sizeof(f->fakes.gpio.lines[1].consumer), "spi1 CS1");
    f->fakes.gpio.lines[2].is_found = false;   /* LED name unknown */
    snprintf(f->fakes.gpio.lines[2].why, sizeof(f->fakes.gpio.lines[2].why),
             "no line of that name on the chip");
    const int n_fail = ps_doctor_run(&f->cfg, &f->report);

    expect(f, "kernel", PS_DOCTOR_WARN, "6.1.0-18-arm64 has no kernel preemption",
           "sudo apt install linux-image-rt-$(dpkg --print-architecture)");
    expect(f, "rt priority", PS_DOCTOR_FAIL, "RLIMIT_RTPRIO 0",
           "echo '@pushstep - rtprio 80' | sudo tee -a /etc/security/limits.d/pushstep.conf");
    expect(f, "rt priority", PS_DOCTOR_FAIL, NULL, "`sudo systemctl start pushstep@rpi5`");
    expect(f, "memlock", PS_DOCTOR_FAIL, "RLIMIT_MEMLOCK 8388608 bytes",
           "echo '@pushstep - memlock unlimited'");
    expect(f, "loop cpu", PS_DOCTOR_FAIL, "not in this process's cpuset (0-2)", "AllowedCPUs=");
    expect(f, "isolation", PS_DOCTOR_WARN, "CPU 3 is not isolated",
           "isolcpus=3 nohz_full=3 rcu_nocbs=3");
    expect(f, "governor", PS_DOCTOR_WARN, "\"ondemand\"",
           "echo performance | sudo tee /sys/devices/system/cpu/cpu3/cpufreq/scaling_governor");
    expect(f, "clock source", PS_DOCTOR_WARN, "hpet",
           "echo tsc | sudo tee /sys/devices/system/clocksource/clocksource0/current_clocksource");
    expect(f, "cpu latency", PS_DOCTOR_WARN, "no /dev/cpu_dma_latency", NULL);
    /* the CAN items carry the runtime's own start-up check, commands included */
    expect(f, "can can0", PS_DOCTOR_FAIL, "down", "can0 is down: sudo ip link set can0 down");
    expect(f, "can can1", PS_DOCTOR_FAIL, "500000 bit/s",
           "sudo ip link set can1 type can bitrate 1000000 dbitrate 5000000 fd on restart-ms 100");
    expect(f, "can can2", PS_DOCTOR_FAIL, "absent", "no interface can2 (`ip link show`)");
    expect(f, "can can3", PS_DOCTOR_FAIL, "txqueuelen 10", "sudo ip link set can3 txqueuelen");
    expect(f, "can0 driver", PS_DOCTOR_FAIL, "can0 is driven by gs_usb on 1-1.2:1.0",
           "udev rules of docs/deploy.md");
    expect(f, "can1 driver", PS_DOCTOR_OK, "mcp251xfd on spi0.0", NULL);
    expect(f, "gpio e-stop", PS_DOCTOR_OK, "free", NULL);
    expect(f, "gpio heartbeat", PS_DOCTOR_FAIL, "in use by \"spi1 CS1\"", "pick a free line");
    expect(f, "gpio LED", PS_DOCTOR_FAIL, "no line of that name", "gpioinfo");
    expect(f, "camera", PS_DOCTOR_WARN, "seen: video0: \"unicam-image\"", "v4l2-ctl");
    assert_int_equal(n_fail, 10);
    assert_int_equal(f->report.n_fail, 10);
    assert_int_equal(f->report.n_warn, 6);
}

/* On board sim, missing RT privileges are worth fixing but not required, and
 * there is no CAN or GPIO to look at. */
static void test_doctor_sim_board_nothing_required(void **state)
{
    fx_t *f = *state;
    prepare(f, "boards/sim.yaml", PLAIN);
    assert_int_equal(ps_doctor_run(&f->cfg, &f->report), 0);
    expect(f, "rt priority", PS_DOCTOR_WARN, "not permitted", "LimitRTPRIO=80");
    expect(f, "memlock", PS_DOCTOR_WARN, NULL, NULL);
    expect(f, "loop cpu", PS_DOCTOR_OK, "CPU 1", NULL);
    expect(f, "can, gpio", PS_DOCTOR_NOTE, "board sim is simulated", NULL);
    expect(f, "camera", PS_DOCTOR_NOTE, "no camera", NULL);
    assert_int_equal(f->fakes.n_can_queries, 0);
    assert_int_equal(f->fakes.n_gpio_probes, 0);
}

/* rpi4's MCP2515 on can3 gets more frames a tick than it holds. */
static void test_doctor_rx_risk_warned(void **state)
{
    fx_t *f = *state;
    prepare(f, "boards/rpi4.yaml", RT_TARGET);
    (void)ps_doctor_run(&f->cfg, &f->report);
    expect(f, "can3 receive", PS_DOCTOR_WARN, "up to 3 frames arrive in one tick", "chrt -f");
    /* the tree's controllers are MCP2518FDs: the board's driver is not theirs */
    expect(f, "can0 driver", PS_DOCTOR_FAIL, "the board wants mcp251x (mcp2515)", NULL);
    for (uint32_t i = 0; i < f->report.n_items; i++)
        assert_true(strcmp(f->report.items[i].what, "can0 receive") != 0);
}

/* A chip that does not open; a tree with nothing in it; no live queries. */
static void test_doctor_gpio_chip_missing_and_empty_tree(void **state)
{
    fx_t *f = *state;
    prepare(f, "boards/rpi5.yaml", "tests/data/doctor/no-such-tree");
    f->fakes.gpio_rc = -ENOENT;
    (void)ps_doctor_run(&f->cfg, &f->report);
    expect(f, "gpio", PS_DOCTOR_FAIL, "cannot open: No such file or directory", "gpiodetect");
    expect(f, "kernel", PS_DOCTOR_WARN, "(no /proc/version)", NULL);
    expect(f, "rt priority", PS_DOCTOR_FAIL, NULL, NULL);
    expect(f, "clock source", PS_DOCTOR_NOTE, "cannot read", NULL);
    expect(f, "camera", PS_DOCTOR_WARN, "(none at all)", NULL);
    f->cfg.ops = (ps_doctor_ops_t){NULL, NULL, NULL};
    (void)ps_doctor_run(&f->cfg, &f->report);
    expect(f, "can can0", PS_DOCTOR_NOTE, "not queried", NULL);
    expect(f, "gpio", PS_DOCTOR_NOTE, "not queried", NULL);
}

/* ---- the command line ------------------------------------------------------ */

/* Runs `pushstep doctor ARGS`, output into out. @return its exit status */
static int run_doctor(const char *args, char *out, size_t len)
{
    const char *bin = getenv("PUSHSTEP_BIN");
    char cmd[512];
    snprintf(cmd, sizeof(cmd), "%s doctor %s 2>&1", bin != NULL ? bin : "build/pushstep", args);
    FILE *p = popen(cmd, "r");
    assert_non_null(p);
    const size_t n = fread(out, 1, len - 1u, p);
    out[n] = '\0';
    const int st = pclose(p);
    assert_true(WIFEXITED(st));
    return WEXITSTATUS(st);
}

static void test_doctor_cli_exit_status(void **state)
{
    (void)state;
    static char out[16384];
    assert_int_equal(run_doctor("--root " PLAIN " --board rpi5", out, sizeof(out)), 1);
    assert_non_null(strstr(out, "pushstep doctor: board rpi5"));
    assert_non_null(strstr(out, "  TO FIX  rt priority: SCHED_FIFO 80 not permitted"));
    assert_non_null(strstr(out, "          fix: run it as the shipped service (LimitRTPRIO=80)"));
    assert_non_null(strstr(out, "  note    can can0: not queried"));
    assert_non_null(strstr(out, "1 fine, 10 to fix (4 required)\n"));
    assert_int_equal(run_doctor("--root " RT_TARGET " --board rpi5", out, sizeof(out)), 0);
    assert_non_null(strstr(out, "13 fine, 0 to fix (0 required)\n"));
    assert_int_equal(run_doctor("--board no-such-board", out, sizeof(out)), 2);
    assert_int_equal(run_doctor("--bogus", out, sizeof(out)), 2);
    assert_int_equal(run_doctor("--help", out, sizeof(out)), 0);
    static const char *const OPTIONS[] = {"--board", "--robot", "--root", "--help"};
    for (size_t i = 0; i < sizeof(OPTIONS) / sizeof(OPTIONS[0]); i++)
        if (strstr(out, OPTIONS[i]) == NULL)
            fail_msg("doctor --help does not mention %s", OPTIONS[i]);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_doctor_rt_target_every_item_fine, setup, teardown),
        cmocka_unit_test_setup_teardown(test_doctor_plain_target_every_fix_named, setup, teardown),
        cmocka_unit_test_setup_teardown(test_doctor_sim_board_nothing_required, setup, teardown),
        cmocka_unit_test_setup_teardown(test_doctor_rx_risk_warned, setup, teardown),
        cmocka_unit_test_setup_teardown(test_doctor_gpio_chip_missing_and_empty_tree, setup,
                                        teardown),
        cmocka_unit_test(test_doctor_cli_exit_status),
    };
    return cmocka_run_group_tests_name("doctor", tests, NULL, NULL);
}
