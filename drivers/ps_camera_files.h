/*
 * ps_camera_files: a camera source that plays a folder of still images
 * (PNG through libpng's simplified API, any colour type, read as grey; PGM
 * and PPM through libapriltag-utils' PNM reader), in file-name order
 * (alphasort), at the configured frame rate, over and over or once.
 * For tests, benchmarks and looking at recorded pictures with
 * `pushstep camera`. Every image must have the configured size.
 *
 * All images are read and decoded at start (up to PS_CAMERA_FILES_MAX
 * images), so a frame costs nothing but the wait for its slot: the
 * detection latency measured on this source is the pipeline's alone. A
 * frame's t_ns comes from the clock given (the loop's), t_mono_ns from
 * CLOCK_MONOTONIC, both read when the frame is handed out.
 *
 * Threads: the perception thread. Allocation: in start (the images).
 */
#ifndef PS_CAMERA_FILES_H
#define PS_CAMERA_FILES_H

#include <stdbool.h>
#include <stdint.h>

#include "../rt/ps_clock.h"
#include "ps_camera.h"

#define PS_CAMERA_FILES_MAX 1024u

typedef struct {
    ps_camera_cfg_t cfg;
    const ps_clock_t *clock; /**< stamps t_ns; NULL: CLOCK_MONOTONIC */
    bool is_looping;         /**< after the last image start over (else -ENODATA) */
    uint8_t *pixels;         /**< n_images * width * height, grey */
    uint32_t n_images;
    uint64_t n_delivered;
    int64_t next_due_ns; /**< CLOCK_MONOTONIC */
    int64_t period_ns;
} ps_camera_files_t;

/** @pre cfg->dir, width, height, fps set  @post f ready for its port's start
 *  @rt INIT */
void ps_camera_files_init(ps_camera_files_t *f, const ps_camera_cfg_t *cfg,
                          const ps_clock_t *clock, bool is_looping);

/** @return the port; start reads the folder: 0 | -ENOENT (no folder, or no
 *  .png/.pgm/.ppm in it) | -PS_ERR_CONFIG (an image that does not decode, or
 *  not of the configured size; err names the file) | -ENOMEM  @rt INIT */
ps_camera_port_t ps_camera_files_port(ps_camera_files_t *f);

#endif /* PS_CAMERA_FILES_H */
