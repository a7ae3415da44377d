#include "ps_crowd.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <mujoco/mujoco.h>

#include "../rt/ps_err.h"

#define G_M_S2          9.81
#define SOLIMP_D        0.9  /* constant impedance the scene sets on agent geoms */
#define STAND_OMEGA     10.0 /* base follows the centre of mass: ~0.1 s */
#define STEP_OMEGA      20.0 /* base tracks a reflex step's path */
#define STANCE_SHIFT_S  0.3  /* feet drift under the CoM between steps */
#define FALLEN_DRAG_N_S 400.0
#define SLOW_FRAC       0.25 /* ahead and slower than this share of v0: in the way */
/* Capsule gating (gate_capsules): a capsule is on while anything it can
 * touch is within its reach plus GATE_MARGIN_M plus what GATE_SPEED_M_S
 * closes in one crowd update and one step (the geoms' places lag a step). */
#define GATE_MARGIN_M  0.05
#define GATE_SPEED_M_S 10.0 /* a falling head, 1.5 m at 5 rad/s, plus the robot's */

typedef struct {
    int qx, qy, qtx, qty; /* qpos addresses */
    int vx, vy, vtx, vty; /* dof addresses */
    int jtx, jty;         /* tilt hinges */
    int body, ring_body, geom, ring; /* the agent's body; the ring's at its torso's CoM */
    double x0, y0; /* body position in the model (slides count from it) */
    double mass, m_torso, radius, pivot_h, com_h, v0;
    double len; /* capsule segment, pivot to head sphere's centre */
    double ankle_k, ankle_max;
    uint32_t group;
    /* state */
    bool is_stepping, is_fallen, is_surging;
    double step_t0, step_offset[2];
    /* where the feet mean to be: the social-force particle, moved by the
     * self-propulsion and shifted by each reflex step */
    double feet[2], vfeet[2];
    double goal_xy[2]; /* hold: the start place */
    double surge_until, surge_v[2];
    double f_social[2];  /* self-propulsion (drive, repulsion, evasion): through the feet */
    /* this update's heading and desired speed, and what its neighbours add
     * up to (neighbour_pass): repulsion, their offsets, how many repel,
     * whether one ahead is down or slow */
    double e[2], v0_now, f_near[2], o_near[2];
    uint32_t n_near;
    bool is_blocked;
    double f_contact[2]; /* sliding friction between bodies: at the torso's CoM */
    double f_base[2], tau_ankle[2];
    /* kinematics at the last update */
    double base[2], vbase[2], com[3], vcom[2], tilt;
} agent_t;

struct ps_crowd {
    ps_crowd_cfg_t cfg;
    uint32_t n;
    agent_t *a;
    double *xy; /* base positions for the grid */
    ps_social_grid_t grid;
    uint32_t *grid_mem;
    int robot_root;
    const unsigned char *is_robot; /* the plant's, nbody */
    int *part_of_body;             /* nbody: part slot or -1 */
    int *agent_of_body;            /* nbody: agent index (torso) or -1 */
    int *ring_of_geom;             /* ngeom: agent index of a ring geom, or -1 */
    int wall_mocap[PS_CROWD_MAX_EVENTS];
    double wall_c0[PS_CROWD_MAX_EVENTS][2];
    bool is_event_started[PS_CROWD_MAX_EVENTS];
    int update_every; /* physics steps per crowd update */
    int step_count;
    double robot_xy[2];
    double wall_pen_m; /* deepest overlap with the arena's sides, this step */
    /* capsule gating: the model's contype/conaffinity (written), the
     * capsules' own bits, the geoms that can touch a capsule */
    int *geom_contype, *geom_conaffinity;
    int cap_contype, cap_conaffinity;
    bool is_gated; /* false: capsules stay on (off in cfg, or a plane can touch them) */
    int *toucher;  /* geoms (not the robot's) that can touch a capsule */
    int n_touchers;
    double *toucher_circle; /* per toucher: x, y, reach (this update) */
    int *robot_geom;        /* the robot's geoms that can touch a capsule: one circle */
    int n_robot_geoms;
    double gate_margin_m;
    ps_crowd_stats_t st;
};

void ps_crowd_default_cfg(ps_crowd_cfg_t *out)
{
    memset(out, 0, sizeof(*out));
    ps_social_default_params(&out->social);
    out->body = (ps_crowd_body_cfg_t){
        .body_k_n_m = 1.2e5f,
        .body_damping = 1.0f,
        .friction = 0.5f,
        .sliding_kappa = 2.4e5f,
        .bos_m = 0.13f,
        .ankle_k_ratio = 1.2f,
        .step_time_s = 0.5f,
        .step_max_m = 0.73f,
        .fall_tilt_rad = 0.6f,
        .ground_mu = 0.8f,
    };
    out->local_radius_m = 1.0f;
    out->robot_radius_m = 0.2f;
    out->robot_a_n = out->social.a_n;
    out->crowd_dt_s = 0.002f;
    out->timestep_s = 0.001f; /* docs/crowd.md, "Performance": the robot stands at it */
    out->gate_capsules = true; /* docs/crowd.md, "Performance" */
    out->tags = PS_CROWD_TAGS_AUTO;
    out->tag_size_m = 0.12f; /* the boards' tag_size_m */
}

/* ---- create ---------------------------------------------------------------- */

static int find(const mjModel *m, mjtObj type, const char *fmt, uint32_t i, char *err,
                size_t err_len)
{
    char name[64];
    (void)snprintf(name, sizeof(name), fmt, i);
    const int id = mj_name2id(m, type, name);
    if (id < 0)
        ps_err_format(err, err_len, "crowd: '%s' not found in the scene", name);
    return id;
}

