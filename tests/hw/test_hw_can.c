/*
 * Tests of drivers/ps_can_socket on real kernel CAN interfaces, run inside
 * the qemu VM of `make test-hw` (tools/qemu/in-vm.sh makes vcan0, vcan1 (FD
 * capable), vcan2 (classical, mtu 16) and the pair vxcan0 <-> vxcan1). A
 * plain raw socket plays the far end of the bus.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "../../drivers/ps_can_socket.h"
#include "../../rt/ps_err.h"
#include "../contract/ps_can_contract.h"

static ps_can_socket_t g_sock, g_sock2;

static int64_t mono_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

static void sh(const char *cmd)
{
    assert_int_equal(system(cmd), 0);
}

/* The far end: a raw socket with no filter, FD frames on. */
static int peer_open(const char *ifname)
{
    int fd = socket(PF_CAN, SOCK_RAW, CAN_RAW);
    assert_true(fd >= 0);
    const int on = 1;
    (void)setsockopt(fd, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof on);
    struct sockaddr_can a = {.can_family = AF_CAN, .can_ifindex = (int)if_nametoindex(ifname)};
    assert_int_equal(bind(fd, (struct sockaddr *)&a, sizeof a), 0);
    return fd;
}

static void peer_send(int fd, uint32_t can_id, uint8_t len, bool is_fd)
{
    struct canfd_frame f;
    memset(&f, 0, sizeof f);
    f.can_id = can_id;
    f.len = len;
    if (is_fd)
        f.flags = CANFD_BRS;
    for (uint8_t i = 0; i < len; i++)
        f.data[i] = (uint8_t)(0xa0 + i);
    const size_t n = is_fd ? CANFD_MTU : CAN_MTU;
    assert_int_equal(write(fd, &f, n), (ssize_t)n);
}

static int recv_some(ps_can_socket_t *s, ps_can_frame_t *out, size_t max, int want)
{
    ps_can_port_t p = ps_can_socket_port(s);
    int total = 0;
    for (int spin = 0; spin < 200 && total < want; spin++) {
        int n = ps_can_recv_batch(&p, out + total, max - (size_t)total);
        assert_true(n >= 0);
        total += n;
        if (total < want)
            usleep(1000);
    }
    return total;
}

static void open_sock(ps_can_socket_t *s, const char *ifname, bool is_fd, uint32_t n_filters,
                      const ps_can_socket_filter_t *filters)
{
    ps_can_socket_cfg_t cfg = {.is_fd = is_fd, .bitrate = 1000000, .n_filters = n_filters};
    snprintf(cfg.ifname, sizeof cfg.ifname, "%s", ifname);
    memcpy(cfg.filters, filters, n_filters * sizeof(filters[0]));
    char err[256] = "";
    int rc = ps_can_socket_open(s, &cfg, err, sizeof err);
    if (rc != 0)
        print_error("open %s: %s\n", ifname, err);
    assert_int_equal(rc, 0);
}

