/*
 * Tests of drivers/ps_gpio_gpiod on a real kernel GPIO chip, run inside the
 * qemu VM of `make test-hw`: gpio-mockup's gpiochip0 (8 lines, named
 * "gpio-mockup-A-0".."gpio-mockup-A-7"; tools/qemu/guest-modules.sh loads it).
 *
 * The far end is gpio-mockup's debugfs: writing 0/1 to
 * /sys/kernel/debug/gpio-mockup/gpiochip0/<offset> sets the line's pull, which
 * an input follows (and raises its edge interrupt); reading it gives the
 * line's value, outputs included. gpio-mockup resets a line to its pull when
 * it is released, so what close drives before the release is sampled by a
 * stand-in for gpiod_chip_close (below), not after.
 *
 * Timing under qemu TCG is loose (several times slower than the host): the
 * debounce tests measure the pulse they made and retry a pulse that came out
 * on the wrong side of the debounce instead of failing on it.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <gpiod.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "../../drivers/ps_gpio_gpiod.h"
#include "../../rt/ps_err.h"
#include "../contract/ps_gpio_contract.h"

#define CHIP        "gpiochip0"
#define MOCKUP_DIR  "/sys/kernel/debug/gpio-mockup/" CHIP
#define N_LINES     8u
#define LINE_NAME   "gpio-mockup-A-"
#define DEBOUNCE_US 20000u /* long against qemu's jitter; PS_GPIO_DEBOUNCE_MAX_US */

static ps_gpio_gpiod_t g_a, g_b;
static char g_err[PS_ERR_MSG_LEN];

/* ---- helpers -------------------------------------------------------------- */