static int bind_agent(ps_crowd_t *c, mjModel *m, const ps_crowd_agent_spec_t *s, uint32_t i,
                      char *err, size_t err_len)
{
    agent_t *a = &c->a[i];
    const int jx = find(m, mjOBJ_JOINT, "agent%u_x", i, err, err_len);
    const int jy = find(m, mjOBJ_JOINT, "agent%u_y", i, err, err_len);
    const int jtx = find(m, mjOBJ_JOINT, "agent%u_tx", i, err, err_len);
    const int jty = find(m, mjOBJ_JOINT, "agent%u_ty", i, err, err_len);
    a->body = find(m, mjOBJ_BODY, "agent%u", i, err, err_len);
    a->geom = find(m, mjOBJ_GEOM, "agent%u_body", i, err, err_len);
    a->ring = find(m, mjOBJ_GEOM, "agent%u_ring", i, err, err_len);
    if (jx < 0 || jy < 0 || jtx < 0 || jty < 0 || a->body < 0 || a->geom < 0 || a->ring < 0)
        return -PS_ERR_CONFIG;
    a->jtx = jtx;
    a->jty = jty;
    a->ring_body = m->geom_bodyid[a->ring];
    a->qx = m->jnt_qposadr[jx];
    a->qy = m->jnt_qposadr[jy];
    a->qtx = m->jnt_qposadr[jtx];
    a->qty = m->jnt_qposadr[jty];
    a->vx = m->jnt_dofadr[jx];
    a->vy = m->jnt_dofadr[jy];
    a->vtx = m->jnt_dofadr[jtx];
    a->vty = m->jnt_dofadr[jty];
    a->x0 = m->body_pos[3 * a->body];
    a->y0 = m->body_pos[3 * a->body + 1];
    a->mass = m->body_mass[a->body];
    a->radius = s->radius_m;
    a->len = 2.0 * m->geom_size[3 * a->geom + 1];
    a->pivot_h = m->body_pos[3 * a->body + 2];
    /* the torso's centre of mass is the ring's place; the body's own lies
     * lower, the feet's mass being at the pivot: m zc = m_torso l */
    const double l_torso = m->body_pos[3 * a->ring_body + 2];
    a->com_h = a->pivot_h + l_torso;
    a->m_torso = a->mass * m->body_ipos[3 * a->body + 2] / l_torso;
    a->v0 = s->v0_m_s;
    a->group = s->group_idx;
    const double l = a->com_h - a->pivot_h;
    a->ankle_k = (double)c->cfg.body.ankle_k_ratio * a->m_torso * G_M_S2 * l;
    a->ankle_max = a->mass * G_M_S2 * (double)c->cfg.body.bos_m;
    a->feet[0] = s->x_m;
    a->feet[1] = s->y_m;
    a->goal_xy[0] = s->x_m;
    a->goal_xy[1] = s->y_m;
    /* Contact stiffness: with constant impedance d and solref (-k, -b) MuJoCo
     * moves a frictionless contact as r'' = (1 - d) a0 - b r' - k r, a0 the
     * unconstrained acceleration D f (D the sum of the two bodies' inverse
     * weights at qpos0), so it settles at depth (1 - d) D f / k. Each agent
     * geom carries k = K (1 - d) 2 w_i, so that the pair's mean is K (1 - d) D:
     * depth f / K; b = 2 zeta sqrt(k) damps it as body_damping says. */
    const double w = m->body_invweight0[2 * a->ring_body];
    const double k = (double)c->cfg.body.body_k_n_m * (1.0 - SOLIMP_D) * 2.0 * w;
    const double b = 2.0 * (double)c->cfg.body.body_damping * sqrt(k);
    const int geoms[2] = {a->geom, a->ring};
    for (int q = 0; q < 2; q++) {
        m->geom_solref[mjNREF * geoms[q]] = -k;
        m->geom_solref[mjNREF * geoms[q] + 1] = -b;
    }
    c->agent_of_body[a->body] = (int)i;
    c->agent_of_body[a->ring_body] = (int)i;
    c->ring_of_geom[a->ring] = (int)i;
    return 0;
}

/* Which geoms can touch an agent's capsule (by the contype/conaffinity
 * rule), split into the robot's and the rest. Gating stays off when there
 * are no agents or when a plane or height field could touch a capsule (no
 * bounding radius). */
static int bind_gating(ps_crowd_t *c, mjModel *m)
{
    c->geom_contype = m->geom_contype;
    c->geom_conaffinity = m->geom_conaffinity;
    c->is_gated = c->cfg.gate_capsules && c->n > 0;
    if (c->n == 0)
        return 0;
    c->cap_contype = m->geom_contype[c->a[0].geom];
    c->cap_conaffinity = m->geom_conaffinity[c->a[0].geom];
    c->toucher = calloc((size_t)m->ngeom, sizeof(int));
    c->robot_geom = calloc((size_t)m->ngeom, sizeof(int));
    c->toucher_circle = calloc(3u * (size_t)m->ngeom, sizeof(double));
    if (c->toucher == NULL || c->robot_geom == NULL || c->toucher_circle == NULL)
        return -ENOMEM;
    for (int g = 0; g < m->ngeom; g++) {
        const int b = m->geom_bodyid[g];
        if (c->agent_of_body[b] >= 0 || !((c->cap_contype & m->geom_conaffinity[g]) ||
                                          (m->geom_contype[g] & c->cap_conaffinity)))
            continue;
        if (m->geom_rbound[g] <= 0.0)
            c->is_gated = false;
        if (c->is_robot[b])
            c->robot_geom[c->n_robot_geoms++] = g;
        else
            c->toucher[c->n_touchers++] = g;
    }
    c->gate_margin_m =
        GATE_MARGIN_M + GATE_SPEED_M_S * ((double)c->cfg.crowd_dt_s + m->opt.timestep);
    return 0;
}

static int bind_parts(ps_crowd_t *c, const mjModel *m)
{
    c->st.n_parts = 0;
    for (int b = 0; b < m->nbody; b++) {
        c->part_of_body[b] = -1;
        if (!c->is_robot[b] || m->body_geomnum[b] == 0)
            continue;
        if (c->st.n_parts >= PS_CROWD_MAX_PARTS)
            continue; /* counted in the total through the nearest slot below */
        const char *name = mj_id2name(m, mjOBJ_BODY, b);
        (void)snprintf(c->st.part_name[c->st.n_parts], PS_NAME_LEN, "%s",
                       name != NULL ? name : "?");
        c->part_of_body[b] = (int)c->st.n_parts++;
    }
    return 0;
}

/* The farthest one agent acts on another in the social force: repulsion
 * within range_m, evasion of those ahead within evasive_range_m. */
static double neighbour_reach_m(const ps_social_params_t *sp)
{
    return sp->range_m > sp->evasive_range_m ? (double)sp->range_m : (double)sp->evasive_range_m;
}

