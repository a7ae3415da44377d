#include "ps_legik.h"

#include <errno.h>
#include <math.h>

static float clampf(float x, float lo, float hi)
{
    return x < lo ? lo : (x > hi ? hi : x);
}

static bool all_finite(const float *v, int n)
{
    for (int i = 0; i < n; i++)
        if (!isfinite(v[i]))
            return false;
    return true;
}

void ps_legik_rot_rpy(float roll_rad, float pitch_rad, float yaw_rad, float out_rot[3][3])
{
    const float cr = cosf(roll_rad), sr = sinf(roll_rad);
    const float cp = cosf(pitch_rad), sp = sinf(pitch_rad);
    const float cy = cosf(yaw_rad), sy = sinf(yaw_rad);
    out_rot[0][0] = cy * cp;
    out_rot[0][1] = cy * sp * sr - sy * cr;
    out_rot[0][2] = cy * sp * cr + sy * sr;
    out_rot[1][0] = sy * cp;
    out_rot[1][1] = sy * sp * sr + cy * cr;
    out_rot[1][2] = sy * sp * cr - cy * sr;
    out_rot[2][0] = -sp;
    out_rot[2][1] = cp * sr;
    out_rot[2][2] = cp * cr;
}

int ps_legik_solve(const ps_kinematics_cfg_t *k, int side, const float sole_m[3],
                   const float foot_rot[3][3], float out_q_rad[PS_LEG_N_JOINTS])
{
    if (k == NULL || sole_m == NULL || foot_rot == NULL || out_q_rad == NULL ||
        (side != 0 && side != 1) || !all_finite(sole_m, 3) || !all_finite(&foot_rot[0][0], 9))
        return -EINVAL;
    const float a = k->thigh_m, b = k->shank_m;
    if (!(a > 0.0f) || !(b > 0.0f))
        return -EINVAL;
    const float (*rf)[3] = foot_rot;
    /* Ankle centre: the sole centre minus the foot's own offset, rotated. */
    const float off[3] = {k->foot_offset_x_m, 0.0f, -k->ankle_height_m};
    float ankle[3];
    for (int i = 0; i < 3; i++)
        ankle[i] = sole_m[i] - (rf[i][0] * off[0] + rf[i][1] * off[1] + rf[i][2] * off[2]);
    const float hip[3] = {0.0f, (side == 0 ? 1.0f : -1.0f) * k->hip_offset_y_m,
                          -k->hip_offset_z_m};
    /* r: hip centre seen from the ankle, in the foot frame (R_f^T (hip - ankle)). */
    const float d[3] = {hip[0] - ankle[0], hip[1] - ankle[1], hip[2] - ankle[2]};
    float r[3];
    for (int i = 0; i < 3; i++)
        r[i] = rf[0][i] * d[0] + rf[1][i] * d[1] + rf[2][i] * d[2];
    float c = sqrtf(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
    int rc = 0;
    const float c_max = a + b, c_min = fabsf(a - b) + 1e-6f;
    if (c > c_max || c < c_min) {
        rc = 1;
        c = clampf(c, c_min, c_max);
    }
    if (!(c > 0.0f))
        return -EINVAL;
    /* Knee from the triangle thigh-shank-c (0: straight, > 0: flexed). */
    const float cos_knee = clampf((c * c - a * a - b * b) / (2.0f * a * b), -1.0f, 1.0f);
    const float knee = acosf(cos_knee);
    /* Ankle: the angle of r in the foot frame, less the shank's share. */
    const float alpha = asinf(clampf(a / c * sinf(3.14159265f - knee), -1.0f, 1.0f));
    float ankle_roll = atan2f(r[1], r[2]);
    if (ankle_roll > 1.5707963f)
        ankle_roll -= 3.14159265f;
    else if (ankle_roll < -1.5707963f)
        ankle_roll += 3.14159265f;
    const float sgn_z = r[2] >= 0.0f ? 1.0f : -1.0f;
    const float ankle_pitch = -atan2f(r[0], sgn_z * sqrtf(r[1] * r[1] + r[2] * r[2])) - alpha;
    /* Hip: R_hip = R_f Rx(-ankle_roll) Ry(-(ankle_pitch + knee)) = Rz(y) Rx(r) Ry(p). */
    const float cr = cosf(-ankle_roll), sr = sinf(-ankle_roll);
    const float t = -(ankle_pitch + knee);
    const float cp = cosf(t), sp = sinf(t);
    const float rx[3][3] = {{1.0f, 0.0f, 0.0f}, {0.0f, cr, -sr}, {0.0f, sr, cr}};
    const float ry[3][3] = {{cp, 0.0f, sp}, {0.0f, 1.0f, 0.0f}, {-sp, 0.0f, cp}};
    float m1[3][3], h[3][3];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            m1[i][j] = rf[i][0] * rx[0][j] + rf[i][1] * rx[1][j] + rf[i][2] * rx[2][j];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            h[i][j] = m1[i][0] * ry[0][j] + m1[i][1] * ry[1][j] + m1[i][2] * ry[2][j];
    const float hip_yaw = atan2f(-h[0][1], h[1][1]);
    const float cy = cosf(hip_yaw), sy = sinf(hip_yaw);
    const float hip_roll = atan2f(h[2][1], -h[0][1] * sy + h[1][1] * cy);
    const float hip_pitch = atan2f(-h[2][0], h[2][2]);
    out_q_rad[PS_LEG_HIP_YAW] = hip_yaw;
    out_q_rad[PS_LEG_HIP_ROLL] = hip_roll;
    out_q_rad[PS_LEG_HIP_PITCH] = hip_pitch;
    out_q_rad[PS_LEG_KNEE] = knee;
    out_q_rad[PS_LEG_ANKLE_PITCH] = ankle_pitch;
    out_q_rad[PS_LEG_ANKLE_ROLL] = ankle_roll;
    return rc;
}
