/*
 * Tests of ps_tags (AprilTag shoulders): detection on synthesised images of
 * tags at known poses (tests/fakes/ps_camera_fake.c casts each pixel's rays
 * onto the tag plane, 3 x 3 rays a pixel, with +-6 grey levels of noise), the
 * camera-to-robot transform on cases worked by hand, the neighbour list's
 * ids and sides, confidence and the margin filter, and argument errors.
 *
 * Tolerance: a tag centre within 1 cm + 1 % of its distance of the truth
 * (a 0.12 m tag, 640 x 480, f = 520 px, 0.6 to 2.5 m, turned up to 50
 * degrees). The largest error measured is printed.
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

#include "../drivers/ps_tags.h"
#include "fakes/ps_camera_fake.h"

#define W 640u
#define H 480u

static const ps_camera_intrinsics_t K = {520.0f, 520.0f, 320.0f, 240.0f};

typedef struct {
    ps_tags_t *tags;
    ps_tags_cfg_t cfg;
    uint8_t *img;
} fixture_t;

static ps_tags_cfg_t default_cfg(void)
{
    return (ps_tags_cfg_t){
        .k = K,
        .tag_size_m = 0.12f,
        .n_threads = 1,
        .decimate = 1.0f,
        .min_margin = 20.0f,
    };
}

static int setup(void **state)
{
    fixture_t *f = calloc(1, sizeof(*f));
    if (f == NULL)
        return -1;
    f->cfg = default_cfg();
    f->img = malloc(W * H);
    if (f->img == NULL || ps_tags_create(&f->cfg, &f->tags, NULL, 0) != 0)
        return -1;
    *state = f;
    return 0;
}

static int teardown(void **state)
{
    fixture_t *f = *state;
    ps_tags_destroy(f->tags);
    free(f->img);
    free(f);
    return 0;
}

static ps_tag_pose_t pose(int id, double x, double y, double z, double yaw_deg, double pitch_deg)
{
    ps_tag_pose_t p = {.id = id, .size_m = 0.12, .pos_cam_m = {x, y, z}};
    ps_tag_pose_turned(&p, yaw_deg * M_PI / 180.0, pitch_deg * M_PI / 180.0);
    return p;
}

static double dist3(const float a[3], const double b[3])
{
    const double dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
    return sqrt(dx * dx + dy * dy + dz * dz);
}

static void test_ps_tags_detect_known_poses_within_tolerance(void **state)
{
    fixture_t *f = *state;
    const ps_tag_pose_t cases[] = {
        pose(0, 0.0, 0.0, 1.0, 0, 0),      pose(1, 0.25, -0.15, 1.5, 30, 0),
        pose(2, -0.4, 0.2, 2.0, -20, 15),  pose(3, 0.1, 0.1, 0.6, 45, -10),
        pose(4, -0.6, -0.3, 2.5, 10, 20),  pose(5, 0.5, 0.25, 1.2, -50, 0),
        pose(6, 0.0, -0.35, 1.8, 0, 35),   pose(7, -0.2, 0.05, 0.9, 25, 25),
        pose(40, 0.3, 0.0, 2.2, -35, -15),
    };
    double worst = 0, worst_rel = 0;
    for (size_t c = 0; c < sizeof(cases) / sizeof(cases[0]); c++) {
        assert_int_equal(ps_tag_image_render(f->img, W, H, &K, &cases[c], 1, 128, 6, (uint32_t)c),
                         0);
        ps_tags_det_t det[4];
        const int n = ps_tags_detect(f->tags, f->img, W, H, W, det, 4);
        if (n != 1)
            fail_msg("case %zu (id %d): %d detections", c, cases[c].id, n);
        assert_int_equal(det[0].id, cases[c].id);
        const double err = dist3(det[0].pos_cam_m, cases[c].pos_cam_m);
        const double tol = 0.01 + 0.01 * cases[c].pos_cam_m[2];
        if (err > tol)
            fail_msg("case %zu: error %.4f m > %.4f m (at %.2f m)", c, err, tol,
                     cases[c].pos_cam_m[2]);
        worst = err > worst ? err : worst;
        worst_rel = err / cases[c].pos_cam_m[2] > worst_rel ? err / cases[c].pos_cam_m[2] : worst_rel;
        assert_true(det[0].confidence > 0.5f);
        assert_int_equal(det[0].hamming, 0);
    }
    printf("    largest position error %.1f mm (%.2f %% of the distance)\n", worst * 1e3,
           worst_rel * 100.0);
}

static void test_ps_tags_detect_several_tags_sorted_with_sides(void **state)
{
    fixture_t *f = *state;
    const ps_tag_pose_t tags[] = {
        pose(7, 0.35, 0.0, 1.4, 0, 0),
        pose(0, -0.45, 0.05, 1.6, 10, 0),
        pose(6, 0.15, 0.0, 1.4, 0, 0),
        pose(1, -0.2, 0.05, 1.6, 10, 0),
    };
    assert_int_equal(ps_tag_image_render(f->img, W, H, &K, tags, 4, 110, 6, 99), 0);
    ps_tags_det_t det[8];
    const int n = ps_tags_detect(f->tags, f->img, W, H, W, det, 8);
    assert_int_equal(n, 4);
    const int ids[] = {0, 1, 6, 7};
    for (int i = 0; i < 4; i++)
        assert_int_equal(det[i].id, ids[i]);
    ps_neighbours_t nb;
    memset(&nb, 0xff, sizeof(nb));
    assert_int_equal(ps_tags_to_neighbours(det, (uint32_t)n, 123, 9, &nb), 0);
    assert_int_equal(nb.n_shoulders, 4);
    assert_int_equal(nb.t_exposure_ns, 123);
    assert_int_equal(nb.frame_seq, 9);
    assert_false(nb.is_valid);
    assert_int_equal(nb.age_ns, 0);
    assert_int_equal(nb.shoulders[0].neighbour_id, 0);
    assert_int_equal(nb.shoulders[0].side, PS_SHOULDER_LEFT);
    assert_int_equal(nb.shoulders[1].neighbour_id, 0);
    assert_int_equal(nb.shoulders[1].side, PS_SHOULDER_RIGHT);
    assert_int_equal(nb.shoulders[2].neighbour_id, 3);
    assert_int_equal(nb.shoulders[2].side, PS_SHOULDER_LEFT);
    assert_int_equal(nb.shoulders[3].neighbour_id, 3);
    assert_int_equal(nb.shoulders[3].side, PS_SHOULDER_RIGHT);
    /* With the camera at the robot's origin looking ahead, the robot frame
     * is (z, -x, -y) of the camera's. */
    assert_float_equal(nb.shoulders[3].pos_robot_m[0], det[3].pos_cam_m[2], 1e-6);
    assert_float_equal(nb.shoulders[3].pos_robot_m[1], -det[3].pos_cam_m[0], 1e-6);
    assert_float_equal(nb.shoulders[3].pos_robot_m[2], -det[3].pos_cam_m[1], 1e-6);
}

