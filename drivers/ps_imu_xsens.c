#include "ps_imu_xsens.h"

#include <errno.h>
#include <math.h>
#include <string.h>

#include "../rt/ps_err.h"

#define RAW_MAX 32767

static void put_be16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)(v >> 8);
    p[1] = (uint8_t)(v & 0xffu);
}

static void put_be32(uint8_t *p, uint32_t v)
{
    put_be16(p, (uint16_t)(v >> 16));
    put_be16(p + 2, (uint16_t)(v & 0xffffu));
}

static uint16_t get_be16(const uint8_t *p)
{
    return (uint16_t)(((uint16_t)p[0] << 8) | p[1]);
}

static uint32_t get_be32(const uint8_t *p)
{
    return ((uint32_t)get_be16(p) << 16) | get_be16(p + 2);
}

/* Round to the LSB and saturate to +-32767; *is_clipped set, never cleared. */
static int16_t to_raw(float x, float lsb, bool *is_clipped)
{
    if (isnan(x)) {
        *is_clipped = true;
        return 0;
    }
    const float r = roundf(x / lsb);
    if (r > (float)RAW_MAX || r < -(float)RAW_MAX) {
        *is_clipped = true;
        return r > 0 ? RAW_MAX : -RAW_MAX;
    }
    return (int16_t)r;
}

static ps_can_frame_t frame(uint32_t id, uint8_t len)
{
    ps_can_frame_t f;
    memset(&f, 0, sizeof(f));
    f.id = id;
    f.len = len;
    return f;
}

int ps_imu_xsens_encode(uint32_t base_id, const ps_imu_sample_t *s, uint16_t counter,
                        uint32_t sample_time, ps_can_frame_t out[PS_IMU_XSENS_N_FRAMES])
{
    uint32_t status = PS_IMU_XSENS_STATUS_FILTER;
    if (!(s->status & PS_IMU_STATUS_SELFTEST_FAIL))
        status |= PS_IMU_XSENS_STATUS_SELFTEST;
    ps_can_frame_t *rot = &out[3], *acc = &out[4];
    *rot = frame(base_id + PS_IMU_XSENS_OFS_RATE_OF_TURN, 6);
    *acc = frame(base_id + PS_IMU_XSENS_OFS_ACCELERATION, 6);
    for (unsigned a = 0; a < 3; a++) {
        bool is_gyr_clip = false, is_acc_clip = false;
        put_be16(&rot->data[2 * a], (uint16_t)to_raw(s->gyro_body_rad_s[a],
                                                     PS_IMU_XSENS_GYRO_LSB_RAD_S, &is_gyr_clip));
        put_be16(&acc->data[2 * a], (uint16_t)to_raw(s->accel_body_m_s2[a],
                                                     PS_IMU_XSENS_ACCEL_LSB_M_S2, &is_acc_clip));
        status |= is_acc_clip ? (0x100u << a) : 0u;
        status |= is_gyr_clip ? (0x800u << a) : 0u;
    }
    out[0] = frame(base_id + PS_IMU_XSENS_OFS_SAMPLE_TIME, 4);
    put_be32(out[0].data, sample_time);
    out[1] = frame(base_id + PS_IMU_XSENS_OFS_COUNTER, 2);
    put_be16(out[1].data, counter);
    out[2] = frame(base_id + PS_IMU_XSENS_OFS_STATUS, 4);
    put_be32(out[2].data, status);
    return (int)PS_IMU_XSENS_N_FRAMES;
}

void ps_imu_xsens_rx_init(ps_imu_xsens_rx_t *rx, uint32_t base_id)
{
    memset(rx, 0, sizeof(*rx));
    rx->base_id = base_id;
}

/* A group's SampleTime comes before its GroupCounter and its StatusWord
 * after: the counter takes the time that came just before it (and no older
 * one: has_pending_time is used once) and starts the status afresh, so a
 * group that lost a frame lends nothing to the next. */
static int open_group(ps_imu_xsens_rx_t *rx, const ps_can_frame_t *f)
{
    if (rx->is_open)
        rx->n_incomplete++; /* the previous group never got its acceleration */
    rx->is_open = true;
    rx->has_gyro = false;
    rx->has_status = false;
    rx->has_time = rx->has_pending_time;
    rx->has_pending_time = false;
    rx->sample_time = rx->pending_time;
    rx->counter = get_be16(f->data);
    rx->t_ns = rx->has_time ? rx->pending_t_ns : f->t_ns;
    return 0;
}

