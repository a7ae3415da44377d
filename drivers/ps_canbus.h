/*
 * ps_canbus: classical CAN wire timing and bus-load planning.
 *
 * Frame length (ISO 11898-1, classical data frame, including the 3-bit
 * intermission): an 11-bit-id frame with n data bytes has 47 + 8n bits
 * without stuffing; of those, 34 + 8n (SOF..CRC) are subject to bit stuffing,
 * which adds at most floor((34 + 8n - 1) / 4) bits. With 8 bytes: 111..135
 * bits. A 29-bit-id frame has 67 + 8n bits, 54 + 8n stuffable.
 *
 * The planner turns a robot's actuator map (command + reply per joint at its
 * rate, IMU frames at its rate) into a per-tick schedule: each source gets a
 * phase so that the worst tick's bits are as few as possible, and the worst
 * tick's load must stay under the board's budget.
 *
 * Threads: any (pure). Allocation: none.
 */
#ifndef PS_CANBUS_H
#define PS_CANBUS_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "../rt/ps_config.h"

/** Longest hyperperiod (lcm of the rate divisors on one bus) the planner
 *  accepts; every rate_div must divide into it, e.g. 1, 2, 4, 8, 16, 32, 64. */
#define PS_CANBUS_MAX_HYPERPERIOD 64u

/** len above 8 counts as 8 (classical CAN). @return bits of a frame with no stuff bits
 *  @rt RT-SAFE */
unsigned ps_canbus_frame_bits_min(uint8_t len, bool is_ext);

/** @return bits of a frame with the most stuff bits possible  @rt RT-SAFE */
unsigned ps_canbus_frame_bits_max(uint8_t len, bool is_ext);

/** @pre bitrate > 0 (0 returns 0)  @return time the bits take on the wire, rounded up
 *  @units ns  @rt RT-SAFE */
int64_t ps_canbus_bits_to_ns(unsigned bits, uint32_t bitrate);

typedef struct {
    uint32_t n_buses;
    uint32_t tick_bits_max[PS_MAX_BUSES];      /**< worst-case bits in the busiest tick */
    uint32_t tick_capacity_bits[PS_MAX_BUSES]; /**< bitrate / servo_hz */
    double load_peak[PS_MAX_BUSES];            /**< tick_bits_max / tick_capacity_bits */
    double load_avg[PS_MAX_BUSES];             /**< worst-case bits per second / bitrate */
    uint32_t n_sources[PS_MAX_BUSES];
    uint8_t joint_phase[PS_MAX_JOINTS]; /**< command joint j on ticks where
                                             (tick + phase) % rate_div == 0 */
    uint8_t imu_phase;
} ps_canbus_plan_t;

/** Plan every bus of a board for a robot and check it against the budget.
 *  Sources per bus: each joint on it (command + reply, 2 x 135 worst-case bits,
 *  every rate_div ticks) and the IMU if on it (gyro + accel, 2 x 135 bits,
 *  every imu.rate_div ticks). Phases are chosen greedily, most bits first,
 *  each minimising the busiest tick of the hyperperiod (lcm of the bus's
 *  divisors). tick_capacity_bits = bitrate / servo_hz (integer division).
 *  @post *out written (also on -PS_ERR_BUS_BUDGET, so callers can report it;
 *        untouched on -PS_ERR_CONFIG); err "" on success
 *  @return 0 | -PS_ERR_BUS_BUDGET (err names the first bus over budget, its load
 *          and the budget) | -PS_ERR_CONFIG (a joint or the IMU names a bus the
 *          board lacks, rate_div 0 or > 64, hyperperiod > 64, servo_hz 0,
 *          n_buses 0 or > PS_MAX_BUSES, n_joints > PS_MAX_JOINTS, bus_budget
 *          outside (0, 1], bitrate < servo_hz; err names the field)
 *  @rt INIT (pure, O(sources * 64 * 64)) */
int ps_canbus_plan(const ps_board_cfg_t *b, const ps_robot_cfg_t *r, ps_canbus_plan_t *out,
                   char *err, size_t err_len);

/** @return true if a source with this divisor and phase sends on this tick  @rt RT-SAFE */
static inline bool ps_canbus_is_due(uint64_t tick, uint32_t rate_div, uint32_t phase)
{
    return ((tick + phase) % rate_div) == 0;
}

#endif /* PS_CANBUS_H */
