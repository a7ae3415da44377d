/*
 * ps_can_sim: simulated classical CAN bus (see ps_can_sim.h).
 *
 * Per direction: one ps_ring_t of ps_can_frame_t, producer = the sending end,
 * consumer = the receiving end. The consumer needs to look at the oldest
 * frame's end time before taking it, and the ring has no peek, so each
 * receiving end keeps one popped-but-not-yet-due frame in `held` (consumer
 * owned, so still single-threaded per end).
 *
 * The wire is a single atomic "free from" time. A sender reserves
 * [max(ready, free), +duration) with compare-and-swap, so the two ends never
 * overlap frames and end times are monotonic in reservation order, which
 * per direction is the ring order: recv can stop at the first frame not yet
 * due. Simplification: the wire is first come, first served in send-call
 * order; a frame reserved for a later start (device end, t_ns > now) holds
 * the wire from the end of the previous reservation, and a frame sent after
 * it queues behind it even if the wire is idle until then. Real arbitration
 * would let the later frame through the gap; with driver turnaround times of
 * tens of microseconds this moves a reply by at most a frame time.
 */
#include "ps_can_sim.h"

#include <errno.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../drivers/ps_canbus.h"
#include "../rt/ps_ring.h"

typedef struct {
    _Atomic uint64_t n_tx_frames;
    _Atomic uint64_t n_rx_frames;
    _Atomic uint64_t n_tx_dropped;
    _Atomic uint64_t n_late;
} end_counters_t;

typedef struct {
    ps_ring_t ring;
    ps_can_frame_t *storage;
    ps_can_frame_t held; /* consumer side: popped, not yet due */
    bool has_held;
} direction_t;

typedef struct {
    ps_can_sim_bus_t *bus;
    bool is_device;
    direction_t *tx; /* frames this end sends */
    direction_t *rx; /* frames this end receives */
    end_counters_t counters;
} end_t;

struct ps_can_sim_bus {
    char name[32];
    uint32_t bitrate;
    ps_canbus_bus_cfg_t timing; /* bitrate, and the FD data rate once set */
    const ps_clock_t *clock;
    int64_t period_ns;
    int64_t epoch_ns;
    uint32_t queue_len;
    _Atomic int64_t bus_free_ns; /* wire idle from this time on */
    _Atomic uint64_t n_bits;
    direction_t to_device;
    direction_t to_host;
    end_t host;
    end_t device;
};

static bool is_valid_frame(const ps_can_sim_bus_t *b, const ps_can_frame_t *f)
{
    return ps_can_is_valid_frame(f) && (!f->is_fd || b->timing.is_fd);
}

/* End of the servo tick (grid epoch + k * period) that contains t. */
static int64_t tick_end_ns(const ps_can_sim_bus_t *b, int64_t t_ns)
{
    const int64_t rel = t_ns - b->epoch_ns;
    int64_t k = rel / b->period_ns;
    if (rel < 0 && k * b->period_ns != rel)
        k--; /* floor, not truncation, before the epoch */
    return b->epoch_ns + (k + 1) * b->period_ns;
}

/* Reserve the wire for dur_ns starting no earlier than ready_ns.
 * @return the end-of-frame time */
static int64_t reserve_wire(ps_can_sim_bus_t *b, int64_t ready_ns, int64_t dur_ns)
{
    int64_t free_ns = atomic_load_explicit(&b->bus_free_ns, memory_order_relaxed);
    int64_t end_ns;
    do {
        const int64_t start_ns = ready_ns > free_ns ? ready_ns : free_ns;
        end_ns = start_ns + dur_ns;
    } while (!atomic_compare_exchange_weak_explicit(&b->bus_free_ns, &free_ns, end_ns,
                                                    memory_order_acq_rel, memory_order_relaxed));
    return end_ns;
}

