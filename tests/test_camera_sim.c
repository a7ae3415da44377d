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
 * published state. The largest error is printed. Then a crowd
 * (tests/data/scenarios/camera-crowd.yaml: 8 tagged people walking up to
 * the robot) over 2 s of lockstep plant time: the detection rate of the
 * tags in view and the shoulder errors, printed; and who wears tags when
 * the scenario leaves it to the board (crowd.tags auto).
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
#include "../sim/ps_plant.h"

#include <mujoco/mujoco.h>

#define BOARD "tests/data/boards/sim-camera.yaml"
#define ROBOT "tests/data/robots/ps1-tags.yaml"
#define MODEL "tests/data/models/ps1-tags.xml"
/* the crowd test: the plain robot, a small tagged crowd walking up to it */
#define CROWD_ROBOT    "robots/ps1.yaml"
#define CROWD_MODEL    "sim/models/ps1.xml"
#define CROWD_SCENARIO "tests/data/scenarios/camera-crowd.yaml"

/* A tag seen whole must be detected when its black square spans at least
 * this many pixels and faces the camera within this angle. */
#define MIN_SIZE_PX   24.0
#define MAX_SLANT_RAD 1.05 /* 60 degrees */
/* In the crowd, the share of such tags that must be found in a frame. */
#define RATE_MIN 0.9

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

