/* Tests of sim/ps_gpio_sim: simulated e-stop (latched), heartbeat and LED
 * lines, and the watchdog relay on the heartbeat. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>

#include "../sim/ps_gpio_sim.h"
#include "contract/ps_gpio_contract.h"

#define MS 1000000LL /* ns */

static void test_ps_gpio_sim_init_released_heartbeat_low_power_off(void **state)
{
    (void)state;
    ps_gpio_sim_t g;
    ps_gpio_sim_init(&g);
    const ps_gpio_port_t p = ps_gpio_sim_port(&g);
    bool is_pressed = true;
    assert_int_equal(ps_gpio_read_estop(&p, &is_pressed), 0);
    assert_false(is_pressed);
    assert_false(ps_gpio_sim_is_power_on(&g));
    assert_false(ps_gpio_sim_update_relay(&g, 0));
    assert_int_equal(ps_gpio_sim_get_led(&g), PS_GPIO_LED_OFF);
    assert_int_equal(ps_gpio_sim_heartbeat_edges(&g), 0);
}

static void test_ps_gpio_read_estop_follows_level(void **state)
{
    (void)state;
    ps_gpio_sim_t g;
    ps_gpio_sim_init(&g);
    const ps_gpio_port_t p = ps_gpio_sim_port(&g);
    bool is_pressed = false;
    ps_gpio_sim_set_estop(&g, true);
    assert_int_equal(ps_gpio_read_estop(&p, &is_pressed), 0);
    assert_true(is_pressed);
    assert_int_equal(ps_gpio_read_estop(&p, &is_pressed), 0);
    assert_true(is_pressed); /* still held */
    ps_gpio_sim_set_estop(&g, false);
    assert_int_equal(ps_gpio_read_estop(&p, &is_pressed), 0);
    assert_false(is_pressed);
    assert_int_equal(ps_gpio_read_estop(&p, NULL), -EINVAL);
}

/* A press and release between two reads (shorter than a tick) is seen by
 * the next read, once; a failed read keeps the latch. */
static void test_ps_gpio_read_estop_press_between_reads_seen_once(void **state)
{
    (void)state;
    ps_gpio_sim_t g;
    ps_gpio_sim_init(&g);
    const ps_gpio_port_t p = ps_gpio_sim_port(&g);
    bool is_pressed = false;
    ps_gpio_sim_set_estop(&g, true);
    ps_gpio_sim_set_estop(&g, false);
    assert_int_equal(ps_gpio_read_estop(&p, NULL), -EINVAL);
    assert_int_equal(ps_gpio_read_estop(&p, &is_pressed), 0);
    assert_true(is_pressed);
    assert_int_equal(ps_gpio_read_estop(&p, &is_pressed), 0);
    assert_false(is_pressed);
}

static void test_ps_gpio_set_heartbeat_counts_edges_only(void **state)
{
    (void)state;
    ps_gpio_sim_t g;
    ps_gpio_sim_init(&g);
    const ps_gpio_port_t p = ps_gpio_sim_port(&g);
    assert_int_equal(ps_gpio_set_heartbeat(&p, false), 0); /* no change */
    assert_int_equal(ps_gpio_sim_heartbeat_edges(&g), 0);
    assert_int_equal(ps_gpio_set_heartbeat(&p, true), 0);
    assert_int_equal(ps_gpio_set_heartbeat(&p, true), 0);
    assert_int_equal(ps_gpio_set_heartbeat(&p, false), 0);
    assert_int_equal(ps_gpio_sim_heartbeat_edges(&g), 2);
}

/* Toggled every 1 ms the relay keeps power on; once the heartbeat stops the
 * power drops within the timeout, and comes back with the next beat. */
static void test_ps_gpio_sim_update_relay_stopped_heartbeat_power_off_within_timeout(void **state)
{
    (void)state;
    ps_gpio_sim_t g;
    ps_gpio_sim_init(&g);
    const ps_gpio_port_t p = ps_gpio_sim_port(&g);
    int64_t t = 0;
    for (int k = 0; k < 50; k++, t += MS) {
        assert_int_equal(ps_gpio_set_heartbeat(&p, (k & 1) != 0), 0);
        const bool is_on = ps_gpio_sim_update_relay(&g, t);
        if (k >= 1)
            assert_true(is_on); /* the first change is at k = 1 */
    }
    const int64_t t_last_edge = t - MS;
    int64_t t_off = -1;
    for (; t < t_last_edge + 3 * PS_GPIO_SIM_RELAY_TIMEOUT_NS; t += MS / 2) {
        if (!ps_gpio_sim_update_relay(&g, t) && t_off < 0)
            t_off = t;
    }
    assert_true(t_off > t_last_edge);
    assert_true(t_off <= t_last_edge + PS_GPIO_SIM_RELAY_TIMEOUT_NS);
    assert_false(ps_gpio_sim_is_power_on(&g));
    assert_int_equal(g.n_power_cuts, 1);
    assert_int_equal(ps_gpio_set_heartbeat(&p, false), 0); /* it was left high */
    assert_true(ps_gpio_sim_update_relay(&g, t));
}

