/*
 * ps_config_board: the board file (boards/<name>.yaml) and the checks of a
 * robot against a board. Shared machinery: ps_config_common.h.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ps_config.h"
#include "ps_config_common.h"
#include "ps_err.h"

#define DEFAULT_BUS_BUDGET 0.8f
/* Detections below this decision margin are dropped unless the board says
 * otherwise: a judgment, a tag that faint is too blurred or small to trust
 * (docs/perception.md). */
#define PS_BOARD_CAMERA_MIN_MARGIN 20.0f
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

/* The optional `camera:` section as written (docs/config.md). */
typedef struct {
    float fx_px, fy_px, cx_px, cy_px;
} intrinsics_raw_t;
typedef struct {
    float xyz_m[3];
    float rpy_rad[3];
} pose_raw_t;
typedef struct {
    char sensor[PS_NAME_LEN]; /* for pushstep doctor; empty when absent */
    /* camera perception: source, then the rest (required with it, refused
     * without it); NULL or empty when absent */
    ps_camera_source_t *source;
    char id[PS_PATH_LEN];  /* libcamera only */
    char dir[PS_PATH_LEN]; /* files only */
    uint32_t *width, *height;
    ps_camera_format_t *format; /* libcamera only */
    float *fps;
    intrinsics_raw_t *intrinsics;
    pose_raw_t *pose;
    float *tag_size_m;
    float *max_age_s;
    uint32_t *threads;
    float *decimate;
    float *min_margin;
} camera_raw_t;

