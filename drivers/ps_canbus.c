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

/* CAN FD (ISO 11898-1:2015). Arbitration: SOF 1, id 11, RRS 1, IDE 1, FDF 1,
 * res 1, BRS 1 = 17 (29-bit: SOF 1, id 11, SRR 1, IDE 1, id 18, RRS 1, FDF 1,
 * res 1, BRS 1 = 36). Data phase: ESI 1, DLC 4, data 8n; dynamic stuffing
 * from SOF to the end of the data field; then the stuff count (4) and the CRC
 * (17 or 21), which carry fixed stuff bits, one before every 4 bits. End: CRC
 * delimiter 1, ACK 2, EOF 7, intermission 3 at the nominal rate. */
#define FD_ARB_SFF 17u
#define FD_ARB_EFF 36u
#define FD_END     13u

static unsigned fd_round_len(uint8_t len)
{
    static const uint8_t LENS[] = {8, 12, 16, 20, 24, 32, 48, 64};
    if (len <= 8u)
        return len;
    for (unsigned i = 0; i < sizeof(LENS); i++)
        if (len <= LENS[i])
            return LENS[i];
    return 64u;
}

void ps_canbus_fd_frame_bits_max(uint8_t len, bool is_ext, bool is_brs, unsigned *out_nominal,
                                 unsigned *out_data)
{
    const unsigned n = fd_round_len(len);
    const unsigned arb = is_ext ? FD_ARB_EFF : FD_ARB_SFF;
    const unsigned data_fields = 1u + 4u + 8u * n; /* ESI, DLC, data */
    const unsigned dyn_stuff = (arb + data_fields - 1u) / 4u;
    const unsigned crc = n <= 16u ? 17u : 21u;
    const unsigned fixed = 4u + crc + (4u + crc + 3u) / 4u; /* stuff count, CRC, fixed stuff */
    /* The dynamic stuff bits fall across both phases; count them in the data
     * phase in proportion is not worth it: put the arbitration part's share
     * (at most (arb - 1) / 4 + 1) in the nominal phase, the rest in data. */
    const unsigned arb_stuff = (arb - 1u) / 4u + 1u;
    const unsigned nominal = arb + arb_stuff + FD_END;
    const unsigned data =
        data_fields + (dyn_stuff > arb_stuff ? dyn_stuff - arb_stuff : 0u) + fixed;
    if (is_brs) {
        *out_nominal = nominal;
        *out_data = data;
    } else {
        *out_nominal = nominal + data;
        *out_data = 0u;
    }
}

int64_t ps_canbus_frame_ns_max(const ps_canbus_frame_shape_t *f, const ps_canbus_bus_cfg_t *bus)
{
    if (!f->is_fd)
        return ps_canbus_bits_to_ns(ps_canbus_frame_bits_max(f->len, f->is_ext), bus->bitrate);
    unsigned nominal = 0u, data = 0u;
    ps_canbus_fd_frame_bits_max(f->len, f->is_ext, f->is_brs, &nominal, &data);
    const uint32_t data_rate = bus->data_bitrate > 0u ? bus->data_bitrate : bus->bitrate;
    return ps_canbus_bits_to_ns(nominal, bus->bitrate) + ps_canbus_bits_to_ns(data, data_rate);
}

unsigned ps_canbus_frame_nominal_bits_max(const ps_canbus_frame_shape_t *f,
                                          const ps_canbus_bus_cfg_t *bus)
{
    if (!f->is_fd)
        return ps_canbus_frame_bits_max(f->len, f->is_ext);
    unsigned nominal = 0u, data = 0u;
    ps_canbus_fd_frame_bits_max(f->len, f->is_ext, f->is_brs, &nominal, &data);
    const uint64_t data_rate = bus->data_bitrate > 0u ? bus->data_bitrate : bus->bitrate;
    /* data bits at the data rate, expressed in nominal bit times, rounded up */
    return nominal + (unsigned)(((uint64_t)data * bus->bitrate + data_rate - 1u) / data_rate);
}

/* ---- planner ---------------------------------------------------------- */

