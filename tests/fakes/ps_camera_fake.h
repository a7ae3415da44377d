/*
 * Test doubles for the camera port (drivers/ps_camera.h):
 *
 * - ps_tag_image_render: draws a tag36h11 tag into an 8-bit grey image at a
 *   known pose, by casting each pixel's rays (3 x 3 per pixel, so edges are
 *   anti-aliased as a lens would) onto the tag's plane. The ground truth for
 *   the detection tests: stored images are synthesised, not captured.
 * - ps_camera_fake: a source that hands out the frames a test queued (one
 *   buffer each, never copied), with scripted errors, counting releases.
 *
 * Threads: the caller's. Allocation: render allocates (libapriltag's tag
 * image) and frees before returning; the fake never allocates.
 */
#ifndef PS_CAMERA_FAKE_H
#define PS_CAMERA_FAKE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "../../drivers/ps_camera.h"

/** A tag's pose in the camera's optical frame (x right, y down, z forward):
 *  centre position and rotation (columns: the tag's x right, y down and z
 *  into the tag, as libapriltag's tag frame). */
typedef struct {
    int id;
    double size_m; /**< edge of the black square */
    double pos_cam_m[3];
    double r_cam_tag[3][3];
} ps_tag_pose_t;

/** Rotation of a tag facing the camera, then turned by yaw about the
 *  camera's y axis (down) and pitched by pitch about its x axis. */
void ps_tag_pose_turned(ps_tag_pose_t *p, double yaw_rad, double pitch_rad);

/** Fill img (w x h, stride w) with a background (grey level bg plus a fixed
 *  pattern), then draw each tag. Noise: uniform in [-noise, +noise] grey
 *  levels from a fixed seed. @return 0 | -ENOMEM */
int ps_tag_image_render(uint8_t *img, uint32_t w, uint32_t h, const ps_camera_intrinsics_t *k,
                        const ps_tag_pose_t *tags, uint32_t n_tags, uint8_t bg, int noise,
                        uint32_t seed);

#define PS_CAMERA_FAKE_MAX_FRAMES 16u

typedef struct {
    ps_camera_frame_t frames[PS_CAMERA_FAKE_MAX_FRAMES];
    uint32_t n_frames;      /**< queued */
    uint32_t next_idx;      /**< next one handed out; wraps when is_looping */
    bool is_looping;        /**< start over after the last (else -ENODATA) */
    int start_rc;           /**< what start returns */
    int64_t frame_gap_ns;   /**< next sleeps this long before each frame (0: none) */
    int64_t t_step_ns;      /**< added to each frame's t_ns and t_mono_ns per lap */
    /* counters */
    uint32_t n_started, n_stopped, n_next, n_released, n_outstanding_max;
    uint32_t n_outstanding;
} ps_camera_fake_t;

/** @return a port over f  @rt any */
ps_camera_port_t ps_camera_fake_port(ps_camera_fake_t *f);

#endif /* PS_CAMERA_FAKE_H */
