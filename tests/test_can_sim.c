/* Tests of sim/ps_can_sim: the simulated CAN wire, on a fake clock and, for
 * the two-thread test, on the real monotonic clock. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <pthread.h>
#include <sched.h>
#include <string.h>

#include "../drivers/ps_canbus.h"
#include "../rt/ps_clock.h"
#include "../sim/ps_can_sim.h"
#include "contract/ps_can_contract.h"

#define BITRATE   1000000u
#define PERIOD_NS 1000000 /* 1 kHz servo tick: 1000 bit times at 1 Mbit/s */
#define FRAME_NS  135000  /* worst-case 8-byte 11-bit frame at 1 Mbit/s */

/* ---- a settable clock, private to this file ---------------------------- */

typedef struct {
    ps_clock_t clock;
    int64_t now_ns;
} test_clock_t;

static int64_t test_clock_now(void *ctx)
{
    return ((test_clock_t *)ctx)->now_ns;
}

static int test_clock_sleep(void *ctx, int64_t deadline_ns)
{
    test_clock_t *c = ctx;
    if (deadline_ns > c->now_ns)
        c->now_ns = deadline_ns;
    return 0;
}

typedef struct {
    test_clock_t clk;
    ps_can_sim_bus_t *bus;
    ps_can_port_t host;
    ps_can_port_t dev;
} fixture_t;

static int make_fixture(void **state, uint32_t queue_len)
{
    fixture_t *f = test_calloc(1, sizeof *f);
    if (f == NULL)
        return -1;
    f->clk.clock =
        (ps_clock_t){.now_ns = test_clock_now, .sleep_until_ns = test_clock_sleep, .ctx = &f->clk};
    f->clk.now_ns = 0;
    if (ps_can_sim_create(&f->bus, "can0", BITRATE, &f->clk.clock, PERIOD_NS, queue_len) != 0) {
        test_free(f);
        return -1;
    }
    f->host = ps_can_sim_host_port(f->bus);
    f->dev = ps_can_sim_device_port(f->bus);
    *state = f;
    return 0;
}

static int setup(void **state)
{
    return make_fixture(state, 64);
}

static int setup_small_queue(void **state)
{
    return make_fixture(state, 4);
}

static int teardown(void **state)
{
    fixture_t *f = *state;
    ps_can_close(&f->host);
    ps_can_close(&f->dev);
    ps_can_close(&f->host); /* twice is safe */
    ps_can_sim_destroy(f->bus);
    test_free(f);
    return 0;
}

static ps_can_frame_t frame8(uint32_t id, uint8_t tag)
{
    ps_can_frame_t fr;
    memset(&fr, 0, sizeof fr);
    fr.id = id;
    fr.len = 8;
    for (unsigned i = 0; i < 8; i++)
        fr.data[i] = (uint8_t)(tag + i);
    return fr;
}

static ps_can_state_t state_of(const ps_can_port_t *p)
{
    ps_can_state_t s;
    assert_int_equal(ps_can_get_state(p, &s), 0);
    return s;
}

/* ---- tests -------------------------------------------------------------- */

static void test_send_batch_one_frame_arrives_after_frame_time(void **state)
{
    fixture_t *f = *state;
    /* The fixture's timing constant agrees with the bus module. */
    assert_int_equal(ps_canbus_bits_to_ns(ps_canbus_frame_bits_max(8, false), BITRATE), FRAME_NS);
    const ps_can_frame_t tx = frame8(0x141, 0x10);
    f->clk.now_ns = 0;
    assert_int_equal(ps_can_send_batch(&f->host, &tx, 1), 1);
    ps_can_frame_t rx[4];
    f->clk.now_ns = FRAME_NS - 1;
    assert_int_equal(ps_can_recv_batch(&f->dev, rx, 4), 0);
    f->clk.now_ns = FRAME_NS;
    assert_int_equal(ps_can_recv_batch(&f->dev, rx, 4), 1);
    assert_int_equal(rx[0].t_ns, FRAME_NS);
    assert_int_equal(rx[0].id, 0x141);
    assert_int_equal(rx[0].len, 8);
    assert_memory_equal(rx[0].data, tx.data, 8);
    /* Not delivered twice, and not to the sender's own end. */
    assert_int_equal(ps_can_recv_batch(&f->dev, rx, 4), 0);
    assert_int_equal(ps_can_recv_batch(&f->host, rx, 4), 0);
}

