/*
 * ps_gpio_gpiod: the GPIO port (drivers/ps_gpio.h) on libgpiod v1.6 (the v1
 * API of Debian 12's libgpiod-dev 1.6.3, over the kernel's GPIO v1 uAPI).
 *
 * Lines: the e-stop input, the heartbeat output (to the drives' watchdog
 * relay) and the status LED output, each by offset or by name on one chip
 * (ps_gpio_cfg_t). Consumers show in `gpioinfo` as "pushstep-estop",
 * "pushstep-heartbeat" and "pushstep-led".
 *
 * E-stop: requested for both-edge events, with the configured active-low
 * flag and bias. The event fd is non-blocking; each read_estop drains the
 * queued events (gpiod_line_event_read_fd_multiple, 16 a read: the kernel's
 * FIFO size; at most 4 reads a call, so a line bouncing faster than the tick
 * cannot hold the tick: the rest waits, counted in n_event_reads_capped) and
 * feeds them with their kernel timestamps to the debounce below, then reads
 * the line's level once (an ioctl).
 *
 * How events are taken: with both edges requested, the v1 uAPI stamps an
 * event in the hard IRQ handler but sets its type (rising/falling) from the
 * level its IRQ thread reads later, so a pulse shorter than the IRQ thread's
 * latency comes as two events of one type, or (two edges merged into one
 * interrupt) one event of the level it returned to. So the type is not
 * trusted: each event is one change of level at its timestamp. The level
 * read after the drain corrects the result: where it differs from what the
 * events said (edges dropped from a full FIFO, which a bouncing contact can
 * fill within a tick; edges stamped but not yet queued by a lagging IRQ
 * thread), it is taken as a change at the time of that read ("level fix"),
 * and events stamped at or before a level fix are skipped when they arrive
 * (the fix already counted them). Cost of the scheme: a pulse merged into one
 * interrupt lasts, for the debounce, until the next read (errs toward
 * pressed); and on chips whose IRQs are nested threads (I2C/SPI expanders,
 * stamped in the thread), a stamp can fall after the fix that saw its edge,
 * which shows as one tick of the opposite level, corrected by the next read.
 *
 * The line is read at open too, so a button already pressed at start counts
 * on the first read_estop.
 *
 * Event timestamps are CLOCK_MONOTONIC on kernels >= 5.7 (CLOCK_REALTIME
 * before): open checks the kernel release, and on older kernels read_estop
 * moves the stamps onto CLOCK_MONOTONIC by the clocks' difference at the
 * read. A stamp later than the read (a clock step) is taken as the read.
 *
 * Record button (optional, cfg has_button): requested for both-edge events
 * (active-low from cfg), fd non-blocking. read_button drains its events
 * (bounded as the e-stop's) and reads its level: pressed now, or an edge
 * since the last read that can only mean a press happened (the first edge
 * after a read that said released, or two or more edges); no debounce: a
 * bounce only repeats "pressed", and the recorder takes each press once.
 * An edge stamped before the last level read but queued after it (a loaded
 * host, seen in a VM) is already in the level that read saw: one such edge
 * (a late release) is no new press; two or more are a whole press that read
 * may have missed, and are reported (erring toward pressed).
 *
 * Heartbeat and LED: requested as outputs, initially low/off;
 * set_heartbeat/set_led are one GPIOHANDLE_SET_LINE_VALUES ioctl each. close
 * drives both low before it releases the lines (the orderly exit path); a
 * process that dies without close leaves the heartbeat still, which the relay
 * sees as a stopped loop (drivers/ps_gpio.h).
 *
 * Threads: the port is used by one thread (the loop). Allocation: open
 * allocates (libgpiod's chip and line structs); read_estop, set_heartbeat and
 * set_led allocate nothing, take no lock, print nothing and never block on
 * a SoC's own GPIO block (the boards' e-stop and enable lines). On lines of
 * an I2C or SPI GPIO expander each get/set ioctl is a bus transfer under the
 * expander driver's mutex: keep the loop's lines on the SoC.
 * The caller owns ps_gpio_gpiod_t.
 */
