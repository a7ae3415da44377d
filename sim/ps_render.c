#include "ps_render.h"

#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <mujoco/mujoco.h>
#include <png.h>

#include "../rt/ps_err.h"
#include "ps_gl.h"
#include "ps_scene.h"

#define N_SLOTS        4u
#define ARROW_M_PER_N  0.002  /* 1 m per 500 N */
#define ARROW_MAX_M    1.5
#define FORCE_RED_N    500.0  /* arrows and tints reach red here */
#define PART_TINT_N    20.0   /* parts under more than this are tinted */
#define DENSITY_CELL_M 0.05
#define DENSITY_SIGMA  0.3
#define DENSITY_MAX    8.0    /* persons / m^2 at the top of the colour scale */
#define DENSITY_PX     6      /* pixels per cell in density.png */
#define EXTRA_GEOMS    400    /* arrows beyond the model's geoms */
#define AGENT_ALPHA    0.45f  /* people drawn translucent: the robot shows through */

typedef struct {
    double time;
    mjtNum *qpos, *qvel, *act, *ctrl, *qfrc, *xfrc, *mpos, *mquat, *warm;
} slot_t;

struct ps_render {
    ps_render_cfg_t cfg;
    char dir[512];
    mjModel *m; /* own copy: the plant's crowd switches collisions in its model as it steps */
    mjData *d;
    int root;
    unsigned char *is_robot; /* nbody */
    int *agent_of_body;      /* nbody: agent index or -1 */
    int *agent_body;         /* ring body of each agent */
    int n_agents;
    slot_t slot[N_SLOTS];
    atomic_uint head, tail; /* head: next to fill (plant), tail: next to render */
    atomic_bool is_running, is_ready;
    atomic_ullong n_dropped;
    int start_rc;
    char start_err[256];
    pthread_t thread;
    bool has_thread;
    ps_gl_t gl;
    mjvScene scn;
    mjvCamera cam;
    mjvOption opt;
    mjrContext con;
    unsigned char *rgb;
    double *part_force_n; /* nbody */
    /* density: grid over the area, sum over frames */
    int gx, gy;
    double *density;
    uint64_t n_frames;
    bool was_view_closed;
    uint32_t robot_px, agent_px, n_agents_seen;
    int write_rc;
    char write_err[1024];
};

/* ---- create ---------------------------------------------------------------- */

static int make_dir(const char *path)
{
    char buf[512];
    (void)snprintf(buf, sizeof(buf), "%s", path);
    for (char *p = buf + 1; *p != '\0'; p++) {
        if (*p != '/')
            continue;
        *p = '\0';
        if (mkdir(buf, 0755) != 0 && errno != EEXIST)
            return -errno;
        *p = '/';
    }
    if (mkdir(buf, 0755) != 0 && errno != EEXIST)
        return -errno;
    return 0;
}

static int alloc_slots(ps_render_t *r)
{
    const mjModel *m = r->m;
    for (unsigned k = 0; k < N_SLOTS; k++) {
        slot_t *s = &r->slot[k];
        s->qpos = calloc((size_t)m->nq + 1, sizeof(mjtNum));
        s->qvel = calloc((size_t)m->nv + 1, sizeof(mjtNum));
        s->act = calloc((size_t)m->na + 1, sizeof(mjtNum));
        s->ctrl = calloc((size_t)m->nu + 1, sizeof(mjtNum));
        s->qfrc = calloc((size_t)m->nv + 1, sizeof(mjtNum));
        s->xfrc = calloc(6 * (size_t)m->nbody + 1, sizeof(mjtNum));
        s->mpos = calloc(3 * (size_t)m->nmocap + 1, sizeof(mjtNum));
        s->mquat = calloc(4 * (size_t)m->nmocap + 1, sizeof(mjtNum));
        s->warm = calloc((size_t)m->nv + 1, sizeof(mjtNum));
        if (s->qpos == NULL || s->qvel == NULL || s->act == NULL || s->ctrl == NULL ||
            s->qfrc == NULL || s->xfrc == NULL || s->mpos == NULL || s->mquat == NULL ||
            s->warm == NULL)
            return -ENOMEM;
    }
    return 0;
}

