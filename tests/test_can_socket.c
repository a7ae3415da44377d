/*
 * Tests of drivers/ps_can_socket that need no CAN interface: the decoding of
 * error frames into the bus state (layouts of linux/can/error.h), the
 * start-up check's verdicts and the `ip link` commands it names, rtnetlink
 * on interfaces every Linux has, and each protocol's receive filter against
 * its own replies. The socket itself is tested in the VM
 * (tests/hw/test_hw_can.c).
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/netlink.h>
#include <string.h>

#include "../drivers/ps_actuator.h"
#include "../drivers/ps_can_socket.h"
#include "../rt/ps_err.h"

static void apply(ps_can_state_t *st, uint32_t classes, uint8_t d1, uint8_t tec, uint8_t rec)
{
    uint8_t data[8] = {0, d1, 0, 0, 0, 0, tec, rec};
    ps_can_socket_apply_error(st, CAN_ERR_FLAG | classes, data);
}

static void test_error_frames_walk_the_fault_confinement_states(void **state)
{
    (void)state;
    ps_can_state_t st;
    memset(&st, 0, sizeof st);
    apply(&st, CAN_ERR_CRTL | CAN_ERR_CNT, CAN_ERR_CRTL_TX_WARNING, 96, 3);
    assert_int_equal(st.mode, PS_CAN_BUS_ERROR_WARNING);
    assert_int_equal(st.tx_error_count, 96);
    assert_int_equal(st.rx_error_count, 3);
    apply(&st, CAN_ERR_CRTL | CAN_ERR_CNT, CAN_ERR_CRTL_RX_PASSIVE, 100, 128);
    assert_int_equal(st.mode, PS_CAN_BUS_ERROR_PASSIVE);
    assert_int_equal(st.rx_error_count, 128);
    apply(&st, CAN_ERR_BUSOFF, 0, 0, 0);
    assert_int_equal(st.mode, PS_CAN_BUS_OFF);
    assert_int_equal(st.n_bus_off, 1);
    apply(&st, CAN_ERR_BUSOFF, 0, 0, 0); /* repeated report, one episode */
    assert_int_equal(st.n_bus_off, 1);
    apply(&st, CAN_ERR_PROT, 0, 0, 0); /* a protocol error says nothing of the state */
    assert_int_equal(st.mode, PS_CAN_BUS_OFF);
    apply(&st, CAN_ERR_RESTARTED, 0, 0, 0);
    assert_int_equal(st.mode, PS_CAN_BUS_ERROR_ACTIVE);
    assert_int_equal(st.n_restarts, 1);
    /* A controller that recovers by itself reports "back to active": also
     * the end of bus-off (else a lost RESTARTED would keep it off for good). */
    apply(&st, CAN_ERR_BUSOFF, 0, 0, 0);
    apply(&st, CAN_ERR_CRTL, CAN_ERR_CRTL_ACTIVE, 0, 0);
    assert_int_equal(st.mode, PS_CAN_BUS_ERROR_ACTIVE);
    assert_int_equal(st.n_bus_off, 2);
    assert_int_equal(st.n_restarts, 2);
    apply(&st, CAN_ERR_CRTL, CAN_ERR_CRTL_TX_PASSIVE, 0, 0);
    apply(&st, CAN_ERR_CRTL, CAN_ERR_CRTL_ACTIVE, 0, 0);
    assert_int_equal(st.mode, PS_CAN_BUS_ERROR_ACTIVE);
    assert_int_equal(st.n_err_frames, 10);
    /* Without CAN_ERR_CNT the counters in data[6..7] are not the driver's. */
    apply(&st, CAN_ERR_CRTL, CAN_ERR_CRTL_RX_WARNING, 77, 77);
    assert_int_equal(st.tx_error_count, 100);
}

static void test_error_frames_count_protocol_ack_and_overflow_reports(void **state)
{
    (void)state;
    ps_can_state_t st;
    memset(&st, 0, sizeof st);
    apply(&st, CAN_ERR_PROT | CAN_ERR_BUSERROR, 0, 0, 0);
    apply(&st, CAN_ERR_ACK, 0, 0, 0);
    apply(&st, CAN_ERR_ACK, 0, 0, 0);
    apply(&st, CAN_ERR_CRTL, CAN_ERR_CRTL_RX_OVERFLOW, 0, 0);
    assert_int_equal(st.n_prot_errors, 1);
    assert_int_equal(st.n_no_ack, 2);
    assert_int_equal(st.n_ctrl_overflow, 1);
    assert_int_equal(st.mode, PS_CAN_BUS_ERROR_ACTIVE);
}

static const ps_canbus_bus_cfg_t CAN0 = {.ifname = "can0", .bitrate = 1000000};
static const ps_canbus_bus_cfg_t CAN1_FD = {
    .ifname = "can1", .bitrate = 1000000, .is_fd = true, .data_bitrate = 5000000};

