/*
 * ps_can_contract: the transport contract of drivers/ps_can.h as one cmocka
 * check, run against every implementation: the simulated wire
 * (tests/test_can_sim.c) and SocketCAN (tests/hw/test_hw_can.c, in the VM).
 * The implementation under test is a port plus a far end that the check
 * drives: a frame put on the wire from the other side, a frame taken off it,
 * and a way to let the wire deliver (time for the sim, a short sleep for a
 * kernel interface).
 *
 * What every port must do: an empty receive returns 0 at once; a batch goes
 * out whole and in order with identifiers, widths, lengths and data intact;
 * frames from the far end come back in order, split over calls when max is
 * small, stamped in the clock's time, not after "now", never decreasing; CAN
 * FD frames (where the port is FD) keep their length and bit-rate switch; a
 * frame no bus can carry is refused with -EINVAL and nothing is sent; the
 * state counts what went each way and the bus is error-active.
 *
 * Threads: the test thread. Allocation: none.
 */
#ifndef PS_CAN_CONTRACT_H
#define PS_CAN_CONTRACT_H

#include <stdbool.h>
#include <stdint.h>

#include "../../drivers/ps_can.h"

typedef struct {
    ps_can_port_t port; /**< under test, opened, passing every identifier */
    void *ctx;
    /** Put f on the wire toward the port.  @return 0 | -errno */
    int (*far_send)(void *ctx, const ps_can_frame_t *f);
    /** Take the next frame the port sent.  @return 1 | 0 none yet */
    int (*far_recv)(void *ctx, ps_can_frame_t *out);
    /** Let the wire deliver what is in flight. */
    void (*settle)(void *ctx);
    /** Now, on the clock receive stamps are on. */
    int64_t (*now_ns)(void *ctx);
    bool is_fd;
} ps_can_contract_t;

/** Run every check; fails the calling cmocka test on the first violation. */
void ps_can_contract_check(const ps_can_contract_t *c);

#endif /* PS_CAN_CONTRACT_H */
