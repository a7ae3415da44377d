/*
 * Tests of ps_perception: the thread over a fake camera (frames of tags at
 * known poses) publishes one neighbour list per frame with the frame's
 * exposure time, releases every buffer, keeps the snapshot and the figures;
 * a camera that fails to start fails ps_perception_start with its message;
 * a source that ends is reported; and the loop's side, ps_perception_take:
 * ageing, the fallback to "no neighbour information" when the list is stale
 * or never came, and the return to valid with the next fresh list.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../rt/ps_err.h"
#include "../rt/ps_clock.h"
#include "../rt/ps_perception.h"
#include "fakes/ps_camera_fake.h"

#define W 320u
#define H 240u

static const ps_camera_intrinsics_t K = {300.0f, 300.0f, 160.0f, 120.0f};

typedef struct {
    ps_camera_fake_t cam;
    uint8_t img[2][W * H];
    ps_perception_t p;
    ps_perception_cfg_t cfg;
} fixture_t;

static int setup(void **state)
{
    fixture_t *f = calloc(1, sizeof(*f));
    if (f == NULL)
        return -1;
    /* frame 0: both shoulders of neighbour 2; frame 1: none */
    ps_tag_pose_t tags[2] = {
        {.id = 4, .size_m = 0.1, .pos_cam_m = {-0.12, 0.0, 1.0}},
        {.id = 5, .size_m = 0.1, .pos_cam_m = {0.12, 0.0, 1.0}},
    };
    ps_tag_pose_turned(&tags[0], 0, 0);
    ps_tag_pose_turned(&tags[1], 0, 0);
    if (ps_tag_image_render(f->img[0], W, H, &K, tags, 2, 128, 4, 1) != 0 ||
        ps_tag_image_render(f->img[1], W, H, &K, NULL, 0, 128, 4, 2) != 0)
        return -1;
    for (int i = 0; i < 2; i++)
        f->cam.frames[i] = (ps_camera_frame_t){.data = f->img[i], .n_bytes = W * H, .width = W,
                                               .height = H, .stride = W, .format = PS_PIX_R8,
                                               .t_ns = 1000 + i, .t_mono_ns = 1};
    f->cam.n_frames = 2;
    f->cfg = (ps_perception_cfg_t){
        .camera = {.source = PS_CAMERA_SRC_FILES, .width = W, .height = H, .fps = 30},
        .tags = {.k = K, .tag_size_m = 0.1f, .n_threads = 1, .decimate = 1.0f, .min_margin = 20},
        .max_age_s = 0.2f,
    };
    *state = f;
    return 0;
}

static int teardown(void **state)
{
    fixture_t *f = *state;
    ps_perception_deinit(&f->p);
    ps_perception_deinit(&f->p); /* twice is safe */
    free(f);
    return 0;
}

static void wait_for(ps_perception_t *p, bool (*done)(ps_perception_t *))
{
    for (int i = 0; i < 2000 && !done(p); i++) {
        const struct timespec ts = {0, 5000000};
        nanosleep(&ts, NULL);
    }
}

