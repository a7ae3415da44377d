/*
 * ps_recorder: the flight recorder. Every tick the loop's tap copies one
 * fixed-size record (ps_rec_tick_t: joints measured and commanded, IMU,
 * estimate with capture point and support polygon, state and condition
 * bits, policy outputs, stage times, buses, GPIO, the plant's ground truth
 * in simulation) into a large ring sized and touched at start-up. A writer
 * thread (non-real-time) turns records into MCAP messages (ros2msg schemas,
 * CDR; rt/ps_mcap.h, rt/ps_rosmsg.h) in two modes, alone or together:
 *
 *  - continuous: every record to one file (--record FILE.mcap);
 *  - flight: nothing written until a trigger; then the pre_s seconds before
 *    it (still in the ring) and the post_s seconds after it go to a new file
 *    DIR/flight-NNNN.mcap (--flight DIR). Triggers: e-stop entered, fall
 *    detected, a watchdog (stale reply or IMU, late policy) while the
 *    controller is in charge, an overrun burst (the OVERRUN condition), the
 *    GPIO record button, and ps_recorder_trigger (SIGUSR1 in pushstep).
 *    Triggers during a dump are noted in it; the next dump starts after.
 *
 * The ring: the loop is its only writer and never waits: record i goes to
 * slot i mod n_slots, overwriting the oldest. Each slot carries a sequence
 * stamp (i + 1 once complete) that the writer thread checks before and
 * after copying a record out (a seqlock per slot), so a record overwritten
 * while being read is detected, and a reader that fell more than n_slots
 * behind knows how many it lost. Nothing is ever dropped at the loop's end:
 * what a slow disk costs shows up as records the writer lost
 * (n_lost_ring), counted in the summary and in the file's metadata.
 *
 * Disk trouble: a failed write (disk full, an I/O error, a path that
 * cannot be created) ends that file (what was written stays readable up to
 * its last complete chunk); its records from then on are counted as lost
 * to I/O (n_lost_io), the loop runs on. A slow disk makes the writer fall
 * behind: records it could not read in time are n_lost_ring. The test knob
 * PUSHSTEP_REC_IO_DELAY_NS (read at init, 0..1e9) sleeps that long before
 * every write, to emulate a slow disk.
 *
 * Threads: init/start/stop/deinit on the main thread; ps_recorder_on_tick
 * on the loop thread (the loop's tap); ps_recorder_trigger from any thread
 * or a signal handler; the writer thread is internal. Allocation: the ring
 * and the writer's buffers at init (the ring's pages touched there); the
 * writer thread allocates (MCAP buffers, file names), the loop side never.
 */
#ifndef PS_RECORDER_H
#define PS_RECORDER_H

#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdint.h>

#include "ps_limits.h"
#include "ps_loop.h"
#include "ps_mcap.h"
#include "ps_ring.h"

/** Crowd contact forces kept per tick (sim, issue 8's crowd): the largest. */
#define PS_REC_MAX_CONTACTS 16u
/** Stage times kept per tick: wake, read, estimate, policy, servo, write, tick. */
#define PS_REC_N_STAGES 7u

typedef enum {
    PS_REC_TRIG_ESTOP = 1u << 0,    /**< the state machine entered ESTOP */
    PS_REC_TRIG_FALL = 1u << 1,     /**< a fall detected while in charge */
    PS_REC_TRIG_WATCHDOG = 1u << 2, /**< stale reply/IMU or late policy while in charge */
    PS_REC_TRIG_OVERRUN = 1u << 3,  /**< overrun burst: the OVERRUN condition rose */
    PS_REC_TRIG_BUTTON = 1u << 4,   /**< the GPIO record button (its press, not its hold) */
    PS_REC_TRIG_SIGNAL = 1u << 5,   /**< ps_recorder_trigger (SIGUSR1) */
} ps_rec_trigger_t;
#define PS_REC_TRIG_COUNT 6u