/* An FD bus: a 64-byte frame with bit rate switch takes 35 bits at 1 Mbit/s
 * and 677 at 5 Mbit/s (tests/test_canbus.c), payload and 29-bit id intact;
 * classical frames keep their timing. Without set_fd, FD frames are refused. */
static void test_send_batch_fd_frame_data_phase_at_data_bitrate(void **state)
{
    fixture_t *f = *state;
    ps_can_frame_t fd;
    memset(&fd, 0, sizeof fd);
    fd.id = 0x1234567;
    fd.is_ext = 1;
    fd.is_fd = 1;
    fd.is_brs = 1;
    fd.len = 64;
    for (unsigned i = 0; i < 64; i++)
        fd.data[i] = (uint8_t)(3 * i);
    assert_int_equal(ps_can_send_batch(&f->host, &fd, 1), -EINVAL); /* classical bus */
    assert_int_equal(ps_can_sim_set_fd(f->bus, 500000), -EINVAL);   /* slower than nominal */
    assert_int_equal(ps_can_sim_set_fd(f->bus, 5000000), 0);
    f->clk.now_ns = 0;
    assert_int_equal(ps_can_send_batch(&f->host, &fd, 1), 1);
    const ps_canbus_bus_cfg_t bus = {.bitrate = BITRATE, .is_fd = true, .data_bitrate = 5000000};
    const ps_canbus_frame_shape_t shape = {
        .len = 64, .is_ext = true, .is_fd = true, .is_brs = true};
    const int64_t t_end = ps_canbus_frame_ns_max(&shape, &bus);
    assert_true(t_end < 64 * 8 * 1000); /* far below 64 bytes at the nominal rate */
    ps_can_frame_t rx[2];
    f->clk.now_ns = t_end - 1;
    assert_int_equal(ps_can_recv_batch(&f->dev, rx, 2), 0);
    f->clk.now_ns = t_end;
    assert_int_equal(ps_can_recv_batch(&f->dev, rx, 2), 1);
    assert_int_equal(rx[0].id, 0x1234567);
    assert_true(rx[0].is_ext && rx[0].is_fd && rx[0].is_brs);
    assert_int_equal(rx[0].len, 64);
    assert_memory_equal(rx[0].data, fd.data, 64);
    /* a length no FD frame has, or BRS on a classical frame: refused */
    fd.len = 13;
    assert_int_equal(ps_can_send_batch(&f->host, &fd, 1), -EINVAL);
    ps_can_frame_t brs = frame8(0x10, 0);
    brs.is_brs = 1;
    assert_int_equal(ps_can_send_batch(&f->host, &brs, 1), -EINVAL);
}

static void test_send_batch_later_send_time_shifts_arrival(void **state)
{
    fixture_t *f = *state;
    const ps_can_frame_t tx = frame8(0x1, 0);
    f->clk.now_ns = 250000;
    assert_int_equal(ps_can_send_batch(&f->host, &tx, 1), 1);
    ps_can_frame_t rx;
    f->clk.now_ns = 250000 + FRAME_NS - 1;
    assert_int_equal(ps_can_recv_batch(&f->dev, &rx, 1), 0);
    f->clk.now_ns = 250000 + FRAME_NS;
    assert_int_equal(ps_can_recv_batch(&f->dev, &rx, 1), 1);
    assert_int_equal(rx.t_ns, 250000 + FRAME_NS);
}

static void test_send_batch_back_to_back_frames_queue_on_wire(void **state)
{
    fixture_t *f = *state;
    const ps_can_frame_t tx[2] = {frame8(0x1, 1), frame8(0x2, 2)};
    assert_int_equal(ps_can_send_batch(&f->host, tx, 2), 2);
    ps_can_frame_t rx[2];
    f->clk.now_ns = FRAME_NS;
    assert_int_equal(ps_can_recv_batch(&f->dev, rx, 2), 1);
    assert_int_equal(rx[0].id, 0x1);
    f->clk.now_ns = 2 * FRAME_NS - 1;
    assert_int_equal(ps_can_recv_batch(&f->dev, rx, 2), 0);
    f->clk.now_ns = 2 * FRAME_NS;
    assert_int_equal(ps_can_recv_batch(&f->dev, rx, 2), 1);
    assert_int_equal(rx[0].id, 0x2);
    assert_int_equal(rx[0].t_ns, 2 * FRAME_NS);
}