static int64_t mono_ns(void)
{
    struct timespec ts;
    (void)clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

static void sleep_us(int64_t us)
{
    const struct timespec ts = {.tv_sec = (time_t)(us / 1000000), .tv_nsec = (us % 1000000) * 1000};
    (void)nanosleep(&ts, NULL); /* an early wake only shortens a wait */
}

static void mock_set(unsigned offset, int v)
{
    char path[96];
    (void)snprintf(path, sizeof(path), MOCKUP_DIR "/%u", offset);
    const int fd = open(path, O_WRONLY);
    assert_true(fd >= 0);
    assert_int_equal(write(fd, v ? "1" : "0", 1), 1);
    assert_int_equal(close(fd), 0);
}

static int mock_fd(unsigned offset)
{
    char path[96];
    (void)snprintf(path, sizeof(path), MOCKUP_DIR "/%u", offset);
    const int fd = open(path, O_RDONLY);
    assert_true(fd >= 0);
    return fd;
}

static int mock_read_fd(int fd)
{
    char c[4] = "";
    const ssize_t n = pread(fd, c, sizeof(c) - 1u, 0);
    assert_true(n >= 1);
    assert_true(c[0] == '0' || c[0] == '1');
    return c[0] - '0';
}

static int mock_get(unsigned offset)
{
    const int fd = mock_fd(offset);
    const int v = mock_read_fd(fd);
    assert_int_equal(close(fd), 0);
    return v;
}

/* e-stop 0, heartbeat 1, LED 2, active high, no debounce */
static ps_gpio_cfg_t cfg_default(void)
{
    ps_gpio_cfg_t c;
    memset(&c, 0, sizeof(c));
    (void)snprintf(c.chip, sizeof(c.chip), "%s", CHIP);
    c.estop_line = 0;
    c.enable_line = 1;
    c.led_line = 2;
    return c;
}

static void open_ok(ps_gpio_gpiod_t *g, const ps_gpio_cfg_t *c)
{
    const int rc = ps_gpio_gpiod_open(g, c, g_err, sizeof(g_err));
    if (rc != 0)
        print_error("open: %d %s\n", rc, g_err);
    assert_int_equal(rc, 0);
}

static bool read_pressed(ps_gpio_gpiod_t *g)
{
    ps_gpio_port_t p = ps_gpio_gpiod_port(g);
    bool is_pressed = false;
    assert_int_equal(ps_gpio_read_estop(&p, &is_pressed), 0);
    return is_pressed;
}

/* Records the heartbeat and LED values the moment the port hands its chip
 * back: gpio-mockup resets released lines to their pull, so this is the only
 * place where what close drove can be seen. The executable's definition takes
 * the calls from drivers/ps_gpio_gpiod.o; the real one is libgpiod's. */
static int g_close_seen_heartbeat = -1, g_close_seen_led = -1;
static unsigned g_close_heartbeat_offset = 1, g_close_led_offset = 2;
void gpiod_chip_close(struct gpiod_chip *chip);
void gpiod_chip_close(struct gpiod_chip *chip)
{
    g_close_seen_heartbeat = mock_get(g_close_heartbeat_offset);
    g_close_seen_led = mock_get(g_close_led_offset);
    void (*real)(struct gpiod_chip *) =
        (void (*)(struct gpiod_chip *))dlsym(RTLD_NEXT, "gpiod_chip_close");
    assert_non_null(real);
    real(chip);
}

static int group_setup(void **state)
{
    (void)state;
    struct stat st;
    if (stat(MOCKUP_DIR, &st) != 0) {
        print_error("no %s: gpio-mockup is not loaded (tools/qemu/guest-modules.sh)\n", MOCKUP_DIR);
        return -1;
    }
    return 0;
}

static int setup(void **state)
{
    (void)state;
    memset(&g_a, 0, sizeof(g_a));
    memset(&g_b, 0, sizeof(g_b));
    for (unsigned i = 0; i < N_LINES; i++)
        mock_set(i, 0);
    g_close_seen_heartbeat = -1;
    g_close_seen_led = -1;
    g_close_heartbeat_offset = 1;
    g_close_led_offset = 2;
    return 0;
}

static int teardown(void **state)
{
    (void)state;
    ps_gpio_gpiod_close(&g_a);
    ps_gpio_gpiod_close(&g_b);
    return 0;
}

/* ---- open ----------------------------------------------------------------- */

static void test_open_by_offset_outputs_low(void **state)
{
    (void)state;
    mock_set(1, 1); /* pulls up: the outputs must still start low */
    mock_set(2, 1);
    const ps_gpio_cfg_t c = cfg_default();
    open_ok(&g_a, &c);
    assert_int_equal(g_a.estop_offset, 0);
    assert_int_equal(g_a.heartbeat_offset, 1);
    assert_int_equal(g_a.led_offset, 2);
    assert_int_equal(mock_get(1), 0);
    assert_int_equal(mock_get(2), 0);
    assert_false(read_pressed(&g_a));
    ps_gpio_gpiod_close(&g_a);
    ps_gpio_gpiod_close(&g_a); /* twice: a no-op */
    /* a closed port refuses, without touching anything */
    ps_gpio_port_t p = ps_gpio_gpiod_port(&g_a);
    bool is_pressed = true;
    assert_int_equal(ps_gpio_read_estop(&p, &is_pressed), -EBADF);
    assert_int_equal(ps_gpio_set_heartbeat(&p, true), -EBADF);
}

static void test_open_by_name_resolves_offsets(void **state)
{
    (void)state;
    ps_gpio_cfg_t c = cfg_default();
    (void)snprintf(c.estop_name, sizeof(c.estop_name), LINE_NAME "5");
    (void)snprintf(c.enable_name, sizeof(c.enable_name), LINE_NAME "6");
    (void)snprintf(c.led_name, sizeof(c.led_name), LINE_NAME "7");
    open_ok(&g_a, &c);
    assert_int_equal(g_a.estop_offset, 5);
    assert_int_equal(g_a.heartbeat_offset, 6);
    assert_int_equal(g_a.led_offset, 7);
    ps_gpio_port_t p = ps_gpio_gpiod_port(&g_a);
    assert_int_equal(ps_gpio_set_heartbeat(&p, true), 0);
    assert_int_equal(mock_get(6), 1);
    mock_set(5, 1);
    sleep_us(2000);
    assert_true(read_pressed(&g_a));
}

/* ---- e-stop ---------------------------------------------------------------- */

static void test_estop_active_high_latched_until_read(void **state)
{
    (void)state;
    const ps_gpio_cfg_t c = cfg_default();
    open_ok(&g_a, &c);
    assert_false(read_pressed(&g_a));
    mock_set(0, 1); /* pressed, held */
    sleep_us(2000);
    assert_true(read_pressed(&g_a));
    assert_true(read_pressed(&g_a)); /* pressed now */
    mock_set(0, 0);
    sleep_us(2000);
    assert_false(read_pressed(&g_a));
    /* pressed and released between two reads, well apart: one report */
    mock_set(0, 1);
    sleep_us(5000);
    mock_set(0, 0);
    sleep_us(50000);
    assert_true(read_pressed(&g_a));
    assert_false(read_pressed(&g_a));
    assert_true(g_a.n_estop_events >= 4u);
    print_message("events %llu, covered by a level fix %llu, level fixes %llu\n",
                  (unsigned long long)g_a.n_estop_events, (unsigned long long)g_a.n_events_covered,
                  (unsigned long long)g_a.n_level_fixes);
}

static void test_estop_active_low_both_ways(void **state)
{
    (void)state;
    ps_gpio_cfg_t c = cfg_default();
    c.is_estop_active_low = true;
    mock_set(0, 1); /* released: high */
    open_ok(&g_a, &c);
    assert_false(read_pressed(&g_a));
    mock_set(0, 0); /* pressed: pulled low */
    sleep_us(2000);
    assert_true(read_pressed(&g_a));
    mock_set(0, 1);
    sleep_us(2000);
    assert_false(read_pressed(&g_a));
    ps_gpio_gpiod_close(&g_a);

    /* Held (low) at open: the first read says pressed. */
    mock_set(0, 0);
    open_ok(&g_a, &c);
    assert_true(read_pressed(&g_a));
    ps_gpio_gpiod_close(&g_a);

    /* Active high, held (high) at open: the same. */
    c.is_estop_active_low = false;
    mock_set(0, 1);
    open_ok(&g_a, &c);
    assert_true(read_pressed(&g_a));
}

/* A press as short as two back-to-back writes (tens of microseconds under
 * qemu), between two reads: still reported with debounce 0. */
static void test_estop_short_press_between_reads_reported(void **state)
{
    (void)state;
    const ps_gpio_cfg_t c = cfg_default();
    open_ok(&g_a, &c);
    assert_false(read_pressed(&g_a));
    for (int k = 0; k < 5; k++) {
        const int64_t t0 = mono_ns();
        mock_set(0, 1);
        mock_set(0, 0);
        const int64_t t1 = mono_ns();
        sleep_us(10000); /* the IRQ thread's events, under qemu */
        if (k == 0)
            print_message("short press: %.1f us between the writes\n", (double)(t1 - t0) / 1e3);
        assert_true(read_pressed(&g_a));
        assert_false(read_pressed(&g_a));
    }
}

/* A burst of edges beyond the kernel's 16-event FIFO between two reads (a
 * badly bouncing contact): the press is reported, and the level after the
 * burst is right whichever way it ended (the level check, not the events). */
static void test_estop_burst_beyond_fifo_level_right(void **state)
{
    (void)state;
    const ps_gpio_cfg_t c = cfg_default();
    open_ok(&g_a, &c);
    assert_false(read_pressed(&g_a));
    for (int i = 0; i < 20; i++) { /* 40 edges, ends released */
        mock_set(0, 1);
        mock_set(0, 0);
    }
    sleep_us(10000);
    assert_true(read_pressed(&g_a));
    assert_false(read_pressed(&g_a));
    for (int i = 0; i < 20; i++) /* 41 edges, ends pressed */
        mock_set(0, i & 1);
    mock_set(0, 1);
    sleep_us(3000);
    assert_true(read_pressed(&g_a));
    assert_true(read_pressed(&g_a));
    mock_set(0, 0);
    sleep_us(3000);
    assert_false(read_pressed(&g_a));
    print_message("burst: events %llu, covered %llu, level fixes %llu\n",
                  (unsigned long long)g_a.n_estop_events, (unsigned long long)g_a.n_events_covered,
                  (unsigned long long)g_a.n_level_fixes);
}

/* A glitch shorter than the debounce is not reported. Each try measures its
 * pulse, and a try that came out too long under a loaded qemu is repeated;
 * so is one whose two edges the kernel merged into one interrupt (one event,
 * the level read fixing the rest), which by design errs toward pressed
 * (drivers/ps_gpio_gpiod.h) and is checked to. The first version of this
 * test, which counted such a try, failed in CI and, under load, here. */
static void test_estop_glitch_shorter_than_debounce_ignored(void **state)
{
    (void)state;
    ps_gpio_cfg_t c = cfg_default();
    c.estop_debounce_us = DEBOUNCE_US;
    open_ok(&g_a, &c);
    assert_false(read_pressed(&g_a));
    int n_ok = 0, k = 0;
    for (; k < 12 && n_ok < 3; k++) {
        const uint64_t n_fixes = g_a.n_level_fixes;
        const int64_t t0 = mono_ns();
        mock_set(0, 1);
        sleep_us(1000);
        mock_set(0, 0);
        const int64_t pulse_ns = mono_ns() - t0;
        sleep_us(2 * DEBOUNCE_US); /* the release holds: nothing pending */
        const bool is_pressed = read_pressed(&g_a);
        if (g_a.n_level_fixes != n_fixes) {
            print_message("glitch try %d: pulse %.2f ms, edges merged by the kernel (a level "
                          "fix): reported pressed, not counted\n",
                          k, (double)pulse_ns / 1e6);
            assert_true(is_pressed);
            /* The fix's release is debounced like any other: reads within
             * the debounce of the fix still say pressed (how many depends
             * on how long a read and the message above take: the VM's
             * serial console made it one read or two, and failed a test
             * that allowed one). Read as the loop does, a tick apart:
             * released once the release has held for the debounce (an edge
             * stamped after the fix, the header's other cost, is a pulse of
             * a tick then, never a press), and it stays released. */
            const int64_t t_fix_ns = mono_ns();
            int n_reads = 0;
            while (read_pressed(&g_a) && n_reads < 200) {
                sleep_us(1000);
                n_reads++;
            }
            const double released_after_ms = (double)(mono_ns() - t_fix_ns) / 1e6;
            print_message("glitch try %d: released %.1f ms after the fix (%d reads pressed)\n", k,
                          released_after_ms, n_reads);
            /* the debounce after the fix, not much more: 5 x covers the
             * VM's stalls (0.1 s seen once) and catches a fix held long */
            assert_true(released_after_ms < 5.0 * DEBOUNCE_US / 1e3);
            for (int i = 0; i < 5; i++) {
                sleep_us(1000);
                assert_false(read_pressed(&g_a));
            }
            continue;
        }
        if (pulse_ns >= (int64_t)DEBOUNCE_US * 1000 / 2) {
            print_message("glitch try %d: pulse %.2f ms, too long under qemu: not counted\n", k,
                          (double)pulse_ns / 1e6);
            continue;
        }
        if (is_pressed)
            fail_msg("glitch try %d: a pulse of %.3f ms (debounce %.1f ms) reported as a press", k,
                     (double)pulse_ns / 1e6, DEBOUNCE_US / 1e3);
        n_ok++;
    }
    print_message("glitch: %d of %d tries counted, none reported\n", n_ok, k);
    assert_int_equal(n_ok, 3);
}

/* A press longer than the debounce is reported: released before the read
 * (judged from the event stamps), and held across reads (judged at the read). */
static void test_estop_press_longer_than_debounce_reported(void **state)
{
    (void)state;
    ps_gpio_cfg_t c = cfg_default();
    c.estop_debounce_us = DEBOUNCE_US;
    open_ok(&g_a, &c);
    assert_false(read_pressed(&g_a));

    mock_set(0, 1);
    sleep_us(2 * DEBOUNCE_US);
    mock_set(0, 0);
    sleep_us(5000);
    assert_true(read_pressed(&g_a));
    sleep_us(2 * DEBOUNCE_US);
    assert_false(read_pressed(&g_a));

    /* Held: not yet at once, then pressed once held for the debounce. */
    const int64_t t0 = mono_ns();
    mock_set(0, 1);
    const bool is_early = read_pressed(&g_a);
    const int64_t early_ns = mono_ns() - t0;
    if (early_ns < (int64_t)DEBOUNCE_US * 1000 / 2)
        assert_false(is_early);
    sleep_us(DEBOUNCE_US + 5000);
    assert_true(read_pressed(&g_a));
    /* and a release needs the stable time too */
    mock_set(0, 0);
    sleep_us(2 * DEBOUNCE_US);
    assert_false(read_pressed(&g_a));
}

static void test_estop_bias_pull_up_applied(void **state)
{
    (void)state;
    ps_gpio_cfg_t c = cfg_default();
    c.estop_bias = PS_GPIO_BIAS_PULL_UP; /* gpio-mockup takes a bias as its pull */
    open_ok(&g_a, &c);
    assert_int_equal(mock_get(0), 1);
    assert_true(read_pressed(&g_a)); /* active high, pulled up */
}

/* ---- errors ---------------------------------------------------------------- */

static void test_open_missing_chip_says_so(void **state)
{
    (void)state;
    ps_gpio_cfg_t c = cfg_default();
    (void)snprintf(c.chip, sizeof(c.chip), "gpiochip9");
    assert_int_equal(ps_gpio_gpiod_open(&g_a, &c, g_err, sizeof(g_err)), -ENOENT);
    print_message("%s\n", g_err);
    assert_non_null(strstr(g_err, "\"gpiochip9\""));
    assert_non_null(strstr(g_err, strerror(ENOENT)));
    assert_non_null(strstr(g_err, "gpiodetect"));
    assert_null(g_a.chip);
}

static void test_open_missing_line_says_so(void **state)
{
    (void)state;
    ps_gpio_cfg_t c = cfg_default();
    c.led_line = N_LINES;
    assert_int_equal(ps_gpio_gpiod_open(&g_a, &c, g_err, sizeof(g_err)), -EINVAL);
    print_message("%s\n", g_err);
    assert_non_null(strstr(g_err, "LED line 8: no such line (offsets 0..7)"));
    assert_non_null(strstr(g_err, "`gpioinfo " CHIP "`"));
    assert_null(g_a.chip);

    c = cfg_default();
    (void)snprintf(c.estop_name, sizeof(c.estop_name), "GPIO17");
    assert_int_equal(ps_gpio_gpiod_open(&g_a, &c, g_err, sizeof(g_err)), -ENOENT);
    print_message("%s\n", g_err);
    assert_non_null(strstr(g_err, "e-stop line \"GPIO17\": no line of that name"));
    assert_non_null(strstr(g_err, "`gpioinfo " CHIP "`"));

    /* two roles on one line (by name and by offset) */
    c = cfg_default();
    (void)snprintf(c.led_name, sizeof(c.led_name), LINE_NAME "1");
    assert_int_equal(ps_gpio_gpiod_open(&g_a, &c, g_err, sizeof(g_err)), -EINVAL);
    print_message("%s\n", g_err);
    assert_non_null(strstr(g_err, "each role needs its own line"));
}

static void test_open_busy_line_names_consumer(void **state)
{
    (void)state;
    const ps_gpio_cfg_t c = cfg_default();
    open_ok(&g_a, &c);
    /* the same lines again: the heartbeat (requested first) is busy */
    assert_int_equal(ps_gpio_gpiod_open(&g_b, &c, g_err, sizeof(g_err)), -EBUSY);
    print_message("%s\n", g_err);
    assert_non_null(strstr(g_err, "line 1 (\"" LINE_NAME "1\", heartbeat)"));
    assert_non_null(strstr(g_err, "line busy: used by \"pushstep-heartbeat\""));
    assert_non_null(strstr(g_err, "`gpioinfo " CHIP "`"));
    assert_null(g_b.chip);

    /* only the e-stop shared: its outputs came free again on the failure */
    ps_gpio_cfg_t c2 = cfg_default();
    c2.enable_line = 6;
    c2.led_line = 7;
    assert_int_equal(ps_gpio_gpiod_open(&g_b, &c2, g_err, sizeof(g_err)), -EBUSY);
    print_message("%s\n", g_err);
    assert_non_null(strstr(g_err, "line busy: used by \"pushstep-estop\""));
    ps_gpio_gpiod_close(&g_a);
    open_ok(&g_b, &c2); /* now free */
}

/* ---- outputs ---------------------------------------------------------------- */

static void test_heartbeat_and_led_visible(void **state)
{
    (void)state;
    const ps_gpio_cfg_t c = cfg_default();
    open_ok(&g_a, &c);
    ps_gpio_port_t p = ps_gpio_gpiod_port(&g_a);
    const int fd = mock_fd(1);
    for (int i = 0; i < 100; i++) {
        const bool level = (i & 1) == 0;
        assert_int_equal(ps_gpio_set_heartbeat(&p, level), 0);
        assert_int_equal(mock_read_fd(fd), level ? 1 : 0);
    }
    assert_int_equal(close(fd), 0);
    assert_int_equal(ps_gpio_set_led(&p, PS_GPIO_LED_ON), 0);
    assert_int_equal(mock_get(2), 1);
    assert_int_equal(ps_gpio_set_led(&p, PS_GPIO_LED_OFF), 0);
    assert_int_equal(mock_get(2), 0);
}

static void test_close_drives_outputs_low(void **state)
{
    (void)state;
    const ps_gpio_cfg_t c = cfg_default();
    open_ok(&g_a, &c);
    ps_gpio_port_t p = ps_gpio_gpiod_port(&g_a);
    assert_int_equal(ps_gpio_set_heartbeat(&p, true), 0);
    assert_int_equal(ps_gpio_set_led(&p, PS_GPIO_LED_ON), 0);
    assert_int_equal(mock_get(1), 1);
    assert_int_equal(mock_get(2), 1);
    ps_gpio_close(&p); /* through the ops, as the loop's owner does */
    assert_int_equal(g_close_seen_heartbeat, 0);
    assert_int_equal(g_close_seen_led, 0);
    assert_int_equal(mock_get(1), 0);
    assert_int_equal(mock_get(2), 0);
}

/* What the RT ops cost here (qemu TCG: several times a board's figure):
 * printed, not asserted. */
static int cmp_i64(const void *a, const void *b)
{
    const int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
    return (x > y) - (x < y);
}

static void print_cost(const char *what, int64_t *ns, int n)
{
    qsort(ns, (size_t)n, sizeof(ns[0]), cmp_i64);
    print_message("%s: p50 %.1f us, p99 %.1f us, max %.1f us over %d calls\n", what,
                  (double)ns[n / 2] / 1e3, (double)ns[n * 99 / 100] / 1e3, (double)ns[n - 1] / 1e3,
                  n);
}

static void test_rt_ops_cost_printed(void **state)
{
    (void)state;
    enum { N = 2000 };
    static int64_t ns[N];
    const ps_gpio_cfg_t c = cfg_default();
    open_ok(&g_a, &c);
    ps_gpio_port_t p = ps_gpio_gpiod_port(&g_a);
    for (int i = 0; i < N; i++) {
        bool is_pressed = true;
        const int64_t t0 = mono_ns();
        assert_int_equal(ps_gpio_read_estop(&p, &is_pressed), 0);
        ns[i] = mono_ns() - t0;
        assert_false(is_pressed);
    }
    print_cost("read_estop, no event", ns, N);
    for (int i = 0; i < N; i++) {
        const int64_t t0 = mono_ns();
        assert_int_equal(ps_gpio_set_heartbeat(&p, (i & 1) == 0), 0);
        ns[i] = mono_ns() - t0;
    }
    print_cost("set_heartbeat", ns, N);
}

/* ---- a killed process ------------------------------------------------------ */

/* The child: open, say so, toggle the heartbeat every 1 ms until killed. */
static void heartbeat_child(int ready_fd)
{
    ps_gpio_gpiod_t g;
    memset(&g, 0, sizeof(g));
    const ps_gpio_cfg_t c = cfg_default();
    char err[PS_ERR_MSG_LEN];
    if (ps_gpio_gpiod_open(&g, &c, err, sizeof(err)) != 0)
        _exit(2);
    const ps_gpio_port_t p = ps_gpio_gpiod_port(&g);
    if (write(ready_fd, "r", 1) != 1)
        _exit(3);
    struct timespec next;
    (void)clock_gettime(CLOCK_MONOTONIC, &next);
    for (bool level = true;; level = !level) {
        (void)ps_gpio_set_heartbeat(&p, level);
        next.tv_nsec += 1000000;
        if (next.tv_nsec >= 1000000000) {
            next.tv_nsec -= 1000000000;
            next.tv_sec++;
        }
        (void)clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, NULL);
    }
}

