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
    ps_canbus_ctrl_t controller; /* absent: 0, any */
} bus_raw_t;

/* The gpio mapping as written: each line by offset or by name, so the
 * offsets are optional (NULL when absent) and the names empty when absent. */
typedef struct {
    char chip[PS_NAME_LEN];
    uint32_t *estop_line;
    bool is_estop_active_low;
    uint32_t *enable_line;
    uint32_t *led_line;
    char estop_name[PS_NAME_LEN];
    char enable_name[PS_NAME_LEN];
    char led_name[PS_NAME_LEN];
    ps_gpio_bias_t estop_bias;
    uint32_t estop_debounce_us;
    uint32_t *button_line; /* the record button: optional, line or name */
    char button_name[PS_NAME_LEN];
    bool is_button_active_low;
} gpio_raw_t;

typedef struct {
    char name[PS_NAME_LEN];
    ps_board_kind_t kind;
    float *bus_budget; /* optional: NULL when absent */
    bus_raw_t *buses;
    uint32_t n_buses;
    gpio_raw_t gpio;
    ps_rt_cfg_t rt;
    ps_board_camera_t *camera; /* optional: NULL when absent */
} board_raw_t;

static const cyaml_strval_t BOARD_KINDS[] = {
    {"sim", PS_BOARD_SIM},
    {"linux", PS_BOARD_LINUX},
};

static const cyaml_strval_t GPIO_BIASES[] = {
    {"as-is", PS_GPIO_BIAS_AS_IS},
    {"pull-up", PS_GPIO_BIAS_PULL_UP},
    {"pull-down", PS_GPIO_BIAS_PULL_DOWN},
    {"disabled", PS_GPIO_BIAS_DISABLED},
};

static const cyaml_strval_t CONTROLLERS[] = {
    {"mcp2515", PS_CANBUS_CTRL_MCP2515}, {"mcp251xfd", PS_CANBUS_CTRL_MCP251XFD},
    {"mttcan", PS_CANBUS_CTRL_MTTCAN},   {"m_can", PS_CANBUS_CTRL_M_CAN},
    {"gs_usb", PS_CANBUS_CTRL_GS_USB},   {"virtual", PS_CANBUS_CTRL_VIRTUAL},
};

static const cyaml_schema_field_t BUS_FIELDS[] = {
    CYAML_FIELD_STRING("ifname", CYAML_FLAG_DEFAULT, bus_raw_t, ifname, 1),
    CYAML_FIELD_UINT("bitrate", CYAML_FLAG_DEFAULT, bus_raw_t, bitrate),
    CYAML_FIELD_BOOL_PTR("fd", CYAML_FLAG_OPTIONAL | CYAML_FLAG_STRICT, bus_raw_t, is_fd),
    CYAML_FIELD_UINT_PTR("data_bitrate", CYAML_FLAG_OPTIONAL, bus_raw_t, data_bitrate),
    CYAML_FIELD_ENUM("controller", CYAML_FLAG_OPTIONAL | CYAML_FLAG_STRICT, bus_raw_t, controller,
                     CONTROLLERS, CYAML_ARRAY_LEN(CONTROLLERS)),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t BUS_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_DEFAULT, bus_raw_t, BUS_FIELDS),
};
/* Each of estop/enable/led: X_line or X_name, exactly one (checked after
 * the load, gpio_from_raw). */
