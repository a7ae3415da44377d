/*
 * ps_can_socket: the CAN transport (drivers/ps_can.h) on Linux SocketCAN.
 *
 * One raw socket (PF_CAN, SOCK_RAW, CAN_RAW) per bus, bound to its interface
 * and filtered in the kernel (CAN_RAW_FILTER) to the identifiers the bus's
 * drives and IMU answer on, so nothing else wakes or fills the loop's queue.
 * Frames move in batches with recvmmsg/sendmmsg and MSG_DONTWAIT: a call never
 * blocks. A send that meets a full queue (ENOBUFS: the qdisc is at
 * txqueuelen; EAGAIN: the socket's send buffer) takes what it can, counts one
 * n_tx_saturated event and the rest as n_tx_dropped, and returns: no retry.
 * (Any short send counts so: a sendmmsg that stopped at frame k > 0 on
 * another error reports no errno, and a batch beyond PS_CAN_SOCKET_BATCH
 * frames is cut there; the next call reports a persisting error.)
 *
 * Error frames are enabled (CAN_RAW_ERR_FILTER, every class) and decoded
 * into the state (ps_can_socket_apply_error): error-warning, error-passive,
 * bus-off, restarted, back to error-active, controller overflows, protocol
 * violations and missing ACKs, and the TX/RX error counters when the driver
 * reports them (CAN_ERR_CNT). The loop turns bus-off into an e-stop condition.
 * Bus-off ends with a "restarted" report, any controller state report, or a
 * data frame received (a bus-off controller receives nothing); get_state
 * reports every bus-off episode at least once, even one that ended within a
 * single receive batch.
 *
 * CAN FD (CAN_RAW_FD_FRAMES) where the bus is configured FD; classical frames
 * on an FD socket still arrive as classical frames (by their size).
 *
 * Receive times: the kernel stamps each frame on arrival (SO_TIMESTAMPNS),
 * in CLOCK_REALTIME, the only clock it offers for socket stamps. Each
 * receive call samples both clocks once and moves the stamps onto
 * CLOCK_MONOTONIC by the difference; a stamp later than "now" (a REALTIME
 * step between arrival and the call) is clamped to now, so a clock step
 * can shift one batch's stamps, never order them after the call.
 *
 * Drops: SO_RXQ_OVFL reports the socket's receive-queue overflow count,
 * kept as n_rx_dropped. The kernel attaches the count to each frame it
 * queues, so drops show with the first frame that arrives after them.
 *
 * Start-up check (ps_can_socket_query, ps_can_socket_check_iface): through
 * rtnetlink (libmnl), the
 * interface exists, is a CAN device, is up, and for real controllers
 * (kind "can") runs the configured bitrate, FD mode and data bitrate, is not
 * bus-off or stopped, has restart-ms set, and has txqueuelen of at least what
 * the caller needs. Each problem is reported with the `ip link` command that
 * fixes it. Virtual interfaces (vcan, vxcan) have no bit timing: only their
 * presence, state, MTU and queue length are checked.
 *
 * Threads: a socket is used by one thread (the loop). Allocation: none; the
 * caller owns ps_can_socket_t (a few tens of kB: keep it static or on the
 * heap). Open and check are INIT; the port's ops are RT-SAFE.
 */
#ifndef PS_CAN_SOCKET_H
#define PS_CAN_SOCKET_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "../rt/ps_limits.h"
#include "ps_can.h"
#include "ps_canbus.h"

/** Kernel filters of one socket: every drive's replies and fault reports,
 *  the IMU's frames (up to 5), spares. */
#define PS_CAN_SOCKET_MAX_FILTERS (2u * PS_MAX_JOINTS + 8u)
/** Frames one recvmmsg/sendmmsg call moves at most. */
#define PS_CAN_SOCKET_BATCH 64u

/** Pass frames whose identifier matches id on the bits set in mask, of one
 *  identifier width. */
typedef struct {
    uint32_t id;
    uint32_t mask;
    bool is_ext; /**< 29-bit identifier */
} ps_can_socket_filter_t;