static void test_ps_perception_thread_publishes_each_frame_in_order(void **state)
{
    fixture_t *f = *state;
    char err[PS_ERR_MSG_LEN] = "";
    assert_int_equal(ps_perception_init(&f->p, &f->cfg, ps_camera_fake_port(&f->cam), true, err,
                                        sizeof(err)),
                     0);
    ps_mailbox_t *mb = ps_perception_mailbox(&f->p);
    assert_int_equal(ps_perception_start(&f->p, -1, err, sizeof(err)), 0);
    wait_for(&f->p, ps_perception_has_ended);
    assert_true(ps_perception_has_ended(&f->p)); /* the fake's two frames, once */
    ps_perception_stop(&f->p);
    assert_int_equal(f->cam.n_started, 1);
    assert_int_equal(f->cam.n_stopped, 1);
    assert_int_equal(f->cam.n_released, 2);
    assert_int_equal(f->cam.n_outstanding_max, 1); /* one buffer held at a time */
    ps_perception_stats_t st;
    ps_perception_get_stats(&f->p, &st);
    assert_int_equal(st.n_frames, 2);
    assert_int_equal(st.n_published, 2);
    assert_int_equal(st.n_tags, 2);
    assert_int_equal(st.n_errors, 0);
    assert_int_equal(st.latency.n, 2);
    assert_int_equal(ps_mailbox_n_published(mb), 2);
    /* the newest list: frame 1, empty */
    ps_neighbours_t nb;
    memset(&nb, 0, sizeof(nb));
    assert_true(ps_perception_take(mb, 1001, PS_NS_PER_S, &nb));
    assert_int_equal(nb.frame_seq, 1);
    assert_int_equal(nb.t_exposure_ns, 1001);
    assert_true(nb.is_valid);
    assert_int_equal(nb.n_shoulders, 0);
    /* the snapshot is the newest frame too */
    static uint8_t grey[W * H];
    ps_tags_det_t det[4];
    uint64_t seq = 99;
    assert_int_equal(ps_perception_snapshot(&f->p, grey, sizeof(grey), det, 4, &seq), 0);
    assert_int_equal(seq, 1);
    assert_memory_equal(grey, f->img[1], sizeof(grey));
}

static void test_ps_perception_take_first_frame_both_shoulders(void **state)
{
    fixture_t *f = *state;
    f->cam.n_frames = 1; /* only the frame with the tags */
    assert_int_equal(
        ps_perception_init(&f->p, &f->cfg, ps_camera_fake_port(&f->cam), true, NULL, 0), 0);
    assert_int_equal(ps_perception_start(&f->p, -1, NULL, 0), 0);
    wait_for(&f->p, ps_perception_has_ended);
    ps_perception_stop(&f->p);
    ps_neighbours_t nb;
    memset(&nb, 0, sizeof(nb));
    assert_true(ps_perception_take(ps_perception_mailbox(&f->p), 1000, 1000, &nb));
    assert_true(nb.is_valid);
    assert_int_equal(nb.n_shoulders, 2);
    assert_int_equal(nb.shoulders[0].neighbour_id, 2);
    assert_int_equal(nb.shoulders[0].side, PS_SHOULDER_LEFT);
    assert_int_equal(nb.shoulders[1].side, PS_SHOULDER_RIGHT);
    /* camera at the robot's origin, level: 1 m ahead, left shoulder at +y */
    assert_float_equal(nb.shoulders[0].pos_robot_m[0], 1.0, 0.02);
    assert_float_equal(nb.shoulders[0].pos_robot_m[1], 0.12, 0.02);
    assert_float_equal(nb.shoulders[1].pos_robot_m[1], -0.12, 0.02);
    static uint8_t grey[W * H];
    ps_tags_det_t det[4];
    assert_int_equal(ps_perception_snapshot(&f->p, grey, sizeof(grey), det, 4, NULL), 2);
    assert_int_equal(det[0].id, 4);
    assert_int_equal(ps_perception_snapshot(&f->p, grey, 10, det, 4, NULL), -EINVAL);
}

static void test_ps_perception_start_camera_fails_message(void **state)
{
    fixture_t *f = *state;
    f->cam.start_rc = -ENODEV;
    assert_int_equal(
        ps_perception_init(&f->p, &f->cfg, ps_camera_fake_port(&f->cam), false, NULL, 0), 0);
    char err[PS_ERR_MSG_LEN] = "";
    assert_int_equal(ps_perception_start(&f->p, -1, err, sizeof(err)), -ENODEV);
    assert_non_null(strstr(err, "fake camera: start failed"));
    assert_int_equal(f->cam.n_stopped, 1);
    static uint8_t grey[W * H];
    assert_int_equal(ps_perception_snapshot(&f->p, grey, sizeof(grey), NULL, 0, NULL), -EINVAL);
}

