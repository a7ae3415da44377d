#include "ps_can_contract.h"

#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <string.h>

static ps_can_frame_t frame(uint32_t id, bool is_ext, uint8_t len, uint8_t seed)
{
    ps_can_frame_t f;
    memset(&f, 0, sizeof(f));
    f.id = id;
    f.is_ext = is_ext;
    f.len = len;
    for (uint8_t i = 0; i < len; i++)
        f.data[i] = (uint8_t)(seed + 7u * i);
    return f;
}

static void assert_same(const ps_can_frame_t *a, const ps_can_frame_t *b)
{
    assert_int_equal(a->id, b->id);
    assert_int_equal(a->is_ext, b->is_ext);
    assert_int_equal(a->len, b->len);
    assert_int_equal(a->is_fd, b->is_fd);
    assert_int_equal(a->is_brs, b->is_brs);
    assert_memory_equal(a->data, b->data, a->len);
}

static void check_empty_receive(const ps_can_contract_t *c)
{
    ps_can_frame_t rx[4];
    assert_int_equal(ps_can_recv_batch(&c->port, rx, 4), 0);
}

static void check_batch_out(const ps_can_contract_t *c, ps_can_frame_t *tx, int n)
{
    for (int i = 0; i < n; i++)
        tx[i] = frame(i % 2 ? 0x1000000u + (uint32_t)i : 0x100u + (uint32_t)i, i % 2,
                      (uint8_t)(i % 9), (uint8_t)i);
    assert_int_equal(ps_can_send_batch(&c->port, tx, (size_t)n), n);
    c->settle(c->ctx);
    for (int i = 0; i < n; i++) {
        ps_can_frame_t got;
        assert_int_equal(c->far_recv(c->ctx, &got), 1);
        assert_same(&got, &tx[i]);
    }
}

static void check_frames_in(const ps_can_contract_t *c, int n)
{
    ps_can_frame_t sent[16];
    for (int i = 0; i < n; i++) {
        sent[i] = frame(0x200u + (uint32_t)i, i == 3, 8, (uint8_t)(0x40 + i));
        assert_int_equal(c->far_send(c->ctx, &sent[i]), 0);
    }
    c->settle(c->ctx);
    const int64_t now = c->now_ns(c->ctx);
    ps_can_frame_t rx[16];
    int got = 0;
    for (int call = 0; call < 2 * n && got < n; call++) {
        const int k = ps_can_recv_batch(&c->port, rx + got, 3); /* small max: split */
        assert_true(k >= 0 && k <= 3);
        got += k;
    }
    assert_int_equal(got, n);
    for (int i = 0; i < n; i++) {
        assert_same(&rx[i], &sent[i]);
        assert_true(rx[i].t_ns <= now);
        if (i > 0)
            assert_true(rx[i].t_ns >= rx[i - 1].t_ns);
    }
}

static void check_fd(const ps_can_contract_t *c)
{
    ps_can_frame_t f = frame(0x321, false, 64, 9);
    f.is_fd = f.is_brs = 1;
    assert_int_equal(ps_can_send_batch(&c->port, &f, 1), 1);
    c->settle(c->ctx);
    ps_can_frame_t got;
    assert_int_equal(c->far_recv(c->ctx, &got), 1);
    assert_same(&got, &f);
    ps_can_frame_t g = frame(0x1abcdef, true, 24, 3);
    g.is_fd = 1;
    assert_int_equal(c->far_send(c->ctx, &g), 0);
    c->settle(c->ctx);
    ps_can_frame_t rx[2];
    assert_int_equal(ps_can_recv_batch(&c->port, rx, 2), 1);
    assert_same(&rx[0], &g);
}

static void check_refusals(const ps_can_contract_t *c)
{
    ps_can_frame_t bad[2] = {frame(0x10, false, 1, 0),
                             frame(0x800, false, 1, 0)}; /* id > 11 bits */
    assert_int_equal(ps_can_send_batch(&c->port, bad, 2), -EINVAL);
    bad[1] = frame(0x10, false, 9, 0); /* no classical frame has 9 bytes */
    assert_int_equal(ps_can_send_batch(&c->port, bad, 2), -EINVAL);
    if (!c->is_fd) {
        bad[1] = frame(0x10, false, 12, 0);
        bad[1].is_fd = 1;
        assert_int_equal(ps_can_send_batch(&c->port, bad, 2), -EINVAL);
    }
    c->settle(c->ctx);
    ps_can_frame_t got;
    assert_int_equal(c->far_recv(c->ctx, &got), 0); /* nothing of a refused batch left */
}

void ps_can_contract_check(const ps_can_contract_t *c)
{
    ps_can_state_t before, after;
    assert_int_equal(ps_can_get_state(&c->port, &before), 0);
    check_empty_receive(c);
    ps_can_frame_t tx[12];
    check_batch_out(c, tx, 12);
    check_frames_in(c, 7);
    if (c->is_fd)
        check_fd(c);
    check_refusals(c);
    check_empty_receive(c);
    assert_int_equal(ps_can_get_state(&c->port, &after), 0);
    assert_int_equal(after.mode, PS_CAN_BUS_ERROR_ACTIVE);
    assert_int_equal(after.n_tx_frames - before.n_tx_frames, 12u + (c->is_fd ? 1u : 0u));
    assert_int_equal(after.n_rx_frames - before.n_rx_frames, 7u + (c->is_fd ? 1u : 0u));
}
