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

static int fake_read_estop(void *ctx, bool *out_pressed_since_last_read)
{
    ps_gpio_fake_t *f = ctx;
    f->n_read_calls++;
    const int err = take_fault(&f->read_fault);
    if (err != 0)
        return err;
    if (out_pressed_since_last_read == NULL)
        return -EINVAL;
    *out_pressed_since_last_read = f->is_estop_pressed || f->is_estop_latched;
    f->is_estop_latched = false;
    return 0;
}

static int fake_read_button(void *ctx, bool *out_pressed_since_last_read)
{
    ps_gpio_fake_t *f = ctx;
    f->n_button_reads++;
    if (out_pressed_since_last_read == NULL)
        return -EINVAL;
    *out_pressed_since_last_read = f->is_button_pressed || f->is_button_latched;
    f->is_button_latched = false;
    return 0;
}

static int fake_set_heartbeat(void *ctx, bool level)
{
    ps_gpio_fake_t *f = ctx;
    const int err = take_fault(&f->heartbeat_fault);
    if (err != 0)
        return err;
    if (f->n_heartbeat_calls < PS_GPIO_FAKE_MAX_LOG)
        f->heartbeat_log[f->n_heartbeat_calls] = level;
    f->n_heartbeat_calls++;
    if (f->heartbeat != level)
        f->n_heartbeat_edges++;
    f->heartbeat = level;
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
    .read_button = fake_read_button,
    .set_heartbeat = fake_set_heartbeat,
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

void ps_gpio_fake_fail_heartbeat(ps_gpio_fake_t *f, int err, uint32_t n_calls)
{
    f->heartbeat_fault = (ps_gpio_fake_fault_t){.err = err, .n_calls = n_calls};
}

void ps_gpio_fake_fail_led(ps_gpio_fake_t *f, int err, uint32_t n_calls)
{
    f->led_fault = (ps_gpio_fake_fault_t){.err = err, .n_calls = n_calls};
}
