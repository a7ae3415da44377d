/*
 * ps_gpio_sim: simulated GPIO lines as C11 atomics and the watchdog relay
 * (see ps_gpio_sim.h). Relaxed ordering is enough: each line is an
 * independent value, and nothing else is published through it.
 */
#include "ps_gpio_sim.h"

#include <errno.h>

static int sim_read_estop(void *ctx, bool *out_pressed_since_last_read)
{
    ps_gpio_sim_t *g = ctx;
    if (out_pressed_since_last_read == NULL)
        return -EINVAL;
    /* latch first: a press between the two loads is then seen now or next time */
    const bool was_latched =
        atomic_exchange_explicit(&g->is_estop_latched, false, memory_order_relaxed);
    const bool is_pressed = atomic_load_explicit(&g->is_estop_pressed, memory_order_relaxed);
    *out_pressed_since_last_read = is_pressed || was_latched;
    return 0;
}

static int sim_read_button(void *ctx, bool *out_pressed_since_last_read)
{
    ps_gpio_sim_t *g = ctx;
    if (out_pressed_since_last_read == NULL)
        return -EINVAL;
    const bool was_latched =
        atomic_exchange_explicit(&g->is_button_latched, false, memory_order_relaxed);
    const bool is_pressed = atomic_load_explicit(&g->is_button_pressed, memory_order_relaxed);
    *out_pressed_since_last_read = is_pressed || was_latched;
    return 0;
}

static int sim_set_heartbeat(void *ctx, bool level)
{
    ps_gpio_sim_t *g = ctx;
    const bool was = atomic_exchange_explicit(&g->heartbeat, level, memory_order_relaxed);
    if (was != level)
        atomic_fetch_add_explicit(&g->n_heartbeat_edges, 1, memory_order_relaxed);
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
    .set_heartbeat = sim_set_heartbeat,
    .set_led = sim_set_led,
    .close = sim_close,
    .read_button = sim_read_button,
};

void ps_gpio_sim_init(ps_gpio_sim_t *g)
{
    atomic_init(&g->is_estop_pressed, false);
    atomic_init(&g->is_estop_latched, false);
    atomic_init(&g->is_button_pressed, false);
    atomic_init(&g->is_button_latched, false);
    atomic_init(&g->heartbeat, false);
    atomic_init(&g->led, (int)PS_GPIO_LED_OFF);
    atomic_init(&g->n_heartbeat_edges, 0);
    g->relay_n_edges_seen = 0;
    g->relay_last_edge_ns = 0;
    g->has_relay_edge = false;
    g->is_power_on = false;
    g->n_power_cuts = 0;
}

ps_gpio_port_t ps_gpio_sim_port(ps_gpio_sim_t *g)
{
    return (ps_gpio_port_t){.ops = &SIM_OPS, .ctx = g};
}

void ps_gpio_sim_set_estop(ps_gpio_sim_t *g, bool is_pressed)
{
    atomic_store_explicit(&g->is_estop_pressed, is_pressed, memory_order_relaxed);
    if (is_pressed)
        atomic_store_explicit(&g->is_estop_latched, true, memory_order_relaxed);
}

void ps_gpio_sim_set_button(ps_gpio_sim_t *g, bool is_pressed)
{
    atomic_store_explicit(&g->is_button_pressed, is_pressed, memory_order_relaxed);
    if (is_pressed)
        atomic_store_explicit(&g->is_button_latched, true, memory_order_relaxed);
}

bool ps_gpio_sim_update_relay(ps_gpio_sim_t *g, int64_t now_ns)
{
    const uint64_t n = atomic_load_explicit(&g->n_heartbeat_edges, memory_order_relaxed);
    if (n != g->relay_n_edges_seen) {
        g->relay_n_edges_seen = n;
        g->relay_last_edge_ns = now_ns;
        g->has_relay_edge = true;
    }
    const bool is_on =
        g->has_relay_edge && now_ns - g->relay_last_edge_ns < PS_GPIO_SIM_RELAY_TIMEOUT_NS;
    if (g->is_power_on && !is_on)
        g->n_power_cuts++;
    g->is_power_on = is_on;
    return is_on;
}

bool ps_gpio_sim_is_power_on(const ps_gpio_sim_t *g)
{
    return g->is_power_on;
}

ps_gpio_led_t ps_gpio_sim_get_led(const ps_gpio_sim_t *g)
{
    return (ps_gpio_led_t)atomic_load_explicit(&g->led, memory_order_relaxed);
}

uint64_t ps_gpio_sim_heartbeat_edges(const ps_gpio_sim_t *g)
{
    return atomic_load_explicit(&g->n_heartbeat_edges, memory_order_relaxed);
}
