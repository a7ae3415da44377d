#include "ps_camera_sim.h"

#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <apriltag/apriltag.h>
#include <apriltag/common/image_u8.h>
#include <apriltag/tag36h11.h>
#include <mujoco/mujoco.h>

#include "../rt/ps_clock.h"
#include "../rt/ps_err.h"
#include "ps_gl.h"
#include "ps_scene.h"

#define NEAR_M 0.02f
#define FAR_M  50.0f

/* A tag: a geom or a site wearing a tag's material. */
typedef struct {
    bool is_site;
    int obj; /* geom or site index */
    int id;
} tag_obj_t;

struct ps_camera_sim {
    ps_camera_sim_cfg_t cfg;
    mjModel *m;
    mjData *d;
    int root_body;
    double r_root_cam[3][3]; /* camera body frame in the root body's */
    tag_obj_t tags[PS_CAMERA_SIM_MAX_TAGS];
    uint32_t n_tags;
    /* rendering, owned by the port's thread between start and stop */
    ps_gl_t gl;
    mjvScene scn;
    mjvCamera cam;
    mjvOption opt;
    mjrContext con;
    bool has_scene, has_con;
    uint8_t *rgb;   /* readPixels, bottom row first */
    uint8_t *frame; /* delivered, top row first */
    int64_t next_due_ns, period_ns;
    uint64_t n_frames;
    /* truth of the last frame */
    pthread_mutex_t mu;
    ps_camera_sim_tag_t truth[PS_CAMERA_SIM_MAX_TAGS];
    ps_camera_sim_tag_t scratch[PS_CAMERA_SIM_MAX_TAGS]; /* the port's thread */
    uint32_t occluders[PS_CAMERA_SIM_MAX_TAGS];          /* site tags ahead, this frame */
    uint32_t n_occluders;
    uint32_t n_truth;
    uint64_t truth_seq;
    bool has_truth;
};

static void rpy_to_matrix(const float rpy[3], double r[3][3])
{
    const double cr = cos(rpy[0]), sr = sin(rpy[0]);
    const double cp = cos(rpy[1]), sp = sin(rpy[1]);
    const double cy = cos(rpy[2]), sy = sin(rpy[2]);
    const double m[3][3] = {
        {cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr},
        {sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr},
        {-sp, cp * sr, cp * cr},
    };
    memcpy(r, m, sizeof(m));
}

/* Fill each "tag36h11_<id>" texture with its tag, nearest-neighbour scaled. */
static uint32_t fill_tag_textures(mjModel *m, int *tex_tag_id)
{
    apriltag_family_t *fam = tag36h11_create();
    uint32_t n = 0;
    for (int t = 0; t < m->ntex; t++) {
        tex_tag_id[t] = -1;
        int id = -1;
        char rest = 0;
        if (fam == NULL || sscanf(m->names + m->name_texadr[t], "tag36h11_%d%c", &id, &rest) != 1 ||
            id < 0 || (uint32_t)id >= fam->ncodes || m->tex_type[t] != mjTEXTURE_2D)
            continue;
        image_u8_t *im = apriltag_to_image(fam, id);
        if (im == NULL)
            continue;
        const int w = m->tex_width[t], h = m->tex_height[t];
        mjtByte *rgb = m->tex_rgb + m->tex_adr[t];
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                const uint8_t v = im->buf[(y * im->height / h) * im->stride + x * im->width / w];
                rgb[3 * (y * w + x)] = rgb[3 * (y * w + x) + 1] = rgb[3 * (y * w + x) + 2] = v;
            }
        image_u8_destroy(im);
        tex_tag_id[t] = id;
        n++;
    }
    if (fam != NULL)
        tag36h11_destroy(fam);
    return n;
}

