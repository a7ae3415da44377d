#include "ps_tags.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include <apriltag/apriltag.h>
#include <apriltag/apriltag_pose.h>
#include <apriltag/tag36h11.h>

#include "../rt/ps_err.h"

struct ps_tags {
    ps_tags_cfg_t cfg;
    apriltag_family_t *family;
    apriltag_detector_t *det;
};

/* libapriltag 3.3 allocates a matd_t as one block (header and data), and
 * Debian's libapriltag does not export matd_destroy: free() is what it does. */
static void free_matd(matd_t *m)
{
    free(m);
}

static void rpy_to_matrix(const float rpy[3], double r[3][3])
{
    const double cr = cos(rpy[0]), sr = sin(rpy[0]);
    const double cp = cos(rpy[1]), sp = sin(rpy[1]);
    const double cy = cos(rpy[2]), sy = sin(rpy[2]);
    /* Rz(yaw) Ry(pitch) Rx(roll) */
    r[0][0] = cy * cp;
    r[0][1] = cy * sp * sr - sy * cr;
    r[0][2] = cy * sp * cr + sy * sr;
    r[1][0] = sy * cp;
    r[1][1] = sy * sp * sr + cy * cr;
    r[1][2] = sy * sp * cr - cy * sr;
    r[2][0] = -sp;
    r[2][1] = cp * sr;
    r[2][2] = cp * cr;
}

int ps_tags_create(const ps_tags_cfg_t *cfg, ps_tags_t **out, char *err, size_t err_len)
{
    if (cfg == NULL || out == NULL)
        return -EINVAL;
    if (!(cfg->k.fx_px > 0) || !(cfg->k.fy_px > 0) || !(cfg->tag_size_m > 0) ||
        cfg->n_threads == 0 || !(cfg->decimate >= 1.0f)) {
        ps_err_format(err, err_len,
                      "tags: focal lengths and tag size must be > 0, threads >= 1, decimate >= 1");
        return -EINVAL;
    }
    ps_tags_t *t = calloc(1, sizeof(*t));
    if (t == NULL)
        return -ENOMEM;
    t->cfg = *cfg;
    t->family = tag36h11_create();
    t->det = apriltag_detector_create();
    if (t->family == NULL || t->det == NULL) {
        ps_err_format(err, err_len, "tags: libapriltag could not create its detector");
        ps_tags_destroy(t);
        return -ENOMEM;
    }
    apriltag_detector_add_family_bits(t->det, t->family, 2); /* the library's default */
    t->det->nthreads = (int)cfg->n_threads;
    t->det->quad_decimate = cfg->decimate;
    t->det->quad_sigma = 0.0f;
    t->det->refine_edges = true;
    t->det->decode_sharpening = 0.25;
    *out = t;
    return 0;
}

void ps_tags_cam_to_robot(const ps_tags_cfg_t *cfg, const double p_cam[3], double out_robot[3])
{
    double r[3][3];
    rpy_to_matrix(cfg->cam_rpy_rad, r);
    /* optical (x right, y down, z forward) -> body (x forward, y left, z up) */
    const double b[3] = {p_cam[2], -p_cam[0], -p_cam[1]};
    for (int i = 0; i < 3; i++)
        out_robot[i] = cfg->cam_pos_m[i] + r[i][0] * b[0] + r[i][1] * b[1] + r[i][2] * b[2];
}

static int by_id(const void *a, const void *b)
{
    const ps_tags_det_t *x = a, *y = b;
    return (x->id > y->id) - (x->id < y->id);
}

