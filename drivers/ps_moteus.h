/*
 * ps_moteus: the mjbots moteus register ("multiplex") protocol over CAN FD, as
 * an actuator protocol table (drivers/ps_actuator.h).
 *
 * Source: mjbots/moteus docs/protocol/can.md (frame, ids, subframes) and
 * docs/protocol/registers.md (registers, mode values, fault codes, integer
 * scalings), https://github.com/mjbots/moteus/tree/main/docs/protocol; the
 * reply rules are mjlib's multiplex/format.h and micro_server.cc.
 *
 * Identifier: 16 bits, source in 15..8, destination in 7..0; bit 15 (the
 * source's high bit) asks the drive to reply. The host sends from
 * 0x80 | reply_id to can_id, so every command id is >= 0x8000 and must be a
 * 29-bit (extended) frame; the drive replies from can_id to reply_id. The
 * firmware sends a reply with a 29-bit id only when the id is >= 0x800
 * (fw/fdcan.cc), i.e. for drive ids >= 8: this table takes drive ids 8..126
 * (can_id_min, id_max; 127 is the broadcast id) so that both directions are
 * 29-bit and one kernel filter per drive sees its replies. Bits 28..16 (the
 * drive's id.can_prefix) must be 0.
 *
 * Payload: a sequence of subframes, values little-endian:
 *   0x00|0x04|0x08|0x0c write int8|int16|int32|float, count in the 2 LSBs
 *                       (0: a varuint count follows), varuint start
 *                       register, the values
 *   0x10..0x1c          read, the same without values
 *   0x20..0x2c          reply, as write
 *   0x30 / 0x31         write / read error: varuint register, varuint code
 *   0x50                nop (padding up to the FD length)
 *
 * Command (host -> drive, 32 bytes, FD with bit rate switch), every cycle:
 *   01 00 0A              write int8 x1 at 0x000: mode 10 (position)
 *   0C 05 20 + 5 floats   write float x5 at 0x020: position (rev), velocity
 *                         (rev/s), feed-forward torque (Nm), kp scale, kd scale
 *   1C 04 00              read float x4 at 0x000: mode, position, velocity, torque
 *   10 06 0A              read int8 x6 at 0x00a: motor temperature, trajectory
 *                         complete, home state, voltage, board temperature, fault
 * Reply (drive -> host, 32 bytes):
 *   2C 04 00 + 4 floats, 20 06 0A + 6 int8 (1 degC per LSB for the
 *   temperatures, 0.5 V for the voltage, -128: not available), 50 50 50 50
 *
 * Floats carry the set-points: no packing range, ~24 bits of the value
 * (resolution_bits 23 allows for the rad <-> rev conversion's rounding);
 * int32 would give 1e-5 rev = 63 urad for position, coarser than a float near
 * the joint range. Units: moteus speaks revolutions and rev/s at its output
 * shaft (after servo.rotor_to_output_ratio), the motor side here is rad,
 * rad/s and Nm: x 2 pi. The drive's PD is
 *   tau = kp_cfg kp_scale (q_cmd - q) + kd_cfg kd_scale (qd_cmd - qd) + tau_ff
 * with kp_cfg = servo.pid_position.kp (Nm/rev) and kd_cfg =
 * servo.pid_position.kd (Nm s/rev) of the drive's configuration. A command's
 * kp is sent as kp_scale = kp / wire.kp_max_nm_rad, so the driver entry's
 * kp_max_nm_rad must be servo.pid_position.kp / (2 pi) and kd_max_nm_s_rad
 * servo.pid_position.kd / (2 pi); servo.pid_position.ki must be 0 (this table
 * does not scale the integrator). The wire p, v and t ranges are what the
 * drive is configured to allow (servopos.position_min/max, servo.max_velocity,
 * the torque of servo.max_current_A); the reply reports torque, not current.
 *
 * Requests (32 bytes each, with the same query, so each gets a full reply):
 *   enable       mode 10 with position NaN ("hold where you are"), velocity,
 *                torque, kp and kd scale 0: position mode, no torque until
 *                the first command
 *   disable      mode 0 (stopped), which also clears a latched fault: clear
 *                fault is the same frame, and the drive side reads it as
 *                disable
 *   set zero     write float 0.0 to 0x131 (set output exact): the present
 *                output position reads 0 from now on
 * Faults: mode 1 (fault) with the fault register's code, or mode 11 (the
 * drive's command timeout, servo.default_timeout_s); codes 96 and up are
 * limits at work during control, not faults (ps_moteus_fault_bits).
 *
 * The emulated drive (device side) reads any write/reply layout and integer
 * width, applies the documented defaults of registers a command leaves out
 * (kp and kd scale 1, the rest 0), and always answers with the reply above;
 * unlike the firmware it holds the position set-point between commands
 * instead of advancing it at the commanded velocity.
 *
 * Not handled: a non-zero id.can_prefix, the drive's other modes, velocity
 * and acceleration limits, maximum torque and watchdog overrides per command.
 *
 * Threads: any (pure functions). Allocation: none.
 */
