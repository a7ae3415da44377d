#include "ps_obs.h"

#include <errno.h>
#include <math.h>
#include <string.h>

static const char *const NAMES[PS_OBS_FIELD_COUNT] = {
    [PS_OBS_GRAVITY_BODY] = "gravity_body",
    [PS_OBS_GYRO_BODY] = "gyro_body",
    [PS_OBS_JOINT_POS] = "joint_pos",
    [PS_OBS_JOINT_VEL] = "joint_vel",
    [PS_OBS_PREV_ACTION] = "prev_action",
    [PS_OBS_COM_POS] = "com_pos",
    [PS_OBS_COM_VEL] = "com_vel",
    [PS_OBS_COP] = "cop",
    [PS_OBS_CAPTURE_POINT] = "capture_point",
    [PS_OBS_BOS_MARGIN] = "bos_margin",
    [PS_OBS_FEET] = "feet",
    [PS_OBS_CONTACT] = "contact",
    [PS_OBS_MOMENTUM] = "momentum",
    [PS_OBS_BASE_ACTION] = "base_action",
};

const char *ps_obs_field_name(ps_obs_field_t f)
{
    return (unsigned)f < PS_OBS_FIELD_COUNT ? NAMES[f] : NULL;
}

int ps_obs_field_find(const char *name)
{
    for (int i = 0; name != NULL && i < (int)PS_OBS_FIELD_COUNT; i++)
        if (strcmp(name, NAMES[i]) == 0)
            return i;
    return -ENOENT;
}

uint32_t ps_obs_field_size(ps_obs_field_t f, uint32_t n_joints, uint32_t n_act)
{
    switch (f) {
    case PS_OBS_GRAVITY_BODY:
    case PS_OBS_GYRO_BODY:
    case PS_OBS_COM_POS:
    case PS_OBS_COM_VEL:
        return 3u;
    case PS_OBS_JOINT_POS:
    case PS_OBS_JOINT_VEL:
        return n_joints;
    case PS_OBS_PREV_ACTION:
    case PS_OBS_BASE_ACTION:
        return n_act;
    case PS_OBS_COP:
    case PS_OBS_CAPTURE_POINT:
    case PS_OBS_CONTACT:
        return 2u;
    case PS_OBS_BOS_MARGIN:
        return 1u;
    case PS_OBS_FEET:
    case PS_OBS_MOMENTUM:
        return 6u;
    case PS_OBS_FIELD_COUNT:
    default:
        return 0u;
    }
}

/* A field whose size is N or A, which a cfg may make 0. */
static bool is_sized_by_cfg(ps_obs_field_t f)
{
    return f == PS_OBS_PREV_ACTION || f == PS_OBS_BASE_ACTION || f == PS_OBS_JOINT_POS ||
           f == PS_OBS_JOINT_VEL;
}

uint32_t ps_obs_size(const ps_obs_cfg_t *cfg)
{
    if (cfg == NULL || cfg->n_fields == 0 || cfg->n_fields > PS_OBS_MAX_FIELDS)
        return 0u;
    uint32_t n = 0;
    for (uint32_t i = 0; i < cfg->n_fields; i++) {
        const uint32_t k = ps_obs_field_size(cfg->fields[i], cfg->n_joints, cfg->n_act);
        if (k == 0u && !is_sized_by_cfg(cfg->fields[i]))
            return 0u;
        n += k;
    }
    return n;
}

int ps_obs_init(ps_obs_t *o, const ps_obs_cfg_t *cfg)
{
    if (o == NULL || cfg == NULL || cfg->n_joints > PS_MAX_JOINTS || cfg->n_act > PS_MAX_JOINTS ||
        !(cfg->clip > 0.0f) || !(cfg->dt_s > 0.0f) || !ps_balance_has_mass_model(&cfg->kin))
        return -EINVAL;
    const uint32_t n = ps_obs_size(cfg);
    if (n == 0u || n > PS_OBS_MAX)
        return -EINVAL;
    for (uint32_t i = 0; i < n; i++)
        if (!(cfg->std[i] > 0.0f) || !isfinite(cfg->std[i]) || !isfinite(cfg->mean[i]))
            return -EINVAL;
    for (uint32_t j = 0; j < cfg->n_joints; j++)
        if (cfg->joint_idx[j] >= PS_MAX_JOINTS || !isfinite(cfg->joint_offset_rad[j]))
            return -EINVAL;
    for (int s = 0; s < 2; s++)
        for (int j = 0; j < PS_LEG_N_JOINTS; j++)
            if (cfg->leg_idx[s][j] < 0 || cfg->leg_idx[s][j] >= (int)PS_MAX_JOINTS)
                return -EINVAL;
    memset(o, 0, sizeof(*o));
    o->cfg = *cfg;
    o->n_obs = n;
    return 0;
}

