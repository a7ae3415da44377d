/*
 * ps_gpio_gpiod: the GPIO port on libgpiod v1.6; see ps_gpio_gpiod.h for the
 * model (events, debounce, level check, timestamps, outputs).
 *
 * libgpiod v1.6.3, read for what the RT ops cost: gpiod_line_set_value and
 * gpiod_line_get_value build a one-line bulk on the stack and make one ioctl;
 * gpiod_line_event_read_fd_multiple reads into a 16-entry stack buffer. None
 * allocates, locks or prints. Allocation happens in gpiod_chip_open_lookup,
 * gpiod_chip_get_line / gpiod_chip_find_line and the requests (open only), and
 * frees in gpiod_chip_close (close only).
 */
#include "ps_gpio_gpiod.h"

#include <errno.h>
#include <fcntl.h>
#include <gpiod.h>
#include <stdio.h>
#include <string.h>
#include <sys/utsname.h>
#include <time.h>

#include "../rt/ps_err.h"

#define CONSUMER_ESTOP     "pushstep-estop"
#define CONSUMER_HEARTBEAT "pushstep-heartbeat"
#define CONSUMER_LED       "pushstep-led"
#define CONSUMER_BUTTON    "pushstep-record-button"
/* The kernel's event FIFO holds 16; gpiod_line_event_read_fd_multiple reads
 * at most that many per call. */
#define MAX_EVENT_READS 4u /* reads of EVENT_BATCH events per read_estop call at most */
#define EVENT_BATCH     16u
/* The kernel's internal ENOTSUPP, which some GPIO drivers let through to
 * user space for a configuration they lack (bias). */
#define ENOTSUPP_KERNEL 524

/* ====================================================================== */
/* debounce                                                               */
/* ====================================================================== */

/* Times never go backwards: a late-read edge counts as seen at the latest
 * time already used (it cannot have changed a decision already taken). */
static int64_t clamp_time(ps_gpio_debounce_t *d, int64_t t_ns)
{
    if (t_ns < d->last_ns)
        t_ns = d->last_ns;
    d->last_ns = t_ns;
    return t_ns;
}

/* The raw level has held from raw_since_ns up to t_ns without a change:
 * adopt it once that is debounce_ns or more. */
static void settle(ps_gpio_debounce_t *d, int64_t t_ns)
{
    if (d->is_raw_pressed == d->is_pressed || t_ns - d->raw_since_ns < d->debounce_ns)
        return;
    d->is_pressed = d->is_raw_pressed;
    if (d->is_pressed)
        d->is_latched = true;
}

void ps_gpio_debounce_init(ps_gpio_debounce_t *d, int64_t debounce_ns, bool is_pressed,
                           int64_t now_ns)
{
    d->debounce_ns = debounce_ns > 0 ? debounce_ns : 0;
    d->is_raw_pressed = is_pressed;
    d->raw_since_ns = now_ns;
    d->is_pressed = is_pressed;
    d->is_latched = is_pressed;
    d->last_ns = now_ns;
}

void ps_gpio_debounce_edge(ps_gpio_debounce_t *d, bool is_pressed, int64_t t_ns)
{
    t_ns = clamp_time(d, t_ns);
    settle(d, t_ns); /* the level before this edge held until t_ns */
    if (is_pressed == d->is_raw_pressed)
        return;
    d->is_raw_pressed = is_pressed;
    d->raw_since_ns = t_ns;
    settle(d, t_ns); /* debounce 0: the edge counts at once */
}

void ps_gpio_debounce_poll(ps_gpio_debounce_t *d, int64_t now_ns)
{
    settle(d, clamp_time(d, now_ns));
}

bool ps_gpio_debounce_take_pressed(ps_gpio_debounce_t *d)
{
    const bool is_pressed = d->is_pressed || d->is_latched;
    d->is_latched = false;
    return is_pressed;
}

/* Edge types are not trusted (as the e-stop's): a first edge after a
 * released read is a press; two or more edges hold a press whatever the
 * level read last was. One edge queued late changed only the level the last
 * read saw; two are a whole press that read may have missed, reported
 * (erring toward pressed, as the e-stop does). */
