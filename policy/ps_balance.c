#include "ps_balance.h"

#include <errno.h>
#include <math.h>
#include <string.h>

void ps_balance_gravity_body(float roll_rad, float pitch_rad, float out[3])
{
    const float cr = cosf(roll_rad), sr = sinf(roll_rad);
    const float cp = cosf(pitch_rad), sp = sinf(pitch_rad);
    out[0] = sp;
    out[1] = -sr * cp;
    out[2] = -cr * cp;
}

bool ps_balance_has_mass_model(const ps_kinematics_cfg_t *k)
{
    return k != NULL && k->trunk_mass_kg > 0.0f;
}

/* r <- r * R_axis(a) */
static void chain(float r[3][3], int axis, float a)
{
    const float c = cosf(a), s = sinf(a);
    float m[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    if (axis == 0) {
        m[1][1] = c, m[1][2] = -s, m[2][1] = s, m[2][2] = c;
    } else if (axis == 1) {
        m[0][0] = c, m[0][2] = s, m[2][0] = -s, m[2][2] = c;
    } else {
        m[0][0] = c, m[0][1] = -s, m[1][0] = s, m[1][1] = c;
    }
    float t[3][3];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            t[i][j] = r[i][0] * m[0][j] + r[i][1] * m[1][j] + r[i][2] * m[2][j];
    memcpy(r, t, sizeof(t));
}

static void place(const float base[3], const float r[3][3], const float v[3], float out[3])
{
    for (int i = 0; i < 3; i++)
        out[i] = base[i] + r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2];
}