int ps_render_create(const ps_render_cfg_t *cfg, const mjModel *m, ps_render_t **out,
                     char *err, size_t err_len)
{
    if (cfg == NULL || m == NULL || out == NULL) {
        ps_err_format(err, err_len, "render: NULL argument");
        return -EINVAL;
    }
    if (!(cfg->fps > 0.0 && cfg->fps <= 200.0)) {
        ps_err_format(err, err_len, "render: fps %g out of range (0, 200]", cfg->fps);
        return -EINVAL;
    }
    if (cfg->width < 16 || cfg->height < 16 || cfg->width > PS_RENDER_MAX_WIDTH ||
        cfg->height > PS_RENDER_MAX_HEIGHT || cfg->width % 2 || cfg->height % 2) {
        ps_err_format(err, err_len, "render: frame size %dx%d: even, 16x16 to %dx%d",
                      cfg->width, cfg->height, PS_RENDER_MAX_WIDTH, PS_RENDER_MAX_HEIGHT);
        return -EINVAL;
    }
    if (!(cfg->area_m[2] > cfg->area_m[0] && cfg->area_m[3] > cfg->area_m[1])) {
        ps_err_format(err, err_len, "render: empty density area");
        return -EINVAL;
    }
    if ((uint32_t)m->ntex > PS_SCENE_MAX_TEXTURES) { /* would overrun mjrContext */
        ps_err_format(err, err_len,
                      "render: the scene has %d textures, MuJoCo 2.2.2's renderer holds %u",
                      m->ntex, PS_SCENE_MAX_TEXTURES);
        return -EINVAL;
    }
    ps_render_t *r = calloc(1, sizeof(*r));
    if (r == NULL)
        return -ENOMEM;
    r->cfg = *cfg;
    int rc = 0;
    r->m = mj_copyModel(NULL, m);
    if (r->m == NULL) {
        rc = -ENOMEM;
        goto fail;
    }
    /* MuJoCo sizes the offscreen buffer from the model (<visual><global
     * offwidth/offheight>, 640 x 480 by default, which the robot's own
     * MJCF keeps): the renderer's copy gets room for the frame. */
    if (r->m->vis.global.offwidth < cfg->width)
        r->m->vis.global.offwidth = cfg->width;
    if (r->m->vis.global.offheight < cfg->height)
        r->m->vis.global.offheight = cfg->height;
    if (cfg->dir != NULL) {
        (void)snprintf(r->dir, sizeof(r->dir), "%s", cfg->dir);
        rc = make_dir(r->dir);
        if (rc < 0) {
            ps_err_format(err, err_len, "render: %s: %s", r->dir, strerror(-rc));
            goto fail;
        }
    }
    r->root = mj_name2id(m, mjOBJ_BODY, cfg->robot_root != NULL ? cfg->robot_root : "pelvis");
    if (r->root < 0) {
        ps_err_format(err, err_len, "render: no body '%s' in the scene", cfg->robot_root);
        rc = -ENOENT;
        goto fail;
    }
    r->is_robot = calloc((size_t)m->nbody, 1);
    r->agent_of_body = calloc((size_t)m->nbody, sizeof(int));
    r->agent_body = calloc((size_t)m->nbody, sizeof(int));
    r->part_force_n = calloc((size_t)m->nbody, sizeof(double));
    r->rgb = malloc(3u * (size_t)cfg->width * (size_t)cfg->height);
    r->gx = (int)ceil((cfg->area_m[2] - cfg->area_m[0]) / DENSITY_CELL_M);
    r->gy = (int)ceil((cfg->area_m[3] - cfg->area_m[1]) / DENSITY_CELL_M);
    r->density = calloc((size_t)r->gx * (size_t)r->gy, sizeof(double));
    r->d = mj_makeData(m);
    if (r->is_robot == NULL || r->agent_of_body == NULL || r->agent_body == NULL ||
        r->part_force_n == NULL || r->rgb == NULL || r->density == NULL || r->d == NULL ||
        alloc_slots(r) < 0) {
        ps_err_format(err, err_len, "render: out of memory");
        rc = -ENOMEM;
        goto fail;
    }
    for (int b = 0; b < m->nbody; b++) {
        r->is_robot[b] = m->body_rootid[b] == m->body_rootid[r->root];
        r->agent_of_body[b] = -1;
    }
    for (int i = 0;; i++) {
        char name[32];
        (void)snprintf(name, sizeof(name), "agent%d", i);
        const int b = mj_name2id(m, mjOBJ_BODY, name);
        (void)snprintf(name, sizeof(name), "agent%d_ring", i);
        const int ring = mj_name2id(m, mjOBJ_BODY, name);
        if (b < 0 || ring < 0)
            break;
        r->agent_of_body[b] = r->agent_of_body[ring] = i;
        r->agent_body[r->n_agents++] = ring;
    }
    if (cfg->is_view) {
        rc = ps_gl_open_window(&r->gl, cfg->width, cfg->height, "pushstep: the crowd", err,
                               err_len);
        if (rc < 0)
            goto fail;
        ps_gl_release(&r->gl); /* the renderer thread takes it */
    }
    *out = r;
    return 0;
fail:
    ps_render_destroy(r);
    return rc;
}

