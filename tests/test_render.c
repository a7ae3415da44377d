/*
 * Tests of the crowd's pictures (sim/ps_render.c, sim/ps_gl.c): frames of a
 * crowd pressing on the robot rendered offscreen (EGL surfaceless, no
 * display), written as PNGs that are not blank and show the robot and the
 * people, the density map, the MP4 with one frame per PNG (ffprobe), and
 * the live viewer refusing cleanly without a display. Built plain and with
 * ASan, UBSan and LeakSanitizer (build/tests/san/test_render: our code
 * around Mesa's, which leaves nothing to report). Run from the repo root;
 * needs ffmpeg.
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
#include <sys/stat.h>
#include <unistd.h>

#include <mujoco/mujoco.h>

#include "../rt/ps_config.h"
#include "../rt/ps_err.h"
#include "../sim/ps_plant.h"
#include "../sim/ps_render.h"
#include "../sim/ps_scene.h"

static ps_robot_cfg_t robot;
static float stance[PS_MAX_JOINTS];

static int setup_robot(void **state)
{
    (void)state;
    char err[PS_ERR_MSG_LEN];
    if (ps_config_load_robot("robots/ps1.yaml", &robot, err, sizeof(err)) != 0) {
        fprintf(stderr, "setup: %s\n", err);
        return -1;
    }
    for (uint32_t j = 0; j < robot.n_joints; j++)
        stance[j] = robot.servo[j].stance_rad;
    return 0;
}

/* 20 people walking into the robot in a 3 m x 3 m pen. */
static ps_plant_t *press_plant(ps_crowd_cfg_t *c)
{
    ps_crowd_default_cfg(c);
    c->is_enabled = true;
    c->arena = (ps_crowd_rect_t){-1.5f, -1.5f, 1.5f, 1.5f};
    c->measure = c->arena;
    c->has_arena_walls = true;
    c->robot_a_n = 0.0f;
    c->n_groups = 1;
    c->groups[0] = (ps_crowd_group_cfg_t){.name = "g",
                                          .count = 20,
                                          .region = c->arena,
                                          .goal = PS_CROWD_GOAL_ROBOT,
                                          .speed_m_s = 0.6f,
                                          .height_m = 1.7f,
                                          .mass_kg = 70.0f,
                                          .radius_m = 0.17f,
                                          .clear_m = 0.45f};
    const ps_plant_cfg_t pc = {.model_path = "sim/models/ps1.xml",
                               .n_joints = robot.n_joints,
                               .joint_name = robot.joint_name,
                               .stance_rad = stance,
                               .crowd = c,
                               .seed = 3};
    ps_plant_t *p = NULL;
    char err[PS_ERR_MSG_LEN] = "";
    if (ps_plant_create(&pc, &p, err, sizeof(err)) != 0)
        fail_msg("ps_plant_create: %s", err);
    return p;
}

/* Decode an RGB PNG: size, the number of distinct colours and of black
 * pixels (every channel below 8; out_black may be NULL). */
static int png_stats(const char *path, int *out_w, int *out_h, uint32_t *out_colours,
                     uint32_t *out_black)
{
    FILE *f = fopen(path, "rb");
    if (f == NULL)
        return -errno;
    png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
    png_infop info = png_create_info_struct(png);
    if (setjmp(png_jmpbuf(png))) {
        png_destroy_read_struct(&png, &info, NULL);
        (void)fclose(f);
        return -EIO;
    }
    png_init_io(png, f);
    png_read_info(png, info);
    const int w = (int)png_get_image_width(png, info), h = (int)png_get_image_height(png, info);
    assert_int_equal(png_get_color_type(png, info), PNG_COLOR_TYPE_RGB);
    unsigned char *row = malloc(3u * (size_t)w);
    static unsigned char seen[1u << 21]; /* 15-bit colour buckets */
    memset(seen, 0, sizeof(seen));
    uint32_t n = 0, n_black = 0;
    for (int y = 0; y < h; y++) {
        png_read_row(png, row, NULL);
        for (int x = 0; x < w; x++) {
            n_black += row[3 * x] < 8 && row[3 * x + 1] < 8 && row[3 * x + 2] < 8;
            const unsigned c = (unsigned)(row[3 * x] >> 1) << 14 |
                               (unsigned)(row[3 * x + 1] >> 1) << 7 |
                               (unsigned)(row[3 * x + 2] >> 1);
            n += seen[c] ? 0u : 1u;
            seen[c] = 1;
        }
    }
    free(row);
    png_destroy_read_struct(&png, &info, NULL);
    (void)fclose(f);
    *out_w = w;
    *out_h = h;
    *out_colours = n;
    if (out_black != NULL)
        *out_black = n_black;
    return 0;
}

static long mp4_frames(const char *path)
{
    char cmd[900];
    (void)snprintf(cmd, sizeof(cmd),
                   "ffprobe -v error -count_frames -select_streams v:0 -show_entries "
                   "stream=nb_read_frames -of csv=p=0 '%s'",
                   path);
    FILE *p = popen(cmd, "r");
    assert_non_null(p);
    long n = -1;
    if (fscanf(p, "%ld", &n) != 1)
        n = -1;
    (void)pclose(p);
    return n;
}