static void test_ps_perception_frame_of_wrong_size_counted_error(void **state)
{
    fixture_t *f = *state;
    f->cam.frames[0].width = W / 2;
    f->cam.n_frames = 1;
    assert_int_equal(
        ps_perception_init(&f->p, &f->cfg, ps_camera_fake_port(&f->cam), false, NULL, 0), 0);
    assert_int_equal(ps_perception_start(&f->p, -1, NULL, 0), 0);
    wait_for(&f->p, ps_perception_has_ended);
    ps_perception_stop(&f->p);
    ps_perception_stats_t st;
    ps_perception_get_stats(&f->p, &st);
    assert_int_equal(st.n_errors, 1);
    assert_int_equal(st.n_published, 0);
    assert_int_equal(f->cam.n_released, 1);
}

static void test_ps_perception_init_bad_size_einval(void **state)
{
    fixture_t *f = *state;
    f->cfg.camera.width = 0;
    char err[200] = "";
    assert_int_equal(
        ps_perception_init(&f->p, &f->cfg, ps_camera_fake_port(&f->cam), false, err, sizeof(err)),
        -EINVAL);
    assert_non_null(strstr(err, "image size"));
    assert_int_equal(ps_perception_init(&f->p, &f->cfg, (ps_camera_port_t){0}, false, NULL, 0),
                     -EINVAL);
}

/* ---- the loop's side: ageing and the stale fallback ------------------------ */

static void publish(ps_mailbox_t *mb, int64_t t_exposure_ns, uint32_t n_shoulders)
{
    ps_neighbours_t *s = ps_mailbox_write_slot(mb);
    memset(s, 0, sizeof(*s));
    s->t_exposure_ns = t_exposure_ns;
    s->n_shoulders = n_shoulders;
    s->frame_seq = (uint64_t)t_exposure_ns;
    ps_mailbox_publish(mb);
}

static void test_ps_perception_take_stale_falls_back_then_recovers(void **state)
{
    (void)state;
    ps_mailbox_t mb;
    ps_neighbours_t slots[PS_MAILBOX_SLOTS];
    assert_int_equal(ps_mailbox_init(&mb, slots, sizeof(slots[0])), 0);
    const int64_t max_age = 200 * PS_NS_PER_MS;
    ps_neighbours_t nb;
    memset(&nb, 0, sizeof(nb));
    /* nothing ever published: no information */
    assert_false(ps_perception_take(&mb, 5 * PS_NS_PER_S, max_age, &nb));
    assert_false(nb.is_valid);
    assert_int_equal(nb.n_shoulders, 0);
    /* a list exposed at 5 s with 3 shoulders */
    publish(&mb, 5 * PS_NS_PER_S, 3);
    assert_true(ps_perception_take(&mb, 5 * PS_NS_PER_S + 50 * PS_NS_PER_MS, max_age, &nb));
    assert_true(nb.is_valid);
    assert_int_equal(nb.n_shoulders, 3);
    assert_int_equal(nb.age_ns, 50 * PS_NS_PER_MS);
    /* exactly max_age old: still valid; one ns more: no information */
    assert_false(ps_perception_take(&mb, 5 * PS_NS_PER_S + max_age, max_age, &nb));
    assert_true(nb.is_valid);
    assert_int_equal(nb.n_shoulders, 3);
    assert_false(ps_perception_take(&mb, 5 * PS_NS_PER_S + max_age + 1, max_age, &nb));
    assert_false(nb.is_valid);
    assert_int_equal(nb.n_shoulders, 0);
    assert_int_equal(nb.age_ns, max_age + 1);
    assert_int_equal(nb.t_exposure_ns, 5 * PS_NS_PER_S); /* what it was, for the record */
    /* stays so without a new list */
    assert_false(ps_perception_take(&mb, 6 * PS_NS_PER_S, max_age, &nb));
    assert_false(nb.is_valid);
    /* a list that is already too old when it arrives is no information either */
    publish(&mb, 6 * PS_NS_PER_S, 2);
    assert_true(ps_perception_take(&mb, 7 * PS_NS_PER_S, max_age, &nb));
    assert_false(nb.is_valid);
    assert_int_equal(nb.n_shoulders, 0);
    /* a fresh one: valid again, with its shoulders */
    publish(&mb, 7 * PS_NS_PER_S, 4);
    assert_true(ps_perception_take(&mb, 7 * PS_NS_PER_S + 10 * PS_NS_PER_MS, max_age, &nb));
    assert_true(nb.is_valid);
    assert_int_equal(nb.n_shoulders, 4);
    /* stamped ahead of the loop's clock: age 0 */
    publish(&mb, 7 * PS_NS_PER_S + max_age, 1);
    assert_true(ps_perception_take(&mb, 7 * PS_NS_PER_S, max_age, &nb));
    assert_true(nb.is_valid);
    assert_int_equal(nb.age_ns, 0);
    /* further ahead than a list may be old (it would never age): refused */
    publish(&mb, 8 * PS_NS_PER_S, 1);
    assert_true(ps_perception_take(&mb, 7 * PS_NS_PER_S, max_age, &nb));
    assert_false(nb.is_valid);
    assert_int_equal(nb.n_shoulders, 0);
    assert_int_equal(nb.t_exposure_ns, 0);
    assert_false(ps_perception_take(&mb, 7 * PS_NS_PER_S + 1, max_age, &nb));
    assert_false(nb.is_valid); /* until a sane list comes */
}