double ps_render_fps(const ps_render_t *r)
{
    return r->cfg.fps;
}

/* ---- the plant's side ---------------------------------------------------------- */

void ps_render_offer(ps_render_t *r, const mjData *d)
{
    const mjModel *m = r->m;
    unsigned head = atomic_load_explicit(&r->head, memory_order_relaxed);
    while (head - atomic_load_explicit(&r->tail, memory_order_acquire) >= N_SLOTS) {
        if (!r->cfg.is_lockstep || !atomic_load(&r->is_running)) {
            atomic_fetch_add(&r->n_dropped, 1);
            return;
        }
        const struct timespec ts = {0, 1000000};
        (void)nanosleep(&ts, NULL);
    }
    slot_t *s = &r->slot[head % N_SLOTS];
    s->time = d->time;
    memcpy(s->qpos, d->qpos, (size_t)m->nq * sizeof(mjtNum));
    memcpy(s->qvel, d->qvel, (size_t)m->nv * sizeof(mjtNum));
    memcpy(s->act, d->act, (size_t)m->na * sizeof(mjtNum));
    memcpy(s->ctrl, d->ctrl, (size_t)m->nu * sizeof(mjtNum));
    memcpy(s->qfrc, d->qfrc_applied, (size_t)m->nv * sizeof(mjtNum));
    memcpy(s->xfrc, d->xfrc_applied, 6 * (size_t)m->nbody * sizeof(mjtNum));
    memcpy(s->mpos, d->mocap_pos, 3 * (size_t)m->nmocap * sizeof(mjtNum));
    memcpy(s->mquat, d->mocap_quat, 4 * (size_t)m->nmocap * sizeof(mjtNum));
    memcpy(s->warm, d->qacc_warmstart, (size_t)m->nv * sizeof(mjtNum));
    atomic_store_explicit(&r->head, head + 1, memory_order_release);
}

/* ---- drawing --------------------------------------------------------------------- */

static void force_colour(double f_n, float rgba[4])
{
    const double s = f_n / FORCE_RED_N > 1.0 ? 1.0 : f_n / FORCE_RED_N;
    rgba[0] = 1.0f;
    rgba[1] = (float)(0.9 * (1.0 - s));
    rgba[2] = 0.05f;
    rgba[3] = 1.0f;
}