#ifndef PS_GPIO_GPIOD_H
#define PS_GPIO_GPIOD_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "ps_gpio.h"

/* ---- software debounce (pure, host-testable) ----------------------------
 *
 * A two-level filter over timestamped edges: `raw` is the input's latest
 * level and since when it has held; `is_pressed` is the debounced level,
 * which follows raw once raw has held for debounce_ns without a change (a
 * press and a release alike). A debounced press also sets a latch, so a
 * press that was stable for debounce_ns and then released between two reads
 * is still reported by the next take. The stable time is judged from edge
 * times and, between edges, from the time given to poll: a press that is
 * still held counts as soon as a poll comes debounce_ns after its edge.
 *
 * debounce_ns 0: every press edge counts at once (and latches), every
 * release too: the behaviour of a port without debounce.
 *
 * Times are CLOCK_MONOTONIC ns; a time earlier than one already seen is
 * taken as that one (edges read late never move the filter backwards).
 */
typedef struct {
    int64_t debounce_ns;  /**< read-only after init */
    bool is_raw_pressed;  /**< the input's latest level */
    int64_t raw_since_ns; /**< when it took that level */
    bool is_pressed;      /**< debounced level */
    bool is_latched;      /**< a debounced press since the last take */
    int64_t last_ns;      /**< latest time seen */
} ps_gpio_debounce_t;

/** Start the filter with the input's level at now_ns. That level counts as
 *  already stable: a button held at start is reported by the first take
 *  (it has been held for longer than anyone can tell).
 *  @pre debounce_ns >= 0  @units debounce_ns, now_ns
 *  @post *d ready  @rt RT-SAFE O(1), pure */
void ps_gpio_debounce_init(ps_gpio_debounce_t *d, int64_t debounce_ns, bool is_pressed,
                           int64_t now_ns);

/** The input was seen at level is_pressed at t_ns (an edge event; a level
 *  equal to the current one is a no-op, so duplicate or re-read levels are
 *  harmless). The level held before t_ns is judged first.
 *  @pre init  @units t_ns  @rt RT-SAFE O(1), pure */
void ps_gpio_debounce_edge(ps_gpio_debounce_t *d, bool is_pressed, int64_t t_ns);

/** No edge up to now_ns: judge whether the input's level has held long
 *  enough to become the debounced level.
 *  @pre init  @units now_ns  @rt RT-SAFE O(1), pure */
void ps_gpio_debounce_poll(ps_gpio_debounce_t *d, int64_t now_ns);

/** @return debounced pressed now, or a debounced press since the previous
 *  take (the first: since init); clears the latch  @pre init
 *  @rt RT-SAFE O(1) */
bool ps_gpio_debounce_take_pressed(ps_gpio_debounce_t *d);

/** The record button's answer to one read (no debounce, see above): pressed
 *  now, or edges since the last read that can only mean a press happened.
 *  n_new_edges: edges stamped after the previous level read; n_late_edges:
 *  edges stamped before it but read only now (one is already in that read's
 *  level; two or more are a whole press it may have missed).
 *  @return true: report a press  @rt RT-SAFE O(1), pure */
bool ps_gpio_button_pressed(bool is_level_pressed, bool was_level_pressed, uint64_t n_new_edges,
                            uint64_t n_late_edges);

/* ---- the port ------------------------------------------------------------ */

struct gpiod_chip;
struct gpiod_line;