#ifndef PS_MOTEUS_H
#define PS_MOTEUS_H

#include <stdint.h>

#include "ps_actuator.h"

#define PS_MOTEUS_FRAME_LEN  32u   /**< every frame, both ways */
#define PS_MOTEUS_REPLY_FLAG 0x80u /**< source id bit: reply requested */
#define PS_MOTEUS_ID_MIN     8u    /**< smallest drive id with 29-bit replies */
#define PS_MOTEUS_ID_MAX     0x7eu /**< 0x7f is the broadcast id */
#define PS_MOTEUS_NOP        0x50u

/* Registers (docs/protocol/registers.md). */
#define PS_MOTEUS_REG_MODE             0x000u
#define PS_MOTEUS_REG_POSITION         0x001u /**< rev */
#define PS_MOTEUS_REG_VELOCITY         0x002u /**< rev/s */
#define PS_MOTEUS_REG_TORQUE           0x003u /**< Nm */
#define PS_MOTEUS_REG_MOTOR_TEMP       0x00au /**< degC, with a thermistor fitted */
#define PS_MOTEUS_REG_VOLTAGE          0x00du
#define PS_MOTEUS_REG_TEMP             0x00eu /**< board (power stage) degC */
#define PS_MOTEUS_REG_FAULT            0x00fu
#define PS_MOTEUS_REG_CMD_POSITION     0x020u
#define PS_MOTEUS_REG_CMD_VELOCITY     0x021u
#define PS_MOTEUS_REG_CMD_TORQUE       0x022u
#define PS_MOTEUS_REG_KP_SCALE         0x023u
#define PS_MOTEUS_REG_KD_SCALE         0x024u
#define PS_MOTEUS_REG_SET_OUTPUT_EXACT 0x131u

/* Mode register values. */
#define PS_MOTEUS_MODE_STOPPED  0u
#define PS_MOTEUS_MODE_FAULT    1u
#define PS_MOTEUS_MODE_POSITION 10u
#define PS_MOTEUS_MODE_TIMEOUT  11u

/** The 16-bit identifier of a frame from source to destination.  @rt RT-SAFE */
static inline uint32_t ps_moteus_id(uint32_t source, uint32_t destination)
{
    return ((source & 0xffu) << 8) | (destination & 0xffu);
}

/** The protocol table: see ps_actuator.h for the ops' contracts. */
extern const ps_act_proto_t ps_moteus_proto;

/** ps_act_fault_t bits for a reply's mode and fault code: mode 11 is
 *  COMMS_LOST; codes 1..95 are faults (34 over-voltage, 40 under-voltage,
 *  38 over-temperature of board or motor, 32/35/42/43 encoder, others OTHER),
 *  and mode 1 with no such code is OTHER; codes 96.. (limits) are none.
 *  @rt RT-SAFE */
uint32_t ps_moteus_fault_bits(uint32_t mode, uint32_t fault_code);

#endif /* PS_MOTEUS_H */
