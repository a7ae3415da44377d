/*
 * ps_gpio: the GPIO port interface (e-stop input, enable output, status LED).
 *
 * Implementations: drivers/ps_gpio_gpiod.c (libgpiod v1.6, later),
 * sim/ps_gpio_sim.c, tests/fakes/ps_gpio_fake.c. The e-stop input is
 * active when pressed; implementations debounce nothing, the state machine
 * latches e-stop on the first sample that reads pressed.
 *
 * Threads: loop thread only. Allocation: none.
 */
#ifndef PS_GPIO_H
#define PS_GPIO_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "../rt/ps_limits.h"

/** GPIO lines of a board (board file, `gpio:`), for the libgpiod port. */
typedef struct {
    char chip[PS_NAME_LEN]; /**< "gpiochip0" */
    uint32_t estop_line;
    bool is_estop_active_low;
    uint32_t enable_line;
    uint32_t led_line;
} ps_gpio_cfg_t;

typedef enum {
    PS_GPIO_LED_OFF = 0,
    PS_GPIO_LED_ON,
} ps_gpio_led_t;

typedef struct {
    /** @post *out_pressed written on success  @return 0 | -errno  @rt RT-SAFE */
    int (*read_estop)(void *ctx, bool *out_pressed);
    /** Drive the power-stage enable output. @return 0 | -errno  @rt RT-SAFE */
    int (*set_enable)(void *ctx, bool is_enabled);
    /** @return 0 | -errno  @rt RT-SAFE */
    int (*set_led)(void *ctx, ps_gpio_led_t led);
    /** Release lines. Safe to call twice. @rt INIT */
    void (*close)(void *ctx);
} ps_gpio_ops_t;

typedef struct {
    const ps_gpio_ops_t *ops;
    void *ctx;
} ps_gpio_port_t;

static inline int ps_gpio_read_estop(const ps_gpio_port_t *p, bool *out_pressed)
{
    return p->ops->read_estop(p->ctx, out_pressed);
}
static inline int ps_gpio_set_enable(const ps_gpio_port_t *p, bool is_enabled)
{
    return p->ops->set_enable(p->ctx, is_enabled);
}
static inline int ps_gpio_set_led(const ps_gpio_port_t *p, ps_gpio_led_t led)
{
    return p->ops->set_led(p->ctx, led);
}
static inline void ps_gpio_close(ps_gpio_port_t *p)
{
    if (p->ops != NULL && p->ops->close != NULL)
        p->ops->close(p->ctx);
}

#endif /* PS_GPIO_H */
