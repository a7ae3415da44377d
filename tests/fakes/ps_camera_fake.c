#include "ps_camera_fake.h"

#include <errno.h>
#include <math.h>
#include <string.h>
#include <time.h>

#include <apriltag/apriltag.h>
#include <apriltag/common/image_u8.h>
#include <apriltag/tag36h11.h>

void ps_tag_pose_turned(ps_tag_pose_t *p, double yaw_rad, double pitch_rad)
{
    const double cy = cos(yaw_rad), sy = sin(yaw_rad), cp = cos(pitch_rad), sp = sin(pitch_rad);
    /* Ry(yaw) * Rx(pitch), camera axes */
    const double r[3][3] = {
        {cy, sy * sp, sy * cp},
        {0.0, cp, -sp},
        {-sy, cy * sp, cy * cp},
    };
    memcpy(p->r_cam_tag, r, sizeof(r));
}

/* The tag's grey level at a point of the image plane (edge coordinates), or
 * -1 when the ray misses the tag's 10 x 10 cells (white border included). */
static int tag_level(const ps_tag_pose_t *tp, const image_u8_t *im, int width_at_border,
                     const ps_camera_intrinsics_t *k, double u, double v)
{
    const double d[3] = {(u - k->cx_px) / k->fx_px, (v - k->cy_px) / k->fy_px, 1.0};
    const double n[3] = {tp->r_cam_tag[0][2], tp->r_cam_tag[1][2], tp->r_cam_tag[2][2]};
    const double *t = tp->pos_cam_m;
    const double nd = n[0] * d[0] + n[1] * d[1] + n[2] * d[2];
    if (fabs(nd) < 1e-9)
        return -1;
    const double s = (n[0] * t[0] + n[1] * t[1] + n[2] * t[2]) / nd;
    if (s <= 0)
        return -1;
    const double q[3] = {s * d[0] - t[0], s * d[1] - t[1], s * d[2] - t[2]};
    /* into the tag's frame: R^T q */
    const double a = tp->r_cam_tag[0][0] * q[0] + tp->r_cam_tag[1][0] * q[1] +
                     tp->r_cam_tag[2][0] * q[2];
    const double b = tp->r_cam_tag[0][1] * q[0] + tp->r_cam_tag[1][1] * q[1] +
                     tp->r_cam_tag[2][1] * q[2];
    const double cell = tp->size_m / width_at_border;
    const double half = im->width / 2.0;
    const double col = a / cell + half, row = b / cell + half;
    if (col < 0 || row < 0 || col >= im->width || row >= im->height)
        return -1;
    return im->buf[(int)row * im->stride + (int)col];
}

