#include "ps_gpio_fake.h"

#include <errno.h>
#include <string.h>

static int take_fault(ps_gpio_fake_fault_t *fault)
{
    if (fault->n_calls == 0)
        return 0;
    fault->n_calls--;
    return fault->err;
}

static int fake_read_estop(void *ctx, bool *out_pressed)
{
    ps_gpio_fake_t *f = ctx;
    f->n_read_calls++;
    const int err = take_fault(&f->read_fault);
    if (err != 0)
        return err;
    if (out_pressed == NULL)
        return -EINVAL;
    *out_pressed = f->is_estop_pressed;
    return 0;
}

static int fake_set_enable(void *ctx, bool is_enabled)
{
    ps_gpio_fake_t *f = ctx;
    const int err = take_fault(&f->enable_fault);
    if (err != 0)
        return err;
    if (f->n_enable_calls < PS_GPIO_FAKE_MAX_LOG)
        f->enable_log[f->n_enable_calls] = is_enabled;
    f->n_enable_calls++;
    if (f->is_enabled != is_enabled)
        f->n_enable_edges++;
    f->is_enabled = is_enabled;
    return 0;
}

static int fake_set_led(void *ctx, ps_gpio_led_t led)
{
    ps_gpio_fake_t *f = ctx;
    const int err = take_fault(&f->led_fault);
    if (err != 0)
        return err;
    if (f->n_led_calls < PS_GPIO_FAKE_MAX_LOG)
        f->led_log[f->n_led_calls] = led;
    f->n_led_calls++;
    f->led = led;
    return 0;
}

static void fake_close(void *ctx)
{
    ps_gpio_fake_t *f = ctx;
    f->n_close_calls++;
}

static const ps_gpio_ops_t FAKE_OPS = {
    .read_estop = fake_read_estop,
    .set_enable = fake_set_enable,
    .set_led = fake_set_led,
    .close = fake_close,
};

void ps_gpio_fake_init(ps_gpio_fake_t *f)
{
    memset(f, 0, sizeof *f);
    f->led = PS_GPIO_LED_OFF;
}

ps_gpio_port_t ps_gpio_fake_port(ps_gpio_fake_t *f)
{
    return (ps_gpio_port_t){.ops = &FAKE_OPS, .ctx = f};
}

void ps_gpio_fake_fail_read(ps_gpio_fake_t *f, int err, uint32_t n_calls)
{
    f->read_fault = (ps_gpio_fake_fault_t){.err = err, .n_calls = n_calls};
}

void ps_gpio_fake_fail_enable(ps_gpio_fake_t *f, int err, uint32_t n_calls)
{
    f->enable_fault = (ps_gpio_fake_fault_t){.err = err, .n_calls = n_calls};
}

void ps_gpio_fake_fail_led(ps_gpio_fake_t *f, int err, uint32_t n_calls)
{
    f->led_fault = (ps_gpio_fake_fault_t){.err = err, .n_calls = n_calls};
}