int ps_crowd_create(const ps_crowd_cfg_t *cfg, const ps_crowd_agent_spec_t *agents,
                    uint32_t n_agents, mjModel *m, const unsigned char *is_robot_body,
                    int robot_root_body, ps_crowd_t **out, char *err, size_t err_len)
{
    if (cfg == NULL || m == NULL || out == NULL || is_robot_body == NULL ||
        (agents == NULL && n_agents > 0) || n_agents > PS_CROWD_MAX_AGENTS) {
        ps_err_format(err, err_len, "crowd: bad arguments");
        return -EINVAL;
    }
    const double ratio = (double)cfg->crowd_dt_s / m->opt.timestep;
    if (!(ratio >= 0.99) || fabs(ratio - round(ratio)) > 0.01) {
        ps_err_format(err, err_len,
                      "crowd: crowd_dt_s %g is not a multiple of the model timestep %g",
                      (double)cfg->crowd_dt_s, m->opt.timestep);
        return -PS_ERR_CONFIG;
    }
    ps_crowd_t *c = calloc(1, sizeof(*c));
    if (c == NULL)
        return -ENOMEM;
    c->cfg = *cfg;
    c->n = n_agents;
    c->update_every = (int)round(ratio);
    c->is_robot = is_robot_body;
    c->robot_root = robot_root_body;
    const ps_crowd_rect_t *ar = &cfg->arena;
    /* A cell as wide as the farthest a neighbour counts (repulsion or
     * evasion): the pass over a cell and its eight neighbours then sees
     * every pair within reach, wherever the cells' edges fall. */
    const double reach = neighbour_reach_m(&cfg->social);
    const double margin = 2.0 * reach;
    const double w = (double)ar->x_max_m - ar->x_min_m + 2.0 * margin;
    const double h = (double)ar->y_max_m - ar->y_min_m + 2.0 * margin;
    const double cell = reach > 0.3 ? reach : 0.3;
    const uint32_t n_cells = ps_social_grid_cells(w, h, cell);
    c->a = calloc(n_agents > 0 ? n_agents : 1u, sizeof(*c->a));
    c->xy = calloc(2u * (n_agents > 0 ? n_agents : 1u), sizeof(*c->xy));
    c->grid_mem = calloc((size_t)n_cells + 1u + 2u * (n_agents + 1u), sizeof(uint32_t));
    c->part_of_body = calloc((size_t)m->nbody, sizeof(int));
    c->agent_of_body = calloc((size_t)m->nbody, sizeof(int));
    c->ring_of_geom = calloc((size_t)m->ngeom, sizeof(int));
    int rc = 0;
    if (c->a == NULL || c->xy == NULL || c->grid_mem == NULL || c->part_of_body == NULL ||
        c->agent_of_body == NULL || c->ring_of_geom == NULL || n_cells == 0) {
        ps_err_format(err, err_len, "crowd: out of memory (or an empty arena)");
        rc = n_cells == 0 ? -PS_ERR_CONFIG : -ENOMEM;
        goto fail;
    }
    ps_social_grid_init(&c->grid, ar->x_min_m - margin, ar->y_min_m - margin, w, h, cell,
                        c->grid_mem, c->grid_mem + n_cells + 1u,
                        c->grid_mem + n_cells + 1u + n_agents + 1u, n_agents);
    for (int b = 0; b < m->nbody; b++)
        c->agent_of_body[b] = -1;
    for (int g = 0; g < m->ngeom; g++)
        c->ring_of_geom[g] = -1;
    for (uint32_t i = 0; i < n_agents && rc == 0; i++)
        rc = bind_agent(c, m, &agents[i], i, err, err_len);
    if (rc < 0)
        goto fail;
    (void)bind_parts(c, m);
    rc = bind_gating(c, m);
    if (rc < 0) {
        ps_err_format(err, err_len, "crowd: out of memory");
        goto fail;
    }
    for (uint32_t e = 0; e < cfg->n_events; e++) {
        c->wall_mocap[e] = -1;
        if (cfg->events[e].kind != PS_CROWD_EVENT_WALL)
            continue;
        const int b = find(m, mjOBJ_BODY, "crowd_wall%u", e, err, err_len);
        if (b < 0 || m->body_mocapid[b] < 0) {
            rc = -PS_ERR_CONFIG;
            goto fail;
        }
        c->wall_mocap[e] = m->body_mocapid[b];
        c->wall_c0[e][0] = m->body_pos[3 * b];
        c->wall_c0[e][1] = m->body_pos[3 * b + 1];
    }
    c->st.n_agents = n_agents;
    c->step_count = 0;
    *out = c;
    return 0;
fail:
    ps_crowd_destroy(c);
    return rc;
}

void ps_crowd_destroy(ps_crowd_t *c)
{
    if (c == NULL)
        return;
    free(c->a);
    free(c->xy);
    free(c->grid_mem);
    free(c->part_of_body);
    free(c->agent_of_body);
    free(c->ring_of_geom);
    free(c->toucher);
    free(c->robot_geom);
    free(c->toucher_circle);
    free(c);
}

uint32_t ps_crowd_agent_count(const ps_crowd_t *c)
{
    return c->n;
}

/* ---- per update -------------------------------------------------------------- */

static void read_agent(agent_t *a, const mjData *d)
{
    a->base[0] = a->x0 + d->qpos[a->qx];
    a->base[1] = a->y0 + d->qpos[a->qy];
    a->vbase[0] = d->qvel[a->vx];
    a->vbase[1] = d->qvel[a->vy];
    const mjtNum *R = d->xmat + 9 * a->body;
    const mjtNum *com = d->xpos + 3 * a->ring_body;
    a->tilt = acos(R[8] > 1.0 ? 1.0 : (R[8] < -1.0 ? -1.0 : R[8]));
    /* omega = qd_tx x + qd_ty (Rx(tx) y); v_com = v_base + omega x (com - pivot) */
    const double tx = d->qpos[a->qtx];
    const double om[3] = {d->qvel[a->vtx], d->qvel[a->vty] * cos(tx), d->qvel[a->vty] * sin(tx)};
    const double r[3] = {com[0] - a->base[0], com[1] - a->base[1], com[2] - a->pivot_h};
    a->vcom[0] = a->vbase[0] + om[1] * r[2] - om[2] * r[1];
    a->vcom[1] = a->vbase[1] + om[2] * r[0] - om[0] * r[2];
    for (int k = 0; k < 3; k++)
        a->com[k] = com[k];
}

/* Unit heading and desired speed of an agent now. */
static void heading(const ps_crowd_t *c, const agent_t *a, double e[2], double *v0)
{
    const ps_crowd_group_cfg_t *g = &c->cfg.groups[a->group];
    double dx = 0.0, dy = 0.0;
    *v0 = a->v0;
    if (a->is_surging) {
        const double s = sqrt(a->surge_v[0] * a->surge_v[0] + a->surge_v[1] * a->surge_v[1]);
        e[0] = s > 0.0 ? a->surge_v[0] / s : 0.0;
        e[1] = s > 0.0 ? a->surge_v[1] / s : 0.0;
        *v0 = s;
        return;
    }
    switch (g->goal) {
    case PS_CROWD_GOAL_DIRECTION:
        dx = g->goal_xy[0];
        dy = g->goal_xy[1];
        break;
    case PS_CROWD_GOAL_POINT:
        dx = g->goal_xy[0] - a->com[0];
        dy = g->goal_xy[1] - a->com[1];
        break;
    case PS_CROWD_GOAL_ROBOT:
        dx = c->robot_xy[0] - a->com[0];
        dy = c->robot_xy[1] - a->com[1];
        break;
    case PS_CROWD_GOAL_HOLD:
    default:
        dx = a->goal_xy[0] - a->com[0];
        dy = a->goal_xy[1] - a->com[1];
        break;
    }
    const double d = sqrt(dx * dx + dy * dy);
    e[0] = d > 1e-9 ? dx / d : 0.0;
    e[1] = d > 1e-9 ? dy / d : 0.0;
    /* Arrival: slow down within 0.5 m of a place to stand. */
    if (g->goal == PS_CROWD_GOAL_HOLD || g->goal == PS_CROWD_GOAL_POINT)
        *v0 *= d < 0.5 ? d / 0.5 : 1.0;
}

/* What j does to i in the social force: its repulsion f (within range_m;
 * zero beyond), and whether j, ahead within evasive_range_m, blocks i's
 * way. */
static void neighbour_acts(const ps_crowd_t *c, agent_t *a, const double xi[2], const agent_t *b,
                           const double xj[2], const double f[2])
{
    a->f_near[0] += f[0];
    a->f_near[1] += f[1];
    if (f[0] != 0.0 || f[1] != 0.0) {
        a->o_near[0] += xj[0] - xi[0];
        a->o_near[1] += xj[1] - xi[1];
        a->n_near++;
    }
    if (!a->is_blocked && a->v0_now > 0.2 &&
        ps_social_is_ahead(xi, a->e, xj, c->cfg.social.evasive_range_m)) {
        const double sj = sqrt(b->vcom[0] * b->vcom[0] + b->vcom[1] * b->vcom[1]);
        a->is_blocked = b->is_fallen || sj < SLOW_FRAC * a->v0_now;
    }
}

