/*
 * ps_can: the CAN transport interface.
 *
 * The loop talks to every CAN bus through a ps_can_port_t: an ops table plus
 * an implementation context. Implementations: drivers/ps_can_socket.c (Linux
 * SocketCAN), sim/ps_can_sim.c (simulated wire with bit timing),
 * tests/fakes/ps_can_fake.c (scripted). The loop never knows which it has.
 *
 * Only data frames reach the loop: an implementation drops remote (RTR) and
 * error frames (SocketCAN's CAN_RTR_FLAG / CAN_ERR_FLAG) and reports bus
 * errors through get_state, and never hands over an 11-bit frame with an
 * id above 0x7ff (the loop counts such a frame as bad, it does not mask it).
 *
 * Threads: a port is used by one thread (the loop) unless an implementation
 * says otherwise. Allocation: none here; implementations allocate in their own
 * INIT-phase open function.
 */
#ifndef PS_CAN_H
#define PS_CAN_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#define PS_CAN_MAX_DLEN    8u     /**< classical CAN payload bytes */
#define PS_CAN_FD_MAX_DLEN 64u    /**< CAN FD payload bytes */
#define PS_CAN_SFF_MASK    0x7ffu /**< 11-bit identifier mask */
#define PS_CAN_EFF_MASK    0x1fffffffu

/** One CAN data frame, classical or FD. */
typedef struct {
    uint32_t id;    /**< 11- or 29-bit identifier */
    uint8_t len;    /**< payload bytes: 0..8 classical; FD also 12, 16, 20, 24, 32, 48, 64 */
    uint8_t is_ext; /**< 1: 29-bit identifier */
    uint8_t is_fd;  /**< 1: CAN FD frame (FDF bit) */
    uint8_t is_brs; /**< 1: FD bit rate switch, data phase at the bus's data bitrate */
    uint8_t data[PS_CAN_FD_MAX_DLEN];
    int64_t t_ns; /**< rx: time the frame was complete on the wire (CLOCK_MONOTONIC
                       or simulated time); tx: ignored */
} ps_can_frame_t;

/** @return true if len is a payload length the frame kind can carry: 0..8, and
 *  for FD also 12, 16, 20, 24, 32, 48 and 64 (the DLC codes 9..15)  @rt RT-SAFE */
static inline bool ps_can_is_valid_len(uint8_t len, bool is_fd)
{
    if (len <= PS_CAN_MAX_DLEN)
        return true;
    if (!is_fd)
        return false;
    return len == 12u || len == 16u || len == 20u || len == 24u || len == 32u || len == 48u ||
           len == 64u;
}

/** @return true if the identifier fits its width, the length its kind, and BRS
 *  is set only on FD frames  @rt RT-SAFE */
static inline bool ps_can_is_valid_frame(const ps_can_frame_t *f)
{
    return f->id <= (f->is_ext ? PS_CAN_EFF_MASK : PS_CAN_SFF_MASK) &&
           ps_can_is_valid_len(f->len, f->is_fd != 0) && (f->is_fd || !f->is_brs);
}

/** ISO 11898 fault confinement state of the controller. */
typedef enum {
    PS_CAN_BUS_ERROR_ACTIVE = 0,
    PS_CAN_BUS_ERROR_WARNING,
    PS_CAN_BUS_ERROR_PASSIVE,
    PS_CAN_BUS_OFF,
} ps_can_bus_mode_t;

/** Bus state and counters, as a snapshot. */
typedef struct {
    ps_can_bus_mode_t mode;
    uint16_t tx_error_count; /**< TEC */
    uint16_t rx_error_count; /**< REC */
    uint64_t n_tx_frames;    /**< frames this port put on the wire */
    uint64_t n_rx_frames;    /**< frames this port took off the wire */
    uint64_t n_tx_dropped;   /**< frames refused because the tx queue was full */
    uint64_t n_rx_dropped;   /**< frames lost because the rx queue was full */
    uint64_t n_late;         /**< frames that completed after the tick they were sent in */
    uint64_t n_bits;         /**< bit times used on the wire by both directions */
    double load;             /**< observed bus load, 0..1, since open */
    /* Error reports of the controller (SocketCAN error frames); 0 where an
     * implementation has none. */
    uint64_t n_err_frames;    /**< error reports taken */
    uint64_t n_bus_off;       /**< times the controller went bus-off */
    uint64_t n_restarts;      /**< times it came back from bus-off */
    uint64_t n_prot_errors;   /**< protocol violations and bus errors seen */
    uint64_t n_no_ack;        /**< transmissions nobody acknowledged */
    uint64_t n_ctrl_overflow; /**< controller rx/tx buffer overflows */
    uint64_t n_tx_saturated;  /**< send calls that met a full queue (ENOBUFS/EAGAIN) */
} ps_can_state_t;

typedef struct {
    /** Queue up to n frames for transmission. @return number queued (0..n) | -errno
     *  @rt RT-SAFE, never blocks */
    int (*send_batch)(void *ctx, const ps_can_frame_t *frames, size_t n);
    /** Take up to max received frames without blocking. @return count (0..max) | -errno
     *  @rt RT-SAFE, never blocks */
    int (*recv_batch)(void *ctx, ps_can_frame_t *out, size_t max);
    /** @return 0 | -errno  @rt RT-SAFE */
    int (*get_state)(void *ctx, ps_can_state_t *out);
    /** Release the bus. Safe to call twice. @rt INIT */
    void (*close)(void *ctx);
} ps_can_ops_t;

typedef struct {
    const ps_can_ops_t *ops;
    void *ctx;
    const char *name; /**< interface name for messages, e.g. "can0" */
} ps_can_port_t;

/** Forwarders: @pre port opened  @return as the ops above  @rt RT-SAFE, loop thread */
static inline int ps_can_send_batch(const ps_can_port_t *p, const ps_can_frame_t *f, size_t n)
{
    return p->ops->send_batch(p->ctx, f, n);
}
static inline int ps_can_recv_batch(const ps_can_port_t *p, ps_can_frame_t *out, size_t max)
{
    return p->ops->recv_batch(p->ctx, out, max);
}
static inline int ps_can_get_state(const ps_can_port_t *p, ps_can_state_t *out)
{
    return p->ops->get_state(p->ctx, out);
}
static inline void ps_can_close(ps_can_port_t *p)
{
    if (p->ops != NULL && p->ops->close != NULL)
        p->ops->close(p->ctx);
}

#endif /* PS_CAN_H */
