/*
 * Tests of the board file's optional `camera:` section (rt/ps_config_board.c):
 * loaded values and defaults, a board without one, and each refusal with its
 * FILE:LINE: FIELD: message (docs/config.md, "camera").
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../rt/ps_config.h"
#include "../rt/ps_err.h"

static const char BOARD[] = "name: cam\n"
                            "kind: sim\n"
                            "buses:\n"
                            "  - {ifname: can0, bitrate: 1000000}\n"
                            "gpio: {chip: sim, estop_line: 0, estop_active_low: true, "
                            "enable_line: 1, led_line: 2}\n"
                            "rt: {priority: 0, loop_cpu: -1, plant_cpu: -1, worker_cpu: -1}\n"
                            "camera:\n"
                            "  source: sim\n"
                            "  width: 640\n"
                            "  height: 480\n"
                            "  fps: 15\n"
                            "  intrinsics: {fx_px: 554.3, fy_px: 554.3, cx_px: 320, cy_px: 240}\n"
                            "  pose: {xyz_m: [0.1, 0, 0.54], rpy_rad: [0, 0.25, 0]}\n"
                            "  tag_size_m: 0.12\n"
                            "  max_age_s: 0.2\n";

typedef struct {
    char path[64];
    char text[4096];
    char err[PS_ERR_MSG_LEN];
    ps_board_cfg_t board;
} fx_t;

static int setup(void **state)
{
    fx_t *f = calloc(1, sizeof(*f));
    if (f == NULL)
        return -1;
    (void)snprintf(f->path, sizeof(f->path), "/tmp/ps_test_camcfg_XXXXXX");
    const int fd = mkstemp(f->path);
    if (fd < 0)
        return -1;
    (void)close(fd);
    *state = f;
    return 0;
}

static int teardown(void **state)
{
    fx_t *f = *state;
    (void)unlink(f->path);
    free(f);
    return 0;
}

/* Writes BOARD with `from` replaced by `to` (from "" : as it is) and loads it. */
static int load_with(fx_t *f, const char *from, const char *to)
{
    const char *at = from[0] != '\0' ? strstr(BOARD, from) : BOARD + strlen(BOARD);
    assert_non_null(at);
    const size_t skip = from[0] != '\0' ? strlen(from) : 0;
    (void)snprintf(f->text, sizeof(f->text), "%.*s%s%s", (int)(at - BOARD), BOARD, to, at + skip);
    FILE *fp = fopen(f->path, "w");
    assert_non_null(fp);
    assert_true(fputs(f->text, fp) >= 0);
    assert_int_equal(fclose(fp), 0);
    f->err[0] = '\0';
    return ps_config_load_board(f->path, &f->board, f->err, sizeof(f->err));
}

static int line_of(const fx_t *f, const char *needle)
{
    const char *at = strstr(f->text, needle);
    assert_non_null(at);
    int line = 1;
    for (const char *p = f->text; p < at; p++)
        line += *p == '\n';
    return line;
}

/* The load fails with "PATH:LINE: rest" (LINE of needle in the file). */
static void expect_error(fx_t *f, const char *from, const char *to, const char *needle,
                         const char *rest)
{
    assert_int_equal(load_with(f, from, to), -PS_ERR_CONFIG);
    char want[PS_ERR_MSG_LEN];
    (void)snprintf(want, sizeof(want), "%s:%d: %s", f->path, line_of(f, needle), rest);
    assert_string_equal(f->err, want);
}

static void test_load_board_camera_sim_values_and_defaults(void **state)
{
    fx_t *f = *state;
    assert_int_equal(load_with(f, "", ""), 0);
    const ps_board_cfg_t *b = &f->board;
    assert_true(b->has_camera);
    assert_true(b->has_perception);
    assert_string_equal(b->camera.sensor, ""); /* no sensor given: pushstep doctor takes any */
    assert_int_equal(b->camera_line, 8); /* the mapping's first line */
    const ps_perception_cfg_t *c = &b->perception;
    assert_int_equal(c->camera.source, PS_CAMERA_SRC_SIM);
    assert_int_equal(c->camera.width, 640);
    assert_int_equal(c->camera.height, 480);
    assert_float_equal(c->camera.fps, 15.0, 0);
    assert_float_equal(c->tags.k.fx_px, 554.3, 1e-4);
    assert_float_equal(c->tags.k.cy_px, 240.0, 0);
    assert_float_equal(c->tags.cam_pos_m[0], 0.1, 1e-7);
    assert_float_equal(c->tags.cam_pos_m[2], 0.54, 1e-7);
    assert_float_equal(c->tags.cam_rpy_rad[1], 0.25, 1e-7);
    assert_float_equal(c->tags.tag_size_m, 0.12, 1e-7);
    assert_float_equal(c->max_age_s, 0.2, 1e-7);
    /* defaults */
    assert_int_equal(c->tags.n_threads, 1);
    assert_float_equal(c->tags.decimate, 1.0, 0);
    assert_float_equal(c->tags.min_margin, 20.0, 0);
    assert_string_equal(c->camera.id, "");
    assert_string_equal(c->camera.dir, "");
    /* and written */
    assert_int_equal(load_with(f, "  max_age_s: 0.2\n",
                               "  max_age_s: 0.2\n  threads: 2\n  decimate: 2\n  min_margin: 35\n"),
                     0);
    assert_int_equal(f->board.perception.tags.n_threads, 2);
    assert_float_equal(f->board.perception.tags.decimate, 2.0, 0);
    assert_float_equal(f->board.perception.tags.min_margin, 35.0, 0);
}