static void test_filters_pass_only_the_expected_ids_with_monotonic_stamps(void **state)
{
    (void)state;
    const ps_can_socket_filter_t f[] = {
        {.id = 0x101, .mask = 0x7ff},
        {.id = 0x02000500, .mask = 0x1f00ffff, .is_ext = true}, /* RobStride-like */
    };
    open_sock(&g_sock, "vcan0", false, 2, f);
    int peer = peer_open("vcan0");
    const int64_t t0 = mono_ns();
    peer_send(peer, 0x101, 8, false);
    peer_send(peer, 0x102, 8, false);                     /* other id */
    peer_send(peer, 0x101 | CAN_EFF_FLAG, 8, false);      /* 29-bit, same low bits */
    peer_send(peer, 0x101 | CAN_RTR_FLAG, 0, false);      /* remote frame */
    peer_send(peer, 0x02ab0500 | CAN_EFF_FLAG, 8, false); /* fault bits differ: passes */
    peer_send(peer, 0x02ab0600 | CAN_EFF_FLAG, 8, false); /* other drive */
    ps_can_frame_t rx[16];
    const int n = recv_some(&g_sock, rx, 16, 2);
    const int64_t t1 = mono_ns();
    usleep(20000);
    ps_can_port_t p = ps_can_socket_port(&g_sock);
    assert_int_equal(ps_can_recv_batch(&p, rx + n, 16 - (size_t)n), 0); /* nothing else came */
    assert_int_equal(n, 2);
    assert_int_equal(rx[0].id, 0x101);
    assert_false(rx[0].is_ext);
    assert_int_equal(rx[0].len, 8);
    assert_int_equal(rx[0].data[7], 0xa7);
    assert_int_equal(rx[1].id, 0x02ab0500);
    assert_true(rx[1].is_ext);
    for (int i = 0; i < 2; i++) {
        assert_true(rx[i].t_ns >= t0 - 1000000 && rx[i].t_ns <= t1);
    }
    ps_can_state_t st;
    assert_int_equal(ps_can_get_state(&p, &st), 0);
    assert_int_equal(st.n_rx_frames, 2);
    assert_int_equal(st.n_rx_dropped, 0);
    close(peer);
    ps_can_socket_close(&g_sock);
}

static void test_batches_go_out_in_order_without_blocking(void **state)
{
    (void)state;
    open_sock(&g_sock, "vcan0", false, 0, NULL);
    int peer = peer_open("vcan0");
    ps_can_frame_t tx[40];
    for (int i = 0; i < 40; i++)
        tx[i] = (ps_can_frame_t){.id = (uint32_t)(0x200 + i), .len = 2, .data = {(uint8_t)i}};
    tx[39].is_ext = 1;
    tx[39].id = 0x1abcdef0;
    ps_can_port_t p = ps_can_socket_port(&g_sock);
    assert_int_equal(ps_can_send_batch(&p, tx, 40), 40);
    for (int i = 0; i < 40; i++) {
        struct can_frame f;
        assert_int_equal(read(peer, &f, sizeof f), (ssize_t)sizeof f);
        if (i < 39)
            assert_int_equal(f.can_id, 0x200u + (unsigned)i);
        else
            assert_int_equal(f.can_id, 0x1abcdef0u | CAN_EFF_FLAG);
        assert_int_equal(f.data[0], i);
    }
    /* A frame that cannot exist is the caller's bug: refused whole. */
    tx[0].len = 9;
    assert_int_equal(ps_can_send_batch(&p, tx, 2), -EINVAL);
    close(peer);
    ps_can_socket_close(&g_sock);
}