/* Every pair of agents in the same or adjacent grid cells, once: each
 * cell with itself and four of its eight neighbours (the other four see it
 * from their side), both agents of a pair served by one distance test. */
static void neighbour_pass(ps_crowd_t *c)
{
    const ps_social_params_t *sp = &c->cfg.social;
    const double reach = neighbour_reach_m(sp);
    const double reach2 = reach * reach, range2 = (double)sp->range_m * sp->range_m;
    for (uint32_t i = 0; i < c->n; i++) {
        agent_t *a = &c->a[i];
        heading(c, a, a->e, &a->v0_now);
        a->f_near[0] = a->f_near[1] = a->o_near[0] = a->o_near[1] = 0.0;
        a->n_near = 0;
        a->is_blocked = false;
    }
    static const int HALF[5][2] = {{0, 0}, {1, 0}, {-1, 1}, {0, 1}, {1, 1}};
    const ps_social_grid_t *g = &c->grid;
    for (int cy = 0; cy < g->ny; cy++) {
        for (int cx = 0; cx < g->nx; cx++) {
            const uint32_t cell = (uint32_t)(cy * g->nx + cx);
            for (uint32_t k = g->cell_start[cell]; k < g->cell_start[cell + 1u]; k++) {
                const uint32_t i = g->items[k];
                const double xi[2] = {c->xy[2 * i], c->xy[2 * i + 1]};
                for (int h = 0; h < 5; h++) {
                    const int gx = cx + HALF[h][0], gy = cy + HALF[h][1];
                    if (gx < 0 || gy < 0 || gx >= g->nx || gy >= g->ny)
                        continue;
                    const uint32_t other = (uint32_t)(gy * g->nx + gx);
                    /* in its own cell, each pair once: those after it */
                    const uint32_t q0 = h == 0 ? k + 1u : g->cell_start[other];
                    for (uint32_t q = q0; q < g->cell_start[other + 1u]; q++) {
                        const uint32_t j = g->items[q];
                        /* positions from the grid's packed copy: the
                         * agents' records stay out of the cache unless near */
                        const double xj[2] = {c->xy[2 * j], c->xy[2 * j + 1]};
                        const double dx = xj[0] - xi[0], dy = xj[1] - xi[1];
                        const double d2 = dx * dx + dy * dy;
                        if (d2 > reach2)
                            continue; /* beyond the repulsion's and the evasion's range */
                        agent_t *a = &c->a[i], *b = &c->a[j];
                        double fa[2] = {0.0, 0.0}, fb[2] = {0.0, 0.0};
                        if (d2 <= range2)
                            ps_social_pair_repulsion(sp, xi, a->radius, a->e, xj, b->radius, b->e,
                                                     fa, fb);
                        if (!a->is_fallen)
                            neighbour_acts(c, a, xi, b, xj, fa);
                        if (!b->is_fallen)
                            neighbour_acts(c, b, xj, a, xi, fb);
                    }
                }
            }
        }
    }
}

static void social_force(ps_crowd_t *c, uint32_t i, const mjModel *m, double out[2])
{
    const ps_social_params_t *sp = &c->cfg.social;
    agent_t *a = &c->a[i];
    const double *e = a->e;
    ps_social_drive(a->mass, a->v0_now, sp->tau_s, e, a->vfeet, out);
    const double xi[2] = {a->com[0], a->com[1]};
    out[0] += a->f_near[0];
    out[1] += a->f_near[1];
    const double o[2] = {a->o_near[0], a->o_near[1]};
    const uint32_t n_near = a->n_near;
    const bool is_blocked = a->is_blocked;
    if (c->cfg.robot_a_n > 0.0f) {
        ps_social_params_t rp = *sp;
        rp.a_n = c->cfg.robot_a_n;
        double f[2];
        ps_social_agent_repulsion(&rp, xi, a->radius, e, c->robot_xy, c->cfg.robot_radius_m, f);
        out[0] += f[0];
        out[1] += f[1];
    }
    /* walls: the arena's sides, the wall segments, the obstacles */
    double f[2];
    if (c->cfg.has_arena_walls) {
        const ps_crowd_rect_t *ar = &c->cfg.arena;
        const double corners[5][2] = {{ar->x_min_m, ar->y_min_m},
                                      {ar->x_max_m, ar->y_min_m},
                                      {ar->x_max_m, ar->y_max_m},
                                      {ar->x_min_m, ar->y_max_m},
                                      {ar->x_min_m, ar->y_min_m}};
        for (int k = 0; k < 4; k++) {
            if (c->cfg.is_periodic_x && (k == 1 || k == 3))
                continue;
            ps_social_wall_repulsion(sp, xi, a->radius, corners[k], corners[k + 1], f);
            out[0] += f[0];
            out[1] += f[1];
        }
    }
    for (uint32_t k = 0; k < c->cfg.n_walls; k++) {
        const ps_crowd_wall_cfg_t *w = &c->cfg.walls[k];
        const double p0[2] = {w->x0_m, w->y0_m}, p1[2] = {w->x1_m, w->y1_m};
        ps_social_wall_repulsion(sp, xi, a->radius, p0, p1, f);
        out[0] += f[0];
        out[1] += f[1];
    }
    for (uint32_t k = 0; k < c->cfg.n_obstacles; k++) {
        const ps_crowd_obstacle_cfg_t *ob = &c->cfg.obstacles[k];
        const double p0[2] = {ob->x_m, ob->y_m};
        ps_social_wall_repulsion(sp, xi, a->radius + (double)ob->radius_m, p0, p0, f);
        out[0] += f[0];
        out[1] += f[1];
    }
    if (n_near > 0) {
        ps_social_evasive(sp, is_blocked, e, o, f);
        out[0] += f[0];
        out[1] += f[1];
    }
    (void)m;
}

/* Minimum-jerk position fraction at phase s in [0, 1], and its rate. */
static void min_jerk(double s, double *out_p, double *out_dp)
{
    s = s < 0.0 ? 0.0 : (s > 1.0 ? 1.0 : s);
    *out_p = s * s * s * (10.0 - 15.0 * s + 6.0 * s * s);
    *out_dp = 30.0 * s * s * (1.0 - 2.0 * s + s * s);
}

static void clamp_norm(double v[2], double max)
{
    const double n = sqrt(v[0] * v[0] + v[1] * v[1]);
    if (n > max && n > 0.0) {
        v[0] *= max / n;
        v[1] *= max / n;
    }
}

