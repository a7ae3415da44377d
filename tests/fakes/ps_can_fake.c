#include "ps_can_fake.h"

#include <errno.h>
#include <string.h>

/* Consume one scripted failure if any is armed. @return its code or 0 */
static int take_fault(ps_can_fake_fault_t *fault)
{
    if (fault->n_calls == 0)
        return 0;
    fault->n_calls--;
    return fault->err;
}

static int fake_send_batch(void *ctx, const ps_can_frame_t *frames, size_t n)
{
    ps_can_fake_t *f = ctx;
    f->n_send_calls++;
    const int err = take_fault(&f->send_fault);
    if (err != 0)
        return err;
    if (f->state.mode == PS_CAN_BUS_OFF)
        return -ENETDOWN;
    if (n > 0 && frames == NULL)
        return -EINVAL;
    size_t n_ok = n;
    if (f->tx_accept_max != 0 && n_ok > f->tx_accept_max)
        n_ok = f->tx_accept_max;
    for (size_t i = 0; i < n_ok; i++) {
        if (f->n_sent < PS_CAN_FAKE_MAX_SENT)
            f->sent[f->n_sent++] = frames[i];
    }
    f->n_sent_total += n_ok;
    f->state.n_tx_frames += n_ok;
    f->state.n_tx_dropped += n - n_ok;
    return (int)n_ok;
}

static int fake_recv_batch(void *ctx, ps_can_frame_t *out, size_t max)
{
    ps_can_fake_t *f = ctx;
    f->n_recv_calls++;
    const int err = take_fault(&f->recv_fault);
    if (err != 0)
        return err;
    if (f->state.mode == PS_CAN_BUS_OFF)
        return 0;
    if (max > 0 && out == NULL)
        return -EINVAL;
    if (f->rx_per_call_max != 0 && max > f->rx_per_call_max)
        max = f->rx_per_call_max;
    size_t n = 0;
    while (n < max && f->rx_tail != f->rx_head) {
        out[n++] = f->rx[f->rx_tail % PS_CAN_FAKE_MAX_RX];
        f->rx_tail++;
    }
    f->state.n_rx_frames += n;
    return (int)n;
}

static int fake_get_state(void *ctx, ps_can_state_t *out)
{
    ps_can_fake_t *f = ctx;
    f->n_state_calls++;
    const int err = take_fault(&f->state_fault);
    if (err != 0)
        return err;
    if (out == NULL)
        return -EINVAL;
    *out = f->state;
    return 0;
}

static void fake_close(void *ctx)
{
    ps_can_fake_t *f = ctx;
    f->n_close_calls++;
}

static const ps_can_ops_t FAKE_OPS = {
    .send_batch = fake_send_batch,
    .recv_batch = fake_recv_batch,
    .get_state = fake_get_state,
    .close = fake_close,
};

void ps_can_fake_init(ps_can_fake_t *f)
{
    memset(f, 0, sizeof *f);
    f->state.mode = PS_CAN_BUS_ERROR_ACTIVE;
}

ps_can_port_t ps_can_fake_port(ps_can_fake_t *f, const char *name)
{
    return (ps_can_port_t){.ops = &FAKE_OPS, .ctx = f, .name = name};
}

int ps_can_fake_push_rx(ps_can_fake_t *f, const ps_can_frame_t *frame)
{
    if (f->rx_head - f->rx_tail >= PS_CAN_FAKE_MAX_RX)
        return -ENOSPC;
    f->rx[f->rx_head % PS_CAN_FAKE_MAX_RX] = *frame;
    f->rx_head++;
    return 0;
}

size_t ps_can_fake_rx_pending(const ps_can_fake_t *f)
{
    return f->rx_head - f->rx_tail;
}

void ps_can_fake_fail_send(ps_can_fake_t *f, int err, uint32_t n_calls)
{
    f->send_fault = (ps_can_fake_fault_t){.err = err, .n_calls = n_calls};
}

void ps_can_fake_fail_recv(ps_can_fake_t *f, int err, uint32_t n_calls)
{
    f->recv_fault = (ps_can_fake_fault_t){.err = err, .n_calls = n_calls};
}

void ps_can_fake_fail_state(ps_can_fake_t *f, int err, uint32_t n_calls)
{
    f->state_fault = (ps_can_fake_fault_t){.err = err, .n_calls = n_calls};
}

void ps_can_fake_set_bus_mode(ps_can_fake_t *f, ps_can_bus_mode_t mode, uint16_t tec, uint16_t rec)
{
    f->state.mode = mode;
    f->state.tx_error_count = tec;
    f->state.rx_error_count = rec;
}

void ps_can_fake_clear_sent(ps_can_fake_t *f)
{
    f->n_sent = 0;
}

const ps_can_frame_t *ps_can_fake_last_sent(const ps_can_fake_t *f, uint32_t id, uint8_t is_ext)
{
    for (size_t i = f->n_sent; i > 0; i--) {
        const ps_can_frame_t *fr = &f->sent[i - 1];
        if (fr->id == id && (fr->is_ext != 0) == (is_ext != 0))
            return fr;
    }
    return NULL;
}