static void test_fd_frames_both_ways_and_fd_refused_on_a_classical_interface(void **state)
{
    (void)state;
    const ps_can_socket_filter_t f[] = {{.id = 0x300, .mask = 0x700}};
    open_sock(&g_sock, "vcan1", true, 1, f);
    int peer = peer_open("vcan1");
    ps_can_frame_t tx = {.id = 0x123, .len = 64, .is_fd = 1, .is_brs = 1};
    for (int i = 0; i < 64; i++)
        tx.data[i] = (uint8_t)i;
    ps_can_port_t p = ps_can_socket_port(&g_sock);
    assert_int_equal(ps_can_send_batch(&p, &tx, 1), 1);
    struct canfd_frame k;
    assert_int_equal(read(peer, &k, sizeof k), (ssize_t)CANFD_MTU);
    assert_int_equal(k.len, 64);
    assert_int_equal(k.flags & CANFD_BRS, CANFD_BRS);
    assert_int_equal(k.data[63], 63);
    peer_send(peer, 0x301, 48, true);
    peer_send(peer, 0x302, 8, false); /* classical frame on an FD socket */
    ps_can_frame_t rx[4];
    assert_int_equal(recv_some(&g_sock, rx, 4, 2), 2);
    assert_true(rx[0].is_fd && rx[0].is_brs);
    assert_int_equal(rx[0].len, 48);
    assert_int_equal(rx[0].data[47], 0xa0 + 47);
    assert_false(rx[1].is_fd);
    close(peer);
    ps_can_socket_close(&g_sock);
    /* vcan2 has mtu 16: the kernel refuses FD frames on it, and open says so. */
    ps_can_socket_cfg_t cfg = {.ifname = "vcan2", .is_fd = true};
    char err[256];
    open_sock(&g_sock, "vcan2", false, 0, NULL); /* classical is fine */
    tx.len = 12;
    p = ps_can_socket_port(&g_sock);
    assert_int_equal(ps_can_send_batch(&p, &tx, 1), -EINVAL); /* FD on a classical socket */
    ps_can_socket_close(&g_sock);
    (void)ps_can_socket_open(&g_sock, &cfg, err, sizeof err);
    /* Binding an FD socket to an mtu-16 interface succeeds in the kernel, but
     * the start-up check refuses the bus. */
    ps_can_socket_close(&g_sock);
    ps_can_socket_iface_t info;
    assert_int_equal(ps_can_socket_query("vcan2", &info, err, sizeof err), 0);
    const ps_canbus_bus_cfg_t bus = {
        .ifname = "vcan2", .bitrate = 1000000, .is_fd = true, .data_bitrate = 5000000};
    char note[128];
    assert_int_equal(ps_can_socket_check_iface(&bus, &info, 16, err, sizeof err, note, sizeof note),
                     -PS_ERR_CONFIG);
    assert_non_null(strstr(err, "vcan2 has mtu 16, CAN FD needs 72"));
}

/* The kernel passes error frames written on a vcan to sockets that asked for
 * them: the far end plays the controller's error reports. */
static void test_error_frames_reach_the_bus_state(void **state)
{
    (void)state;
    open_sock(&g_sock, "vcan0", false, 0, NULL);
    int peer = peer_open("vcan0");
    struct can_frame e;
    memset(&e, 0, sizeof e);
    e.len = CAN_ERR_DLC;
    e.can_id = CAN_ERR_FLAG | CAN_ERR_CRTL | CAN_ERR_CNT;
    e.data[1] = CAN_ERR_CRTL_TX_PASSIVE;
    e.data[6] = 130;
    e.data[7] = 5;
    ssize_t w = write(peer, &e, sizeof e);
    assert_int_equal(w, (ssize_t)sizeof e);
    ps_can_frame_t rx[4];
    ps_can_port_t p = ps_can_socket_port(&g_sock);
    ps_can_state_t st;
    for (int i = 0; i < 100; i++) {
        assert_int_equal(ps_can_recv_batch(&p, rx, 4), 0); /* no data frame for the loop */
        assert_int_equal(ps_can_get_state(&p, &st), 0);
        if (st.n_err_frames > 0)
            break;
        usleep(1000);
    }
    assert_int_equal(st.mode, PS_CAN_BUS_ERROR_PASSIVE);
    assert_int_equal(st.tx_error_count, 130);
    e.can_id = CAN_ERR_FLAG | CAN_ERR_BUSOFF;
    assert_int_equal(write(peer, &e, sizeof e), (ssize_t)sizeof e);
    e.can_id = CAN_ERR_FLAG | CAN_ERR_RESTARTED;
    for (int i = 0; i < 100 && st.mode != PS_CAN_BUS_OFF; i++) {
        usleep(1000);
        (void)ps_can_recv_batch(&p, rx, 4);
        (void)ps_can_get_state(&p, &st);
    }
    assert_int_equal(st.mode, PS_CAN_BUS_OFF);
    assert_int_equal(write(peer, &e, sizeof e), (ssize_t)sizeof e);
    for (int i = 0; i < 100 && st.mode != PS_CAN_BUS_ERROR_ACTIVE; i++) {
        usleep(1000);
        (void)ps_can_recv_batch(&p, rx, 4);
        (void)ps_can_get_state(&p, &st);
    }
    assert_int_equal(st.mode, PS_CAN_BUS_ERROR_ACTIVE);
    assert_int_equal(st.n_bus_off, 1);
    assert_int_equal(st.n_restarts, 1);
    /* A bus-off and a data frame right behind it, taken in one batch: the
     * frame ends the episode, but the next state read still reports it. */
    ps_can_socket_close(&g_sock);
    const ps_can_socket_filter_t all = {0, 0, false};
    open_sock(&g_sock, "vcan0", false, 1, &all);
    p = ps_can_socket_port(&g_sock);
    e.can_id = CAN_ERR_FLAG | CAN_ERR_BUSOFF;
    assert_int_equal(write(peer, &e, sizeof e), (ssize_t)sizeof e);
    peer_send(peer, 0x12, 1, false);
    assert_int_equal(recv_some(&g_sock, rx, 4, 1), 1);
    assert_int_equal(ps_can_get_state(&p, &st), 0);
    assert_int_equal(st.mode, PS_CAN_BUS_OFF);
    assert_int_equal(ps_can_get_state(&p, &st), 0);
    assert_int_equal(st.mode, PS_CAN_BUS_ERROR_ACTIVE); /* once */
    assert_int_equal(st.n_bus_off, 1);
    close(peer);
    ps_can_socket_close(&g_sock);
}

