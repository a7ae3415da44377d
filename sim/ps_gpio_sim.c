/*
 * ps_gpio_sim: simulated GPIO lines as C11 atomics (see ps_gpio_sim.h).
 * Relaxed ordering is enough: each line is an independent value, and nothing
 * else is published through it.
 */
#include "ps_gpio_sim.h"

#include <errno.h>

static int sim_read_estop(void *ctx, bool *out_pressed)
{
    ps_gpio_sim_t *g = ctx;
    if (out_pressed == NULL)
        return -EINVAL;
    *out_pressed = atomic_load_explicit(&g->is_estop_pressed, memory_order_relaxed);
    return 0;
}

static int sim_set_enable(void *ctx, bool is_enabled)
{
    ps_gpio_sim_t *g = ctx;
    const bool was = atomic_exchange_explicit(&g->is_enabled, is_enabled, memory_order_relaxed);
    if (was != is_enabled)
        atomic_fetch_add_explicit(&g->n_enable_edges, 1, memory_order_relaxed);
    return 0;
}

static int sim_set_led(void *ctx, ps_gpio_led_t led)
{
    ps_gpio_sim_t *g = ctx;
    if (led != PS_GPIO_LED_OFF && led != PS_GPIO_LED_ON)
        return -EINVAL;
    atomic_store_explicit(&g->led, (int)led, memory_order_relaxed);
    return 0;
}

static void sim_close(void *ctx)
{
    (void)ctx; /* nothing to release: the caller owns the struct */
}

static const ps_gpio_ops_t SIM_OPS = {
    .read_estop = sim_read_estop,
    .set_enable = sim_set_enable,
    .set_led = sim_set_led,
    .close = sim_close,
};

void ps_gpio_sim_init(ps_gpio_sim_t *g)
{
    atomic_init(&g->is_estop_pressed, false);
    atomic_init(&g->is_enabled, false);
    atomic_init(&g->led, (int)PS_GPIO_LED_OFF);
    atomic_init(&g->n_enable_edges, 0);
}

ps_gpio_port_t ps_gpio_sim_port(ps_gpio_sim_t *g)
{
    return (ps_gpio_port_t){.ops = &SIM_OPS, .ctx = g};
}

void ps_gpio_sim_set_estop(ps_gpio_sim_t *g, bool is_pressed)
{
    atomic_store_explicit(&g->is_estop_pressed, is_pressed, memory_order_relaxed);
}

bool ps_gpio_sim_is_enabled(const ps_gpio_sim_t *g)
{
    return atomic_load_explicit(&g->is_enabled, memory_order_relaxed);
}

ps_gpio_led_t ps_gpio_sim_get_led(const ps_gpio_sim_t *g)
{
    return (ps_gpio_led_t)atomic_load_explicit(&g->led, memory_order_relaxed);
}

uint64_t ps_gpio_sim_enable_edges(const ps_gpio_sim_t *g)
{
    return atomic_load_explicit(&g->n_enable_edges, memory_order_relaxed);
}
