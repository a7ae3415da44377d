/*
 * Camera perception end to end (built plain and with ASan and UBSan,
 * build/tests/san/, which runs the sanitized runtime and reports the loop
 * thread's page faults, and in real time how fresh the lists were, rather
 * than asserting them: tests/fakes/ps_san.h):
 *  - in lockstep, in process: the runtime with the simulated camera
 *    (tests/data/boards/sim-camera.yaml, tests/data/robots/ps1-tags.yaml)
 *    takes neighbour lists into the loop while the loop thread, guarded,
 *    allocates, frees, faults and locks nothing;
 *  - in real time, through the command line: the same, the summary's
 *    after-init counts all zero, and the loop saw fresh lists with the
 *    tags' shoulders;
 *  - `pushstep camera` on the simulated camera: the PNG (read back with
 *    libpng) and the JSON, every tag of the static scene detected against
 *    the truth; on the default crowd, its people wearing tags (auto);
 *  - `pushstep camera` on an image folder of a synthesised tag at a known
 *    pose: found where it is;
 *  - a board without a camera: exit 2, the file named.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <cjson/cJSON.h>
#include <math.h>
#include <png.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "../rt/ps_app.h"
#include "../rt/ps_err.h"
#include "../rt/ps_guard.h"
#include "../rt/ps_rtsetup.h"
#include "fakes/ps_camera_fake.h"
#include "fakes/ps_cli.h"
#include "fakes/ps_san.h"

#define BOARD    "tests/data/boards/sim-camera.yaml"
#define ROBOT    "tests/data/robots/ps1-tags.yaml"
#define START_NS PS_NS_PER_S
#define OUT_MAX  (256 * 1024)

static char out[OUT_MAX];

static int run(const char *args)
{
    return ps_cli_run(args, out, sizeof(out));
}

static void make_temp_dir(char *path, size_t len)
{
    snprintf(path, len, "/tmp/ps_e2e_cam_XXXXXX");
    assert_non_null(mkdtemp(path));
}

static void remove_tree(const char *path)
{
    char cmd[128];
    snprintf(cmd, sizeof(cmd), "rm -rf '%s'", path);
    assert_int_equal(system(cmd), 0);
}

/* ---- in process, lockstep, guarded ---------------------------------------- */

static ps_app_t app; /* large: static, like main's */

static int teardown_app(void **state)
{
    (void)state;
    ps_app_deinit(&app);
    return 0;
}