/* A token bucket of 10 kbit/s stands for a controller that cannot keep up,
 * and under it a plain FIFO whose length is the interface's txqueuelen, set
 * to 2 (a vcan sends at once, so without the bucket no queue ever fills):
 * the send takes what fits, counts the rest, and returns at once. */
static void test_a_full_queue_is_counted_never_waited_for(void **state)
{
    (void)state;
    sh("ip link add dev vcan9 type vcan && ip link set vcan9 txqueuelen 2 && "
       "ip link set vcan9 up && "
       "tc qdisc add dev vcan9 root handle 1: tbf rate 10kbit burst 100 latency 1s && "
       "tc qdisc add dev vcan9 parent 1:1 handle 10: pfifo");
    open_sock(&g_sock, "vcan9", false, 0, NULL);
    ps_can_frame_t tx[64];
    for (int i = 0; i < 64; i++)
        tx[i] = (ps_can_frame_t){.id = 0x10, .len = 8};
    ps_can_port_t p = ps_can_socket_port(&g_sock);
    const int64_t t0 = mono_ns();
    const int n = ps_can_send_batch(&p, tx, 64);
    const int n2 = ps_can_send_batch(&p, tx, 64);
    const int64_t dt = mono_ns() - t0;
    print_message("txqueuelen 2 under a 10 kbit/s bucket: %d then %d of 64 frames taken in "
                  "%.3f ms\n",
                  n, n2, (double)dt * 1e-6);
    /* The bucket's 100 bytes pass 6 frames (an skb of a CAN frame is 16
     * bytes) at once; 2 more wait in the FIFO; the rest are refused. */
    assert_true(n >= 2 && n <= 9);
    assert_true(n2 >= 0 && n2 <= 2);
    assert_true(dt < 50000000); /* returned, did not wait for the bucket */
    ps_can_state_t st;
    assert_int_equal(ps_can_get_state(&p, &st), 0);
    assert_int_equal(st.n_tx_saturated, 2);
    assert_int_equal(st.n_tx_dropped, 128u - (unsigned)(n + n2));
    assert_int_equal(st.n_tx_frames, (unsigned)(n + n2));
    ps_can_socket_close(&g_sock);
    sh("ip link del dev vcan9");
}