typedef struct {
    char name[PS_NAME_LEN];
    ps_board_kind_t kind;
    float *bus_budget; /* optional: NULL when absent */
    bus_raw_t *buses;
    uint32_t n_buses;
    gpio_raw_t gpio;
    ps_rt_cfg_t rt;
    camera_raw_t *camera; /* optional: NULL when absent */
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

static const cyaml_strval_t CAMERA_SOURCES[] = {
    {"libcamera", PS_CAMERA_SRC_LIBCAMERA},
    {"files", PS_CAMERA_SRC_FILES},
    {"sim", PS_CAMERA_SRC_SIM},
};
static_assert(sizeof(CAMERA_SOURCES) / sizeof(CAMERA_SOURCES[0]) == PS_CAMERA_SRC_COUNT,
              "one YAML name per camera source");
static const cyaml_strval_t CAMERA_FORMATS[] = {
    {"R8", PS_PIX_R8},         {"YUV420", PS_PIX_YUV420}, {"NV12", PS_PIX_NV12},
    {"RGB888", PS_PIX_RGB888}, {"BGR888", PS_PIX_BGR888}, {"XRGB8888", PS_PIX_XRGB8888},
};
static_assert(sizeof(CAMERA_FORMATS) / sizeof(CAMERA_FORMATS[0]) == PS_PIX_COUNT,
              "one YAML name per pixel format");
static const cyaml_schema_value_t CAMERA_FLOAT_SCHEMA = {
    CYAML_VALUE_FLOAT(CYAML_FLAG_DEFAULT, float),
};
static const cyaml_schema_field_t INTRINSICS_FIELDS[] = {
    CYAML_FIELD_FLOAT("fx_px", CYAML_FLAG_DEFAULT, intrinsics_raw_t, fx_px),
    CYAML_FIELD_FLOAT("fy_px", CYAML_FLAG_DEFAULT, intrinsics_raw_t, fy_px),
    CYAML_FIELD_FLOAT("cx_px", CYAML_FLAG_DEFAULT, intrinsics_raw_t, cx_px),
    CYAML_FIELD_FLOAT("cy_px", CYAML_FLAG_DEFAULT, intrinsics_raw_t, cy_px),
    CYAML_FIELD_END,
};
static const cyaml_schema_field_t POSE_FIELDS[] = {
    CYAML_FIELD_SEQUENCE_FIXED("xyz_m", CYAML_FLAG_DEFAULT, pose_raw_t, xyz_m,
                               &CAMERA_FLOAT_SCHEMA, 3),
    CYAML_FIELD_SEQUENCE_FIXED("rpy_rad", CYAML_FLAG_DEFAULT, pose_raw_t, rpy_rad,
                               &CAMERA_FLOAT_SCHEMA, 3),
    CYAML_FIELD_END,
};
static const cyaml_schema_field_t CAMERA_FIELDS[] = {
    CYAML_FIELD_STRING("sensor", CYAML_FLAG_OPTIONAL, camera_raw_t, sensor, 1),
    CYAML_FIELD_ENUM_PTR("source", CYAML_FLAG_OPTIONAL | CYAML_FLAG_STRICT, camera_raw_t, source,
                         CAMERA_SOURCES, CYAML_ARRAY_LEN(CAMERA_SOURCES)),
    CYAML_FIELD_STRING("id", CYAML_FLAG_OPTIONAL, camera_raw_t, id, 1),
    CYAML_FIELD_STRING("dir", CYAML_FLAG_OPTIONAL, camera_raw_t, dir, 1),
    CYAML_FIELD_UINT_PTR("width", CYAML_FLAG_OPTIONAL, camera_raw_t, width),
    CYAML_FIELD_UINT_PTR("height", CYAML_FLAG_OPTIONAL, camera_raw_t, height),
    CYAML_FIELD_ENUM_PTR("format", CYAML_FLAG_OPTIONAL | CYAML_FLAG_STRICT, camera_raw_t, format,
                         CAMERA_FORMATS, CYAML_ARRAY_LEN(CAMERA_FORMATS)),
    CYAML_FIELD_FLOAT_PTR("fps", CYAML_FLAG_OPTIONAL, camera_raw_t, fps),
    CYAML_FIELD_MAPPING_PTR("intrinsics", CYAML_FLAG_OPTIONAL, camera_raw_t, intrinsics,
                            INTRINSICS_FIELDS),
    CYAML_FIELD_MAPPING_PTR("pose", CYAML_FLAG_OPTIONAL, camera_raw_t, pose, POSE_FIELDS),
    CYAML_FIELD_FLOAT_PTR("tag_size_m", CYAML_FLAG_OPTIONAL, camera_raw_t, tag_size_m),
    CYAML_FIELD_FLOAT_PTR("max_age_s", CYAML_FLAG_OPTIONAL, camera_raw_t, max_age_s),
    CYAML_FIELD_UINT_PTR("threads", CYAML_FLAG_OPTIONAL, camera_raw_t, threads),
    CYAML_FIELD_FLOAT_PTR("decimate", CYAML_FLAG_OPTIONAL, camera_raw_t, decimate),
    CYAML_FIELD_FLOAT_PTR("min_margin", CYAML_FLAG_OPTIONAL, camera_raw_t, min_margin),
    CYAML_FIELD_END,
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
    /* Camera perception's (keys "camera."): checked only when the board's
     * camera has a source. */
    PS_CFG_RULE_U32(0, 0, "camera.width", ps_board_cfg_t, perception.camera.width, 16.0,
                    PS_CAMERA_MAX_WIDTH),
    PS_CFG_RULE_U32(0, 0, "camera.height", ps_board_cfg_t, perception.camera.height, 16.0,
                    PS_CAMERA_MAX_HEIGHT),
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "camera.fps", ps_board_cfg_t, perception.camera.fps, 0.0,
                    240.0),
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "camera.intrinsics.fx_px", ps_board_cfg_t,
                    perception.tags.k.fx_px, 0.0, 100000.0),
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "camera.intrinsics.fy_px", ps_board_cfg_t,
                    perception.tags.k.fy_px, 0.0, 100000.0),
    PS_CFG_RULE_F32(0, 0, "camera.intrinsics.cx_px", ps_board_cfg_t, perception.tags.k.cx_px, 0.0,
                    PS_CAMERA_MAX_WIDTH),
    PS_CFG_RULE_F32(0, 0, "camera.intrinsics.cy_px", ps_board_cfg_t, perception.tags.k.cy_px, 0.0,
                    PS_CAMERA_MAX_HEIGHT),
    PS_CFG_RULE_F32(0, 0, "camera.pose.xyz_m[0]", ps_board_cfg_t, perception.tags.cam_pos_m[0], -5.0,
                    5.0),
    PS_CFG_RULE_F32(0, 0, "camera.pose.xyz_m[1]", ps_board_cfg_t, perception.tags.cam_pos_m[1], -5.0,
                    5.0),
    PS_CFG_RULE_F32(0, 0, "camera.pose.xyz_m[2]", ps_board_cfg_t, perception.tags.cam_pos_m[2], -5.0,
                    5.0),
    PS_CFG_RULE_F32(0, 0, "camera.pose.rpy_rad[0]", ps_board_cfg_t, perception.tags.cam_rpy_rad[0],
                    -M_PI, M_PI),
    PS_CFG_RULE_F32(0, 0, "camera.pose.rpy_rad[1]", ps_board_cfg_t, perception.tags.cam_rpy_rad[1],
                    -M_PI_2, M_PI_2),
    PS_CFG_RULE_F32(0, 0, "camera.pose.rpy_rad[2]", ps_board_cfg_t, perception.tags.cam_rpy_rad[2],
                    -M_PI, M_PI),
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "camera.tag_size_m", ps_board_cfg_t,
                    perception.tags.tag_size_m, 0.0, 2.0),
    PS_CFG_RULE_F32(0, PS_CFG_RANGE_OPEN_MIN, "camera.max_age_s", ps_board_cfg_t,
                    perception.max_age_s, 0.0, 10.0),
    PS_CFG_RULE_U32(0, 0, "camera.threads", ps_board_cfg_t, perception.tags.n_threads, 1.0, 16.0),
    PS_CFG_RULE_F32(0, 0, "camera.decimate", ps_board_cfg_t, perception.tags.decimate, 1.0, 8.0),
    PS_CFG_RULE_F32(0, 0, "camera.min_margin", ps_board_cfg_t, perception.tags.min_margin, 0.0, 255.0),
};