typedef struct {
    struct gpiod_chip *chip; /**< NULL when closed */
    struct gpiod_line *estop;
    struct gpiod_line *heartbeat;
    struct gpiod_line *led;
    struct gpiod_line *button; /**< the record button; NULL: none */
    int estop_fd;              /**< the e-stop's event fd, O_NONBLOCK; -1 when closed */
    int button_fd;             /**< the button's event fd, O_NONBLOCK; -1: none */
    bool was_button_pressed;   /**< the button's level at the last read_button */
    uint32_t button_offset;    /**< read-only */
    uint64_t n_button_events;  /**< read-only: button edge events read */
    uint64_t
        n_button_events_covered; /**< read-only: of those, stamped before the last level read */
    int64_t button_level_ns;     /**< when the button's level was last read (open or read_button) */
    bool is_event_ts_monotonic;  /**< kernel >= 5.7: event stamps are CLOCK_MONOTONIC */
    ps_gpio_debounce_t debounce;
    uint32_t estop_offset;         /**< read-only: the lines as resolved at open */
    uint32_t heartbeat_offset;     /**< read-only */
    uint32_t led_offset;           /**< read-only */
    int64_t level_fix_ns;          /**< the last level fix (or open): older events are counted */
    uint64_t n_estop_events;       /**< read-only: edge events read */
    uint64_t n_event_reads_capped; /**< read_estop calls that left events for the next tick */
    uint64_t n_events_covered;     /**< read-only: events skipped, stamped before a level fix */
    uint64_t n_level_fixes;        /**< read-only: times the level disagreed with the events */
} ps_gpio_gpiod_t;

/** Open the chip, resolve the three lines (by name where cfg gives one),
 *  request the e-stop for both-edge events (active-low and bias from cfg,
 *  fd non-blocking) and the heartbeat and LED as outputs driven low, read
 *  the e-stop's level and start the debounce with it.
 *  @pre g not open (zeroed, or closed)  @post on 0 g is open; on failure g
 *       is closed and err names the chip, the line (offset, name, role),
 *       errno's text and what to check (`gpiodetect`, `gpioinfo CHIP`, the
 *       line's current consumer when it is busy)
 *  @return 0 | -ENOENT no such chip or line name | -EINVAL offset beyond the
 *          chip, two roles on one line, cfg out of range | -EBUSY line in
 *          use | -EACCES/-EPERM | -errno of libgpiod or fcntl
 *  @owner g: caller; cfg and err: caller, not kept  @rt INIT, main thread */
int ps_gpio_gpiod_open(ps_gpio_gpiod_t *g, const ps_gpio_cfg_t *cfg, char *err, size_t err_len);

/** @pre g open  @return the GPIO port over g (ops: read_estop, set_heartbeat,
 *  set_led, close, and read_button when the board has the record button)
 *  @rt INIT */
ps_gpio_port_t ps_gpio_gpiod_port(ps_gpio_gpiod_t *g);

/** Drive the heartbeat and LED low, release the lines, close the chip. Safe
 *  twice and on a zeroed struct.  @rt INIT */
void ps_gpio_gpiod_close(ps_gpio_gpiod_t *g);

/** One role's line as the kernel reports it, for `pushstep doctor`. */
typedef struct {
    char role[16];          /**< "e-stop", "heartbeat", "LED" */
    bool is_found;          /**< the name or offset exists on the chip */
    uint32_t offset;        /**< is_found only */
    char name[PS_NAME_LEN]; /**< the line's name, "" when it has none */
    bool is_used;           /**< requested by someone, or taken by a kernel driver */
    char consumer[32];      /**< who, when is_used ("" when the kernel names nobody) */
    char why[256];          /**< !is_found: the message open would give */
} ps_gpio_gpiod_line_info_t;

typedef struct {
    char chip_name[32];  /**< "gpiochip0" */
    char chip_label[64]; /**< "pinctrl-bcm2711" */
    uint32_t n_lines;
    ps_gpio_gpiod_line_info_t lines[3]; /**< e-stop, heartbeat, LED */
} ps_gpio_gpiod_probe_t;

/** Look the board's chip and lines up without requesting anything (the
 *  heartbeat is not driven): whether each exists, its offset and name, and
 *  whether it is free or whose it is.
 *  @post *out written on 0; err says why the chip did not open otherwise
 *  @return 0 (lines not found are in out) | -ENOENT no such chip | -EACCES/
 *          -EPERM | -EINVAL cfg | -errno of libgpiod
 *  @rt INIT (allocates inside libgpiod, frees before return) */
int ps_gpio_gpiod_probe(const ps_gpio_cfg_t *cfg, ps_gpio_gpiod_probe_t *out, char *err,
                        size_t err_len);

#endif /* PS_GPIO_GPIOD_H */
