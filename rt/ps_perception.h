/*
 * ps_perception: camera perception beside the loop, off its real-time path.
 *
 * A non-real-time thread takes frames from a camera port (drivers/ps_camera.h:
 * libcamera, an image folder, or the simulated camera), converts each to grey,
 * finds the AprilTags worn on the neighbours' shoulders (drivers/ps_tags.h)
 * and publishes the neighbour list into a latest-wins mailbox
 * (rt/ps_mailbox.h). The loop reads the mailbox once a tick with
 * ps_perception_take, which ages the list and falls back to "no neighbour
 * information" (is_valid false, no shoulders) when it is older than
 * max_age_s or when none came yet. The loop never calls into the camera and
 * never waits for this thread; this thread never waits for the loop.
 *
 * Latency (stats.latency): from the frame's exposure (t_mono_ns, CLOCK_MONOTONIC)
 * to the publish into the mailbox. Ages are on the loop's clock (t_ns).
 *
 * Threads: init/start/stop/deinit on the main thread; the perception thread
 * inside; ps_perception_take on the loop thread (the mailbox's only reader);
 * get_stats and snapshot from any other thread (a mutex the loop never
 * touches). Allocation: at init (grey image, detector) and start (the
 * camera's buffers); libapriltag allocates on the perception thread per frame.
 */
#ifndef PS_PERCEPTION_H
#define PS_PERCEPTION_H

#include <pthread.h>
#include <semaphore.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdint.h>

#include "../drivers/ps_camera.h"
#include "../drivers/ps_tags.h"
#include "ps_limits.h"
#include "ps_mailbox.h"
#include "ps_neighbours.h"
#include "ps_perf.h"

/** The board file's `camera:` section. */
typedef struct {
    ps_camera_cfg_t camera;
    ps_tags_cfg_t tags;
    float max_age_s; /**< a list older than this is no neighbour information */
} ps_perception_cfg_t;

typedef struct {
    uint64_t n_frames;     /**< frames taken from the camera */
    uint64_t n_tags;       /**< tags detected (after the margin filter) */
    uint64_t n_published;  /**< neighbour lists published (one per frame) */
    uint64_t n_left_out;   /**< shoulders that did not fit a list */
    uint64_t n_timeouts;   /**< waits for a frame that timed out */
    uint64_t n_errors;     /**< camera or detector errors, frames of the wrong size */
    int64_t t_first_mono_ns, t_last_mono_ns; /**< first and last publish */
    ps_perf_hist_t latency; /**< exposure to mailbox */
    ps_perf_hist_t detect;  /**< grey conversion and detection */
} ps_perception_stats_t;

typedef struct {
    ps_perception_cfg_t cfg;
    ps_camera_port_t port;
    ps_tags_t *tags;
    uint8_t *grey; /**< width * height */
    ps_mailbox_t mailbox;
    ps_neighbours_t mailbox_slots[PS_MAILBOX_SLOTS];
    pthread_t thread;
    bool is_thread;
    atomic_bool is_running;
    sem_t started;
    bool has_sem;
    int start_rc;
    char start_err[PS_ERR_MSG_LEN];
    int cpu;
    pthread_mutex_t mu; /**< stats and snapshot (never the loop) */
    bool has_mutex;
    ps_perception_stats_t stats;
    bool is_snapshot_kept;
    uint8_t *snap_grey;
    ps_tags_det_t snap_det[PS_TAGS_MAX_DETECTIONS];
    uint32_t n_snap_det;
    uint64_t snap_seq;
    bool has_snap;
    atomic_bool has_ended; /**< the source said it has no more frames */
} ps_perception_t;

/** Set up (no thread yet): the detector, the grey image, the mailbox.
 *  keep_snapshot: also keep the newest frame and its detections for
 *  ps_perception_snapshot (`pushstep camera`).
 *  @pre cfg from the loader, port valid  @return 0 | -EINVAL | -ENOMEM
 *  @rt INIT */
int ps_perception_init(ps_perception_t *p, const ps_perception_cfg_t *cfg,
                       ps_camera_port_t port, bool keep_snapshot, char *err, size_t err_len);

/** Start the thread on cpu (-1: any; SCHED_OTHER) and wait until it has
 *  started the camera. @post the camera streams  @return 0 | the camera's
 *  start error (err says why) | -errno (pthread)  @rt INIT */
int ps_perception_start(ps_perception_t *p, int cpu, char *err, size_t err_len);

/** Stop the thread (it finishes the frame under way) and the camera.
 *  Safe twice and without start.  @rt INIT */
void ps_perception_stop(ps_perception_t *p);

/** The mailbox the loop reads.  @rt any */
ps_mailbox_t *ps_perception_mailbox(ps_perception_t *p);

/** Take the newest list into *inout when there is one, and age it at now_ns:
 *  inout->age_ns = now_ns - t_exposure_ns; a list from the future counts as
 *  age 0. is_valid when a list was ever taken and its age is at most
 *  max_age_ns; otherwise the list is emptied (n_shoulders 0: no neighbour
 *  information) while t_exposure_ns and frame_seq stay as they were. A new
 *  list that is not sane (more than PS_MAX_SHOULDERS, a non-finite position,
 *  a confidence outside 0..1, a side that is neither, an exposure more than
 *  max_age_ns in the future) is refused: t_exposure_ns 0, not valid, until
 *  a sane one comes.
 *  @return true when a new list was taken this call
 *  @rt RT-SAFE O(list), wait-free, the mailbox's reader thread (the loop) */
bool ps_perception_take(ps_mailbox_t *mb, int64_t now_ns, int64_t max_age_ns,
                        ps_neighbours_t *inout);

/** @post *out = a copy of the statistics  @rt NON-RT, any thread but the loop */
void ps_perception_get_stats(ps_perception_t *p, ps_perception_stats_t *out);

/** The newest frame (grey, width * height bytes into grey) and its
 *  detections (keep_snapshot only). @return detections copied | -ENODATA
 *  none yet | -EINVAL  @rt NON-RT, any thread but the loop */
int ps_perception_snapshot(ps_perception_t *p, uint8_t *grey, size_t grey_len,
                           ps_tags_det_t *det, uint32_t max, uint64_t *out_seq);

/** @return true once the source has no more frames (an image folder played
 *  once)  @rt any */
bool ps_perception_has_ended(ps_perception_t *p);

/** Stop, then free everything. Safe twice and on a zeroed or half-initialised
 *  struct.  @rt INIT */
void ps_perception_deinit(ps_perception_t *p);

#endif /* PS_PERCEPTION_H */