static fixture_t *make_fixture(const char *robot, const char *model, const char *scenario)
{
    fixture_t *f = calloc(1, sizeof(*f));
    char err[PS_ERR_MSG_LEN];
    if (f == NULL || ps_config_load_board(BOARD, &f->board, err, sizeof(err)) != 0 ||
        ps_config_load_robot_sim(robot, &f->robot, &f->devices, err, sizeof(err)) != 0 ||
        ps_config_load_scenario(scenario, &f->scenario, err, sizeof(err)) != 0)
        fail_msg("config: %s", err);
    ps_app_sim_board(&f->board, &f->sim_board);
    ps_app_sim_robot(&f->robot, &f->devices, &f->sim_robot);
    const ps_sim_cfg_t sc = {
        .board = &f->sim_board,
        .robot = &f->sim_robot,
        .scenario = &f->scenario,
        .model_path = model,
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
    return f;
}

static int setup(void **state)
{
    *state = make_fixture(ROBOT, MODEL, "scenarios/stand.yaml");
    return 0;
}

static int setup_crowd(void **state)
{
    *state = make_fixture(CROWD_ROBOT, CROWD_MODEL, CROWD_SCENARIO);
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

/* The next frame, its tags detected. @return how many */
static int grab_and_detect(fixture_t *f, ps_camera_frame_t *fr, ps_tags_det_t *det)
{
    assert_int_equal(f->port.ops->next(f->port.ctx, fr, PS_NS_PER_S), 0);
    const ps_camera_cfg_t *cc = &f->board.perception.camera;
    static uint8_t grey[640 * 480];
    assert_int_equal(fr->width, cc->width);
    assert_int_equal(ps_camera_to_grey(fr, grey, sizeof(grey)), 0);
    f->port.ops->release(f->port.ctx, fr);
    const int n = ps_tags_detect(f->tags, grey, cc->width, cc->height, cc->width, det,
                                 PS_TAGS_MAX_DETECTIONS);
    assert_true(n >= 0);
    return n;
}

/* One frame: detections against the truth. @return the largest error (m) */
static double check_frame(fixture_t *f, uint32_t *out_n_seen)
{
    ps_camera_frame_t fr;
    ps_tags_det_t det[PS_TAGS_MAX_DETECTIONS];
    const int n = grab_and_detect(f, &fr, det);
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

/* What the crowd test counts over its frames. */
typedef struct {
    uint32_t n_frames;
    uint32_t n_required; /* tags seen whole, large and square enough: must be found */
    uint32_t n_found;    /* of those, detected */
    uint32_t n_det;      /* detections of tags seen whole */
    double err_sum_m, err_max_m;
    uint32_t n_partial; /* detected though not seen whole (an edge hidden) */
    double partial_max_m;
} crowd_tally_t;

/* One frame of the crowd: every detection is a tag of the scene, within
 * 2 cm + 2 % of its distance of the truth (the plant's shoulders, robot
 * frame); every tag seen whole, at least MIN_SIZE_PX across and within
 * MAX_SLANT_RAD, is counted as required, and whether it was found. */
static void tally_crowd_frame(fixture_t *f, crowd_tally_t *t)
{
    ps_camera_frame_t fr;
    ps_tags_det_t det[PS_TAGS_MAX_DETECTIONS];
    const int n = grab_and_detect(f, &fr, det);
    static ps_camera_sim_tag_t truth[PS_CAMERA_SIM_MAX_TAGS];
    uint64_t seq = 0;
    const int n_truth = ps_camera_sim_truth(f->cam, truth, PS_CAMERA_SIM_MAX_TAGS, &seq);
    assert_int_equal(n_truth, 16); /* 8 people, two shoulders each */
    assert_int_equal(seq, fr.seq);
    t->n_frames++;
    for (int i = 0; i < n; i++) {
        const ps_camera_sim_tag_t *tr = NULL;
        for (int k = 0; k < n_truth; k++)
            if (truth[k].id == det[i].id)
                tr = &truth[k];
        if (tr == NULL)
            fail_msg("detected tag %d is not in the scene", det[i].id);
        double e2 = 0;
        for (int k = 0; k < 3; k++)
            e2 += pow(det[i].pos_robot_m[k] - tr->pos_robot_m[k], 2);
        const double e = sqrt(e2), dist = tr->pos_cam_m[2];
        if (e > 0.02 + 0.02 * dist)
            fail_msg("tag %d: error %.4f m at %.2f m (detected %.3f %.3f %.3f, true %.3f %.3f "
                     "%.3f)",
                     tr->id, e, dist, det[i].pos_robot_m[0], det[i].pos_robot_m[1],
                     det[i].pos_robot_m[2], tr->pos_robot_m[0], tr->pos_robot_m[1],
                     tr->pos_robot_m[2]);
        const bool is_whole = tr->is_facing && tr->is_in_view && tr->is_unoccluded;
        if (is_whole) {
            t->n_det++;
            t->err_sum_m += e;
            t->err_max_m = e > t->err_max_m ? e : t->err_max_m;
        } else {
            t->n_partial++;
            t->partial_max_m = e > t->partial_max_m ? e : t->partial_max_m;
        }
    }
    for (int k = 0; k < n_truth; k++) {
        const ps_camera_sim_tag_t *tr = &truth[k];
        if (!(tr->is_facing && tr->is_in_view && tr->is_unoccluded) || tr->size_px < MIN_SIZE_PX ||
            tr->slant_rad > MAX_SLANT_RAD)
            continue;
        t->n_required++;
        bool is_found = false;
        for (int i = 0; i < n; i++)
            is_found |= det[i].id == tr->id;
        t->n_found += is_found ? 1u : 0u;
        if (!is_found)
            print_message("    frame %llu: tag %d at %.2f m, %.0f px, %.0f deg not detected\n",
                          (unsigned long long)fr.seq, tr->id, tr->pos_cam_m[2], tr->size_px,
                          tr->slant_rad * 57.2958);
    }
}

/* The test: in a crowd scene (8 tagged people walking up to the
 * robot from 0.9 to 2.8 m ahead, arriving and pressing on it within 2 s of
 * lockstep plant time), the shoulders the camera finds against the plant's
 * truth, frame by frame. */
static void test_camera_sim_crowd_shoulders_detected_as_truth(void **state)
{
    fixture_t *f = *state;
    assert_int_equal(ps_camera_sim_n_tags(f->cam), 16);
    const ps_clock_t *clk = ps_sim_clock(f->sim);
    assert_int_equal(ps_sim_start(f->sim, PS_NS_PER_S), 0);
    crowd_tally_t t = {0};
    for (int k = 0; k <= 8; k++) { /* every 0.25 s of plant time, 0 to 2 s */
        assert_int_equal(ps_clock_sleep_until_ns(clk, PS_NS_PER_S + k * PS_NS_PER_S / 4), 0);
        tally_crowd_frame(f, &t);
    }
    const double rate = t.n_required > 0 ? (double)t.n_found / t.n_required : 0.0;
    print_message("    crowd, %u frames: %u of %u tags in view detected (%.1f %%); shoulder "
                  "error over %u detections of tags seen whole: mean %.1f mm, max %.1f mm; %u "
                  "more of partly hidden tags, max %.1f mm\n",
                  t.n_frames, t.n_found, t.n_required, 100.0 * rate, t.n_det,
                  t.n_det > 0 ? 1e3 * t.err_sum_m / t.n_det : 0.0, 1e3 * t.err_max_m, t.n_partial,
                  1e3 * t.partial_max_m);
    assert_true(t.n_required >= 3u * t.n_frames); /* the crowd is in view */
    assert_true(rate >= RATE_MIN);
}

/* Who wears tags: with crowd.tags absent (auto) the crowd does when the
 * board's camera is the simulated one, not on plain board sim; a scenario
 * that says true puts them on without a camera. */
static void test_camera_sim_crowd_tags_auto_with_sim_camera_only(void **state)
{
    (void)state;
    static const struct {
        const char *board, *scenario;
        bool has_tags;
    } CASES[] = {
        {BOARD, "scenarios/crowd.yaml", true},
        {"boards/sim.yaml", "scenarios/crowd.yaml", false},
        {"boards/sim.yaml", CROWD_SCENARIO, true},
    };
    static ps_app_t app; /* large */
    for (size_t k = 0; k < sizeof(CASES) / sizeof(CASES[0]); k++) {
        char err[PS_ERR_MSG_LEN] = "";
        const ps_app_opts_t o = {.data_dir = ".",
                                 .board = CASES[k].board,
                                 .scenario = CASES[k].scenario,
                                 .is_lockstep = true};
        if (ps_app_init(&app, &o, err, sizeof(err)) != 0)
            fail_msg("%s, %s: %s", CASES[k].board, CASES[k].scenario, err);
        const mjModel *m = ps_plant_model(ps_sim_plant(app.sim));
        const int left = mj_name2id(m, mjOBJ_SITE, "agent0_tag_left");
        print_message("    board %s, scenario %s: %s\n", CASES[k].board, CASES[k].scenario,
                      left >= 0 ? "tags" : "no tags");
        assert_int_equal(left >= 0, CASES[k].has_tags);
        ps_app_deinit(&app);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_camera_sim_static_scene_detected_as_truth, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_camera_sim_lockstep_scene_follows_plant, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_camera_sim_crowd_shoulders_detected_as_truth,
                                        setup_crowd, teardown),
        cmocka_unit_test(test_camera_sim_crowd_tags_auto_with_sim_camera_only),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