void ps_obs_reset(ps_obs_t *o)
{
    if (o == NULL)
        return;
    o->has_prev = false;
    memset(o->prev_action, 0, sizeof(o->prev_action));
    memset(o->base_action, 0, sizeof(o->base_action));
}

void ps_obs_set_action(ps_obs_t *o, const float *a)
{
    if (o == NULL || a == NULL)
        return;
    memcpy(o->prev_action, a, o->cfg.n_act * sizeof(float));
}

void ps_obs_set_base_action(ps_obs_t *o, const float *a)
{
    if (o == NULL || a == NULL)
        return;
    memcpy(o->base_action, a, o->cfg.n_act * sizeof(float));
}

static float meas_q(const ps_meas_t *m, uint32_t idx)
{
    return idx < m->n_joints ? m->joints[idx].q_rad : NAN;
}

/* Everything geometric, in the ground frame: points of the mass model, CoM,
 * sole yaw (from the legs' FK) for the support polygon. */
typedef struct {
    ps_balance_point_t pts[PS_BALANCE_N_POINTS];
    float com[3];
    float yaw[2];
} geometry_t;

static int geometry(const ps_obs_t *o, const ps_meas_t *m, const ps_estimate_t *est, geometry_t *g)
{
    const ps_obs_cfg_t *c = &o->cfg;
    float q[2][PS_LEG_N_JOINTS];
    for (int s = 0; s < 2; s++)
        for (int j = 0; j < PS_LEG_N_JOINTS; j++)
            q[s][j] = meas_q(m, (uint32_t)c->leg_idx[s][j]);
    ps_balance_point_t p[PS_BALANCE_N_POINTS];
    if (ps_balance_points(&c->kin, (const float(*)[PS_LEG_N_JOINTS])q, p) < 0)
        return -EINVAL;
    const float(*r)[3] = est->pelvis_rot;
    for (uint32_t i = 0; i < PS_BALANCE_N_POINTS; i++) {
        g->pts[i].mass_kg = p[i].mass_kg;
        for (int a = 0; a < 3; a++)
            g->pts[i].pos_m[a] = est->pelvis_m[a] + r[a][0] * p[i].pos_m[0] +
                                 r[a][1] * p[i].pos_m[1] + r[a][2] * p[i].pos_m[2];
    }
    if (ps_balance_com(g->pts, PS_BALANCE_N_POINTS, g->com) != 0)
        return -EINVAL;
    for (int s = 0; s < 2; s++) {
        float rot[3][3], sole[3];
        ps_estimate_leg_fk_pose(&c->kin, s, q[s], sole, NULL, rot);
        /* the foot's x axis in the ground frame: pelvis_rot * rot column 0 */
        const float fx = r[0][0] * rot[0][0] + r[0][1] * rot[1][0] + r[0][2] * rot[2][0];
        const float fy = r[1][0] * rot[0][0] + r[1][1] * rot[1][0] + r[1][2] * rot[2][0];
        g->yaw[s] = atan2f(fy, fx);
    }
    return 0;
}