static ps_can_socket_iface_t good_real(const ps_canbus_bus_cfg_t *bus)
{
    ps_can_socket_iface_t i = {.exists = true,
                               .is_can = true,
                               .is_up = true,
                               .kind = "can",
                               .mtu = bus->is_fd ? CANFD_MTU : CAN_MTU,
                               .txqueuelen = 128,
                               .has_bittiming = true,
                               .bitrate = bus->bitrate,
                               .is_fd_mode = bus->is_fd,
                               .data_bitrate = bus->is_fd ? bus->data_bitrate : 0,
                               .restart_ms = 100,
                               .can_state = CAN_STATE_ERROR_ACTIVE};
    return i;
}

static int check(const ps_canbus_bus_cfg_t *bus, const ps_can_socket_iface_t *i, char *err,
                 char *note)
{
    return ps_can_socket_check_iface(bus, i, 64, err, 512, note, 256);
}

static void test_check_accepts_a_well_set_up_interface(void **state)
{
    (void)state;
    char err[512], note[256];
    ps_can_socket_iface_t i = good_real(&CAN0);
    assert_int_equal(check(&CAN0, &i, err, note), 0);
    assert_string_equal(err, "");
    assert_string_equal(note, "");
    i = good_real(&CAN1_FD);
    assert_int_equal(check(&CAN1_FD, &i, err, note), 0);
}

static void test_check_names_the_ip_link_command_for_a_wrong_bitrate(void **state)
{
    (void)state;
    char err[512], note[256];
    ps_can_socket_iface_t i = good_real(&CAN0);
    i.bitrate = 500000;
    assert_int_equal(check(&CAN0, &i, err, note), -PS_ERR_CONFIG);
    assert_non_null(strstr(err, "can0 runs 500000 bit/s, the board wants 1000000 classical: "
                                "sudo ip link set can0 down; sudo ip link set can0 type can "
                                "bitrate 1000000 restart-ms 100; sudo ip link set can0 up"));
    i = good_real(&CAN1_FD);
    i.data_bitrate = 2000000;
    assert_int_equal(check(&CAN1_FD, &i, err, note), -PS_ERR_CONFIG);
    assert_non_null(strstr(err, "data 2000000 bit/s"));
    assert_non_null(strstr(err, "type can bitrate 1000000 dbitrate 5000000 fd on restart-ms 100"));
    i.is_fd_mode = false; /* an FD bus on a classical controller setting */
    i.data_bitrate = 0;
    assert_int_equal(check(&CAN1_FD, &i, err, note), -PS_ERR_CONFIG);
    assert_non_null(strstr(err, "fd on"));
}

static void test_check_names_down_queue_length_mtu_and_bus_off(void **state)
{
    (void)state;
    char err[512], note[256];
    ps_can_socket_iface_t i = good_real(&CAN1_FD);
    i.is_up = false;
    i.txqueuelen = 10;
    i.mtu = CAN_MTU;
    assert_int_equal(check(&CAN1_FD, &i, err, note), -PS_ERR_CONFIG);
    assert_non_null(strstr(err, "can1 is down: sudo ip link set can1 down;"));
    assert_non_null(strstr(err, "can1 has txqueuelen 10, the loop needs at least 64: "
                                "`sudo ip link set can1 txqueuelen 64`"));
    assert_non_null(strstr(err, "can1 has mtu 16, CAN FD needs 72"));
    assert_true(strncmp(err, "; ", 2) != 0); /* no leading separator */
    i = good_real(&CAN0);
    i.can_state = CAN_STATE_BUS_OFF;
    i.restart_ms = 0;
    assert_int_equal(check(&CAN0, &i, err, note), -PS_ERR_CONFIG);
    assert_non_null(strstr(err, "can0 is bus-off"));
    assert_non_null(strstr(err, "type can restart`"));
    assert_non_null(strstr(err, "restart-ms 0"));
}

static void test_check_on_virtual_and_missing_interfaces(void **state)
{
    (void)state;
    char err[512], note[256];
    ps_can_socket_iface_t i = {.exists = true,
                               .is_can = true,
                               .is_up = true,
                               .kind = "vcan",
                               .mtu = CANFD_MTU,
                               .txqueuelen = 1000,
                               .can_state = -1};
    assert_int_equal(check(&CAN0, &i, err, note), 0);
    assert_non_null(strstr(note, "can0: virtual (vcan), bitrate not checked"));
    i.is_up = false;
    assert_int_equal(check(&CAN0, &i, err, note), -PS_ERR_CONFIG);
    assert_string_equal(err, "can0 is down: `sudo ip link set can0 up`");
    i.exists = false;
    assert_int_equal(check(&CAN0, &i, err, note), -PS_ERR_CONFIG);
    assert_non_null(strstr(err, "no interface can0"));
    i = (ps_can_socket_iface_t){.exists = true, .is_can = false};
    assert_int_equal(check(&CAN0, &i, err, note), -PS_ERR_CONFIG);
    assert_non_null(strstr(err, "can0 is not a CAN interface"));
}

