/*
 * ps_devices: the emulated devices of the simulated robot, pure with respect
 * to the plant: they take joint states and ideal IMU readings as plain values
 * and give torques and CAN frames. sim/ps_sim.c moves frames between them and
 * the simulated buses and torques into the MuJoCo plant.
 *
 * Actuator (one per robot joint), emulating a drive of the joint's protocol
 * (ps_act_cfg_t.protocol, through the protocol's device-side ops):
 *  - consumes frames the protocol addresses to it: mode requests (enable,
 *    disable, set zero, clear fault) and command frames, decoded on the
 *    drive's wire range (so the set-points are quantised exactly as a real
 *    drive sees them) and converted to the joint side (gear, direction, zero
 *    offset: ps_act_cmd_from_motor);
 *  - starts with motor mode OFF, like real drives: command frames are
 *    answered but not obeyed until an enable arrives. The runtime must
 *    enable every joint before it expects torque;
 *  - runs its PD at its rate act.motor.pd_hz (at every physics step when the
 *    drive's dynamics are not modelled or the rate is above the physics
 *    rate; held in between): tau = kp (p_des - p) + kd (v_des - v) + t_ff,
 *    saturated to the wire t range and to +-torque_max_nm, 0 when not in
 *    motor mode, no command arrived since enable, or power is off. p is the
 *    joint angle minus the zero offset set by a set-zero request. Then, at
 *    every physics step, the motor's torque-speed limit at the joint's speed
 *    (ps_act_motor_limit_torque on the motor side, when modelled);
 *  - answers every valid frame with a reply (position, velocity, torque,
 *    temperature, fault bits, converted to the motor side and encoded by the
 *    protocol) stamped t_ns = arrival + reply_latency_s, which the simulated
 *    bus uses as the earliest start of the reply on the wire;
 *  - first-order winding temperature: P = i^2 R, dT/dt = (P Rth - (T - Ta)) / tau;
 *    above temp_max_c it leaves motor mode with ROTOR_OVERTEMP; ENTER is
 *    refused (answered, not obeyed) until T < temp_max_c - PS_DEVICES_TEMP_HYST_C;
 *  - comms-loss: in motor mode with no command for PS_DEVICES_COMMS_TIMEOUT_NS
 *    it goes limp, leaves motor mode and sets COMMS_LOST; a new ENTER clears it;
 *  - counts commands, rejected frames, and commands whose decoded values lie
 *    outside the joint's configured limits (one quantisation step of slack);
 *    such commands are still obeyed, as a driver knows nothing of the joint;
 *  - drop_replies_until_ns: fault injection, replies to frames arriving before
 *    this time are suppressed while the commands are still obeyed.
 *
 * IMU: every rate_div servo ticks one sample (in the IMU's protocol, ps_imu_encode)
 * of the ideal readings plus white Gaussian noise (sigma from robot->sim) and
 * a constant bias per axis drawn uniformly in [-bias, +bias] at init, all from
 * a xoshiro256** generator seeded through splitmix64 from the scenario seed:
 * same seed, same frames.
 *
 * Physics values are double: they come from MuJoCo (mjtNum) and the winding
 * temperature moves by ~1e-6 degC per step, below float resolution at 40 degC.
 *
 * Threads: one thread per device (the plant thread, or the loop thread in
 * lockstep). Allocation: none (caller owns the structs).
 */
#ifndef PS_DEVICES_H
#define PS_DEVICES_H

#include <stdbool.h>
#include <stdint.h>

#include "../drivers/ps_actuator.h"
#include "../drivers/ps_can.h"
#include "../drivers/ps_imu.h"

/** Parameters of the emulated devices (board `sim` only). */
typedef struct {
    float gyro_noise_rad_s; /**< white noise sigma per sample */
    float gyro_bias_rad_s;  /**< bias magnitude drawn per axis at start */
    float accel_noise_m_s2;
    float accel_bias_m_s2;
    float reply_latency_s; /**< driver turnaround before its reply */
    float thermal_r_c_w;   /**< winding thermal resistance, degC per W */
    float thermal_tau_s;   /**< winding thermal time constant */
    float winding_r_ohm;   /**< phase resistance for copper loss */
    float ambient_c;
} ps_sim_devices_cfg_t;

/** Real drivers go limp after this long without a command in motor mode. */
#define PS_DEVICES_COMMS_TIMEOUT_NS 100000000LL
/** Over-temperature clears only this far below temp_max_c. */
#define PS_DEVICES_TEMP_HYST_C 5.0

