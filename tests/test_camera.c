/*
 * Tests of the camera port's helpers (drivers/ps_camera: formats, the grey
 * conversion) and of the image-folder source (drivers/ps_camera_files):
 * stored images of tags at known poses (synthesised by the test into a
 * temporary folder, as PNG and as PGM) read back and detected within the
 * tolerance of test_tags (1 cm + 1 % of the distance), name order, the end
 * of a folder, and each error a folder can give.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <math.h>
#include <png.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <apriltag/common/image_u8.h>

#include "../drivers/ps_camera_files.h"
#include "../drivers/ps_camera_libcamera.h"
#include "../drivers/ps_tags.h"
#include "../rt/ps_err.h"
#include "fakes/ps_camera_fake.h"

#define W 320u
#define H 240u

static const ps_camera_intrinsics_t K = {300.0f, 300.0f, 160.0f, 120.0f};

/* ---- formats and conversion ------------------------------------------- */

static void test_ps_camera_format_names_round_trip(void **state)
{
    (void)state;
    for (int f = 0; f < PS_PIX_COUNT; f++)
        assert_int_equal(ps_camera_format_from_name(ps_camera_format_name(f)), f);
    assert_int_equal(ps_camera_format_from_name("MJPEG"), -ENOENT);
    assert_int_equal(ps_camera_format_from_name(NULL), -ENOENT);
    assert_string_equal(ps_camera_format_name(PS_PIX_COUNT), "?");
    assert_int_equal(ps_camera_format_bpp(PS_PIX_XRGB8888), 4);
    assert_int_equal(ps_camera_format_bpp(PS_PIX_COUNT), 0);
    assert_string_equal(ps_camera_source_name(PS_CAMERA_SRC_SIM), "sim");
}

static void test_ps_camera_to_grey_each_format_luma(void **state)
{
    (void)state;
    /* one row of 2 pixels, stride with padding: pure red, then white */
    uint8_t grey[2];
    const struct {
        ps_camera_format_t f;
        uint8_t px[2][4];
        uint8_t want0;
    } cases[] = {
        {PS_PIX_RGB888, {{0, 0, 255}, {255, 255, 255}}, 77},      /* B G R */
        {PS_PIX_BGR888, {{255, 0, 0}, {255, 255, 255}}, 77},      /* R G B */
        {PS_PIX_XRGB8888, {{0, 0, 255, 9}, {255, 255, 255, 9}}, 77},
        {PS_PIX_R8, {{40}, {255}}, 40},
        {PS_PIX_NV12, {{41}, {255}}, 41},
        {PS_PIX_YUV420, {{42}, {255}}, 42},
    };
    for (size_t c = 0; c < sizeof(cases) / sizeof(cases[0]); c++) {
        const uint32_t bpp = ps_camera_format_bpp(cases[c].f);
        uint8_t buf[32] = {0};
        memcpy(buf, cases[c].px[0], bpp);
        memcpy(buf + bpp, cases[c].px[1], bpp);
        const ps_camera_frame_t fr = {.data = buf, .n_bytes = sizeof(buf), .width = 2,
                                      .height = 1, .stride = 16, .format = cases[c].f};
        assert_int_equal(ps_camera_to_grey(&fr, grey, sizeof(grey)), 0);
        assert_int_equal(grey[0], cases[c].want0);
        assert_int_equal(grey[1], 255);
    }
}