/* What one round saw; times in ns after the kill. */
typedef struct {
    int n_before;        /* heartbeat changes in the 100 ms before the kill */
    double sample_us;    /* the parent's sampling period */
    int64_t gone_ns;     /* the child waitable: its files, and so its lines, released */
    int n_after;         /* changes after the kill */
    int64_t after_ns[2]; /* the first two of them */
    int64_t last_ns;     /* the last change (0: none) */
    int n_after_gone;    /* changes later than 1 ms after the child was gone */
} kill_round_t;

/* One round: fork a beating child, sample its heartbeat for 100 ms, SIGKILL
 * it, sample 100 ms more, polling (waitid WNOWAIT) for when it is gone. */
static void kill_round(kill_round_t *out)
{
    int pipefd[2];
    assert_int_equal(pipe(pipefd), 0);
    const pid_t pid = fork();
    assert_true(pid >= 0);
    if (pid == 0) {
        (void)close(pipefd[0]);
        heartbeat_child(pipefd[1]);
    }
    (void)close(pipefd[1]);
    char r = 0;
    assert_int_equal(read(pipefd[0], &r, 1), 1);
    (void)close(pipefd[0]);

    memset(out, 0, sizeof(*out));
    const int fd = mock_fd(1);
    int v = mock_read_fd(fd);
    uint64_t n_samples = 0;
    const int64_t t_start = mono_ns();
    while (mono_ns() - t_start < 100000000LL) {
        const int v2 = mock_read_fd(fd);
        out->n_before += v2 != v;
        v = v2;
        n_samples++;
    }
    const int64_t t_kill = mono_ns();
    assert_int_equal(kill(pid, SIGKILL), 0);
    int64_t t_gone = -1;
    while (mono_ns() - t_kill < 100000000LL) {
        const int v2 = mock_read_fd(fd);
        if (v2 != v) {
            const int64_t t = mono_ns() - t_kill;
            if (out->n_after < 2)
                out->after_ns[out->n_after] = t;
            out->n_after++;
            out->last_ns = t;
            if (t_gone >= 0 && t > t_gone + 1000000LL)
                out->n_after_gone++;
        }
        v = v2;
        if (t_gone < 0) {
            siginfo_t si;
            memset(&si, 0, sizeof(si));
            assert_int_equal(waitid(P_PID, (id_t)pid, &si, WEXITED | WNOHANG | WNOWAIT), 0);
            if (si.si_pid == pid)
                t_gone = mono_ns() - t_kill;
        }
    }
    int status = 0;
    assert_int_equal(waitpid(pid, &status, 0), pid);
    assert_true(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);
    assert_int_equal(close(fd), 0);
    assert_true(t_gone >= 0);
    out->sample_us = 100000.0 / (double)(n_samples > 0 ? n_samples : 1);
    out->gone_ns = t_gone;
}

