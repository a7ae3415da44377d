/*
 * ps_robstride: the RobStride / Xiaomi CyberGear private CAN protocol, as an
 * actuator protocol table (drivers/ps_actuator.h). RobStride 01..04 and the
 * CyberGear micromotor share the frame layout; only the wire ranges differ
 * (the driver entry in the robot file).
 *
 * Every frame is a classical 8-byte frame with a 29-bit identifier:
 *   bits 28..24 communication type, bits 23..8 "data area 2",
 *   bits 7..0 the target (for replies: the host) id.
 * Fields in the data are 16-bit, big-endian (high byte first), each mapped
 * linearly from its wire range onto 0..65535 (ps_mit_float_to_uint's rule).
 *
 *   type 1 motion control (host -> drive): area 2 = torque (t range);
 *          data: angle (p range), velocity (v range), kp [0, kp_max],
 *          kd [0, kd_max]; target = drive id (can_id)
 *   type 2 feedback (drive -> host): area 2 = bits 15..8 drive id, bits
 *          21..16 faults (21 not calibrated, 20 HALL encoder, 19 magnetic
 *          encoder, 18 over-temperature, 17 overcurrent, 16 undervoltage),
 *          bits 23..22 mode (0 reset, 1 calibration, 2 run); target = host
 *          id; data: angle, velocity, torque (t range), temperature x 10 degC
 *   type 3 enable, type 4 stop (data[0] = 1: stop and clear faults), type 6
 *          set mechanical zero (data[0] = 1): area 2 bits 15..8 = host id,
 *          target = drive id; the drive answers each with a type 2 frame
 *
 * In ps_act_cfg_t, can_id is the drive's id (1..255) and reply_id the host's
 * id (0..255, the same for every drive of a host): replies are told apart by
 * the drive id inside them, so only can_id must be unique on a bus.
 *
 *   type 21 fault report (drive -> host, when a fault latches): area 2 bits
 *          15..8 = host id, target = drive id (as the manual's table 4.1.10
 *          has it); bytes 0..3 fault value, 4..7 warning value, little-
 *          endian: bit 0 motor over-temperature, 1 driver chip, 2 under-
 *          voltage, 3 over-voltage, 4/5/16 phase B/C/A over-current, 7
 *          encoder not calibrated, 8..15 overload; warning bit 0: motor
 *          over-temperature warning (not a fault)
 *
 * Not handled yet: parameter reads and writes (types 17, 18), the other run
 * modes.
 *
 * Threads: any (pure functions). Allocation: none.
 */
#ifndef PS_ROBSTRIDE_H
#define PS_ROBSTRIDE_H

#include <stdint.h>

#include "ps_actuator.h"

#define PS_ROBSTRIDE_TYPE_MOTION   1u
#define PS_ROBSTRIDE_TYPE_FEEDBACK 2u
#define PS_ROBSTRIDE_TYPE_ENABLE   3u
#define PS_ROBSTRIDE_TYPE_STOP     4u
#define PS_ROBSTRIDE_TYPE_ZERO     6u
#define PS_ROBSTRIDE_TYPE_FAULT    21u

/** The 29-bit identifier of a frame: type, data area 2, target.  @rt RT-SAFE */
static inline uint32_t ps_robstride_id(uint32_t type, uint32_t area2, uint32_t target)
{
    return ((type & 0x1fu) << 24) | ((area2 & 0xffffu) << 8) | (target & 0xffu);
}

/** The protocol table: see ps_actuator.h for the ops' contracts. */
extern const ps_act_proto_t ps_robstride_proto;

/** @return ps_act_fault_t bits for a type-21 report's fault value (bytes 0..3);
 *  a bit the manual does not name counts as PS_ACT_FAULT_OTHER  @rt RT-SAFE */
uint32_t ps_robstride_report_fault_bits(uint32_t fault_value);

/** @return ps_act_fault_t bits for the feedback frame's fault field
 *  (identifier bits 21..16)  @rt RT-SAFE */
uint32_t ps_robstride_fault_bits(uint32_t id);

#endif /* PS_ROBSTRIDE_H */