static void test_recv_batch_respects_max_and_fifo(void **state)
{
    fixture_t *f = *state;
    ps_can_frame_t tx[5];
    for (unsigned i = 0; i < 5; i++)
        tx[i] = frame8(0x10 + i, (uint8_t)i);
    assert_int_equal(ps_can_send_batch(&f->host, tx, 5), 5);
    f->clk.now_ns = 10 * FRAME_NS;
    ps_can_frame_t rx[5];
    assert_int_equal(ps_can_recv_batch(&f->dev, rx, 2), 2);
    assert_int_equal(ps_can_recv_batch(&f->dev, &rx[2], 5), 3);
    for (unsigned i = 0; i < 5; i++) {
        assert_int_equal(rx[i].id, 0x10 + i);
        assert_int_equal(rx[i].t_ns, (int64_t)(i + 1) * FRAME_NS);
    }
    assert_int_equal(ps_can_recv_batch(&f->dev, rx, 0), 0);
}

static void test_send_batch_both_directions_share_wire(void **state)
{
    fixture_t *f = *state;
    const ps_can_frame_t cmd = frame8(0x1, 0);
    const ps_can_frame_t rep = frame8(0x11, 0x80);
    assert_int_equal(ps_can_send_batch(&f->host, &cmd, 1), 1);
    assert_int_equal(ps_can_send_batch(&f->dev, &rep, 1), 1);
    ps_can_frame_t rx;
    f->clk.now_ns = 2 * FRAME_NS - 1;
    assert_int_equal(ps_can_recv_batch(&f->host, &rx, 1), 0);
    f->clk.now_ns = 2 * FRAME_NS;
    assert_int_equal(ps_can_recv_batch(&f->host, &rx, 1), 1);
    assert_int_equal(rx.id, 0x11);
    assert_int_equal(rx.t_ns, 2 * FRAME_NS);
    assert_int_equal(ps_can_recv_batch(&f->dev, &rx, 1), 1);
    assert_int_equal(rx.t_ns, FRAME_NS);
}

static void test_send_batch_device_t_ns_is_earliest_start(void **state)
{
    fixture_t *f = *state;
    ps_can_frame_t rep = frame8(0x11, 0);
    rep.t_ns = 500000; /* driver turnaround: may start at 0.5 ms */
    assert_int_equal(ps_can_send_batch(&f->dev, &rep, 1), 1);
    ps_can_frame_t rx;
    f->clk.now_ns = 500000 + FRAME_NS - 1;
    assert_int_equal(ps_can_recv_batch(&f->host, &rx, 1), 0);
    f->clk.now_ns = 500000 + FRAME_NS;
    assert_int_equal(ps_can_recv_batch(&f->host, &rx, 1), 1);
    assert_int_equal(rx.t_ns, 500000 + FRAME_NS);

    /* A device t_ns in the past does not pull the frame earlier than now. */
    rep.t_ns = 1;
    f->clk.now_ns = 2000000;
    assert_int_equal(ps_can_send_batch(&f->dev, &rep, 1), 1);
    f->clk.now_ns = 2000000 + FRAME_NS;
    assert_int_equal(ps_can_recv_batch(&f->host, &rx, 1), 1);
    assert_int_equal(rx.t_ns, 2000000 + FRAME_NS);
}

static void test_send_batch_host_t_ns_ignored(void **state)
{
    fixture_t *f = *state;
    ps_can_frame_t cmd = frame8(0x1, 0);
    cmd.t_ns = 700000;
    assert_int_equal(ps_can_send_batch(&f->host, &cmd, 1), 1);
    ps_can_frame_t rx;
    f->clk.now_ns = FRAME_NS;
    assert_int_equal(ps_can_recv_batch(&f->dev, &rx, 1), 1);
    assert_int_equal(rx.t_ns, FRAME_NS);
}