/* Renders the plant for n_steps physics steps at rc's frame rate (lockstep:
 * every frame drawn) and returns what the renderer says; *out_r stays
 * open for the caller's checks (ps_render_destroy). */
static ps_render_result_t render_steps(ps_plant_t *p, const ps_render_cfg_t *rc, int n_steps,
                                       ps_render_t **out_r)
{
    char err[PS_ERR_MSG_LEN] = "";
    if (ps_render_create(rc, ps_plant_model(p), out_r, err, sizeof(err)) != 0)
        fail_msg("ps_render_create: %s", err);
    if (ps_render_start(*out_r, err, sizeof(err)) != 0)
        fail_msg("ps_render_start: %s", err);
    const int every = (int)lround(1.0 / (rc->fps * ps_plant_timestep_s(p)));
    for (int k = 1; k <= n_steps; k++) {
        assert_int_equal(ps_plant_step(p), 0);
        if (k % every == 0)
            ps_render_offer(*out_r, ps_plant_data(p));
    }
    ps_render_result_t res;
    if (ps_render_finish(*out_r, &res, err, sizeof(err)) != 0)
        fail_msg("ps_render_finish: %s", err);
    return res;
}

static void test_render_records_frames_density_and_mp4(void **state)
{
    (void)state;
    char dir[] = "/tmp/ps_render_XXXXXX";
    assert_non_null(mkdtemp(dir));
    ps_crowd_cfg_t c;
    ps_plant_t *p = press_plant(&c);
    const ps_render_cfg_t rc = {.dir = dir,
                                .fps = 20.0,
                                .width = 640,
                                .height = 360,
                                .is_lockstep = true,
                                .is_census = true,
                                .robot_root = "pelvis",
                                .area_m = {-1.5, -1.5, 1.5, 1.5}};
    ps_render_t *r = NULL;
    const ps_render_result_t res = render_steps(p, &rc, 800, &r); /* 0.8 s: 16 frames */
    printf("render: %llu frames, %llu dropped; last frame: robot %u px, people %u px, %u of 20 "
           "people seen\n",
           (unsigned long long)res.n_frames, (unsigned long long)res.n_dropped, res.robot_px,
           res.agent_px, res.n_agents_seen);
    assert_int_equal(res.n_frames, 16);
    assert_int_equal(res.n_dropped, 0);
    assert_true(res.robot_px > 1000);     /* the robot (1888 px when written), through the people */
    assert_true(res.n_agents_seen >= 10); /* most of the people around it */
    char path[600];
    int w, h;
    uint32_t colours;
    (void)snprintf(path, sizeof(path), "%s/frame_00015.png", dir);
    assert_int_equal(png_stats(path, &w, &h, &colours, NULL), 0);
    printf("render: %s %dx%d, %u colours\n", path, w, h, colours);
    assert_int_equal(w, 640);
    assert_int_equal(h, 360);
    assert_true(colours > 500); /* shaded bodies, floor, text: not blank */
    (void)snprintf(path, sizeof(path), "%s/density.png", dir);
    assert_int_equal(png_stats(path, &w, &h, &colours, NULL), 0);
    printf("render: %s %dx%d, %u colours\n", path, w, h, colours);
    assert_true(res.is_density);
    assert_true(colours > 20);
    (void)snprintf(path, sizeof(path), "%s/crowd.mp4", dir);
    assert_true(res.is_mp4);
    const long n = mp4_frames(path);
    printf("render: %s has %ld frames\n", path, n);
    assert_int_equal(n, 16);
    ps_render_destroy(r);
    ps_plant_destroy(p);
    if (getenv("PS_KEEP_RENDER") == NULL) {
        char cmd[700];
        (void)snprintf(cmd, sizeof(cmd), "rm -rf '%s'", dir);
        assert_int_equal(system(cmd), 0);
    }
}

/* The robot alone (no crowd scene around it): its MJCF leaves MuJoCo's
 * 640 x 480 offscreen buffer, yet the frames come at `pushstep --render`'s
 * 960 x 540 (they used to be refused: "frame size 960x540: even, 16x16 to
 * 640x480"). */
