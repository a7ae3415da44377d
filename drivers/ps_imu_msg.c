#include "ps_imu_msg.h"

#include <math.h>
#include <stdbool.h>
#include <string.h>

#include "../rt/ps_err.h"

#define RAW_MAX 32767

/* Round to the nearest LSB and saturate symmetrically to +-32767 (the header
 * documents +-32.767 rad/s, so -32768 is never sent). *is_sat is set, never
 * cleared, so one call per axis accumulates into the status bit. */
static int16_t to_raw(float x, float lsb, bool *is_sat)
{
    if (isnan(x)) {
        *is_sat = true;
        return 0;
    }
    const float r = roundf(x / lsb);
    if (r > (float)RAW_MAX) {
        *is_sat = true;
        return RAW_MAX;
    }
    if (r < -(float)RAW_MAX) {
        *is_sat = true;
        return -RAW_MAX;
    }
    return (int16_t)r;
}

static void put_le16(uint8_t *p, int16_t v)
{
    const uint16_t u = (uint16_t)v;
    p[0] = (uint8_t)(u & 0xFFu);
    p[1] = (uint8_t)(u >> 8);
}

static int16_t get_le16(const uint8_t *p)
{
    return (int16_t)(uint16_t)((uint16_t)p[0] | ((uint16_t)p[1] << 8));
}

/* Components in +-32767 LSB: -32768 lies outside the message (the encoder
 * never sends it) and is refused, not decoded beyond the stated range. */
static bool is_in_scale(const uint8_t *data)
{
    for (unsigned a = 0; a < 3; a++)
        if (get_le16(&data[2 * a]) < -RAW_MAX)
            return false;
    return true;
}

void ps_imu_msg_encode(uint32_t base_id, const ps_imu_sample_t *s, ps_can_frame_t out[2])
{
    bool is_gyro_sat = false, is_accel_sat = false;
    memset(out, 0, 2 * sizeof out[0]);
    out[0].id = base_id;
    out[0].len = 8;
    out[1].id = base_id + 1u;
    out[1].len = 8;
    for (unsigned a = 0; a < 3; a++) {
        put_le16(&out[0].data[2 * a],
                 to_raw(s->gyro_body_rad_s[a], PS_IMU_GYRO_LSB_RAD_S, &is_gyro_sat));
        put_le16(&out[1].data[2 * a],
                 to_raw(s->accel_body_m_s2[a], PS_IMU_ACCEL_LSB_M_S2, &is_accel_sat));
    }
    uint8_t status = s->status;
    if (is_gyro_sat)
        status |= PS_IMU_STATUS_GYRO_SAT;
    if (is_accel_sat)
        status |= PS_IMU_STATUS_ACCEL_SAT;
    out[0].data[6] = s->seq;
    out[0].data[7] = status;
    out[1].data[6] = (uint8_t)s->temp_c;
    out[1].data[7] = s->seq;
}

void ps_imu_msg_rx_init(ps_imu_msg_rx_t *rx, uint32_t base_id)
{
    memset(rx, 0, sizeof *rx);
    rx->base_id = base_id;
}

int ps_imu_msg_rx_feed(ps_imu_msg_rx_t *rx, const ps_can_frame_t *f, ps_imu_sample_t *out)
{
    const bool is_gyro = f->id == rx->base_id;
    const bool is_accel = f->id == rx->base_id + 1u;
    if (f->is_ext || (!is_gyro && !is_accel))
        return -ENOENT;
    if (f->len != 8 || !is_in_scale(f->data)) {
        /* The stream is broken; pairing across it could mix two samples. */
        rx->has_gyro = 0;
        return -PS_ERR_PROTOCOL;
    }
    if (is_gyro) {
        for (unsigned a = 0; a < 3; a++)
            rx->gyro_body_rad_s[a] = (float)get_le16(&f->data[2 * a]) * PS_IMU_GYRO_LSB_RAD_S;
        rx->gyro_seq = f->data[6];
        rx->gyro_status = f->data[7];
        rx->gyro_t_ns = f->t_ns;
        rx->has_gyro = 1;
        return 0;
    }
    const uint8_t seq = f->data[7];
    if (!rx->has_gyro || rx->gyro_seq != seq) {
        rx->has_gyro = 0;
        return -PS_ERR_PROTOCOL;
    }
    rx->has_gyro = 0;
    for (unsigned a = 0; a < 3; a++) {
        out->gyro_body_rad_s[a] = rx->gyro_body_rad_s[a];
        out->accel_body_m_s2[a] = (float)get_le16(&f->data[2 * a]) * PS_IMU_ACCEL_LSB_M_S2;
    }
    out->temp_c = (int8_t)f->data[6];
    out->seq = seq;
    out->status = rx->gyro_status;
    out->t_ns = rx->gyro_t_ns;
    return 1;
}