static void test_send_batch_beyond_tick_capacity_counted_late(void **state)
{
    fixture_t *f = *state;
    /* 1000 bit times per tick hold 7 worst-case frames (945 us); the 8th
     * ends at 1080 us, after the tick. */
    ps_can_frame_t tx[8];
    for (unsigned i = 0; i < 8; i++)
        tx[i] = frame8(0x20 + i, 0);
    assert_int_equal(ps_can_send_batch(&f->host, tx, 7), 7);
    assert_int_equal(state_of(&f->host).n_late, 0);
    assert_int_equal(ps_can_send_batch(&f->host, &tx[7], 1), 1);
    assert_int_equal(state_of(&f->host).n_late, 1);
    assert_int_equal(state_of(&f->dev).n_late, 0);

    /* In the next tick, one frame sent at 1.9 ms on an idle wire ends at
     * 2.035 ms: past its tick's end at 2 ms, late. A device frame sent at
     * 2.1 ms is not. */
    f->clk.now_ns = 1900000;
    assert_int_equal(ps_can_send_batch(&f->host, tx, 1), 1);
    assert_int_equal(state_of(&f->host).n_late, 2);
    f->clk.now_ns = 2100000;
    assert_int_equal(ps_can_send_batch(&f->dev, tx, 1), 1);
    assert_int_equal(state_of(&f->dev).n_late, 0);
}

static void test_set_epoch_moves_tick_grid(void **state)
{
    fixture_t *f = *state;
    /* Grid from 0.5 ms: the tick holding 0.9 ms ends at 1.5 ms, so a frame
     * ending at 1.035 ms is on time (it would be late on the default grid). */
    ps_can_sim_set_epoch(f->bus, 500000);
    const ps_can_frame_t tx = frame8(0x1, 0);
    f->clk.now_ns = 900000;
    assert_int_equal(ps_can_send_batch(&f->host, &tx, 1), 1);
    assert_int_equal(state_of(&f->host).n_late, 0);
    /* Times before the epoch use the same grid extended backwards: with the
     * epoch at 1.5 ms, 1.4 ms lies in tick [0.5, 1.5) ms; on the idle wire the
     * frame ends at 1.535 ms, after that tick: late. */
    ps_can_sim_set_epoch(f->bus, 1500000);
    f->clk.now_ns = 1400000;
    assert_int_equal(ps_can_send_batch(&f->host, &tx, 1), 1);
    assert_int_equal(state_of(&f->host).n_late, 1);
}

static void test_get_state_load_equals_bits_over_capacity(void **state)
{
    fixture_t *f = *state;
    assert_true(state_of(&f->host).load == 0.0); /* no time elapsed yet */
    ps_can_frame_t tx[3] = {frame8(1, 0), frame8(2, 0), frame8(3, 0)};
    assert_int_equal(ps_can_send_batch(&f->host, tx, 3), 3);
    ps_can_frame_t short_frame = frame8(0x12, 0);
    short_frame.len = 2; /* 47 + 16 = 63 bits, stuffable 50 -> +12 = 75 */
    assert_int_equal(ps_can_send_batch(&f->dev, &short_frame, 1), 1);
    const uint64_t bits =
        3 * ps_canbus_frame_bits_max(8, false) + ps_canbus_frame_bits_max(2, false);
    assert_int_equal(bits, 3 * 135 + 75);
    f->clk.now_ns = 2 * PERIOD_NS;
    const ps_can_state_t h = state_of(&f->host), d = state_of(&f->dev);
    assert_int_equal(h.n_bits, bits);
    assert_int_equal(d.n_bits, bits);
    /* 480 bits in 2 ms at 1 Mbit/s: 480 / 2000 = 0.24 */
    assert_float_equal(h.load, (double)bits / (2e-3 * BITRATE), 1e-12);
    assert_float_equal(d.load, 0.24, 1e-12);
    assert_int_equal(h.mode, PS_CAN_BUS_ERROR_ACTIVE);
}