static void test_receive_overflow_is_counted(void **state)
{
    (void)state;
    open_sock(&g_sock, "vcan0", false, 1,
              (const ps_can_socket_filter_t[]){{.id = 0x55, .mask = 0x7ff}});
    const int sz = 4096; /* the kernel doubles it; a few frames fit */
    assert_int_equal(setsockopt(g_sock.fd, SOL_SOCKET, SO_RCVBUF, &sz, sizeof sz), 0);
    int peer = peer_open("vcan0");
    for (int i = 0; i < 500; i++)
        peer_send(peer, 0x55, 8, false);
    ps_can_frame_t rx[64];
    ps_can_port_t p = ps_can_socket_port(&g_sock);
    int got = 0, n;
    while ((n = ps_can_recv_batch(&p, rx, 64)) > 0)
        got += n;
    /* The kernel tells the drop count with the next frame it queues. */
    peer_send(peer, 0x55, 8, false);
    got += recv_some(&g_sock, rx, 64, 1) - 1;
    ps_can_state_t st;
    assert_int_equal(ps_can_get_state(&p, &st), 0);
    print_message("rx overflow: %d frames taken, %llu counted dropped of 500\n", got,
                  (unsigned long long)st.n_rx_dropped);
    assert_true(st.n_rx_dropped > 0);
    assert_int_equal((uint64_t)got + st.n_rx_dropped, 500);
    close(peer);
    ps_can_socket_close(&g_sock);
}

static void test_check_and_send_on_a_downed_interface(void **state)
{
    (void)state;
    char err[512], note[128];
    ps_can_socket_iface_t info;
    assert_int_equal(ps_can_socket_query("vcan1", &info, err, sizeof err), 0);
    assert_true(info.exists && info.is_can && info.is_up);
    assert_string_equal(info.kind, "vcan");
    assert_int_equal(info.mtu, CANFD_MTU);
    const ps_canbus_bus_cfg_t bus = {.ifname = "vcan1", .bitrate = 1000000};
    assert_int_equal(ps_can_socket_check_iface(&bus, &info, 64, err, sizeof err, note, sizeof note),
                     0);
    assert_non_null(strstr(note, "vcan1: virtual (vcan), bitrate not checked"));
    open_sock(&g_sock, "vcan1", false, 0, NULL);
    sh("ip link set vcan1 down && ip link set vcan1 txqueuelen 4");
    assert_int_equal(ps_can_socket_query("vcan1", &info, err, sizeof err), 0);
    assert_int_equal(ps_can_socket_check_iface(&bus, &info, 64, err, sizeof err, note, sizeof note),
                     -PS_ERR_CONFIG);
    assert_non_null(strstr(err, "vcan1 is down: `sudo ip link set vcan1 up`"));
    assert_non_null(strstr(err, "`sudo ip link set vcan1 txqueuelen 64`"));
    ps_can_frame_t tx = {.id = 1, .len = 1};
    ps_can_port_t p = ps_can_socket_port(&g_sock);
    assert_int_equal(ps_can_send_batch(&p, &tx, 1), -ENETDOWN);
    sh("ip link set vcan1 txqueuelen 1000 && ip link set vcan1 up");
    ps_can_socket_close(&g_sock);
    assert_int_equal(ps_can_socket_query("vxcan0", &info, err, sizeof err), 0);
    assert_string_equal(info.kind, "vxcan");
}

/* Two buses served in one "tick": each socket only sees its own. */
static void test_two_buses_in_one_tick_over_a_vxcan_pair(void **state)
{
    (void)state;
    const ps_can_socket_filter_t all = {.id = 0, .mask = 0};
    open_sock(&g_sock, "vxcan0", false, 1, &all);
    open_sock(&g_sock2, "vcan0", false, 1, &all);
    int far = peer_open("vxcan1");
    int peer0 = peer_open("vcan0");
    ps_can_frame_t a = {.id = 0x11, .len = 1, .data = {1}}, b = {.id = 0x22, .len = 1, .data = {2}};
    ps_can_port_t pa = ps_can_socket_port(&g_sock), pb = ps_can_socket_port(&g_sock2);
    assert_int_equal(ps_can_send_batch(&pa, &a, 1), 1);
    assert_int_equal(ps_can_send_batch(&pb, &b, 1), 1);
    struct can_frame f;
    assert_int_equal(read(far, &f, sizeof f), (ssize_t)sizeof f);
    assert_int_equal(f.can_id, 0x11);
    assert_int_equal(read(peer0, &f, sizeof f), (ssize_t)sizeof f);
    assert_int_equal(f.can_id, 0x22);
    peer_send(far, 0x33, 2, false);
    ps_can_frame_t rx[4];
    assert_int_equal(recv_some(&g_sock, rx, 4, 1), 1);
    assert_int_equal(rx[0].id, 0x33);
    assert_int_equal(ps_can_recv_batch(&pb, rx, 4), 0);
    close(far);
    close(peer0);
    ps_can_socket_close(&g_sock);
    ps_can_socket_close(&g_sock2);
}