typedef struct {
    uint32_t bits; /* worst-case bits each time the source is due */
    uint32_t div;  /* due every div servo ticks */
    uint32_t idx;  /* index into the caller's sources */
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
    return a->idx < b->idx;
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

static int check_bus(const ps_canbus_cfg_t *c, uint32_t i, char *err, size_t err_len)
{
    const ps_canbus_bus_cfg_t *b = &c->buses[i];
    if (b->bitrate / c->servo_hz == 0u) {
        ps_err_format(err, err_len, "bus %u (%s): bitrate %u gives no bits per tick at %u Hz", i,
                      b->ifname, b->bitrate, c->servo_hz);
        return -PS_ERR_CONFIG;
    }
    if (b->is_fd && b->data_bitrate < b->bitrate) {
        ps_err_format(err, err_len, "bus %u (%s): FD data_bitrate %u below bitrate %u", i,
                      b->ifname, b->data_bitrate, b->bitrate);
        return -PS_ERR_CONFIG;
    }
    return 0;
}

static int check_source(const ps_canbus_cfg_t *c, const ps_canbus_source_t *s, size_t k, char *err,
                        size_t err_len)
{
    const char *name = s->name != NULL ? s->name : "?";
    if (s->bus_idx >= c->n_buses) {
        ps_err_format(err, err_len, "source %zu (%s): bus %u but the board has %u bus(es) (0..%u)",
                      k, name, s->bus_idx, c->n_buses, c->n_buses - 1u);
        return -PS_ERR_CONFIG;
    }
    if (s->rate_div == 0u || s->rate_div > PS_CANBUS_MAX_HYPERPERIOD) {
        ps_err_format(err, err_len, "source %zu (%s): rate_div %u outside [1, %u]", k, name,
                      s->rate_div, PS_CANBUS_MAX_HYPERPERIOD);
        return -PS_ERR_CONFIG;
    }
    if (s->n_frames == 0u || s->n_frames > PS_CANBUS_MAX_SOURCE_FRAMES) {
        ps_err_format(err, err_len, "source %zu (%s): %u frames outside [1, %u]", k, name,
                      s->n_frames, PS_CANBUS_MAX_SOURCE_FRAMES);
        return -PS_ERR_CONFIG;
    }
    const ps_canbus_bus_cfg_t *b = &c->buses[s->bus_idx];
    for (uint32_t f = 0; f < s->n_frames; f++) {
        if (s->frames[f].is_fd && !b->is_fd) {
            ps_err_format(err, err_len,
                          "source %zu (%s): sends CAN FD frames but bus %u (%s) is classical CAN",
                          k, name, s->bus_idx, b->ifname);
            return -PS_ERR_CONFIG;
        }
    }
    return 0;
}

static int check_inputs(const ps_canbus_cfg_t *c, const ps_canbus_source_t *src, size_t n,
                        char *err, size_t err_len)
{
    if (c->n_buses == 0u || c->n_buses > PS_MAX_BUSES || c->buses == NULL) {
        ps_err_format(err, err_len, "n_buses %u outside [1, %u]", c->n_buses, PS_MAX_BUSES);
        return -PS_ERR_CONFIG;
    }
    if (n > PS_CANBUS_MAX_SOURCES || (n > 0u && src == NULL)) {
        ps_err_format(err, err_len, "%zu sources outside [0, %u]", n, PS_CANBUS_MAX_SOURCES);
        return -PS_ERR_CONFIG;
    }
    if (c->servo_hz == 0u) {
        ps_err_format(err, err_len, "servo_hz is 0");
        return -PS_ERR_CONFIG;
    }
    if (!isfinite(c->bus_budget) || !(c->bus_budget > 0.0f) || c->bus_budget > 1.0f) {
        ps_err_format(err, err_len, "bus_budget %g outside (0, 1]", (double)c->bus_budget);
        return -PS_ERR_CONFIG;
    }
    for (uint32_t i = 0; i < c->n_buses; i++) {
        const int rc = check_bus(c, i, err, err_len);
        if (rc < 0)
            return rc;
    }
    for (size_t k = 0; k < n; k++) {
        const int rc = check_source(c, &src[k], k, err, err_len);
        if (rc < 0)
            return rc;
    }
    return 0;
}

/* Facts per controller. MCP2515: two receive buffers (datasheet DS20001801,
 * "two receive buffers with prioritized message storage"). MCP251xFD: RX
 * FIFOs in its 2 KiB RAM. Tegra mttcan and TI MCAN: Bosch M_CAN cores whose
 * message RAM holds RX FIFOs of tens of elements (TI's J721E device tree
 * gives each MCAN 64-element RX FIFOs). gs_usb: the adapter's firmware
 * queues frames for the USB transfer. */
static const ps_canbus_ctrl_info_t CTRL_INFO[PS_CANBUS_CTRL_COUNT] = {
    [PS_CANBUS_CTRL_ANY] = {"any", NULL, true, 0u},
    [PS_CANBUS_CTRL_MCP2515] = {"mcp2515", "mcp251x", false, 2u},
    [PS_CANBUS_CTRL_MCP251XFD] = {"mcp251xfd", "mcp251xfd", true, 0u},
    [PS_CANBUS_CTRL_MTTCAN] = {"mttcan", "mttcan", true, 0u},
    [PS_CANBUS_CTRL_M_CAN] = {"m_can", "m_can_platform", true, 0u},
    [PS_CANBUS_CTRL_GS_USB] = {"gs_usb", "gs_usb", false, 0u},
    [PS_CANBUS_CTRL_VIRTUAL] = {"virtual", NULL, true, 0u},
};

const ps_canbus_ctrl_info_t *ps_canbus_ctrl_info(ps_canbus_ctrl_t c)
{
    return (unsigned)c < (unsigned)PS_CANBUS_CTRL_COUNT ? &CTRL_INFO[c]
                                                        : &CTRL_INFO[PS_CANBUS_CTRL_ANY];
}

int ps_canbus_rx_risk(const ps_canbus_bus_cfg_t *bus, const ps_canbus_plan_t *plan,
                      uint32_t bus_idx, char *note, size_t note_len)
{
    if (bus == NULL || plan == NULL || bus_idx >= plan->n_buses || bus_idx >= PS_MAX_BUSES)
        return 0;
    const ps_canbus_ctrl_info_t *ci = ps_canbus_ctrl_info(bus->controller);
    const uint32_t n = plan->rx_frames_max[bus_idx];
    if (ci->rx_buffer_frames == 0u || n <= ci->rx_buffer_frames)
        return 0;
    ps_err_format(note, note_len,
                  "%s (%s): up to %u frames arrive in one tick, the controller holds %u: the "
                  "host must read each within %.0f us or lose the next",
                  bus->ifname, ci->name, n, ci->rx_buffer_frames,
                  (double)plan->rx_frame_ns_min[bus_idx] * 1e-3);
    return 1;
}

/* The received frames of a source when it is due, and the shortest of them
 * on the wire (no stuff bits), in ns; 0 frames: INT64_MAX. */
static uint32_t source_rx(const ps_canbus_source_t *s, const ps_canbus_bus_cfg_t *bus,
                          int64_t *out_ns_min)
{
    uint32_t n = 0u;
    int64_t ns_min = INT64_MAX;
    for (uint32_t f = 0; f < s->n_frames; f++) {
        const ps_canbus_frame_shape_t *fs = &s->frames[f];
        if (!fs->is_rx)
            continue;
        n++;
        /* The shortest such frame: no stuff bits; an FD frame is timed at its
         * worst case, an upper bound that only an FD bus uses. */
        const int64_t ns =
            fs->is_fd ? ps_canbus_frame_ns_max(fs, bus)
                      : ps_canbus_bits_to_ns(ps_canbus_frame_bits_min(fs->len, fs->is_ext),
                                             bus->bitrate);
        ns_min = ns < ns_min ? ns : ns_min;
    }
    *out_ns_min = ns_min;
    return n;
}

static uint32_t source_bits(const ps_canbus_source_t *s, const ps_canbus_bus_cfg_t *bus)
{
    uint32_t bits = 0u;
    for (uint32_t f = 0; f < s->n_frames; f++)
        bits += ps_canbus_frame_nominal_bits_max(&s->frames[f], bus);
    return bits;
}

int ps_canbus_plan(const ps_canbus_cfg_t *c, const ps_canbus_source_t *sources, size_t n_sources,
                   ps_canbus_plan_t *out, char *err, size_t err_len)
{
    ps_canbus_plan_t plan;
    memset(&plan, 0, sizeof plan);
    if (err != NULL && err_len > 0u)
        err[0] = '\0';
    if (c == NULL || out == NULL) {
        ps_err_format(err, err_len, "no bus configuration");
        return -PS_ERR_CONFIG;
    }
    const int rc = check_inputs(c, sources, n_sources, err, err_len);
    if (rc < 0)
        return rc;

    const uint32_t hz = c->servo_hz;
    plan.n_buses = c->n_buses;
    plan.n_sources_total = (uint32_t)n_sources;
    for (uint32_t bus = 0; bus < c->n_buses; bus++) {
        const ps_canbus_bus_cfg_t *bc = &c->buses[bus];
        source_t src[PS_CANBUS_MAX_SOURCES];
        uint32_t n = 0u;
        for (size_t k = 0; k < n_sources; k++) {
            if (sources[k].bus_idx == bus)
                src[n++] =
                    (source_t){source_bits(&sources[k], bc), sources[k].rate_div, (uint32_t)k};
        }

        uint32_t hyper = 1u;
        for (uint32_t k = 0; k < n; k++) {
            hyper = hyper / gcd_u32(hyper, src[k].div) * src[k].div;
            if (hyper > PS_CANBUS_MAX_HYPERPERIOD) {
                ps_err_format(err, err_len,
                              "bus %u (%s): the rate_div values on it repeat only every %u+ ticks, "
                              "more than %u; use divisors of %u",
                              bus, bc->ifname, hyper, PS_CANBUS_MAX_HYPERPERIOD,
                              PS_CANBUS_MAX_HYPERPERIOD);
                return -PS_ERR_CONFIG;
            }
        }

        sort_sources(src, n);
        uint32_t tick_bits[PS_CANBUS_MAX_HYPERPERIOD] = {0};
        double bits_per_s = 0.0;
        for (uint32_t k = 0; k < n; k++) {
            plan.phase[src[k].idx] = (uint8_t)place_source(tick_bits, hyper, &src[k]);
            bits_per_s += (double)src[k].bits * (double)hz / (double)src[k].div;
        }
        uint32_t peak = 0u;
        for (uint32_t t = 0; t < hyper; t++)
            peak = tick_bits[t] > peak ? tick_bits[t] : peak;

        /* Received frames per tick over the hyperperiod, with the phases chosen. */
        uint32_t rx_max = 0u;
        int64_t rx_ns_min = INT64_MAX;
        for (uint32_t t = 0; t < hyper; t++) {
            uint32_t rx = 0u;
            for (uint32_t k = 0; k < n; k++) {
                const ps_canbus_source_t *s = &sources[src[k].idx];
                int64_t ns = INT64_MAX;
                const uint32_t r = source_rx(s, bc, &ns);
                if (r > 0u && ps_canbus_is_due(t, s->rate_div, plan.phase[src[k].idx])) {
                    rx += r;
                    rx_ns_min = ns < rx_ns_min ? ns : rx_ns_min;
                }
            }
            rx_max = rx > rx_max ? rx : rx_max;
        }
        plan.rx_frames_max[bus] = rx_max;
        plan.rx_frame_ns_min[bus] = rx_max > 0u ? rx_ns_min : 0;

        plan.n_sources[bus] = n;
        plan.tick_bits_max[bus] = peak;
        plan.tick_capacity_bits[bus] = bc->bitrate / hz;
        plan.load_peak[bus] = (double)peak / (double)plan.tick_capacity_bits[bus];
        plan.load_avg[bus] = bits_per_s / (double)bc->bitrate;
    }
    *out = plan;

    for (uint32_t bus = 0; bus < plan.n_buses; bus++) {
        if (plan.load_peak[bus] > (double)c->bus_budget) {
            ps_err_format(
                err, err_len,
                "bus %u (%s): worst-case tick load %.1f%% (%u of %u bits at %u Hz) exceeds "
                "budget %.3g%%; raise rate_div of its joints or move joints to another bus",
                bus, c->buses[bus].ifname, plan.load_peak[bus] * 100.0, plan.tick_bits_max[bus],
                plan.tick_capacity_bits[bus], hz, (double)c->bus_budget * 100.0);
            return -PS_ERR_BUS_BUDGET;
        }
    }
    return 0;
}