/* Ankle, stepping reflex and fall of one agent (after its social force). */
static void balance(ps_crowd_t *c, agent_t *a, const mjData *d, double t_s)
{
    const ps_crowd_body_cfg_t *bc = &c->cfg.body;
    if (!a->is_fallen && a->tilt > (double)bc->fall_tilt_rad) {
        a->is_fallen = true;
        a->is_stepping = false;
        c->st.n_fallen++;
    }
    if (a->is_fallen) {
        /* Lying: no ankle, no drive; the body drags on the floor. */
        a->tau_ankle[0] = a->tau_ankle[1] = 0.0;
        a->f_social[0] = a->f_social[1] = 0.0;
        for (int k = 0; k < 2; k++)
            a->f_base[k] = -FALLEN_DRAG_N_S * a->vbase[k];
        clamp_norm(a->f_base, (double)bc->ground_mu * a->mass * G_M_S2);
        return;
    }
    /* Ankle: spring toward upright, torque capped at m g bos (CoP in the foot). */
    a->tau_ankle[0] = -a->ankle_k * d->qpos[a->qtx];
    a->tau_ankle[1] = -a->ankle_k * d->qpos[a->qty];
    clamp_norm(a->tau_ankle, a->ankle_max);

    /* The feet walk as the social-force particle: its acceleration is the
     * self-propulsion over the mass (which also acts on the body, spread in
     * proportion to mass, ps_crowd_before_step), so in a free walk body and
     * feet move together and the feet's controller does nothing. */
    const double dt = (double)c->cfg.crowd_dt_s;
    for (int k = 0; k < 2; k++) {
        a->vfeet[k] += a->f_social[k] / a->mass * dt;
        a->feet[k] += a->vfeet[k] * dt;
    }
    /* Stepping reflex on the capture point relative to the feet, which
     * stand where they mean to be (ground friction): what has to be caught
     * is the torso falling relative to them, pushed or pressed,
     * xi = (com - base) + (v_com - v_base) / omega0. */
    const double omega0 = sqrt(G_M_S2 / a->com_h);
    double xi[2] = {a->com[0] - a->base[0] + (a->vcom[0] - a->vbase[0]) / omega0,
                    a->com[1] - a->base[1] + (a->vcom[1] - a->vbase[1]) / omega0};
    if (!a->is_stepping && sqrt(xi[0] * xi[0] + xi[1] * xi[1]) > (double)bc->bos_m) {
        clamp_norm(xi, (double)bc->step_max_m);
        a->is_stepping = true;
        a->step_t0 = t_s;
        a->step_offset[0] = xi[0];
        a->step_offset[1] = xi[1];
        c->st.n_steps_taken++;
    }
    double target[2], vtarget[2];
    if (a->is_stepping) {
        /* the swing foot heads for where the capture point is now (it lands
         * where the body would come to rest over it) along a minimum-jerk
         * path from where the feet stood */
        for (int k = 0; k < 2; k++)
            a->step_offset[k] =
                a->com[k] - a->feet[k] + (a->vcom[k] - a->vfeet[k]) / omega0;
        clamp_norm(a->step_offset, (double)bc->step_max_m);
        const double T = (double)bc->step_time_s;
        double p, dp;
        min_jerk((t_s - a->step_t0) / T, &p, &dp);
        for (int k = 0; k < 2; k++) {
            target[k] = a->feet[k] + p * a->step_offset[k];
            vtarget[k] = a->vfeet[k] + dp / T * a->step_offset[k];
        }
        if (t_s - a->step_t0 >= T) {
            a->is_stepping = false;
            a->feet[0] += a->step_offset[0];
            a->feet[1] += a->step_offset[1];
        }
    } else {
        /* standing or walking: small shuffles bring the feet under the CoM
         * and to its speed over STANCE_SHIFT_S (weight shifts; a lean the
         * ankle alone would take seconds to undo; and where bodies press on
         * each other the feet do not walk on through them) */
        const double w = dt / STANCE_SHIFT_S < 1.0 ? dt / STANCE_SHIFT_S : 1.0;
        for (int k = 0; k < 2; k++) {
            a->feet[k] += w * (a->com[k] - a->feet[k]);
            a->vfeet[k] += w * (a->vcom[k] - a->vfeet[k]);
            target[k] = a->feet[k];
            vtarget[k] = a->vfeet[k];
        }
    }
    const double omega = a->is_stepping ? STEP_OMEGA : STAND_OMEGA;
    for (int k = 0; k < 2; k++)
        a->f_base[k] = a->mass * (omega * omega * (target[k] - a->base[k]) +
                                  2.0 * omega * (vtarget[k] - a->vbase[k]));
    const double cap = (double)bc->ground_mu * a->mass * G_M_S2;
    if (hypot(a->f_base[0], a->f_base[1]) > cap && !a->is_stepping) {
        /* more than friction holds: the feet slide, and mean to be where
         * they are now */
        for (int k = 0; k < 2; k++) {
            a->feet[k] = a->base[k];
            a->vfeet[k] = a->vbase[k];
        }
    }
    clamp_norm(a->f_base, cap);
}

static void run_events(ps_crowd_t *c, double t_s)
{
    for (uint32_t e = 0; e < c->cfg.n_events; e++) {
        const ps_crowd_event_cfg_t *ev = &c->cfg.events[e];
        if (ev->kind != PS_CROWD_EVENT_SURGE || c->is_event_started[e] || t_s < ev->t_s)
            continue;
        c->is_event_started[e] = true;
        /* The rear rows: group members deepest against the direction. */
        uint32_t gi = 0;
        while (gi < c->cfg.n_groups && strcmp(c->cfg.groups[gi].name, ev->group) != 0)
            gi++;
        double lo = INFINITY, n_in = 0.0;
        for (uint32_t i = 0; i < c->n; i++) {
            const agent_t *a = &c->a[i];
            if (a->group != gi)
                continue;
            const double p = a->base[0] * ev->direction[0] + a->base[1] * ev->direction[1];
            lo = p < lo ? p : lo;
            n_in += 1.0;
        }
        if (gi >= c->cfg.n_groups || n_in == 0.0)
            continue;
        const ps_crowd_group_cfg_t *g = &c->cfg.groups[gi];
        const ps_crowd_rect_t *r = &g->region;
        const double area = ((double)r->x_max_m - r->x_min_m) * ((double)r->y_max_m - r->y_min_m);
        const double rho = g->density_m2 > 0.0f ? (double)g->density_m2 : n_in / area;
        const double row = sqrt(2.0 / (sqrt(3.0) * rho)) * sqrt(3.0) / 2.0;
        for (uint32_t i = 0; i < c->n; i++) {
            agent_t *a = &c->a[i];
            const double p = a->base[0] * ev->direction[0] + a->base[1] * ev->direction[1];
            if (a->group != gi || p > lo + (double)ev->rows * row)
                continue;
            a->is_surging = true;
            a->surge_until = (double)ev->t_s + (double)ev->duration_s;
            a->surge_v[0] = (double)ev->speed_m_s * ev->direction[0];
            a->surge_v[1] = (double)ev->speed_m_s * ev->direction[1];
        }
    }
    for (uint32_t i = 0; i < c->n; i++)
        if (c->a[i].is_surging && t_s >= c->a[i].surge_until)
            c->a[i].is_surging = false;
}

/* Helbing 2000's sliding friction between touching agents: kappa g dv_t
 * along the tangent, g the overlap of their MuJoCo contact (the ring
 * contacts are frictionless: this is their tangential part). */