static void test_e2e_camera_lockstep_loop_takes_lists_no_alloc_no_lock(void **state)
{
    (void)state;
    char err[PS_ERR_MSG_LEN] = "";
    const ps_app_opts_t o = {.data_dir = ".",
                             .board = BOARD,
                             .robot = ROBOT,
                             .scenario = "scenarios/stand.yaml",
                             .is_lockstep = true};
    const int rc = ps_app_init(&app, &o, err, sizeof(err));
    if (rc != 0)
        fail_msg("ps_app_init: %s (%s)", err, ps_strerror(rc));
    assert_true(app.has_perception);
    assert_non_null(app.loop.cfg.neighbours);
    assert_int_equal(ps_sim_start(app.sim, START_NS), 0);
    assert_int_equal(ps_loop_start(&app.loop, START_NS), 0);
    if (ps_rtsetup_lock_memory() < 0)
        (void)ps_rtsetup_prefault_maps();
    ps_rtsetup_prefault_stack(256 * 1024);
    /* the first list in, before the guarded part (its first copy may fault
     * the page of meas.neighbours the loop never touched yet: init's work) */
    while (app.loop.counters.n_neighbour_lists == 0 &&
           app.loop.t_deadline_ns < START_NS + 30 * PS_NS_PER_S)
        assert_int_equal(ps_loop_step(&app.loop), 0);
    assert_true(app.loop.counters.n_neighbour_lists > 0);
    const uint64_t lists0 = app.loop.counters.n_neighbour_lists;
    static ps_loop_rec_t transitions[64];
    unsigned n_transitions = 0;
    ps_guard_arm();
    const int64_t end = app.loop.t_deadline_ns + 4 * PS_NS_PER_S;
    while (app.loop.t_deadline_ns < end) {
        if (ps_loop_step(&app.loop) != 0)
            break;
        if (app.loop.counters.n_ticks % 50 == 0) {
            ps_guard_pause();
            ps_loop_rec_t rec;
            while (ps_ring_pop(&app.ring, &rec) == 0)
                if (rec.kind == PS_REC_TRANSITION && n_transitions < 64)
                    transitions[n_transitions++] = rec;
            ps_guard_resume();
        }
    }
    ps_guard_counts_t c;
    ps_guard_disarm(&c);
    assert_true(app.loop.t_deadline_ns >= end);
    const uint64_t n_lists = app.loop.counters.n_neighbour_lists - lists0;
    print_message("4 s of lockstep with the camera: %llu lists taken; loop thread: %llu mallocs, "
                  "%llu frees, %llu page faults, %llu locks\n",
                  (unsigned long long)n_lists, (unsigned long long)c.n_allocs,
                  (unsigned long long)c.n_frees, (unsigned long long)c.n_faults,
                  (unsigned long long)c.n_locks);
    assert_true(n_lists > 0);
    ps_san_assert_guard_clean(&c, "4 s of lockstep with the camera");
    for (unsigned i = 0; i < n_transitions; i++)
        print_message("transition at %.3f s: %s -> %s (conditions 0x%x)\n",
                      ps_ns_to_s(transitions[i].t_ns - START_NS),
                      ps_sm_state_name(transitions[i].from_state),
                      ps_sm_state_name(transitions[i].state), transitions[i].cond);
    assert_int_equal(app.loop.state, PS_SM_ACTIVE);
}

/* ---- real time, command line ------------------------------------------------ */

static void test_e2e_camera_realtime_fresh_lists_summary_no_alloc(void **state)
{
    (void)state;
    char path[32];
    ps_cli_temp_file(path, sizeof(path));
    char args[512];
    snprintf(args, sizeof(args), "--board %s --robot %s --duration 3 --quiet --summary %s", BOARD,
             ROBOT, path);
    const int rc = run(args);
    if (rc != 0)
        fail_msg("exit %d:\n%s", rc, out);
    const char *line = strstr(out, "camera: ");
    if (line == NULL)
        fail_msg("no camera line:\n%s", out);
    unsigned long long frames = 0, tags = 0, lists = 0, stale = 0, ticks = 0;
    double fps = 0;
    if (sscanf(line, "camera: %llu frames (%lf/s), %llu tags", &frames, &fps, &tags) != 3)
        fail_msg("camera line: %s", line);
    const char *took = strstr(line, "the loop took ");
    assert_non_null(took);
    assert_int_equal(sscanf(took, "the loop took %llu lists, %llu of %llu ticks", &lists, &stale,
                            &ticks),
                     3);
    print_message("real time, 3 s: %llu frames (%.1f/s), %llu tags, %llu lists taken, %llu of "
                  "%llu ticks without a fresh one\n",
                  frames, fps, tags, lists, stale, ticks);
    assert_true(frames > 0 && tags > 0);
    assert_true(lists > 0);
    /* some ticks had a list younger than max_age_s (0.2 s: under ASan on a
     * loaded machine the slower pipeline has been seen at 1.6 frames/s with
     * every list older than that) */
    ps_san_assert_true(stale < ticks, PS_SAN_CPU_TIME, "a list younger than max_age_s");
    cJSON *j = ps_cli_read_json(path);
    ps_cli_assert_after_init_clean(j);
    cJSON_Delete(j);
    unlink(path);
}

/* ---- pushstep camera ---------------------------------------------------------- */