/* Which optional camera fields were written (kept past the raw data's free). */
typedef struct {
    bool has_format, has_id, has_dir;
} camera_written_t;

/* The camera section against itself and the board (after its ranges). */
static int check_camera(ps_cfg_ctx_t *c, const ps_board_cfg_t *b, const camera_written_t *r)
{
    const ps_perception_cfg_t *cam = &b->perception;
    const ps_camera_source_t src = cam->camera.source;
    const char *name = ps_camera_source_name(src);
    if (src == PS_CAMERA_SRC_LIBCAMERA && !r->has_format)
        return ps_cfg_fail_field(c, "camera", "missing field \"format\" (the libcamera stream's "
                                              "pixel format, e.g. YUV420)");
    if (src != PS_CAMERA_SRC_LIBCAMERA && r->has_format)
        return ps_cfg_fail_field(c, "camera.format",
                                 "only source libcamera takes a format (%s delivers its own)",
                                 name);
    if (src != PS_CAMERA_SRC_LIBCAMERA && r->has_id)
        return ps_cfg_fail_field(c, "camera.id", "only source libcamera takes an id");
    if (src == PS_CAMERA_SRC_FILES && !r->has_dir)
        return ps_cfg_fail_field(c, "camera", "missing field \"dir\" (the image folder)");
    if (src != PS_CAMERA_SRC_FILES && r->has_dir)
        return ps_cfg_fail_field(c, "camera.dir", "only source files takes a dir");
    if (src == PS_CAMERA_SRC_SIM && b->kind != PS_BOARD_SIM)
        return ps_cfg_fail_field(c, "camera.source",
                                 "the simulated camera needs a board of kind sim");
    const ps_camera_intrinsics_t *k = &cam->tags.k;
    if (k->cx_px > (float)cam->camera.width)
        return ps_cfg_fail_field(c, "camera.intrinsics.cx_px", "value %g outside [0, width %u]",
                                 (double)k->cx_px, cam->camera.width);
    if (k->cy_px > (float)cam->camera.height)
        return ps_cfg_fail_field(c, "camera.intrinsics.cy_px", "value %g outside [0, height %u]",
                                 (double)k->cy_px, cam->camera.height);
    /* MuJoCo's camera has square pixels and its axis through the centre. */
    if (src == PS_CAMERA_SRC_SIM && fabsf(k->fx_px - k->fy_px) > 1e-3f * k->fy_px)
        return ps_cfg_fail_field(c, "camera.intrinsics.fx_px",
                                 "the simulated camera has square pixels: fx_px %g must equal "
                                 "fy_px %g",
                                 (double)k->fx_px, (double)k->fy_px);
    if (src == PS_CAMERA_SRC_SIM && (fabsf(k->cx_px - 0.5f * (float)cam->camera.width) > 0.01f ||
                                     fabsf(k->cy_px - 0.5f * (float)cam->camera.height) > 0.01f))
        return ps_cfg_fail_field(c, "camera.intrinsics.cx_px",
                                 "the simulated camera's axis is the image centre: cx_px, cy_px "
                                 "must be %g, %g",
                                 0.5 * cam->camera.width, 0.5 * cam->camera.height);
    return 0;
}

/* Camera perception's fields: every one needed with camera.source, none
 * without it (a camera: with its sensor alone is for pushstep doctor). */
