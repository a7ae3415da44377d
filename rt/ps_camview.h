/*
 * ps_camview: `pushstep camera`, what the camera pipeline sees. Opens the
 * board's camera (its `camera:` section: libcamera, an image folder, or on
 * board sim the simulated camera over a plant at rest) and runs the same
 * perception thread as the runtime (rt/ps_perception) for a while, with no
 * loop, buses or GPIO. Then it prints frames and detections per second, the
 * latency from exposure to mailbox and the detection time (percentiles), and
 * writes camera.png (the last frame as the detector saw it, grey, each tag's
 * outline, centre, id, side and distance drawn on it) and
 * camera.json (the same figures, and each detection). On the simulated camera
 * it also compares the last frame's detections with the plant's truth.
 *
 * Composition root (it may open the simulated plant): rt/main.c calls it.
 * Threads: main thread, the perception thread inside. Allocation: INIT/NON-RT.
 */
#ifndef PS_CAMVIEW_H
#define PS_CAMVIEW_H

#include <stddef.h>
#include <stdint.h>

#include "../drivers/ps_tags.h"

/** Draw the detections on a grey image (outline, centre, and "<id><L|R>
 *  <distance>m") and write it as an RGB PNG (libapriltag-utils' line drawing,
 *  libpng).  @return 0 | -EIO (libpng could not write; err says why) |
 *  -ENOMEM  @rt NON-RT */
int ps_camview_write_png(const char *path, const uint8_t *grey, uint32_t width, uint32_t height,
                         const ps_tags_det_t *det, uint32_t n_det, char *err, size_t err_len);

/** Parse argv (argv[0] = "camera"), run, print.
 *  @return process exit status: 0 ok, 1 runtime failure, 2 usage/config  @rt INIT */
int ps_camview_main(int argc, char **argv, const char *data_dir);

#endif /* PS_CAMVIEW_H */
