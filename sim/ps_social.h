/*
 * ps_social: the social-force decision model of the simulated crowd, as pure
 * functions, and the uniform cell grid that finds each agent's neighbours.
 *
 * The model (Helbing and Molnar 1995; Helbing, Farkas and Vicsek 2000, as
 * RESCUE 001 uses it, with RESCUE's evasive term) gives each agent a force
 * in the floor plane:
 *   drive     m (v0 e - v) / tau                       toward the goal
 *   agents    A exp((r_ij - d_ij) / B) n_ij w(phi)      per neighbour j
 *   walls     A_w exp((r_i - d_iW) / B_w) n_iW          per wall segment
 *   evasive   E s p                                     (RESCUE eq. 1)
 * with w(phi) = lambda + (1 - lambda)(1 + cos phi)/2 the anisotropy of
 * Helbing and Johansson (people react more to whom they see ahead).
 * Body compression and sliding friction, the contact terms of Helbing 2000,
 * are NOT computed here: bodies touch through MuJoCo contacts whose
 * stiffness and friction the scene sets (sim/ps_scene.h).
 *
 * Units: SI, double (the plant's mjtNum), 2-D vectors {x, y} in the world
 * frame. Threads: any; functions are pure or touch only their arguments.
 * Allocation: none (the grid's storage is the caller's).
 */
#ifndef PS_SOCIAL_H
#define PS_SOCIAL_H

#include <stdbool.h>
#include <stdint.h>

/** Social-force parameters. Defaults: ps_social_default_params. */
typedef struct {
    float v0_m_s;          /**< desired speed (thesis 004, Table 6.1: 1.29) */
    float tau_s;           /**< relaxation time (thesis 004, Table 6.1: 0.54) */
    float a_n;             /**< agent repulsion strength (Helbing 2000: 2000 N) */
    float b_m;             /**< agent repulsion range (Helbing 2000: 0.08 m) */
    float wall_a_n;        /**< wall repulsion strength (Helbing 2000: 2000 N) */
    float wall_b_m;        /**< wall repulsion range (Helbing 2000: 0.08 m) */
    float lambda;          /**< anisotropy, 1: isotropic (0.5: our choice, see docs) */
    float range_m;         /**< no social force beyond this centre distance */
    float evasive_n;       /**< RESCUE evasive force magnitude */
    float evasive_range_m; /**< how far ahead (45 degree sector) an obstacle counts */
} ps_social_params_t;

/** @post *out holds the defaults named in ps_social_params_t  @rt any */
void ps_social_default_params(ps_social_params_t *out);

/** Driving term m (v0 e - v) / tau.  @pre tau_s > 0; e unit or zero
 *  @units kg, m/s, s -> N  @rt RT-SAFE O(1) */
void ps_social_drive(double mass_kg, double v0_m_s, double tau_s, const double e[2],
                     const double v_m_s[2], double out_n[2]);

/** Repulsion of agent i (at xi, radius ri, heading e_i, unit or zero) by
 *  agent j: A exp((ri + rj - d) / B) w(phi) along xi - xj. Zero when the
 *  centres coincide or d > range_m.  @units m -> N  @rt RT-SAFE O(1) */
void ps_social_agent_repulsion(const ps_social_params_t *p, const double xi[2], double ri_m,
                               const double e_i[2], const double xj[2], double rj_m,
                               double out_n[2]);

/** Both sides of one pair at once: out_i_n = ps_social_agent_repulsion(i
 *  by j), out_j_n = (j by i), bit for bit, one sqrt and one exp between
 *  them.  @units m -> N  @rt RT-SAFE O(1) */
void ps_social_pair_repulsion(const ps_social_params_t *p, const double xi[2], double ri_m,
                              const double e_i[2], const double xj[2], double rj_m,
                              const double e_j[2], double out_i_n[2], double out_j_n[2]);

/** Repulsion of an agent (at x, radius r) by the wall segment a-b:
 *  A_w exp((r - d) / B_w) along the normal from the closest point. Zero
 *  beyond range_m.  @units m -> N  @rt RT-SAFE O(1) */
void ps_social_wall_repulsion(const ps_social_params_t *p, const double x[2], double r_m,
                              const double a[2], const double b[2], double out_n[2]);

/** RESCUE's evasive term (001, eq. 1): when something blocks the way ahead
 *  (is_blocked: an obstacle in the 45 degree sector ahead), a push of
 *  evasive_n along the perpendicular p of the heading e, to the side away
 *  from the mean relative position o of the neighbours (the side with room;
 *  RESCUE's mask A). Zero when not blocked, e is zero, or o is along e.
 *  @units N  @rt RT-SAFE O(1) */
void ps_social_evasive(const ps_social_params_t *p, bool is_blocked, const double e[2],
                       const double o[2], double out_n[2]);

/** Whether x_j lies in the 45 degree sector ahead of x_i along heading e
 *  (|angle| <= 22.5 deg) within range_m.  @rt RT-SAFE O(1) */
bool ps_social_is_ahead(const double xi[2], const double e[2], const double xj[2],
                        double range_m);

/* ---- cell grid ----------------------------------------------------------- */

/** Uniform grid over a rectangle; points outside are clamped into the border
 *  cells (so nothing is lost, only searched a little wider). Storage is the
 *  caller's: cell_start has n_cells + 1 entries, items has max_items. */
typedef struct {
    double x0_m, y0_m; /**< lower-left corner */
    double cell_m;     /**< cell side, >= the largest query radius */
    int nx, ny;
    uint32_t *cell_start; /**< n_cells + 1 prefix sums */
    uint32_t *items;      /**< point indices sorted by cell */
    uint32_t *cell_of;    /**< per point: its cell (max_items entries) */
    uint32_t max_items;
    uint32_t n_items;
} ps_social_grid_t;

/** Cells needed for a rectangle at a cell size.  @return nx*ny, 0 when the
 *  arguments are not finite and positive  @rt any */
uint32_t ps_social_grid_cells(double w_m, double h_m, double cell_m);

/** @pre storage as described, sized with ps_social_grid_cells  @rt any */
void ps_social_grid_init(ps_social_grid_t *g, double x0_m, double y0_m, double w_m, double h_m,
                         double cell_m, uint32_t *cell_start, uint32_t *items, uint32_t *cell_of,
                         uint32_t max_items);

/** Bin n points (xy interleaved) by counting sort.  @pre n <= max_items
 *  @rt RT-SAFE O(n + cells) */
void ps_social_grid_build(ps_social_grid_t *g, const double *xy, uint32_t n);

/** Cell coordinates of a point (clamped).  @rt RT-SAFE O(1) */
void ps_social_grid_cell(const ps_social_grid_t *g, const double x[2], int *out_cx, int *out_cy);

#endif /* PS_SOCIAL_H */