bool ps_gpio_button_pressed(bool is_level_pressed, bool was_level_pressed, uint64_t n_new_edges,
                            uint64_t n_late_edges)
{
    return is_level_pressed || (n_new_edges > 0 && !was_level_pressed) || n_new_edges >= 2 ||
           n_late_edges >= 2;
}

/* ====================================================================== */
/* the port                                                               */
/* ====================================================================== */

static int64_t now_ns_of(clockid_t clock)
{
    struct timespec ts;
    /* Through the vDSO; it cannot fail with a valid clock id and pointer. */
    (void)clock_gettime(clock, &ts);
    return (int64_t)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

static int64_t mono_now_ns(void)
{
    return now_ns_of(CLOCK_MONOTONIC);
}

/* Kernels from 5.7 stamp GPIO v1 line events with CLOCK_MONOTONIC; earlier
 * ones used CLOCK_REALTIME, which read_estop moves onto CLOCK_MONOTONIC. */
static bool kernel_stamps_monotonic(void)
{
    struct utsname u;
    int major = 0, minor = 0;
    if (uname(&u) != 0 || sscanf(u.release, "%d.%d", &major, &minor) != 2)
        return false; /* unknown: use the time of the read, always valid */
    return major > 5 || (major == 5 && minor >= 7);
}

/* Taken after an event read, so every event it took is stamped at or
 * before read_ns. Kernels < 5.7: REALTIME stamps, moved by the clocks'
 * difference now (a clock step between the edge and now shifts them:
 * clamped to the read). */
typedef struct {
    int64_t read_ns;
    int64_t rt_off_ns;
} event_clock_t;

static event_clock_t event_clock_now(const ps_gpio_gpiod_t *g)
{
    const int64_t read_ns = mono_now_ns();
    return (event_clock_t){.read_ns = read_ns,
                           .rt_off_ns =
                               g->is_event_ts_monotonic ? 0 : now_ns_of(CLOCK_REALTIME) - read_ns};
}

static int64_t event_mono_ns(const event_clock_t *clk, const struct gpiod_line_event *ev)
{
    const int64_t t_ns = (int64_t)ev->ts.tv_sec * 1000000000LL + ev->ts.tv_nsec - clk->rt_off_ns;
    return t_ns > clk->read_ns ? clk->read_ns : t_ns;
}

static int read_estop(void *ctx, bool *out_pressed_since_last_read)
{
    ps_gpio_gpiod_t *g = ctx;
    if (out_pressed_since_last_read == NULL)
        return -EINVAL;
    if (g->chip == NULL)
        return -EBADF;
    struct gpiod_line_event ev[EVENT_BATCH];
    /* Bounded: a line bouncing fast enough to refill the kernel's queue
     * between reads must not keep the tick here. What is left waits for the
     * next tick; the level check below puts the state right meanwhile. */
    for (unsigned pass = 0;; pass++) {
        if (pass == MAX_EVENT_READS) {
            g->n_event_reads_capped++;
            break;
        }
        const int n = gpiod_line_event_read_fd_multiple(g->estop_fd, ev, EVENT_BATCH);
        if (n < 0) {
            if (errno == EAGAIN || errno == EWOULDBLOCK)
                break;     /* drained */
            return -errno; /* the latch stays: nothing was taken */
        }
        const event_clock_t clk = event_clock_now(g);
        for (int i = 0; i < n; i++) {
            const int64_t t_ns = event_mono_ns(&clk, &ev[i]);
            if (t_ns <= g->level_fix_ns) {
                g->n_events_covered++;
                continue; /* the level read of that fix already saw this edge */
            }
            /* One change of level; the event's type is not trusted (header). */
            ps_gpio_debounce_edge(&g->debounce, !g->debounce.is_raw_pressed, t_ns);
        }
        g->n_estop_events += (uint64_t)n;
        if ((unsigned)n < EVENT_BATCH)
            break; /* a short read: the FIFO was emptied */
    }
    /* The level as the kernel reads it now (logical: active-low applied),
     * against what the events said; see the header for why. The time is taken
     * before the read, so every edge stamped at or before it is in the level. */
    const int64_t now_ns = mono_now_ns();
    const int level = gpiod_line_get_value(g->estop);
    if (level < 0)
        return -errno;
    if ((level != 0) != g->debounce.is_raw_pressed) {
        g->n_level_fixes++;
        g->level_fix_ns = now_ns;
        ps_gpio_debounce_edge(&g->debounce, level != 0, now_ns);
    }
    ps_gpio_debounce_poll(&g->debounce, now_ns);
    *out_pressed_since_last_read = ps_gpio_debounce_take_pressed(&g->debounce);
    return 0;
}

static int read_button(void *ctx, bool *out_pressed_since_last_read)
{
    ps_gpio_gpiod_t *g = ctx;
    if (out_pressed_since_last_read == NULL)
        return -EINVAL;
    if (g->chip == NULL || g->button == NULL)
        return -EBADF;
    struct gpiod_line_event ev[EVENT_BATCH];
    uint64_t n_edges = 0, n_new_edges = 0;
    for (unsigned pass = 0; pass < MAX_EVENT_READS; pass++) {
        const int n = gpiod_line_event_read_fd_multiple(g->button_fd, ev, EVENT_BATCH);
        if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK))
            break;
        if (n < 0)
            return -errno;
        /* An edge stamped before the last level read is in that level
         * already (a release queued late, after the read that saw it). */
        const event_clock_t clk = event_clock_now(g);
        for (int i = 0; i < n; i++)
            n_new_edges += event_mono_ns(&clk, &ev[i]) > g->button_level_ns ? 1 : 0;
        n_edges += (uint64_t)n;
        if ((unsigned)n < EVENT_BATCH)
            break;
    }
    g->n_button_events += n_edges;
    g->n_button_events_covered += n_edges - n_new_edges;
    const int64_t level_ns = mono_now_ns(); /* before the read: edges up to it are in it */
    const int level = gpiod_line_get_value(g->button);
    if (level < 0)
        return -errno;
    *out_pressed_since_last_read = ps_gpio_button_pressed(level != 0, g->was_button_pressed,
                                                          n_new_edges, n_edges - n_new_edges);
    g->was_button_pressed = level != 0;
    g->button_level_ns = level_ns;
    return 0;
}