int ps_camera_sim_create(const ps_camera_sim_cfg_t *cfg, ps_camera_sim_t **out, char *err,
                         size_t err_len)
{
    if (cfg == NULL || out == NULL || cfg->sim == NULL || cfg->root_body == NULL ||
        cfg->camera.width == 0 || cfg->camera.height == 0 || !(cfg->k.fy_px > 0) ||
        fabsf(cfg->k.fx_px - cfg->k.fy_px) > 1e-3f * cfg->k.fy_px) {
        ps_err_format(err, err_len, "sim camera: needs a size, and fx_px == fy_px > 0");
        return -EINVAL;
    }
    ps_camera_sim_t *c = calloc(1, sizeof(*c));
    if (c == NULL)
        return -ENOMEM;
    c->cfg = *cfg;
    if (pthread_mutex_init(&c->mu, NULL) != 0) {
        free(c);
        return -ENOMEM;
    }
    c->m = ps_sim_copy_model(cfg->sim);
    c->d = c->m != NULL ? mj_makeData(c->m) : NULL;
    int *tex_tag_id = c->m != NULL ? calloc((size_t)c->m->ntex + 1u, sizeof(int)) : NULL;
    if (c->d == NULL || tex_tag_id == NULL) {
        free(tex_tag_id);
        ps_camera_sim_destroy(c);
        ps_err_format(err, err_len, "sim camera: no memory for the model's copy");
        return -ENOMEM;
    }
    if ((uint32_t)c->m->ntex > PS_SCENE_MAX_TEXTURES) { /* would overrun mjrContext */
        free(tex_tag_id);
        ps_err_format(err, err_len,
                      "sim camera: the model has %d textures; MuJoCo 2.2.2's renderer holds %u",
                      c->m->ntex, PS_SCENE_MAX_TEXTURES);
        ps_camera_sim_destroy(c);
        return -EINVAL;
    }
    c->root_body = mj_name2id(c->m, mjOBJ_BODY, cfg->root_body);
    if (c->root_body < 0) {
        free(tex_tag_id);
        ps_err_format(err, err_len, "sim camera: no body \"%s\" in the model", cfg->root_body);
        ps_camera_sim_destroy(c);
        return -ENOENT;
    }
    rpy_to_matrix(cfg->cam_rpy_rad, c->r_root_cam);
    (void)fill_tag_textures(c->m, tex_tag_id);
    /* geoms, then sites, wearing a tag's material */
    for (int k = 0; k < c->m->ngeom + c->m->nsite && c->n_tags < PS_CAMERA_SIM_MAX_TAGS; k++) {
        const bool is_site = k >= c->m->ngeom;
        const int obj = is_site ? k - c->m->ngeom : k;
        const int mat = is_site ? c->m->site_matid[obj] : c->m->geom_matid[obj];
        const int tex = mat >= 0 ? c->m->mat_texid[mat] : -1;
        if (tex >= 0 && tex_tag_id[tex] >= 0)
            c->tags[c->n_tags++] =
                (tag_obj_t){.is_site = is_site, .obj = obj, .id = tex_tag_id[tex]};
    }
    free(tex_tag_id);
    c->m->vis.global.offwidth = (int)cfg->camera.width;
    c->m->vis.global.offheight = (int)cfg->camera.height;
    *out = c;
    return 0;
}

uint32_t ps_camera_sim_n_tags(const ps_camera_sim_t *c)
{
    return c->n_tags;
}

/* ---- GL ------------------------------------------------------------------- */

static void gl_stop(ps_camera_sim_t *c)
{
    if (c->has_con)
        mjr_freeContext(&c->con);
    if (c->has_scene)
        mjv_freeScene(&c->scn);
    c->has_con = c->has_scene = false;
    ps_gl_close(&c->gl);
    free(c->rgb);
    free(c->frame);
    c->rgb = c->frame = NULL;
}

static int sim_start(void *ctx, char *err, size_t err_len)
{
    ps_camera_sim_t *c = ctx;
    gl_stop(c);
    char why[PS_ERR_MSG_LEN];
    const int rc = ps_gl_open_offscreen(&c->gl, why, sizeof(why));
    if (rc < 0) {
        ps_err_format(err, err_len, "sim camera: %s", why);
        return rc;
    }
    mjv_defaultScene(&c->scn);
    mjv_defaultCamera(&c->cam);
    mjv_defaultOption(&c->opt);
    mjr_defaultContext(&c->con);
    mjv_makeScene(c->m, &c->scn, c->m->ngeom + 100);
    c->has_scene = true;
    mjr_makeContext(c->m, &c->con, mjFONTSCALE_100);
    c->has_con = true;
    mjr_setBuffer(mjFB_OFFSCREEN, &c->con);
    const size_t n_px = (size_t)c->cfg.camera.width * c->cfg.camera.height;
    c->rgb = malloc(3 * n_px);
    c->frame = malloc(3 * n_px);
    if (c->con.currentBuffer != mjFB_OFFSCREEN || c->con.offWidth < (int)c->cfg.camera.width ||
        c->con.offHeight < (int)c->cfg.camera.height || c->rgb == NULL || c->frame == NULL) {
        ps_err_format(err, err_len, "sim camera: no %ux%u offscreen buffer",
                      c->cfg.camera.width, c->cfg.camera.height);
        gl_stop(c);
        return -EIO;
    }
    /* A camera sees no shadows or reflections worth their cost here. */
    c->scn.flags[mjRND_SHADOW] = 0;
    c->scn.flags[mjRND_REFLECTION] = 0;
    c->period_ns = (int64_t)(1e9 / c->cfg.camera.fps);
    c->next_due_ns = ps_clock_now_ns(ps_clock_monotonic());
    c->n_frames = 0;
    return 0;
}