static void test_load_board_camera_libcamera_and_files_loaded(void **state)
{
    fx_t *f = *state;
    assert_int_equal(load_with(f, "kind: sim", "kind: linux"), -PS_ERR_CONFIG); /* sim source */
    char text[4096];
    (void)snprintf(text, sizeof(text), "%s", "  source: libcamera\n  id: imx219\n  format: YUV420\n");
    assert_int_equal(load_with(f, "  source: sim\n", text), 0);
    assert_int_equal(f->board.perception.camera.source, PS_CAMERA_SRC_LIBCAMERA);
    assert_string_equal(f->board.perception.camera.id, "imx219");
    assert_int_equal(f->board.perception.camera.format, PS_PIX_YUV420);
    assert_int_equal(load_with(f, "  source: sim\n", "  source: files\n  dir: pictures\n"), 0);
    assert_int_equal(f->board.perception.camera.source, PS_CAMERA_SRC_FILES);
    assert_string_equal(f->board.perception.camera.dir, "pictures");
    /* files and libcamera take any intrinsics */
    assert_int_equal(load_with(f, "  source: sim\n  width: 640\n",
                               "  source: files\n  dir: p\n  width: 700\n"),
                     0);
}

static void test_load_board_without_camera_none(void **state)
{
    fx_t *f = *state;
    const char *at = strstr(BOARD, "camera:\n");
    (void)snprintf(f->text, sizeof(f->text), "%.*s", (int)(at - BOARD), BOARD);
    FILE *fp = fopen(f->path, "w");
    assert_non_null(fp);
    assert_true(fputs(f->text, fp) >= 0);
    assert_int_equal(fclose(fp), 0);
    assert_int_equal(ps_config_load_board(f->path, &f->board, f->err, sizeof(f->err)), 0);
    assert_false(f->board.has_perception);
    assert_int_equal(f->board.camera_line, 0);
    assert_int_equal(ps_config_load_board("boards/sim.yaml", &f->board, f->err, sizeof(f->err)),
                     0);
    assert_false(f->board.has_perception);
}

static void test_load_board_camera_ranges_rejected(void **state)
{
    fx_t *f = *state;
    expect_error(f, "width: 640", "width: 10", "width: 10",
                 "camera.width: value 10 outside [16, 4096]");
    expect_error(f, "fps: 15", "fps: 0", "fps: 0", "camera.fps: value 0 outside (0, 240]");
    expect_error(f, "tag_size_m: 0.12", "tag_size_m: -0.1", "tag_size_m",
                 "camera.tag_size_m: value -0.1 outside (0, 2]");
    expect_error(f, "max_age_s: 0.2", "max_age_s: 11", "max_age_s",
                 "camera.max_age_s: value 11 outside (0, 10]");
    expect_error(f, "fx_px: 554.3", "fx_px: 0", "intrinsics",
                 "camera.intrinsics.fx_px: value 0 outside (0, 100000]");
    expect_error(f, "rpy_rad: [0, 0.25, 0]", "rpy_rad: [0, 2, 0]", "pose",
                 "camera.pose.rpy_rad[1]: value 2 outside [-1.5708, 1.5708]");
    expect_error(f, "xyz_m: [0.1, 0, 0.54]", "xyz_m: [0.1, 0, 9]", "pose",
                 "camera.pose.xyz_m[2]: value 9 outside [-5, 5]");
    expect_error(f, "max_age_s: 0.2\n", "max_age_s: 0.2\n  threads: 0\n", "threads",
                 "camera.threads: value 0 outside [1, 16]");
    expect_error(f, "max_age_s: 0.2\n", "max_age_s: 0.2\n  decimate: 0.5\n", "decimate",
                 "camera.decimate: value 0.5 outside [1, 8]");
}

