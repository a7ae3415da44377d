/*
 * ps_config_board: the board file (boards/<name>.yaml) and the checks of a
 * robot against a board. Shared machinery: ps_config_common.h.
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ps_config.h"
#include "ps_config_common.h"
#include "ps_err.h"

#define DEFAULT_BUS_BUDGET 0.8f
#define MAX_GPIO_LINE      1023u

/* One bus as written; fd and data_bitrate are optional (NULL when absent). */
typedef struct {
    char ifname[PS_NAME_LEN];
    uint32_t bitrate;
    bool *is_fd;
    uint32_t *data_bitrate;
} bus_raw_t;

typedef struct {
    char name[PS_NAME_LEN];
    ps_board_kind_t kind;
    float *bus_budget; /* optional: NULL when absent */
    bus_raw_t *buses;
    uint32_t n_buses;
    ps_gpio_cfg_t gpio;
    ps_rt_cfg_t rt;
} board_raw_t;

static const cyaml_strval_t BOARD_KINDS[] = {
    {"sim", PS_BOARD_SIM},
    {"linux", PS_BOARD_LINUX},
};

static const cyaml_schema_field_t BUS_FIELDS[] = {
    CYAML_FIELD_STRING("ifname", CYAML_FLAG_DEFAULT, bus_raw_t, ifname, 1),
    CYAML_FIELD_UINT("bitrate", CYAML_FLAG_DEFAULT, bus_raw_t, bitrate),
    CYAML_FIELD_BOOL_PTR("fd", CYAML_FLAG_OPTIONAL | CYAML_FLAG_STRICT, bus_raw_t, is_fd),
    CYAML_FIELD_UINT_PTR("data_bitrate", CYAML_FLAG_OPTIONAL, bus_raw_t, data_bitrate),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t BUS_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_DEFAULT, bus_raw_t, BUS_FIELDS),
};
static const cyaml_schema_field_t GPIO_FIELDS[] = {
    CYAML_FIELD_STRING("chip", CYAML_FLAG_DEFAULT, ps_gpio_cfg_t, chip, 1),
    CYAML_FIELD_UINT("estop_line", CYAML_FLAG_DEFAULT, ps_gpio_cfg_t, estop_line),
    CYAML_FIELD_BOOL("estop_active_low", CYAML_FLAG_STRICT, ps_gpio_cfg_t, is_estop_active_low),
    CYAML_FIELD_UINT("enable_line", CYAML_FLAG_DEFAULT, ps_gpio_cfg_t, enable_line),
    CYAML_FIELD_UINT("led_line", CYAML_FLAG_DEFAULT, ps_gpio_cfg_t, led_line),
    CYAML_FIELD_END,
};
static const cyaml_schema_field_t RT_FIELDS[] = {
    CYAML_FIELD_UINT("priority", CYAML_FLAG_DEFAULT, ps_rt_cfg_t, priority),
    CYAML_FIELD_INT("loop_cpu", CYAML_FLAG_DEFAULT, ps_rt_cfg_t, loop_cpu),
    CYAML_FIELD_INT("plant_cpu", CYAML_FLAG_DEFAULT, ps_rt_cfg_t, plant_cpu),
    CYAML_FIELD_INT("worker_cpu", CYAML_FLAG_DEFAULT, ps_rt_cfg_t, worker_cpu),
    CYAML_FIELD_END,
};
static const cyaml_schema_field_t BOARD_FIELDS[] = {
    CYAML_FIELD_STRING("name", CYAML_FLAG_DEFAULT, board_raw_t, name, 1),
    CYAML_FIELD_ENUM("kind", CYAML_FLAG_STRICT, board_raw_t, kind, BOARD_KINDS,
                     CYAML_ARRAY_LEN(BOARD_KINDS)),
    CYAML_FIELD_FLOAT_PTR("bus_budget", CYAML_FLAG_OPTIONAL, board_raw_t, bus_budget),
    CYAML_FIELD_SEQUENCE_COUNT("buses", CYAML_FLAG_POINTER, board_raw_t, buses, n_buses,
                               &BUS_SCHEMA, 1, PS_MAX_BUSES),
    CYAML_FIELD_MAPPING("gpio", CYAML_FLAG_DEFAULT, board_raw_t, gpio, GPIO_FIELDS),
    CYAML_FIELD_MAPPING("rt", CYAML_FLAG_DEFAULT, board_raw_t, rt, RT_FIELDS),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t BOARD_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_POINTER, board_raw_t, BOARD_FIELDS),
};