int ps_tag_image_render(uint8_t *img, uint32_t w, uint32_t h, const ps_camera_intrinsics_t *k,
                        const ps_tag_pose_t *tags, uint32_t n_tags, uint8_t bg, int noise,
                        uint32_t seed)
{
    apriltag_family_t *fam = tag36h11_create();
    if (fam == NULL)
        return -ENOMEM;
    image_u8_t *ims[8] = {0};
    const uint32_t n = n_tags < 8u ? n_tags : 8u;
    int rc = 0;
    for (uint32_t i = 0; i < n; i++) {
        ims[i] = apriltag_to_image(fam, tags[i].id);
        if (ims[i] == NULL)
            rc = -ENOMEM;
    }
    /* Each tag's image box (its 10 x 10 cells projected, one pixel more):
     * rays are cast only there. */
    double box[8][4];
    for (uint32_t i = 0; i < n && rc == 0; i++) {
        box[i][0] = box[i][1] = INFINITY;
        box[i][2] = box[i][3] = -INFINITY;
        const double half = tags[i].size_m * ims[i]->width / fam->width_at_border / 2.0;
        for (int c = 0; c < 4; c++) {
            const double a = (c & 1) ? half : -half, b = (c & 2) ? half : -half;
            double p[3];
            for (int r = 0; r < 3; r++)
                p[r] = tags[i].pos_cam_m[r] + tags[i].r_cam_tag[r][0] * a +
                       tags[i].r_cam_tag[r][1] * b;
            if (p[2] <= 0)
                continue;
            const double u = k->fx_px * p[0] / p[2] + k->cx_px, v = k->fy_px * p[1] / p[2] + k->cy_px;
            box[i][0] = fmin(box[i][0], u - 1);
            box[i][1] = fmin(box[i][1], v - 1);
            box[i][2] = fmax(box[i][2], u + 1);
            box[i][3] = fmax(box[i][3], v + 1);
        }
    }
    uint32_t lcg = seed * 2654435761u + 1u;
    for (uint32_t y = 0; y < h && rc == 0; y++) {
        for (uint32_t x = 0; x < w; x++) {
            bool is_near = false;
            for (uint32_t i = 0; i < n; i++)
                is_near |= x + 1.0 >= box[i][0] && x <= box[i][2] && y + 1.0 >= box[i][1] &&
                           y <= box[i][3];
            double sum = 0;
            for (int sj = 0; sj < 3; sj++) {
                for (int si = 0; si < 3; si++) {
                    const double u = x + (si + 0.5) / 3.0, v = y + (sj + 0.5) / 3.0;
                    int level = -1;
                    double nearest = INFINITY;
                    for (uint32_t i = 0; i < n && is_near; i++) {
                        const int l = tag_level(&tags[i], ims[i], fam->width_at_border, k, u, v);
                        if (l >= 0 && tags[i].pos_cam_m[2] < nearest) {
                            level = l;
                            nearest = tags[i].pos_cam_m[2];
                        }
                    }
                    if (level < 0) /* a soft fixed pattern behind the tags */
                        level = bg + (int)(18.0 * sin(u / 23.0) * sin(v / 17.0));
                    sum += level;
                }
            }
            lcg = lcg * 1664525u + 1013904223u;
            const int jitter = noise > 0 ? (int)(lcg >> 8) % (2 * noise + 1) - noise : 0;
            const int value = (int)lround(sum / 9.0) + jitter;
            img[(size_t)y * w + x] = (uint8_t)(value < 0 ? 0 : value > 255 ? 255 : value);
        }
    }
    for (uint32_t i = 0; i < n; i++)
        if (ims[i] != NULL)
            image_u8_destroy(ims[i]);
    tag36h11_destroy(fam);
    return rc;
}

/* ---- the fake source ---------------------------------------------------- */

static int fake_start(void *ctx, char *err, size_t err_len)
{
    ps_camera_fake_t *f = ctx;
    f->n_started++;
    if (f->start_rc < 0 && err != NULL && err_len > 0)
        (void)strncpy(err, "fake camera: start failed as scripted", err_len - 1);
    return f->start_rc;
}

static int fake_next(void *ctx, ps_camera_frame_t *out, int64_t timeout_ns)
{
    (void)timeout_ns;
    ps_camera_fake_t *f = ctx;
    f->n_next++;
    if (f->n_frames == 0 || (!f->is_looping && f->next_idx >= f->n_frames))
        return -ENODATA;
    if (f->frame_gap_ns > 0) {
        const struct timespec ts = {f->frame_gap_ns / 1000000000, f->frame_gap_ns % 1000000000};
        nanosleep(&ts, NULL);
    }
    const uint32_t i = f->next_idx % f->n_frames;
    const int64_t lap = (int64_t)(f->next_idx / f->n_frames);
    *out = f->frames[i];
    out->t_ns += lap * f->t_step_ns;
    out->t_mono_ns += lap * f->t_step_ns;
    out->seq = f->next_idx;
    out->buf_idx = i;
    f->next_idx++;
    f->n_outstanding++;
    if (f->n_outstanding > f->n_outstanding_max)
        f->n_outstanding_max = f->n_outstanding;
    return 0;
}

static void fake_release(void *ctx, const ps_camera_frame_t *fr)
{
    (void)fr;
    ps_camera_fake_t *f = ctx;
    f->n_released++;
    if (f->n_outstanding > 0)
        f->n_outstanding--;
}

static void fake_stop(void *ctx)
{
    ps_camera_fake_t *f = ctx;
    f->n_stopped++;
}

static const ps_camera_ops_t FAKE_OPS = {
    .start = fake_start,
    .next = fake_next,
    .release = fake_release,
    .stop = fake_stop,
};

ps_camera_port_t ps_camera_fake_port(ps_camera_fake_t *f)
{
    return (ps_camera_port_t){.ops = &FAKE_OPS, .ctx = f};
}
