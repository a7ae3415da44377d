/*
 * ps_actuator: the protocol-neutral actuator port.
 *
 * The servo layer and the loop speak only in joint units through the neutral
 * types below: a joint command (position, velocity, kp, kd, feed-forward
 * torque, for the drive's own PD) and a joint measurement (position,
 * velocity, torque, temperature, fault bits, time). Each actuator protocol
 * (MIT mode in drivers/ps_mit.c, RobStride in ps_robstride.c, moteus over
 * CAN FD in ps_moteus.c; ODrive comes next) is
 * an ops table, ps_act_proto_t, that encodes commands and mode requests into
 * CAN frames and matches and decodes replies, all on the motor side.
 *
 * Between the two sides sits one conversion, applied here and nowhere else
 * (ps_act_cmd_to_motor, ps_act_meas_from_motor): with gear ratio N (motor
 * turns per joint turn), direction d (+1 or -1) and zero offset z (the joint
 * angle at which the motor reads 0),
 *   q_motor = d N (q_joint - z)      qd_motor = d N qd_joint
 *   tau_motor = d tau_joint / N      kp_motor = kp_joint / N^2 (kd likewise)
 * so the drive's PD on the motor side applies exactly the joint-side PD.
 * Replies report the motor's current; torque = d N kt i.
 *
 * The device side of each protocol (decode a command, classify a request,
 * encode a reply) is in the same table, for the emulated drives in sim/: the
 * whole system runs in simulation with any protocol.
 *
 * Threads: pure functions, any thread. Allocation: none.
 */
#ifndef PS_ACTUATOR_H
#define PS_ACTUATOR_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "ps_can.h"

/** Frames a protocol may need for one command cycle or one request. */
#define PS_ACT_MAX_FRAMES 2u

/** A command for the drive's PD: tau = kp (q - q_meas) + kd (qd - qd_meas) + tau_ff.
 *  Joint units on the servo side, motor units inside a protocol. */
typedef struct {
    float q_rad;
    float qd_rad_s;
    float kp_nm_rad;
    float kd_nm_s_rad;
    float tau_ff_nm;
} ps_act_cmd_t;

/** Fault bits a drive can report, whatever its protocol. */
typedef enum {
    PS_ACT_FAULT_OVERVOLTAGE = 1u << 0,
    PS_ACT_FAULT_UNDERVOLTAGE = 1u << 1,
    PS_ACT_FAULT_OVERCURRENT = 1u << 2,
    PS_ACT_FAULT_DRIVER_OVERTEMP = 1u << 3, /**< power stage */
    PS_ACT_FAULT_MOTOR_OVERTEMP = 1u << 4,  /**< winding */
    PS_ACT_FAULT_COMMS_LOST = 1u << 5,      /**< the drive's own command timeout */
    PS_ACT_FAULT_OVERLOAD = 1u << 6,
    PS_ACT_FAULT_ENCODER = 1u << 7,
    PS_ACT_FAULT_OTHER = 1u << 8, /**< a code the protocol's table does not name */
} ps_act_fault_t;

/** One joint as its drive last reported it. */
typedef struct {
    float q_rad;
    float qd_rad_s;
    float tau_nm;        /**< from the reported current or torque */
    float temp_c;        /**< hottest reported temperature */
    uint32_t fault_bits; /**< ps_act_fault_t bits, 0: none */
    int64_t t_ns;        /**< time the reply was taken; 0: never */
} ps_act_meas_t;

/** Mode requests every protocol can express. */
typedef enum {
    PS_ACT_REQ_ENABLE = 0, /**< enter closed-loop (motor) mode; obey commands */
    PS_ACT_REQ_DISABLE,    /**< leave it: no torque */
    PS_ACT_REQ_SET_ZERO,   /**< the present position reads 0 from now on */
    PS_ACT_REQ_CLEAR_FAULT,
    PS_ACT_REQ_COUNT
} ps_act_request_t;

/** Wire ranges of a drive's packing, motor side (the firmware's constants):
 *  every field of a command must lie inside them. kp and kd start at 0. */
typedef struct {
    float p_min_rad, p_max_rad;
    float v_min_rad_s, v_max_rad_s;
    float kp_max_nm_rad;
    float kd_max_nm_s_rad;
    float t_min_nm, t_max_nm;
    float i_min_a, i_max_a; /**< reply current range */
} ps_act_range_t;