/* Arrows for the crowd's contacts on the robot, and each part's load. */
static void add_force_arrows(ps_render_t *r)
{
    const mjModel *m = r->m;
    mjData *d = r->d;
    memset(r->part_force_n, 0, (size_t)m->nbody * sizeof(double));
    for (int k = 0; k < d->ncon; k++) {
        const mjContact *con = &d->contact[k];
        const int b1 = m->geom_bodyid[con->geom1], b2 = m->geom_bodyid[con->geom2];
        const bool is_r1 = r->is_robot[b1] && !r->is_robot[b2] && b2 != 0;
        const bool is_r2 = r->is_robot[b2] && !r->is_robot[b1] && b1 != 0;
        if (!is_r1 && !is_r2)
            continue;
        mjtNum f[6];
        mj_contactForce(m, d, k, f);
        /* f acts on geom2, in the contact frame (normal first) */
        double fw[3];
        for (int q = 0; q < 3; q++)
            fw[q] = con->frame[q] * f[0] + con->frame[3 + q] * f[1] + con->frame[6 + q] * f[2];
        const double sign = is_r2 ? 1.0 : -1.0;
        const double mag = sqrt(fw[0] * fw[0] + fw[1] * fw[1] + fw[2] * fw[2]);
        r->part_force_n[is_r2 ? b2 : b1] += mag;
        if (mag < 1.0 || r->scn.ngeom >= r->scn.maxgeom)
            continue;
        double len = mag * ARROW_M_PER_N;
        len = len > ARROW_MAX_M ? ARROW_MAX_M : len;
        const double *p = con->pos;
        mjvGeom *g = &r->scn.geoms[r->scn.ngeom++];
        float rgba[4];
        force_colour(mag, rgba);
        mjv_initGeom(g, mjGEOM_ARROW, NULL, NULL, NULL, rgba);
        /* from outside, pointing into the part */
        mjv_makeConnector(g, mjGEOM_ARROW, 0.025, p[0] - sign * fw[0] / mag * len,
                          p[1] - sign * fw[1] / mag * len, p[2] - sign * fw[2] / mag * len, p[0],
                          p[1], p[2]);
        g->segid = -1;
        g->objtype = mjOBJ_UNKNOWN;
        g->objid = -1;
    }
    /* see through the people to the robot; tint its parts under load */
    for (int i = 0; i < r->scn.ngeom; i++) {
        mjvGeom *g = &r->scn.geoms[i];
        if (g->objtype != mjOBJ_GEOM || g->objid < 0)
            continue;
        const int b = m->geom_bodyid[g->objid];
        if (r->agent_of_body[b] >= 0)
            g->rgba[3] = AGENT_ALPHA;
        if (!r->is_robot[b] || r->part_force_n[b] < PART_TINT_N)
            continue;
        float c[4];
        force_colour(r->part_force_n[b], c);
        for (int q = 0; q < 3; q++)
            g->rgba[q] = 0.4f * g->rgba[q] + 0.6f * c[q];
    }
}

static void accumulate_density(ps_render_t *r)
{
    const double *a = r->cfg.area_m;
    const int reach = (int)ceil(3.0 * DENSITY_SIGMA / DENSITY_CELL_M);
    const double norm = 1.0 / (2.0 * M_PI * DENSITY_SIGMA * DENSITY_SIGMA);
    for (int i = 0; i < r->n_agents; i++) {
        const mjtNum *p = r->d->xpos + 3 * r->agent_body[i];
        const int cx = (int)floor((p[0] - a[0]) / DENSITY_CELL_M);
        const int cy = (int)floor((p[1] - a[1]) / DENSITY_CELL_M);
        for (int y = cy - reach; y <= cy + reach; y++) {
            for (int x = cx - reach; x <= cx + reach; x++) {
                if (x < 0 || y < 0 || x >= r->gx || y >= r->gy)
                    continue;
                const double dx = a[0] + (x + 0.5) * DENSITY_CELL_M - p[0];
                const double dy = a[1] + (y + 0.5) * DENSITY_CELL_M - p[1];
                r->density[(size_t)y * r->gx + x] +=
                    norm * exp(-(dx * dx + dy * dy) / (2.0 * DENSITY_SIGMA * DENSITY_SIGMA));
            }
        }
    }
}

/* Pixels of robot geoms, of agents, and agents with a pixel, in a
 * segmentation render (each geom coloured by its scene index). */
static void count_ids(ps_render_t *r, mjrRect vp, uint32_t *robot_px, uint32_t *agent_px,
                      uint32_t *n_agents_seen)
{
    const mjModel *m = r->m;
    r->scn.flags[mjRND_SEGMENT] = 1;
    r->scn.flags[mjRND_IDCOLOR] = 1;
    mjr_render(vp, &r->scn, &r->con);
    mjr_readPixels(r->rgb, NULL, vp, &r->con);
    r->scn.flags[mjRND_SEGMENT] = 0;
    r->scn.flags[mjRND_IDCOLOR] = 0;
    unsigned char *seen = calloc((size_t)(r->n_agents + 1), 1);
    *robot_px = *agent_px = *n_agents_seen = 0;
    const size_t n = (size_t)vp.width * (size_t)vp.height;
    for (size_t k = 0; k < n; k++) {
        const unsigned char *c = r->rgb + 3 * k;
        const int id = (c[0] | c[1] << 8 | c[2] << 16) - 1;
        if (id < 0 || id >= r->scn.ngeom)
            continue;
        const mjvGeom *g = &r->scn.geoms[id];
        if (g->objtype != mjOBJ_GEOM || g->objid < 0)
            continue;
        const int b = m->geom_bodyid[g->objid];
        *robot_px += r->is_robot[b] ? 1u : 0u;
        const int ag = r->agent_of_body[b];
        if (ag >= 0) {
            (*agent_px)++;
            if (seen != NULL && !seen[ag]) {
                seen[ag] = 1;
                (*n_agents_seen)++;
            }
        }
    }
    free(seen);
}