static void sim_stop(void *ctx)
{
    gl_stop(ctx);
}

/* The camera's world pose: optical centre, and the body frame's axes. */
static void camera_pose(const ps_camera_sim_t *c, double pos[3], double r_world_cam[3][3])
{
    const mjtNum *p = c->d->xpos + 3 * c->root_body;
    const mjtNum *r = c->d->xmat + 9 * c->root_body; /* row-major world <- root */
    for (int i = 0; i < 3; i++) {
        pos[i] = p[i];
        for (int k = 0; k < 3; k++)
            pos[i] += r[3 * i + k] * c->cfg.cam_pos_m[k];
        for (int j = 0; j < 3; j++) {
            r_world_cam[i][j] = 0;
            for (int k = 0; k < 3; k++)
                r_world_cam[i][j] += r[3 * i + k] * c->r_root_cam[k][j];
        }
    }
}

/* A world point in the optical frame (x right, y down, z ahead). */
static void to_optical(const double cam_pos[3], const double r_world_cam[3][3], const double p[3],
                       double out[3])
{
    double body[3];
    for (int k = 0; k < 3; k++) {
        body[k] = 0; /* camera body frame: R^T (p - cam) */
        for (int j = 0; j < 3; j++)
            body[k] += r_world_cam[j][k] * (p[j] - cam_pos[j]);
    }
    out[0] = -body[1];
    out[1] = -body[2];
    out[2] = body[0];
}

/* Whether the ray from the camera to p meets tag `self` before anything
 * else: MuJoCo's rays see geoms only (a geom tag must be the first geom
 * hit), so the tag plates that are sites (c->occluders, those in front of
 * the camera) are tried one by one. */
static bool is_seen(const ps_camera_sim_t *c, const double cam_pos[3], const double p[3],
                    uint32_t self)
{
    const mjtNum vec[3] = {p[0] - cam_pos[0], p[1] - cam_pos[1], p[2] - cam_pos[2]};
    const tag_obj_t *t = &c->tags[self];
    int hit = -1;
    const mjtNum x = mj_ray(c->m, c->d, cam_pos, vec, NULL, 1, -1, &hit);
    if (!((!t->is_site && hit == t->obj) || x < 0 || x > 1.0 - 1e-6))
        return false;
    for (uint32_t k = 0; k < c->n_occluders; k++) {
        const uint32_t j = c->occluders[k];
        const int s = c->tags[j].obj;
        if (j == self)
            continue;
        const mjtNum xs = mju_rayGeom(c->d->site_xpos + 3 * s, c->d->site_xmat + 9 * s,
                                      c->m->site_size + 3 * s, cam_pos, vec, mjGEOM_BOX);
        if (xs >= 0 && xs < 1.0 - 1e-6)
            return false;
    }
    return true;
}

/* One tag: its face's centre in the robot and optical frames, and whether
 * the camera can see it whole (the rays only for a tag facing the camera
 * inside the picture: a crowd has hundreds of tags, most out of sight). */
