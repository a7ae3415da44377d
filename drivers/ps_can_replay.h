/*
 * ps_can_replay: CAN ports (drivers/ps_can.h) fed from a candump -L log, and
 * the clock that paces them, for offline analysis and regression tests
 * (`pushstep --replay FILE`).
 *
 * A log of a bus holds both directions: what the drives and the IMU sent and
 * what the host sent (a `pushstep --candump` log, or candump on a live bus).
 * Each frame is classified by the robot's configuration:
 *   fed       a reply some joint's protocol matches (match_reply) on that
 *             bus, or one of the IMU's frames (11-bit ids the caller lists,
 *             e.g. from ps_imu_frames) on its bus: the frames the loop would
 *             receive, handed to it by recv_batch;
 *   expected  a frame some joint's drive accepts (is_for_drive): a command
 *             or mode request of the host, kept to compare with what the loop
 *             sends;
 *   unknown   anything else: counted and skipped.
 * Replies are tried before drive frames, as the loop does.
 *
 * Time: the replay clock (ps_can_replay_clock) starts at the earliest frame
 * time of the log rounded down to a tick (period_ns; at least one period, as
 * time 0 means "never" to the loop) and moves only when the loop sleeps:
 * sleep_until jumps to the deadline. So the loop runs unpaced and
 * deterministic, as in lockstep, on the log's own time base. recv_batch
 * hands over, per bus and in file order, the fed frames whose logged t_ns is
 * at or before the clock's now, with their logged t_ns; a frame not yet due
 * holds back the frames after it on that bus.
 *
 * Comparison: send_batch accepts every frame (the count is its return) and
 * looks for each one among the expected frames of that bus logged within
 * match_window_ns of now, with the same identifier and kind, oldest first and
 * each logged frame used once. A match is decoded with that joint's
 * protocol, both sides, and the difference of each command field (q, qd, kp,
 * kd, tau_ff, joint side) is kept as its largest value, in joint units and in
 * wire steps (ps_act_joint_lsb); a request is compared by kind.
 *
 * Limits: the plant is absent. The loop's commands do not change the
 * replies, so this is for the loop's response to recorded sensor data, not a
 * closed loop. There are no bus errors: get_state is error-active, with the
 * frame counts and no bit times (load 0).
 *
 * Threads: init, measure and stats on the main thread; the ports and the
 * clock on the loop thread (the clock's now_ns from any thread). The ports'
 * ops are RT-SAFE: recv_batch is O(frames handed over), send_batch O(frames
 * logged within the window) per frame sent, and neither allocates, locks or
 * does I/O. Allocation: none: the caller provides the entry and payload
 * storage, sized with ps_can_replay_measure (the file is read twice).
 */
#ifndef PS_CAN_REPLAY_H
#define PS_CAN_REPLAY_H

#include <stdatomic.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "../rt/ps_clock.h"
#include "../rt/ps_limits.h"
#include "ps_actuator.h"
#include "ps_can.h"
#include "ps_gpio.h"

#define PS_CAN_REPLAY_NONE        UINT32_MAX /**< end of an entry list */
#define PS_CAN_REPLAY_MAX_IMU_IDS 8u         /**< frames of one IMU sample, any protocol */

/** Command fields compared, in the order of ps_act_joint_lsb. */
enum {
    PS_CAN_REPLAY_Q = 0,
    PS_CAN_REPLAY_QD,
    PS_CAN_REPLAY_KP,
    PS_CAN_REPLAY_KD,
    PS_CAN_REPLAY_TAU,
    PS_CAN_REPLAY_N_FIELDS
};

typedef enum {
    PS_CAN_REPLAY_FED = 0,  /**< a reply or IMU frame: handed to the loop */
    PS_CAN_REPLAY_EXPECTED, /**< a host command or request: compared */
    PS_CAN_REPLAY_UNKNOWN,  /**< neither: counted, skipped */
} ps_can_replay_role_t;

typedef struct {
    const char *path;                            /**< the candump -L log */
    uint32_t n_buses;                            /**< 1..PS_MAX_BUSES */
    const char *ifname[PS_MAX_BUSES];            /**< the board's bus names; a log line's
                                                      interface must be one of them */
    const ps_act_cfg_t *act;                     /**< the robot's joints (n_joints entries) */
    uint32_t n_joints;                           /**< 0..PS_MAX_JOINTS */
    uint32_t imu_bus_idx;                        /**< the IMU's bus */
    uint32_t n_imu_ids;                          /**< 0 (no IMU)..PS_CAN_REPLAY_MAX_IMU_IDS */
    uint32_t imu_ids[PS_CAN_REPLAY_MAX_IMU_IDS]; /**< 11-bit ids of the IMU's frames */
    int64_t period_ns;                           /**< the loop's tick, > 0 */
    int64_t match_window_ns; /**< |logged - now| a command may differ by; 0: period_ns */
} ps_can_replay_cfg_t;

/** One fed or expected frame of the log, compact (the payload lives in the
 *  data pool). Read-only outside the module. */
typedef struct {
    int64_t t_ns;
    uint32_t id;
    uint32_t next_idx; /**< next entry of the same bus and role; PS_CAN_REPLAY_NONE */
    uint32_t data_off; /**< payload offset in the data pool */
    uint8_t len;
    uint8_t flags; /**< bit 0 ext, 1 FD, 2 BRS */
    uint8_t bus_idx;
    uint8_t joint_idx;  /**< expected: the joint its drive is; fed: 0 */
    uint8_t is_matched; /**< expected: a sent frame matched it */
    uint8_t pad[7];
} ps_can_replay_entry_t;

/** Storage a log needs: ps_can_replay_measure. */
typedef struct {
    size_t n_entries; /**< fed and expected frames */
    size_t n_data;    /**< their payload bytes */
    uint64_t n_lines; /**< lines of the file */
} ps_can_replay_size_t;