int ps_balance_points(const ps_kinematics_cfg_t *k, const float q_leg[2][PS_LEG_N_JOINTS],
                      ps_balance_point_t out[PS_BALANCE_N_POINTS])
{
    if (!ps_balance_has_mass_model(k) || q_leg == NULL || out == NULL)
        return -EINVAL;
    out[0] = (ps_balance_point_t){
        {k->trunk_com_x_m, k->trunk_com_y_m, k->trunk_com_z_m}, k->trunk_mass_kg};
    for (int s = 0; s < 2; s++) {
        const float *q = q_leg[s];
        const float hip[3] = {0.0f, (s == 0 ? 1.0f : -1.0f) * k->hip_offset_y_m,
                              -k->hip_offset_z_m};
        float r[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
        chain(r, 2, q[PS_LEG_HIP_YAW]);
        chain(r, 0, q[PS_LEG_HIP_ROLL]);
        chain(r, 1, q[PS_LEG_HIP_PITCH]);
        const float thigh_c[3] = {0.0f, 0.0f, -k->thigh_com_m};
        const float thigh_v[3] = {0.0f, 0.0f, -k->thigh_m};
        float knee[3];
        ps_balance_point_t *p = &out[1 + 4 * s];
        p[0] = (ps_balance_point_t){{hip[0], hip[1], hip[2]}, k->hip_mass_kg};
        place(hip, r, thigh_c, p[1].pos_m);
        p[1].mass_kg = k->thigh_mass_kg;
        place(hip, r, thigh_v, knee);
        chain(r, 1, q[PS_LEG_KNEE]);
        const float shank_c[3] = {0.0f, 0.0f, -k->shank_com_m};
        const float shank_v[3] = {0.0f, 0.0f, -k->shank_m};
        float ankle[3];
        place(knee, r, shank_c, p[2].pos_m);
        p[2].mass_kg = k->shank_mass_kg;
        place(knee, r, shank_v, ankle);
        chain(r, 1, q[PS_LEG_ANKLE_PITCH]);
        chain(r, 0, q[PS_LEG_ANKLE_ROLL]);
        const float foot_c[3] = {k->foot_com_x_m, 0.0f, k->foot_com_z_m};
        place(ankle, r, foot_c, p[3].pos_m);
        p[3].mass_kg = k->foot_mass_kg;
    }
    return (int)PS_BALANCE_N_POINTS;
}

int ps_balance_com(const ps_balance_point_t *pts, uint32_t n, float out_com_m[3])
{
    if (pts == NULL || out_com_m == NULL || n == 0)
        return -EINVAL;
    float m = 0.0f, c[3] = {0.0f, 0.0f, 0.0f};
    for (uint32_t i = 0; i < n; i++) {
        m += pts[i].mass_kg;
        for (int a = 0; a < 3; a++)
            c[a] += pts[i].mass_kg * pts[i].pos_m[a];
    }
    if (!(m > 0.0f) || !isfinite(m))
        return -EINVAL;
    for (int a = 0; a < 3; a++)
        out_com_m[a] = c[a] / m;
    return 0;
}

int ps_balance_momentum(const ps_balance_point_t *now, const ps_balance_point_t *before,
                        uint32_t n, float dt_s, float out_p[3], float out_l[3])
{
    float c[3];
    if (before == NULL || out_p == NULL || out_l == NULL || !(dt_s > 0.0f) ||
        ps_balance_com(now, n, c) != 0)
        return -EINVAL;
    float p[3] = {0, 0, 0}, l[3] = {0, 0, 0};
    for (uint32_t i = 0; i < n; i++) {
        const float m = now[i].mass_kg;
        float v[3], r[3];
        for (int a = 0; a < 3; a++) {
            v[a] = (now[i].pos_m[a] - before[i].pos_m[a]) / dt_s;
            r[a] = now[i].pos_m[a] - c[a];
            p[a] += m * v[a];
        }
        l[0] += m * (r[1] * v[2] - r[2] * v[1]);
        l[1] += m * (r[2] * v[0] - r[0] * v[2]);
        l[2] += m * (r[0] * v[1] - r[1] * v[0]);
    }
    memcpy(out_p, p, sizeof(p));
    memcpy(out_l, l, sizeof(l));
    return 0;
}

int ps_balance_capture_point(const float com_m[3], const float vel_m_s[3], float g_m_s2,
                             float out_xy[2])
{
    if (com_m == NULL || vel_m_s == NULL || out_xy == NULL || !(com_m[2] > 0.0f) ||
        !(g_m_s2 > 0.0f))
        return -EINVAL;
    const float w0 = sqrtf(g_m_s2 / com_m[2]);
    const float x = com_m[0] + vel_m_s[0] / w0, y = com_m[1] + vel_m_s[1] / w0;
    if (!isfinite(x) || !isfinite(y))
        return -EINVAL;
    out_xy[0] = x;
    out_xy[1] = y;
    return 0;
}

static float cross(const float o[2], const float a[2], const float b[2])
{
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
}

int ps_balance_support_polygon(const float sole_xy[2][2], const float yaw_rad[2],
                               const bool is_contact[2], float length_m, float width_m,
                               float out_xy[PS_BALANCE_MAX_POLY][2])
{
    if (sole_xy == NULL || yaw_rad == NULL || is_contact == NULL || out_xy == NULL ||
        !(length_m > 0.0f) || !(width_m > 0.0f))
        return -EINVAL;
    float pts[8][2];
    int n = 0;
    const float hl = 0.5f * length_m, hw = 0.5f * width_m;
    static const float SX[4] = {1, -1, -1, 1}, SY[4] = {1, 1, -1, -1};
    for (int s = 0; s < 2; s++) {
        if (!is_contact[s])
            continue;
        const float c = cosf(yaw_rad[s]), sn = sinf(yaw_rad[s]);
        for (int k = 0; k < 4; k++) {
            const float x = SX[k] * hl, y = SY[k] * hw;
            pts[n][0] = sole_xy[s][0] + c * x - sn * y;
            pts[n][1] = sole_xy[s][1] + sn * x + c * y;
            n++;
        }
    }
    if (n == 0)
        return 0;
    /* Andrew's monotone chain on at most 8 points: sort by x, then y. */
    for (int i = 1; i < n; i++) {
        float t[2] = {pts[i][0], pts[i][1]};
        int j = i - 1;
        while (j >= 0 && (pts[j][0] > t[0] || (pts[j][0] == t[0] && pts[j][1] > t[1]))) {
            pts[j + 1][0] = pts[j][0];
            pts[j + 1][1] = pts[j][1];
            j--;
        }
        pts[j + 1][0] = t[0];
        pts[j + 1][1] = t[1];
    }
    float hull[16][2];
    int h = 0;
    for (int i = 0; i < n; i++) { /* lower */
        while (h >= 2 && cross(hull[h - 2], hull[h - 1], pts[i]) <= 0.0f)
            h--;
        hull[h][0] = pts[i][0], hull[h][1] = pts[i][1], h++;
    }
    for (int i = n - 2, lo = h + 1; i >= 0; i--) { /* upper */
        while (h >= lo && cross(hull[h - 2], hull[h - 1], pts[i]) <= 0.0f)
            h--;
        hull[h][0] = pts[i][0], hull[h][1] = pts[i][1], h++;
    }
    h--; /* the last point repeats the first */
    for (int i = 0; i < h && i < (int)PS_BALANCE_MAX_POLY; i++) {
        out_xy[i][0] = hull[i][0];
        out_xy[i][1] = hull[i][1];
    }
    return h < (int)PS_BALANCE_MAX_POLY ? h : (int)PS_BALANCE_MAX_POLY;
}

/* Distance from p to segment ab. */
static float seg_dist(const float a[2], const float b[2], const float p[2])
{
    const float dx = b[0] - a[0], dy = b[1] - a[1];
    const float l2 = dx * dx + dy * dy;
    float t = l2 > 0.0f ? ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2 : 0.0f;
    t = t < 0.0f ? 0.0f : (t > 1.0f ? 1.0f : t);
    const float ex = a[0] + t * dx - p[0], ey = a[1] + t * dy - p[1];
    return sqrtf(ex * ex + ey * ey);
}

float ps_balance_polygon_distance(const float (*poly)[2], int n, const float p[2])
{
    if (poly == NULL || p == NULL || n <= 0)
        return -INFINITY;
    if (n == 1)
        return -seg_dist(poly[0], poly[0], p);
    bool is_inside = n >= 3;
    float d = INFINITY;
    for (int i = 0; i < n; i++) {
        const float *a = poly[i], *b = poly[(i + 1) % n];
        const float e = seg_dist(a, b, p);
        d = e < d ? e : d;
        if (cross(a, b, p) < 0.0f)
            is_inside = false;
    }
    return is_inside ? d : -d;
}

int ps_balance_polygon_centre(const float (*poly)[2], int n, float out_xy[2])
{
    if (poly == NULL || out_xy == NULL || n < 1)
        return -EINVAL;
    float x = 0.0f, y = 0.0f;
    for (int i = 0; i < n; i++) {
        x += poly[i][0];
        y += poly[i][1];
    }
    out_xy[0] = x / (float)n;
    out_xy[1] = y / (float)n;
    return 0;
}

int ps_balance_cop(const float (*point_xy)[2], const float *force_n, uint32_t n, float out_xy[2])
{
    if (point_xy == NULL || force_n == NULL || out_xy == NULL || n == 0)
        return -EINVAL;
    float f = 0.0f, x = 0.0f, y = 0.0f;
    for (uint32_t i = 0; i < n; i++) {
        f += force_n[i];
        x += force_n[i] * point_xy[i][0];
        y += force_n[i] * point_xy[i][1];
    }
    if (!(f > 0.0f) || !isfinite(f))
        return -EINVAL;
    out_xy[0] = x / f;
    out_xy[1] = y / f;
    return 0;
}

int ps_balance_com_velocity_odometry(const float com_now[3], const float com_before[3],
                                     const float sole_now[3], const float sole_before[3],
                                     const float gyro_rad_s[3], const float (*rot)[3], float dt_s,
                                     float out_m_s[3])
{
    if (com_now == NULL || com_before == NULL || sole_now == NULL || sole_before == NULL ||
        gyro_rad_s == NULL || rot == NULL || out_m_s == NULL || !(dt_s > 0.0f))
        return -EINVAL;
    const float *w = gyro_rad_s;
    float r[3], v[3];
    for (int a = 0; a < 3; a++)
        r[a] = com_now[a] - sole_now[a];
    for (int a = 0; a < 3; a++)
        v[a] = (com_now[a] - com_before[a] - (sole_now[a] - sole_before[a])) / dt_s;
    v[0] += w[1] * r[2] - w[2] * r[1];
    v[1] += w[2] * r[0] - w[0] * r[2];
    v[2] += w[0] * r[1] - w[1] * r[0];
    for (int a = 0; a < 3; a++)
        out_m_s[a] = rot[a][0] * v[0] + rot[a][1] * v[1] + rot[a][2] * v[2];
    return 0;
}