static uint8_t status_bits(const ps_imu_xsens_rx_t *rx)
{
    if (!rx->has_status)
        return 0;
    uint8_t st = 0;
    if (rx->status_word & PS_IMU_XSENS_STATUS_CLIP_ACC)
        st |= PS_IMU_STATUS_ACCEL_SAT;
    if (rx->status_word & PS_IMU_XSENS_STATUS_CLIP_GYR)
        st |= PS_IMU_STATUS_GYRO_SAT;
    if (!(rx->status_word & PS_IMU_XSENS_STATUS_SELFTEST))
        st |= PS_IMU_STATUS_SELFTEST_FAIL;
    return st;
}

/* The group's last frame: check it is whole and fresh, then hand it over. */
static int close_group(ps_imu_xsens_rx_t *rx, const ps_can_frame_t *f, ps_imu_sample_t *out)
{
    const bool is_whole = rx->is_open && rx->has_gyro;
    const bool is_frozen =
        rx->has_time && rx->has_last_time && rx->sample_time == rx->last_sample_time;
    rx->is_open = false;
    if (!is_whole) {
        rx->n_incomplete++;
        rx->has_time = rx->has_status = false;
        return -PS_ERR_PROTOCOL;
    }
    if (rx->has_last_counter && rx->counter != (uint16_t)(rx->last_counter + 1u))
        rx->n_gaps++;
    rx->has_last_counter = true;
    rx->last_counter = rx->counter;
    if (rx->has_time) {
        rx->last_sample_time = rx->sample_time;
        rx->has_last_time = true;
    }
    const uint8_t status = status_bits(rx);
    rx->has_time = rx->has_status = false;
    if (is_frozen) {
        rx->n_frozen++;
        return -PS_ERR_PROTOCOL;
    }
    for (unsigned a = 0; a < 3; a++) {
        out->gyro_body_rad_s[a] = rx->gyro_body_rad_s[a];
        out->accel_body_m_s2[a] =
            (float)(int16_t)get_be16(&f->data[2 * a]) * PS_IMU_XSENS_ACCEL_LSB_M_S2;
    }
    out->temp_c = 0;
    out->seq = (uint8_t)(rx->counter & 0xffu);
    out->status = status;
    out->t_ns = rx->t_ns;
    return 1;
}

int ps_imu_xsens_rx_feed(ps_imu_xsens_rx_t *rx, const ps_can_frame_t *f, ps_imu_sample_t *out)
{
    if (f->is_ext || f->id < rx->base_id)
        return -ENOENT;
    static const uint8_t LEN[] = {[PS_IMU_XSENS_OFS_SAMPLE_TIME] = 4,
                                  [PS_IMU_XSENS_OFS_COUNTER] = 2,
                                  [PS_IMU_XSENS_OFS_STATUS] = 4,
                                  [PS_IMU_XSENS_OFS_RATE_OF_TURN] = 6,
                                  [PS_IMU_XSENS_OFS_ACCELERATION] = 6};
    const uint32_t ofs = f->id - rx->base_id;
    if (ofs >= sizeof(LEN) || LEN[ofs] == 0)
        return -ENOENT;
    if (f->len != LEN[ofs] || f->is_fd) {
        rx->is_open = false; /* the stream is broken: do not mix two samples */
        rx->has_time = rx->has_status = rx->has_pending_time = false;
        return -PS_ERR_PROTOCOL;
    }
    switch (ofs) {
    case PS_IMU_XSENS_OFS_SAMPLE_TIME:
        rx->pending_time = get_be32(f->data);
        rx->has_pending_time = true;
        rx->pending_t_ns = f->t_ns; /* SampleTime comes first: the group's time */
        return 0;
    case PS_IMU_XSENS_OFS_COUNTER:
        return open_group(rx, f);
    case PS_IMU_XSENS_OFS_STATUS:
        rx->status_word = get_be32(f->data);
        rx->has_status = true;
        return 0;
    case PS_IMU_XSENS_OFS_RATE_OF_TURN:
        for (unsigned a = 0; a < 3; a++)
            rx->gyro_body_rad_s[a] =
                (float)(int16_t)get_be16(&f->data[2 * a]) * PS_IMU_XSENS_GYRO_LSB_RAD_S;
        rx->has_gyro = rx->is_open;
        return 0;
    default:
        return close_group(rx, f, out);
    }
}