static int camera_fields_present(ps_cfg_ctx_t *c, const camera_raw_t *r)
{
    const struct {
        const char *key;
        bool is_there;
        bool is_required;
    } f[] = {
        {"width", r->width != NULL, true},
        {"height", r->height != NULL, true},
        {"fps", r->fps != NULL, true},
        {"intrinsics", r->intrinsics != NULL, true},
        {"pose", r->pose != NULL, true},
        {"tag_size_m", r->tag_size_m != NULL, true},
        {"max_age_s", r->max_age_s != NULL, true},
        {"id", r->id[0] != '\0', false},
        {"dir", r->dir[0] != '\0', false},
        {"format", r->format != NULL, false},
        {"threads", r->threads != NULL, false},
        {"decimate", r->decimate != NULL, false},
        {"min_margin", r->min_margin != NULL, false},
    };
    char field[PS_CFG_FIELD_PATH_LEN];
    for (size_t i = 0; i < sizeof(f) / sizeof(f[0]); i++) {
        if (r->source == NULL && f[i].is_there) {
            (void)snprintf(field, sizeof(field), "camera.%s", f[i].key);
            return ps_cfg_fail_field(c, field,
                                     "camera perception's fields need camera.source (libcamera, "
                                     "files or sim)");
        }
        if (r->source != NULL && f[i].is_required && !f[i].is_there)
            return ps_cfg_fail_field(c, "camera", "missing field \"%s\"", f[i].key);
    }
    /* camera: {} names neither a sensor (for doctor) nor a source */
    if (r->source == NULL && r->sensor[0] == '\0')
        return ps_cfg_fail_field(c, "camera", "missing field \"sensor\"");
    return 0;
}

/* @pre camera_fields_present passed and r->source != NULL */
static void camera_from_raw(const camera_raw_t *r, ps_perception_cfg_t *out)
{
    memset(out, 0, sizeof(*out));
    ps_camera_cfg_t *cc = &out->camera;
    cc->source = *r->source;
    memcpy(cc->id, r->id, sizeof(cc->id));
    memcpy(cc->dir, r->dir, sizeof(cc->dir));
    cc->width = *r->width;
    cc->height = *r->height;
    cc->format = r->format != NULL ? *r->format : PS_PIX_R8;
    cc->fps = *r->fps;
    ps_tags_cfg_t *t = &out->tags;
    t->k = (ps_camera_intrinsics_t){r->intrinsics->fx_px, r->intrinsics->fy_px,
                                    r->intrinsics->cx_px, r->intrinsics->cy_px};
    memcpy(t->cam_pos_m, r->pose->xyz_m, sizeof(t->cam_pos_m));
    memcpy(t->cam_rpy_rad, r->pose->rpy_rad, sizeof(t->cam_rpy_rad));
    t->tag_size_m = *r->tag_size_m;
    t->n_threads = r->threads != NULL ? *r->threads : 1u;
    t->decimate = r->decimate != NULL ? *r->decimate : 1.0f;
    t->min_margin = r->min_margin != NULL ? *r->min_margin : PS_BOARD_CAMERA_MIN_MARGIN;
    out->max_age_s = *r->max_age_s;
}

static int check_board(ps_cfg_ctx_t *c, const ps_board_cfg_t *b)
{
    /* Camera perception's rules only with camera.source: without it, the
     * table less the rules whose key starts with "camera.". */
    ps_cfg_rule_t rules[PS_CFG_COUNT(BOARD_RANGES)];
    size_t n = 0;
    for (size_t i = 0; i < PS_CFG_COUNT(BOARD_RANGES); i++)
        if (b->has_perception || strncmp(BOARD_RANGES[i].key, "camera.", 7) != 0)
            rules[n++] = BOARD_RANGES[i];
    const ps_cfg_rule_t *all = c->rules;
    const size_t n_all = c->n_rules;
    c->rules = rules;
    c->n_rules = n;
    int rc = ps_cfg_check_ranges(c, b);
    c->rules = all;
    c->n_rules = n_all;
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
        rc = gpio_from_raw(&c, &raw->gpio, &b.gpio);
        b.has_camera = raw->camera != NULL;
        if (b.has_camera) {
            memcpy(b.camera.sensor, raw->camera->sensor, sizeof(b.camera.sensor));
            b.camera_line = ps_cfg_line_of(&c, "camera");
            if (rc == 0)
                rc = camera_fields_present(&c, raw->camera);
            b.has_perception = rc == 0 && raw->camera->source != NULL;
            if (b.has_perception)
                camera_from_raw(raw->camera, &b.perception);
        }
    }
    camera_written_t cam_written = {false, false, false}; /* check_camera's, past the free */
    if (rc == 0 && raw->camera != NULL)
        cam_written = (camera_written_t){raw->camera->format != NULL, raw->camera->id[0] != '\0',
                                         raw->camera->dir[0] != '\0'};
    if (raw != NULL)
        (void)cyaml_free(&c.cyaml, &BOARD_SCHEMA, raw, 0); /* only fails on a NULL schema */
    if (rc == 0 && dbr_without_fd >= 0) {
        char field[PS_CFG_FIELD_PATH_LEN];
        (void)snprintf(field, sizeof(field), "buses[%d].data_bitrate", dbr_without_fd);
        rc = ps_cfg_fail_field(&c, field, "a data bit rate needs a CAN FD bus (fd: true)");
    }
    if (rc == 0)
        rc = check_board(&c, &b);
    if (rc == 0 && b.has_perception)
        rc = check_camera(&c, &b, &cam_written);
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