int ps_tags_detect(ps_tags_t *t, const uint8_t *grey, uint32_t width, uint32_t height,
                   uint32_t stride, ps_tags_det_t *out, uint32_t max)
{
    if (t == NULL || grey == NULL || (out == NULL && max > 0) || width == 0 || height == 0 ||
        stride < width)
        return -EINVAL;
    /* libapriltag reads the image and never writes it; its struct is not const. */
    image_u8_t im = {.width = (int32_t)width,
                     .height = (int32_t)height,
                     .stride = (int32_t)stride,
                     .buf = (uint8_t *)(uintptr_t)grey};
    zarray_t *dets = apriltag_detector_detect(t->det, &im);
    if (dets == NULL)
        return -ENOMEM;
    uint32_t n = 0;
    for (int i = 0; i < zarray_size(dets) && n < max; i++) {
        apriltag_detection_t *d = NULL;
        zarray_get(dets, i, &d);
        if (d->decision_margin < t->cfg.min_margin)
            continue;
        apriltag_detection_info_t info = {
            .det = d,
            .tagsize = t->cfg.tag_size_m,
            .fx = t->cfg.k.fx_px,
            .fy = t->cfg.k.fy_px,
            .cx = t->cfg.k.cx_px,
            .cy = t->cfg.k.cy_px,
        };
        apriltag_pose_t pose = {0};
        const double e = estimate_tag_pose(&info, &pose);
        if (pose.t == NULL || pose.R == NULL) {
            free_matd(pose.t);
            free_matd(pose.R);
            continue;
        }
        ps_tags_det_t *o = &out[n];
        memset(o, 0, sizeof(*o));
        o->id = d->id;
        o->hamming = d->hamming;
        o->margin = d->decision_margin;
        o->centre_px[0] = (float)d->c[0];
        o->centre_px[1] = (float)d->c[1];
        for (int k = 0; k < 4; k++) {
            o->corners_px[k][0] = (float)d->p[k][0];
            o->corners_px[k][1] = (float)d->p[k][1];
        }
        const double p_cam[3] = {pose.t->data[0], pose.t->data[1], pose.t->data[2]};
        double p_robot[3];
        ps_tags_cam_to_robot(&t->cfg, p_cam, p_robot);
        for (int k = 0; k < 3; k++) {
            o->pos_cam_m[k] = (float)p_cam[k];
            o->pos_robot_m[k] = (float)p_robot[k];
        }
        o->pose_err = (float)e;
        const float m = d->decision_margin / PS_TAGS_MARGIN_FULL;
        o->confidence = (m < 1.0f ? m : 1.0f) / (1.0f + (float)d->hamming);
        free_matd(pose.t);
        free_matd(pose.R);
        /* A pose behind the camera or not finite is no detection. */
        if (isfinite(o->pos_robot_m[0]) && isfinite(o->pos_robot_m[1]) &&
            isfinite(o->pos_robot_m[2]) && o->pos_cam_m[2] > 0.0f)
            n++;
    }
    apriltag_detections_destroy(dets);
    qsort(out, n, sizeof(*out), by_id);
    return (int)n;
}

uint32_t ps_tags_to_neighbours(const ps_tags_det_t *det, uint32_t n, int64_t t_exposure_ns,
                               uint64_t frame_seq, ps_neighbours_t *out)
{
    memset(out, 0, sizeof(*out));
    out->t_exposure_ns = t_exposure_ns;
    out->frame_seq = frame_seq;
    uint32_t n_left_out = 0;
    for (uint32_t i = 0; i < n; i++) {
        if (det[i].id < 0 || det[i].id / 2 > UINT16_MAX || out->n_shoulders >= PS_MAX_SHOULDERS) {
            n_left_out++;
            continue;
        }
        ps_shoulder_t *s = &out->shoulders[out->n_shoulders++];
        memcpy(s->pos_robot_m, det[i].pos_robot_m, sizeof(s->pos_robot_m));
        s->confidence = det[i].confidence;
        s->neighbour_id = (uint16_t)(det[i].id / 2);
        s->side = (uint8_t)(det[i].id % 2);
    }
    return n_left_out;
}

void ps_tags_destroy(ps_tags_t *t)
{
    if (t == NULL)
        return;
    if (t->det != NULL)
        apriltag_detector_destroy(t->det);
    if (t->family != NULL)
        tag36h11_destroy(t->family);
    free(t);
}
