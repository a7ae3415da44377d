#include "ps_social.h"

#include <math.h>
#include <string.h>

/* cos(22.5 deg): RESCUE's 45 degree perception sector ahead. */
#define SECTOR_COS 0.92387953251128674

void ps_social_default_params(ps_social_params_t *out)
{
    *out = (ps_social_params_t){
        .v0_m_s = 1.29f,
        .tau_s = 0.54f,
        .a_n = 2000.0f,
        .b_m = 0.08f,
        .wall_a_n = 2000.0f,
        .wall_b_m = 0.08f,
        .lambda = 0.5f,
        .range_m = 1.0f,
        .evasive_n = 80.0f,
        .evasive_range_m = 1.5f,
    };
}

void ps_social_drive(double mass_kg, double v0_m_s, double tau_s, const double e[2],
                     const double v_m_s[2], double out_n[2])
{
    for (int k = 0; k < 2; k++)
        out_n[k] = mass_kg * (v0_m_s * e[k] - v_m_s[k]) / tau_s;
}

void ps_social_agent_repulsion(const ps_social_params_t *p, const double xi[2], double ri_m,
                               const double e_i[2], const double xj[2], double rj_m,
                               double out_n[2])
{
    out_n[0] = out_n[1] = 0.0;
    const double dx = xi[0] - xj[0], dy = xi[1] - xj[1];
    const double d = sqrt(dx * dx + dy * dy);
    if (d <= 0.0 || d > (double)p->range_m)
        return;
    const double n[2] = {dx / d, dy / d};
    /* phi: angle between the heading and the direction to j (-n). */
    double w = 1.0;
    if (e_i[0] != 0.0 || e_i[1] != 0.0) {
        const double cos_phi = -(e_i[0] * n[0] + e_i[1] * n[1]);
        const double lambda = (double)p->lambda;
        w = lambda + (1.0 - lambda) * 0.5 * (1.0 + cos_phi);
    }
    const double f = (double)p->a_n * exp((ri_m + rj_m - d) / (double)p->b_m) * w;
    out_n[0] = f * n[0];
    out_n[1] = f * n[1];
}

/* w(phi) of an agent heading e toward a neighbour in direction -n. */
static double anisotropy(const ps_social_params_t *p, const double e[2], const double n[2])
{
    if (e[0] == 0.0 && e[1] == 0.0)
        return 1.0;
    const double cos_phi = -(e[0] * n[0] + e[1] * n[1]);
    const double lambda = (double)p->lambda;
    return lambda + (1.0 - lambda) * 0.5 * (1.0 + cos_phi);
}

void ps_social_pair_repulsion(const ps_social_params_t *p, const double xi[2], double ri_m,
                              const double e_i[2], const double xj[2], double rj_m,
                              const double e_j[2], double out_i_n[2], double out_j_n[2])
{
    out_i_n[0] = out_i_n[1] = out_j_n[0] = out_j_n[1] = 0.0;
    const double dx = xi[0] - xj[0], dy = xi[1] - xj[1];
    const double d = sqrt(dx * dx + dy * dy);
    if (d <= 0.0 || d > (double)p->range_m)
        return;
    const double n[2] = {dx / d, dy / d}, nj[2] = {-n[0], -n[1]};
    const double s = (double)p->a_n * exp((ri_m + rj_m - d) / (double)p->b_m);
    const double fi = s * anisotropy(p, e_i, n), fj = s * anisotropy(p, e_j, nj);
    out_i_n[0] = fi * n[0];
    out_i_n[1] = fi * n[1];
    out_j_n[0] = fj * nj[0];
    out_j_n[1] = fj * nj[1];
}

void ps_social_wall_repulsion(const ps_social_params_t *p, const double x[2], double r_m,
                              const double a[2], const double b[2], double out_n[2])
{
    out_n[0] = out_n[1] = 0.0;
    const double ab[2] = {b[0] - a[0], b[1] - a[1]};
    const double len2 = ab[0] * ab[0] + ab[1] * ab[1];
    double t = len2 > 0.0 ? ((x[0] - a[0]) * ab[0] + (x[1] - a[1]) * ab[1]) / len2 : 0.0;
    t = t < 0.0 ? 0.0 : (t > 1.0 ? 1.0 : t);
    const double dx = x[0] - (a[0] + t * ab[0]), dy = x[1] - (a[1] + t * ab[1]);
    const double d = sqrt(dx * dx + dy * dy);
    if (d <= 0.0 || d > (double)p->range_m)
        return;
    const double f = (double)p->wall_a_n * exp((r_m - d) / (double)p->wall_b_m);
    out_n[0] = f * dx / d;
    out_n[1] = f * dy / d;
}