typedef struct {
    char ifname[PS_NAME_LEN];
    bool is_fd;         /**< accept and send CAN FD frames */
    uint32_t bitrate;   /**< for the load figure, bit/s (0: no load figure) */
    uint32_t n_filters; /**< 0: pass nothing but error frames */
    ps_can_socket_filter_t filters[PS_CAN_SOCKET_MAX_FILTERS];
} ps_can_socket_cfg_t;

/* Scratch for one batch call; internal. */
typedef struct {
    uint8_t frame[72]; /* struct canfd_frame; can_frame is a prefix */
    uint8_t control[64];
} ps_can_socket_slot_t;

typedef struct {
    int fd;       /**< -1 when closed */
    bool is_open; /**< fd is ours: close on a zeroed struct touches nothing */
    int ifindex;
    bool is_fd;
    uint32_t bitrate;
    char ifname[PS_NAME_LEN];
    int64_t open_ns;
    ps_can_state_t state;
    uint64_t n_bus_off_reported; /**< bus-off episodes get_state has shown */
    ps_can_socket_slot_t rx[PS_CAN_SOCKET_BATCH];
    ps_can_socket_slot_t tx[PS_CAN_SOCKET_BATCH];
} ps_can_socket_t;

/** Open, bind, filter and configure the socket of one bus.
 *  @post s->fd >= 0 on success; on failure s is closed and err names the
 *        interface, the call that failed and errno's text
 *  @return 0 | -errno (-ENODEV no such interface, -EPERM, ...) | -EINVAL cfg
 *  @rt INIT */
int ps_can_socket_open(ps_can_socket_t *s, const ps_can_socket_cfg_t *cfg, char *err,
                       size_t err_len);

/** @pre s opened  @return the transport port over s (name: the interface)  @rt INIT */
ps_can_port_t ps_can_socket_port(ps_can_socket_t *s);

/** Close the socket. Safe twice and on a zeroed struct.  @rt INIT */
void ps_can_socket_close(ps_can_socket_t *s);

/** Fold one error frame's report into the state (mode, counters).
 *  @param can_id  the frame's identifier with CAN_ERR_FLAG and class bits
 *  @param data    its 8 data bytes (CAN_ERR_DLC)
 *  @rt RT-SAFE, pure */
void ps_can_socket_apply_error(ps_can_state_t *st, uint32_t can_id, const uint8_t data[8]);

/** What rtnetlink says of an interface. */
typedef struct {
    bool exists;
    bool is_can;   /**< link type ARPHRD_CAN */
    bool is_up;    /**< IFF_UP */
    char kind[16]; /**< "can", "vcan", "vxcan", "" */
    uint32_t mtu;  /**< 16 classical, 72 FD */
    uint32_t txqueuelen;
    bool has_bittiming; /**< kind "can": the values below are set */
    uint32_t bitrate;
    bool is_fd_mode; /**< CAN_CTRLMODE_FD on */
    uint32_t data_bitrate;
    uint32_t restart_ms;
    int can_state; /**< enum can_state: 0 active .. 3 bus-off, 4 stopped; -1 unknown */
} ps_can_socket_iface_t;

/** Ask rtnetlink about an interface.
 *  @post *out written (exists false when there is no such interface)
 *  @return 0 | -errno the netlink request failed (err says why)  @rt INIT */
int ps_can_socket_query(const char *ifname, ps_can_socket_iface_t *out, char *err, size_t err_len);

/** Check an interface against its bus: see the header comment.
 *  @param min_txqueuelen frames the queue must hold (the caller's worst tick, with margin)
 *  @post err holds every problem found, each with its `ip link` fix; notes
 *        (what was not checked on a virtual interface) go to note
 *  @return 0 | -PS_ERR_CONFIG  @rt INIT, pure */
int ps_can_socket_check_iface(const ps_canbus_bus_cfg_t *bus, const ps_can_socket_iface_t *info,
                              uint32_t min_txqueuelen, char *err, size_t err_len, char *note,
                              size_t note_len);

#endif /* PS_CAN_SOCKET_H */