static void test_ps_camera_to_grey_short_buffers_einval(void **state)
{
    (void)state;
    uint8_t buf[64] = {0}, grey[16];
    ps_camera_frame_t fr = {.data = buf, .n_bytes = sizeof(buf), .width = 4, .height = 4,
                            .stride = 12, .format = PS_PIX_RGB888};
    assert_int_equal(ps_camera_to_grey(&fr, grey, sizeof(grey)), 0);
    fr.stride = 11; /* < 4 pixels * 3 bytes */
    assert_int_equal(ps_camera_to_grey(&fr, grey, sizeof(grey)), -EINVAL);
    fr.stride = 12;
    fr.n_bytes = 3 * 12 + 11; /* last row one byte short */
    assert_int_equal(ps_camera_to_grey(&fr, grey, sizeof(grey)), -EINVAL);
    fr.n_bytes = 3 * 12 + 12;
    assert_int_equal(ps_camera_to_grey(&fr, grey, 15), -EINVAL);
    assert_int_equal(ps_camera_to_grey(&fr, grey, 16), 0);
    fr.format = PS_PIX_COUNT;
    assert_int_equal(ps_camera_to_grey(&fr, grey, 16), -EINVAL);
    assert_int_equal(ps_camera_to_grey(NULL, grey, 16), -EINVAL);
}

/* ---- the image folder ---------------------------------------------------- */

typedef struct {
    char dir[64];
    uint8_t img[W * H];
} folder_t;

static int setup_folder(void **state)
{
    folder_t *f = calloc(1, sizeof(*f));
    if (f == NULL)
        return -1;
    snprintf(f->dir, sizeof(f->dir), "/tmp/ps_camera_files_XXXXXX");
    if (mkdtemp(f->dir) == NULL)
        return -1;
    *state = f;
    return 0;
}

static int teardown_folder(void **state)
{
    folder_t *f = *state;
    char cmd[128];
    snprintf(cmd, sizeof(cmd), "rm -rf '%s'", f->dir);
    if (system(cmd) != 0)
        return -1;
    free(f);
    return 0;
}

static void write_png(const folder_t *f, const char *name, const uint8_t *img, uint32_t w,
                      uint32_t h)
{
    char path[128];
    snprintf(path, sizeof(path), "%s/%s", f->dir, name);
    png_image im;
    memset(&im, 0, sizeof(im));
    im.version = PNG_IMAGE_VERSION;
    im.width = w;
    im.height = h;
    im.format = PNG_FORMAT_GRAY;
    assert_true(png_image_write_to_file(&im, path, 0, img, (png_int_32)w, NULL));
}

static void write_pgm(const folder_t *f, const char *name, const uint8_t *img)
{
    char path[128];
    snprintf(path, sizeof(path), "%s/%s", f->dir, name);
    image_u8_t im = {.width = W, .height = H, .stride = W, .buf = (uint8_t *)(uintptr_t)img};
    assert_int_equal(image_u8_write_pnm(&im, path), 0);
}

static ps_camera_cfg_t folder_cfg(const folder_t *f)
{
    ps_camera_cfg_t c = {.source = PS_CAMERA_SRC_FILES, .width = W, .height = H, .fps = 1000.0f};
    snprintf(c.dir, sizeof(c.dir), "%s", f->dir);
    return c;
}

