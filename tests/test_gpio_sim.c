/* Tests of sim/ps_gpio_sim: simulated e-stop, enable and LED lines. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>

#include "../sim/ps_gpio_sim.h"

static void test_init_lines_released_enable_off(void **state)
{
    (void)state;
    ps_gpio_sim_t g;
    ps_gpio_sim_init(&g);
    const ps_gpio_port_t p = ps_gpio_sim_port(&g);
    bool is_pressed = true;
    assert_int_equal(ps_gpio_read_estop(&p, &is_pressed), 0);
    assert_false(is_pressed);
    assert_false(ps_gpio_sim_is_enabled(&g));
    assert_int_equal(ps_gpio_sim_get_led(&g), PS_GPIO_LED_OFF);
    assert_int_equal(ps_gpio_sim_enable_edges(&g), 0);
}

static void test_read_estop_follows_scenario(void **state)
{
    (void)state;
    ps_gpio_sim_t g;
    ps_gpio_sim_init(&g);
    const ps_gpio_port_t p = ps_gpio_sim_port(&g);
    bool is_pressed = false;
    ps_gpio_sim_set_estop(&g, true);
    assert_int_equal(ps_gpio_read_estop(&p, &is_pressed), 0);
    assert_true(is_pressed);
    ps_gpio_sim_set_estop(&g, false);
    assert_int_equal(ps_gpio_read_estop(&p, &is_pressed), 0);
    assert_false(is_pressed);
    assert_int_equal(ps_gpio_read_estop(&p, NULL), -EINVAL);
}

static void test_set_enable_counts_edges_only(void **state)
{
    (void)state;
    ps_gpio_sim_t g;
    ps_gpio_sim_init(&g);
    const ps_gpio_port_t p = ps_gpio_sim_port(&g);
    assert_int_equal(ps_gpio_set_enable(&p, false), 0); /* no change */
    assert_int_equal(ps_gpio_sim_enable_edges(&g), 0);
    assert_int_equal(ps_gpio_set_enable(&p, true), 0);
    assert_true(ps_gpio_sim_is_enabled(&g));
    assert_int_equal(ps_gpio_set_enable(&p, true), 0);
    assert_int_equal(ps_gpio_set_enable(&p, false), 0);
    assert_false(ps_gpio_sim_is_enabled(&g));
    assert_int_equal(ps_gpio_sim_enable_edges(&g), 2);
    assert_int_equal(atomic_load(&g.n_enable_edges), 2);
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

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_init_lines_released_enable_off),
        cmocka_unit_test(test_read_estop_follows_scenario),
        cmocka_unit_test(test_set_enable_counts_edges_only),
        cmocka_unit_test(test_set_led_on_off_and_invalid),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