/* A steady level, high or low, written every tick keeps no power on. */
static void test_ps_gpio_sim_update_relay_steady_level_no_power(void **state)
{
    (void)state;
    ps_gpio_sim_t g;
    ps_gpio_sim_init(&g);
    const ps_gpio_port_t p = ps_gpio_sim_port(&g);
    int64_t t = 0;
    for (int k = 0; k < 100; k++, t += MS) {
        assert_int_equal(ps_gpio_set_heartbeat(&p, true), 0);
        const bool is_on = ps_gpio_sim_update_relay(&g, t);
        if (t >= PS_GPIO_SIM_RELAY_TIMEOUT_NS)
            assert_false(is_on); /* one edge (low -> high) at t 0, then nothing */
    }
    ps_gpio_sim_init(&g);
    for (int k = 0; k < 100; k++, t += MS) {
        assert_int_equal(ps_gpio_set_heartbeat(&p, false), 0);
        assert_false(ps_gpio_sim_update_relay(&g, t));
    }
}

static void test_set_led_on_off_and_invalid(void **state)
{
    (void)state;
    ps_gpio_sim_t g;
    ps_gpio_sim_init(&g);
    ps_gpio_port_t p = ps_gpio_sim_port(&g);
    assert_int_equal(ps_gpio_set_led(&p, PS_GPIO_LED_ON), 0);
    assert_int_equal(ps_gpio_sim_get_led(&g), PS_GPIO_LED_ON);
    assert_int_equal(ps_gpio_set_led(&p, (ps_gpio_led_t)7), -EINVAL);
    assert_int_equal(ps_gpio_sim_get_led(&g), PS_GPIO_LED_ON);
    assert_int_equal(ps_gpio_set_led(&p, PS_GPIO_LED_OFF), 0);
    assert_int_equal(ps_gpio_sim_get_led(&g), PS_GPIO_LED_OFF);
    ps_gpio_close(&p);
    ps_gpio_close(&p); /* twice is safe */
}

/* ---- the port contract the libgpiod port keeps too (tests/contract) ---- */

static void sim_set_estop(void *ctx, bool is_pressed)
{
    ps_gpio_sim_set_estop(ctx, is_pressed);
}

static void sim_settle(void *ctx)
{
    (void)ctx; /* the simulated line has no kernel in between */
}

static bool sim_heartbeat_level(void *ctx)
{
    return atomic_load(&((ps_gpio_sim_t *)ctx)->heartbeat);
}

static bool sim_is_led_on(void *ctx)
{
    return ps_gpio_sim_get_led(ctx) == PS_GPIO_LED_ON;
}

static void sim_set_button(void *ctx, bool is_pressed)
{
    ps_gpio_sim_set_button(ctx, is_pressed);
}

static void test_ps_gpio_sim_keeps_the_port_contract(void **state)
{
    (void)state;
    ps_gpio_sim_t g;
    ps_gpio_sim_init(&g);
    const ps_gpio_contract_t c = {.port = ps_gpio_sim_port(&g),
                                  .ctx = &g,
                                  .set_estop = sim_set_estop,
                                  .settle = sim_settle,
                                  .heartbeat_level = sim_heartbeat_level,
                                  .is_led_on = sim_is_led_on,
                                  .set_button = sim_set_button};
    ps_gpio_contract_check(&c);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ps_gpio_sim_keeps_the_port_contract),
        cmocka_unit_test(test_ps_gpio_sim_init_released_heartbeat_low_power_off),
        cmocka_unit_test(test_ps_gpio_read_estop_follows_level),
        cmocka_unit_test(test_ps_gpio_read_estop_press_between_reads_seen_once),
        cmocka_unit_test(test_ps_gpio_set_heartbeat_counts_edges_only),
        cmocka_unit_test(test_ps_gpio_sim_update_relay_stopped_heartbeat_power_off_within_timeout),
        cmocka_unit_test(test_ps_gpio_sim_update_relay_steady_level_no_power),
        cmocka_unit_test(test_set_led_on_off_and_invalid),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