void ps_social_evasive(const ps_social_params_t *p, bool is_blocked, const double e[2],
                       const double o[2], double out_n[2])
{
    out_n[0] = out_n[1] = 0.0;
    if (!is_blocked || (e[0] == 0.0 && e[1] == 0.0))
        return;
    const double perp[2] = {-e[1], e[0]}; /* left of the heading */
    const double side = o[0] * perp[0] + o[1] * perp[1];
    if (side == 0.0)
        return;
    const double s = side > 0.0 ? -1.0 : 1.0; /* away from the neighbours */
    out_n[0] = (double)p->evasive_n * s * perp[0];
    out_n[1] = (double)p->evasive_n * s * perp[1];
}

bool ps_social_is_ahead(const double xi[2], const double e[2], const double xj[2], double range_m)
{
    const double dx = xj[0] - xi[0], dy = xj[1] - xi[1];
    const double d = sqrt(dx * dx + dy * dy);
    if (d <= 0.0 || d > range_m)
        return false;
    return (dx * e[0] + dy * e[1]) / d >= SECTOR_COS;
}

/* ---- cell grid ----------------------------------------------------------- */

uint32_t ps_social_grid_cells(double w_m, double h_m, double cell_m)
{
    if (!(w_m > 0.0) || !(h_m > 0.0) || !(cell_m > 0.0) || !isfinite(w_m) || !isfinite(h_m))
        return 0;
    const double nx = ceil(w_m / cell_m), ny = ceil(h_m / cell_m);
    if (nx * ny > 1e7)
        return 0;
    return (uint32_t)(nx < 1 ? 1 : nx) * (uint32_t)(ny < 1 ? 1 : ny);
}

void ps_social_grid_init(ps_social_grid_t *g, double x0_m, double y0_m, double w_m, double h_m,
                         double cell_m, uint32_t *cell_start, uint32_t *items, uint32_t *cell_of,
                         uint32_t max_items)
{
    g->x0_m = x0_m;
    g->y0_m = y0_m;
    g->cell_m = cell_m;
    g->nx = (int)ceil(w_m / cell_m);
    g->ny = (int)ceil(h_m / cell_m);
    g->nx = g->nx < 1 ? 1 : g->nx;
    g->ny = g->ny < 1 ? 1 : g->ny;
    g->cell_start = cell_start;
    g->items = items;
    g->cell_of = cell_of;
    g->max_items = max_items;
    g->n_items = 0;
}

void ps_social_grid_cell(const ps_social_grid_t *g, const double x[2], int *out_cx, int *out_cy)
{
    double fx = floor((x[0] - g->x0_m) / g->cell_m);
    double fy = floor((x[1] - g->y0_m) / g->cell_m);
    fx = isfinite(fx) ? fx : 0.0;
    fy = isfinite(fy) ? fy : 0.0;
    *out_cx = fx < 0.0 ? 0 : (fx >= g->nx ? g->nx - 1 : (int)fx);
    *out_cy = fy < 0.0 ? 0 : (fy >= g->ny ? g->ny - 1 : (int)fy);
}

void ps_social_grid_build(ps_social_grid_t *g, const double *xy, uint32_t n)
{
    const uint32_t n_cells = (uint32_t)g->nx * (uint32_t)g->ny;
    if (n > g->max_items)
        n = g->max_items;
    memset(g->cell_start, 0, (n_cells + 1u) * sizeof(g->cell_start[0]));
    for (uint32_t i = 0; i < n; i++) {
        int cx, cy;
        ps_social_grid_cell(g, xy + 2 * i, &cx, &cy);
        g->cell_of[i] = (uint32_t)(cy * g->nx + cx);
        g->cell_start[g->cell_of[i] + 1u]++;
    }
    for (uint32_t c = 0; c < n_cells; c++)
        g->cell_start[c + 1u] += g->cell_start[c];
    /* Place each point at its cell's next free slot; cell_start is shifted by
     * one slot per placed point, then restored. */
    for (uint32_t i = 0; i < n; i++)
        g->items[g->cell_start[g->cell_of[i]]++] = i;
    for (uint32_t c = n_cells; c > 0; c--)
        g->cell_start[c] = g->cell_start[c - 1u];
    g->cell_start[0] = 0;
    g->n_items = n;
}