int ps_obs_build(ps_obs_t *o, const ps_meas_t *m, const ps_estimate_t *est, float *out_norm,
                 float *out_raw)
{
    if (o == NULL || m == NULL || est == NULL || out_norm == NULL)
        return -EINVAL;
    const ps_obs_cfg_t *c = &o->cfg;
    geometry_t g;
    int rc = geometry(o, m, est, &g) == 0 ? 0 : -ERANGE;
    if (rc != 0)
        memset(&g, 0, sizeof(g));

    /* Velocities and momentum from the previous build. */
    float vel[3] = {0, 0, 0}, mom_p[3] = {0, 0, 0}, mom_l[3] = {0, 0, 0};
    if (o->has_prev && rc == 0) {
        /* The ground frame moves with the feet: measure against the soles
         * that stayed in contact (their shift d since the last build). */
        float d[3] = {0, 0, 0};
        int n_ref = 0;
        for (int s = 0; s < 2; s++) {
            if (!est->is_contact[s] || !o->prev_contact[s])
                continue;
            for (int a = 0; a < 3; a++)
                d[a] += est->foot_m[s][a] - o->prev_feet_m[s][a];
            n_ref++;
        }
        ps_balance_point_t before[PS_BALANCE_N_POINTS];
        for (uint32_t i = 0; i < PS_BALANCE_N_POINTS; i++) {
            before[i] = o->prev_pts[i];
            for (int a = 0; a < 3 && n_ref > 0; a++)
                before[i].pos_m[a] += d[a] / (float)n_ref;
        }
        for (int a = 0; a < 3; a++)
            vel[a] =
                (g.com[a] - o->prev_com_m[a] - (n_ref > 0 ? d[a] / (float)n_ref : 0.0f)) / c->dt_s;
        (void)ps_balance_momentum(g.pts, before, PS_BALANCE_N_POINTS, c->dt_s, mom_p, mom_l);
    }
    const float mass = c->kin.mass_kg > 0.0f ? c->kin.mass_kg : 1.0f;

    /* Support polygon of the contact feet, its centre the reference point. */
    float soles[2][2], poly[PS_BALANCE_MAX_POLY][2], centre[2] = {0, 0};
    for (int s = 0; s < 2; s++) {
        soles[s][0] = est->foot_m[s][0];
        soles[s][1] = est->foot_m[s][1];
    }
    const int n_poly = ps_balance_support_polygon((const float(*)[2])soles, g.yaw, est->is_contact,
                                                  c->kin.foot_length_m, c->kin.foot_width_m, poly);
    if (n_poly <= 0 || ps_balance_polygon_centre((const float(*)[2])poly, n_poly, centre) != 0)
        rc = -ERANGE;
    float cp[2] = {0, 0};
    if (ps_balance_capture_point(g.com, vel, PS_ESTIMATE_G_M_S2, cp) != 0)
        rc = -ERANGE;
    const float margin =
        n_poly > 0 ? ps_balance_polygon_distance((const float(*)[2])poly, n_poly, cp) : 0.0f;

    float raw[PS_OBS_MAX];
    uint32_t n = 0;
    for (uint32_t f = 0; f < c->n_fields; f++) {
        float *v = raw + n;
        switch (c->fields[f]) {
        case PS_OBS_GRAVITY_BODY:
            ps_balance_gravity_body(est->roll_rad, est->pitch_rad, v);
            n += 3;
            break;
        case PS_OBS_GYRO_BODY:
            memcpy(v, m->imu.gyro_body_rad_s, 3 * sizeof(float));
            n += 3;
            break;
        case PS_OBS_JOINT_POS:
            for (uint32_t j = 0; j < c->n_joints; j++)
                v[j] = meas_q(m, c->joint_idx[j]) - c->joint_offset_rad[j];
            n += c->n_joints;
            break;
        case PS_OBS_JOINT_VEL:
            for (uint32_t j = 0; j < c->n_joints; j++)
                v[j] = c->joint_idx[j] < m->n_joints ? m->joints[c->joint_idx[j]].qd_rad_s : NAN;
            n += c->n_joints;
            break;
        case PS_OBS_PREV_ACTION:
            memcpy(v, o->prev_action, c->n_act * sizeof(float));
            n += c->n_act;
            break;
        case PS_OBS_COM_POS:
            v[0] = g.com[0] - centre[0];
            v[1] = g.com[1] - centre[1];
            v[2] = g.com[2];
            n += 3;
            break;
        case PS_OBS_COM_VEL:
            memcpy(v, vel, sizeof(vel));
            n += 3;
            break;
        case PS_OBS_COP:
            v[0] = est->cop_m[0] - centre[0];
            v[1] = est->cop_m[1] - centre[1];
            n += 2;
            break;
        case PS_OBS_CAPTURE_POINT:
            v[0] = cp[0] - centre[0];
            v[1] = cp[1] - centre[1];
            n += 2;
            break;
        case PS_OBS_BOS_MARGIN:
            v[0] = margin;
            n += 1;
            break;
        case PS_OBS_FEET:
            for (int s = 0; s < 2; s++) {
                v[3 * s + 0] = est->foot_m[s][0] - g.com[0];
                v[3 * s + 1] = est->foot_m[s][1] - g.com[1];
                v[3 * s + 2] = est->foot_m[s][2];
            }
            n += 6;
            break;
        case PS_OBS_CONTACT:
            v[0] = est->is_contact[0] ? 1.0f : 0.0f;
            v[1] = est->is_contact[1] ? 1.0f : 0.0f;
            n += 2;
            break;
        case PS_OBS_MOMENTUM:
            for (int a = 0; a < 3; a++) {
                v[a] = mom_p[a] / mass;
                v[3 + a] = mom_l[a] / mass;
            }
            n += 6;
            break;
        case PS_OBS_BASE_ACTION:
            memcpy(v, o->base_action, c->n_act * sizeof(float));
            n += c->n_act;
            break;
        case PS_OBS_FIELD_COUNT:
        default:
            break;
        }
    }
    for (uint32_t i = 0; i < n; i++) {
        if (!isfinite(raw[i]))
            rc = -ERANGE;
        float z = (raw[i] - c->mean[i]) / c->std[i];
        z = z > c->clip ? c->clip : (z < -c->clip ? -c->clip : z);
        out_norm[i] = isfinite(z) ? z : 0.0f;
    }
    if (out_raw != NULL)
        memcpy(out_raw, raw, n * sizeof(float));
    memcpy(o->prev_pts, g.pts, sizeof(g.pts));
    memcpy(o->prev_com_m, g.com, sizeof(g.com));
    memcpy(o->prev_feet_m, est->foot_m, sizeof(o->prev_feet_m));
    o->prev_contact[0] = est->is_contact[0];
    o->prev_contact[1] = est->is_contact[1];
    o->has_prev = rc == 0;
    return rc != 0 ? rc : (int)n;
}