/* ---- the transport contract, as the simulated wire keeps it ------------ */

static int far_send(void *ctx, const ps_can_frame_t *f)
{
    const int fd = *(int *)ctx;
    struct canfd_frame k;
    memset(&k, 0, sizeof k);
    k.can_id = f->is_ext ? (f->id | CAN_EFF_FLAG) : f->id;
    k.len = f->len;
    k.flags = f->is_brs ? CANFD_BRS : 0;
    memcpy(k.data, f->data, f->len);
    const size_t n = f->is_fd ? CANFD_MTU : CAN_MTU;
    return write(fd, &k, n) == (ssize_t)n ? 0 : -errno;
}

static int far_recv(void *ctx, ps_can_frame_t *out)
{
    const int fd = *(int *)ctx;
    struct canfd_frame k;
    const ssize_t n = recv(fd, &k, sizeof k, MSG_DONTWAIT);
    if (n != CAN_MTU && n != CANFD_MTU)
        return 0;
    memset(out, 0, sizeof *out);
    out->is_ext = (k.can_id & CAN_EFF_FLAG) != 0;
    out->id = k.can_id & (out->is_ext ? CAN_EFF_MASK : CAN_SFF_MASK);
    out->is_fd = n == CANFD_MTU;
    out->is_brs = out->is_fd && (k.flags & CANFD_BRS);
    out->len = k.len;
    memcpy(out->data, k.data, k.len);
    return 1;
}

static void far_settle(void *ctx)
{
    (void)ctx;
    usleep(5000);
}

static int64_t far_now(void *ctx)
{
    (void)ctx;
    return mono_ns();
}

static void run_contract(const char *ifname, bool is_fd)
{
    const ps_can_socket_filter_t all[] = {{0, 0, false}, {0, 0, true}};
    open_sock(&g_sock, ifname, is_fd, 2, all);
    int peer = peer_open(ifname);
    const ps_can_contract_t c = {.port = ps_can_socket_port(&g_sock),
                                 .ctx = &peer,
                                 .far_send = far_send,
                                 .far_recv = far_recv,
                                 .settle = far_settle,
                                 .now_ns = far_now,
                                 .is_fd = is_fd};
    ps_can_contract_check(&c);
    close(peer);
    ps_can_socket_close(&g_sock);
}

static void test_socketcan_keeps_the_transport_contract(void **state)
{
    (void)state;
    run_contract("vcan0", false);
}

static void test_socketcan_fd_keeps_the_transport_contract(void **state)
{
    (void)state;
    run_contract("vcan1", true);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_socketcan_keeps_the_transport_contract),
        cmocka_unit_test(test_socketcan_fd_keeps_the_transport_contract),
        cmocka_unit_test(test_filters_pass_only_the_expected_ids_with_monotonic_stamps),
        cmocka_unit_test(test_batches_go_out_in_order_without_blocking),
        cmocka_unit_test(test_fd_frames_both_ways_and_fd_refused_on_a_classical_interface),
        cmocka_unit_test(test_error_frames_reach_the_bus_state),
        cmocka_unit_test(test_a_full_queue_is_counted_never_waited_for),
        cmocka_unit_test(test_receive_overflow_is_counted),
        cmocka_unit_test(test_check_and_send_on_a_downed_interface),
        cmocka_unit_test(test_two_buses_in_one_tick_over_a_vxcan_pair),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