static void test_get_state_counters_per_end(void **state)
{
    fixture_t *f = *state;
    ps_can_frame_t tx[3] = {frame8(1, 0), frame8(2, 0), frame8(3, 0)};
    assert_int_equal(ps_can_send_batch(&f->host, tx, 3), 3);
    assert_int_equal(ps_can_send_batch(&f->dev, tx, 1), 1);
    f->clk.now_ns = PERIOD_NS;
    ps_can_frame_t rx[4];
    assert_int_equal(ps_can_recv_batch(&f->dev, rx, 4), 3);
    assert_int_equal(ps_can_recv_batch(&f->host, rx, 4), 1);
    const ps_can_state_t h = state_of(&f->host), d = state_of(&f->dev);
    assert_int_equal(h.n_tx_frames, 3);
    assert_int_equal(h.n_rx_frames, 1);
    assert_int_equal(d.n_tx_frames, 1);
    assert_int_equal(d.n_rx_frames, 3);
    assert_int_equal(h.n_tx_dropped + d.n_tx_dropped + h.n_rx_dropped + d.n_rx_dropped, 0);
    ps_can_state_t *null_state = NULL;
    assert_int_equal(ps_can_get_state(&f->host, null_state), -EINVAL);
}

static void test_send_batch_queue_full_drops_counted(void **state)
{
    fixture_t *f = *state; /* 4 slots per direction */
    ps_can_frame_t tx[6];
    for (unsigned i = 0; i < 6; i++)
        tx[i] = frame8(0x30 + i, 0);
    assert_int_equal(ps_can_send_batch(&f->host, tx, 6), 4);
    ps_can_state_t h = state_of(&f->host);
    assert_int_equal(h.n_tx_frames, 4);
    assert_int_equal(h.n_tx_dropped, 2);
    assert_int_equal(h.n_bits, 4 * 135); /* refused frames hold no wire time */
    assert_int_equal(state_of(&f->dev).n_tx_dropped, 0);
    /* The other direction has its own queue. */
    assert_int_equal(ps_can_send_batch(&f->dev, tx, 4), 4);
    /* Draining makes room again; the fifth frame follows the eighth on the wire. */
    f->clk.now_ns = 8 * FRAME_NS;
    ps_can_frame_t rx[4];
    assert_int_equal(ps_can_recv_batch(&f->dev, rx, 4), 4);
    assert_int_equal(ps_can_send_batch(&f->host, &tx[4], 2), 2);
    f->clk.now_ns = 10 * FRAME_NS;
    assert_int_equal(ps_can_recv_batch(&f->dev, rx, 4), 2);
    assert_int_equal(rx[0].id, 0x34);
    assert_int_equal(rx[1].t_ns, 10 * FRAME_NS);
}

static void test_send_batch_invalid_frame_einval(void **state)
{
    fixture_t *f = *state;
    ps_can_frame_t tx[2] = {frame8(0x1, 0), frame8(0x2, 0)};
    tx[1].len = 9;
    assert_int_equal(ps_can_send_batch(&f->host, tx, 2), -EINVAL);
    tx[1].len = 8;
    tx[1].id = 0x800; /* needs 12 bits, but is_ext is 0 */
    assert_int_equal(ps_can_send_batch(&f->host, tx, 2), -EINVAL);
    tx[1].is_ext = 1; /* fine as a 29-bit id */
    tx[1].id = PS_CAN_EFF_MASK + 1u;
    assert_int_equal(ps_can_send_batch(&f->host, tx, 2), -EINVAL);
    assert_int_equal(ps_can_send_batch(&f->host, NULL, 1), -EINVAL);
    assert_int_equal(state_of(&f->host).n_tx_frames, 0); /* all or nothing */
    assert_int_equal(ps_can_send_batch(&f->host, tx, 0), 0);
    tx[1].id = 0x800;
    assert_int_equal(ps_can_send_batch(&f->host, tx, 2), 2);
    /* A 29-bit frame takes 160 bit times. */
    f->clk.now_ns = FRAME_NS + 160000;
    ps_can_frame_t rx[2];
    assert_int_equal(ps_can_recv_batch(&f->dev, rx, 2), 2);
    assert_int_equal(rx[1].t_ns, FRAME_NS + 160000);
    assert_int_equal(ps_can_recv_batch(&f->dev, NULL, 2), -EINVAL);
}