static void read_png_size(const char *path, uint32_t *w, uint32_t *h)
{
    png_image im;
    memset(&im, 0, sizeof(im));
    im.version = PNG_IMAGE_VERSION;
    if (!png_image_begin_read_from_file(&im, path))
        fail_msg("%s: %s", path, im.message);
    *w = im.width;
    *h = im.height;
    png_image_free(&im);
}

static void test_e2e_camera_tool_sim_png_json_all_tags(void **state)
{
    (void)state;
    char dir[64];
    make_temp_dir(dir, sizeof(dir));
    char args[512];
    snprintf(args, sizeof(args),
             "camera --board %s --robot %s --scenario scenarios/stand.yaml --duration 2 --out %s",
             BOARD, ROBOT, dir);
    const int rc = run(args);
    if (rc != 0)
        fail_msg("exit %d:\n%s", rc, out);
    assert_non_null(strstr(out, "6 seen whole by the camera, 6 of them detected"));
    char path[128];
    snprintf(path, sizeof(path), "%s/camera.png", dir);
    uint32_t w = 0, h = 0;
    read_png_size(path, &w, &h);
    assert_int_equal(w, 640);
    assert_int_equal(h, 480);
    snprintf(path, sizeof(path), "%s/camera.json", dir);
    cJSON *j = ps_cli_read_json(path);
    const cJSON *st = ps_cli_obj(j, "stats");
    assert_true(ps_cli_num(st, "frames") >= 1);
    assert_true(ps_cli_num(ps_cli_obj(st, "latency_ms"), "p50") > 0);
    const cJSON *t = ps_cli_obj(j, "truth");
    assert_int_equal((int)ps_cli_num(t, "tags_detected"), 6);
    assert_true(ps_cli_num(t, "max_error_mm") < 50.0);
    assert_int_equal(cJSON_GetArraySize(ps_cli_obj(j, "last_frame_detections")), 6);
    cJSON_Delete(j);
    remove_tree(dir);
}

/* The default scenario, its crowd of 24 around the plain robot: on the
 * simulated camera's board the people wear tags (crowd.tags auto), and the
 * tool finds their shoulders where the plant has them. */
static void test_e2e_camera_tool_sim_default_crowd_wears_tags(void **state)
{
    (void)state;
    char dir[64];
    make_temp_dir(dir, sizeof(dir));
    char args[512];
    snprintf(args, sizeof(args), "camera --board %s --duration 1 --out %s", BOARD, dir);
    const int rc = run(args);
    if (rc != 0)
        fail_msg("exit %d:\n%s", rc, out);
    char path[128];
    snprintf(path, sizeof(path), "%s/camera.json", dir);
    cJSON *j = ps_cli_read_json(path);
    const cJSON *t = ps_cli_obj(j, "truth");
    print_message("default crowd: %d tags in the scene, %d seen whole, %d detected, largest "
                  "error %.1f mm\n",
                  (int)ps_cli_num(t, "tags_in_scene"), (int)ps_cli_num(t, "tags_seen_whole"),
                  (int)ps_cli_num(t, "tags_detected"), ps_cli_num(t, "max_error_mm"));
    assert_int_equal((int)ps_cli_num(t, "tags_in_scene"), 48); /* 24 people */
    assert_true(ps_cli_num(t, "tags_detected") >= 1);
    assert_true(ps_cli_num(t, "max_error_mm") < 50.0);
    cJSON_Delete(j);
    remove_tree(dir);
}

