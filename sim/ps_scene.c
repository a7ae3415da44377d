#include "ps_scene.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../rt/ps_err.h"

#define SQRT3          1.7320508075688772
#define JITTER_FRAC    0.05 /* lattice jitter, fraction of the spacing */
#define RANDOM_GAP_M   0.15 /* random layout: free gap between bodies (A exp(-gap/B) stays ~300 N) */
#define RANDOM_TRIES   20000u
#define WALL_HALF_T_M  0.05
#define WALL_HEIGHT_M  2.0
#define OBST_HEIGHT_M  1.5
#define ARENA_WALL_HEIGHT_M 1.2
#define WALL_SEG_M     2.0 /* longest box of a wall */
#define PIVOT_MASS_FRAC 0.15 /* feet and shanks: the base */
#define TAG_HEIGHT_FRAC     0.80 /* plate centres: height over the person's */
#define TAG_SIDE_FRAC       0.11 /* and off the axis, sideways */
#define TAG_GAP_M           0.002
#define TAG_HALF_T_M        0.003

/* ---- seeded generator (splitmix64) --------------------------------------- */

typedef struct {
    uint64_t s;
} rng_t;

static uint64_t rng_next(rng_t *r)
{
    uint64_t z = (r->s += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

static double rng_uniform(rng_t *r)
{
    return (double)(rng_next(r) >> 11) * (1.0 / 9007199254740992.0);
}

/* Standard normal (Box-Muller), clamped to +-2.5 sd. */
static double rng_normal(rng_t *r)
{
    double u1 = rng_uniform(r);
    const double u2 = rng_uniform(r);
    u1 = u1 < 1e-12 ? 1e-12 : u1;
    double z = sqrt(-2.0 * log(u1)) * cos(2.0 * M_PI * u2);
    return z < -2.5 ? -2.5 : (z > 2.5 ? 2.5 : z);
}

/* ---- placement ------------------------------------------------------------ */

static bool is_blocked(const ps_crowd_cfg_t *cfg, const ps_crowd_group_cfg_t *g,
                       const double robot_xy[2], double x, double y, double r)
{
    const double dx = x - robot_xy[0], dy = y - robot_xy[1];
    if (sqrt(dx * dx + dy * dy) < (double)g->clear_m)
        return true;
    for (uint32_t k = 0; k < cfg->n_obstacles; k++) {
        const ps_crowd_obstacle_cfg_t *o = &cfg->obstacles[k];
        const double ox = x - o->x_m, oy = y - o->y_m;
        if (sqrt(ox * ox + oy * oy) < (double)o->radius_m + r)
            return true;
    }
    return false;
}

static void draw_body(const ps_crowd_cfg_t *cfg, const ps_crowd_group_cfg_t *g, rng_t *rng,
                      uint32_t group_idx, ps_crowd_agent_spec_t *a)
{
    a->height_m = g->height_m + g->height_sd_m * rng_normal(rng);
    a->mass_kg = g->mass_kg + g->mass_sd_kg * rng_normal(rng);
    a->radius_m = g->radius_m + g->radius_sd_m * rng_normal(rng);
    const double v0 = g->speed_m_s > 0.0f ? g->speed_m_s : cfg->social.v0_m_s;
    a->v0_m_s = v0 + g->speed_sd_m_s * rng_normal(rng);
    a->v0_m_s = a->v0_m_s < 0.0 ? 0.0 : a->v0_m_s;
    a->group_idx = group_idx;
}

static double rect_area(const ps_crowd_rect_t *r)
{
    return ((double)r->x_max_m - r->x_min_m) * ((double)r->y_max_m - r->y_min_m);
}

/* Lattice points of spacing a in the region (half a cell from its edges),
 * outside the robot's clearance and the obstacles; at most max of them. */
static uint32_t lattice_points(const ps_crowd_cfg_t *cfg, const ps_crowd_group_cfg_t *g,
                               const double robot_xy[2], double a, double *out_xy, uint32_t max)
{
    const ps_crowd_rect_t *r = &g->region;
    const double row = a * SQRT3 / 2.0;
    uint32_t n = 0;
    int k = 0;
    for (double y = r->y_min_m + row / 2.0; y <= r->y_max_m - row / 2.0 + 1e-9; y += row, k++) {
        for (double x = r->x_min_m + (k % 2 ? a : a / 2.0); x <= r->x_max_m - a / 2.0 + 1e-9;
             x += a) {
            if (is_blocked(cfg, g, robot_xy, x, y, g->radius_m))
                continue;
            if (n < max) {
                out_xy[2 * n] = x;
                out_xy[2 * n + 1] = y;
            }
            n++;
        }
    }
    return n;
}

/* A hexagonal lattice holding the group's count (or density x area) in its
 * region: the nominal spacing sqrt(2 / (sqrt(3) density)) shrunk in 1 %
 * steps until the region's edges and the robot's clearance leave room, so
 * the region as a whole holds the density asked for. */
static int place_lattice(const ps_crowd_cfg_t *cfg, uint32_t gi, rng_t *rng,
                         const double robot_xy[2], ps_crowd_agent_spec_t *out, uint32_t room,
                         uint32_t *out_n)
{
    const ps_crowd_group_cfg_t *g = &cfg->groups[gi];
    const double area = rect_area(&g->region);
    const uint32_t want =
        g->count > 0 ? g->count : (uint32_t)lround((double)g->density_m2 * area);
    const double density = (double)want / area;
    if (want > room)
        return -ENOSPC;
    double *xy = malloc(2u * (size_t)(want + 1u) * sizeof(double));
    if (xy == NULL)
        return -ENOMEM;
    const double a0 = sqrt(2.0 / (SQRT3 * density));
    double a = a0;
    uint32_t n = 0;
    for (int shrink = 0; shrink <= 30; shrink++) {
        a = a0 * (1.0 - 0.01 * shrink);
        n = lattice_points(cfg, g, robot_xy, a, xy, want);
        if (n >= want)
            break;
    }
    if (n < want) {
        free(xy);
        *out_n = n;
        return -ERANGE;
    }
    for (uint32_t i = 0; i < want; i++) {
        out[i].x_m = xy[2 * i] + JITTER_FRAC * a * (2.0 * rng_uniform(rng) - 1.0);
        out[i].y_m = xy[2 * i + 1] + JITTER_FRAC * a * (2.0 * rng_uniform(rng) - 1.0);
        draw_body(cfg, g, rng, gi, &out[i]);
    }
    free(xy);
    *out_n = want;
    return 0;
}

static int place_random(const ps_crowd_cfg_t *cfg, uint32_t gi, rng_t *rng,
                        const double robot_xy[2], const ps_crowd_agent_spec_t *placed,
                        uint32_t n_placed, ps_crowd_agent_spec_t *out, uint32_t room,
                        uint32_t *out_n)
{
    const ps_crowd_group_cfg_t *g = &cfg->groups[gi];
    const ps_crowd_rect_t *r = &g->region;
    const uint32_t want = g->count > 0 ? g->count
                                       : (uint32_t)lround((double)g->density_m2 * rect_area(r));
    if (want > room)
        return -ENOSPC;
    uint32_t n = 0;
    for (uint32_t tries = 0; n < want && tries < RANDOM_TRIES * (want + 1u); tries++) {
        ps_crowd_agent_spec_t a;
        draw_body(cfg, g, rng, gi, &a);
        /* the body inside the region, a gap from its edges */
        const double e = a.radius_m + RANDOM_GAP_M;
        a.x_m = r->x_min_m + e + rng_uniform(rng) * ((double)r->x_max_m - r->x_min_m - 2.0 * e);
        a.y_m = r->y_min_m + e + rng_uniform(rng) * ((double)r->y_max_m - r->y_min_m - 2.0 * e);
        if (is_blocked(cfg, g, robot_xy, a.x_m, a.y_m, a.radius_m))
            continue;
        bool is_free = true;
        for (uint32_t k = 0; k < n_placed + n && is_free; k++) {
            const ps_crowd_agent_spec_t *o = k < n_placed ? &placed[k] : &out[k - n_placed];
            const double dx = a.x_m - o->x_m, dy = a.y_m - o->y_m;
            is_free = sqrt(dx * dx + dy * dy) >= a.radius_m + o->radius_m + RANDOM_GAP_M;
        }
        if (is_free)
            out[n++] = a;
    }
    *out_n = n;
    return n == want ? 0 : -ERANGE;
}

static void place_line(const ps_crowd_cfg_t *cfg, uint32_t gi, rng_t *rng,
                       ps_crowd_agent_spec_t *out, uint32_t n)
{
    const ps_crowd_group_cfg_t *g = &cfg->groups[gi];
    const ps_crowd_rect_t *r = &g->region;
    double u[2] = {(double)r->x_max_m - r->x_min_m, (double)r->y_max_m - r->y_min_m};
    const double len = sqrt(u[0] * u[0] + u[1] * u[1]);
    u[0] = len > 0.0 ? u[0] / len : 1.0;
    u[1] = len > 0.0 ? u[1] / len : 0.0;
    for (uint32_t k = 0; k < n; k++) {
        out[k].x_m = r->x_min_m + (double)k * g->spacing_m * u[0];
        out[k].y_m = r->y_min_m + (double)k * g->spacing_m * u[1];
        draw_body(cfg, g, rng, gi, &out[k]);
    }
}

/* An agent faces where its goal lies at the start: along its direction, at
 * its point, or at the robot (goals robot and hold: people standing about a
 * robot look at it). It never turns (the agent has no yaw joint), so the
 * facing is also where its tags look. */
static void set_facing(const ps_crowd_cfg_t *cfg, const double robot_xy[2],
                       ps_crowd_agent_spec_t *a)
{
    const ps_crowd_group_cfg_t *g = &cfg->groups[a->group_idx];
    double v[2] = {robot_xy[0] - a->x_m, robot_xy[1] - a->y_m};
    if (g->goal == PS_CROWD_GOAL_DIRECTION) {
        v[0] = g->goal_xy[0];
        v[1] = g->goal_xy[1];
    } else if (g->goal == PS_CROWD_GOAL_POINT) {
        v[0] = g->goal_xy[0] - a->x_m;
        v[1] = g->goal_xy[1] - a->y_m;
    }
    a->facing_rad = v[0] * v[0] + v[1] * v[1] > 1e-12 ? atan2(v[1], v[0]) : 0.0;
}

int ps_scene_place(const ps_crowd_cfg_t *cfg, uint32_t seed, const double robot_xy[2],
                   ps_crowd_agent_spec_t *out, uint32_t max, uint32_t *out_n, char *err,
                   size_t err_len)
{
    rng_t rng = {.s = 0x5eed0000ull ^ (uint64_t)seed};
    uint32_t n = 0;
    for (uint32_t gi = 0; gi < cfg->n_groups; gi++) {
        const ps_crowd_group_cfg_t *g = &cfg->groups[gi];
        uint32_t got = 0;
        int rc = 0;
        if (g->layout == PS_CROWD_LAYOUT_LINE) {
            if (g->count > max - n)
                rc = -ENOSPC;
            else
                place_line(cfg, gi, &rng, out + n, g->count);
            got = g->count;
        } else if (g->layout == PS_CROWD_LAYOUT_RANDOM) {
            rc = place_random(cfg, gi, &rng, robot_xy, out, n, out + n, max - n, &got);
        } else {
            rc = place_lattice(cfg, gi, &rng, robot_xy, out + n, max - n, &got);
        }
        if (rc == -ENOSPC) {
            ps_err_format(err, err_len, "crowd.groups[%u] (%s): more than %u agents in all", gi,
                          g->name, max);
            return -PS_ERR_CONFIG;
        }
        if (rc == -ENOMEM) {
            ps_err_format(err, err_len, "crowd: out of memory");
            return rc;
        }
        if (rc < 0) {
            const uint32_t want = g->count > 0 ? g->count
                                               : (uint32_t)lround((double)g->density_m2 *
                                                                  rect_area(&g->region));
            ps_err_format(err, err_len,
                          "crowd.groups[%u] (%s): its region holds only %u of its %u agents", gi,
                          g->name, got, want);
            return -PS_ERR_CONFIG;
        }
        n += got;
    }
    for (uint32_t i = 0; i < n; i++)
        set_facing(cfg, robot_xy, &out[i]);
    *out_n = n;
    return 0;
}

/* ---- MJCF ------------------------------------------------------------------ */

void ps_scene_sizes(uint32_t n_agents, int robot_nconmax, int robot_njmax, int *out_nconmax,
                    int *out_njmax)
{
    /* A packed agent touches about six others and the robot: some three
     * contacts of its own, four rows each under a pyramidal cone, plus two
     * tilt limits when it lies down. Measured on concert-6 (200 agents):
     * fewer than 1.5 contacts and 6 rows per agent. */
    *out_nconmax = robot_nconmax + 50 + 4 * (int)n_agents;
    *out_njmax = robot_njmax + 200 + 12 * (int)n_agents;
}

static const float GROUP_RGBA[][3] = {
    {0.20f, 0.45f, 0.80f}, {0.85f, 0.55f, 0.15f}, {0.30f, 0.65f, 0.30f}, {0.60f, 0.35f, 0.70f},
    {0.75f, 0.70f, 0.25f}, {0.25f, 0.65f, 0.70f}, {0.70f, 0.40f, 0.45f}, {0.50f, 0.50f, 0.50f},
};

static void write_box(FILE *f, const char *name, double x0, double y0, double x1, double y1,
                      double h, const char *rgba)
{
    const double cx = (x0 + x1) / 2.0, cy = (y0 + y1) / 2.0;
    const double len = sqrt((x1 - x0) * (x1 - x0) + (y1 - y0) * (y1 - y0));
    const double ang = atan2(y1 - y0, x1 - x0);
    fprintf(f,
            "    <geom name=\"%s\" type=\"box\" pos=\"%.4f %.4f %.4f\" "
            "quat=\"%.6f 0 0 %.6f\" size=\"%.4f %.4f %.4f\" contype=\"16\" conaffinity=\"3\" "
            "condim=\"3\" priority=\"2\" friction=\"0.5 0.005 0.0001\" solref=\"0.004 1\" "
            "solimp=\"0.9 0.95 0.001 0.5 2\" margin=\"0\" gap=\"0\" rgba=\"%s\"/>\n",
            name, cx, cy, h / 2.0, cos(ang / 2.0), sin(ang / 2.0), len / 2.0 + WALL_HALF_T_M,
            WALL_HALF_T_M, h / 2.0, rgba);
}

/* Inertia of a solid capsule of mass m, radius r and segment length len
 * about its centre: out[0] across the axis, out[1] along it (a cylinder
 * plus two hemispheres, each hemisphere's own 83/320 m r^2 moved by the
 * parallel-axis theorem to its centroid 3r/8 beyond the segment's end). */
static void capsule_inertia(double m, double r, double len, double out[2])
{
    const double v_cyl = M_PI * r * r * len, v_sph = 4.0 / 3.0 * M_PI * r * r * r;
    const double m_cyl = m * v_cyl / (v_cyl + v_sph), m_hemi = (m - m_cyl) / 2.0;
    const double off = len / 2.0 + 3.0 * r / 8.0;
    out[0] = m_cyl * (3.0 * r * r + len * len) / 12.0 +
             2.0 * (83.0 / 320.0 * m_hemi * r * r + m_hemi * off * off);
    out[1] = m_cyl * r * r / 2.0 + 2.0 * (2.0 / 5.0 * m_hemi * r * r);
}

/* ---- tags ------------------------------------------------------------------ */

uint32_t ps_scene_choose_tagged(const ps_crowd_agent_spec_t *agents, uint32_t n_agents,
                                const double robot_xy[2], uint32_t first_id, uint32_t max_people,
                                int32_t *out_tag_id)
{
    /* Selection by rank: n is at most PS_CROWD_MAX_AGENTS, and this runs once. */
    uint32_t n_tagged = 0;
    for (uint32_t k = 0; k < n_agents; k++) {
        out_tag_id[k] = -1;
        const uint32_t id = first_id + 2u * k;
        if (id + 1u >= PS_SCENE_TAG_IDS)
            continue;
        const double dk = hypot(agents[k].x_m - robot_xy[0], agents[k].y_m - robot_xy[1]);
        uint32_t n_nearer = 0; /* ties: the lower index is nearer */
        for (uint32_t j = 0; j < n_agents && n_nearer < max_people; j++) {
            const double dj = hypot(agents[j].x_m - robot_xy[0], agents[j].y_m - robot_xy[1]);
            n_nearer += j != k && first_id + 2u * j + 1u < PS_SCENE_TAG_IDS &&
                        (dj < dk || (dj == dk && j < k));
        }
        if (n_nearer < max_people) {
            out_tag_id[k] = (int32_t)id;
            n_tagged++;
        }
    }
    return n_tagged;
}

/* A texture and a material per tag: sim/ps_camera_sim fills every texture
 * named tag36h11_<id> with that tag. */
static void write_tag_assets(FILE *f, const int32_t *tag_id, uint32_t n_agents)
{
    fprintf(f, "  <asset>\n");
    for (uint32_t k = 0; k < n_agents; k++)
        for (int32_t id = tag_id[k]; id >= 0 && id <= tag_id[k] + 1; id++)
            fprintf(f,
                    "    <texture name=\"tag36h11_%d\" type=\"2d\" builtin=\"flat\" "
                    "width=\"%d\" height=\"%d\" rgb1=\"1 1 1\"/>\n"
                    "    <material name=\"tag36h11_%d\" texture=\"tag36h11_%d\" "
                    "texuniform=\"false\" texrepeat=\"1 1\" emission=\"0.6\" specular=\"0\"/>\n",
                    id, PS_SCENE_TAG_TEX_PX, PS_SCENE_TAG_TEX_PX, id, id);
    fprintf(f, "  </asset>\n");
}

/* The two plates on the front of the shoulders: box sites (drawn with
 * their material, never in a collision, so the physics is that of an
 * untagged crowd), the tag on each plate's +z face looking along the
 * agent's facing, upright; left (id) and right (id + 1) as the agent sees
 * them. Centres at 0.80 h above the floor and 0.11 h either side of the
 * axis: the shoulder (acromion) stands at 0.818 h and the shoulders are
 * 0.259 h wide (Winter's body-segment proportions), the plate a little in
 * and below; 2 mm in front of the torso. */
static void write_tags(FILE *f, const ps_crowd_cfg_t *cfg, const ps_crowd_agent_spec_t *a,
                       uint32_t i, int32_t tag_id)
{
    const double half = (double)cfg->tag_size_m / 0.8 / 2.0; /* black square: 8 of 10 cells */
    const double cf = cos(a->facing_rad), sf = sin(a->facing_rad);
    const double ahead = a->radius_m + TAG_GAP_M + TAG_HALF_T_M;
    const double z = TAG_HEIGHT_FRAC * a->height_m - a->radius_m; /* body frame: pivot at r */
    for (int side = 0; side < 2; side++) {
        const double s = side == 0 ? TAG_SIDE_FRAC * a->height_m : -TAG_SIDE_FRAC * a->height_m;
        fprintf(f,
                "      <site name=\"agent%u_tag_%s\" type=\"box\" pos=\"%.4f %.4f %.4f\" "
                "xyaxes=\"%.6f %.6f 0 0 0 1\" size=\"%.4f %.4f %.4f\" material=\"tag36h11_%d\"/>\n",
                i, side == 0 ? "left" : "right", ahead * cf - s * sf, ahead * sf + s * cf, z, -sf,
                cf, half, half, TAG_HALF_T_M, tag_id + side);
    }
}

/* One agent: one body on four joints (slide x, slide y, then the tilt
 * hinges x and y, all through the pivot at height r), the feet's mass at the
 * pivot and the torso capsule's above it, so the slides carry the whole
 * person and the hinges tilt the torso about the feet. The ring (agent-agent
 * contact) sits on a jointless child body at the torso's centre of mass:
 * MuJoCo's broadphase drops a body pair by contype/conaffinity only when each
 * body has a single geom, and sizes a body's box by its largest geom. With
 * the ring beside the capsule every two agents within a capsule's length
 * (1.7 m) made a pair to sort and test; on its own body a ring pairs only
 * with rings within a diameter. */
static void write_agent(FILE *f, const ps_crowd_cfg_t *cfg, const ps_crowd_agent_spec_t *a,
                        uint32_t i, int32_t tag_id)
{
    const double r = a->radius_m;
    const double len = a->height_m - 2.0 * r; /* capsule segment; pivot at height r */
    const double m_base = PIVOT_MASS_FRAC * a->mass_kg;
    const double m_torso = a->mass_kg - m_base;
    const double l = len / 2.0; /* the torso's centre of mass above the pivot */
    double it[2];
    capsule_inertia(m_torso, r, len, it);
    /* the body's centre of mass and inertia about it, feet at the pivot */
    const double zc = m_torso * l / a->mass_kg;
    const double i_across = it[0] + m_torso * (l - zc) * (l - zc) + m_base * zc * zc;
    /* Tilt damping: about 0.7 of critical for the torso on the ankle spring
     * net of gravity, inertia about the pivot. */
    const double inertia = it[0] + m_torso * l * l;
    const double k_net = ((double)cfg->body.ankle_k_ratio - 1.0) * m_torso * 9.81 * l;
    const double c = 1.4 * sqrt((k_net > 1.0 ? k_net : 1.0) * inertia);
    const float *rgb = GROUP_RGBA[a->group_idx % (sizeof(GROUP_RGBA) / sizeof(GROUP_RGBA[0]))];
    fprintf(f,
            "    <body name=\"agent%u\" pos=\"%.4f %.4f %.4f\">\n"
            "      <joint name=\"agent%u_x\" type=\"slide\" axis=\"1 0 0\" limited=\"false\" "
            "armature=\"0\" damping=\"0\" stiffness=\"0\" frictionloss=\"0\"/>\n"
            "      <joint name=\"agent%u_y\" type=\"slide\" axis=\"0 1 0\" limited=\"false\" "
            "armature=\"0\" damping=\"0\" stiffness=\"0\" frictionloss=\"0\"/>\n"
            "      <joint name=\"agent%u_tx\" type=\"hinge\" axis=\"1 0 0\" limited=\"true\" "
            "range=\"-1.5708 1.5708\" armature=\"0\" damping=\"%.2f\" stiffness=\"0\" "
            "frictionloss=\"0\"/>\n"
            "      <joint name=\"agent%u_ty\" type=\"hinge\" axis=\"0 1 0\" limited=\"true\" "
            "range=\"-1.5708 1.5708\" armature=\"0\" damping=\"%.2f\" stiffness=\"0\" "
            "frictionloss=\"0\"/>\n"
            "      <inertial pos=\"0 0 %.5f\" mass=\"%.4f\" diaginertia=\"%.5f %.5f %.5f\"/>\n"
            "      <geom name=\"agent%u_body\" type=\"capsule\" fromto=\"0 0 0 0 0 %.4f\" "
            "size=\"%.4f\" contype=\"8\" conaffinity=\"18\" condim=\"3\" "
            "priority=\"1\" friction=\"%.3f 0.005 0.0001\" solref=\"0.02 1\" "
            "solimp=\"0.9 0.9 0.001 0.5 2\" margin=\"0\" gap=\"0\" rgba=\"%.2f %.2f %.2f 1\"/>\n"
            "      <body name=\"agent%u_ring\" pos=\"0 0 %.4f\">\n"
            "        <inertial pos=\"0 0 0\" mass=\"1e-6\" diaginertia=\"1e-9 1e-9 1e-9\"/>\n"
            "        <geom name=\"agent%u_ring\" type=\"sphere\" size=\"%.4f\" "
            "contype=\"4\" conaffinity=\"4\" condim=\"1\" priority=\"1\" "
            "friction=\"%.3f 0.005 0.0001\" solref=\"0.02 1\" solimp=\"0.9 0.9 0.001 0.5 2\" "
            "margin=\"0\" gap=\"0\" group=\"3\" rgba=\"%.2f %.2f %.2f 1\"/>\n"
            "      </body>\n",
            i, a->x_m, a->y_m, r, i, i, i, c, i, c, zc, a->mass_kg, i_across, i_across, it[1], i,
            len, r, (double)cfg->body.friction, (double)rgb[0], (double)rgb[1], (double)rgb[2], i,
            l, i, r, (double)cfg->body.friction, (double)rgb[0], (double)rgb[1], (double)rgb[2]);
    if (tag_id >= 0)
        write_tags(f, cfg, a, i, tag_id);
    fprintf(f, "    </body>\n");
}

/* A vertical wall from (x0, y0) to (x1, y1), h high, as boxes of at most
 * WALL_SEG_M on static bodies of their own. A long box (or a plane) in the
 * world body is tested against every body of the scene each step; a short
 * one on its own body reaches the narrow phase only for what stands near
 * it (the broadphase sorts bodies by their boxes). */
static void write_wall(FILE *f, const char *name, double x0, double y0, double x1, double y1,
                       double h, const char *rgba)
{
    const double len = sqrt((x1 - x0) * (x1 - x0) + (y1 - y0) * (y1 - y0));
    const int n = len > WALL_SEG_M ? (int)ceil(len / WALL_SEG_M) : 1;
    const double ang = atan2(y1 - y0, x1 - x0);
    for (int k = 0; k < n; k++) {
        const double s0 = (double)k / n, s1 = (double)(k + 1) / n;
        const double cx = x0 + (s0 + s1) / 2.0 * (x1 - x0), cy = y0 + (s0 + s1) / 2.0 * (y1 - y0);
        /* segments overlap by the wall's thickness so no gap opens at a joint */
        fprintf(f,
                "    <body name=\"%s_%d\" pos=\"%.4f %.4f %.4f\" quat=\"%.6f 0 0 %.6f\">\n"
                "      <geom name=\"%s_%d\" type=\"box\" size=\"%.4f %.4f %.4f\" contype=\"16\" "
                "conaffinity=\"3\" condim=\"3\" priority=\"2\" friction=\"0.5 0.005 0.0001\" "
                "solref=\"0.004 1\" solimp=\"0.9 0.95 0.001 0.5 2\" margin=\"0\" gap=\"0\" "
                "rgba=\"%s\"/>\n"
                "    </body>\n",
                name, k, cx, cy, h / 2.0, cos(ang / 2.0), sin(ang / 2.0), name, k,
                len / (2.0 * n) + WALL_HALF_T_M, WALL_HALF_T_M, h / 2.0, rgba);
    }
}

static void write_walls(FILE *f, const ps_crowd_cfg_t *cfg)
{
    char name[32];
    if (cfg->has_arena_walls) {
        /* Drawn only: the crowd pushes agents out of them itself (Helbing's
         * wall contact, sim/ps_crowd.c), which costs O(agents) where even a
         * plane in the world body is tested against every body each step.
         * They bound the crowd only: the robot may stand anywhere. */
        const ps_crowd_rect_t *a = &cfg->arena;
        const double t = WALL_HALF_T_M, h = ARENA_WALL_HEIGHT_M / 2.0;
        const double cx = (a->x_min_m + a->x_max_m) / 2.0, cy = (a->y_min_m + a->y_max_m) / 2.0;
        const double hx = (a->x_max_m - a->x_min_m) / 2.0 + 2.0 * t;
        const double hy = (a->y_max_m - a->y_min_m) / 2.0 + 2.0 * t;
        /* centre x, y and half sizes x, y of each side's box */
        const double sides[4][4] = {{a->x_min_m - t, cy, t, hy}, {a->x_max_m + t, cy, t, hy},
                                    {cx, a->y_min_m - t, hx, t}, {cx, a->y_max_m + t, hx, t}};
        fprintf(f, "    <body name=\"arena\">\n");
        for (int k = cfg->is_periodic_x ? 2 : 0; k < 4; k++) /* periodic: no end walls */
            fprintf(f,
                    "      <geom name=\"arena_wall%d\" type=\"box\" pos=\"%.4f %.4f %.4f\" "
                    "size=\"%.4f %.4f %.4f\" contype=\"0\" conaffinity=\"0\" "
                    "rgba=\"0.55 0.55 0.6 0.35\"/>\n",
                    k, sides[k][0], sides[k][1], h, sides[k][2], sides[k][3], h);
        fprintf(f, "    </body>\n");
    }
    for (uint32_t k = 0; k < cfg->n_walls; k++) {
        const ps_crowd_wall_cfg_t *w = &cfg->walls[k];
        (void)snprintf(name, sizeof(name), "wall%u", k);
        write_wall(f, name, w->x0_m, w->y0_m, w->x1_m, w->y1_m, WALL_HEIGHT_M, "0.5 0.5 0.55 1");
    }
    for (uint32_t k = 0; k < cfg->n_obstacles; k++) {
        const ps_crowd_obstacle_cfg_t *o = &cfg->obstacles[k];
        fprintf(f,
                "    <body name=\"obstacle%u\" pos=\"%.4f %.4f %.4f\">\n"
                "      <geom name=\"obstacle%u\" type=\"cylinder\" size=\"%.4f %.4f\" "
                "contype=\"16\" conaffinity=\"3\" condim=\"3\" priority=\"2\" "
                "friction=\"0.5 0.005 0.0001\" solref=\"0.004 1\" margin=\"0\" gap=\"0\" "
                "rgba=\"0.45 0.4 0.35 1\"/>\n"
                "    </body>\n",
                k, o->x_m, o->y_m, OBST_HEIGHT_M / 2.0, k, o->radius_m, OBST_HEIGHT_M / 2.0);
    }
    for (uint32_t e = 0; e < cfg->n_events; e++) {
        const ps_crowd_event_cfg_t *ev = &cfg->events[e];
        if (ev->kind != PS_CROWD_EVENT_WALL)
            continue;
        const double cx = (ev->wall[0] + ev->wall[2]) / 2.0, cy = (ev->wall[1] + ev->wall[3]) / 2.0;
        fprintf(f, "    <body name=\"crowd_wall%u\" mocap=\"true\" pos=\"%.4f %.4f 0\">\n", e, cx,
                cy);
        (void)snprintf(name, sizeof(name), "crowd_wall%u_geom", e);
        write_box(f, name, ev->wall[0] - cx, ev->wall[1] - cy, ev->wall[2] - cx, ev->wall[3] - cy,
                  WALL_HEIGHT_M, "0.8 0.3 0.2 1");
        fprintf(f, "    </body>\n");
    }
}

int ps_scene_write_mjcf(const ps_crowd_cfg_t *cfg, const ps_crowd_agent_spec_t *agents,
                        uint32_t n_agents, const char *robot_model_path, int robot_nconmax,
                        int robot_njmax, const int32_t *tag_id, char **out_xml, char *err,
                        size_t err_len)
{
    if (cfg == NULL || (agents == NULL && n_agents > 0) || robot_model_path == NULL ||
        out_xml == NULL) {
        ps_err_format(err, err_len, "scene: NULL argument");
        return -EINVAL;
    }
    uint32_t n_tagged = 0;
    for (uint32_t k = 0; tag_id != NULL && k < n_agents; k++) {
        if (tag_id[k] < 0)
            continue;
        if (tag_id[k] % 2 != 0 || (uint32_t)tag_id[k] + 1u >= PS_SCENE_TAG_IDS) {
            ps_err_format(err, err_len, "scene: agent %u: tag %d is no pair's first tag36h11 id", k,
                          tag_id[k]);
            return -EINVAL;
        }
        n_tagged++;
    }
    char *buf = NULL;
    size_t size = 0;
    FILE *f = open_memstream(&buf, &size);
    if (f == NULL) {
        ps_err_format(err, err_len, "scene: out of memory");
        return -ENOMEM;
    }
    /* The solver, whatever the robot model says: Newton with a pyramidal
     * cone and a sparse Jacobian. Measured on 100 pressed agents (docs/
     * crowd.md, "Performance"): CG, PGS and the elliptic cone cost as much
     * or more per step, a dense Jacobian fifteen times more (2.2.2 then
     * factors an nv x nv Hessian). */
    char option[128] = "  <option solver=\"Newton\" cone=\"pyramidal\" jacobian=\"sparse\"/>\n";
    if (cfg->timestep_s > 0.0f)
        (void)snprintf(option, sizeof(option),
                       "  <option timestep=\"%g\" solver=\"Newton\" cone=\"pyramidal\" "
                       "jacobian=\"sparse\"/>\n",
                       (double)cfg->timestep_s);
    int nconmax, njmax;
    ps_scene_sizes(n_agents, robot_nconmax, robot_njmax, &nconmax, &njmax);
    fprintf(f,
            "<mujoco model=\"pushstep-scene\">\n"
            "  <include file=\"%s\"/>\n"
            "  <size nconmax=\"%d\" njmax=\"%d\"/>\n"
            "%s"
            "  <visual>\n"
            "    <global offwidth=\"1280\" offheight=\"720\"/>\n"
            "    <map force=\"0.004\"/>\n"
            "    <scale forcewidth=\"0.03\" contactwidth=\"0.05\" contactheight=\"0.01\"/>\n"
            "  </visual>\n",
            robot_model_path, nconmax, njmax, option);
    if (n_tagged > 0)
        write_tag_assets(f, tag_id, n_agents);
    fprintf(f, "  <worldbody>\n");
    write_walls(f, cfg);
    for (uint32_t i = 0; i < n_agents; i++)
        write_agent(f, cfg, &agents[i], i, tag_id != NULL ? tag_id[i] : -1);
    fprintf(f, "  </worldbody>\n</mujoco>\n");
    const bool is_bad = ferror(f) != 0;
    if (fclose(f) != 0 || is_bad || buf == NULL) {
        free(buf);
        ps_err_format(err, err_len, "scene: out of memory");
        return -ENOMEM;
    }
    *out_xml = buf;
    return 0;
}