static int set_heartbeat(void *ctx, bool level)
{
    ps_gpio_gpiod_t *g = ctx;
    if (g->chip == NULL)
        return -EBADF;
    return gpiod_line_set_value(g->heartbeat, level ? 1 : 0) == 0 ? 0 : -errno;
}

static int set_led(void *ctx, ps_gpio_led_t led)
{
    ps_gpio_gpiod_t *g = ctx;
    if (g->chip == NULL)
        return -EBADF;
    return gpiod_line_set_value(g->led, led == PS_GPIO_LED_ON ? 1 : 0) == 0 ? 0 : -errno;
}

static void close_op(void *ctx)
{
    ps_gpio_gpiod_close(ctx);
}

static const ps_gpio_ops_t OPS = {
    .read_estop = read_estop,
    .set_heartbeat = set_heartbeat,
    .set_led = set_led,
    .close = close_op,
};

static const ps_gpio_ops_t OPS_BUTTON = {
    .read_estop = read_estop,
    .set_heartbeat = set_heartbeat,
    .set_led = set_led,
    .close = close_op,
    .read_button = read_button,
};

void ps_gpio_gpiod_close(ps_gpio_gpiod_t *g)
{
    if (g == NULL || g->chip == NULL)
        return;
    /* The orderly exit: heartbeat held low (the relay drops the drives'
     * power PS_GPIO_HEARTBEAT_TIMEOUT_NS after its last change) and the LED
     * off, before the lines are released. A line a failed open did not
     * request yet is left alone. */
    if (g->heartbeat != NULL && gpiod_line_is_requested(g->heartbeat))
        (void)gpiod_line_set_value(g->heartbeat, 0); /* nothing more to do on exit */
    if (g->led != NULL && gpiod_line_is_requested(g->led))
        (void)gpiod_line_set_value(g->led, 0); /* idem */
    gpiod_chip_close(g->chip);                 /* releases the lines, frees them */
    g->chip = NULL;
    g->estop = NULL;
    g->heartbeat = NULL;
    g->led = NULL;
    g->button = NULL;
    g->estop_fd = -1;
    g->button_fd = -1;
}