static void sliding_friction(ps_crowd_t *c, const mjModel *m, const mjData *d)
{
    const double kappa = (double)c->cfg.body.sliding_kappa;
    if (kappa <= 0.0)
        return;
    for (int k = 0; k < d->ncon; k++) {
        const mjContact *con = &d->contact[k];
        const int i = c->ring_of_geom[con->geom1], j = c->ring_of_geom[con->geom2];
        if (i < 0 || j < 0 || con->dist >= 0.0)
            continue;
        agent_t *a = &c->a[i], *b = &c->a[j];
        const double t[2] = {-con->frame[1], con->frame[0]}; /* horizontal tangent */
        const double dvt = (b->vcom[0] - a->vcom[0]) * t[0] + (b->vcom[1] - a->vcom[1]) * t[1];
        const double f = kappa * -con->dist * dvt; /* on a, along t */
        if (!a->is_fallen) {
            a->f_contact[0] += f * t[0];
            a->f_contact[1] += f * t[1];
        }
        if (!b->is_fallen) {
            b->f_contact[0] -= f * t[0];
            b->f_contact[1] -= f * t[1];
        }
    }
    (void)m;
}

/* Periodic corridor: an agent past an end re-enters at the other, unless
 * someone stands where it would land (it tries again next update). */
static void wrap_x(ps_crowd_t *c, mjData *d)
{
    const double w = (double)c->cfg.arena.x_max_m - c->cfg.arena.x_min_m;
    for (uint32_t i = 0; i < c->n; i++) {
        agent_t *a = &c->a[i];
        const double x = a->x0 + d->qpos[a->qx];
        const double shift = x > c->cfg.arena.x_max_m   ? -w
                             : x < c->cfg.arena.x_min_m ? w
                                                        : 0.0;
        if (shift == 0.0 || a->is_fallen)
            continue;
        bool is_free = true;
        for (uint32_t j = 0; j < c->n && is_free; j++) {
            const agent_t *b = &c->a[j];
            const double dx = b->x0 + d->qpos[b->qx] - (x + shift);
            const double dy = b->y0 + d->qpos[b->qy] - (a->y0 + d->qpos[a->qy]);
            is_free = j == i || dx * dx + dy * dy > 4.0 * 0.25 * 0.25;
        }
        if (is_free) {
            d->qpos[a->qx] += shift;
            a->feet[0] += shift;
        }
    }
}

/* Horizontal circle around a geom: its centre and bounding radius plus margin. */
static void geom_circle(const mjModel *m, const mjData *d, int g, double out[3])
{
    out[0] = d->geom_xpos[3 * g];
    out[1] = d->geom_xpos[3 * g + 1];
    out[2] = m->geom_rbound[g] + m->geom_margin[g];
}

/* Capsule gating. An agent's capsule touches only the robot and walls
 * (contype/conaffinity), but MuJoCo 2.2.2's broadphase boxes every body by
 * its geoms' bounding spheres: a capsule the height of a person makes a
 * 1.7 m cube that overlaps dozens of other bodies, and every robot body
 * within it goes on to the narrow phase. So a capsule takes part in
 * collision only while the robot (one circle around its touching geoms) or
 * another geom that can touch it is horizontally within reach; otherwise
 * its contype and conaffinity are 0 and the broadphase skips its body. The
 * test is conservative (gate_margin_m covers what moves in an update), so
 * the contacts are those without gating. */
static void gate_capsules(ps_crowd_t *c, const mjModel *m, const mjData *d)
{
    if (!c->is_gated)
        return;
    double robot[3] = {c->robot_xy[0], c->robot_xy[1], 0.0};
    for (int k = 0; k < c->n_robot_geoms; k++) {
        double q[3];
        geom_circle(m, d, c->robot_geom[k], q);
        const double r =
            sqrt((q[0] - robot[0]) * (q[0] - robot[0]) + (q[1] - robot[1]) * (q[1] - robot[1])) +
            q[2];
        robot[2] = r > robot[2] ? r : robot[2];
    }
    for (int k = 0; k < c->n_touchers; k++)
        geom_circle(m, d, c->toucher[k], c->toucher_circle + 3 * k);
    for (uint32_t i = 0; i < c->n; i++) {
        const agent_t *a = &c->a[i];
        const mjtNum *p0 = d->xpos + 3 * a->body, *R = d->xmat + 9 * a->body;
        /* the capsule's horizontal circle: its axis's midpoint, half its
         * horizontal length plus the radius */
        const double h[2] = {a->len * R[2], a->len * R[5]};
        const double cx = p0[0] + h[0] / 2.0, cy = p0[1] + h[1] / 2.0;
        const double reach = sqrt(h[0] * h[0] + h[1] * h[1]) / 2.0 + a->radius + c->gate_margin_m;
        bool is_near = false;
        for (int k = -1; k < c->n_touchers && !is_near; k++) {
            const double *q = k < 0 ? robot : c->toucher_circle + 3 * k;
            const double dx = cx - q[0], dy = cy - q[1], r = reach + q[2];
            is_near = (k >= 0 || c->n_robot_geoms > 0) && dx * dx + dy * dy < r * r;
        }
        c->geom_contype[a->geom] = is_near ? c->cap_contype : 0;
        c->geom_conaffinity[a->geom] = is_near ? c->cap_conaffinity : 0;
    }
}

static void update(ps_crowd_t *c, const mjModel *m, mjData *d, double t_s)
{
    const mjtNum *rp = d->xpos + 3 * c->robot_root;
    c->robot_xy[0] = rp[0];
    c->robot_xy[1] = rp[1];
    if (c->cfg.is_periodic_x)
        wrap_x(c, d);
    for (uint32_t i = 0; i < c->n; i++) {
        read_agent(&c->a[i], d);
        if (c->cfg.is_periodic_x) { /* the kinematics lag the wrap by one step */
            const double dx = c->a[i].com[0] - c->a[i].base[0];
            if (fabs(dx) > 1.0) {
                const double w = (double)c->cfg.arena.x_max_m - c->cfg.arena.x_min_m;
                c->a[i].com[0] -= dx > 0 ? w : -w;
            }
        }
        c->xy[2 * i] = c->a[i].com[0];
        c->xy[2 * i + 1] = c->a[i].com[1];
    }
    ps_social_grid_build(&c->grid, c->xy, c->n);
    run_events(c, t_s);
    uint32_t n_stepping = 0;
    neighbour_pass(c);
    for (uint32_t i = 0; i < c->n; i++) {
        agent_t *a = &c->a[i];
        if (!a->is_fallen)
            social_force(c, i, m, a->f_social);
        else
            a->f_social[0] = a->f_social[1] = 0.0;
        a->f_contact[0] = a->f_contact[1] = 0.0;
    }
    sliding_friction(c, m, d);
    for (uint32_t i = 0; i < c->n; i++) {
        agent_t *a = &c->a[i];
        balance(c, a, d, t_s);
        n_stepping += a->is_stepping ? 1u : 0u;
    }
    c->st.n_stepping = n_stepping;
    /* densities and speed */
    const double rl = (double)c->cfg.local_radius_m;
    const ps_crowd_rect_t *ma = &c->cfg.measure;
    uint32_t n_local = 0, n_meas = 0;
    double speed_sum = 0.0;
    for (uint32_t i = 0; i < c->n; i++) {
        const agent_t *a = &c->a[i];
        const double dx = a->com[0] - c->robot_xy[0], dy = a->com[1] - c->robot_xy[1];
        n_local += dx * dx + dy * dy <= rl * rl ? 1u : 0u;
        if (a->com[0] >= ma->x_min_m && a->com[0] <= ma->x_max_m && a->com[1] >= ma->y_min_m &&
            a->com[1] <= ma->y_max_m) {
            n_meas++;
            speed_sum += sqrt(a->vcom[0] * a->vcom[0] + a->vcom[1] * a->vcom[1]);
        }
    }
    const double area = ((double)ma->x_max_m - ma->x_min_m) * ((double)ma->y_max_m - ma->y_min_m);
    c->st.local_density_m2 = (double)n_local / (M_PI * rl * rl);
    c->st.measure_density_m2 = area > 0.0 ? (double)n_meas / area : 0.0;
    c->st.measure_speed_m_s = n_meas > 0 ? speed_sum / (double)n_meas : 0.0;
    gate_capsules(c, m, d);
}

