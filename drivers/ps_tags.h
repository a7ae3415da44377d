/*
 * ps_tags: neighbours' shoulders from AprilTag markers (libapriltag-dev,
 * family tag36h11). Finds the tags in an 8-bit grey image, estimates each
 * tag's pose from the camera's intrinsics and the tag's size
 * (estimate_tag_pose: homography, then orthogonal iteration), and moves the
 * tag's centre into the robot frame with the camera's pose on the robot.
 * Why AprilTags: docs/perception.md (known ids name the person and the side,
 * metric pose from one monocular frame, a maintained detector in Debian, a
 * few milliseconds per VGA frame on one core).
 *
 * Frames: the camera's optical frame is AprilTag's (x right, y down, z along
 * the optical axis). Its pose on the robot is given as a position and
 * roll/pitch/yaw of a "camera body" frame whose x is the optical axis, y
 * left and z up, relative to the robot (pelvis) frame; R = Rz(yaw) Ry(pitch)
 * Rx(roll), so pitch > 0 looks down. Tag ids: rt/ps_neighbours.h.
 *
 * Threads: one thread per detector (the perception thread); libapriltag runs
 * its own worker threads when n_threads > 1. Allocation: libapriltag
 * allocates at create and inside every detect call (NON-RT only).
 */
#ifndef PS_TAGS_H
#define PS_TAGS_H

#include <stddef.h>
#include <stdint.h>

#include "../rt/ps_neighbours.h"
#include "ps_camera.h"

/** Decision margin at which a detection's confidence reaches 1 (a clean,
 *  sharp tag gives 100..250; a blurred or noisy one 20..60). */
#define PS_TAGS_MARGIN_FULL 80.0f
/** Most detections one frame returns. */
#define PS_TAGS_MAX_DETECTIONS 64u

typedef struct {
    ps_camera_intrinsics_t k;
    float cam_pos_m[3];   /**< optical centre in the robot frame */
    float cam_rpy_rad[3]; /**< camera body frame (x optical axis, y left, z up) */
    float tag_size_m;     /**< edge of the tag's black square (tag36h11: 8 of its 10 cells) */
    uint32_t n_threads;   /**< libapriltag worker threads, >= 1 */
    float decimate;       /**< libapriltag quad_decimate, >= 1 (faster, shorter range) */
    float min_margin;     /**< detections below this decision margin are dropped */
} ps_tags_cfg_t;

typedef struct {
    int id;
    int hamming;          /**< bits corrected */
    float margin;         /**< libapriltag's decision margin */
    float centre_px[2];
    float corners_px[4][2];
    float pos_cam_m[3];   /**< tag centre, optical frame */
    float pos_robot_m[3]; /**< tag centre, robot frame */
    float pose_err;       /**< estimate_tag_pose's object-space error, m^2 */
    float confidence;     /**< 0..1: min(1, margin / PS_TAGS_MARGIN_FULL) / (1 + hamming) */
} ps_tags_det_t;

typedef struct ps_tags ps_tags_t;

/** @pre cfg valid (the loader's ranges)  @post *out owned by the caller
 *  @return 0 | -EINVAL (NULL, a size or focal length <= 0, n_threads 0,
 *  decimate < 1) | -ENOMEM  @rt NON-RT */
int ps_tags_create(const ps_tags_cfg_t *cfg, ps_tags_t **out, char *err, size_t err_len);

/** Detect tags in a grey image (width x height, rows stride bytes apart).
 *  @post out[0..n) sorted by id  @return n (0..max) | -EINVAL | -ENOMEM
 *  @rt NON-RT O(pixels), allocates (libapriltag) */
int ps_tags_detect(ps_tags_t *t, const uint8_t *grey, uint32_t width, uint32_t height,
                   uint32_t stride, ps_tags_det_t *out, uint32_t max);

/** The neighbour list of a frame's detections (ids beyond 2 * 65535 and
 *  shoulders beyond PS_MAX_SHOULDERS are left out, counted in the return).
 *  @post out->n_shoulders, shoulders[], t_exposure_ns, frame_seq written;
 *  is_valid and age_ns zero (the loop sets them)  @return shoulders left out
 *  @rt RT-SAFE O(n) */
uint32_t ps_tags_to_neighbours(const ps_tags_det_t *det, uint32_t n, int64_t t_exposure_ns,
                               uint64_t frame_seq, ps_neighbours_t *out);

/** A point from the optical frame to the robot frame with cfg's pose.
 *  @rt RT-SAFE */
void ps_tags_cam_to_robot(const ps_tags_cfg_t *cfg, const double p_cam[3], double out_robot[3]);

/** Safe on NULL.  @rt NON-RT */
void ps_tags_destroy(ps_tags_t *t);

#endif /* PS_TAGS_H */