/** Ground truth of a simulated plant for one tick (world frame, SI). */
typedef struct {
    float t_s;
    float com_m[3];
    float pelvis_m[3];
    float head_height_m;
    float push_force_n[3]; /**< scenario pushes acting now */
    float tau_abs_sum_nm;  /**< sum of |joint torque| applied */
    uint8_t is_fallen;
    uint8_t is_drive_power_on;
    uint16_t n_contacts; /**< the crowd's contacts on the robot (agent UINT16_MAX: a
                              wall or an obstacle); force on the robot, world */
    uint16_t contact_agent[PS_REC_MAX_CONTACTS];
    float contact_fx_n[PS_REC_MAX_CONTACTS], contact_fy_n[PS_REC_MAX_CONTACTS],
        contact_fz_n[PS_REC_MAX_CONTACTS];
    float contact_x_m[PS_REC_MAX_CONTACTS], contact_y_m[PS_REC_MAX_CONTACTS],
        contact_z_m[PS_REC_MAX_CONTACTS];
} ps_rec_truth_t;

/** Where the truth comes from (the composition root wires the sim's). */
typedef struct {
    /** @return true when *out was filled  @rt RT-SAFE, loop thread */
    bool (*read)(void *ctx, ps_rec_truth_t *out);
    void *ctx;
} ps_rec_truth_src_t;

/** One tick. Fixed size, no pointers; arrays are by joint / bus index. */
typedef struct {
    uint64_t tick;
    int64_t t_ns; /**< the tick's deadline on the loop's clock */
    uint32_t cond;
    uint32_t triggers; /**< ps_rec_trigger_t bits raised on this tick */
    uint8_t state, state_before;
    uint8_t is_policy_tick;
    uint8_t has_truth;
    uint32_t n_joints, n_buses; /**< as the robot and board have */
    /* joints as measured */
    float q_rad[PS_MAX_JOINTS], qd_rad_s[PS_MAX_JOINTS], tau_nm[PS_MAX_JOINTS],
        temp_c[PS_MAX_JOINTS];
    uint32_t fault_bits[PS_MAX_JOINTS];
    /* commands (the last computed per joint; is_cmd_sent this tick) */
    uint8_t is_cmd_sent[PS_MAX_JOINTS];
    float cmd_q_rad[PS_MAX_JOINTS], cmd_qd_rad_s[PS_MAX_JOINTS], cmd_kp_nm_rad[PS_MAX_JOINTS],
        cmd_kd_nm_s_rad[PS_MAX_JOINTS], cmd_tau_ff_nm[PS_MAX_JOINTS];
    /* policy outputs (valid on policy ticks) */
    float target_q_rad[PS_MAX_JOINTS], target_qd_rad_s[PS_MAX_JOINTS],
        target_tau_ff_nm[PS_MAX_JOINTS];
    int64_t policy_ns;
    uint8_t is_policy_late, is_target_invalid;
    /* IMU */
    float gyro_body_rad_s[3], accel_body_m_s2[3];
    int64_t imu_t_ns;
    /* estimate (ground frame of policy/ps_state.h) */
    float roll_rad, pitch_rad;
    float com_m[3], com_vel_m_s[3], cop_m[2];
    float capture_point_m[2];                 /**< com_xy + com_vel_xy / sqrt(g / com_z) */
    float support_min_m[2], support_max_m[2]; /**< box around the soles in contact */
    float foot_left_m[3], foot_right_m[3];
    uint8_t is_contact_left, is_contact_right, is_fallen;
    /* timing */
    int64_t stage_ns[PS_REC_N_STAGES]; /**< wake, read, estimate, policy (-1: none), servo,
                                            write, tick */
    uint64_t n_overruns;
    /* buses */
    uint8_t bus_mode[PS_MAX_BUSES]; /**< ps_can_bus_mode_t */
    uint16_t bus_tx_errors[PS_MAX_BUSES], bus_rx_errors[PS_MAX_BUSES];
    uint16_t bus_n_rx[PS_MAX_BUSES], bus_n_tx[PS_MAX_BUSES]; /**< this tick */
    float bus_load[PS_MAX_BUSES];
    uint64_t n_rx_bad, n_rx_unknown, n_tx_refused, n_bus_errors, n_gpio_errors;
    /* GPIO */
    uint8_t is_estop_input, heartbeat, led, is_button_pressed;
    /* simulation */
    ps_rec_truth_t truth;
} ps_rec_tick_t;

