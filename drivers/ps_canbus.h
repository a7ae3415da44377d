/*
 * ps_canbus: CAN wire timing (classical and FD) and bus-load planning.
 *
 * Classical frame length (ISO 11898-1, data frame, including the 3-bit
 * intermission): an 11-bit-id frame with n data bytes has 47 + 8n bits
 * without stuffing; of those, 34 + 8n (SOF..CRC) are subject to bit stuffing,
 * which adds at most floor((34 + 8n - 1) / 4) bits. With 8 bytes: 111..135
 * bits. A 29-bit-id frame has 67 + 8n bits, 54 + 8n stuffable.
 *
 * CAN FD frame (ISO 11898-1:2015): the arbitration phase (SOF, id, RRS, IDE,
 * FDF, res, BRS: 17 bits for an 11-bit id, 36 for 29-bit) and the end (CRC
 * delimiter, ACK, EOF, intermission: 13 bits) run at the nominal bitrate;
 * with BRS the data phase (ESI, DLC 4, 8n data bits, stuff count 4, CRC 17
 * for n <= 16 bytes else 21, plus one fixed stuff bit per 4 bits of stuff
 * count and CRC) runs at the data bitrate. Dynamic stuffing (at most one bit
 * per 4 after the first 5) applies from SOF to the end of the data field.
 * Time on the wire = nominal bits / bitrate + data bits / data bitrate.
 *
 * The planner takes a plain list of sources (each: a bus, a rate divisor and
 * the frames it puts on the wire when due) and gives each a phase so that
 * the worst tick's wire time is as short as possible; the worst tick's load
 * must stay under the board's budget. Loads are expressed in nominal bit
 * times (FD data-phase bits weighted by bitrate / data_bitrate), so a tick's
 * capacity is bitrate / servo_hz bits on every kind of bus.
 *
 * Threads: any (pure). Allocation: none.
 */
#ifndef PS_CANBUS_H
#define PS_CANBUS_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "../rt/ps_limits.h"

/** Longest hyperperiod (lcm of the rate divisors on one bus) the planner
 *  accepts; every rate_div must divide into it, e.g. 1, 2, 4, 8, 16, 32, 64. */
#define PS_CANBUS_MAX_HYPERPERIOD 64u
/** Sources the planner takes: every joint and the IMU. */
#define PS_CANBUS_MAX_SOURCES (PS_MAX_JOINTS + 1u)
/** Frame shapes one source may put on the wire each time it is due (an
 *  Xsens IMU sample is five). */
#define PS_CANBUS_MAX_SOURCE_FRAMES 5u

/** The CAN controller behind a bus (board file, `buses[i].controller`):
 *  what it can do and how much it buffers. */
typedef enum {
    PS_CANBUS_CTRL_ANY = 0,   /**< not stated: nothing checked against it */
    PS_CANBUS_CTRL_MCP2515,   /**< Microchip MCP2515 on SPI: classical, 2 receive buffers */
    PS_CANBUS_CTRL_MCP251XFD, /**< Microchip MCP2517FD/MCP2518FD on SPI: FD, RX FIFO in its RAM */
    PS_CANBUS_CTRL_MTTCAN,    /**< NVIDIA Tegra's M_CAN (driver mttcan): FD */
    PS_CANBUS_CTRL_M_CAN,     /**< Bosch M_CAN in a SoC (TI MCAN, driver m_can_platform): FD */
    PS_CANBUS_CTRL_GS_USB,    /**< USB adapter with gs_usb firmware (candleLight): classical */
    PS_CANBUS_CTRL_VIRTUAL,   /**< vcan / vxcan: no controller, no bit timing */
    PS_CANBUS_CTRL_COUNT
} ps_canbus_ctrl_t;

/** What is known of a controller. */
typedef struct {
    const char *name;          /**< as written in the board file */
    const char *driver;        /**< the kernel driver that binds it (sysfs
                                    device/driver), NULL for virtual or any */
    bool is_fd_capable;        /**< can run a CAN FD bus */
    uint32_t rx_buffer_frames; /**< received frames it holds until the host reads
                                    them; 0: a FIFO deep enough not to matter at
                                    one tick's traffic (or unknown, for ANY) */
} ps_canbus_ctrl_info_t;

/** One bus of a board. */
typedef struct {
    char ifname[PS_NAME_LEN];    /**< "can0"; for sim a label */
    uint32_t bitrate;            /**< nominal (arbitration) bit rate, bit/s */
    bool is_fd;                  /**< CAN FD controller and bus */
    uint32_t data_bitrate;       /**< FD data-phase bit rate, bit/s (is_fd only; >= bitrate) */
    ps_canbus_ctrl_t controller; /**< what drives it; ANY when not stated */
} ps_canbus_bus_cfg_t;

/** The shape of one frame on the wire. */
typedef struct {
    uint8_t len; /**< payload bytes */
    bool is_ext; /**< 29-bit identifier */
    bool is_fd;  /**< FD frame */
    bool is_brs; /**< FD with bit rate switch */
    bool is_rx;  /**< sent by a device, received by the host (a reply, an IMU frame) */
} ps_canbus_frame_shape_t;

/** Something that puts frames on a bus every rate_div ticks. */
typedef struct {
    uint32_t bus_idx;
    uint32_t rate_div;
    uint32_t n_frames; /**< 1..PS_CANBUS_MAX_SOURCE_FRAMES */
    ps_canbus_frame_shape_t frames[PS_CANBUS_MAX_SOURCE_FRAMES];
    const char *name; /**< for messages, e.g. "joint l_knee" */
} ps_canbus_source_t;