ps_gpio_port_t ps_gpio_gpiod_port(ps_gpio_gpiod_t *g)
{
    const ps_gpio_port_t p = {.ops = g->button != NULL ? &OPS_BUTTON : &OPS, .ctx = g};
    return p;
}

/* ---- open ----------------------------------------------------------------- */

typedef struct {
    const char *role; /* for messages */
    const char *consumer;
    const char *name; /* "" = by offset */
    uint32_t offset;
} line_spec_t;

/* "line 17 (\"GPIO17\", e-stop)" or "line \"GPIO99\" (e-stop)" */
static void describe(char *out, size_t out_len, const line_spec_t *s, struct gpiod_line *line)
{
    if (line != NULL) {
        const char *name = gpiod_line_name(line);
        (void)snprintf(out, out_len, "line %u (\"%s\", %s)", gpiod_line_offset(line),
                       name != NULL ? name : "", s->role);
    } else if (s->name[0] != '\0') {
        (void)snprintf(out, out_len, "line \"%s\" (%s)", s->name, s->role);
    } else {
        (void)snprintf(out, out_len, "line %u (%s)", s->offset, s->role);
    }
}

static int find_line(ps_gpio_gpiod_t *g, const line_spec_t *s, struct gpiod_line **out, char *err,
                     size_t err_len)
{
    const char *chip_name = gpiod_chip_name(g->chip);
    struct gpiod_line *line;
    if (s->name[0] != '\0') {
        errno = 0;
        line = gpiod_chip_find_line(g->chip, s->name);
        if (line == NULL) {
            const int rc = errno != 0 ? -errno : -ENOENT;
            if (rc == -ENOENT)
                ps_err_format(err, err_len,
                              "gpio %s [%s]: %s line \"%s\": no line of that name on the chip; "
                              "check the names with `gpioinfo %s` (and gpio.chip)",
                              chip_name, gpiod_chip_label(g->chip), s->role, s->name, chip_name);
            else
                ps_err_format(err, err_len, "gpio %s: %s line \"%s\": lookup failed: %s", chip_name,
                              s->role, s->name, strerror(-rc));
            return rc;
        }
    } else {
        const unsigned n_lines = gpiod_chip_num_lines(g->chip);
        if (s->offset >= n_lines) {
            ps_err_format(err, err_len,
                          "gpio %s [%s], %u lines: %s line %u: no such line (offsets 0..%u); "
                          "check `gpioinfo %s`",
                          chip_name, gpiod_chip_label(g->chip), n_lines, s->role, s->offset,
                          n_lines > 0 ? n_lines - 1u : 0u, chip_name);
            return -EINVAL;
        }
        line = gpiod_chip_get_line(g->chip, s->offset);
        if (line == NULL) {
            const int rc = -errno;
            ps_err_format(err, err_len, "gpio %s: %s line %u: cannot get line info: %s", chip_name,
                          s->role, s->offset, strerror(errno));
            return rc;
        }
    }
    *out = line;
    return 0;
}

