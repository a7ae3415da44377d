/*
 * ps_can_sim: a simulated classical CAN bus that models the wire.
 *
 * One bus has two ends: the host end (what the loop gets, a ps_can_port_t
 * like a SocketCAN one) and the device end (where the emulated actuators and
 * IMU sit). Both share one wire: every frame occupies it for its worst-case
 * bit time (ps_canbus_frame_bits_max at the bus bitrate) starting when the
 * wire is free, and can be received at the other end only once the clock
 * reaches its end-of-frame time. Frames that end after the servo tick they
 * were sent in are counted late. Bits used give the observed bus load.
 *
 * Each direction is a lock-free SPSC ring, so the host end may be used by the
 * loop thread while the device end is used by the plant thread; the wire
 * occupancy is shared through an atomic compare-and-swap.
 *
 * Device end only: a tx frame with t_ns > 0 starts no earlier than t_ns
 * (a driver's turnaround time after the command it answers).
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
 *  @post *out owned by caller  @return 0 | -EINVAL | -ENOMEM  @rt INIT */
int ps_can_sim_create(ps_can_sim_bus_t **out, const char *name, uint32_t bitrate,
                      const ps_clock_t *clock, int64_t period_ns, uint32_t queue_len);

/** Tick grid origin for late-frame accounting and load (default: create time).
 *  @rt INIT */
void ps_can_sim_set_epoch(ps_can_sim_bus_t *b, int64_t epoch_ns);

/** @return the loop's end  @rt INIT */
ps_can_port_t ps_can_sim_host_port(ps_can_sim_bus_t *b);

/** @return the devices' end  @rt INIT */
ps_can_port_t ps_can_sim_device_port(ps_can_sim_bus_t *b);

/** Safe on NULL.  @rt INIT */
void ps_can_sim_destroy(ps_can_sim_bus_t *b);

#endif /* PS_CAN_SIM_H */