static const ps_cfg_array_t BOARD_ARRAYS[] = {
    PS_CFG_ARRAY("buses", ps_board_cfg_t, buses, ps_canbus_bus_cfg_t, n_buses),
};
enum { BA_BUSES = 1 };
static const ps_cfg_rule_t BOARD_RANGES[] = {
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "bus_budget", ps_board_cfg_t, bus_budget, 0.0, 1.0),
    PS_CFG_RULE_U32(BA_BUSES, 0, "bitrate", ps_canbus_bus_cfg_t, bitrate, 10000.0, 1000000.0),
    PS_CFG_RULE_U32(BA_BUSES, 0, "data_bitrate", ps_canbus_bus_cfg_t, data_bitrate, 10000.0,
                    8000000.0),
    PS_CFG_RULE_U32(0, 0, "gpio.estop_line", ps_board_cfg_t, gpio.estop_line, 0.0, MAX_GPIO_LINE),
    PS_CFG_RULE_U32(0, 0, "gpio.enable_line", ps_board_cfg_t, gpio.enable_line, 0.0, MAX_GPIO_LINE),
    PS_CFG_RULE_U32(0, 0, "gpio.led_line", ps_board_cfg_t, gpio.led_line, 0.0, MAX_GPIO_LINE),
    PS_CFG_RULE_U32(0, 0, "rt.priority", ps_board_cfg_t, rt.priority, 0.0, 98.0),
    PS_CFG_RULE_I32(0, 0, "rt.loop_cpu", ps_board_cfg_t, rt.loop_cpu, -1.0, 1023.0),
    PS_CFG_RULE_I32(0, 0, "rt.plant_cpu", ps_board_cfg_t, rt.plant_cpu, -1.0, 1023.0),
    PS_CFG_RULE_I32(0, 0, "rt.worker_cpu", ps_board_cfg_t, rt.worker_cpu, -1.0, 1023.0),
};

static int check_board(ps_cfg_ctx_t *c, const ps_board_cfg_t *b)
{
    int rc = ps_cfg_check_ranges(c, b);
    if (rc != 0)
        return rc;
    char field[PS_CFG_FIELD_PATH_LEN];
    for (uint32_t i = 0; i < b->n_buses; i++) {
        const ps_canbus_bus_cfg_t *bus = &b->buses[i];
        /* ISO 11898-1 FD controllers: data phase 1..8 Mbit/s in practice,
         * never slower than the arbitration phase. */
        if (!bus->is_fd && bus->data_bitrate != bus->bitrate) {
            (void)snprintf(field, sizeof(field), "buses[%u].data_bitrate", i);
            return ps_cfg_fail_field(c, field, "a data bit rate needs a CAN FD bus (fd: true)");
        }
        if (bus->is_fd && (bus->data_bitrate < bus->bitrate || bus->data_bitrate > 8000000u)) {
            (void)snprintf(field, sizeof(field), "buses[%u].data_bitrate", i);
            return ps_cfg_fail_field(c, field, "value %u outside [bitrate %u, 8000000]",
                                     bus->data_bitrate, bus->bitrate);
        }
        for (uint32_t k = 0; k < i; k++) {
            if (strcmp(b->buses[i].ifname, b->buses[k].ifname) == 0) {
                (void)snprintf(field, sizeof(field), "buses[%u].ifname", i);
                return ps_cfg_fail_field(c, field, "duplicate interface \"%s\" (also buses[%u])",
                                         b->buses[i].ifname, k);
            }
        }
    }
    const struct {
        const char *key;
        uint32_t line;
    } lines[] = {
        {"gpio.estop_line", b->gpio.estop_line},
        {"gpio.enable_line", b->gpio.enable_line},
        {"gpio.led_line", b->gpio.led_line},
    };
    for (size_t i = 1; i < sizeof(lines) / sizeof(lines[0]); i++) {
        for (size_t k = 0; k < i; k++) {
            if (lines[i].line == lines[k].line)
                return ps_cfg_fail_field(c, lines[i].key, "line %u already used by %s",
                                         lines[i].line, lines[k].key);
        }
    }
    return 0;
}