/* A request failed with errno e: say why, and for a busy line who holds it. */
static int request_failed(const ps_gpio_gpiod_t *g, const line_spec_t *s, struct gpiod_line *line,
                          const char *what, int e, char *err, size_t err_len)
{
    const char *chip_name = gpiod_chip_name(g->chip);
    char where[96];
    describe(where, sizeof(where), s, line);
    if (e == EBUSY) {
        /* The consumer as the kernel reports it now, not as cached at lookup. */
        const char *consumer = gpiod_line_update(line) == 0 ? gpiod_line_consumer(line) : NULL;
        ps_err_format(err, err_len,
                      "gpio %s %s: cannot request %s: %s: line busy: used by \"%s\"; "
                      "check `gpioinfo %s` (another pushstep, a driver or a gpioset/gpiomon)",
                      chip_name, where, what, strerror(e),
                      consumer != NULL ? consumer : "(unknown)", chip_name);
    } else if (e == EACCES || e == EPERM) {
        ps_err_format(err, err_len,
                      "gpio %s %s: cannot request %s: %s; check the permissions of /dev/%s "
                      "(group gpio, or root)",
                      chip_name, where, what, strerror(e), chip_name);
    } else if (e == EOPNOTSUPP || e == ENOTSUPP_KERNEL) {
        ps_err_format(err, err_len,
                      "gpio %s %s: cannot request %s: %s; the chip's driver or this kernel "
                      "(bias needs >= 5.5) cannot do it: check gpio.estop_bias",
                      chip_name, where, what, strerror(e));
    } else {
        ps_err_format(err, err_len, "gpio %s %s: cannot request %s: %s; check `gpioinfo %s`",
                      chip_name, where, what, strerror(e), chip_name);
    }
    return -e;
}

/* The chip by name, label, number or path, with what to check on failure. */
static int open_chip(const ps_gpio_cfg_t *cfg, struct gpiod_chip **out, char *err, size_t err_len)
{
    errno = 0;
    *out = gpiod_chip_open_lookup(cfg->chip);
    if (*out != NULL)
        return 0;
    const int e = errno != 0 ? errno : ENOENT;
    if (e == EACCES || e == EPERM)
        ps_err_format(err, err_len,
                      "gpio chip \"%s\": cannot open: %s; check the permissions of "
                      "/dev/gpiochip* (group gpio, or root)",
                      cfg->chip, strerror(e));
    else
        ps_err_format(err, err_len,
                      "gpio chip \"%s\": cannot open: %s; check `gpiodetect` for this "
                      "board's chips (gpio.chip takes a name, label, number or /dev path)",
                      cfg->chip, strerror(e));
    return -e;
}

/* The three roles, in the order of ps_gpio_gpiod_probe_t.lines. */
/* The board's lines; the record button last, when there is one.
 * @return how many (3 or 4) */
static int line_specs(const ps_gpio_cfg_t *cfg, line_spec_t out[4])
{
    out[0] = (line_spec_t){"e-stop", CONSUMER_ESTOP, cfg->estop_name, cfg->estop_line};
    out[1] = (line_spec_t){"heartbeat", CONSUMER_HEARTBEAT, cfg->enable_name, cfg->enable_line};
    out[2] = (line_spec_t){"LED", CONSUMER_LED, cfg->led_name, cfg->led_line};
    out[3] = (line_spec_t){"record button", CONSUMER_BUTTON, cfg->button_name, cfg->button_line};
    return cfg->has_button ? 4 : 3;
}

static int check_spec(const ps_gpio_cfg_t *cfg, const line_spec_t *s, char *err, size_t err_len)
{
    if (memchr(s->name, '\0', PS_NAME_LEN) != NULL)
        return 0;
    ps_err_format(err, err_len, "gpio %s: %s line name not terminated", cfg->chip, s->role);
    return -EINVAL;
}

static int bias_flags(ps_gpio_bias_t bias)
{
    switch (bias) {
    case PS_GPIO_BIAS_PULL_UP:
        return GPIOD_LINE_REQUEST_FLAG_BIAS_PULL_UP;
    case PS_GPIO_BIAS_PULL_DOWN:
        return GPIOD_LINE_REQUEST_FLAG_BIAS_PULL_DOWN;
    case PS_GPIO_BIAS_DISABLED:
        return GPIOD_LINE_REQUEST_FLAG_BIAS_DISABLE;
    case PS_GPIO_BIAS_AS_IS:
    default:
        return 0;
    }
}