/** A trigger as the loop hands it to the writer. */
typedef struct {
    uint64_t idx;  /**< record index */
    uint32_t bits; /**< ps_rec_trigger_t */
} ps_rec_trig_t;

/** Triggers queued for the writer; more between two of its passes are noted
 *  in their records (and /events) but start no dump of their own. */
#define PS_REC_TRIG_QUEUE 64u

/** A ring slot: sequence stamp and record. */
typedef struct {
    _Atomic uint64_t seq; /**< i + 1 once record i is complete; UINT64_MAX while written */
    ps_rec_tick_t rec;
} ps_rec_slot_t;

typedef struct {
    const char *path;  /**< continuous file; NULL: off */
    const char *dir;   /**< flight dumps folder; NULL: off */
    double pre_s;      /**< flight: seconds kept before a trigger */
    double post_s;     /**< flight: seconds written after it */
    double ring_s;     /**< ring length in seconds (at least 0.1); 0: pre_s + post_s + 1,
                            at least 2. Rounded up to a power of two of records */
    uint32_t servo_hz; /**< ticks per second (sizes the ring) */
    ps_mcap_compression_t compression;
    size_t chunk_size;   /**< 0: 256 KiB */
    bool is_sync_chunks; /**< fdatasync every chunk (power-cut safe); default on */
    int cpu;             /**< writer thread CPU, -1: any */
    /** Unpaced runs (lockstep, replay): the loop waits for the writer rather
     *  than overwrite a record the writer still needs, so a recording of a
     *  simulation is complete however busy the machine. Never in real time
     *  (the wait blocks the tick). */
    bool is_lossless;
    /* what the files say about the run */
    const char *board_name, *robot_name, *scenario_path;
    const char (*joint_name)[PS_NAME_LEN];
    uint32_t n_joints;
    const char (*bus_name)[PS_NAME_LEN];
    uint32_t n_buses;
    float foot_length_m, foot_width_m; /**< for the support polygon */
    const char *clock_name;            /**< "CLOCK_MONOTONIC" or "simulated" */
} ps_recorder_cfg_t;

/** One output file's account. */
typedef struct {
    char path[PS_PATH_LEN + 32];
    uint64_t n_records;  /**< records written */
    uint64_t n_messages; /**< MCAP messages in the file */
    uint64_t n_bytes;
    uint64_t n_lost_ring;   /**< records overwritten before the writer read them */
    uint64_t n_lost_io;     /**< records that could not be written (I/O error) */
    uint64_t n_index_bytes; /**< chunk index held in memory until close, for the MCAP
                                 summary: it grows with the file (the one growth a long
                                 recording has; tools/soak.py allows for it) */
    int err;                /**< 0 or the error that ended the file */
    uint32_t triggers;      /**< flight: cause(s) of the dump */
    uint64_t trigger_tick;
    uint64_t channel_n_messages[PS_MCAP_MAX_CHANNELS];
} ps_rec_file_stats_t;

#define PS_REC_MAX_DUMP_STATS 16u

typedef struct {
    uint32_t n_slots;    /**< ring size in records */
    uint64_t n_pushed;   /**< records the loop put into the ring */
    uint32_t n_channels; /**< channels defined (not all appear in every file) */
    char channel_topic[PS_MCAP_MAX_CHANNELS][32];
    ps_rec_file_stats_t cont; /**< continuous file */
    uint32_t n_triggers;      /**< triggers raised */
    uint32_t n_triggers_by[PS_REC_TRIG_COUNT];
    uint32_t n_dumps;                                /**< flight dumps started */
    uint32_t n_dumps_failed;                         /**< ... that ended with an error */
    ps_rec_file_stats_t dump[PS_REC_MAX_DUMP_STATS]; /**< the first dumps */
    uint64_t bytes_total;
} ps_recorder_stats_t;