static void test_create_bad_args_einval(void **state)
{
    (void)state;
    test_clock_t clk = {{test_clock_now, test_clock_sleep, NULL}, 0};
    clk.clock.ctx = &clk;
    ps_can_sim_bus_t *b = NULL;
    assert_int_equal(ps_can_sim_create(NULL, "x", BITRATE, &clk.clock, PERIOD_NS, 8), -EINVAL);
    assert_int_equal(ps_can_sim_create(&b, "x", 0, &clk.clock, PERIOD_NS, 8), -EINVAL);
    assert_int_equal(ps_can_sim_create(&b, "x", BITRATE, NULL, PERIOD_NS, 8), -EINVAL);
    assert_int_equal(ps_can_sim_create(&b, "x", BITRATE, &clk.clock, 0, 8), -EINVAL);
    assert_int_equal(ps_can_sim_create(&b, "x", BITRATE, &clk.clock, PERIOD_NS, 6), -EINVAL);
    assert_int_equal(ps_can_sim_create(&b, "x", BITRATE, &clk.clock, PERIOD_NS, 1), -EINVAL);
    assert_null(b);
    assert_int_equal(ps_can_sim_create(&b, NULL, BITRATE, &clk.clock, PERIOD_NS, 2), 0);
    const ps_can_port_t p = ps_can_sim_host_port(b);
    assert_string_equal(p.name, "sim");
    ps_can_sim_destroy(b);
    ps_can_sim_destroy(NULL);
}

/* ---- two threads, real clock ---------------------------------------------- */

#define N_ECHO 1000u
#define WINDOW 8u

typedef struct {
    ps_can_port_t port;
    const ps_clock_t *clock;
    unsigned n_done;
    unsigned n_errors;
    int64_t last_t_ns;
} echo_ctx_t;

static void *device_echo(void *arg)
{
    echo_ctx_t *c = arg;
    const int64_t give_up_ns = ps_clock_now_ns(c->clock) + 10 * PS_NS_PER_S;
    while (c->n_done < N_ECHO && ps_clock_now_ns(c->clock) < give_up_ns) {
        ps_can_frame_t rx[WINDOW];
        const int n = ps_can_recv_batch(&c->port, rx, WINDOW);
        if (n < 0) {
            c->n_errors++;
            break;
        }
        for (int i = 0; i < n; i++) {
            /* Arrival not before the clock, FIFO end times never go back. */
            if (rx[i].t_ns > ps_clock_now_ns(c->clock) || rx[i].t_ns < c->last_t_ns)
                c->n_errors++;
            c->last_t_ns = rx[i].t_ns;
            ps_can_frame_t echo = rx[i];
            echo.id = rx[i].id + 0x100u;
            echo.data[7] = (uint8_t)(rx[i].data[7] ^ 0xFFu);
            echo.t_ns = 0;
            while (ps_can_send_batch(&c->port, &echo, 1) != 1)
                sched_yield(); /* queue full: the host is behind, retry */
            c->n_done++;
        }
        if (n == 0)
            sched_yield();
    }
    return NULL;
}

static void test_two_threads_host_sends_device_echoes(void **state)
{
    (void)state;
    const ps_clock_t *clock = ps_clock_monotonic();
    ps_can_sim_bus_t *bus = NULL;
    assert_int_equal(ps_can_sim_create(&bus, "can1", BITRATE, clock, PERIOD_NS, 16), 0);
    echo_ctx_t dev = {.port = ps_can_sim_device_port(bus), .clock = clock};
    const ps_can_port_t host = ps_can_sim_host_port(bus);
    pthread_t th;
    assert_int_equal(pthread_create(&th, NULL, device_echo, &dev), 0);

    unsigned n_sent = 0, n_got = 0, n_bad = 0;
    int64_t last_t_ns = 0;
    const int64_t give_up_ns = ps_clock_now_ns(clock) + 10 * PS_NS_PER_S;
    while (n_got < N_ECHO && ps_clock_now_ns(clock) < give_up_ns) {
        while (n_sent < N_ECHO && n_sent - n_got < WINDOW) {
            ps_can_frame_t tx;
            memset(&tx, 0, sizeof tx);
            tx.id = n_sent & 0xFFu;
            tx.len = 8;
            memcpy(tx.data, &n_sent, sizeof n_sent);
            tx.data[7] = (uint8_t)n_sent;
            if (ps_can_send_batch(&host, &tx, 1) != 1)
                break;
            n_sent++;
        }
        ps_can_frame_t rx[WINDOW];
        const int n = ps_can_recv_batch(&host, rx, WINDOW);
        assert_true(n >= 0);
        for (int i = 0; i < n; i++) {
            unsigned seq;
            memcpy(&seq, rx[i].data, sizeof seq);
            if (seq != n_got || rx[i].id != (n_got & 0xFFu) + 0x100u ||
                rx[i].data[7] != (uint8_t)(n_got ^ 0xFFu) || rx[i].t_ns < last_t_ns + FRAME_NS)
                n_bad++;
            last_t_ns = rx[i].t_ns;
            n_got++;
        }
        if (n == 0)
            sched_yield();
    }
    assert_int_equal(pthread_join(th, NULL), 0);
    assert_int_equal(n_got, N_ECHO);
    assert_int_equal(n_bad, 0);
    assert_int_equal(dev.n_done, N_ECHO);
    assert_int_equal(dev.n_errors, 0);
    const ps_can_state_t h = state_of(&host), d = state_of(&dev.port);
    assert_int_equal(h.n_tx_frames, N_ECHO);
    assert_int_equal(h.n_rx_frames, N_ECHO);
    assert_int_equal(d.n_rx_frames, N_ECHO);
    assert_int_equal(d.n_tx_frames, N_ECHO);
    assert_int_equal(h.n_bits, 2u * N_ECHO * 135u);
    /* 2000 frames of 135 us each need at least 0.27 s of wire: load <= 1. */
    assert_true(h.load > 0.0 && h.load <= 1.0);
    ps_can_sim_destroy(bus);
}

