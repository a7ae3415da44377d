/*
 * ps_render: pictures of the simulated crowd. The thread that steps the
 * plant offers the state at every frame time (ps_render_offer: a copy into
 * a small preallocated ring); a renderer thread of its own replays each
 * state (mj_forward on its own mjData), draws it with MuJoCo's renderer
 * (offscreen, sim/ps_gl.h) from a camera that follows the robot, with the
 * crowd's contact forces on the robot's parts as arrows (into the part, 1 m
 * per 500 N, yellow to red) and the parts under load tinted, and writes
 * DIR/frame_00000.png... At the end (ps_render_finish) it writes
 * DIR/density.png (the crowd's density seen from above, averaged over the
 * frames: a Gaussian of 0.3 m per person, 0 dark blue to 8 / m^2 dark red;
 * white ring: the robot at the end; black dots: the people at the end) and
 * DIR/crowd.mp4 (ffmpeg, libx264, from the PNGs). With is_view the frames
 * are also shown in a window (needs a display).
 *
 * In lockstep the plant waits for a free slot, so no frame is lost; in real
 * time a full ring drops the frame and counts it.
 *
 * Threads: create, start, finish, destroy on one thread (main); offer on the
 * plant's thread; the renderer thread owns the GL context. Allocation:
 * create and start (ring, mjData, scene, GL); offer copies only.
 */
#ifndef PS_RENDER_H
#define PS_RENDER_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

struct mjModel_;
struct mjData_;

typedef struct ps_render ps_render_t;

#define PS_RENDER_MAX_WIDTH  1920 /**< largest frame */
#define PS_RENDER_MAX_HEIGHT 1080

typedef struct {
    const char *dir;         /**< output folder (made if missing); NULL: no files */
    double fps;              /**< frames per simulated second */
    int width, height;       /**< frame size, even, 16 x 16 to PS_RENDER_MAX_* */
    bool is_view;            /**< also show frames in a window */
    bool is_lockstep;        /**< wait for the renderer rather than drop frames */
    bool is_census;          /**< count what each frame shows (tests; renders twice) */
    const char *robot_root;  /**< the robot's root body ("pelvis") */
    double area_m[4];        /**< density map: x_min, y_min, x_max, y_max */
} ps_render_cfg_t;

/** What the last frame showed (is_census): pixels of robot geoms, pixels of
 *  agents, and how many agents have a pixel. */
typedef struct {
    uint64_t n_frames;        /**< frames rendered (and written) */
    uint64_t n_dropped;       /**< frames offered while the ring was full */
    bool is_mp4;              /**< crowd.mp4 written */
    bool is_density;          /**< density.png written */
    bool was_view_closed;     /**< the user closed the window */
    uint32_t robot_px, agent_px, n_agents_seen;
} ps_render_result_t;

/** Check cfg, make the folder, bind the model (root body, agents by name
 *  "agentI_ring"), and with is_view open the window here (refused without a
 *  display). The renderer works on its own copy of m, taken here: create it
 *  before the plant's first step (the crowd switches its agents' capsule
 *  collisions in the plant's model as it steps, sim/ps_crowd.h).
 *  @return 0 | -EINVAL (cfg: err names the field) | -ENOENT (no root body)
 *          | -ENXIO (view: no display) | -EIO | -ENOMEM  @rt INIT */
int ps_render_create(const ps_render_cfg_t *cfg, const struct mjModel_ *m, ps_render_t **out,
                     char *err, size_t err_len);

/** Start the renderer thread: GL context (offscreen, or the window's),
 *  MuJoCo's scene and renderer. Returns once they are up or failed.
 *  @return 0 | -EIO (err says why: no EGL, ...) | -ENOMEM  @rt INIT */
int ps_render_start(ps_render_t *r, char *err, size_t err_len);

/** The state at a frame time, from the plant's own thread. Copies the
 *  state into a free slot (O(nq + nv + nbody)); none free: in lockstep it
 *  waits for the renderer, else it counts a drop.  @rt plant thread;
 *  allocates nothing; in real time never blocks */
void ps_render_offer(ps_render_t *r, const struct mjData_ *d);

/** Frames per simulated second (the caller offers on this grid).  @rt any */
double ps_render_fps(const ps_render_t *r);

/** Render what is left, stop the thread, write density.png and crowd.mp4.
 *  @post *out filled  @return 0 | -EIO (a write or ffmpeg failed; err says
 *  which)  @rt NON-RT, main thread */
int ps_render_finish(ps_render_t *r, ps_render_result_t *out, char *err, size_t err_len);

/** Safe on NULL; finishes first if needed.  @rt INIT */
void ps_render_destroy(ps_render_t *r);

#endif /* PS_RENDER_H */
