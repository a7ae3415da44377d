/*
 * ps_gpio_sim: simulated GPIO lines (e-stop input, heartbeat output, LED)
 * and the external watchdog relay that feeds the emulated drives' power
 * stage (drivers/ps_gpio.h gives the rule).
 *
 * The scenario (plant side) presses and releases the e-stop; the loop reads
 * it through a ps_gpio_port_t as "pressed since the last read": a press is
 * latched until the next read, so one shorter than a tick is still seen.
 * The loop toggles the heartbeat; the plant side evaluates the relay at each
 * physics step with ps_gpio_sim_update_relay: power is on while the heartbeat
 * changed level within PS_GPIO_SIM_RELAY_TIMEOUT_NS of that step's time
 * (off at init, until the first change). The relay samples the edge count at
 * the physics step, so an edge counts from the first step after it (0.5 ms
 * resolution on ps1).
 *
 * Lines are C11 atomics, so the two sides may be on different threads; the
 * relay state is the plant side's only. Allocation: none (caller owns the
 * struct).
 */
#ifndef PS_GPIO_SIM_H
#define PS_GPIO_SIM_H

#include <stdatomic.h>
#include <stdbool.h>
#include <stddef.h> /* ps_gpio.h uses NULL without including it */
#include <stdint.h>

#include "../drivers/ps_gpio.h"

/** The emulated relay's timeout: the contract's (10 ms, 10 servo periods). */
#define PS_GPIO_SIM_RELAY_TIMEOUT_NS PS_GPIO_HEARTBEAT_TIMEOUT_NS

typedef struct {
    atomic_bool is_estop_pressed; /**< the level now */
    atomic_bool is_estop_latched; /**< pressed since the last read */
    atomic_bool is_button_pressed; /**< record button: the level now */
    atomic_bool is_button_latched; /**< record button: pressed since the last read */
    atomic_bool heartbeat;        /**< level last set by the loop */
    atomic_int led;
    atomic_uint_fast64_t n_heartbeat_edges; /**< heartbeat level changes seen */
    /* relay, plant side only (read-only for others) */
    uint64_t relay_n_edges_seen;
    int64_t relay_last_edge_ns;
    bool has_relay_edge;
    bool is_power_on;
    uint64_t n_power_cuts; /**< on -> off changes of the relay */
} ps_gpio_sim_t;

/** @post e-stop released and not latched, heartbeat low, no edge, relay off
 *  @rt INIT */
void ps_gpio_sim_init(ps_gpio_sim_t *g);

/** @return the loop-side port  @rt INIT */
ps_gpio_port_t ps_gpio_sim_port(ps_gpio_sim_t *g);

/* Port semantics: read_estop (and read_button, the record button) -EINVAL
 * on out NULL (latch kept), else pressed now or latched since the previous
 * read, and clears the latch;
 * set_heartbeat counts an edge only when the level changes; set_led -EINVAL
 * on a value other than OFF/ON (line unchanged); close is a no-op. */

/** Plant/scenario side: set the e-stop level; a press also latches until the
 *  loop's next read. @rt RT-SAFE, any thread */
void ps_gpio_sim_set_estop(ps_gpio_sim_t *g, bool is_pressed);

/** Plant/scenario side: the record button, as the e-stop (a press latches
 *  until the loop's next read_button).  @rt RT-SAFE, any thread */
void ps_gpio_sim_set_button(ps_gpio_sim_t *g, bool is_pressed);

/** Evaluate the watchdog relay at time now_ns (non-decreasing between calls):
 *  a heartbeat edge since the previous call counts as made at now_ns.
 *  @return whether the drives' power is on  @units ns
 *  @rt RT-SAFE O(1), plant side (one thread) */
bool ps_gpio_sim_update_relay(ps_gpio_sim_t *g, int64_t now_ns);

/** @return the relay's state at its last update  @rt RT-SAFE, plant side */
bool ps_gpio_sim_is_power_on(const ps_gpio_sim_t *g);

/** @return the LED line as last set by the loop  @rt RT-SAFE, any thread */
ps_gpio_led_t ps_gpio_sim_get_led(const ps_gpio_sim_t *g);

/** @return heartbeat level changes seen so far  @rt RT-SAFE, any thread */
uint64_t ps_gpio_sim_heartbeat_edges(const ps_gpio_sim_t *g);

#endif /* PS_GPIO_SIM_H */
