#include "ps_canbus.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "../rt/ps_err.h"

/* Classical CAN field lengths (ISO 11898-1). SOF 1, id 11 (+ SRR 1, IDE 1,
 * id 18 for 29-bit), RTR 1, IDE/r1 1, r0 1, DLC 4, data 8n, CRC 15: the
 * stuffable part, 34 + 8n (54 + 8n). Then CRC delimiter 1, ACK 2, EOF 7,
 * intermission 3: 13 more bits that are never stuffed. */
#define STUFFABLE_SFF 34u
#define STUFFABLE_EFF 54u
#define TRAILER_BITS  13u

static unsigned clamp_len(uint8_t len)
{
    /* A DLC above 8 still carries 8 bytes in classical CAN. */
    return len > 8u ? 8u : len;
}

static unsigned stuffable_bits(uint8_t len, bool is_ext)
{
    return (is_ext ? STUFFABLE_EFF : STUFFABLE_SFF) + 8u * clamp_len(len);
}

unsigned ps_canbus_frame_bits_min(uint8_t len, bool is_ext)
{
    return stuffable_bits(len, is_ext) + TRAILER_BITS;
}

unsigned ps_canbus_frame_bits_max(uint8_t len, bool is_ext)
{
    const unsigned s = stuffable_bits(len, is_ext);
    /* Worst case: the first stuff bit after 5 equal bits, then one after
     * every 4 more (the stuff bit starts the next run). */
    return s + TRAILER_BITS + (s - 1u) / 4u;
}

int64_t ps_canbus_bits_to_ns(unsigned bits, uint32_t bitrate)
{
    if (bitrate == 0u)
        return 0; /* violated @pre; never divide by zero */
    const uint64_t num = (uint64_t)bits * 1000000000u + (uint64_t)bitrate - 1u;
    return (int64_t)(num / bitrate);
}

/* ---- planner ---------------------------------------------------------- */

typedef struct {
    uint32_t bits;     /* worst-case bits each time the source is due */
    uint32_t div;      /* due every div servo ticks */
    int32_t joint_idx; /* -1: the IMU */
} source_t;

static uint32_t gcd_u32(uint32_t a, uint32_t b)
{
    while (b != 0u) {
        const uint32_t t = a % b;
        a = b;
        b = t;
    }
    return a;
}

/* Order: most bits first (hardest to place), then the most frequent (fewest
 * phase choices), then configuration order so the plan is deterministic. */
static bool goes_before(const source_t *a, const source_t *b)
{
    if (a->bits != b->bits)
        return a->bits > b->bits;
    if (a->div != b->div)
        return a->div < b->div;
    return a->joint_idx < b->joint_idx; /* IMU (-1) before joints on a full tie */
}

static void sort_sources(source_t *s, uint32_t n)
{
    for (uint32_t i = 1; i < n; i++) {
        const source_t key = s[i];
        uint32_t j = i;
        while (j > 0u && goes_before(&key, &s[j - 1u])) {
            s[j] = s[j - 1u];
            j--;
        }
        s[j] = key;
    }
}

/* Greedy phase choice for one source over the hyperperiod. Primary key: the
 * bus's resulting busiest tick; secondary: the busiest of the ticks this
 * source lands on (spreads load even when the primary key ties); then the
 * lowest phase. */
static uint32_t place_source(uint32_t *tick_bits, uint32_t hyper, const source_t *s)
{
    uint32_t best_phase = 0u;
    uint32_t best_peak = UINT32_MAX, best_own = UINT32_MAX;
    for (uint32_t ph = 0; ph < s->div; ph++) {
        uint32_t peak = 0u, own = 0u;
        for (uint32_t t = 0; t < hyper; t++) {
            uint32_t v = tick_bits[t];
            if (ps_canbus_is_due(t, s->div, ph)) {
                own = v > own ? v : own;
                v += s->bits;
            }
            peak = v > peak ? v : peak;
        }
        if (peak < best_peak || (peak == best_peak && own < best_own)) {
            best_peak = peak;
            best_own = own;
            best_phase = ph;
        }
    }
    for (uint32_t t = 0; t < hyper; t++) {
        if (ps_canbus_is_due(t, s->div, best_phase))
            tick_bits[t] += s->bits;
    }
    return best_phase;
}