static int sim_send_batch(void *ctx, const ps_can_frame_t *frames, size_t n)
{
    end_t *e = ctx;
    ps_can_sim_bus_t *b = e->bus;
    if (n == 0)
        return 0;
    if (frames == NULL)
        return -EINVAL;
    for (size_t i = 0; i < n; i++) {
        if (!is_valid_frame(b, &frames[i]))
            return -EINVAL; /* nothing queued: all or nothing on bad input */
    }
    if (n > (size_t)INT32_MAX)
        n = (size_t)INT32_MAX; /* the count must fit the int return */

    const int64_t now_ns = ps_clock_now_ns(b->clock);
    size_t n_queued = 0;
    for (; n_queued < n; n_queued++) {
        const ps_can_frame_t *f = &frames[n_queued];
        /* Only this thread pushes, so a count below capacity guarantees the
         * push below succeeds; check first so a refused frame never holds the
         * wire. */
        if (ps_ring_count(&e->tx->ring) >= b->queue_len)
            break;
        int64_t ready_ns = now_ns;
        if (e->is_device && f->t_ns > ready_ns)
            ready_ns = f->t_ns;
        const ps_canbus_frame_shape_t shape = {.len = f->len,
                                               .is_ext = f->is_ext != 0,
                                               .is_fd = f->is_fd != 0,
                                               .is_brs = f->is_brs != 0};
        const unsigned bits = ps_canbus_frame_nominal_bits_max(&shape, &b->timing);
        const int64_t end_ns =
            reserve_wire(b, ready_ns, ps_canbus_frame_ns_max(&shape, &b->timing));
        ps_can_frame_t q = *f;
        q.t_ns = end_ns;
        if (ps_ring_push(&e->tx->ring, &q) != 0)
            break; /* cannot happen (see above); the wire time is then lost */
        atomic_fetch_add_explicit(&b->n_bits, bits, memory_order_relaxed);
        atomic_fetch_add_explicit(&e->counters.n_tx_frames, 1, memory_order_relaxed);
        if (end_ns > tick_end_ns(b, ready_ns))
            atomic_fetch_add_explicit(&e->counters.n_late, 1, memory_order_relaxed);
    }
    if (n_queued < n)
        atomic_fetch_add_explicit(&e->counters.n_tx_dropped, n - n_queued, memory_order_relaxed);
    return (int)n_queued;
}

static int sim_recv_batch(void *ctx, ps_can_frame_t *out, size_t max)
{
    end_t *e = ctx;
    direction_t *d = e->rx;
    if (max == 0)
        return 0;
    if (out == NULL)
        return -EINVAL;
    if (max > (size_t)INT32_MAX)
        max = (size_t)INT32_MAX;
    const int64_t now_ns = ps_clock_now_ns(e->bus->clock);
    size_t n = 0;
    while (n < max) {
        if (!d->has_held) {
            if (ps_ring_pop(&d->ring, &d->held) != 0)
                break;
            d->has_held = true;
        }
        if (d->held.t_ns > now_ns)
            break; /* still on the wire; later frames end later still */
        out[n++] = d->held;
        d->has_held = false;
    }
    atomic_fetch_add_explicit(&e->counters.n_rx_frames, n, memory_order_relaxed);
    return (int)n;
}

static int sim_get_state(void *ctx, ps_can_state_t *out)
{
    const end_t *e = ctx;
    ps_can_sim_bus_t *b = e->bus;
    if (out == NULL)
        return -EINVAL;
    ps_can_state_t s;
    memset(&s, 0, sizeof s);
    s.mode = PS_CAN_BUS_ERROR_ACTIVE;
    s.n_tx_frames = atomic_load_explicit(&e->counters.n_tx_frames, memory_order_relaxed);
    s.n_rx_frames = atomic_load_explicit(&e->counters.n_rx_frames, memory_order_relaxed);
    s.n_tx_dropped = atomic_load_explicit(&e->counters.n_tx_dropped, memory_order_relaxed);
    s.n_late = atomic_load_explicit(&e->counters.n_late, memory_order_relaxed);
    s.n_bits = atomic_load_explicit(&b->n_bits, memory_order_relaxed);
    const int64_t elapsed_ns = ps_clock_now_ns(b->clock) - b->epoch_ns;
    if (elapsed_ns > 0)
        s.load = (double)s.n_bits * 1e9 / ((double)elapsed_ns * (double)b->bitrate);
    *out = s;
    return 0;
}

