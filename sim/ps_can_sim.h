/*
 * ps_can_sim: a simulated CAN bus (classical, or FD with bit rate switch)
 * that models the wire.
 *
 * One bus has two ends: the host end (what the loop gets, a ps_can_port_t
 * like a SocketCAN one) and the device end (where the emulated actuators and
 * IMU sit). Both share one wire: every frame occupies it for its worst-case
 * time (ps_canbus_frame_ns_max: classical frames at the bitrate, FD frames'
 * data phase at the data bitrate when BRS is set) starting when the
 * wire is free, and can be received at the other end only once the clock
 * reaches its end-of-frame time. Frames that end after the servo tick they
 * were sent in are counted late. Bits used give the observed bus load.
 *
 * Each direction is a lock-free SPSC ring, so the host end may be used by the
 * loop thread while the device end is used by the plant thread; the wire
 * occupancy is shared through an atomic compare-and-swap.
 *
 * Device end only: a tx frame with t_ns > 0 starts no earlier than t_ns
 * (a driver's turnaround time after the command it answers). The host end
 * ignores tx t_ns.
 *
 * Timing model, per frame sent: ready = now (device end: max(now, t_ns));
 * start = max(ready, end of the previous frame on the wire, either
 * direction); end = start + ps_canbus_bits_to_ns(frame_bits_max). The frame
 * is received with t_ns = end, by recv_batch calls made at clock >= end, FIFO
 * per direction. The wire is first come, first served in send-call order (no
 * arbitration into idle gaps before a future-start reservation).
 * Late: end > the end of the servo tick (epoch + k * period_ns) holding ready.
 *
 * Ops semantics (ps_can.h): send_batch returns frames queued (fewer than n
 * when the direction's queue is full; the rest count n_tx_dropped) or -EINVAL
 * (frames NULL, a length the frame kind cannot carry, an FD frame on a
 * classical bus, id beyond its 11/29-bit mask; then nothing is queued). recv_batch returns frames
 * taken (0 if none due) or -EINVAL (out NULL). get_state: mode always ERROR_ACTIVE, TEC/REC 0,
 * n_rx_dropped 0; n_tx_frames/n_rx_frames/n_tx_dropped/n_late count this end only; n_bits
 * (worst-case bits of every frame queued, both directions, counted at send)
 * in nominal bit times) and load = n_bits / ((now - epoch) * bitrate) (0 while now <= epoch) are
 * the bus's. load can exceed the true wire occupancy by frames queued for
 * later. close is a no-op; ps_can_sim_destroy frees the bus.
 *
 * Threads: host end one thread, device end one thread. Allocation: at create.
 */
#ifndef PS_CAN_SIM_H
#define PS_CAN_SIM_H

#include <stdint.h>

#include "../drivers/ps_can.h"
#include "../rt/ps_clock.h"

typedef struct ps_can_sim_bus ps_can_sim_bus_t;

/** @pre clock outlives the bus, bitrate > 0, period_ns > 0, queue_len power of two
 *       in [2, 2^30] (slots per direction); name copied (NULL: "sim", at most 31 chars)
 *  @post *out owned by caller; epoch = clock now  @return 0 | -EINVAL | -ENOMEM  @rt INIT */
int ps_can_sim_create(ps_can_sim_bus_t **out, const char *name, uint32_t bitrate,
                      const ps_clock_t *clock, int64_t period_ns, uint32_t queue_len);

/** Make the bus CAN FD: FD frames are accepted, their data phase (with BRS)
 *  runs at data_bitrate.  @pre no thread uses the bus yet
 *  @return 0 | -EINVAL (b NULL, data_bitrate below the bitrate)  @rt INIT */
int ps_can_sim_set_fd(ps_can_sim_bus_t *b, uint32_t data_bitrate);

/** Tick grid origin for late-frame accounting and load (default: create time).
 *  @pre no thread uses the bus yet  @units ns  @rt INIT */
void ps_can_sim_set_epoch(ps_can_sim_bus_t *b, int64_t epoch_ns);

/** @return the loop's end  @rt INIT */
ps_can_port_t ps_can_sim_host_port(ps_can_sim_bus_t *b);

/** @return the devices' end  @rt INIT */
ps_can_port_t ps_can_sim_device_port(ps_can_sim_bus_t *b);

/** Safe on NULL.  @rt INIT */
void ps_can_sim_destroy(ps_can_sim_bus_t *b);

#endif /* PS_CAN_SIM_H */