typedef struct {
    ps_recorder_cfg_t cfg;
    char path[PS_PATH_LEN];
    char dir[PS_PATH_LEN];
    ps_rec_slot_t *slots;
    uint32_t n_slots;             /**< power of two */
    _Atomic uint64_t head;        /**< records pushed (loop thread writes) */
    _Atomic uint32_t ext_trigger; /**< PS_REC_TRIG_SIGNAL/BUTTON bits posted from outside */
    ps_ring_t trig_ring;          /**< triggers to the writer (ps_rec_trig_t), in order */
    ps_rec_trig_t trig_storage[PS_REC_TRIG_QUEUE];
    _Atomic uint32_t n_trig; /**< triggers raised (loop thread writes) */
    _Atomic uint32_t n_trig_by[PS_REC_TRIG_COUNT];
    /** the oldest record the writer may still read (its files' next, a
     *  pending dump's pre window); the loop waits on it when is_lossless */
    _Atomic uint64_t writer_needed;
    atomic_bool is_writer_running;
    uint64_t n_lossless_waits; /**< ticks the loop waited for the writer (loop thread) */
    uint8_t last_state;
    uint32_t last_cond;
    bool was_button; /**< the button read pressed last tick (a press triggers once) */
    ps_rec_truth_src_t truth;
    int64_t io_delay_ns;
    /* writer side */
    pthread_t thread;
    bool has_thread;
    atomic_bool should_stop;
    void *w;                   /**< writer-thread state (rt/ps_recorder.c) */
    ps_recorder_stats_t stats; /**< final after ps_recorder_stop */
} ps_recorder_t;

/** Size the ring (ring_s * servo_hz rounded up to a power of two), allocate
 *  and touch it, check that the continuous file can be created (it is
 *  created empty now, written from start) and the flight folder exists and
 *  is writable.
 *  @return 0 | -EINVAL (neither path nor dir; pre_s/post_s outside 0..600)
 *  | -ENOMEM | -errno of the file or folder; err names it  @rt INIT */
int ps_recorder_init(ps_recorder_t *r, const ps_recorder_cfg_t *cfg, char *err, size_t err_len);

/** The truth source (before start).  @rt INIT */
void ps_recorder_set_truth(ps_recorder_t *r, ps_rec_truth_src_t src);

/** The loop's tap: fill the next slot from the loop's state, raise
 *  triggers.  @rt RT-SAFE O(joints + buses), loop thread; with
 *  cfg.is_lossless it may first sleep until the writer catches up */
void ps_recorder_on_tick(void *ctx, const ps_loop_t *loop);

/** Ask for a flight dump now (taken by the next tick).
 *  @rt async-signal-safe, any thread */
void ps_recorder_trigger(ps_recorder_t *r, ps_rec_trigger_t cause);

/** Start the writer thread.  @return 0 | -errno  @rt INIT */
int ps_recorder_start(ps_recorder_t *r);

/** Write what is left (a dump in progress ends at the last record),
 *  close the files (summary sections, recorder metadata), join the thread,
 *  fill r->stats. Safe twice.  @rt INIT, after the loop stopped */
void ps_recorder_stop(ps_recorder_t *r);

/** Free the ring. Safe twice and on a zeroed recorder.  @rt INIT */
void ps_recorder_deinit(ps_recorder_t *r);

/** @return name of one trigger bit ("estop")  @rt any */
const char *ps_recorder_trigger_name(ps_rec_trigger_t bit);

/* ---- the ring, exposed for tests ---------------------------------------- */

/** Copy record idx out of the ring.
 *  @return 0 | -EAGAIN not written yet | -ESTALE overwritten (lost)
 *  @rt RT-SAFE, any thread but the loop's */
int ps_recorder_read(const ps_recorder_t *r, uint64_t idx, ps_rec_tick_t *out);

/** Claim the next slot for the loop to fill (stamped as being written);
 *  ps_recorder_commit publishes it.  @rt RT-SAFE, loop thread */
ps_rec_tick_t *ps_recorder_begin(ps_recorder_t *r);
void ps_recorder_commit(ps_recorder_t *r);

#endif /* PS_RECORDER_H */