/** What a replay did, for the end-of-run report. */
typedef struct {
    uint64_t n_lines;
    uint64_t n_fed;          /**< frames handed to the loop */
    uint64_t n_fed_logged;   /**< fed frames in the log */
    uint32_t n_buses_fed;    /**< buses that handed over at least one frame */
    uint64_t n_sent;         /**< frames the loop sent (all accepted) */
    uint64_t n_expected;     /**< host frames in the log */
    uint64_t n_unknown;      /**< frames neither fed nor expected */
    uint64_t n_matched;      /**< sent frames paired with a logged one */
    uint64_t n_unmatched;    /**< sent frames with no logged one in the window */
    uint64_t n_differ;       /**< matched pairs of different kind (a request against a
                                  command, other requests) or that do not decode */
    uint64_t n_cmd_compared; /**< matched command pairs whose fields were compared */
    float max_diff[PS_CAN_REPLAY_N_FIELDS];     /**< largest |sent - logged|, joint units */
    float max_diff_lsb[PS_CAN_REPLAY_N_FIELDS]; /**< the same in wire steps of the joint */
    int64_t first_ns, last_ns;                  /**< earliest and latest frame time of the log */
} ps_can_replay_stats_t;

typedef struct ps_can_replay ps_can_replay_t;

/** One bus: the port's context. Internal; read-only. */
typedef struct {
    ps_can_replay_t *owner;
    uint32_t bus_idx;
    uint32_t fed_idx;      /**< next fed entry to hand over */
    uint32_t fed_tail_idx; /**< (init) last fed entry linked */
    uint32_t exp_idx;      /**< oldest expected entry still in the window */
    uint32_t exp_tail_idx; /**< (init) last expected entry linked */
    uint64_t n_fed, n_sent;
} ps_can_replay_bus_t;

struct ps_can_replay {
    ps_can_replay_cfg_t cfg;
    ps_can_replay_entry_t *entries;
    uint8_t *data;
    size_t n_entries, max_entries, n_data, max_data;
    ps_can_replay_bus_t bus[PS_MAX_BUSES];
    _Atomic int64_t now_ns;
    int64_t start_ns;
    ps_clock_t clock;
    ps_can_replay_stats_t stats;
};

/** Which role a frame of bus bus_idx plays (see the module comment).
 *  @post *out_joint_idx: the joint for a reply or a drive frame, else untouched
 *  @return its role  @rt RT-SAFE O(n_joints), any thread */
ps_can_replay_role_t ps_can_replay_classify(const ps_can_replay_cfg_t *cfg, uint32_t bus_idx,
                                            const ps_can_frame_t *f, uint32_t *out_joint_idx);

/** Read the whole log for the storage it needs (every line is parsed and
 *  checked as by ps_can_replay_init).
 *  @pre cfg valid  @post *out written on success
 *  @return 0 | -ENOENT and others: the file cannot be read ("path: why" in err)
 *  | -PS_ERR_PROTOCOL a line that does not parse ("path:line:column: what") or
 *  is too long ("path:line: ...") | -PS_ERR_CONFIG an interface that is not a
 *  bus of the board ("path:line: ..."), an empty log | -EINVAL a bad cfg
 *  @rt INIT (file I/O), main thread */
int ps_can_replay_measure(const ps_can_replay_cfg_t *cfg, ps_can_replay_size_t *out, char *err,
                          size_t err_len);

/** Read and classify the whole log into the caller's storage; the clock
 *  starts at the log's start (ps_can_replay_start_ns).
 *  @pre entries and data at least as large as ps_can_replay_measure said
 *  (n_data may be 0 with data NULL for a log of empty payloads); the
 *  strings and the act array cfg points to outlive r; r not in use
 *  @post r ready; its ports and clock valid until r is reused
 *  @return 0 | as ps_can_replay_measure | -ENOSPC the storage is too small
 *  (the file changed since it was measured)  @rt INIT, main thread */
int ps_can_replay_init(ps_can_replay_t *r, const ps_can_replay_cfg_t *cfg,
                       ps_can_replay_entry_t *entries, size_t max_entries, uint8_t *data,
                       size_t max_data, char *err, size_t err_len);

/** @pre init ok, bus_idx < cfg.n_buses  @return the port of one bus, named as
 *  the board names it  @rt INIT */
ps_can_port_t ps_can_replay_port(ps_can_replay_t *r, uint32_t bus_idx);

/** @pre init ok  @return the replay clock (see the module comment)  @rt INIT */
const ps_clock_t *ps_can_replay_clock(ps_can_replay_t *r);

/** @return the clock's first time: the earliest frame time rounded down to
 *  a tick, at least one tick  @units ns  @rt RT-SAFE */
int64_t ps_can_replay_start_ns(const ps_can_replay_t *r);

/** @return the latest frame time of the log  @units ns  @rt RT-SAFE */
int64_t ps_can_replay_last_ns(const ps_can_replay_t *r);

/** @post *out: the counts and comparison so far  @rt NON-RT, after the loop
 *  (reads the loop thread's counters) */
void ps_can_replay_get_stats(const ps_can_replay_t *r, ps_can_replay_stats_t *out);

/** A GPIO port for runs without GPIO lines (replay): the e-stop is never
 *  pressed, the heartbeat and LED outputs are ignored.
 *  @return a port of static, stateless ops  @rt INIT */
ps_gpio_port_t ps_can_replay_gpio_port(void);

/** Forget the storage (the caller frees it). Safe twice and on a zeroed r.
 *  @rt INIT */
void ps_can_replay_deinit(ps_can_replay_t *r);

#endif /* PS_CAN_REPLAY_H */