static void test_render_robot_alone_at_the_cli_frame_size(void **state)
{
    (void)state;
    char dir[] = "/tmp/ps_render_XXXXXX";
    assert_non_null(mkdtemp(dir));
    const ps_plant_cfg_t pc = {.model_path = "sim/models/ps1.xml",
                               .n_joints = robot.n_joints,
                               .joint_name = robot.joint_name,
                               .stance_rad = stance};
    ps_plant_t *p = NULL;
    char err[PS_ERR_MSG_LEN] = "";
    if (ps_plant_create(&pc, &p, err, sizeof(err)) != 0)
        fail_msg("ps_plant_create: %s", err);
    assert_true(ps_plant_model(p)->vis.global.offwidth < 960);
    const ps_render_cfg_t rc = {.dir = dir,
                                .fps = 20.0,
                                .width = 960,
                                .height = 540,
                                .is_lockstep = true,
                                .is_census = true,
                                .robot_root = "pelvis",
                                .area_m = {-3.0, -3.0, 3.0, 3.0}};
    ps_render_t *r = NULL;
    const int every = (int)lround(1.0 / (rc.fps * ps_plant_timestep_s(p)));
    const ps_render_result_t res = render_steps(p, &rc, 2 * every, &r);
    printf("render: robot alone, %llu frames, robot %u px\n", (unsigned long long)res.n_frames,
           res.robot_px);
    assert_int_equal(res.n_frames, 2);
    assert_true(res.robot_px > 1000);
    char path[600];
    int w, h;
    uint32_t colours;
    uint32_t black = 0;
    (void)snprintf(path, sizeof(path), "%s/frame_00001.png", dir);
    assert_int_equal(png_stats(path, &w, &h, &colours, &black), 0);
    printf("render: %s %dx%d, %u colours, %u black pixels\n", path, w, h, colours, black);
    assert_int_equal(w, 960);
    assert_int_equal(h, 540);
    assert_true(colours > 100); /* a plain floor and one robot (538 when written) */
    /* drawn edge to edge: a 640 x 480 buffer leaves the rest black (a third
     * of the frame); the floor and the robot have no black pixel */
    assert_true(black < 960u * 540u / 100u);
    ps_render_destroy(r);
    ps_plant_destroy(p);
    char cmd[700];
    (void)snprintf(cmd, sizeof(cmd), "rm -rf '%s'", dir);
    assert_int_equal(system(cmd), 0);
}

static void test_render_create_view_without_display_refused(void **state)
{
    (void)state;
    ps_crowd_cfg_t c;
    ps_plant_t *p = press_plant(&c);
    char *display = getenv("DISPLAY") ? strdup(getenv("DISPLAY")) : NULL;
    char *wayland = getenv("WAYLAND_DISPLAY") ? strdup(getenv("WAYLAND_DISPLAY")) : NULL;
    unsetenv("DISPLAY");
    unsetenv("WAYLAND_DISPLAY");
    const ps_render_cfg_t rc = {.fps = 25.0,
                                .width = 640,
                                .height = 360,
                                .is_view = true,
                                .robot_root = "pelvis",
                                .area_m = {-1.5, -1.5, 1.5, 1.5}};
    ps_render_t *r = NULL;
    char err[PS_ERR_MSG_LEN] = "";
    assert_int_equal(ps_render_create(&rc, ps_plant_model(p), &r, err, sizeof(err)), -ENXIO);
    assert_null(r);
    printf("view without a display: %s\n", err);
    assert_non_null(strstr(err, "needs a display"));
    if (display != NULL)
        setenv("DISPLAY", display, 1);
    if (wayland != NULL)
        setenv("WAYLAND_DISPLAY", wayland, 1);
    free(display);
    free(wayland);
    ps_plant_destroy(p);
}

static void test_render_create_bad_size_rejected(void **state)
{
    (void)state;
    ps_crowd_cfg_t c;
    ps_plant_t *p = press_plant(&c);
    ps_render_cfg_t rc = {.fps = 25.0,
                          .width = 641,
                          .height = 360,
                          .robot_root = "pelvis",
                          .area_m = {-1.5, -1.5, 1.5, 1.5}};
    ps_render_t *r = NULL;
    char err[PS_ERR_MSG_LEN] = "";
    assert_int_equal(ps_render_create(&rc, ps_plant_model(p), &r, err, sizeof(err)), -EINVAL);
    assert_non_null(strstr(err, "frame size 641x360"));
    rc.width = 640;
    rc.fps = 0.0;
    assert_int_equal(ps_render_create(&rc, ps_plant_model(p), &r, err, sizeof(err)), -EINVAL);
    assert_non_null(strstr(err, "fps 0"));
    rc.fps = 25.0;
    rc.robot_root = "nobody";
    assert_int_equal(ps_render_create(&rc, ps_plant_model(p), &r, err, sizeof(err)), -ENOENT);
    /* more textures than MuJoCo 2.2.2's renderer has slots for: refused
     * before anything is drawn (only the count is read) */
    rc.robot_root = "pelvis";
    mjModel *many = mj_copyModel(NULL, ps_plant_model(p));
    assert_non_null(many);
    many->ntex = (int)PS_SCENE_MAX_TEXTURES + 1;
    assert_int_equal(ps_render_create(&rc, many, &r, err, sizeof(err)), -EINVAL);
    assert_non_null(strstr(err, "101 textures"));
    mj_deleteModel(many);
    ps_plant_destroy(p);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_render_records_frames_density_and_mp4),
        cmocka_unit_test(test_render_robot_alone_at_the_cli_frame_size),
        cmocka_unit_test(test_render_create_view_without_display_refused),
        cmocka_unit_test(test_render_create_bad_size_rejected),
    };
    return cmocka_run_group_tests(tests, setup_robot, NULL);
}