/* Lists no perception thread makes are refused like a stale one: more
 * shoulders than a list holds, a NaN position, a confidence outside 0..1,
 * a side that is neither; the next sane list is taken. */
static void test_ps_perception_take_insane_list_refused(void **state)
{
    (void)state;
    ps_mailbox_t mb;
    ps_neighbours_t slots[PS_MAILBOX_SLOTS];
    assert_int_equal(ps_mailbox_init(&mb, slots, sizeof(slots[0])), 0);
    const int64_t t = 5 * PS_NS_PER_S, max_age = 200 * PS_NS_PER_MS;
    ps_neighbours_t nb;
    memset(&nb, 0, sizeof(nb));
    for (int bad = 0; bad < 4; bad++) {
        ps_neighbours_t *last = ps_mailbox_write_slot(&mb);
        memset(last, 0, sizeof(*last));
        last->t_exposure_ns = t;
        last->n_shoulders = 2;
        if (bad == 0)
            last->n_shoulders = PS_MAX_SHOULDERS + 1;
        else if (bad == 1)
            last->shoulders[1].pos_robot_m[2] = NAN;
        else if (bad == 2)
            last->shoulders[0].confidence = 1.5f;
        else
            last->shoulders[0].side = 2;
        ps_mailbox_publish(&mb);
        assert_true(ps_perception_take(&mb, t, max_age, &nb));
        assert_false(nb.is_valid);
        assert_int_equal(nb.n_shoulders, 0);
        assert_int_equal(nb.t_exposure_ns, 0);
    }
    publish(&mb, t, 2);
    assert_true(ps_perception_take(&mb, t, max_age, &nb));
    assert_true(nb.is_valid);
    assert_int_equal(nb.n_shoulders, 2);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_ps_perception_thread_publishes_each_frame_in_order,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_perception_take_first_frame_both_shoulders, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_ps_perception_start_camera_fails_message, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_ps_perception_frame_of_wrong_size_counted_error,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_perception_init_bad_size_einval, setup, teardown),
        cmocka_unit_test(test_ps_perception_take_stale_falls_back_then_recovers),
        cmocka_unit_test(test_ps_perception_take_insane_list_refused),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