/** What the planner needs of a board and the loop. */
typedef struct {
    uint32_t n_buses;
    const ps_canbus_bus_cfg_t *buses;
    float bus_budget;  /**< max worst-case load per bus, (0, 1] */
    uint32_t servo_hz; /**< ticks per second */
} ps_canbus_cfg_t;

/** Classical frames; len above 8 counts as 8. @return bits of a frame with no
 *  stuff bits  @rt RT-SAFE */
unsigned ps_canbus_frame_bits_min(uint8_t len, bool is_ext);

/** @return bits of a frame with the most stuff bits possible  @rt RT-SAFE */
unsigned ps_canbus_frame_bits_max(uint8_t len, bool is_ext);

/** @pre bitrate > 0 (0 returns 0)  @return time the bits take on the wire, rounded up
 *  @units ns  @rt RT-SAFE */
int64_t ps_canbus_bits_to_ns(unsigned bits, uint32_t bitrate);

/** Worst-case (most stuff bits) bits of an FD frame, split by phase: bits at
 *  the nominal rate and bits in the data phase (at the data rate with BRS, at
 *  the nominal rate without: then all count as nominal). A length that is
 *  not an FD length is rounded up to the next one.
 *  @rt RT-SAFE */
void ps_canbus_fd_frame_bits_max(uint8_t len, bool is_ext, bool is_brs, unsigned *out_nominal,
                                 unsigned *out_data);

/** Worst-case time of one frame of this shape on this bus (classical or FD).
 *  @pre bus bitrate > 0  @units ns  @rt RT-SAFE */
int64_t ps_canbus_frame_ns_max(const ps_canbus_frame_shape_t *f, const ps_canbus_bus_cfg_t *bus);

/** The same in nominal bit times: time * bitrate, rounded up.  @rt RT-SAFE */
unsigned ps_canbus_frame_nominal_bits_max(const ps_canbus_frame_shape_t *f,
                                          const ps_canbus_bus_cfg_t *bus);

typedef struct {
    uint32_t n_buses;
    uint32_t tick_bits_max[PS_MAX_BUSES];      /**< worst-case bits in the busiest tick */
    uint32_t tick_capacity_bits[PS_MAX_BUSES]; /**< bitrate / servo_hz */
    double load_peak[PS_MAX_BUSES];            /**< tick_bits_max / tick_capacity_bits */
    double load_avg[PS_MAX_BUSES];             /**< worst-case bits per second / bitrate */
    uint32_t n_sources[PS_MAX_BUSES];
    uint32_t n_sources_total;
    uint32_t rx_frames_max[PS_MAX_BUSES]; /**< most frames the host receives in one tick */
    int64_t rx_frame_ns_min[PS_MAX_BUSES]; /**< the shortest of them on the wire (0: none) */
    uint8_t phase[PS_CANBUS_MAX_SOURCES]; /**< source k sends on ticks where
                                               (tick + phase) % rate_div == 0 */
} ps_canbus_plan_t;

/** Plan every bus for a list of sources and check it against the budget.
 *  Each source's cost when due is the sum of its frames' worst-case nominal
 *  bit times on its bus. Phases are chosen greedily, most bits first, each
 *  minimising the busiest tick of the hyperperiod (lcm of the bus's
 *  divisors). tick_capacity_bits = bitrate / servo_hz (integer division).
 *  @post *out written (also on -PS_ERR_BUS_BUDGET, so callers can report it;
 *        untouched on -PS_ERR_CONFIG); err "" on success
 *  @return 0 | -PS_ERR_BUS_BUDGET (err names the first bus over budget, its load
 *          and the budget) | -PS_ERR_CONFIG (a source names a bus the board
 *          lacks, has no frames or more than PS_CANBUS_MAX_SOURCE_FRAMES, an
 *          FD frame on a classical bus, rate_div 0 or > 64, hyperperiod > 64,
 *          servo_hz 0, n_buses 0 or > PS_MAX_BUSES, n_sources >
 *          PS_CANBUS_MAX_SOURCES, bus_budget outside (0, 1], bitrate <
 *          servo_hz, FD data_bitrate below bitrate; err names the source or bus)
 *  @rt INIT (pure, O(sources * 64 * 64)) */
int ps_canbus_plan(const ps_canbus_cfg_t *cfg, const ps_canbus_source_t *sources, size_t n_sources,
                   ps_canbus_plan_t *out, char *err, size_t err_len);

/** @return the facts of a controller; the ANY entry for a value out of range
 *  @rt RT-SAFE, pure */
const ps_canbus_ctrl_info_t *ps_canbus_ctrl_info(ps_canbus_ctrl_t c);

/** Whether a bus's controller may lose received frames under this plan: the
 *  busiest tick brings more frames (plan->rx_frames_max) than the controller
 *  holds, so the host must read one within the shortest frame's time on the
 *  wire (plan->rx_frame_ns_min) or lose the next. On success writes one line
 *  naming the bus, the controller and both figures, e.g.
 *  "can3 (mcp2515): up to 3 frames arrive in one tick, the controller holds
 *  2: the host must read each within 111 us or lose the next"
 *  @return 1 at risk (note written) | 0 not (a FIFO, or few enough frames)
 *  @rt INIT, pure */
int ps_canbus_rx_risk(const ps_canbus_bus_cfg_t *bus, const ps_canbus_plan_t *plan,
                      uint32_t bus_idx, char *note, size_t note_len);

/** @return true if a source with this divisor and phase sends on this tick  @rt RT-SAFE */
static inline bool ps_canbus_is_due(uint64_t tick, uint32_t rate_div, uint32_t phase)
{
    return ((tick + phase) % rate_div) == 0;
}

#endif /* PS_CANBUS_H */