/** A joint's configured limits, joint side: no command leaves the runtime
 *  outside them (robot file, per joint). */
typedef struct {
    float pos_min_rad, pos_max_rad;
    float vel_max_rad_s;   /**< |qd| any command may ask for */
    float torque_max_nm;   /**< |tau| any command may ask for */
    float kp_max_nm_rad;   /**< no command's kp exceeds this */
    float kd_max_nm_s_rad; /**< no command's kd exceeds this */
} ps_act_limits_t;

/** A drive's dynamics, drive output side like the wire ranges (the emulated
 *  drives and the training model apply them; the runtime does not need them).
 *  All fields 0: not modelled (torque bounded by the wire range and the
 *  joint's torque_max only).
 *
 *  Torque-speed limit: the datasheet's two points, no-load speed w0 at zero
 *  torque and the rated torque tr at the rated speed wr, give the ideal DC
 *  motor line of a voltage-limited drive, whose stall torque is
 *  ts = tr w0 / (w0 - wr). While motoring (torque and speed of the same sign)
 *  |tau| <= ts (1 - |w| / w0), and never beyond the peak torque; braking
 *  (opposite signs) the peak torque is available. Above w0 only braking
 *  torque is left. (The same model as Isaac Lab's DC motor actuator.) */
typedef struct {
    float peak_torque_nm;      /**< |tau| the drive gives at low speed, > 0 */
    float rated_torque_nm;     /**< the datasheet's rated point: this torque ... */
    float rated_speed_rad_s;   /**< ... at this speed */
    float no_load_speed_rad_s; /**< speed at zero torque (rated voltage) */
    float armature_kg_m2;      /**< rotor inertia reflected to the output; the model's
                                    joint armature is this times gear_ratio^2 */
    float pd_hz;               /**< rate of the drive's own PD (impedance) loop */
} ps_act_motor_t;

typedef enum {
    PS_ACT_PROTO_MIT = 0,   /**< MIT mode (CubeMars AK, Damiao): drivers/ps_mit.h */
    PS_ACT_PROTO_ROBSTRIDE, /**< RobStride / Xiaomi CyberGear: drivers/ps_robstride.h */
    PS_ACT_PROTO_MOTEUS,    /**< mjbots moteus over CAN FD: drivers/ps_moteus.h */
    PS_ACT_PROTO_COUNT
} ps_act_proto_id_t;

/** One joint's actuator: where it sits on the wire and how its units map.
 *  Consumed by the actuator port, the bus planner's sources and the emulated
 *  drives. */
typedef struct {
    uint32_t bus_idx;           /**< index into the board's buses */
    uint32_t can_id;            /**< the drive's id (command identifier or id field) */
    uint32_t reply_id;          /**< identifier its replies arrive on (protocols that use one) */
    ps_act_proto_id_t protocol; /**< which ops table */
    ps_act_range_t wire;        /**< the drive's packing ranges, motor side */
    float gear_ratio;           /**< motor turns per joint turn, > 0 (1: direct) */
    float direction;            /**< +1 or -1: motor sense relative to the joint */
    float zero_offset_rad;      /**< joint angle at which the motor reads 0 */
    float kt_nm_a;              /**< motor torque constant, current -> motor torque */
    float temp_max_c;           /**< fault above this temperature */
    uint32_t rate_div;          /**< command every rate_div servo ticks, 1.. */
    ps_act_motor_t motor;       /**< the drive's dynamics (all 0: not modelled) */
} ps_act_cfg_t;

/** A protocol: pure encode/decode on the motor side. Every function is RT-SAFE,
 *  O(1), and writes its outputs only on success. */