static void test_ps_tags_cam_to_robot_hand_worked_poses(void **state)
{
    (void)state;
    ps_tags_cfg_t c = default_cfg();
    c.cam_pos_m[0] = 0.1f;
    c.cam_pos_m[1] = -0.05f;
    c.cam_pos_m[2] = 0.5f;
    const double ahead[3] = {0.0, 0.0, 2.0}, right_down[3] = {0.3, 0.2, 1.0};
    double r[3];
    /* level, looking ahead: 2 m ahead; 0.3 right and 0.2 down of a 1 m point */
    ps_tags_cam_to_robot(&c, ahead, r);
    assert_float_equal(r[0], 2.1, 1e-6);
    assert_float_equal(r[1], -0.05, 1e-6);
    assert_float_equal(r[2], 0.5, 1e-6);
    ps_tags_cam_to_robot(&c, right_down, r);
    assert_float_equal(r[0], 1.1, 1e-6);
    assert_float_equal(r[1], -0.35, 1e-6);
    assert_float_equal(r[2], 0.3, 1e-6);
    /* pitched 90 degrees down: the optical axis points at -z */
    c.cam_rpy_rad[1] = (float)(M_PI / 2);
    ps_tags_cam_to_robot(&c, ahead, r);
    assert_float_equal(r[0], 0.1, 1e-6);
    assert_float_equal(r[1], -0.05, 1e-6);
    assert_float_equal(r[2], -1.5, 1e-6);
    /* yawed 90 degrees left: the optical axis points at +y, image right at +x */
    c.cam_rpy_rad[1] = 0.0f;
    c.cam_rpy_rad[2] = (float)(M_PI / 2);
    ps_tags_cam_to_robot(&c, right_down, r);
    assert_float_equal(r[0], 0.1 + 0.3, 1e-6);
    assert_float_equal(r[1], -0.05 + 1.0, 1e-6);
    assert_float_equal(r[2], 0.5 - 0.2, 1e-6);
    /* rolled 90 degrees (about the optical axis, right side down): image
     * right is world down, image down is world left... of the body frame */
    c.cam_rpy_rad[2] = 0.0f;
    c.cam_rpy_rad[0] = (float)(M_PI / 2);
    ps_tags_cam_to_robot(&c, right_down, r);
    assert_float_equal(r[0], 0.1 + 1.0, 1e-6);
    assert_float_equal(r[1], -0.05 + 0.2, 1e-6);
    assert_float_equal(r[2], 0.5 - 0.3, 1e-6);
}