static int check_inputs(const ps_board_cfg_t *b, const ps_robot_cfg_t *r, char *err, size_t err_len)
{
    if (b->n_buses == 0u || b->n_buses > PS_MAX_BUSES) {
        ps_err_format(err, err_len, "board %s: n_buses %u outside [1, %u]", b->name, b->n_buses,
                      PS_MAX_BUSES);
        return -PS_ERR_CONFIG;
    }
    if (r->n_joints > PS_MAX_JOINTS) {
        ps_err_format(err, err_len, "robot %s: n_joints %u outside [0, %u]", r->name, r->n_joints,
                      PS_MAX_JOINTS);
        return -PS_ERR_CONFIG;
    }
    if (r->control.servo_hz == 0u) {
        ps_err_format(err, err_len, "robot %s: control.servo_hz is 0", r->name);
        return -PS_ERR_CONFIG;
    }
    if (!isfinite(b->bus_budget) || !(b->bus_budget > 0.0f) || b->bus_budget > 1.0f) {
        ps_err_format(err, err_len, "board %s: bus_budget %g outside (0, 1]", b->name,
                      (double)b->bus_budget);
        return -PS_ERR_CONFIG;
    }
    for (uint32_t i = 0; i < b->n_buses; i++) {
        if (b->buses[i].bitrate / r->control.servo_hz == 0u) {
            ps_err_format(err, err_len, "bus %u (%s): bitrate %u gives no bits per tick at %u Hz",
                          i, b->buses[i].ifname, b->buses[i].bitrate, r->control.servo_hz);
            return -PS_ERR_CONFIG;
        }
    }
    for (uint32_t j = 0; j < r->n_joints; j++) {
        const ps_joint_cfg_t *jc = &r->joints[j];
        if (jc->bus_idx >= b->n_buses) {
            ps_err_format(err, err_len,
                          "joint %u (%s): bus_idx %u but board %s has %u bus(es) (0..%u)", j,
                          jc->name, jc->bus_idx, b->name, b->n_buses, b->n_buses - 1u);
            return -PS_ERR_CONFIG;
        }
        if (jc->rate_div == 0u || jc->rate_div > PS_CANBUS_MAX_HYPERPERIOD) {
            ps_err_format(err, err_len, "joint %u (%s): rate_div %u outside [1, %u]", j, jc->name,
                          jc->rate_div, PS_CANBUS_MAX_HYPERPERIOD);
            return -PS_ERR_CONFIG;
        }
    }
    if (r->imu.bus_idx >= b->n_buses) {
        ps_err_format(err, err_len, "imu: bus_idx %u but board %s has %u bus(es) (0..%u)",
                      r->imu.bus_idx, b->name, b->n_buses, b->n_buses - 1u);
        return -PS_ERR_CONFIG;
    }
    if (r->imu.rate_div == 0u || r->imu.rate_div > PS_CANBUS_MAX_HYPERPERIOD) {
        ps_err_format(err, err_len, "imu: rate_div %u outside [1, %u]", r->imu.rate_div,
                      PS_CANBUS_MAX_HYPERPERIOD);
        return -PS_ERR_CONFIG;
    }
    return 0;
}

int ps_canbus_plan(const ps_board_cfg_t *b, const ps_robot_cfg_t *r, ps_canbus_plan_t *out,
                   char *err, size_t err_len)
{
    ps_canbus_plan_t plan;
    memset(&plan, 0, sizeof plan);
    if (err != NULL && err_len > 0u)
        err[0] = '\0';
    const int rc = check_inputs(b, r, err, err_len);
    if (rc < 0)
        return rc;

    const uint32_t hz = r->control.servo_hz;
    /* Command and reply, both 8-byte 11-bit frames, per joint per due tick. */
    const uint32_t joint_bits = 2u * ps_canbus_frame_bits_max(PS_MIT_FRAME_LEN, false);
    /* Gyro and accel frames per IMU sample. */
    const uint32_t imu_bits = 2u * ps_canbus_frame_bits_max(8u, false);

    plan.n_buses = b->n_buses;
    for (uint32_t bus = 0; bus < b->n_buses; bus++) {
        source_t src[PS_MAX_JOINTS + 1u];
        uint32_t n = 0u;
        for (uint32_t j = 0; j < r->n_joints; j++) {
            if (r->joints[j].bus_idx == bus)
                src[n++] = (source_t){joint_bits, r->joints[j].rate_div, (int32_t)j};
        }
        if (r->imu.bus_idx == bus)
            src[n++] = (source_t){imu_bits, r->imu.rate_div, -1};

        uint32_t hyper = 1u;
        for (uint32_t k = 0; k < n; k++) {
            hyper = hyper / gcd_u32(hyper, src[k].div) * src[k].div;
            if (hyper > PS_CANBUS_MAX_HYPERPERIOD) {
                ps_err_format(err, err_len,
                              "bus %u (%s): the rate_div values on it repeat only every %u+ ticks, "
                              "more than %u; use divisors of %u",
                              bus, b->buses[bus].ifname, hyper, PS_CANBUS_MAX_HYPERPERIOD,
                              PS_CANBUS_MAX_HYPERPERIOD);
                return -PS_ERR_CONFIG;
            }
        }

        sort_sources(src, n);
        uint32_t tick_bits[PS_CANBUS_MAX_HYPERPERIOD] = {0};
        double bits_per_s = 0.0;
        for (uint32_t k = 0; k < n; k++) {
            const uint32_t ph = place_source(tick_bits, hyper, &src[k]);
            if (src[k].joint_idx < 0)
                plan.imu_phase = (uint8_t)ph;
            else
                plan.joint_phase[src[k].joint_idx] = (uint8_t)ph;
            bits_per_s += (double)src[k].bits * (double)hz / (double)src[k].div;
        }
        uint32_t peak = 0u;
        for (uint32_t t = 0; t < hyper; t++)
            peak = tick_bits[t] > peak ? tick_bits[t] : peak;

        const uint32_t bitrate = b->buses[bus].bitrate;
        plan.n_sources[bus] = n;
        plan.tick_bits_max[bus] = peak;
        plan.tick_capacity_bits[bus] = bitrate / hz;
        plan.load_peak[bus] = (double)peak / (double)plan.tick_capacity_bits[bus];
        plan.load_avg[bus] = bits_per_s / (double)bitrate;
    }
    *out = plan;

    for (uint32_t bus = 0; bus < plan.n_buses; bus++) {
        if (plan.load_peak[bus] > (double)b->bus_budget) {
            ps_err_format(
                err, err_len,
                "bus %u (%s): worst-case tick load %.1f%% (%u of %u bits at %u Hz) exceeds "
                "budget %.3g%%; raise rate_div of its joints or move joints to another bus",
                bus, b->buses[bus].ifname, plan.load_peak[bus] * 100.0, plan.tick_bits_max[bus],
                plan.tick_capacity_bits[bus], hz, (double)b->bus_budget * 100.0);
            return -PS_ERR_BUS_BUDGET;
        }
    }
    return 0;
}