/* ---- the transport contract every port keeps (tests/contract) ---------- */

static int sim_far_send(void *ctx, const ps_can_frame_t *f)
{
    fixture_t *fx = ctx;
    return ps_can_send_batch(&fx->dev, f, 1) == 1 ? 0 : -EIO;
}

static int sim_far_recv(void *ctx, ps_can_frame_t *out)
{
    fixture_t *fx = ctx;
    return ps_can_recv_batch(&fx->dev, out, 1);
}

static void sim_settle(void *ctx)
{
    fixture_t *fx = ctx;
    fx->clk.now_ns += 10 * PERIOD_NS; /* the wire delivers everything in flight */
}

static int64_t sim_now(void *ctx)
{
    fixture_t *fx = ctx;
    return fx->clk.now_ns;
}

static void run_contract(fixture_t *f, bool is_fd)
{
    const ps_can_contract_t c = {.port = f->host,
                                 .ctx = f,
                                 .far_send = sim_far_send,
                                 .far_recv = sim_far_recv,
                                 .settle = sim_settle,
                                 .now_ns = sim_now,
                                 .is_fd = is_fd};
    ps_can_contract_check(&c);
}

static void test_sim_bus_keeps_the_transport_contract(void **state)
{
    run_contract(*state, false);
}

static void test_sim_fd_bus_keeps_the_transport_contract(void **state)
{
    fixture_t *f = *state;
    assert_int_equal(ps_can_sim_set_fd(f->bus, 5000000), 0);
    run_contract(f, true);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_sim_bus_keeps_the_transport_contract, setup, teardown),
        cmocka_unit_test_setup_teardown(test_sim_fd_bus_keeps_the_transport_contract, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_send_batch_one_frame_arrives_after_frame_time, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_send_batch_fd_frame_data_phase_at_data_bitrate, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_send_batch_later_send_time_shifts_arrival, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_send_batch_back_to_back_frames_queue_on_wire, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_recv_batch_respects_max_and_fifo, setup, teardown),
        cmocka_unit_test_setup_teardown(test_send_batch_both_directions_share_wire, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_send_batch_device_t_ns_is_earliest_start, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_send_batch_host_t_ns_ignored, setup, teardown),
        cmocka_unit_test_setup_teardown(test_send_batch_beyond_tick_capacity_counted_late, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_set_epoch_moves_tick_grid, setup, teardown),
        cmocka_unit_test_setup_teardown(test_get_state_load_equals_bits_over_capacity, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_get_state_counters_per_end, setup, teardown),
        cmocka_unit_test_setup_teardown(test_send_batch_queue_full_drops_counted, setup_small_queue,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_send_batch_invalid_frame_einval, setup, teardown),
        cmocka_unit_test(test_create_bad_args_einval),
        cmocka_unit_test(test_two_threads_host_sends_device_echoes),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