/* What the frame shows: the people as drawn, and the robot through them
 * (they are translucent; segmentation draws everything opaque, so the robot
 * is counted with the people's geoms moved out of sight). */
static void census(ps_render_t *r, mjrRect vp)
{
    uint32_t robot_px;
    count_ids(r, vp, &robot_px, &r->agent_px, &r->n_agents_seen);
    mjtNum z_saved[EXTRA_GEOMS];
    int n_moved = 0;
    for (int i = 0; i < r->scn.ngeom; i++) {
        mjvGeom *g = &r->scn.geoms[i];
        if (g->objtype == mjOBJ_GEOM && g->objid >= 0 &&
            r->agent_of_body[r->m->geom_bodyid[g->objid]] >= 0 && n_moved < EXTRA_GEOMS) {
            z_saved[n_moved++] = g->pos[2];
            g->pos[2] -= 1000.0f;
        }
    }
    uint32_t agent_px, n_seen;
    count_ids(r, vp, &r->robot_px, &agent_px, &n_seen);
    n_moved = 0;
    for (int i = 0; i < r->scn.ngeom; i++) {
        mjvGeom *g = &r->scn.geoms[i];
        if (g->objtype == mjOBJ_GEOM && g->objid >= 0 &&
            r->agent_of_body[r->m->geom_bodyid[g->objid]] >= 0 && n_moved < EXTRA_GEOMS)
            g->pos[2] = (float)z_saved[n_moved++];
    }
    (void)robot_px;
}