int ps_config_load_board(const char *path, ps_board_cfg_t *out, char *err, size_t err_len)
{
    if (path == NULL || out == NULL)
        return -EINVAL;
    ps_cfg_ctx_t c;
    int rc = ps_cfg_ctx_open(&c, path, err, err_len, BOARD_ARRAYS, BOARD_RANGES,
                             PS_CFG_COUNT(BOARD_RANGES));
    board_raw_t *raw = NULL;
    if (rc == 0)
        rc = ps_cfg_load_file(&c, &BOARD_SCHEMA, (void **)&raw);

    ps_board_cfg_t b;
    memset(&b, 0, sizeof(b));
    int dbr_without_fd = -1; /* a bus with data_bitrate written but no fd: true */
    if (rc == 0) {
        memcpy(b.name, raw->name, sizeof(b.name));
        b.kind = raw->kind;
        b.bus_budget = raw->bus_budget != NULL ? *raw->bus_budget : DEFAULT_BUS_BUDGET;
        b.n_buses = raw->n_buses; /* libcyaml enforced <= PS_MAX_BUSES */
        for (uint32_t i = 0; i < raw->n_buses; i++) {
            const bus_raw_t *r = &raw->buses[i];
            memcpy(b.buses[i].ifname, r->ifname, sizeof(b.buses[i].ifname));
            b.buses[i].bitrate = r->bitrate;
            b.buses[i].is_fd = r->is_fd != NULL && *r->is_fd;
            /* Without FD the data phase is the arbitration phase. */
            b.buses[i].data_bitrate = r->data_bitrate != NULL ? *r->data_bitrate : r->bitrate;
            if (r->data_bitrate != NULL && !b.buses[i].is_fd && dbr_without_fd < 0)
                dbr_without_fd = (int)i;
        }
        b.gpio = raw->gpio;
        b.rt = raw->rt;
    }
    if (raw != NULL)
        (void)cyaml_free(&c.cyaml, &BOARD_SCHEMA, raw, 0); /* only fails on a NULL schema */
    if (rc == 0 && dbr_without_fd >= 0) {
        char field[PS_CFG_FIELD_PATH_LEN];
        (void)snprintf(field, sizeof(field), "buses[%d].data_bitrate", dbr_without_fd);
        rc = ps_cfg_fail_field(&c, field, "a data bit rate needs a CAN FD bus (fd: true)");
    }
    if (rc == 0)
        rc = check_board(&c, &b);
    if (rc == 0)
        *out = b;
    ps_cfg_ctx_close(&c);
    return rc;
}

/* "FILE:LINE: text" for a field of a loaded robot file, else (a struct built
 * in code) "robot NAME: text". @return -PS_ERR_CONFIG */
static int pair_fail(char *err, size_t err_len, const ps_robot_cfg_t *r, uint32_t line,
                     const char *fmt, ...) __attribute__((format(printf, 5, 6)));
static int pair_fail(char *err, size_t err_len, const ps_robot_cfg_t *r, uint32_t line,
                     const char *fmt, ...)
{
    char text[PS_ERR_MSG_LEN];
    va_list ap;
    va_start(ap, fmt);
    (void)vsnprintf(text, sizeof(text), fmt, ap); /* truncation is acceptable */
    va_end(ap);
    if (r->src.path[0] == '\0')
        ps_err_format(err, err_len, "robot %s: %s", r->name, text);
    else if (line == 0)
        ps_err_format(err, err_len, "%s: %s", r->src.path, text);
    else
        ps_err_format(err, err_len, "%s:%u: %s", r->src.path, line, text);
    return -PS_ERR_CONFIG;
}

int ps_config_check_pair(const ps_board_cfg_t *b, const ps_robot_cfg_t *r, char *err,
                         size_t err_len)
{
    if (b == NULL || r == NULL)
        return -EINVAL;
    if (err != NULL && err_len > 0)
        err[0] = '\0';
    for (uint32_t i = 0; i < r->n_joints && i < PS_MAX_JOINTS; i++) {
        const uint32_t bus_idx = r->act[i].bus_idx;
        if (bus_idx >= b->n_buses)
            return pair_fail(err, err_len, r, r->src.joint_bus_line[i],
                             "joints[%u].bus: bus %u not on board %s (buses 0..%u)", i, bus_idx,
                             b->name, b->n_buses - 1u);
        const ps_act_proto_t *p = ps_act_proto_get(r->act[i].protocol);
        if (p != NULL && p->is_fd && !b->buses[bus_idx].is_fd)
            return pair_fail(err, err_len, r, r->src.joint_protocol_line[i],
                             "joints[%u].protocol: %s needs CAN FD but bus %u (%s) of board %s "
                             "is classical",
                             i, p->name, bus_idx, b->buses[bus_idx].ifname, b->name);
    }
    if (r->imu.bus_idx >= b->n_buses)
        return pair_fail(err, err_len, r, r->src.imu_bus_line,
                         "imu.bus: bus %u not on board %s (buses 0..%u)", r->imu.bus_idx, b->name,
                         b->n_buses - 1u);
    return 0;
}