static void test_ps_camera_files_stored_tags_detected_in_name_order(void **state)
{
    folder_t *f = *state;
    /* b_ as PGM, a_ as PNG: played a_ first; a text file is ignored */
    ps_tag_pose_t pa = {.id = 3, .size_m = 0.1, .pos_cam_m = {0.1, -0.05, 0.9}};
    ps_tag_pose_turned(&pa, 0.4, 0.0);
    ps_tag_pose_t pb = {.id = 8, .size_m = 0.1, .pos_cam_m = {-0.15, 0.08, 1.3}};
    ps_tag_pose_turned(&pb, -0.3, 0.2);
    assert_int_equal(ps_tag_image_render(f->img, W, H, &K, &pb, 1, 140, 5, 2), 0);
    write_pgm(f, "b_frame.pgm", f->img);
    assert_int_equal(ps_tag_image_render(f->img, W, H, &K, &pa, 1, 120, 5, 1), 0);
    write_png(f, "a_frame.png", f->img, W, H);
    char path[128];
    snprintf(path, sizeof(path), "%s/notes.txt", f->dir);
    FILE *t = fopen(path, "w");
    assert_non_null(t);
    fputs("not an image\n", t);
    fclose(t);

    const ps_camera_cfg_t cfg = folder_cfg(f);
    ps_camera_files_t src;
    ps_camera_files_init(&src, &cfg, NULL, false);
    ps_camera_port_t port = ps_camera_files_port(&src);
    char err[256] = "";
    assert_int_equal(port.ops->start(port.ctx, err, sizeof(err)), 0);
    const ps_tags_cfg_t tc = {.k = K, .tag_size_m = 0.1f, .n_threads = 1, .decimate = 1.0f};
    ps_tags_t *tags = NULL;
    assert_int_equal(ps_tags_create(&tc, &tags, NULL, 0), 0);
    const ps_tag_pose_t *want[2] = {&pa, &pb};
    int64_t prev_t = 0;
    for (int i = 0; i < 2; i++) {
        ps_camera_frame_t fr;
        assert_int_equal(port.ops->next(port.ctx, &fr, PS_NS_PER_S), 0);
        assert_int_equal(fr.seq, (uint64_t)i);
        assert_int_equal(fr.format, PS_PIX_R8);
        assert_true(fr.t_ns >= prev_t && fr.t_mono_ns > 0);
        prev_t = fr.t_ns;
        ps_tags_det_t det[2];
        assert_int_equal(ps_tags_detect(tags, fr.data, fr.width, fr.height, fr.stride, det, 2), 1);
        assert_int_equal(det[0].id, want[i]->id);
        const double dx = det[0].pos_cam_m[0] - want[i]->pos_cam_m[0];
        const double dy = det[0].pos_cam_m[1] - want[i]->pos_cam_m[1];
        const double dz = det[0].pos_cam_m[2] - want[i]->pos_cam_m[2];
        assert_true(sqrt(dx * dx + dy * dy + dz * dz) < 0.01 + 0.01 * want[i]->pos_cam_m[2]);
        port.ops->release(port.ctx, &fr);
    }
    ps_camera_frame_t fr;
    assert_int_equal(port.ops->next(port.ctx, &fr, PS_NS_PER_S), -ENODATA); /* played once */
    port.ops->stop(port.ctx);
    port.ops->stop(port.ctx); /* twice is fine */
    ps_tags_destroy(tags);
}

static void test_ps_camera_files_looping_starts_over(void **state)
{
    folder_t *f = *state;
    memset(f->img, 7, sizeof(f->img));
    write_png(f, "one.png", f->img, W, H);
    const ps_camera_cfg_t cfg = folder_cfg(f);
    ps_camera_files_t src;
    ps_camera_files_init(&src, &cfg, NULL, true);
    ps_camera_port_t port = ps_camera_files_port(&src);
    assert_int_equal(port.ops->start(port.ctx, NULL, 0), 0);
    for (uint64_t i = 0; i < 3; i++) {
        ps_camera_frame_t fr;
        assert_int_equal(port.ops->next(port.ctx, &fr, PS_NS_PER_S), 0);
        assert_int_equal(fr.seq, i);
        assert_int_equal(fr.data[0], 7);
    }
    port.ops->stop(port.ctx);
}

static void test_ps_camera_files_next_before_due_etimedout(void **state)
{
    folder_t *f = *state;
    memset(f->img, 7, sizeof(f->img));
    write_png(f, "one.png", f->img, W, H);
    ps_camera_cfg_t cfg = folder_cfg(f);
    cfg.fps = 0.5f; /* a frame every 2 s */
    ps_camera_files_t src;
    ps_camera_files_init(&src, &cfg, NULL, true);
    ps_camera_port_t port = ps_camera_files_port(&src);
    assert_int_equal(port.ops->start(port.ctx, NULL, 0), 0);
    ps_camera_frame_t fr;
    assert_int_equal(port.ops->next(port.ctx, &fr, 0), 0); /* the first is due at start */
    assert_int_equal(port.ops->next(port.ctx, &fr, PS_NS_PER_MS), -ETIMEDOUT);
    port.ops->stop(port.ctx);
}