static int write_png(const char *path, const unsigned char *rgb, int w, int h, bool is_bottom_up,
                     const char *comment)
{
    FILE *f = fopen(path, "wb");
    if (f == NULL)
        return -errno;
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
    png_infop info = png != NULL ? png_create_info_struct(png) : NULL;
    if (png == NULL || info == NULL) {
        png_destroy_write_struct(&png, &info);
        (void)fclose(f);
        return -ENOMEM;
    }
    if (setjmp(png_jmpbuf(png))) {
        png_destroy_write_struct(&png, &info);
        (void)fclose(f);
        return -EIO;
    }
    png_init_io(png, f);
    png_set_compression_level(png, 1);
    png_set_IHDR(png, info, (png_uint_32)w, (png_uint_32)h, 8, PNG_COLOR_TYPE_RGB,
                 PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    if (comment != NULL) {
        png_text t = {.compression = PNG_TEXT_COMPRESSION_NONE,
                      .key = (png_charp) "Comment",
                      .text = (png_charp)comment};
        png_set_text(png, info, &t, 1);
    }
    png_write_info(png, info);
    for (int y = 0; y < h; y++) {
        const int row = is_bottom_up ? h - 1 - y : y;
        png_write_row(png, (png_const_bytep)(rgb + 3 * (size_t)w * (size_t)row));
    }
    png_write_end(png, NULL);
    png_destroy_write_struct(&png, &info);
    return fclose(f) == 0 ? 0 : -EIO;
}

static void render_one(ps_render_t *r, const slot_t *s)
{
    const mjModel *m = r->m;
    mjData *d = r->d;
    d->time = s->time;
    memcpy(d->qpos, s->qpos, (size_t)m->nq * sizeof(mjtNum));
    memcpy(d->qvel, s->qvel, (size_t)m->nv * sizeof(mjtNum));
    memcpy(d->act, s->act, (size_t)m->na * sizeof(mjtNum));
    memcpy(d->ctrl, s->ctrl, (size_t)m->nu * sizeof(mjtNum));
    memcpy(d->qfrc_applied, s->qfrc, (size_t)m->nv * sizeof(mjtNum));
    memcpy(d->xfrc_applied, s->xfrc, 6 * (size_t)m->nbody * sizeof(mjtNum));
    memcpy(d->mocap_pos, s->mpos, 3 * (size_t)m->nmocap * sizeof(mjtNum));
    memcpy(d->mocap_quat, s->mquat, 4 * (size_t)m->nmocap * sizeof(mjtNum));
    memcpy(d->qacc_warmstart, s->warm, (size_t)m->nv * sizeof(mjtNum));
    mj_forward(m, d); /* contacts and their forces as the step saw them */
    /* follow the robot */
    const mjtNum *root = d->xpos + 3 * r->root;
    r->cam.lookat[0] = root[0];
    r->cam.lookat[1] = root[1];
    r->cam.lookat[2] = 0.6;
    mjv_updateScene(m, d, &r->opt, NULL, &r->cam, mjCAT_ALL, &r->scn);
    add_force_arrows(r);
    accumulate_density(r);
    const mjrRect vp = {0, 0, r->cfg.width, r->cfg.height};
    double total = 0.0;
    for (int b = 0; b < m->nbody; b++)
        total += r->part_force_n[b];
    uint32_t n_down = 0;
    for (int i = 0; i < r->n_agents; i++)
        n_down += d->xpos[3 * r->agent_body[i] + 2] < 0.45 ? 1u : 0u;
    char title[128], line[160];
    (void)snprintf(title, sizeof(title), "t = %.2f s", d->time);
    (void)snprintf(line, sizeof(line),
                   "%d people, %u down; crowd force on the robot %.0f N (arrows: 1 m = 500 N)",
                   r->n_agents, n_down, total);
    if (r->dir[0] != '\0' || r->cfg.is_census) {
        mjr_setBuffer(mjFB_OFFSCREEN, &r->con);
        if (r->cfg.is_census)
            census(r, vp);
        mjr_render(vp, &r->scn, &r->con);
        mjr_overlay(mjFONT_NORMAL, mjGRID_TOPLEFT, vp, title, line, &r->con);
        mjr_readPixels(r->rgb, NULL, vp, &r->con);
        if (r->dir[0] != '\0' && r->write_rc == 0) {
            char path[600];
            (void)snprintf(path, sizeof(path), "%s/frame_%05llu.png", r->dir,
                           (unsigned long long)r->n_frames);
            const int rc = write_png(path, r->rgb, r->cfg.width, r->cfg.height, true, NULL);
            if (rc < 0) {
                r->write_rc = rc;
                (void)snprintf(r->write_err, sizeof(r->write_err), "%s: %s", path,
                               strerror(-rc));
            }
        }
    }
    if (r->cfg.is_view && !r->was_view_closed) {
        int w, h;
        ps_gl_window_size(&r->gl, &w, &h);
        const mjrRect wv = {0, 0, w, h};
        mjr_setBuffer(mjFB_WINDOW, &r->con);
        mjr_render(wv, &r->scn, &r->con);
        mjr_overlay(mjFONT_NORMAL, mjGRID_TOPLEFT, wv, title, line, &r->con);
        r->was_view_closed = !ps_gl_show(&r->gl);
    }
    r->n_frames++;
}

static void *render_thread(void *arg)
{
    ps_render_t *r = arg;
    int rc = r->cfg.is_view ? ps_gl_make_current(&r->gl)
                            : ps_gl_open_offscreen(&r->gl, r->start_err, sizeof(r->start_err));
    if (rc < 0 && r->cfg.is_view)
        (void)snprintf(r->start_err, sizeof(r->start_err), "render: the window's context");
    if (rc == 0) {
        mjv_defaultCamera(&r->cam);
        r->cam.type = mjCAMERA_FREE;
        r->cam.distance = 5.0;
        r->cam.azimuth = 135.0;
        r->cam.elevation = -45.0;
        mjv_defaultOption(&r->opt);
        mjv_defaultScene(&r->scn);
        mjv_makeScene(r->m, &r->scn, r->m->ngeom + EXTRA_GEOMS);
        mjr_defaultContext(&r->con);
        mjr_makeContext(r->m, &r->con, mjFONTSCALE_100);
        if (r->con.offFBO == 0) {
            (void)snprintf(r->start_err, sizeof(r->start_err),
                           "render: MuJoCo could not make its offscreen buffer");
            rc = -EIO;
        }
    }
    r->start_rc = rc;
    atomic_store(&r->is_ready, true);
    if (rc < 0)
        return NULL;
    for (;;) {
        const unsigned tail = atomic_load_explicit(&r->tail, memory_order_relaxed);
        if (tail == atomic_load_explicit(&r->head, memory_order_acquire)) {
            if (!atomic_load(&r->is_running))
                break;
            const struct timespec ts = {0, 2000000};
            (void)nanosleep(&ts, NULL);
            continue;
        }
        render_one(r, &r->slot[tail % N_SLOTS]);
        atomic_store_explicit(&r->tail, tail + 1, memory_order_release);
    }
    mjr_freeContext(&r->con);
    mjv_freeScene(&r->scn);
    ps_gl_release(&r->gl);
    return NULL;
}

int ps_render_start(ps_render_t *r, char *err, size_t err_len)
{
    atomic_store(&r->is_running, true);
    atomic_store(&r->is_ready, false);
    if (pthread_create(&r->thread, NULL, render_thread, r) != 0) {
        atomic_store(&r->is_running, false);
        ps_err_format(err, err_len, "render: no thread");
        return -ENOMEM;
    }
    r->has_thread = true;
    while (!atomic_load(&r->is_ready)) {
        const struct timespec ts = {0, 1000000};
        (void)nanosleep(&ts, NULL);
    }
    if (r->start_rc < 0) {
        atomic_store(&r->is_running, false);
        (void)pthread_join(r->thread, NULL);
        r->has_thread = false;
        ps_err_format(err, err_len, "%s", r->start_err);
        return r->start_rc;
    }
    return 0;
}

/* ---- the end ----------------------------------------------------------------------- */

/* 0 .. 1 to a blue - cyan - yellow - red scale */
static void heat(double s, unsigned char out[3])
{
    static const double STOPS[5][3] = {
        {0.05, 0.05, 0.35}, {0.1, 0.45, 0.85}, {0.3, 0.85, 0.75}, {0.95, 0.85, 0.2}, {0.6, 0.0, 0.0}};
    s = s < 0.0 ? 0.0 : (s > 1.0 ? 1.0 : s);
    const double x = s * 4.0;
    const int i = x >= 4.0 ? 3 : (int)x;
    const double f = x - i;
    for (int q = 0; q < 3; q++)
        out[q] = (unsigned char)lround(255.0 * (STOPS[i][q] * (1.0 - f) + STOPS[i + 1][q] * f));
}

static void dot(unsigned char *img, int w, int h, double cx, double cy, double rad, double ring,
                const unsigned char c[3])
{
    for (int y = (int)(cy - rad - 1); y <= (int)(cy + rad + 1); y++) {
        for (int x = (int)(cx - rad - 1); x <= (int)(cx + rad + 1); x++) {
            if (x < 0 || y < 0 || x >= w || y >= h)
                continue;
            const double dd = hypot(x + 0.5 - cx, y + 0.5 - cy);
            if (dd <= rad && dd >= rad - ring)
                memcpy(img + 3 * ((size_t)y * w + x), c, 3);
        }
    }
}

static int write_density(ps_render_t *r)
{
    const int w = r->gx * DENSITY_PX, h = r->gy * DENSITY_PX + 4 * DENSITY_PX;
    unsigned char *img = calloc(3u * (size_t)w * (size_t)h, 1);
    if (img == NULL)
        return -ENOMEM;
    const double n = r->n_frames > 0 ? (double)r->n_frames : 1.0;
    /* y up in the world, down in the image */
    for (int y = 0; y < r->gy * DENSITY_PX; y++) {
        const int cy = r->gy - 1 - y / DENSITY_PX;
        for (int x = 0; x < w; x++) {
            const double v = r->density[(size_t)cy * r->gx + x / DENSITY_PX] / n;
            heat(v / DENSITY_MAX, img + 3 * ((size_t)y * w + x));
        }
    }
    /* the scale under the map: 0 to DENSITY_MAX left to right */
    for (int y = r->gy * DENSITY_PX + DENSITY_PX; y < h - DENSITY_PX; y++)
        for (int x = 0; x < w; x++)
            heat((double)x / (w - 1), img + 3 * ((size_t)y * w + x));
    const double *a = r->cfg.area_m;
    const double px_per_m = DENSITY_PX / DENSITY_CELL_M;
    const unsigned char black[3] = {0, 0, 0}, white[3] = {255, 255, 255};
    for (int i = 0; i < r->n_agents; i++) {
        const mjtNum *p = r->d->xpos + 3 * r->agent_body[i];
        dot(img, w, r->gy * DENSITY_PX, (p[0] - a[0]) * px_per_m,
            r->gy * DENSITY_PX - (p[1] - a[1]) * px_per_m, 2.5, 2.5, black);
    }
    const mjtNum *rp = r->d->xpos + 3 * r->root;
    dot(img, w, r->gy * DENSITY_PX, (rp[0] - a[0]) * px_per_m,
        r->gy * DENSITY_PX - (rp[1] - a[1]) * px_per_m, 0.25 * px_per_m, 3.0, white);
    char path[600], comment[256];
    (void)snprintf(path, sizeof(path), "%s/density.png", r->dir);
    (void)snprintf(comment, sizeof(comment),
                   "pushstep crowd density over %llu frames, area x %.2f..%.2f m, y %.2f..%.2f "
                   "m, colour 0 (dark blue) to %.0f / m^2 (dark red), bar below; white ring: "
                   "the robot, black dots: people, at the end",
                   (unsigned long long)r->n_frames, a[0], a[2], a[1], a[3], DENSITY_MAX);
    const int rc = write_png(path, img, w, h, false, comment);
    free(img);
    if (rc < 0)
        (void)snprintf(r->write_err, sizeof(r->write_err), "%s: %s", path, strerror(-rc));
    return rc;
}

static int run_ffmpeg(ps_render_t *r)
{
    char fps[32], in[600], out[600];
    (void)snprintf(fps, sizeof(fps), "%g", r->cfg.fps);
    (void)snprintf(in, sizeof(in), "%s/frame_%%05d.png", r->dir);
    (void)snprintf(out, sizeof(out), "%s/crowd.mp4", r->dir);
    char *const argv[] = {"ffmpeg", "-hide_banner", "-loglevel", "error", "-y", "-framerate",
                          fps, "-i", in, "-c:v", "libx264", "-pix_fmt", "yuv420p", "-crf",
                          "23", out, NULL};
    const pid_t pid = fork();
    if (pid < 0)
        return -errno;
    if (pid == 0) {
        execvp("ffmpeg", argv);
        _exit(127);
    }
    int status = 0;
    while (waitpid(pid, &status, 0) < 0) {
        if (errno != EINTR)
            return -errno;
    }
    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
        (void)snprintf(r->write_err, sizeof(r->write_err),
                       "ffmpeg (Debian package ffmpeg) failed making %s (exit %d)", out,
                       WIFEXITED(status) ? WEXITSTATUS(status) : -1);
        return -EIO;
    }
    return 0;
}

