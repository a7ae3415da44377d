#include "ps_gpio_contract.h"

#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

static bool read_estop(const ps_gpio_contract_t *c)
{
    bool is_pressed = true;
    assert_int_equal(ps_gpio_read_estop(&c->port, &is_pressed), 0);
    return is_pressed;
}

static bool read_button(const ps_gpio_contract_t *c)
{
    bool is_pressed = true;
    assert_int_equal(ps_gpio_read_button(&c->port, &is_pressed), 0);
    return is_pressed;
}

/* One input with "pressed since the last read" semantics (the e-stop, the
 * record button). */
static void check_input(const ps_gpio_contract_t *c, bool (*read)(const ps_gpio_contract_t *),
                        void (*set)(void *, bool))
{
    c->settle(c->ctx);
    assert_false(read(c));
    assert_false(read(c));
    set(c->ctx, true); /* held */
    c->settle(c->ctx);
    assert_true(read(c));
    assert_true(read(c));
    set(c->ctx, false);
    c->settle(c->ctx);
    /* the release itself: the press may still be the latched answer once */
    (void)read(c);
    assert_false(read(c));
    set(c->ctx, true); /* a press shorter than a tick */
    c->settle(c->ctx);
    set(c->ctx, false);
    c->settle(c->ctx);
    assert_true(read(c));  /* reported once */
    assert_false(read(c)); /* then released */
}

static void check_estop(const ps_gpio_contract_t *c)
{
    check_input(c, read_estop, c->set_estop);
}

static void check_button(const ps_gpio_contract_t *c)
{
    if (c->set_button != NULL) {
        check_input(c, read_button, c->set_button);
        return;
    }
    assert_false(read_button(c)); /* no button: never pressed */
}

static void check_outputs(const ps_gpio_contract_t *c)
{
    for (int i = 0; i < 6; i++) {
        const bool level = (i & 1) != 0;
        assert_int_equal(ps_gpio_set_heartbeat(&c->port, level), 0);
        assert_int_equal(c->heartbeat_level(c->ctx), level);
    }
    assert_int_equal(ps_gpio_set_heartbeat(&c->port, true), 0);
    assert_int_equal(ps_gpio_set_heartbeat(&c->port, true), 0);
    assert_true(c->heartbeat_level(c->ctx));
    assert_int_equal(ps_gpio_set_led(&c->port, PS_GPIO_LED_ON), 0);
    assert_true(c->is_led_on(c->ctx));
    assert_int_equal(ps_gpio_set_led(&c->port, PS_GPIO_LED_OFF), 0);
    assert_false(c->is_led_on(c->ctx));
}

void ps_gpio_contract_check(const ps_gpio_contract_t *c)
{
    check_estop(c);
    check_button(c);
    check_outputs(c);
}
