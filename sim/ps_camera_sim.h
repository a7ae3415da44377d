/*
 * ps_camera_sim: the simulated camera. A camera port (drivers/ps_camera.h)
 * that renders the MuJoCo scene offscreen (EGL on Mesa's surfaceless
 * platform: no display, no GPU needed; libegl-mesa0's software rasteriser)
 * from a camera fixed to the robot's root body (the pelvis) at the board's
 * camera pose, with the board's intrinsics (square pixels, axis through the
 * image centre: fy gives MuJoCo's vertical field of view).
 *
 * AprilTags in the scene: every texture named "tag36h11_<id>" (declare it
 * `type="2d" builtin="flat"` with any size, 80 x 80 or more) is filled with
 * that tag36h11 tag (libapriltag's apriltag_to_image, white border
 * included), so a box geom or box site wearing its material shows the tag
 * on its +z face, readable from outside. The tag's black square is 8/10 of
 * the face. The model is the sim's own (ps_sim_copy_model): the crowd's
 * people wear tags as sites (sim/ps_scene.h), a test scene adds tagged
 * bodies through the robot file's model (tests/data/models/ps1-tags.xml).
 * The OpenGL context is sim/ps_gl's offscreen one.
 *
 * Each frame renders the newest scene the sim published (ps_sim_read_scene),
 * paced at cfg.fps on CLOCK_MONOTONIC; t_ns is the scene's simulated time,
 * t_mono_ns when it was taken. Frames are BGR888 (bytes R, G, B), top row
 * first. The ground truth of the last frame rendered (every tag whose face
 * looks at the camera, in the robot frame) is kept for the tests.
 *
 * Threads: create and destroy on the main thread; the port on one thread
 * (the perception thread), which owns the GL context from start to stop;
 * truth from any thread (a mutex; never the loop). Allocation: create (the
 * model's copy, textures) and start (GL context, scene, frame buffer).
 */
#ifndef PS_CAMERA_SIM_H
#define PS_CAMERA_SIM_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "../drivers/ps_camera.h"
#include "ps_sim.h"

/** Tags the truth keeps per frame: every id of tag36h11 (587) once. */
#define PS_CAMERA_SIM_MAX_TAGS 600u

typedef struct ps_camera_sim ps_camera_sim_t;

typedef struct {
    ps_sim_t *sim;                  /**< the scene; outlives the camera */
    ps_camera_cfg_t camera;         /**< width, height, fps */
    ps_camera_intrinsics_t k;       /**< fx == fy, (cx, cy) the image centre */
    float cam_pos_m[3];             /**< optical centre in the robot (root body) frame */
    float cam_rpy_rad[3];           /**< camera body frame: x optical axis, y left, z up */
    const char *root_body;          /**< the robot's root body, "pelvis" */
} ps_camera_sim_cfg_t;

/** One tag of the scene at a frame. */
typedef struct {
    int id;
    double pos_robot_m[3]; /**< centre of its face, robot (root body) frame */
    double pos_cam_m[3];   /**< the same in the optical frame (x right, y down, z ahead) */
    bool is_facing;        /**< the face looks at the camera (its normal toward it) */
    bool is_in_view;       /**< the plate's corners (the whole face: the detector needs
                                the white border around the black square) project
                                inside the image (2 px in), in front of the camera */
    bool is_unoccluded;    /**< rays from the camera to the face's centre, corners and
                                edge midpoints meet this tag first (mj_ray, and the
                                site plates one by one); only worked out for a tag
                                facing the camera in view, false otherwise */
    double size_px;        /**< longest projected edge of the black square (in view) */
    double slant_rad;      /**< angle between the face's normal and the line of sight */
} ps_camera_sim_tag_t;

/** Copy the model, find the root body and the tag textures and fill them.
 *  @return 0 | -EINVAL (a NULL, fx != fy, a size of 0, or more textures than
 *  MuJoCo 2.2.2 can draw, PS_SCENE_MAX_TEXTURES) | -ENOENT (no root
 *  body) | -ENOMEM  @rt INIT */
int ps_camera_sim_create(const ps_camera_sim_cfg_t *cfg, ps_camera_sim_t **out, char *err,
                         size_t err_len);

/** @return the port (start: the EGL context and MuJoCo's renderer on the
 *  calling thread; -EIO with err when EGL or OpenGL cannot be had)  @rt INIT */
ps_camera_port_t ps_camera_sim_port(ps_camera_sim_t *c);

/** @return the number of tags in the model (textures found)  @rt any */
uint32_t ps_camera_sim_n_tags(const ps_camera_sim_t *c);

/** The truth of the last frame rendered. @post out[0..n) by id
 *  @return n | -ENODATA no frame yet  @rt NON-RT, any thread but the loop */
int ps_camera_sim_truth(ps_camera_sim_t *c, ps_camera_sim_tag_t *out, uint32_t max,
                        uint64_t *out_frame_seq);

/** Safe on NULL; the port must be stopped.  @rt INIT */
void ps_camera_sim_destroy(ps_camera_sim_t *c);

#endif /* PS_CAMERA_SIM_H */