int ps_render_finish(ps_render_t *r, ps_render_result_t *out, char *err, size_t err_len)
{
    memset(out, 0, sizeof(*out));
    if (r->has_thread) {
        atomic_store(&r->is_running, false);
        (void)pthread_join(r->thread, NULL);
        r->has_thread = false;
    }
    out->n_frames = r->n_frames;
    out->n_dropped = atomic_load(&r->n_dropped);
    out->was_view_closed = r->was_view_closed;
    out->robot_px = r->robot_px;
    out->agent_px = r->agent_px;
    out->n_agents_seen = r->n_agents_seen;
    int rc = r->write_rc;
    if (r->dir[0] != '\0' && rc == 0) {
        rc = write_density(r);
        out->is_density = rc == 0;
        if (rc == 0 && r->n_frames > 0) {
            rc = run_ffmpeg(r);
            out->is_mp4 = rc == 0;
        }
    }
    if (rc < 0)
        ps_err_format(err, err_len, "render: %s", r->write_err);
    return rc < 0 ? -EIO : 0;
}

void ps_render_destroy(ps_render_t *r)
{
    if (r == NULL)
        return;
    if (r->has_thread) {
        atomic_store(&r->is_running, false);
        (void)pthread_join(r->thread, NULL);
    }
    ps_gl_close(&r->gl);
    for (unsigned k = 0; k < N_SLOTS; k++) {
        slot_t *s = &r->slot[k];
        free(s->qpos);
        free(s->qvel);
        free(s->act);
        free(s->ctrl);
        free(s->qfrc);
        free(s->xfrc);
        free(s->mpos);
        free(s->mquat);
        free(s->warm);
    }
    if (r->d != NULL)
        mj_deleteData(r->d);
    if (r->m != NULL)
        mj_deleteModel(r->m);
    free(r->is_robot);
    free(r->agent_of_body);
    free(r->agent_body);
    free(r->part_force_n);
    free(r->rgb);
    free(r->density);
    free(r);
}
