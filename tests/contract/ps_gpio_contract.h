/*
 * ps_gpio_contract: the GPIO port contract of drivers/ps_gpio.h as one cmocka
 * check, run against the simulated lines (tests/test_gpio_sim.c) and the
 * libgpiod port on gpio-mockup (tests/hw/test_hw_gpio.c, in the VM). The far
 * end presses and releases the e-stop and reads the outputs back.
 *
 * What every port must do (debounce 0): read_estop says released while the
 * line is released; pressed while it is held; a press and release between two
 * reads is reported once, by the next read, then released again; the
 * heartbeat and LED outputs show the level last set; setting the same
 * heartbeat level twice is no change at the far end. A port with the record
 * button (set_button given) reads it as the e-stop: released, held, a press
 * between two reads reported once; a port without it reads "not pressed".
 *
 * Threads: the test thread. Allocation: none.
 */
#ifndef PS_GPIO_CONTRACT_H
#define PS_GPIO_CONTRACT_H

#include <stdbool.h>

#include "../../drivers/ps_gpio.h"

typedef struct {
    ps_gpio_port_t port; /**< under test, opened, e-stop released, no debounce */
    void *ctx;
    /** Press (true) or release the e-stop at the far end. */
    void (*set_estop)(void *ctx, bool is_pressed);
    /** Let an edge reach the port (an edge event through the kernel). */
    void (*settle)(void *ctx);
    /** The far end's view of the heartbeat line and the LED line. */
    bool (*heartbeat_level)(void *ctx);
    bool (*is_led_on)(void *ctx);
    /** Press or release the record button at the far end; NULL: the port
     *  has none (read_button must then say not pressed). */
    void (*set_button)(void *ctx, bool is_pressed);
} ps_gpio_contract_t;

/** Run every check; fails the calling cmocka test on the first violation. */
void ps_gpio_contract_check(const ps_gpio_contract_t *c);

#endif /* PS_GPIO_CONTRACT_H */