/* SIGKILL the process that beats: the line stops changing, so the relay drops
 * the drives' power PS_GPIO_HEARTBEAT_TIMEOUT_NS after the last change. The
 * parent samples the line's value through debugfs as fast as it can. After
 * the kill at most two changes may come: a beat in flight, and the release at
 * exit (gpio-mockup resets a released line to its pull, 0; a Raspberry Pi
 * turns a freed pin back into an input, which its pull then sets). Nothing
 * may change once the process is gone. When it is gone depends on qemu (its
 * exit unmaps a large image: 1.5 to 17 ms seen), so that is printed, not
 * asserted. */
static void test_sigkill_heartbeat_stops(void **state)
{
    (void)state;
    int64_t worst_last_ns = 0, worst_gone_ns = 0;
    for (int k = 0; k < 3; k++) {
        kill_round_t r;
        kill_round(&r);
        char after[64] = "none";
        if (r.n_after == 1)
            (void)snprintf(after, sizeof(after), "%.3f ms", (double)r.after_ns[0] / 1e6);
        else if (r.n_after >= 2)
            (void)snprintf(after, sizeof(after), "%.3f, %.3f ms", (double)r.after_ns[0] / 1e6,
                           (double)r.after_ns[1] / 1e6);
        print_message("SIGKILL round %d: %d heartbeat changes in the 100 ms before (a sample "
                      "every %.1f us); after the kill %d change(s) (at %s), process gone at "
                      "%.3f ms\n",
                      k, r.n_before, r.sample_us, r.n_after, after, (double)r.gone_ns / 1e6);
        /* it was beating: 100 changes at 1 kHz, far fewer when the host
         * starves the VM's CPUs (8 seen under load 4) */
        assert_true(r.n_before >= 3);
        assert_true(r.n_after <= 2);         /* a beat in flight and the release at most */
        assert_int_equal(r.n_after_gone, 0); /* nothing moves the line once it is gone */
        if (r.last_ns > worst_last_ns)
            worst_last_ns = r.last_ns;
        if (r.gone_ns > worst_gone_ns)
            worst_gone_ns = r.gone_ns;
    }
    print_message("SIGKILL: the heartbeat's last change came at most %.3f ms after the kill "
                  "(the process was gone at most %.3f ms after it)\n",
                  (double)worst_last_ns / 1e6, (double)worst_gone_ns / 1e6);
}