/* The record button: both-edge events, non-blocking, its level now. */
static int open_button(ps_gpio_gpiod_t *g, const ps_gpio_cfg_t *cfg, const line_spec_t *spec,
                       char *err, size_t err_len)
{
    g->button_offset = gpiod_line_offset(g->button);
    const int flags = cfg->is_button_active_low ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0;
    if (gpiod_line_request_both_edges_events_flags(g->button, CONSUMER_BUTTON, flags) != 0)
        return request_failed(g, spec, g->button, "both-edge events", errno, err, err_len);
    g->button_fd = gpiod_line_event_get_fd(g->button);
    const int fl = g->button_fd >= 0 ? fcntl(g->button_fd, F_GETFL) : -1;
    g->button_level_ns = mono_now_ns();
    const int level = gpiod_line_get_value(g->button);
    if (fl < 0 || fcntl(g->button_fd, F_SETFL, fl | O_NONBLOCK) != 0 || level < 0) {
        const int rc = -errno;
        ps_err_format(err, err_len, "gpio %s: record button line %u: %s", gpiod_chip_name(g->chip),
                      g->button_offset, strerror(errno));
        return rc;
    }
    g->was_button_pressed = level != 0;
    return 0;
}

int ps_gpio_gpiod_open(ps_gpio_gpiod_t *g, const ps_gpio_cfg_t *cfg, char *err, size_t err_len)
{
    if (err != NULL && err_len > 0)
        err[0] = '\0';
    if (g == NULL || cfg == NULL)
        return -EINVAL;
    memset(g, 0, sizeof(*g));
    g->estop_fd = -1;
    g->button_fd = -1;
    if (cfg->chip[0] == '\0' || memchr(cfg->chip, '\0', sizeof(cfg->chip)) == NULL) {
        ps_err_format(err, err_len, "gpio: no chip given (gpio.chip)");
        return -EINVAL;
    }
    if (cfg->estop_debounce_us > PS_GPIO_DEBOUNCE_MAX_US ||
        (unsigned)cfg->estop_bias > (unsigned)PS_GPIO_BIAS_DISABLED) {
        ps_err_format(err, err_len,
                      "gpio %s: estop_debounce_us %u (at most %u) or estop_bias %d out of range",
                      cfg->chip, cfg->estop_debounce_us, PS_GPIO_DEBOUNCE_MAX_US,
                      (int)cfg->estop_bias);
        return -EINVAL;
    }

    int rc = open_chip(cfg, &g->chip, err, err_len);
    if (rc < 0)
        return rc;

    line_spec_t spec[4];
    const int n_lines = line_specs(cfg, spec);
    struct gpiod_line *lines[4] = {NULL, NULL, NULL, NULL};
    for (int i = 0; i < n_lines && rc == 0; i++) {
        rc = check_spec(cfg, &spec[i], err, err_len);
        if (rc == 0)
            rc = find_line(g, &spec[i], &lines[i], err, err_len);
        for (int k = 0; k < i && rc == 0; k++) {
            if (lines[k] == lines[i]) { /* libgpiod keeps one struct per offset */
                char a[96], b[96];
                describe(a, sizeof(a), &spec[i], lines[i]);
                describe(b, sizeof(b), &spec[k], lines[k]);
                ps_err_format(err, err_len, "gpio %s: %s is also %s: each role needs its own line",
                              gpiod_chip_name(g->chip), a, b);
                rc = -EINVAL;
            }
        }
    }
    if (rc != 0)
        goto fail;
    g->estop = lines[0];
    g->heartbeat = lines[1];
    g->led = lines[2];
    g->estop_offset = gpiod_line_offset(g->estop);
    g->heartbeat_offset = gpiod_line_offset(g->heartbeat);
    g->led_offset = gpiod_line_offset(g->led);
    g->button = lines[3];

    /* Outputs first, driven low: the relay sees no beat and the LED is off
     * from the moment the lines are ours. */
    if (gpiod_line_request_output(g->heartbeat, CONSUMER_HEARTBEAT, 0) != 0) {
        rc = request_failed(g, &spec[1], g->heartbeat, "it as output", errno, err, err_len);
        goto fail;
    }
    if (gpiod_line_request_output(g->led, CONSUMER_LED, 0) != 0) {
        rc = request_failed(g, &spec[2], g->led, "it as output", errno, err, err_len);
        goto fail;
    }
    const int flags = (cfg->is_estop_active_low ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0) |
                      bias_flags(cfg->estop_bias);
    if (gpiod_line_request_both_edges_events_flags(g->estop, CONSUMER_ESTOP, flags) != 0) {
        rc = request_failed(g, &spec[0], g->estop, "both-edge events", errno, err, err_len);
        goto fail;
    }
    g->estop_fd = gpiod_line_event_get_fd(g->estop);
    const int fl = g->estop_fd >= 0 ? fcntl(g->estop_fd, F_GETFL) : -1;
    if (fl < 0 || fcntl(g->estop_fd, F_SETFL, fl | O_NONBLOCK) != 0) {
        rc = -errno;
        ps_err_format(err, err_len,
                      "gpio %s: e-stop line %u: cannot make its event fd non-blocking: %s",
                      gpiod_chip_name(g->chip), g->estop_offset, strerror(errno));
        goto fail;
    }
    g->is_event_ts_monotonic = kernel_stamps_monotonic();
    if (g->button != NULL) {
        rc = open_button(g, cfg, &spec[3], err, err_len);
        if (rc != 0)
            goto fail;
    }

    /* The level now, after the request, so no edge falls between the two.
     * Edges stamped up to this time are in the level; later ones are events. */
    const int64_t now_ns = mono_now_ns();
    const int level = gpiod_line_get_value(g->estop);
    if (level < 0) {
        rc = -errno;
        ps_err_format(err, err_len, "gpio %s: e-stop line %u: cannot read its level: %s",
                      gpiod_chip_name(g->chip), g->estop_offset, strerror(errno));
        goto fail;
    }
    g->level_fix_ns = now_ns;
    ps_gpio_debounce_init(&g->debounce, (int64_t)cfg->estop_debounce_us * 1000LL, level != 0,
                          now_ns);
    return 0;

fail:
    ps_gpio_gpiod_close(g);
    return rc;
}