/* rtnetlink works in any network namespace: the loopback is always there. */
static void test_query_reports_loopback_as_not_can_and_a_missing_name(void **state)
{
    (void)state;
    char err[256];
    ps_can_socket_iface_t i;
    assert_int_equal(ps_can_socket_query("lo", &i, err, sizeof err), 0);
    assert_true(i.exists);
    assert_false(i.is_can);
    assert_true(i.is_up);
    assert_int_equal(ps_can_socket_query("nosuchcan9", &i, err, sizeof err), 0);
    assert_false(i.exists);
    assert_int_equal(ps_can_socket_query("a-name-longer-than-ifnamsiz", &i, err, sizeof err),
                     -EINVAL);
}

static void test_open_refuses_a_missing_interface_by_name(void **state)
{
    (void)state;
    char err[256];
    static ps_can_socket_t s;
    ps_can_socket_cfg_t cfg = {.ifname = "nosuchcan9"};
    assert_int_equal(ps_can_socket_open(&s, &cfg, err, sizeof err), -ENODEV);
    assert_non_null(strstr(err, "CAN nosuchcan9: no such interface"));
    assert_int_equal(s.fd, -1);
    ps_can_socket_close(&s); /* safe on a failed open */
    cfg.n_filters = PS_CAN_SOCKET_MAX_FILTERS + 1;
    assert_int_equal(ps_can_socket_open(&s, &cfg, err, sizeof err), -EINVAL);
}

static bool passes(uint32_t id, uint32_t mask, const ps_can_frame_t *f)
{
    return (f->id & mask) == (id & mask);
}

static ps_act_cfg_t drive(ps_act_proto_id_t proto, uint32_t can_id, uint32_t reply_id)
{
    ps_act_cfg_t a;
    memset(&a, 0, sizeof a);
    a.protocol = proto;
    a.can_id = can_id;
    a.reply_id = reply_id;
    a.wire = (ps_act_range_t){.p_min_rad = -12.5f,
                              .p_max_rad = 12.5f,
                              .v_min_rad_s = -30.0f,
                              .v_max_rad_s = 30.0f,
                              .kp_max_nm_rad = 500.0f,
                              .kd_max_nm_s_rad = 5.0f,
                              .t_min_nm = -18.0f,
                              .t_max_nm = 18.0f,
                              .i_min_a = -30.0f,
                              .i_max_a = 30.0f};
    a.gear_ratio = 1.0f;
    a.direction = 1.0f;
    a.kt_nm_a = 1.0f;
    a.temp_max_c = 80.0f;
    a.rate_div = 1;
    return a;
}

/* Every reply a drive sends, whatever its fault and mode bits, passes its own
 * filter; a neighbour's replies do not. */
static void test_each_protocol_filter_passes_its_replies_only(void **state)
{
    (void)state;
    for (int p = 0; p < PS_ACT_PROTO_COUNT; p++) {
        const ps_act_proto_t *proto = ps_act_proto_get((ps_act_proto_id_t)p);
        assert_non_null(proto->reply_filter);
        const ps_act_cfg_t a =
            drive((ps_act_proto_id_t)p, 0x05, p == PS_ACT_PROTO_MIT ? 0x15 : 0xfd);
        const ps_act_cfg_t b =
            drive((ps_act_proto_id_t)p, 0x06, p == PS_ACT_PROTO_MIT ? 0x16 : 0xfd);
        uint32_t id, mask;
        proto->reply_filter(&a, &id, &mask);
        const float temps[] = {25.0f, 95.0f};
        const uint32_t faults[] = {0u, 0xffffffffu};
        for (int k = 0; k < 2; k++) {
            ps_act_meas_t m = {.q_rad = 1.0f, .temp_c = temps[k], .fault_bits = faults[k]};
            ps_can_frame_t f[PS_ACT_MAX_FRAMES], g[PS_ACT_MAX_FRAMES];
            const int n = proto->encode_reply(&a, &m, f, PS_ACT_MAX_FRAMES);
            const int nb = proto->encode_reply(&b, &m, g, PS_ACT_MAX_FRAMES);
            assert_true(n >= 1 && nb >= 1);
            for (int i = 0; i < n; i++) {
                assert_true(proto->match_reply(&a, &f[i]));
                assert_true(passes(id, mask, &f[i]));
                assert_int_equal(f[i].is_ext, proto->id_bits > 11u);
            }
            for (int i = 0; i < nb; i++)
                assert_false(passes(id, mask, &g[i]));
        }
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_error_frames_walk_the_fault_confinement_states),
        cmocka_unit_test(test_error_frames_count_protocol_ack_and_overflow_reports),
        cmocka_unit_test(test_check_accepts_a_well_set_up_interface),
        cmocka_unit_test(test_check_names_the_ip_link_command_for_a_wrong_bitrate),
        cmocka_unit_test(test_check_names_down_queue_length_mtu_and_bus_off),
        cmocka_unit_test(test_check_on_virtual_and_missing_interfaces),
        cmocka_unit_test(test_query_reports_loopback_as_not_can_and_a_missing_name),
        cmocka_unit_test(test_open_refuses_a_missing_interface_by_name),
        cmocka_unit_test(test_each_protocol_filter_passes_its_replies_only),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
