/*
 * ps_gpio_fake: a scripted GPIO port for tests of the loop.
 *
 * The test sets the e-stop level (or a latched press, as a press shorter
 * than a tick leaves it), reads back the heartbeat and LED outputs and a log
 * of every successful set call, and makes the next N calls of an op fail
 * with an error of its choice (the line then keeps its level).
 *
 * Threads: not thread-safe (one test thread). Allocation: none.
 */
#ifndef PS_GPIO_FAKE_H
#define PS_GPIO_FAKE_H

#include <stdbool.h>
#include <stddef.h> /* ps_gpio.h uses NULL without including it */
#include <stdint.h>

#include "../../drivers/ps_gpio.h"

#define PS_GPIO_FAKE_MAX_LOG 256u /**< set calls logged (more are counted only) */

typedef struct {
    int err;          /**< negative code the failing calls return */
    uint32_t n_calls; /**< how many upcoming calls fail */
} ps_gpio_fake_fault_t;

typedef struct {
    /* script (test may modify) */
    bool is_estop_pressed; /**< the level */
    bool is_estop_latched; /**< pressed since the last read; a read clears it */
    bool is_button_pressed; /**< the record button's level */
    bool is_button_latched; /**< a button press since the last read_button */
    ps_gpio_fake_fault_t read_fault;
    ps_gpio_fake_fault_t heartbeat_fault;
    ps_gpio_fake_fault_t led_fault;

    /* outputs and records (read-only) */
    bool heartbeat;
    ps_gpio_led_t led;
    bool heartbeat_log[PS_GPIO_FAKE_MAX_LOG]; /**< level of each successful set_heartbeat */
    ps_gpio_led_t led_log[PS_GPIO_FAKE_MAX_LOG];
    size_t n_heartbeat_calls; /**< successful set_heartbeat calls (log: min with MAX) */
    size_t n_led_calls;
    size_t n_heartbeat_edges; /**< level changes of the heartbeat output */
    size_t n_read_calls;      /**< every read_estop call, failed included */
    size_t n_button_reads;    /**< every read_button call */
    size_t n_close_calls;
} ps_gpio_fake_t;

/** @post f zeroed: released, heartbeat low, LED off, no script  @rt tests */
void ps_gpio_fake_init(ps_gpio_fake_t *f);

/** @return a port on f  @rt tests */
ps_gpio_port_t ps_gpio_fake_port(ps_gpio_fake_t *f);

/** The next n_calls calls of that op return err (< 0) and change nothing. */
void ps_gpio_fake_fail_read(ps_gpio_fake_t *f, int err, uint32_t n_calls);
void ps_gpio_fake_fail_heartbeat(ps_gpio_fake_t *f, int err, uint32_t n_calls);
void ps_gpio_fake_fail_led(ps_gpio_fake_t *f, int err, uint32_t n_calls);

#endif /* PS_GPIO_FAKE_H */