#define T(fn) cmocka_unit_test_setup_teardown(fn, setup, teardown)

/* ---- the port contract the simulated lines keep too (tests/contract) ----- */

/* The event fd of the input the mock changed last, -1 when none since the
 * last settle. */
static int g_changed_fd = -1;

static void mock_set_estop(void *ctx, bool is_pressed)
{
    (void)ctx;
    mock_set(0, is_pressed ? 1 : 0); /* active-high in cfg_default */
    g_changed_fd = g_a.estop_fd;
}

/* The edge's interrupt thread queues the event: wait, bounded, until the
 * changed line's fd has one to read, then 3 ms more. A fixed 3 ms alone is
 * too short when the host starves the VM (CI failed the contract check once
 * with it; its excerpt did not show the line): a press shorter than a tick
 * whose edges were not queued yet reads as never pressed. An fd already readable (a press's edge
 * not read yet when its release comes) returns at once: a release queued late is stamped before the
 * level read that saw it, and counts as no new press. */
static void mock_settle(void *ctx)
{
    (void)ctx;
    if (g_changed_fd >= 0) {
        struct pollfd p = {.fd = g_changed_fd, .events = POLLIN};
        assert_int_equal(poll(&p, 1, 1000), 1);
    }
    g_changed_fd = -1;
    sleep_us(3000);
}

