/*
 * ps_can_fake: a scripted CAN port for tests of the loop.
 *
 * The test pushes frames that recv_batch hands out (FIFO, as pushed, t_ns
 * untouched), reads back what send_batch recorded, makes the next N calls of
 * an op fail with an error of its choice (-EIO, -ENOBUFS, ...), limits how
 * many frames a send accepts (a full tx queue) or a recv returns, and sets the
 * bus mode and error counters get_state reports.
 *
 * In PS_CAN_BUS_OFF mode send_batch fails with -ENETDOWN (what SocketCAN
 * returns while the controller is bus-off) and recv_batch returns 0 frames;
 * injected errors take precedence over that.
 *
 * Threads: not thread-safe (one test thread). Allocation: none; all storage
 * is in the struct (about 30 KiB: allocate it in a test's setup).
 */
#ifndef PS_CAN_FAKE_H
#define PS_CAN_FAKE_H

#include <stddef.h>
#include <stdint.h>

#include "../../drivers/ps_can.h"

#define PS_CAN_FAKE_MAX_RX   256u  /**< frames waiting to be received */
#define PS_CAN_FAKE_MAX_SENT 1024u /**< sent frames recorded (more are counted only) */

typedef struct {
    int err;          /**< negative code the failing calls return */
    uint32_t n_calls; /**< how many upcoming calls fail; decremented per failure */
} ps_can_fake_fault_t;

typedef struct {
    /* script (test may modify) */
    uint32_t tx_accept_max;   /**< 0: accept every frame; k: at most k per send call,
                                   the rest count n_tx_dropped */
    uint32_t rx_per_call_max; /**< 0: no limit; k: recv returns at most k per call */
    ps_can_fake_fault_t send_fault;
    ps_can_fake_fault_t recv_fault;
    ps_can_fake_fault_t state_fault;
    ps_can_state_t state; /**< mode/TEC/REC set by the test; counters kept by the fake */

    /* records (read-only) */
    ps_can_frame_t sent[PS_CAN_FAKE_MAX_SENT]; /**< accepted frames, in order */
    size_t n_sent;                             /**< entries in sent[] */
    uint64_t n_sent_total;                     /**< accepted frames, including those past sent[] */
    size_t n_send_calls, n_recv_calls, n_state_calls, n_close_calls;

    /* internal */
    ps_can_frame_t rx[PS_CAN_FAKE_MAX_RX];
    uint32_t rx_head, rx_tail; /* free-running push / take counters */
} ps_can_fake_t;

/** @post f zeroed, mode ERROR_ACTIVE, no script  @rt tests */
void ps_can_fake_init(ps_can_fake_t *f);

/** @return a port on f, named name (not copied)  @rt tests */
ps_can_port_t ps_can_fake_port(ps_can_fake_t *f, const char *name);

/** Queue a frame for recv_batch. @return 0 | -ENOSPC (PS_CAN_FAKE_MAX_RX waiting) */
int ps_can_fake_push_rx(ps_can_fake_t *f, const ps_can_frame_t *frame);

/** @return frames pushed and not yet received */
size_t ps_can_fake_rx_pending(const ps_can_fake_t *f);

/** The next n_calls calls of that op return err (< 0) and do nothing else. */
void ps_can_fake_fail_send(ps_can_fake_t *f, int err, uint32_t n_calls);
void ps_can_fake_fail_recv(ps_can_fake_t *f, int err, uint32_t n_calls);
void ps_can_fake_fail_state(ps_can_fake_t *f, int err, uint32_t n_calls);

/** Set the fault-confinement state get_state reports (PS_CAN_BUS_OFF also
 *  stops traffic, see above). */
void ps_can_fake_set_bus_mode(ps_can_fake_t *f, ps_can_bus_mode_t mode, uint16_t tec, uint16_t rec);

/** @post sent[] emptied, n_sent 0 (n_sent_total and counters kept) */
void ps_can_fake_clear_sent(ps_can_fake_t *f);

/** @return the last recorded sent frame with this id (and is_ext), or NULL */
const ps_can_frame_t *ps_can_fake_last_sent(const ps_can_fake_t *f, uint32_t id, uint8_t is_ext);

#endif /* PS_CAN_FAKE_H */