static double profile(const ps_crowd_event_cfg_t *ev, double t_s)
{
    if (t_s < ev->t_s || t_s >= (double)ev->t_s + ev->duration_s)
        return 0.0;
    if (ev->profile == PS_CROWD_PROFILE_HALF_SINE)
        return sin(M_PI * (t_s - ev->t_s) / (double)ev->duration_s);
    return 1.0;
}

/* A force f (world) at point p of the agent's body as generalised forces on
 * its four joints, J^T f: the slides take f, each hinge the moment of f
 * about its axis through its anchor. mj_applyFT (what xfrc_applied goes
 * through) forms a 3 x nv Jacobian per body, O(agents^2) per step in all;
 * this is O(1) per agent. Axes and anchors are the last mj_step's. */
static void point_force_qfrc(const agent_t *a, const mjData *d, const double p[3],
                             const double f[3])
{
    d->qfrc_applied[a->vx] += f[0];
    d->qfrc_applied[a->vy] += f[1];
    const int joints[2] = {a->jtx, a->jty}, dofs[2] = {a->vtx, a->vty};
    for (int q = 0; q < 2; q++) {
        const mjtNum *ax = d->xaxis + 3 * joints[q], *an = d->xanchor + 3 * joints[q];
        const double r[3] = {p[0] - an[0], p[1] - an[1], p[2] - an[2]};
        const double rxf[3] = {r[1] * f[2] - r[2] * f[1], r[2] * f[0] - r[0] * f[2],
                               r[0] * f[1] - r[1] * f[0]};
        d->qfrc_applied[dofs[q]] += ax[0] * rxf[0] + ax[1] * rxf[1] + ax[2] * rxf[2];
    }
}

static void torso_force_qfrc(const agent_t *a, const mjData *d, const double f[3])
{
    point_force_qfrc(a, d, d->xpos + 3 * a->ring_body, f);
}

/* Helbing 2000's contact with a wall, k g n - kappa g (v . t) t, plus a
 * damper c g' along n (c = 2 zeta sqrt(k m), zeta = body_damping), on the
 * capsule's two sphere centres: against a vertical plane the capsule's
 * deepest point lies below one of them. The arena's sides push this way
 * instead of through MuJoCo contacts (sim/ps_scene.c says why). Runs every
 * physics step; returns the deepest overlap. */
static double arena_contact(ps_crowd_t *c, const agent_t *a, mjData *d)
{
    const ps_crowd_rect_t *ar = &c->cfg.arena;
    const ps_crowd_body_cfg_t *bc = &c->cfg.body;
    const mjtNum *p0 = d->xpos + 3 * a->body, *R = d->xmat + 9 * a->body;
    /* nothing of the capsule reaches a side: most agents, most steps */
    const double reach = a->len + a->radius;
    const bool is_far_x =
        c->cfg.is_periodic_x || (p0[0] - ar->x_min_m > reach && ar->x_max_m - p0[0] > reach);
    if (is_far_x && p0[1] - ar->y_min_m > reach && ar->y_max_m - p0[1] > reach)
        return 0.0;
    const double p1[3] = {p0[0] + a->len * R[2], p0[1] + a->len * R[5], p0[2] + a->len * R[8]};
    /* angular velocity from the hinges' world axes; endpoint velocities */
    const mjtNum *ax = d->xaxis + 3 * a->jtx, *ay = d->xaxis + 3 * a->jty;
    const double wx = d->qvel[a->vtx], wy = d->qvel[a->vty];
    const double om[3] = {wx * ax[0] + wy * ay[0], wx * ax[1] + wy * ay[1],
                          wx * ax[2] + wy * ay[2]};
    const double r1[3] = {p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]};
    const double vb[2] = {d->qvel[a->vx], d->qvel[a->vy]};
    const double v1[2] = {vb[0] + om[1] * r1[2] - om[2] * r1[1],
                          vb[1] + om[2] * r1[0] - om[0] * r1[2]};
    const double *pts[2] = {p0, p1}, *vel[2] = {vb, v1};
    const double k = (double)bc->body_k_n_m, kappa = (double)bc->sliding_kappa;
    const double damp = 2.0 * (double)bc->body_damping * sqrt(k * a->mass);
    /* inward normal and the wall's coordinate along it, per side */
    const double sides[4][3] = {{1.0, 0.0, ar->x_min_m}, {-1.0, 0.0, -(double)ar->x_max_m},
                                {0.0, 1.0, ar->y_min_m}, {0.0, -1.0, -(double)ar->y_max_m}};
    double deepest = 0.0;
    for (int s = c->cfg.is_periodic_x ? 2 : 0; s < 4; s++) {
        const double n[2] = {sides[s][0], sides[s][1]}, t[2] = {-sides[s][1], sides[s][0]};
        for (int q = 0; q < 2; q++) {
            const double *p = pts[q], *v = vel[q];
            const double g = a->radius - (n[0] * p[0] + n[1] * p[1] - sides[s][2]);
            if (g <= 0.0)
                continue;
            const double vn = v[0] * n[0] + v[1] * n[1], vt = v[0] * t[0] + v[1] * t[1];
            double fn = k * g - damp * vn;
            fn = fn > 0.0 ? fn : 0.0;
            const double ft = -kappa * g * vt;
            const double f[3] = {fn * n[0] + ft * t[0], fn * n[1] + ft * t[1], 0.0};
            point_force_qfrc(a, d, p, f);
            deepest = g > deepest ? g : deepest;
        }
    }
    return deepest;
}