static void test_e2e_camera_tool_image_folder_tag_where_it_is(void **state)
{
    (void)state;
    char dir[64];
    make_temp_dir(dir, sizeof(dir));
    char sub[96];
    snprintf(sub, sizeof(sub), "%s/images", dir);
    assert_int_equal(mkdir(sub, 0755), 0);
    /* one tag, id 9 (neighbour 4, right shoulder), 1.5 m ahead, 0.2 m left */
    static uint8_t img[320 * 240];
    const ps_camera_intrinsics_t k = {300, 300, 160, 120};
    ps_tag_pose_t p = {.id = 9, .size_m = 0.12, .pos_cam_m = {-0.2, 0.0, 1.5}};
    ps_tag_pose_turned(&p, 0.2, 0.0);
    assert_int_equal(ps_tag_image_render(img, 320, 240, &k, &p, 1, 128, 4, 3), 0);
    char path[160];
    snprintf(path, sizeof(path), "%s/f000.png", sub);
    png_image im;
    memset(&im, 0, sizeof(im));
    im.version = PNG_IMAGE_VERSION;
    im.width = 320;
    im.height = 240;
    im.format = PNG_FORMAT_GRAY;
    assert_true(png_image_write_to_file(&im, path, 0, img, 320, NULL));
    snprintf(path, sizeof(path), "%s/board.yaml", dir);
    FILE *f = fopen(path, "w");
    assert_non_null(f);
    fputs("name: folder\nkind: linux\nbuses:\n  - {ifname: can0, bitrate: 1000000}\n"
          "gpio: {chip: gpiochip0, estop_line: 0, estop_active_low: true, enable_line: 1, "
          "led_line: 2}\nrt: {priority: 0, loop_cpu: -1, plant_cpu: -1, worker_cpu: -1}\n"
          "camera:\n  source: files\n  dir: images\n  width: 320\n  height: 240\n  fps: 20\n"
          "  intrinsics: {fx_px: 300, fy_px: 300, cx_px: 160, cy_px: 120}\n"
          "  pose: {xyz_m: [0, 0, 0.5], rpy_rad: [0, 0, 0]}\n  tag_size_m: 0.12\n"
          "  max_age_s: 0.2\n",
          f);
    fclose(f);
    char args[512];
    snprintf(args, sizeof(args), "camera --board %s --duration 1 --out %s", path, dir);
    const int rc = run(args);
    if (rc != 0)
        fail_msg("exit %d:\n%s", rc, out);
    const char *line = strstr(out, "tag 9 (neighbour 4, right shoulder): ");
    if (line == NULL)
        fail_msg("no tag 9:\n%s", out);
    double x = 0, y = 0, z = 0;
    assert_int_equal(sscanf(line + strlen("tag 9 (neighbour 4, right shoulder): "),
                            "%lf %lf %lf", &x, &y, &z),
                     3);
    /* the camera 0.5 m up, looking ahead: 1.5 m ahead, 0.2 m left, level */
    assert_true(fabs(x - 1.5) < 0.03 && fabs(y - 0.2) < 0.03 && fabs(z - 0.5) < 0.03);
    assert_null(strstr(out, "truth:")); /* no truth without the simulated camera */
    remove_tree(dir);
}

static void test_e2e_camera_tool_board_without_camera_exit_2(void **state)
{
    (void)state;
    assert_int_equal(run("camera --board boards/sim.yaml --duration 1 --out /tmp"), 2);
    assert_non_null(strstr(out, "boards/sim.yaml: the board has no camera perception"));
    assert_int_equal(run("camera --duration 1"), 2); /* no board */
    assert_non_null(strstr(out, "usage: pushstep camera"));
    assert_int_equal(run("camera --board boards/sim.yaml --duration -1"), 2);
    /* --scenario reaches the loader */
    assert_int_equal(run("camera --board " BOARD " --robot " ROBOT
                         " --scenario tests/data/nope.yaml --duration 1 --out /tmp"),
                     2);
    assert_non_null(strstr(out, "tests/data/nope.yaml: cannot open"));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_teardown(test_e2e_camera_lockstep_loop_takes_lists_no_alloc_no_lock,
                                  teardown_app),
        cmocka_unit_test(test_e2e_camera_realtime_fresh_lists_summary_no_alloc),
        cmocka_unit_test(test_e2e_camera_tool_sim_png_json_all_tags),
        cmocka_unit_test(test_e2e_camera_tool_sim_default_crowd_wears_tags),
        cmocka_unit_test(test_e2e_camera_tool_image_folder_tag_where_it_is),
        cmocka_unit_test(test_e2e_camera_tool_board_without_camera_exit_2),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
