/*
 * ps_mit: the MIT-mode actuator protocol (CubeMars AK / Damiao style), as
 * pure encode/decode functions. See docs/can-protocols.md for the byte layout.
 *
 * Command (8 bytes, host -> driver, CAN id = motor id):
 *   p16 | v12 | kp12 | kd12 | t12, big-endian bit packing, each value mapped
 *   linearly from [min, max] onto [0, 2^bits - 1] and rounded to nearest.
 * Special frames: FF FF FF FF FF FF FF FC enter motor mode, ...FD exit, ...FE
 *   set current position as zero.
 * Reply (8 bytes, driver -> host, CAN id = reply id):
 *   byte0 = motor id (low nibble) | fault << 4, p16, v12, i12 (phase current),
 *   byte6 = driver (MOSFET) temperature degC, byte7 = rotor temperature degC,
 *   both as int8.
 *
 * Threads: any (pure functions). Allocation: none.
 */
#ifndef PS_MIT_H
#define PS_MIT_H

#include <stdint.h>

#include "ps_actuator.h"

#define PS_MIT_FRAME_LEN 8u
#define PS_MIT_P_BITS    16u
#define PS_MIT_V_BITS    12u
#define PS_MIT_KP_BITS   12u
#define PS_MIT_KD_BITS   12u
#define PS_MIT_T_BITS    12u
#define PS_MIT_I_BITS    12u

/* Wire ranges: ps_act_range_t (drivers/ps_actuator.h), the firmware constants
 * of one motor model. */

typedef struct {
    float p_rad;       /**< position set-point */
    float v_rad_s;     /**< velocity set-point */
    float kp_nm_rad;   /**< stiffness */
    float kd_nm_s_rad; /**< damping */
    float t_ff_nm;     /**< feed-forward torque */
} ps_mit_cmd_t;

/** Driver fault codes carried in the reply's high nibble. */
typedef enum {
    PS_MIT_FAULT_NONE = 0x0,
    PS_MIT_FAULT_OVERVOLTAGE = 0x8,
    PS_MIT_FAULT_UNDERVOLTAGE = 0x9,
    PS_MIT_FAULT_OVERCURRENT = 0xA,
    PS_MIT_FAULT_MOS_OVERTEMP = 0xB,
    PS_MIT_FAULT_ROTOR_OVERTEMP = 0xC,
    PS_MIT_FAULT_COMMS_LOST = 0xD,
    PS_MIT_FAULT_OVERLOAD = 0xE,
} ps_mit_fault_t;

typedef struct {
    uint8_t motor_id; /**< low nibble of the sender's motor id */
    uint8_t fault;    /**< ps_mit_fault_t */
    float p_rad;
    float v_rad_s;
    float i_a; /**< phase current */
    int8_t temp_mos_c;
    int8_t temp_rotor_c;
} ps_mit_reply_t;

typedef enum {
    PS_MIT_SPECIAL_ENTER = 0xFC,
    PS_MIT_SPECIAL_EXIT = 0xFD,
    PS_MIT_SPECIAL_ZERO = 0xFE,
} ps_mit_special_t;

/** Check a range table: min < max, kp/kd max > 0, all finite.
 *  @return 0 | -EINVAL  @rt RT-SAFE */
int ps_mit_check_range(const ps_act_range_t *r);

/** Encode a command. A field outside its wire range, NaN or infinite is
 *  refused, never clamped silently (the servo layer clamps to the tighter joint
 *  limits first). Ranges are inclusive: kp in [0, kp_max], kd in [0, kd_max].
 *  A command whose packing would equal a special frame (p, v, kp, kd all at
 *  their maxima and t within 3 LSB of t_max) is refused too, since a driver
 *  would read it as a mode change.
 *  @pre r checked  @post out written on success only  @return 0 | -PS_ERR_LIMIT
 *  @rt RT-SAFE O(1) */
int ps_mit_encode_cmd(const ps_act_range_t *r, const ps_mit_cmd_t *cmd,
                      uint8_t out[PS_MIT_FRAME_LEN]);

/** Decode a command frame (the driver's side, used by the emulated actuator).
 *  @return 0 | -PS_ERR_PROTOCOL (len != 8 or a special frame)  @rt RT-SAFE */
int ps_mit_decode_cmd(const ps_act_range_t *r, const uint8_t *data, uint8_t len, ps_mit_cmd_t *out);

/** @post out = the 8-byte special frame  @rt RT-SAFE */
void ps_mit_encode_special(ps_mit_special_t which, uint8_t out[PS_MIT_FRAME_LEN]);

/** @return the special code (0xFC..0xFE) if data is a special frame, else 0  @rt RT-SAFE */
int ps_mit_classify_special(const uint8_t *data, uint8_t len);

/** Encode a reply (driver side). Values outside the range saturate, as a
 *  driver's packing does.  @rt RT-SAFE */
void ps_mit_encode_reply(const ps_act_range_t *r, const ps_mit_reply_t *rep,
                         uint8_t out[PS_MIT_FRAME_LEN]);

/** Decode a reply. @return 0 | -PS_ERR_PROTOCOL (len != 8)  @rt RT-SAFE */
int ps_mit_decode_reply(const ps_act_range_t *r, const uint8_t *data, uint8_t len,
                        ps_mit_reply_t *out);

/** Linear float <-> unsigned mapping used by every field, exposed for tests.
 *  float_to_uint: u = round((x - min) * (2^bits - 1) / (max - min)), halves
 *  rounded up; x <= min -> 0, x >= max -> 2^bits - 1, NaN -> 0.
 *  uint_to_float: x = u * (max - min) / (2^bits - 1) + min (u saturates to
 *  2^bits - 1). Round trip error is at most half an LSB inside [min, max].
 *  @pre bits 1..32  @rt RT-SAFE */
uint32_t ps_mit_float_to_uint(float x, float min, float max, unsigned bits);
float ps_mit_uint_to_float(uint32_t u, float min, float max, unsigned bits);

/** MIT mode as an actuator protocol (ps_actuator.h): 11-bit ids, command on
 *  can_id, reply on reply_id whose byte 0 low nibble is can_id's low nibble;
 *  ENABLE = ENTER, DISABLE = EXIT, SET_ZERO = ZERO, CLEAR_FAULT = ENTER
 *  (MIT drivers clear a latched fault when motor mode is entered again).
 *  Fault codes map to ps_act_fault_t bits by ps_mit_fault_bits. */
extern const ps_act_proto_t ps_mit_proto;

/** @return ps_act_fault_t bits for an MIT fault nibble (0: none; unknown
 *  codes: PS_ACT_FAULT_OTHER)  @rt RT-SAFE */
uint32_t ps_mit_fault_bits(uint8_t code);

/** @return the MIT fault nibble for the most serious of the bits (for the
 *  emulated driver), 0 for none  @rt RT-SAFE */
uint8_t ps_mit_fault_code(uint32_t fault_bits);

#endif /* PS_MIT_H */