typedef struct {
    const char *name;            /**< as written in robot files, e.g. "mit" */
    uint8_t id_bits;             /**< 11 or 29 */
    bool is_fd;                  /**< needs a CAN FD bus */
    uint8_t cmd_len;             /**< payload bytes of a command frame */
    uint8_t reply_len;           /**< payload bytes of a reply frame */
    uint8_t n_cmd;               /**< frames per command cycle, 1..PS_ACT_MAX_FRAMES */
    uint8_t n_reply;             /**< reply frames per command cycle */
    uint32_t can_id_min;         /**< smallest valid can_id; 0: 1 */
    uint32_t id_max;             /**< largest valid drive id (can_id and reply_id) */
    bool is_reply_id_shared;     /**< reply_id is the host's id, the same for every drive
                                      on a bus: only can_id must be unique there */
    uint32_t resolution_bits[5]; /**< bits of q, qd, kp, kd, tau_ff in a command */

    /** Host side. @return frames written (1..max) | -PS_ERR_LIMIT a field outside
     *  the wire range or not finite (refused, never clamped) | -ENOSPC max too small */
    int (*encode_cmd)(const ps_act_cfg_t *a, const ps_act_cmd_t *motor_cmd, ps_can_frame_t *out,
                      size_t max);
    /** @return frames written | -ENOSPC | -ENOTSUP not expressible in this protocol */
    int (*encode_request)(const ps_act_cfg_t *a, ps_act_request_t req, ps_can_frame_t *out,
                          size_t max);
    /** @return true if f is a reply of the drive a (id, width, and any id field) */
    bool (*match_reply)(const ps_act_cfg_t *a, const ps_can_frame_t *f);
    /** The receive filter for drive a's replies: a frame of the protocol's id
     *  width whose identifier equals *out_id on the bits set in *out_mask
     *  (SocketCAN's CAN_RAW_FILTER rule). It passes every frame match_reply
     *  accepts, and as few others as the layout allows. */
    void (*reply_filter)(const ps_act_cfg_t *a, uint32_t *out_id, uint32_t *out_mask);
    /** @post *out motor side, t_ns untouched  @return 0 | -PS_ERR_PROTOCOL malformed */
    int (*decode_reply)(const ps_act_cfg_t *a, const ps_can_frame_t *f, ps_act_meas_t *out);

    /** Optional (NULL in protocols without one): a fault report the drive sends
     *  on its own when a fault latches, apart from its replies (RobStride
     *  type 21). fault_filter: the receive filter for drive a's reports, as
     *  reply_filter. decode_fault: @post *out_fault_bits ps_act_fault_t bits
     *  @return 0 | -ENOENT not drive a's report | -PS_ERR_PROTOCOL malformed.
     *  encode_fault (device side): @return frames written | -ENOSPC */
    void (*fault_filter)(const ps_act_cfg_t *a, uint32_t *out_id, uint32_t *out_mask);
    int (*decode_fault)(const ps_act_cfg_t *a, const ps_can_frame_t *f, uint32_t *out_fault_bits);
    int (*encode_fault)(const ps_act_cfg_t *a, uint32_t fault_bits, ps_can_frame_t *out,
                        size_t max);

    /** Device side (emulated drives). @return true if f is addressed to drive a */
    bool (*is_for_drive)(const ps_act_cfg_t *a, const ps_can_frame_t *f);
    /** @return the request f carries (0..PS_ACT_REQ_COUNT-1) | -ENOENT f is a
     *  command, not a request */
    int (*classify_request)(const ps_act_cfg_t *a, const ps_can_frame_t *f);
    /** @return 0 | -PS_ERR_PROTOCOL malformed command frame */
    int (*decode_cmd)(const ps_act_cfg_t *a, const ps_can_frame_t *f, ps_act_cmd_t *out_motor);
    /** Values outside the wire range saturate, as a drive's packing does.
     *  @return frames written | -ENOSPC */
    int (*encode_reply)(const ps_act_cfg_t *a, const ps_act_meas_t *motor, ps_can_frame_t *out,
                        size_t max);
} ps_act_proto_t;

/** @return true when m models a drive (peak_torque_nm > 0)  @rt RT-SAFE */
bool ps_act_motor_is_modelled(const ps_act_motor_t *m);

/** Check a drive model: all zero, or every field finite with
 *  0 < rated_torque <= peak_torque, 0 <= rated_speed < no_load_speed,
 *  armature >= 0 and pd_hz > 0.
 *  @post err holds "field: problem" on failure  @return 0 | -EINVAL  @rt INIT */
int ps_act_check_motor(const ps_act_motor_t *m, char *err, size_t err_len);

/** The torque the drive can give for a requested tau_nm at output speed
 *  omega_rad_s (the torque-speed limit above). Not modelled: tau unchanged;
 *  modelled and either input NaN: NaN.
 *  @units Nm, rad/s, drive output side  @rt RT-SAFE O(1), pure */
float ps_act_motor_limit_torque(const ps_act_motor_t *m, float tau_nm, float omega_rad_s);

