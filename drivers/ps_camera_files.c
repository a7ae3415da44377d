#include "ps_camera_files.h"

#include <dirent.h>
#include <errno.h>
#include <png.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <time.h>

#include <apriltag/common/image_u8.h>

#include "../rt/ps_err.h"

void ps_camera_files_init(ps_camera_files_t *f, const ps_camera_cfg_t *cfg,
                          const ps_clock_t *clock, bool is_looping)
{
    memset(f, 0, sizeof(*f));
    f->cfg = *cfg;
    f->clock = clock != NULL ? clock : ps_clock_monotonic();
    f->is_looping = is_looping;
}

static bool has_suffix(const char *name, const char *suffix)
{
    const size_t n = strlen(name), s = strlen(suffix);
    return n > s && strcasecmp(name + n - s, suffix) == 0;
}

static int is_image(const struct dirent *d)
{
    return has_suffix(d->d_name, ".png") || has_suffix(d->d_name, ".pgm") ||
           has_suffix(d->d_name, ".ppm");
}

/* One image, decoded to grey into out (w * h bytes). */
static int read_image(const char *path, uint32_t w, uint32_t h, uint8_t *out, char *err,
                      size_t err_len)
{
    if (has_suffix(path, ".png")) {
        png_image im;
        memset(&im, 0, sizeof(im));
        im.version = PNG_IMAGE_VERSION;
        if (!png_image_begin_read_from_file(&im, path)) {
            ps_err_format(err, err_len, "%s: not a PNG libpng can read: %s", path, im.message);
            return -PS_ERR_CONFIG;
        }
        if (im.width != w || im.height != h) {
            ps_err_format(err, err_len, "%s: %ux%u, the board's camera is %ux%u", path, im.width,
                          im.height, w, h);
            png_image_free(&im);
            return -PS_ERR_CONFIG;
        }
        im.format = PNG_FORMAT_GRAY;
        if (!png_image_finish_read(&im, NULL, out, (png_int_32)w, NULL)) {
            ps_err_format(err, err_len, "%s: %s", path, im.message);
            png_image_free(&im);
            return -PS_ERR_CONFIG;
        }
        return 0;
    }
    image_u8_t *im = image_u8_create_from_pnm(path); /* P5 as is, P6 to grey */
    if (im == NULL) {
        ps_err_format(err, err_len, "%s: not a PGM/PPM image", path);
        return -PS_ERR_CONFIG;
    }
    int rc = 0;
    if ((uint32_t)im->width != w || (uint32_t)im->height != h) {
        ps_err_format(err, err_len, "%s: %dx%d, the board's camera is %ux%u", path, im->width,
                      im->height, w, h);
        rc = -PS_ERR_CONFIG;
    } else {
        for (uint32_t y = 0; y < h; y++)
            memcpy(out + (size_t)y * w, im->buf + (size_t)y * (size_t)im->stride, w);
    }
    image_u8_destroy(im);
    return rc;
}

static void files_stop(void *ctx)
{
    ps_camera_files_t *f = ctx;
    free(f->pixels);
    f->pixels = NULL;
    f->n_images = 0;
}

static int files_start(void *ctx, char *err, size_t err_len)
{
    ps_camera_files_t *f = ctx;
    files_stop(f);
    struct dirent **list = NULL;
    const int n = scandir(f->cfg.dir, &list, is_image, alphasort);
    if (n < 0) {
        const int e = errno;
        ps_err_format(err, err_len, "camera: %s: %s", f->cfg.dir, strerror(e));
        return -e;
    }
    int rc = 0;
    const size_t frame_bytes = (size_t)f->cfg.width * f->cfg.height;
    const uint32_t n_use = (uint32_t)n < PS_CAMERA_FILES_MAX ? (uint32_t)n : PS_CAMERA_FILES_MAX;
    if (n == 0) {
        ps_err_format(err, err_len, "camera: %s: no .png, .pgm or .ppm image", f->cfg.dir);
        rc = -ENOENT;
    } else if (frame_bytes == 0) {
        ps_err_format(err, err_len, "camera: %s: image size 0", f->cfg.dir);
        rc = -EINVAL;
    } else {
        f->pixels = malloc(frame_bytes * n_use);
        if (f->pixels == NULL) {
            ps_err_format(err, err_len, "camera: %s: no memory for %u images", f->cfg.dir, n_use);
            rc = -ENOMEM;
        }
    }
    for (uint32_t i = 0; rc == 0 && i < n_use; i++) {
        char path[PS_PATH_LEN + 272];
        (void)snprintf(path, sizeof(path), "%s/%s", f->cfg.dir, list[i]->d_name);
        rc = read_image(path, f->cfg.width, f->cfg.height, f->pixels + frame_bytes * i, err,
                        err_len);
        f->n_images = i + 1u;
    }
    for (int i = 0; i < n; i++)
        free(list[i]);
    free(list);
    if (rc < 0) {
        files_stop(f);
        return rc;
    }
    f->n_delivered = 0;
    f->period_ns = f->cfg.fps > 0 ? (int64_t)(1e9 / f->cfg.fps) : 0;
    f->next_due_ns = ps_clock_now_ns(ps_clock_monotonic());
    return 0;
}

static int files_next(void *ctx, ps_camera_frame_t *out, int64_t timeout_ns)
{
    ps_camera_files_t *f = ctx;
    if (f->pixels == NULL || (!f->is_looping && f->n_delivered >= f->n_images))
        return -ENODATA;
    const ps_clock_t *mono = ps_clock_monotonic();
    const int64_t now = ps_clock_now_ns(mono);
    if (f->next_due_ns > now + timeout_ns) {
        (void)ps_clock_sleep_until_ns(mono, now + timeout_ns); /* an EINTR ends it early */
        return -ETIMEDOUT;
    }
    (void)ps_clock_sleep_until_ns(mono, f->next_due_ns); /* early on EINTR: no harm */
    const int64_t t_mono = ps_clock_now_ns(mono);
    /* On the frame grid; a consumer slower than the grid takes the next slot
     * from now (no burst of overdue frames). */
    f->next_due_ns += f->period_ns;
    if (f->next_due_ns < t_mono)
        f->next_due_ns = t_mono + f->period_ns;
    const uint32_t i = (uint32_t)(f->n_delivered % f->n_images);
    const size_t frame_bytes = (size_t)f->cfg.width * f->cfg.height;
    *out = (ps_camera_frame_t){
        .data = f->pixels + frame_bytes * i,
        .n_bytes = frame_bytes,
        .width = f->cfg.width,
        .height = f->cfg.height,
        .stride = f->cfg.width,
        .format = PS_PIX_R8,
        .t_ns = ps_clock_now_ns(f->clock),
        .t_mono_ns = t_mono,
        .seq = f->n_delivered,
        .buf_idx = i,
    };
    f->n_delivered++;
    return 0;
}

static void files_release(void *ctx, const ps_camera_frame_t *fr)
{
    (void)ctx; /* the images stay loaded until stop */
    (void)fr;
}

static const ps_camera_ops_t FILES_OPS = {
    .start = files_start,
    .next = files_next,
    .release = files_release,
    .stop = files_stop,
};

ps_camera_port_t ps_camera_files_port(ps_camera_files_t *f)
{
    return (ps_camera_port_t){.ops = &FILES_OPS, .ctx = f};
}