void ps_crowd_before_step(ps_crowd_t *c, const mjModel *m, mjData *d, double t_s)
{
    if (c->step_count++ % c->update_every == 0)
        update(c, m, d, t_s);
    for (uint32_t i = 0; i < c->n; i++) {
        const agent_t *a = &c->a[i];
        /* the base force acts on the slides alone, the ankle on the hinges */
        d->qfrc_applied[a->vx] = a->f_base[0];
        d->qfrc_applied[a->vy] = a->f_base[1];
        d->qfrc_applied[a->vtx] = a->tau_ankle[0];
        d->qfrc_applied[a->vty] = a->tau_ankle[1];
        /* Self-propulsion is a ground reaction: spread in proportion to
         * mass (the torso's share at its CoM, the rest at the feet) it
         * translates the person without tipping them. Body contact acts on
         * the torso. */
        const double share = a->m_torso / a->mass;
        const double f[3] = {share * a->f_social[0] + a->f_contact[0],
                             share * a->f_social[1] + a->f_contact[1], 0.0};
        d->qfrc_applied[a->vx] += (1.0 - share) * a->f_social[0];
        d->qfrc_applied[a->vy] += (1.0 - share) * a->f_social[1];
        torso_force_qfrc(a, d, f);
    }
    double wall_pen = 0.0;
    if (c->cfg.has_arena_walls) {
        for (uint32_t i = 0; i < c->n; i++) {
            const double g = arena_contact(c, &c->a[i], d);
            wall_pen = g > wall_pen ? g : wall_pen;
        }
    }
    c->wall_pen_m = wall_pen;
    for (uint32_t e = 0; e < c->cfg.n_events; e++) {
        const ps_crowd_event_cfg_t *ev = &c->cfg.events[e];
        if (ev->kind == PS_CROWD_EVENT_PUSH) {
            const double s = profile(ev, t_s);
            if (s == 0.0)
                continue;
            uint32_t k = 0; /* index within the group */
            for (uint32_t i = 0; i < c->n; i++) {
                const agent_t *a = &c->a[i];
                if (strcmp(c->cfg.groups[a->group].name, ev->group) != 0)
                    continue;
                if (ev->agent < 0 || (uint32_t)ev->agent == k) {
                    const double f[3] = {s * (double)ev->force_n[0], s * (double)ev->force_n[1],
                                         s * (double)ev->force_n[2]};
                    torso_force_qfrc(a, d, f);
                }
                k++;
            }
        } else if (ev->kind == PS_CROWD_EVENT_WALL && c->wall_mocap[e] >= 0) {
            double dt = t_s - (double)ev->t_s;
            dt = dt < 0.0 ? 0.0 : (dt > ev->duration_s ? (double)ev->duration_s : dt);
            mjtNum *mp = d->mocap_pos + 3 * c->wall_mocap[e];
            mp[0] = c->wall_c0[e][0] + (double)ev->speed_m_s * ev->direction[0] * dt;
            mp[1] = c->wall_c0[e][1] + (double)ev->speed_m_s * ev->direction[1] * dt;
        }
    }
}

/* One crowd contact on the robot into the stats' list (the recorder's
 * ground truth); other_body is the crowd's side. */
static void list_robot_contact(ps_crowd_t *c, const mjContact *con, int other_body, uint32_t part,
                               double sign, const double fw[3])
{
    const uint32_t n = c->st.n_robot_contacts_total++;
    if (n >= PS_CROWD_MAX_ROBOT_CONTACTS)
        return;
    ps_crowd_robot_contact_t *rc = &c->st.robot_contact[n];
    const int agent = c->agent_of_body[other_body];
    rc->agent = agent >= 0 ? agent : PS_CROWD_NOT_AGENT;
    rc->part = part;
    for (int q = 0; q < 3; q++) {
        rc->force_n[q] = sign * fw[q];
        rc->pos_m[q] = con->pos[q];
    }
    c->st.n_robot_contacts = n + 1;
}

void ps_crowd_after_step(ps_crowd_t *c, const mjModel *m, const mjData *d, double dt_s)
{
    double part_f[PS_CROWD_MAX_PARTS][3];
    memset(part_f, 0, sizeof(part_f));
    double pen = c->wall_pen_m;
    c->st.n_robot_contacts = 0;
    c->st.n_robot_contacts_total = 0;
    for (int k = 0; k < d->ncon; k++) {
        const mjContact *con = &d->contact[k];
        const int b1 = m->geom_bodyid[con->geom1], b2 = m->geom_bodyid[con->geom2];
        const bool is_a1 = c->agent_of_body[b1] >= 0, is_a2 = c->agent_of_body[b2] >= 0;
        if ((is_a1 || is_a2) && -con->dist > pen)
            pen = -con->dist;
        const int p1 = c->part_of_body[b1], p2 = c->part_of_body[b2];
        /* the crowd on the robot: one side a robot part, the other not the
         * robot and not the world (the floor) */
        const bool is_r1 = p1 >= 0 && !c->is_robot[b2] && b2 != 0;
        const bool is_r2 = p2 >= 0 && !c->is_robot[b1] && b1 != 0;
        if (!is_r1 && !is_r2)
            continue;
        mjtNum f[6];
        mj_contactForce(m, d, k, f);
        /* f acts on geom2 along the frame (normal first, from geom1 to geom2) */
        double fw[3];
        for (int q = 0; q < 3; q++)
            fw[q] = con->frame[q] * f[0] + con->frame[3 + q] * f[1] + con->frame[6 + q] * f[2];
        const int part = is_r2 ? p2 : p1;
        const double sign = is_r2 ? 1.0 : -1.0;
        for (int q = 0; q < 3; q++)
            part_f[part][q] += sign * fw[q];
        list_robot_contact(c, con, is_r2 ? b1 : b2, (uint32_t)part, sign, fw);
        if (is_a1 || is_a2) {
            c->st.transmitted_impulse_ns += f[0] * dt_s;
            c->st.part_impulse_ns[part] += f[0] * dt_s;
        }
    }
    double total = 0.0;
    for (uint32_t p = 0; p < c->st.n_parts; p++) {
        const double fp = sqrt(part_f[p][0] * part_f[p][0] + part_f[p][1] * part_f[p][1] +
                               part_f[p][2] * part_f[p][2]);
        c->st.part_force_n[p] = fp;
        c->st.part_force_max_n[p] = fp > c->st.part_force_max_n[p] ? fp : c->st.part_force_max_n[p];
        total += fp;
    }
    c->st.robot_force_n = total;
    c->st.robot_force_max_n = total > c->st.robot_force_max_n ? total : c->st.robot_force_max_n;
    c->st.penetration_m = pen;
    c->st.penetration_max_m = pen > c->st.penetration_max_m ? pen : c->st.penetration_max_m;
}

void ps_crowd_get_stats(const ps_crowd_t *c, ps_crowd_stats_t *out)
{
    *out = c->st;
}

int ps_crowd_get_agent(const ps_crowd_t *c, uint32_t idx, ps_crowd_agent_state_t *out)
{
    if (idx >= c->n)
        return -EINVAL;
    const agent_t *a = &c->a[idx];
    *out = (ps_crowd_agent_state_t){
        .base_m = {a->base[0], a->base[1]},
        .com_m = {a->com[0], a->com[1], a->com[2]},
        .vel_m_s = {a->vcom[0], a->vcom[1]},
        .tilt_rad = a->tilt,
        .is_stepping = a->is_stepping,
        .is_fallen = a->is_fallen,
        .group_idx = a->group,
    };
    return 0;
}
