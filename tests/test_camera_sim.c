/*
 * Tests of the simulated camera (sim/ps_camera_sim): the MuJoCo scene of
 * tests/data/models/ps1-tags.xml (the robot and three people wearing tags on
 * their shoulders) rendered offscreen with EGL from the robot's head
 * (tests/data/boards/sim-camera.yaml), run through the AprilTag detector,
 * and compared with the plant's ground truth: every tag that faces the
 * camera whole inside the picture (unoccluded: MuJoCo's rays), at least
 * 24 px across and within 60 degrees of facing it, is found; nothing else is
 * (a tag seen whole but smaller or more slanted may or may not be); and each
 * detected
 * shoulder lies within 2 cm + 2 % of its distance of the true one, in the
 * robot frame. Then the same with the robot in motion: the scene of a
 * lockstep run after the harness let go, truth and picture from the same
 * published state. The largest error is printed.
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
#include "../rt/ps_app.h"
#include "../rt/ps_config.h"
#include "../rt/ps_config_sim.h"
#include "../rt/ps_err.h"
#include "../sim/ps_camera_sim.h"

#define BOARD "tests/data/boards/sim-camera.yaml"
#define ROBOT "tests/data/robots/ps1-tags.yaml"
#define MODEL "tests/data/models/ps1-tags.xml"

/* A tag seen whole must be detected when its black square spans at least
 * this many pixels and faces the camera within this angle. */
#define MIN_SIZE_PX   24.0
#define MAX_SLANT_RAD 1.05 /* 60 degrees */

typedef struct {
    ps_board_cfg_t board;
    ps_robot_cfg_t robot;
    ps_sim_devices_cfg_t devices;
    ps_scenario_cfg_t scenario;
    ps_sim_board_t sim_board;
    ps_sim_robot_t sim_robot;
    ps_sim_t *sim;
    ps_camera_sim_t *cam;
    ps_camera_port_t port;
    ps_tags_t *tags;
    bool is_started;
} fixture_t;

static int setup(void **state)
{
    fixture_t *f = calloc(1, sizeof(*f));
    char err[PS_ERR_MSG_LEN];
    if (f == NULL || ps_config_load_board(BOARD, &f->board, err, sizeof(err)) != 0 ||
        ps_config_load_robot_sim(ROBOT, &f->robot, &f->devices, err, sizeof(err)) != 0 ||
        ps_config_load_scenario("scenarios/stand.yaml", &f->scenario, err, sizeof(err)) != 0)
        fail_msg("config: %s", err);
    ps_app_sim_board(&f->board, &f->sim_board);
    ps_app_sim_robot(&f->robot, &f->devices, &f->sim_robot);
    const ps_sim_cfg_t sc = {
        .board = &f->sim_board,
        .robot = &f->sim_robot,
        .scenario = &f->scenario,
        .model_path = MODEL,
        .is_lockstep = true,
        .period_ns = PS_NS_PER_S / f->robot.control.servo_hz,
    };
    if (ps_sim_create(&sc, &f->sim, err, sizeof(err)) != 0)
        fail_msg("sim: %s", err);
    const ps_perception_cfg_t *pc = &f->board.perception;
    const ps_camera_sim_cfg_t cc = {
        .sim = f->sim,
        .camera = pc->camera,
        .k = pc->tags.k,
        .cam_pos_m = {pc->tags.cam_pos_m[0], pc->tags.cam_pos_m[1], pc->tags.cam_pos_m[2]},
        .cam_rpy_rad = {pc->tags.cam_rpy_rad[0], pc->tags.cam_rpy_rad[1], pc->tags.cam_rpy_rad[2]},
        .root_body = "pelvis",
    };
    if (ps_camera_sim_create(&cc, &f->cam, err, sizeof(err)) != 0)
        fail_msg("camera: %s", err);
    f->port = ps_camera_sim_port(f->cam);
    if (f->port.ops->start(f->port.ctx, err, sizeof(err)) != 0)
        fail_msg("camera start: %s", err);
    f->is_started = true;
    if (ps_tags_create(&pc->tags, &f->tags, err, sizeof(err)) != 0)
        fail_msg("tags: %s", err);
    *state = f;
    return 0;
}

static int teardown(void **state)
{
    fixture_t *f = *state;
    if (f->is_started)
        f->port.ops->stop(f->port.ctx);
    ps_tags_destroy(f->tags);
    ps_camera_sim_destroy(f->cam);
    ps_sim_destroy(f->sim);
    free(f);
    return 0;
}