static void tag_truth(const ps_camera_sim_t *c, uint32_t idx, const double cam_pos[3],
                      const double r_world_cam[3][3], ps_camera_sim_tag_t *t)
{
    const tag_obj_t *tag = &c->tags[idx];
    const mjtNum *p_root = c->d->xpos + 3 * c->root_body;
    const mjtNum *r_root = c->d->xmat + 9 * c->root_body;
    const int o = tag->obj;
    const mjtNum *gp = tag->is_site ? c->d->site_xpos + 3 * o : c->d->geom_xpos + 3 * o;
    const mjtNum *gr = tag->is_site ? c->d->site_xmat + 9 * o : c->d->geom_xmat + 9 * o;
    const mjtNum *size = tag->is_site ? c->m->site_size + 3 * o : c->m->geom_size + 3 * o;
    double face[3], n[3], rel[3];
    for (int k = 0; k < 3; k++) {
        n[k] = gr[3 * k + 2]; /* the plate's z axis */
        face[k] = gp[k] + n[k] * size[2];
        rel[k] = cam_pos[k] - face[k];
    }
    memset(t, 0, sizeof(*t));
    t->id = tag->id;
    const double dist = sqrt(rel[0] * rel[0] + rel[1] * rel[1] + rel[2] * rel[2]);
    const double cos_slant = (n[0] * rel[0] + n[1] * rel[1] + n[2] * rel[2]) / dist;
    t->is_facing = cos_slant > 0;
    t->slant_rad = acos(cos_slant < -1 ? -1 : cos_slant > 1 ? 1 : cos_slant);
    for (int k = 0; k < 3; k++) { /* robot frame: R_root^T (face - p_root) */
        t->pos_robot_m[k] = 0;
        for (int j = 0; j < 3; j++)
            t->pos_robot_m[k] += r_root[3 * j + k] * (face[j] - p_root[j]);
    }
    to_optical(cam_pos, r_world_cam, face, t->pos_cam_m);
    /* The plate's four corners and four edge midpoints (q 0-3, 4-7), and
     * the black square's corners (8 of the face's 10 cells; q 8-11). The
     * detector needs the white border around the black square, so the
     * plate as a whole must be inside the picture and in sight. */
    static const double U[12][2] = {{-1, -1}, {1, -1}, {1, 1},     {-1, 1},   {0, -1},  {1, 0},
                                    {0, 1},   {-1, 0}, {-.8, -.8}, {.8, -.8}, {.8, .8}, {-.8, .8}};
    double point[12][3], uv[12][2];
    t->is_in_view = true;
    for (int q = 0; q < 12; q++) {
        const double a = U[q][0] * size[0], b = U[q][1] * size[1];
        double opt[3];
        for (int k = 0; k < 3; k++)
            point[q][k] = face[k] + gr[3 * k] * a + gr[3 * k + 1] * b;
        to_optical(cam_pos, r_world_cam, point[q], opt);
        if (opt[2] <= 0) {
            t->is_in_view = false;
            continue;
        }
        uv[q][0] = c->cfg.k.fx_px * opt[0] / opt[2] + c->cfg.k.cx_px;
        uv[q][1] = c->cfg.k.fy_px * opt[1] / opt[2] + c->cfg.k.cy_px;
        if (q < 4)
            t->is_in_view &= uv[q][0] >= 2 && uv[q][1] >= 2 &&
                             uv[q][0] <= c->cfg.camera.width - 2.0 &&
                             uv[q][1] <= c->cfg.camera.height - 2.0;
        /* a point a hair inside the plate: on its face, not its edge */
        for (int k = 0; k < 3; k++)
            point[q][k] -= (gr[3 * k] * a + gr[3 * k + 1] * b) * 0.02;
    }
    if (!t->is_in_view)
        return;
    for (int q = 8; q < 12; q++) {
        const int r = q == 11 ? 8 : q + 1;
        const double du = uv[r][0] - uv[q][0], dv = uv[r][1] - uv[q][1];
        const double edge = sqrt(du * du + dv * dv);
        t->size_px = edge > t->size_px ? edge : t->size_px;
    }
    if (!t->is_facing)
        return;
    t->is_unoccluded = is_seen(c, cam_pos, face, idx);
    for (int q = 0; q < 8 && t->is_unoccluded; q++)
        t->is_unoccluded = is_seen(c, cam_pos, point[q], idx);
}

/* Every tag of the scene at this frame. */
static void update_truth(ps_camera_sim_t *c, const double cam_pos[3],
                         const double r_world_cam[3][3], uint64_t seq)
{
    c->n_occluders = 0;
    for (uint32_t i = 0; i < c->n_tags; i++) {
        double opt[3];
        if (!c->tags[i].is_site)
            continue;
        to_optical(cam_pos, r_world_cam, c->d->site_xpos + 3 * c->tags[i].obj, opt);
        if (opt[2] > 0)
            c->occluders[c->n_occluders++] = i;
    }
    for (uint32_t i = 0; i < c->n_tags; i++)
        tag_truth(c, i, cam_pos, r_world_cam, &c->scratch[i]);
    pthread_mutex_lock(&c->mu);
    memcpy(c->truth, c->scratch, sizeof(c->truth[0]) * c->n_tags);
    c->n_truth = c->n_tags;
    c->truth_seq = seq;
    c->has_truth = true;
    pthread_mutex_unlock(&c->mu);
}

