#include "ps_camera_sim.h"

#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <apriltag/apriltag.h>
#include <apriltag/common/image_u8.h>
#include <apriltag/tag36h11.h>
#include <mujoco/mujoco.h>

#include "../rt/ps_clock.h"
#include "../rt/ps_err.h"

#define NEAR_M 0.02f
#define FAR_M  50.0f

typedef struct {
    int geom;
    int id;
} tag_geom_t;

struct ps_camera_sim {
    ps_camera_sim_cfg_t cfg;
    mjModel *m;
    mjData *d;
    int root_body;
    double r_root_cam[3][3]; /* camera body frame in the root body's */
    tag_geom_t tags[PS_CAMERA_SIM_MAX_TAGS];
    uint32_t n_tags;
    /* rendering, owned by the port's thread between start and stop */
    EGLDisplay dpy;
    EGLContext ctx;
    bool is_gl;
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
    c->root_body = mj_name2id(c->m, mjOBJ_BODY, cfg->root_body);
    if (c->root_body < 0) {
        free(tex_tag_id);
        ps_err_format(err, err_len, "sim camera: no body \"%s\" in the model", cfg->root_body);
        ps_camera_sim_destroy(c);
        return -ENOENT;
    }
    rpy_to_matrix(cfg->cam_rpy_rad, c->r_root_cam);
    (void)fill_tag_textures(c->m, tex_tag_id);
    for (int g = 0; g < c->m->ngeom && c->n_tags < PS_CAMERA_SIM_MAX_TAGS; g++) {
        const int mat = c->m->geom_matid[g];
        const int tex = mat >= 0 ? c->m->mat_texid[mat] : -1;
        if (tex >= 0 && tex_tag_id[tex] >= 0)
            c->tags[c->n_tags++] = (tag_geom_t){.geom = g, .id = tex_tag_id[tex]};
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
    if (c->is_gl) {
        (void)eglMakeCurrent(c->dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
        (void)eglDestroyContext(c->dpy, c->ctx);
        /* (no eglTerminate: the display is shared and stays for a later start) */
    }
    c->is_gl = false;
    free(c->rgb);
    free(c->frame);
    c->rgb = c->frame = NULL;
}

static int egl_start(ps_camera_sim_t *c, char *err, size_t err_len)
{
    /* Mesa's surfaceless platform renders with no display and no GPU; without
     * the extension, the default display (EGL_PLATFORM=surfaceless selects it). */
    PFNEGLGETPLATFORMDISPLAYEXTPROC get_platform_display =
        (PFNEGLGETPLATFORMDISPLAYEXTPROC)eglGetProcAddress("eglGetPlatformDisplayEXT");
    c->dpy = get_platform_display != NULL
                 ? get_platform_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, NULL)
                 : eglGetDisplay(EGL_DEFAULT_DISPLAY);
    EGLint major = 0, minor = 0;
    if (c->dpy == EGL_NO_DISPLAY || eglInitialize(c->dpy, &major, &minor) != EGL_TRUE) {
        ps_err_format(err, err_len,
                      "sim camera: no EGL display (error 0x%x; Mesa's libegl-mesa0 and "
                      "libgl1-mesa-dri render without one)",
                      (unsigned)eglGetError());
        return -EIO;
    }
    /* A pbuffer-capable config: the surfaceless platform has no windows, and
     * MuJoCo renders into its own framebuffer object anyway. */
    const EGLint attrs[] = {EGL_RED_SIZE,     8,  EGL_GREEN_SIZE,      8,
                            EGL_BLUE_SIZE,    8,  EGL_DEPTH_SIZE,      24,
                            EGL_SURFACE_TYPE, EGL_PBUFFER_BIT, EGL_RENDERABLE_TYPE,
                            EGL_OPENGL_BIT,   EGL_NONE};
    EGLConfig conf;
    EGLint n_conf = 0;
    if (eglChooseConfig(c->dpy, attrs, &conf, 1, &n_conf) != EGL_TRUE || n_conf < 1 ||
        eglBindAPI(EGL_OPENGL_API) != EGL_TRUE) {
        ps_err_format(err, err_len, "sim camera: no EGL OpenGL config (error 0x%x)",
                      (unsigned)eglGetError());
        (void)eglTerminate(c->dpy);
        return -EIO;
    }
    c->ctx = eglCreateContext(c->dpy, conf, EGL_NO_CONTEXT, NULL);
    if (c->ctx == EGL_NO_CONTEXT ||
        eglMakeCurrent(c->dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, c->ctx) != EGL_TRUE) {
        ps_err_format(err, err_len, "sim camera: no EGL context (error 0x%x)",
                      (unsigned)eglGetError());
        if (c->ctx != EGL_NO_CONTEXT)
            (void)eglDestroyContext(c->dpy, c->ctx);
        (void)eglTerminate(c->dpy);
        return -EIO;
    }
    c->is_gl = true;
    return 0;
}

static int sim_start(void *ctx, char *err, size_t err_len)
{
    ps_camera_sim_t *c = ctx;
    gl_stop(c);
    int rc = egl_start(c, err, err_len);
    if (rc < 0)
        return rc;
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

/* Whether the ray from the camera to p meets geom g before anything else. */
static bool is_seen(const ps_camera_sim_t *c, const double cam_pos[3], const double p[3], int g)
{
    const mjtNum vec[3] = {p[0] - cam_pos[0], p[1] - cam_pos[1], p[2] - cam_pos[2]};
    int hit = -1;
    const mjtNum x = mj_ray(c->m, c->d, cam_pos, vec, NULL, 1, -1, &hit);
    return hit == g || x < 0 || x > 1.0 - 1e-6;
}

/* Every tag: its face's centre in the robot and optical frames, and whether
 * the camera can see it whole. */
static void update_truth(ps_camera_sim_t *c, const double cam_pos[3],
                         const double r_world_cam[3][3], uint64_t seq)
{
    const mjtNum *p_root = c->d->xpos + 3 * c->root_body;
    const mjtNum *r_root = c->d->xmat + 9 * c->root_body;
    ps_camera_sim_tag_t truth[PS_CAMERA_SIM_MAX_TAGS];
    for (uint32_t i = 0; i < c->n_tags; i++) {
        const int g = c->tags[i].geom;
        const mjtNum *gp = c->d->geom_xpos + 3 * g, *gr = c->d->geom_xmat + 9 * g;
        const mjtNum *size = c->m->geom_size + 3 * g;
        double face[3], n[3], rel[3];
        for (int k = 0; k < 3; k++) {
            n[k] = gr[3 * k + 2]; /* the geom's z axis */
            face[k] = gp[k] + n[k] * size[2];
            rel[k] = cam_pos[k] - face[k];
        }
        ps_camera_sim_tag_t *t = &truth[i];
        memset(t, 0, sizeof(*t));
        t->id = c->tags[i].id;
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
        /* the black square's corners: 8 of the face's 10 cells */
        t->is_in_view = true;
        t->is_unoccluded = is_seen(c, cam_pos, face, g);
        double uv[4][2];
        for (int q = 0; q < 4; q++) {
            const double a = (q == 0 || q == 3 ? -0.8 : 0.8) * size[0];
            const double b = (q < 2 ? -0.8 : 0.8) * size[1];
            double corner[3], opt[3];
            for (int k = 0; k < 3; k++)
                corner[k] = face[k] + gr[3 * k] * a + gr[3 * k + 1] * b;
            to_optical(cam_pos, r_world_cam, corner, opt);
            if (opt[2] <= 0) {
                t->is_in_view = false;
                continue;
            }
            uv[q][0] = c->cfg.k.fx_px * opt[0] / opt[2] + c->cfg.k.cx_px;
            uv[q][1] = c->cfg.k.fy_px * opt[1] / opt[2] + c->cfg.k.cy_px;
            t->is_in_view &= uv[q][0] >= 2 && uv[q][1] >= 2 &&
                             uv[q][0] <= c->cfg.camera.width - 2.0 &&
                             uv[q][1] <= c->cfg.camera.height - 2.0;
            /* a point a hair inside the corner: on the face, not its edge */
            for (int k = 0; k < 3; k++)
                corner[k] -= (gr[3 * k] * a + gr[3 * k + 1] * b) * 0.02;
            t->is_unoccluded &= is_seen(c, cam_pos, corner, g);
        }
        for (int q = 0; q < 4 && t->is_in_view; q++) {
            const double du = uv[(q + 1) % 4][0] - uv[q][0], dv = uv[(q + 1) % 4][1] - uv[q][1];
            const double edge = sqrt(du * du + dv * dv);
            t->size_px = edge > t->size_px ? edge : t->size_px;
        }
    }
    pthread_mutex_lock(&c->mu);
    memcpy(c->truth, truth, sizeof(truth[0]) * c->n_tags);
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