static const cyaml_schema_field_t GPIO_FIELDS[] = {
    CYAML_FIELD_STRING("chip", CYAML_FLAG_DEFAULT, gpio_raw_t, chip, 1),
    CYAML_FIELD_UINT_PTR("estop_line", CYAML_FLAG_OPTIONAL, gpio_raw_t, estop_line),
    CYAML_FIELD_BOOL("estop_active_low", CYAML_FLAG_STRICT, gpio_raw_t, is_estop_active_low),
    CYAML_FIELD_UINT_PTR("enable_line", CYAML_FLAG_OPTIONAL, gpio_raw_t, enable_line),
    CYAML_FIELD_UINT_PTR("led_line", CYAML_FLAG_OPTIONAL, gpio_raw_t, led_line),
    CYAML_FIELD_STRING("estop_name", CYAML_FLAG_OPTIONAL, gpio_raw_t, estop_name, 1),
    CYAML_FIELD_STRING("enable_name", CYAML_FLAG_OPTIONAL, gpio_raw_t, enable_name, 1),
    CYAML_FIELD_STRING("led_name", CYAML_FLAG_OPTIONAL, gpio_raw_t, led_name, 1),
    CYAML_FIELD_ENUM("estop_bias", CYAML_FLAG_OPTIONAL | CYAML_FLAG_STRICT, gpio_raw_t, estop_bias,
                     GPIO_BIASES, CYAML_ARRAY_LEN(GPIO_BIASES)),
    CYAML_FIELD_UINT("estop_debounce_us", CYAML_FLAG_OPTIONAL, gpio_raw_t, estop_debounce_us),
    CYAML_FIELD_UINT_PTR("record_button_line", CYAML_FLAG_OPTIONAL, gpio_raw_t, button_line),
    CYAML_FIELD_STRING("record_button_name", CYAML_FLAG_OPTIONAL, gpio_raw_t, button_name, 1),
    CYAML_FIELD_BOOL("record_button_active_low", CYAML_FLAG_OPTIONAL | CYAML_FLAG_STRICT,
                     gpio_raw_t, is_button_active_low),
    CYAML_FIELD_END,
};
static const cyaml_schema_field_t RT_FIELDS[] = {
    CYAML_FIELD_UINT("priority", CYAML_FLAG_DEFAULT, ps_rt_cfg_t, priority),
    CYAML_FIELD_INT("loop_cpu", CYAML_FLAG_DEFAULT, ps_rt_cfg_t, loop_cpu),
    CYAML_FIELD_INT("plant_cpu", CYAML_FLAG_DEFAULT, ps_rt_cfg_t, plant_cpu),
    CYAML_FIELD_INT("worker_cpu", CYAML_FLAG_DEFAULT, ps_rt_cfg_t, worker_cpu),
    CYAML_FIELD_END,
};
static const cyaml_schema_field_t CAMERA_FIELDS[] = {
    CYAML_FIELD_STRING("sensor", CYAML_FLAG_DEFAULT, ps_board_camera_t, sensor, 1),
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
    CYAML_FIELD_MAPPING_PTR("camera", CYAML_FLAG_OPTIONAL, board_raw_t, camera, CAMERA_FIELDS),
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
    PS_CFG_RULE_U32(0, 0, "gpio.record_button_line", ps_board_cfg_t, gpio.button_line, 0.0,
                    MAX_GPIO_LINE),
    PS_CFG_RULE_U32(0, 0, "gpio.estop_debounce_us", ps_board_cfg_t, gpio.estop_debounce_us, 0.0,
                    PS_GPIO_DEBOUNCE_MAX_US),
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
        const ps_canbus_ctrl_info_t *ci = ps_canbus_ctrl_info(bus->controller);
        if (bus->is_fd && !ci->is_fd_capable) {
            (void)snprintf(field, sizeof(field), "buses[%u].fd", i);
            return ps_cfg_fail_field(c, field, "controller %s is classical CAN only", ci->name);
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
    /* Lines by offset are compared by offset, lines by name by name; one by
     * name against one by offset can only be compared on the chip (the port
     * refuses two roles on one line at open). */
    const struct {
        const char *key;
        const char *name_key;
        uint32_t line;
        const char *name;
    } lines[] = {
        {"gpio.estop_line", "gpio.estop_name", b->gpio.estop_line, b->gpio.estop_name},
        {"gpio.enable_line", "gpio.enable_name", b->gpio.enable_line, b->gpio.enable_name},
        {"gpio.led_line", "gpio.led_name", b->gpio.led_line, b->gpio.led_name},
        {"gpio.record_button_line", "gpio.record_button_name", b->gpio.button_line,
         b->gpio.button_name},
    };
    const size_t n_lines = sizeof(lines) / sizeof(lines[0]) - (b->gpio.has_button ? 0u : 1u);
    for (size_t i = 1; i < n_lines; i++) {
        for (size_t k = 0; k < i; k++) {
            const bool is_named_i = lines[i].name[0] != '\0';
            const bool is_named_k = lines[k].name[0] != '\0';
            if (!is_named_i && !is_named_k && lines[i].line == lines[k].line)
                return ps_cfg_fail_field(c, lines[i].key, "line %u already used by %s",
                                         lines[i].line, lines[k].key);
            if (is_named_i && is_named_k && strcmp(lines[i].name, lines[k].name) == 0)
                return ps_cfg_fail_field(c, lines[i].name_key, "line \"%s\" already used by %s",
                                         lines[i].name, lines[k].name_key);
        }
    }
    return 0;
}

/* One line of the gpio mapping: exactly one of X_line and X_name. */
static int gpio_line_from_raw(ps_cfg_ctx_t *c, const char *role, const uint32_t *line,
                              const char *name, uint32_t *out_line)
{
    char key[PS_CFG_FIELD_PATH_LEN];
    if (line != NULL && name[0] != '\0') {
        (void)snprintf(key, sizeof(key), "gpio.%s_name", role);
        return ps_cfg_fail_field(c, key, "give gpio.%s_line or gpio.%s_name, not both", role, role);
    }
    if (line == NULL && name[0] == '\0')
        return ps_cfg_fail_field(c, "gpio", "missing field \"%s_line\" (or \"%s_name\")", role,
                                 role);
    *out_line = line != NULL ? *line : 0u; /* by name: the offset is unused */
    return 0;
}

static int gpio_from_raw(ps_cfg_ctx_t *c, const gpio_raw_t *r, ps_gpio_cfg_t *out)
{
    memset(out, 0, sizeof(*out));
    memcpy(out->chip, r->chip, sizeof(out->chip));
    out->is_estop_active_low = r->is_estop_active_low;
    memcpy(out->estop_name, r->estop_name, sizeof(out->estop_name));
    memcpy(out->enable_name, r->enable_name, sizeof(out->enable_name));
    memcpy(out->led_name, r->led_name, sizeof(out->led_name));
    out->estop_bias = r->estop_bias;               /* absent: 0, as-is */
    out->estop_debounce_us = r->estop_debounce_us; /* absent: 0, no debounce */
    int rc = gpio_line_from_raw(c, "estop", r->estop_line, r->estop_name, &out->estop_line);
    if (rc == 0)
        rc = gpio_line_from_raw(c, "enable", r->enable_line, r->enable_name, &out->enable_line);
    if (rc == 0)
        rc = gpio_line_from_raw(c, "led", r->led_line, r->led_name, &out->led_line);
    /* the record button is optional: no line and no name, no button */
    out->has_button = r->button_line != NULL || r->button_name[0] != '\0';
    out->is_button_active_low = r->is_button_active_low;
    memcpy(out->button_name, r->button_name, sizeof(out->button_name));
    if (rc == 0 && out->has_button)
        rc = gpio_line_from_raw(c, "record_button", r->button_line, r->button_name,
                                &out->button_line);
    return rc;
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
            b.buses[i].controller = r->controller;
            if (r->data_bitrate != NULL && !b.buses[i].is_fd && dbr_without_fd < 0)
                dbr_without_fd = (int)i;
        }
        b.rt = raw->rt;
        if (raw->camera != NULL) {
            b.has_camera = true;
            b.camera = *raw->camera;
        }
        rc = gpio_from_raw(&c, &raw->gpio, &b.gpio);
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