static void test_load_board_camera_source_rules_rejected(void **state)
{
    fx_t *f = *state;
    expect_error(f, "  source: sim\n", "  source: libcamera\n", "  source:",
                 "camera: missing field \"format\" (the libcamera stream's pixel format, e.g. "
                 "YUV420)");
    expect_error(f, "  source: sim\n", "  source: files\n", "  source:",
                 "camera: missing field \"dir\" (the image folder)");
    expect_error(f, "  source: sim\n", "  source: sim\n  format: R8\n", "format",
                 "camera.format: only source libcamera takes a format (sim delivers its own)");
    expect_error(f, "  source: sim\n", "  source: sim\n  dir: x\n", "dir",
                 "camera.dir: only source files takes a dir");
    expect_error(f, "  source: sim\n", "  source: files\n  dir: x\n  id: cam0\n", "id:",
                 "camera.id: only source libcamera takes an id");
    expect_error(f, "kind: sim", "kind: linux", "source",
                 "camera.source: the simulated camera needs a board of kind sim");
    expect_error(f, "fx_px: 554.3", "fx_px: 600", "intrinsics",
                 "camera.intrinsics.fx_px: the simulated camera has square pixels: fx_px 600 "
                 "must equal fy_px 554.3");
    expect_error(f, "cx_px: 320", "cx_px: 300", "intrinsics",
                 "camera.intrinsics.cx_px: the simulated camera's axis is the image centre: "
                 "cx_px, cy_px must be 320, 240");
    expect_error(f, "  source: sim\n  width: 640\n", "  source: files\n  dir: d\n  width: 300\n",
                 "intrinsics", "camera.intrinsics.cx_px: value 320 outside [0, width 300]");
}

/* A camera: with its sensor alone (the shipped boards): a camera for
 * pushstep doctor, no perception; perception's fields need a source. */
static void test_load_board_camera_sensor_only_no_perception(void **state)
{
    fx_t *f = *state;
    const char *at = strstr(BOARD, "camera:\n");
    char text[2048];
    (void)snprintf(text, sizeof(text), "%.*scamera: {sensor: imx708}\n", (int)(at - BOARD), BOARD);
    FILE *fp = fopen(f->path, "w");
    assert_non_null(fp);
    assert_true(fputs(text, fp) >= 0);
    assert_int_equal(fclose(fp), 0);
    assert_int_equal(ps_config_load_board(f->path, &f->board, f->err, sizeof(f->err)), 0);
    assert_true(f->board.has_camera);
    assert_string_equal(f->board.camera.sensor, "imx708");
    assert_false(f->board.has_perception);
    /* with the sensor and the perception fields, both */
    assert_int_equal(load_with(f, "  source: sim\n", "  sensor: sim\n  source: sim\n"), 0);
    assert_true(f->board.has_perception);
    assert_string_equal(f->board.camera.sensor, "sim");
    /* perception's fields without a source */
    expect_error(f, "  source: sim\n", "", "width",
                 "camera.width: camera perception's fields need camera.source (libcamera, files "
                 "or sim)");
    /* a source without a required field */
    expect_error(f, "  fps: 15\n", "", "  source:", "camera: missing field \"fps\"");
    expect_error(f, "  pose: {xyz_m: [0.1, 0, 0.54], rpy_rad: [0, 0.25, 0]}\n", "", "  source:",
                 "camera: missing field \"pose\"");
}

static void test_load_board_camera_schema_rejected(void **state)
{
    fx_t *f = *state;
    assert_int_equal(load_with(f, "source: sim", "source: usb"), -PS_ERR_CONFIG);
    assert_non_null(strstr(f->err, "camera.source"));
    assert_int_equal(load_with(f, "max_age_s: 0.2\n", "max_age_s: 0.2\n  exposure_us: 100\n"),
                     -PS_ERR_CONFIG);
    assert_non_null(strstr(f->err, "exposure_us"));
    assert_int_equal(load_with(f, "  source: sim\n", "  source: libcamera\n  format: MJPEG\n"),
                     -PS_ERR_CONFIG);
    assert_non_null(strstr(f->err, "camera.format"));
    assert_int_equal(load_with(f, "xyz_m: [0.1, 0, 0.54]", "xyz_m: [0.1, 0]"), -PS_ERR_CONFIG);
    assert_non_null(strstr(f->err, "xyz_m"));
    assert_int_equal(load_with(f, "  tag_size_m: 0.12\n", ""), -PS_ERR_CONFIG);
    assert_non_null(strstr(f->err, "tag_size_m"));
}

int main(void)
{
#define T(fn) cmocka_unit_test_setup_teardown(fn, setup, teardown)
    const struct CMUnitTest tests[] = {
        T(test_load_board_camera_sim_values_and_defaults),
        T(test_load_board_camera_libcamera_and_files_loaded),
        T(test_load_board_without_camera_none),
        T(test_load_board_camera_ranges_rejected),
        T(test_load_board_camera_source_rules_rejected),
        T(test_load_board_camera_sensor_only_no_perception),
        T(test_load_board_camera_schema_rejected),
    };
#undef T
    return cmocka_run_group_tests(tests, NULL, NULL);
}