static int sim_next(void *ctx, ps_camera_frame_t *out, int64_t timeout_ns)
{
    ps_camera_sim_t *c = ctx;
    if (!c->has_con)
        return -EIO;
    const ps_clock_t *mono = ps_clock_monotonic();
    const int64_t now = ps_clock_now_ns(mono);
    if (c->next_due_ns > now + timeout_ns) {
        (void)ps_clock_sleep_until_ns(mono, now + timeout_ns); /* EINTR: shorter */
        return -ETIMEDOUT;
    }
    (void)ps_clock_sleep_until_ns(mono, c->next_due_ns);
    const int64_t t_mono = ps_clock_now_ns(mono);
    c->next_due_ns += c->period_ns;
    if (c->next_due_ns < t_mono) /* rendering slower than the rate: no burst */
        c->next_due_ns = t_mono + c->period_ns;
    int64_t t_ns = 0;
    if (ps_sim_read_scene(c->cfg.sim, c->d->qpos, (uint32_t)c->m->nq, &t_ns, NULL) < 0)
        return -EIO;
    mj_kinematics(c->m, c->d);
    mj_camlight(c->m, c->d);
    double pos[3], r[3][3];
    camera_pose(c, pos, r);
    mjv_updateScene(c->m, c->d, &c->opt, NULL, &c->cam, mjCAT_ALL, &c->scn);
    const float top = NEAR_M * 0.5f * (float)c->cfg.camera.height / c->cfg.k.fy_px;
    for (int e = 0; e < 2; e++) {
        mjvGLCamera *gc = &c->scn.camera[e];
        for (int i = 0; i < 3; i++) {
            gc->pos[i] = (float)pos[i];
            gc->forward[i] = (float)r[i][0]; /* body x: the optical axis */
            gc->up[i] = (float)r[i][2];      /* body z: up */
        }
        gc->frustum_center = 0;
        gc->frustum_near = NEAR_M;
        gc->frustum_far = FAR_M;
        gc->frustum_top = top;
        gc->frustum_bottom = -top;
    }
    const mjrRect vp = {0, 0, (int)c->cfg.camera.width, (int)c->cfg.camera.height};
    mjr_render(vp, &c->scn, &c->con);
    mjr_readPixels(c->rgb, NULL, vp, &c->con);
    const size_t row = 3u * c->cfg.camera.width;
    for (uint32_t y = 0; y < c->cfg.camera.height; y++)
        memcpy(c->frame + y * row, c->rgb + (c->cfg.camera.height - 1u - y) * row, row);
    update_truth(c, pos, r, c->n_frames);
    *out = (ps_camera_frame_t){
        .data = c->frame,
        .n_bytes = row * c->cfg.camera.height,
        .width = c->cfg.camera.width,
        .height = c->cfg.camera.height,
        .stride = (uint32_t)row,
        .format = PS_PIX_BGR888,
        .t_ns = t_ns,
        .t_mono_ns = t_mono,
        .seq = c->n_frames++,
    };
    return 0;
}

static void sim_release(void *ctx, const ps_camera_frame_t *f)
{
    (void)ctx; /* one buffer, rewritten by the next frame */
    (void)f;
}

static const ps_camera_ops_t SIM_OPS = {
    .start = sim_start,
    .next = sim_next,
    .release = sim_release,
    .stop = sim_stop,
};

ps_camera_port_t ps_camera_sim_port(ps_camera_sim_t *c)
{
    return (ps_camera_port_t){.ops = &SIM_OPS, .ctx = c};
}

static int by_id(const void *a, const void *b)
{
    const ps_camera_sim_tag_t *x = a, *y = b;
    return (x->id > y->id) - (x->id < y->id);
}

int ps_camera_sim_truth(ps_camera_sim_t *c, ps_camera_sim_tag_t *out, uint32_t max,
                        uint64_t *out_frame_seq)
{
    pthread_mutex_lock(&c->mu);
    int rc = -ENODATA;
    if (c->has_truth) {
        const uint32_t n = c->n_truth < max ? c->n_truth : max;
        memcpy(out, c->truth, sizeof(out[0]) * n);
        if (out_frame_seq != NULL)
            *out_frame_seq = c->truth_seq;
        rc = (int)n;
    }
    pthread_mutex_unlock(&c->mu);
    if (rc > 0)
        qsort(out, (size_t)rc, sizeof(out[0]), by_id);
    return rc;
}

void ps_camera_sim_destroy(ps_camera_sim_t *c)
{
    if (c == NULL)
        return;
    if (c->d != NULL)
        mj_deleteData(c->d);
    if (c->m != NULL)
        mj_deleteModel(c->m);
    pthread_mutex_destroy(&c->mu);
    free(c);
}