/* One frame: detections against the truth. @return the largest error (m) */
static double check_frame(fixture_t *f, uint32_t *out_n_seen)
{
    ps_camera_frame_t fr;
    assert_int_equal(f->port.ops->next(f->port.ctx, &fr, PS_NS_PER_S), 0);
    const ps_camera_cfg_t *cc = &f->board.perception.camera;
    static uint8_t grey[640 * 480];
    assert_int_equal(fr.width, cc->width);
    assert_int_equal(ps_camera_to_grey(&fr, grey, sizeof(grey)), 0);
    f->port.ops->release(f->port.ctx, &fr);
    ps_tags_det_t det[PS_TAGS_MAX_DETECTIONS];
    const int n = ps_tags_detect(f->tags, grey, cc->width, cc->height, cc->width, det,
                                 PS_TAGS_MAX_DETECTIONS);
    assert_true(n >= 0);
    ps_camera_sim_tag_t truth[PS_CAMERA_SIM_MAX_TAGS];
    uint64_t seq = 99;
    const int n_truth = ps_camera_sim_truth(f->cam, truth, PS_CAMERA_SIM_MAX_TAGS, &seq);
    assert_int_equal(n_truth, 6);
    assert_int_equal(seq, fr.seq);
    double worst = 0;
    uint32_t n_seen = 0;
    for (int t = 0; t < n_truth; t++) {
        const ps_camera_sim_tag_t *tr = &truth[t];
        const ps_tags_det_t *d = NULL;
        for (int i = 0; i < n; i++)
            if (det[i].id == tr->id)
                d = &det[i];
        const bool is_visible = tr->is_facing && tr->is_in_view && tr->is_unoccluded;
        if (!is_visible) {
            assert_null(d);
            continue;
        }
        /* Seen whole but too small or too slanted to read: either way. */
        if (tr->size_px < MIN_SIZE_PX || tr->slant_rad > MAX_SLANT_RAD) {
            if (d == NULL)
                continue;
        }
        n_seen++;
        if (d == NULL)
            fail_msg("tag %d at (%.2f %.2f %.2f) m not detected", tr->id, tr->pos_robot_m[0],
                     tr->pos_robot_m[1], tr->pos_robot_m[2]);
        const double dx = d->pos_robot_m[0] - tr->pos_robot_m[0];
        const double dy = d->pos_robot_m[1] - tr->pos_robot_m[1];
        const double dz = d->pos_robot_m[2] - tr->pos_robot_m[2];
        const double e = sqrt(dx * dx + dy * dy + dz * dz), dist = tr->pos_cam_m[2];
        if (e > 0.02 + 0.02 * dist)
            fail_msg("tag %d: error %.4f m at %.2f m (detected %.3f %.3f %.3f, true %.3f %.3f "
                     "%.3f)",
                     tr->id, e, dist, d->pos_robot_m[0], d->pos_robot_m[1], d->pos_robot_m[2],
                     tr->pos_robot_m[0], tr->pos_robot_m[1], tr->pos_robot_m[2]);
        worst = e > worst ? e : worst;
    }
    for (int i = 0; i < n; i++) { /* nothing but the scene's tags */
        bool is_known = false;
        for (int t = 0; t < n_truth; t++)
            is_known |= truth[t].id == det[i].id;
        assert_true(is_known);
    }
    *out_n_seen = n_seen;
    return worst;
}

static void test_camera_sim_static_scene_detected_as_truth(void **state)
{
    fixture_t *f = *state;
    assert_int_equal(ps_camera_sim_n_tags(f->cam), 6);
    uint32_t n_seen = 0;
    const double worst = check_frame(f, &n_seen);
    assert_int_equal(n_seen, 6); /* the scene is built so that all six face the robot */
    printf("    %u tags, largest error %.1f mm\n", n_seen, worst * 1e3);
}

/* The robot released from the harness, the scene published by the lockstep
 * plant: picture and truth from the same state. */
static void test_camera_sim_lockstep_scene_follows_plant(void **state)
{
    fixture_t *f = *state;
    const ps_clock_t *clk = ps_sim_clock(f->sim);
    assert_int_equal(ps_sim_start(f->sim, PS_NS_PER_S), 0);
    /* 0.5 s of plant time without a controller: the harness holds it
     * (stand.yaml releases it at 2 s), it sags a little */
    assert_int_equal(ps_clock_sleep_until_ns(clk, PS_NS_PER_S + PS_NS_PER_S / 2), 0);
    uint32_t n_seen = 0;
    const double worst = check_frame(f, &n_seen);
    assert_true(n_seen >= 5);
    printf("    after 0.5 s of plant time: %u tags, largest error %.1f mm\n", n_seen,
           worst * 1e3);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_camera_sim_static_scene_detected_as_truth, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_camera_sim_lockstep_scene_follows_plant, setup,
                                        teardown),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
