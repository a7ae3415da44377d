#include "ps_imu.h"

#include <errno.h>
#include <math.h>
#include <string.h>

#include "../rt/ps_err.h"

static const char *const NAMES[PS_IMU_PROTO_COUNT] = {
    [PS_IMU_PROTO_PUSHSTEP] = "pushstep",
    [PS_IMU_PROTO_XSENS] = "xsens",
};

const char *ps_imu_proto_name(ps_imu_proto_id_t id)
{
    return (unsigned)id < PS_IMU_PROTO_COUNT ? NAMES[id] : "?";
}

int ps_imu_proto_find(const char *name)
{
    for (int i = 0; i < PS_IMU_PROTO_COUNT; i++)
        if (strcmp(NAMES[i], name) == 0)
            return i;
    return -ENOENT;
}

void ps_imu_rx_init(ps_imu_rx_t *rx, const ps_imu_cfg_t *cfg)
{
    memset(rx, 0, sizeof(*rx));
    rx->protocol = cfg->protocol;
    rx->frozen_samples = cfg->frozen_samples;
    if (cfg->protocol == PS_IMU_PROTO_XSENS)
        ps_imu_xsens_rx_init(&rx->u.xsens, cfg->base_id);
    else
        ps_imu_msg_rx_init(&rx->u.msg, cfg->base_id);
}

uint32_t ps_imu_frozen_default(uint32_t imu_hz)
{
    const double n = ceil(PS_IMU_FROZEN_DEFAULT_S * (double)imu_hz - 1e-9);
    return n < 2.0 ? 2u : n > (double)PS_IMU_FROZEN_SAMPLES_MAX ? PS_IMU_FROZEN_SAMPLES_MAX
                                                                  : (uint32_t)n;
}

/* The six values, bit for bit, against the run so far. */
static bool is_frozen(ps_imu_rx_t *rx, const ps_imu_sample_t *s)
{
    float v[6];
    memcpy(v, s->gyro_body_rad_s, sizeof(s->gyro_body_rad_s));
    memcpy(v + 3, s->accel_body_m_s2, sizeof(s->accel_body_m_s2));
    if (rx->n_same > 0 && memcmp(v, rx->last_values, sizeof(v)) == 0) {
        if (rx->n_same < UINT32_MAX)
            rx->n_same++;
    } else {
        memcpy(rx->last_values, v, sizeof(v));
        rx->n_same = 1;
    }
    return rx->frozen_samples != 0 && rx->n_same >= rx->frozen_samples;
}

int ps_imu_rx_feed(ps_imu_rx_t *rx, const ps_can_frame_t *f, ps_imu_sample_t *out)
{
    const int rc = rx->protocol == PS_IMU_PROTO_XSENS ? ps_imu_xsens_rx_feed(&rx->u.xsens, f, out)
                                                      : ps_imu_msg_rx_feed(&rx->u.msg, f, out);
    if (rc != 1 || !is_frozen(rx, out))
        return rc;
    rx->n_frozen_values++;
    return -PS_ERR_STALE;
}

int ps_imu_encode(const ps_imu_cfg_t *cfg, const ps_imu_sample_t *s, uint32_t n, int64_t t_ns,
                  ps_can_frame_t out[PS_IMU_MAX_FRAMES])
{
    if (cfg->protocol == PS_IMU_PROTO_XSENS) {
        const uint32_t ticks = (uint32_t)((uint64_t)(t_ns > 0 ? t_ns : 0) / 100000u);
        return ps_imu_xsens_encode(cfg->base_id, s, (uint16_t)n, ticks, out);
    }
    ps_imu_msg_encode(cfg->base_id, s, out);
    return 2;
}

unsigned ps_imu_frames(const ps_imu_cfg_t *cfg, uint32_t ids[PS_IMU_MAX_FRAMES],
                       uint8_t lens[PS_IMU_MAX_FRAMES])
{
    if (cfg->protocol == PS_IMU_PROTO_XSENS) {
        static const uint32_t OFS[] = {PS_IMU_XSENS_OFS_SAMPLE_TIME, PS_IMU_XSENS_OFS_COUNTER,
                                       PS_IMU_XSENS_OFS_STATUS, PS_IMU_XSENS_OFS_RATE_OF_TURN,
                                       PS_IMU_XSENS_OFS_ACCELERATION};
        static const uint8_t LEN[] = {4, 2, 4, 6, 6};
        for (unsigned i = 0; i < PS_IMU_XSENS_N_FRAMES; i++) {
            ids[i] = cfg->base_id + OFS[i];
            lens[i] = LEN[i];
        }
        return PS_IMU_XSENS_N_FRAMES;
    }
    ids[0] = cfg->base_id;
    ids[1] = cfg->base_id + 1u;
    lens[0] = lens[1] = 8;
    return 2;
}