static void test_ps_tags_detect_low_contrast_lower_confidence_and_filtered(void **state)
{
    fixture_t *f = *state;
    const ps_tag_pose_t p = pose(2, 0.0, 0.0, 1.2, 0, 0);
    assert_int_equal(ps_tag_image_render(f->img, W, H, &K, &p, 1, 128, 3, 5), 0);
    ps_tags_det_t sharp, faint;
    assert_int_equal(ps_tags_detect(f->tags, f->img, W, H, W, &sharp, 1), 1);
    /* the same picture squeezed into 24 grey levels around mid grey */
    for (size_t i = 0; i < W * H; i++)
        f->img[i] = (uint8_t)(116 + f->img[i] * 24 / 255);
    assert_int_equal(ps_tags_detect(f->tags, f->img, W, H, W, &faint, 1), 1);
    assert_true(faint.margin < sharp.margin);
    assert_true(faint.confidence < sharp.confidence);
    /* a detector that wants more margin than the faint tag has drops it */
    ps_tags_cfg_t c = f->cfg;
    c.min_margin = faint.margin + 1.0f;
    ps_tags_t *strict = NULL;
    assert_int_equal(ps_tags_create(&c, &strict, NULL, 0), 0);
    assert_int_equal(ps_tags_detect(strict, f->img, W, H, W, &faint, 1), 0);
    ps_tags_destroy(strict);
}

static void test_ps_tags_detect_no_tag_zero(void **state)
{
    fixture_t *f = *state;
    assert_int_equal(ps_tag_image_render(f->img, W, H, &K, NULL, 0, 128, 6, 1), 0);
    ps_tags_det_t det[4];
    assert_int_equal(ps_tags_detect(f->tags, f->img, W, H, W, det, 4), 0);
}

static void test_ps_tags_bad_args_einval(void **state)
{
    fixture_t *f = *state;
    ps_tags_t *t = NULL;
    ps_tags_cfg_t c = default_cfg();
    char err[200] = "";
    c.k.fx_px = 0;
    assert_int_equal(ps_tags_create(&c, &t, err, sizeof(err)), -EINVAL);
    assert_non_null(strstr(err, "focal"));
    c = default_cfg();
    c.n_threads = 0;
    assert_int_equal(ps_tags_create(&c, &t, NULL, 0), -EINVAL);
    c = default_cfg();
    c.decimate = 0.5f;
    assert_int_equal(ps_tags_create(&c, &t, NULL, 0), -EINVAL);
    assert_null(t);
    ps_tags_det_t det[1];
    assert_int_equal(ps_tags_detect(f->tags, NULL, W, H, W, det, 1), -EINVAL);
    assert_int_equal(ps_tags_detect(f->tags, f->img, W, H, W - 1, det, 1), -EINVAL);
    assert_int_equal(ps_tags_detect(NULL, f->img, W, H, W, det, 1), -EINVAL);
    ps_tags_destroy(NULL);
}

static void test_ps_tags_to_neighbours_more_than_fit_left_out(void **state)
{
    (void)state;
    ps_tags_det_t det[PS_MAX_SHOULDERS + 8];
    memset(det, 0, sizeof(det));
    for (uint32_t i = 0; i < PS_MAX_SHOULDERS + 8; i++)
        det[i].id = (int)i;
    det[0].id = -1; /* never from libapriltag, but not a shoulder */
    ps_neighbours_t nb;
    /* 39 shoulders: 32 fit, 7 left out, and the id -1 */
    assert_int_equal(ps_tags_to_neighbours(det, PS_MAX_SHOULDERS + 8, 1, 1, &nb), 8);
    assert_int_equal(nb.n_shoulders, PS_MAX_SHOULDERS);
    assert_int_equal(nb.shoulders[0].neighbour_id, 0);
    assert_int_equal(nb.shoulders[0].side, 1);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_ps_tags_detect_known_poses_within_tolerance, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_ps_tags_detect_several_tags_sorted_with_sides, setup,
                                        teardown),
        cmocka_unit_test(test_ps_tags_cam_to_robot_hand_worked_poses),
        cmocka_unit_test_setup_teardown(
            test_ps_tags_detect_low_contrast_lower_confidence_and_filtered, setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_tags_detect_no_tag_zero, setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_tags_bad_args_einval, setup, teardown),
        cmocka_unit_test(test_ps_tags_to_neighbours_more_than_fit_left_out),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