typedef struct {
    ps_act_cfg_t act;              /**< copy of the joint's actuator (read-only) */
    ps_act_limits_t lim;           /**< copy of the joint's configured limits (read-only) */
    ps_sim_devices_cfg_t sim;      /**< copy of the device parameters (read-only) */
    bool is_motor_mode;            /**< read-only */
    bool has_cmd;                  /**< a command arrived since enable (read-only) */
    bool is_powered;               /**< user may modify: power stage on (enable relay) */
    ps_act_cmd_t cmd;              /**< last decoded command, joint side (read-only) */
    double zero_offset_rad;        /**< joint angle that reads 0 (ZERO frame) */
    int64_t last_cmd_ns;           /**< arrival of the last command or ENTER */
    double temp_c;                 /**< winding temperature */
    uint32_t fault_bits;           /**< ps_act_fault_t bits, latched */
    uint32_t fault_bits_reported;  /**< of those, sent in a fault report (read-only) */
    uint64_t n_fault_reports;      /**< fault reports produced */
    double tau_nm;                 /**< torque of the last step */
    double pd_tau_nm;              /**< the PD's torque, held between its updates */
    int64_t pd_due_ns;             /**< next PD update (act.motor.pd_hz); 0: at once */
    int64_t drop_replies_until_ns; /**< user may modify: fault injection */
    uint64_t n_cmd_frames;         /**< command frames decoded (obeyed or not) */
    uint64_t n_cmd_ignored;        /**< command frames received outside motor mode */
    uint64_t n_cmd_out_of_limits;  /**< commands outside the joint's limits */
    uint64_t n_bad_frames;         /**< frames for this id that were rejected */
    uint64_t n_replies;            /**< replies produced */
    uint64_t n_replies_dropped;    /**< replies suppressed by drop_replies_until_ns */
} ps_devices_actuator_t;

typedef struct {
    ps_imu_cfg_t cfg;          /**< copy (read-only) */
    ps_sim_devices_cfg_t sim;  /**< copy (read-only) */
    uint64_t rng[4];           /**< xoshiro256** state */
    double gyro_bias_rad_s[3]; /**< drawn at init (read-only) */
    double accel_bias_m_s2[3]; /**< drawn at init (read-only) */
    uint8_t seq;
    uint64_t n_samples;
} ps_devices_imu_t;

/** @pre act, lim and sim checked by the config loader  @post motor mode off,
 *  no fault, powered, temperature at ambient, zero offset 0  @rt INIT */
void ps_devices_init_actuator(ps_devices_actuator_t *a, const ps_act_cfg_t *act,
                              const ps_act_limits_t *lim, const ps_sim_devices_cfg_t *sim);

/** Consume one frame from the device end of the actuator's bus.
 *  @pre f->t_ns is the frame's arrival (end-of-frame) time; q_rad, qd_rad_s the
 *       joint state now
 *  @post state updated; *out_reply written when 1 is returned
 *  @return 1 reply produced | 0 consumed, reply suppressed (drop knob)
 *          | -ENOENT frame not addressed to this actuator (not counted)
 *          | -PS_ERR_PROTOCOL frame for this drive rejected (malformed for its
 *            protocol; counted in n_bad_frames, no reply)
 *  @units rad, rad/s, ns  @rt RT-SAFE O(1), plant thread */
int ps_devices_handle_frame(ps_devices_actuator_t *a, const ps_can_frame_t *f, double q_rad,
                            double qd_rad_s, ps_can_frame_t *out_reply);

/** One physics step of the driver: comms-loss check at now_ns, PD torque,
 *  saturation, winding temperature over dt_s, over-temperature check.
 *  @return the torque to apply during the step  @units rad, rad/s, ns, s, Nm
 *  @rt RT-SAFE O(1), plant thread */
double ps_devices_step_actuator(ps_devices_actuator_t *a, double q_rad, double qd_rad_s,
                                int64_t now_ns, double dt_s);

/** A drive whose protocol has a fault report (RobStride type 21) sends one
 *  when a fault latches that it has not reported yet, as a real one does
 *  on its own; faults cleared by an enable can be reported again.
 *  @post *out written (t_ns = now_ns) when 1 is returned
 *  @return 1 report due | 0 none  @rt RT-SAFE O(1), plant thread */
int ps_devices_take_fault_report(ps_devices_actuator_t *a, int64_t now_ns, ps_can_frame_t *out);

/** Offer one frame from bus bus_idx to the drives on that bus (acts[j] is
 *  joint j, at q_rad[j], qd_rad_s[j]), the first that it addresses takes it.
 *  @post *out_joint the joint that took it, -1 when none (out_joint may be NULL)
 *  @return as ps_devices_handle_frame; -ENOENT when no drive on the bus is
 *          addressed  @rt RT-SAFE O(n_joints) */
int ps_devices_route_frame(ps_devices_actuator_t *acts, uint32_t n_joints, uint32_t bus_idx,
                           const ps_can_frame_t *f, const double *q_rad, const double *qd_rad_s,
                           ps_can_frame_t *out_reply, int *out_joint);

/** @pre cfg->rate_div >= 1  @post biases drawn from seed  @rt INIT */
void ps_devices_init_imu(ps_devices_imu_t *imu, const ps_imu_cfg_t *cfg,
                         const ps_sim_devices_cfg_t *sim, uint64_t seed);

/** Servo tick `tick` (0 at start): when tick % rate_div == 0, sample the ideal
 *  readings with bias and noise and encode them in the IMU's protocol
 *  (ps_imu_encode: two frames for pushstep, five for xsens) stamped t_ns.
 *  @return frames written | 0 no sample this tick  @units rad/s, m/s^2, ns
 *  @rt RT-SAFE O(1), plant thread */
int ps_devices_tick_imu(ps_devices_imu_t *imu, uint64_t tick, const double gyro_rad_s[3],
                        const double accel_m_s2[3], int64_t t_ns,
                        ps_can_frame_t out[PS_IMU_MAX_FRAMES]);

#endif /* PS_DEVICES_H */