/* ---- probe ----------------------------------------------------------------- */

int ps_gpio_gpiod_probe(const ps_gpio_cfg_t *cfg, ps_gpio_gpiod_probe_t *out, char *err,
                        size_t err_len)
{
    if (err != NULL && err_len > 0)
        err[0] = '\0';
    if (cfg == NULL || out == NULL)
        return -EINVAL;
    memset(out, 0, sizeof(*out));
    if (cfg->chip[0] == '\0' || memchr(cfg->chip, '\0', sizeof(cfg->chip)) == NULL) {
        ps_err_format(err, err_len, "gpio: no chip given (gpio.chip)");
        return -EINVAL;
    }
    ps_gpio_gpiod_t g; /* find_line's view of the chip; nothing is requested */
    memset(&g, 0, sizeof(g));
    g.estop_fd = -1;
    int rc = open_chip(cfg, &g.chip, err, err_len);
    if (rc < 0)
        return rc;
    (void)snprintf(out->chip_name, sizeof(out->chip_name), "%s", gpiod_chip_name(g.chip));
    (void)snprintf(out->chip_label, sizeof(out->chip_label), "%s", gpiod_chip_label(g.chip));
    out->n_lines = gpiod_chip_num_lines(g.chip);
    line_spec_t spec[4];
    (void)line_specs(cfg, spec); /* the probe looks at the three lines every board has */
    for (int i = 0; i < 3; i++) {
        ps_gpio_gpiod_line_info_t *li = &out->lines[i];
        (void)snprintf(li->role, sizeof(li->role), "%s", spec[i].role);
        struct gpiod_line *line = NULL;
        if (check_spec(cfg, &spec[i], li->why, sizeof(li->why)) < 0 ||
            find_line(&g, &spec[i], &line, li->why, sizeof(li->why)) < 0)
            continue;
        li->is_found = true;
        li->offset = gpiod_line_offset(line);
        const char *name = gpiod_line_name(line);
        const char *consumer = gpiod_line_consumer(line);
        (void)snprintf(li->name, sizeof(li->name), "%s", name != NULL ? name : "");
        li->is_used = gpiod_line_is_used(line);
        (void)snprintf(li->consumer, sizeof(li->consumer), "%s", consumer != NULL ? consumer : "");
    }
    gpiod_chip_close(g.chip);
    return 0;
}