static void sim_close(void *ctx)
{
    (void)ctx; /* the bus outlives its ports; ps_can_sim_destroy frees it */
}

static const ps_can_ops_t SIM_OPS = {
    .send_batch = sim_send_batch,
    .recv_batch = sim_recv_batch,
    .get_state = sim_get_state,
    .close = sim_close,
};

static int direction_init(direction_t *d, uint32_t queue_len)
{
    d->storage = calloc(queue_len, sizeof *d->storage);
    if (d->storage == NULL)
        return -ENOMEM;
    d->has_held = false;
    return ps_ring_init(&d->ring, d->storage, queue_len, sizeof *d->storage);
}

int ps_can_sim_create(ps_can_sim_bus_t **out, const char *name, uint32_t bitrate,
                      const ps_clock_t *clock, int64_t period_ns, uint32_t queue_len)
{
    if (out == NULL || clock == NULL || bitrate == 0 || period_ns <= 0 || queue_len < 2 ||
        queue_len > (UINT32_C(1) << 30) || (queue_len & (queue_len - 1u)) != 0)
        return -EINVAL;
    ps_can_sim_bus_t *b = calloc(1, sizeof *b);
    if (b == NULL)
        return -ENOMEM;
    (void)snprintf(b->name, sizeof b->name, "%s", name != NULL ? name : "sim");
    b->bitrate = bitrate;
    b->timing.bitrate = bitrate;
    b->clock = clock;
    b->period_ns = period_ns;
    b->queue_len = queue_len;
    b->epoch_ns = ps_clock_now_ns(clock);
    atomic_init(&b->bus_free_ns, INT64_MIN);
    atomic_init(&b->n_bits, 0);
    int rc = direction_init(&b->to_device, queue_len);
    if (rc == 0)
        rc = direction_init(&b->to_host, queue_len);
    if (rc != 0) {
        ps_can_sim_destroy(b);
        return rc;
    }
    /* Counters are already zero from calloc; only the wiring is set here. */
    b->host.bus = b;
    b->host.is_device = false;
    b->host.tx = &b->to_device;
    b->host.rx = &b->to_host;
    b->device.bus = b;
    b->device.is_device = true;
    b->device.tx = &b->to_host;
    b->device.rx = &b->to_device;
    *out = b;
    return 0;
}

int ps_can_sim_set_fd(ps_can_sim_bus_t *b, uint32_t data_bitrate)
{
    if (b == NULL || data_bitrate < b->bitrate)
        return -EINVAL;
    b->timing.is_fd = true;
    b->timing.data_bitrate = data_bitrate;
    return 0;
}

void ps_can_sim_set_epoch(ps_can_sim_bus_t *b, int64_t epoch_ns)
{
    b->epoch_ns = epoch_ns;
}

ps_can_port_t ps_can_sim_host_port(ps_can_sim_bus_t *b)
{
    return (ps_can_port_t){.ops = &SIM_OPS, .ctx = &b->host, .name = b->name};
}

ps_can_port_t ps_can_sim_device_port(ps_can_sim_bus_t *b)
{
    return (ps_can_port_t){.ops = &SIM_OPS, .ctx = &b->device, .name = b->name};
}

void ps_can_sim_destroy(ps_can_sim_bus_t *b)
{
    if (b == NULL)
        return;
    free(b->to_device.storage);
    free(b->to_host.storage);
    free(b);
}
