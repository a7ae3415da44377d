/*
 * ps_camera_libcamera: a camera through libcamera (libcamera-dev 0.0.3 in
 * Debian 12), as a camera port (drivers/ps_camera.h). The project's only
 * C++ lives behind this C header, in ps_camera_libcamera.cpp; no exception
 * crosses it.
 *
 * Loaded when first used: the C++ side is built as its own shared module
 * ($BUILD/libpushstep-libcamera.so, with drivers/ps_camera.c) and
 * ps_camera_libcamera_create dlopens it (ps_camera_libcamera_dl.c), so a
 * process without a libcamera camera never loads libcamera (its static
 * set-up, LTTng's threads and its crypto libraries cost some 35 ms of CPU at
 * every start, measured, and would put threads into the real-time process).
 * The module is $PUSHSTEP_LIBCAMERA_SO when that is set (only there), else
 * it is looked for next to the executable and one and two folders up
 * (build/pushstep, build/tests/hw/), then in ../lib/pushstep/ from the
 * executable (an installed layout).
 *
 * start: a CameraManager, the camera whose id equals cfg.id or whose id or
 * model name contains it (the first camera when cfg.id is empty), one
 * stream (role viewfinder) of cfg's size and pixel format with
 * PS_CAMERA_LIBCAMERA_BUFFERS buffers, the frame rate through the
 * FrameDurationLimits control where the camera has it, every buffer mapped
 * once and one request per buffer queued. A configuration libcamera would
 * have to adjust (another size or format) is refused, naming what the camera
 * offers instead: the board's intrinsics hold for one size only.
 * next: the oldest completed request (libcamera's thread hands it over
 * through a mutex and condition variable, never the loop); t_ns and
 * t_mono_ns are the SensorTimestamp (CLOCK_MONOTONIC: the start of the
 * exposure), else the buffer's timestamp. release: the request is reused and
 * queued again (buffers reused, no allocation per frame).
 *
 * Threads: create, destroy on the main thread; the port on one thread (the
 * perception thread); libcamera's own threads inside. Allocation: libcamera
 * allocates in start (and in its threads); nothing per frame on our side.
 */
#ifndef PS_CAMERA_LIBCAMERA_H
#define PS_CAMERA_LIBCAMERA_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

#include "ps_camera.h" /* C declarations, also for the C++ side */

#define PS_CAMERA_LIBCAMERA_BUFFERS 4u

typedef struct ps_camera_libcamera ps_camera_libcamera_t;

/** Loads the module (once per process), then makes the camera. Also sets
 *  LIBCAMERA_LOG_LEVELS to "*:ERROR" unless it is set: libcamera's info and
 *  warning lines stay off the runtime's output.
 *  @pre cfg->source is libcamera  @post *out owned by the caller; err holds
 *  one line on failure  @return 0 | -EINVAL | -ENOMEM | -ENOENT (the module
 *  is not found or does not load; err says where it looked)  @rt INIT */
int ps_camera_libcamera_create(const ps_camera_cfg_t *cfg, ps_camera_libcamera_t **out, char *err,
                               size_t err_len);

/** @return the port. start: 0 | -ENODEV (no such camera; err lists the
 *  cameras there are) | -EBUSY (acquired elsewhere) | -EINVAL (the stream
 *  cannot be had as configured; err says what the camera offers) | -EIO
 *  @rt INIT */
ps_camera_port_t ps_camera_libcamera_port(ps_camera_libcamera_t *c);

/** Frames that completed with an error or were cancelled (counted, not
 *  delivered).  @rt any */
unsigned long ps_camera_libcamera_n_bad_frames(const ps_camera_libcamera_t *c);

/** Safe on NULL; stops the port first if it runs.  @rt INIT */
void ps_camera_libcamera_destroy(ps_camera_libcamera_t *c);

/* What the module exports (ps_camera_libcamera.cpp), found with dlsym by the
 * functions above; call those. Same contracts. */
int ps_camera_libcamera_impl_create(const ps_camera_cfg_t *cfg, ps_camera_libcamera_t **out);
ps_camera_port_t ps_camera_libcamera_impl_port(ps_camera_libcamera_t *c);
unsigned long ps_camera_libcamera_impl_n_bad_frames(const ps_camera_libcamera_t *c);
void ps_camera_libcamera_impl_destroy(ps_camera_libcamera_t *c);

#ifdef __cplusplus
}
#endif

#endif /* PS_CAMERA_LIBCAMERA_H */