/** @return the ops table of a protocol, NULL outside the enum  @rt RT-SAFE */
const ps_act_proto_t *ps_act_proto_get(ps_act_proto_id_t id);

/** @return protocol id for its name ("mit"), -ENOENT unknown  @rt INIT */
int ps_act_proto_find(const char *name);

/** Check one actuator's configuration against its protocol: wire ranges
 *  ordered and finite, gear ratio finite and > 0, direction +1 or -1, zero
 *  offset finite, can_id within [can_id_min (at least 1), id_max], reply_id
 *  at most id_max.
 *  @post err holds "field: problem" on failure  @return 0 | -EINVAL  @rt INIT */
int ps_act_check_cfg(const ps_act_cfg_t *a, char *err, size_t err_len);

/** The wire ranges seen from the joint: what a joint command may hold so that
 *  its motor-side image encodes (ordered min < max whatever the direction).
 *  @pre a checked  @rt RT-SAFE O(1), pure */
void ps_act_joint_range(const ps_act_cfg_t *a, ps_act_range_t *out_joint);

/** The smallest step of each command field seen from the joint, from the
 *  protocol's resolution: q, qd, kp, kd, tau_ff. @pre a checked  @rt RT-SAFE */
void ps_act_joint_lsb(const ps_act_cfg_t *a, float out_lsb[5]);

/** Joint command -> motor command (gear, direction, zero offset).  @rt RT-SAFE, pure */
void ps_act_cmd_to_motor(const ps_act_cfg_t *a, const ps_act_cmd_t *joint, ps_act_cmd_t *out_motor);
/** Motor command -> joint command (the emulated drive's view).  @rt RT-SAFE, pure */
void ps_act_cmd_from_motor(const ps_act_cfg_t *a, const ps_act_cmd_t *motor,
                           ps_act_cmd_t *out_joint);
/** Motor measurement -> joint measurement; fault bits, temperature and t_ns copied.
 *  @rt RT-SAFE, pure */
void ps_act_meas_from_motor(const ps_act_cfg_t *a, const ps_act_meas_t *motor,
                            ps_act_meas_t *out_joint);
/** Joint measurement -> motor measurement (the emulated drive's reply).  @rt RT-SAFE */
void ps_act_meas_to_motor(const ps_act_cfg_t *a, const ps_act_meas_t *joint,
                          ps_act_meas_t *out_motor);

/** Encode a joint command for the wire: convert, then the protocol's encoder.
 *  A field the conversion's rounding puts outside the wire range by at most
 *  1e-5 of the range is put back on its edge, so every command inside
 *  ps_act_joint_range encodes; anything further out is refused.
 *  @pre a checked  @return frames written | -PS_ERR_LIMIT | -ENOSPC | -EINVAL
 *  @rt RT-SAFE O(1) */
int ps_act_encode_command(const ps_act_cfg_t *a, const ps_act_cmd_t *joint, ps_can_frame_t *out,
                          size_t max);

/** @return frames written | -ENOSPC | -ENOTSUP | -EINVAL  @rt RT-SAFE O(1) */
int ps_act_encode_request(const ps_act_cfg_t *a, ps_act_request_t req, ps_can_frame_t *out,
                          size_t max);

/** Match and decode a reply into a joint measurement (t_ns not written).
 *  @post *out_joint written on success only, every value finite
 *  @return 0 | -ENOENT not this drive's reply | -PS_ERR_PROTOCOL malformed, or
 *          a value that is not finite once converted to the joint
 *  @rt RT-SAFE O(1) */
int ps_act_decode_reply(const ps_act_cfg_t *a, const ps_can_frame_t *f, ps_act_meas_t *out_joint);

/** A fault report of drive a (the protocol's decode_fault).
 *  @return 0 | -ENOENT not its report, or its protocol has none
 *          | -PS_ERR_PROTOCOL malformed  @rt RT-SAFE O(1) */
int ps_act_decode_fault(const ps_act_cfg_t *a, const ps_can_frame_t *f, uint32_t *out_fault_bits);

/** @return name of the lowest set fault bit, e.g. "MOTOR_OVERTEMP"; "none" for 0
 *  @rt RT-SAFE */
const char *ps_act_fault_name(uint32_t fault_bits);

#endif /* PS_ACTUATOR_H */