static void test_ps_camera_files_errors_name_the_problem(void **state)
{
    folder_t *f = *state;
    ps_camera_cfg_t cfg = folder_cfg(f);
    ps_camera_files_t src;
    char err[512];
    /* empty folder */
    ps_camera_files_init(&src, &cfg, NULL, false);
    ps_camera_port_t port = ps_camera_files_port(&src);
    assert_int_equal(port.ops->start(port.ctx, err, sizeof(err)), -ENOENT);
    assert_non_null(strstr(err, "no .png"));
    /* no folder */
    snprintf(cfg.dir, sizeof(cfg.dir), "%s/missing", f->dir);
    ps_camera_files_init(&src, &cfg, NULL, false);
    assert_int_equal(port.ops->start(port.ctx, err, sizeof(err)), -ENOENT);
    assert_non_null(strstr(err, "missing"));
    /* the wrong size */
    cfg = folder_cfg(f);
    memset(f->img, 9, sizeof(f->img));
    write_png(f, "small.png", f->img, W / 2, H / 2);
    ps_camera_files_init(&src, &cfg, NULL, false);
    assert_int_equal(port.ops->start(port.ctx, err, sizeof(err)), -PS_ERR_CONFIG);
    assert_non_null(strstr(err, "small.png: 160x120, the board's camera is 320x240"));
    /* not a PNG */
    char path[128];
    snprintf(path, sizeof(path), "%s/small.png", f->dir);
    FILE *t = fopen(path, "w");
    assert_non_null(t);
    fputs("GIF89a", t);
    fclose(t);
    assert_int_equal(port.ops->start(port.ctx, err, sizeof(err)), -PS_ERR_CONFIG);
    assert_non_null(strstr(err, "small.png: not a PNG"));
    ps_camera_frame_t fr;
    assert_int_equal(port.ops->next(port.ctx, &fr, 0), -ENODATA); /* nothing loaded */
    port.ops->stop(port.ctx);
}

/* The libcamera module is loaded on first use; one that is not there is a
 * clear error, not a crash (this process never loads it). */
static void test_ps_camera_libcamera_module_missing_enoent_says_where(void **state)
{
    (void)state;
    assert_int_equal(setenv("PUSHSTEP_LIBCAMERA_SO", "/nonexistent/libpushstep-libcamera.so", 1),
                     0);
    const ps_camera_cfg_t cfg = {.source = PS_CAMERA_SRC_LIBCAMERA, .width = W, .height = H,
                                 .format = PS_PIX_R8, .fps = 10};
    ps_camera_libcamera_t *c = NULL;
    char err[PS_ERR_MSG_LEN] = "";
    assert_int_equal(ps_camera_libcamera_create(&cfg, &c, err, sizeof(err)), -ENOENT);
    assert_null(c);
    assert_non_null(strstr(err, "/nonexistent/libpushstep-libcamera.so"));
    assert_int_equal(ps_camera_libcamera_create(&cfg, &c, err, sizeof(err)), -ENOENT); /* again */
    assert_int_equal(ps_camera_libcamera_create(NULL, &c, err, sizeof(err)), -EINVAL);
    ps_camera_libcamera_destroy(NULL);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ps_camera_format_names_round_trip),
        cmocka_unit_test(test_ps_camera_to_grey_each_format_luma),
        cmocka_unit_test(test_ps_camera_to_grey_short_buffers_einval),
        cmocka_unit_test(test_ps_camera_libcamera_module_missing_enoent_says_where),
        cmocka_unit_test_setup_teardown(test_ps_camera_files_stored_tags_detected_in_name_order,
                                        setup_folder, teardown_folder),
        cmocka_unit_test_setup_teardown(test_ps_camera_files_looping_starts_over, setup_folder,
                                        teardown_folder),
        cmocka_unit_test_setup_teardown(test_ps_camera_files_next_before_due_etimedout,
                                        setup_folder, teardown_folder),
        cmocka_unit_test_setup_teardown(test_ps_camera_files_errors_name_the_problem,
                                        setup_folder, teardown_folder),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
