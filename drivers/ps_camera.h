/*
 * ps_camera: the camera port. A source delivers frames one at a time to the
 * perception thread (rt/ps_perception), never to the loop. Sources:
 *   - libcamera (drivers/ps_camera_libcamera.h, the project's only C++),
 *   - a folder of PNG/PGM images (drivers/ps_camera_files.h),
 *   - the simulated camera rendering the MuJoCo scene (sim/ps_camera_sim.h),
 *   - a fake in the tests (tests/fakes/ps_camera_fake.c).
 * The board file's `camera:` section picks one (docs/config.md).
 *
 * A frame stays valid until it is released; a source reuses its buffers
 * (no allocation per frame). Pixel formats carry libcamera's names, which
 * are DRM fourcc names: multi-byte pixels are little-endian words, so
 * RGB888 is stored B, G, R in memory and BGR888 is R, G, B.
 *
 * Also here: the configuration each source consumes, the camera's intrinsics
 * and the conversion of any supported format to the 8-bit grey image the
 * detector works on.
 *
 * Threads: a port is used by one thread (the perception thread), from start
 * to stop. Allocation: sources allocate in start only.
 */
#ifndef PS_CAMERA_H
#define PS_CAMERA_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "../rt/ps_limits.h"

#define PS_CAMERA_MAX_WIDTH  4096u
#define PS_CAMERA_MAX_HEIGHT 4096u

typedef enum {
    PS_CAMERA_SRC_LIBCAMERA = 0, /**< a camera through libcamera */
    PS_CAMERA_SRC_FILES,         /**< a folder of PNG/PGM images, played in name order */
    PS_CAMERA_SRC_SIM,           /**< the simulated camera (board sim only) */
    PS_CAMERA_SRC_COUNT
} ps_camera_source_t;

typedef enum {
    PS_PIX_R8 = 0,   /**< 8-bit grey (libcamera R8) */
    PS_PIX_YUV420,   /**< planar Y, then U and V at half size; the Y plane is used */
    PS_PIX_NV12,     /**< Y plane, then interleaved UV; the Y plane is used */
    PS_PIX_RGB888,   /**< 3 bytes a pixel, B G R in memory */
    PS_PIX_BGR888,   /**< 3 bytes a pixel, R G B in memory */
    PS_PIX_XRGB8888, /**< 4 bytes a pixel, B G R X in memory */
    PS_PIX_COUNT
} ps_camera_format_t;

/** Pinhole intrinsics of the delivered image. Pixel coordinates as
 *  AprilTag's: x right, y down, the centre of the top-left pixel at (0.5, 0.5),
 *  so the centre of a W x H image is (W/2, H/2). */
typedef struct {
    float fx_px, fy_px; /**< focal lengths */
    float cx_px, cy_px; /**< principal point */
} ps_camera_intrinsics_t;

/** The stream a source is asked for (board file `camera:`). */
typedef struct {
    ps_camera_source_t source;
    char id[PS_PATH_LEN];  /**< libcamera: camera id, or a part of its model name;
                                empty: the first camera */
    char dir[PS_PATH_LEN]; /**< files: the image folder (resolved by the loader) */
    uint32_t width, height;
    ps_camera_format_t format; /**< libcamera: the stream's format; files and sim
                                    deliver R8 and BGR888 of their own */
    float fps;                 /**< frame rate asked for (files, sim: paced at it) */
} ps_camera_cfg_t;

/** One frame. data points at the first plane (the only one used). */
typedef struct {
    const uint8_t *data;
    size_t n_bytes; /**< bytes readable from data */
    uint32_t width, height;
    uint32_t stride; /**< bytes per row of the first plane */
    ps_camera_format_t format;
    int64_t t_ns;      /**< exposure, on the loop's clock (simulated on board sim) */
    int64_t t_mono_ns; /**< exposure, CLOCK_MONOTONIC (for latency figures) */
    uint64_t seq;      /**< the source's frame number */
    uint32_t buf_idx;  /**< the source's own, for release */
} ps_camera_frame_t;

typedef struct {
    /** Open and start streaming. Called on the thread that will call next.
     *  @post err holds one line on failure  @return 0 | -errno | -PS_ERR_*
     *  @rt NON-RT (allocates, may block) */
    int (*start)(void *ctx, char *err, size_t err_len);
    /** Wait up to timeout_ns for the next frame.
     *  @post *out valid until release  @return 0 | -ETIMEDOUT | -ENODATA (the
     *  source has no more frames) | -EIO  @rt NON-RT */
    int (*next)(void *ctx, ps_camera_frame_t *out, int64_t timeout_ns);
    /** Give a frame's buffer back.  @rt NON-RT */
    void (*release)(void *ctx, const ps_camera_frame_t *f);
    /** Stop streaming and free what start took. Safe after a failed start
     *  and twice.  @rt NON-RT */
    void (*stop)(void *ctx);
} ps_camera_ops_t;

typedef struct {
    const ps_camera_ops_t *ops;
    void *ctx;
} ps_camera_port_t;

/** @return libcamera's name of a format ("R8", "BGR888", ...), "?" when
 *  out of range  @rt RT-SAFE */
const char *ps_camera_format_name(ps_camera_format_t f);

/** @return the format with that name, or -ENOENT  @rt RT-SAFE */
int ps_camera_format_from_name(const char *name);

/** Bytes per pixel of a format's first plane (1 for the planar YUV ones).
 *  @rt RT-SAFE */
uint32_t ps_camera_format_bpp(ps_camera_format_t f);

/** @return the source's name in the board file ("libcamera", "files", "sim")
 *  @rt RT-SAFE */
const char *ps_camera_source_name(ps_camera_source_t s);

/** Convert a frame to 8-bit grey (BT.601 luma weights for colour; the Y plane
 *  as it is for YUV), row by row into out (width * height bytes, stride width).
 *  @return 0 | -EINVAL (a format out of range, or a frame whose stride or
 *  n_bytes cannot hold width x height)  @rt NON-RT O(pixels), no allocation */
int ps_camera_to_grey(const ps_camera_frame_t *f, uint8_t *out, size_t out_len);

#endif /* PS_CAMERA_H */
