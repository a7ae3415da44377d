/*
 * ps_gpio_sim: simulated GPIO lines (e-stop input, enable output, LED).
 * The scenario (plant side) presses and releases the e-stop; the loop reads
 * it through a ps_gpio_port_t. Lines are C11 atomics, so the two sides may be
 * on different threads. Allocation: none (caller owns the struct).
 */
#ifndef PS_GPIO_SIM_H
#define PS_GPIO_SIM_H

#include <stdatomic.h>
#include <stdbool.h>
#include <stddef.h> /* ps_gpio.h uses NULL without including it */
#include <stdint.h>

#include "../drivers/ps_gpio.h"

typedef struct {
    atomic_bool is_estop_pressed;
    atomic_bool is_enabled;
    atomic_int led;
    atomic_uint_fast64_t n_enable_edges; /**< enable output changes seen */
} ps_gpio_sim_t;

/** @post lines released, enable off  @rt INIT */
void ps_gpio_sim_init(ps_gpio_sim_t *g);

/** @return the loop-side port  @rt INIT */
ps_gpio_port_t ps_gpio_sim_port(ps_gpio_sim_t *g);

/* Port semantics: read_estop -EINVAL on out NULL; set_enable counts an edge
 * only when the level changes; set_led -EINVAL on a value other than
 * OFF/ON (line unchanged); close is a no-op. */

/** Plant/scenario side. @rt RT-SAFE, any thread */
void ps_gpio_sim_set_estop(ps_gpio_sim_t *g, bool is_pressed);
bool ps_gpio_sim_is_enabled(const ps_gpio_sim_t *g);

/** @return the LED line as last set by the loop  @rt RT-SAFE, any thread */
ps_gpio_led_t ps_gpio_sim_get_led(const ps_gpio_sim_t *g);

/** @return enable output changes seen so far  @rt RT-SAFE, any thread */
uint64_t ps_gpio_sim_enable_edges(const ps_gpio_sim_t *g);

#endif /* PS_GPIO_SIM_H */
