/*
 * ps_gpio: the GPIO port interface (e-stop input, heartbeat output to the
 * drives' power relay, status LED).
 *
 * Implementations: drivers/ps_gpio_gpiod.c (libgpiod v1.6),
 * sim/ps_gpio_sim.c, tests/fakes/ps_gpio_fake.c.
 *
 * E-stop: active when pressed. The loop reads it once a tick, so a press
 * shorter than a tick would be lost if read as a level: read_estop reports
 * "pressed since the last read", latched inside the implementation (an edge
 * interrupt or an edge event on real hardware): true if the input is pressed
 * now OR was pressed at any time since the previous read_estop call (the
 * first call: since open). The state machine latches e-stop on the first
 * read that says pressed, so whatever debounce there is lives below this
 * interface: the gpiod port debounces in software (estop_debounce_us: a
 * press counts once the line has been pressed for that long without a
 * break, a glitch shorter than that is ignored; 0 = the first edge counts),
 * because libgpiod v1 and the v1 kernel interface have none. The sim and
 * the fake debounce nothing: their lines do not bounce.
 *
 * Heartbeat: the drives' power stage is fed through an external watchdog
 * relay, not switched by a level: the relay keeps power on only while the
 * heartbeat output changed level within the last PS_GPIO_HEARTBEAT_TIMEOUT_NS,
 * and drops it otherwise (at power-up too, until the first change). The loop
 * toggles it every tick while it wants the drives powered; to cut power it
 * holds the level still (in ESTOP, at the end of a run), and a loop that stops
 * ticking (hung, crashed, killed) cuts power the same way. A steady level,
 * high or low, proves nothing and keeps no power on.
 *
 * Record button (optional): a push button that asks the flight recorder
 * for a dump (rt/ps_recorder.h). read_button has the e-stop's semantics
 * (pressed now or at any time since the previous read) without debounce;
 * a port without the button has read_button NULL, and ps_gpio_read_button
 * then reads "not pressed".
 *
 * Threads: loop thread only. Allocation: none.
 */
#ifndef PS_GPIO_H
#define PS_GPIO_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "../rt/ps_limits.h"

/** Bias (pull) of the e-stop input, set when the line is requested. */
typedef enum {
    PS_GPIO_BIAS_AS_IS = 0, /**< leave what firmware or device tree set */
    PS_GPIO_BIAS_PULL_UP,
    PS_GPIO_BIAS_PULL_DOWN,
    PS_GPIO_BIAS_DISABLED,
} ps_gpio_bias_t;

/** The longest e-stop debounce a board may ask for: a contact that bounces
 *  for longer is broken, and every microsecond of it delays an e-stop. */
#define PS_GPIO_DEBOUNCE_MAX_US 20000u

/** GPIO lines of a board (board file, `gpio:`), for the libgpiod port. Each
 *  line is given by offset on the chip or, where its *_name is not empty, by
 *  the line's name (`gpioinfo` shows both); a zeroed struct plus chip and
 *  offsets is the old, offset-only configuration. */
typedef struct {
    char chip[PS_NAME_LEN]; /**< "gpiochip0", a chip label, a number or a /dev path */
    uint32_t estop_line;    /**< offset; unused when estop_name is set */
    bool is_estop_active_low;
    uint32_t enable_line;          /**< heartbeat output; unused when enable_name is set */
    uint32_t led_line;             /**< unused when led_name is set */
    char estop_name[PS_NAME_LEN];  /**< "" = use estop_line */
    char enable_name[PS_NAME_LEN]; /**< "" = use enable_line */
    char led_name[PS_NAME_LEN];    /**< "" = use led_line */
    ps_gpio_bias_t estop_bias;
    /** A change of the e-stop input counts once it has held this long
     *  (press and release alike); 0 = the first edge counts. */
    uint32_t estop_debounce_us;
    bool has_button;                /**< a record button line (flight recorder trigger) */
    uint32_t button_line;           /**< offset; unused when button_name is set */
    char button_name[PS_NAME_LEN];  /**< "" = use button_line */
    bool is_button_active_low;
} ps_gpio_cfg_t;

/** The watchdog relay drops the drives' power when the heartbeat has not
 *  changed level for this long: 10 servo periods at 1 kHz. */
#define PS_GPIO_HEARTBEAT_TIMEOUT_NS 10000000LL

typedef enum {
    PS_GPIO_LED_OFF = 0,
    PS_GPIO_LED_ON,
} ps_gpio_led_t;

typedef struct {
    /** @post *out_pressed_since_last_read written on success: pressed now or
     *  at any time since the previous call; the latch is cleared
     *  @return 0 | -errno (latch kept)  @rt RT-SAFE */
    int (*read_estop)(void *ctx, bool *out_pressed_since_last_read);
    /** Drive the heartbeat output to `level`; the relay sees a beat only when
     *  the level changes. @return 0 | -errno  @rt RT-SAFE */
    int (*set_heartbeat)(void *ctx, bool level);
    /** @return 0 | -errno  @rt RT-SAFE */
    int (*set_led)(void *ctx, ps_gpio_led_t led);
    /** Release lines. Safe to call twice. @rt INIT */
    void (*close)(void *ctx);
    /** The record button, as read_estop (no debounce). NULL: no button.
     *  @return 0 | -errno  @rt RT-SAFE */
    int (*read_button)(void *ctx, bool *out_pressed_since_last_read);
} ps_gpio_ops_t;

typedef struct {
    const ps_gpio_ops_t *ops;
    void *ctx;
} ps_gpio_port_t;

static inline int ps_gpio_read_estop(const ps_gpio_port_t *p, bool *out_pressed_since_last_read)
{
    return p->ops->read_estop(p->ctx, out_pressed_since_last_read);
}
/** @post *out false when the port has no record button  @return as read_button */
static inline int ps_gpio_read_button(const ps_gpio_port_t *p, bool *out_pressed_since_last_read)
{
    if (p->ops->read_button == NULL) {
        *out_pressed_since_last_read = false;
        return 0;
    }
    return p->ops->read_button(p->ctx, out_pressed_since_last_read);
}
static inline int ps_gpio_set_heartbeat(const ps_gpio_port_t *p, bool level)
{
    return p->ops->set_heartbeat(p->ctx, level);
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