static bool mock_heartbeat_level(void *ctx)
{
    (void)ctx;
    return mock_get(1) == 1;
}

static bool mock_is_led_on(void *ctx)
{
    (void)ctx;
    return mock_get(2) == 1;
}

static void mock_set_button(void *ctx, bool is_pressed)
{
    (void)ctx;
    mock_set(3, is_pressed ? 1 : 0); /* active high */
    g_changed_fd = g_a.button_fd;
}

/* Without the record button (read_button says not pressed), then with it
 * on line 3 (read as the e-stop is). */
static void test_gpiod_keeps_the_port_contract(void **state)
{
    (void)state;
    ps_gpio_cfg_t c = cfg_default(); /* debounce 0 */
    open_ok(&g_a, &c);
    ps_gpio_contract_t k = {.port = ps_gpio_gpiod_port(&g_a),
                            .ctx = NULL,
                            .set_estop = mock_set_estop,
                            .settle = mock_settle,
                            .heartbeat_level = mock_heartbeat_level,
                            .is_led_on = mock_is_led_on};
    ps_gpio_contract_check(&k);
    ps_gpio_gpiod_close(&g_a);
    c.has_button = true;
    c.button_line = 3;
    open_ok(&g_a, &c);
    assert_int_equal(g_a.button_offset, 3);
    k.port = ps_gpio_gpiod_port(&g_a);
    k.set_button = mock_set_button;
    ps_gpio_contract_check(&k);
    /* The button is read by its edge events, not by the level alone: the
     * check's two presses are four edges. The mockup's interrupt work may
     * queue the last one after the check's last read when the host starves
     * the VM (3 of 4 counted once in CI), so keep reading, a bounded while. */
    const int64_t t0_ns = mono_ns();
    while (g_a.n_button_events < 4 && mono_ns() - t0_ns < 1000000000LL) {
        sleep_us(1000);
        bool is_pressed = true;
        assert_int_equal(ps_gpio_read_button(&k.port, &is_pressed), 0);
        assert_false(is_pressed); /* a late release edge is no new press */
    }
    print_message("button: %llu edge events counted (%llu stamped before a level read), "
                  "the last %.1f ms after the check\n",
                  (unsigned long long)g_a.n_button_events,
                  (unsigned long long)g_a.n_button_events_covered,
                  (double)(mono_ns() - t0_ns) / 1e6);
    assert_true(g_a.n_button_events >= 4);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        T(test_gpiod_keeps_the_port_contract),
        T(test_open_by_offset_outputs_low),
        T(test_open_by_name_resolves_offsets),
        T(test_estop_active_high_latched_until_read),
        T(test_estop_active_low_both_ways),
        T(test_estop_short_press_between_reads_reported),
        T(test_estop_burst_beyond_fifo_level_right),
        T(test_estop_glitch_shorter_than_debounce_ignored),
        T(test_estop_press_longer_than_debounce_reported),
        T(test_estop_bias_pull_up_applied),
        T(test_open_missing_chip_says_so),
        T(test_open_missing_line_says_so),
        T(test_open_busy_line_names_consumer),
        T(test_heartbeat_and_led_visible),
        T(test_close_drives_outputs_low),
        T(test_rt_ops_cost_printed),
        T(test_sigkill_heartbeat_stops),
    };
    return cmocka_run_group_tests(tests, group_setup, NULL);
}
