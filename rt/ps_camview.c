#include "ps_args.h"
#include "ps_camview.h"

#include <cjson/cJSON.h>
#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <png.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>

#include <apriltag/common/image_u8x3.h>

#include "ps_app.h"
#include "ps_err.h"

#define POLL_NS    (50 * PS_NS_PER_MS)

static volatile sig_atomic_t g_stop;

static void on_signal(int sig)
{
    (void)sig;
    g_stop = 1;
}

typedef struct {
    const char *board;
    const char *robot;
    const char *scenario;
    const char *out_dir;
    double duration_s;
} camview_opts_t;

static const char USAGE[] =
    "usage: pushstep camera --board NAME|FILE [--robot FILE] [--scenario NAME|FILE]\n"
    "                       [--duration S] [--out DIR]\n"
    "Runs the board's camera (its camera: section: libcamera, an image folder, or\n"
    "on board sim the simulated camera looking at the robot's scene at rest)\n"
    "through the runtime's perception (AprilTags on the neighbours' shoulders)\n"
    "without the loop, then prints frames and detections per second, the latency\n"
    "from exposure to mailbox and the detection time, and writes DIR/camera.png\n"
    "(the last frame as the detector saw it, each tag drawn with its id, neighbour,\n"
    "side and distance) and DIR/camera.json. On the simulated camera the last\n"
    "frame's detections are also compared with the plant's truth.\n"
    "\n"
    "  --board NAME|FILE   board file with a camera: section\n"
    "  --robot NAME|FILE   robot file (board sim: its model is the scene;\n"
    "                      default robots/ps1.yaml)\n"
    "  --scenario NAME|FILE  board sim: the scenario whose scene the camera sees,\n"
    "                      its crowd placed as at the start (default crowd; a\n"
    "                      simulated camera puts tags on the crowd's shoulders\n"
    "                      unless the scenario's crowd.tags says false)\n"
    "  --duration S        run S seconds (default 5; an image folder ends sooner\n"
    "                      only when Ctrl-C stops it)\n"
    "  --out DIR           output folder (default ./camera)\n";

static int parse(int argc, char **argv, camview_opts_t *o)
{
    static const struct option LONG[] = {
        {"board", required_argument, NULL, 'b'},
        {"robot", required_argument, NULL, 'r'},
        {"scenario", required_argument, NULL, 's'},
        {"duration", required_argument, NULL, 'd'},
        {"out", required_argument, NULL, 'o'},
        {"help", no_argument, NULL, 'h'},
        {NULL, 0, NULL, 0},
    };
    *o = (camview_opts_t){.out_dir = "camera", .duration_s = 5.0};
    int c;
    while ((c = getopt_long(argc, argv, "h", LONG, NULL)) != -1) {
        switch (c) {
        case 'b':
            o->board = optarg;
            break;
        case 'r':
            o->robot = optarg;
            break;
        case 's':
            o->scenario = optarg;
            break;
        case 'o':
            o->out_dir = optarg;
            break;
        case 'd':
            if (ps_args_seconds(optarg, 0.0, 86400.0, true, &o->duration_s) < 0) {
                fprintf(stderr, "pushstep camera: --duration: '%s' is not seconds in (0, 86400]\n",
                        optarg);
                return -EINVAL;
            }
            break;
        case 'h':
            fputs(USAGE, stdout);
            exit(0);
        default:
            fputs(USAGE, stderr);
            return -EINVAL;
        }
    }
    if (optind < argc || o->board == NULL) {
        fputs(USAGE, stderr);
        return -EINVAL;
    }
    return 0;
}

/* ---- the picture ---------------------------------------------------------- */

/* Labels are drawn with this 5 x 7 font (a column per bit, top row first):
 * the characters a label needs, no more. A text library (cairo) would bring
 * X11, fontconfig and freetype into every start of the runtime: some 18 ms
 * more, measured, for a label in a picture. */
static const struct {
    char c;
    uint8_t rows[7];
} GLYPHS[] = {
    {'0', {0x0e, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0e}},
    {'1', {0x04, 0x0c, 0x04, 0x04, 0x04, 0x04, 0x0e}},
    {'2', {0x0e, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1f}},
    {'3', {0x1f, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0e}},
    {'4', {0x02, 0x06, 0x0a, 0x12, 0x1f, 0x02, 0x02}},
    {'5', {0x1f, 0x10, 0x1e, 0x01, 0x01, 0x11, 0x0e}},
    {'6', {0x06, 0x08, 0x10, 0x1e, 0x11, 0x11, 0x0e}},
    {'7', {0x1f, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08}},
    {'8', {0x0e, 0x11, 0x11, 0x0e, 0x11, 0x11, 0x0e}},
    {'9', {0x0e, 0x11, 0x11, 0x0f, 0x01, 0x02, 0x0c}},
    {'.', {0x00, 0x00, 0x00, 0x00, 0x00, 0x0c, 0x0c}},
    {'L', {0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1f}},
    {'R', {0x1e, 0x11, 0x11, 0x1e, 0x14, 0x12, 0x11}},
    {'m', {0x00, 0x00, 0x1a, 0x15, 0x15, 0x11, 0x11}},
    {' ', {0, 0, 0, 0, 0, 0, 0}},
};
#define GLYPH_SCALE 2
#define GLYPH_W     (6 * GLYPH_SCALE) /* 5 columns and a gap */
#define GLYPH_H     (8 * GLYPH_SCALE)

static void put_px(image_u8x3_t *im, int x, int y, const uint8_t rgb[3])
{
    if (x >= 0 && y >= 0 && x < im->width && y < im->height)
        memcpy(im->buf + (size_t)y * (size_t)im->stride + 3u * (size_t)x, rgb, 3);
}

/* text at (x, y) (top left) on a black box */
static void draw_text(image_u8x3_t *im, int x, int y, const char *text, const uint8_t rgb[3])
{
    static const uint8_t BLACK[3] = {0, 0, 0};
    const int w = (int)strlen(text) * GLYPH_W + GLYPH_SCALE;
    for (int yy = y - GLYPH_SCALE; yy < y + GLYPH_H; yy++)
        for (int xx = x - GLYPH_SCALE; xx < x + w; xx++)
            put_px(im, xx, yy, BLACK);
    for (const char *p = text; *p != '\0'; p++, x += GLYPH_W) {
        const uint8_t *rows = NULL;
        for (size_t g = 0; g < sizeof(GLYPHS) / sizeof(GLYPHS[0]); g++)
            if (GLYPHS[g].c == *p)
                rows = GLYPHS[g].rows;
        for (int r = 0; rows != NULL && r < 7; r++)
            for (int col = 0; col < 5; col++)
                if (rows[r] & (0x10 >> col))
                    for (int k = 0; k < GLYPH_SCALE * GLYPH_SCALE; k++)
                        put_px(im, x + col * GLYPH_SCALE + k % GLYPH_SCALE,
                               y + r * GLYPH_SCALE + k / GLYPH_SCALE, rgb);
    }
}

int ps_camview_write_png(const char *path, const uint8_t *grey, uint32_t width, uint32_t height,
                         const ps_tags_det_t *det, uint32_t n_det, char *err, size_t err_len)
{
    image_u8x3_t *im = image_u8x3_create(width, height);
    if (im == NULL) {
        ps_err_format(err, err_len, "%s: no memory for a %ux%u picture", path, width, height);
        return -ENOMEM;
    }
    for (uint32_t y = 0; y < height; y++)
        for (uint32_t x = 0; x < width; x++)
            memset(im->buf + (size_t)y * (size_t)im->stride + 3u * x, grey[(size_t)y * width + x],
                   3);
    static const uint8_t GREEN[3] = {30, 230, 50}, RED[3] = {255, 50, 50}, YELLOW[3] = {255, 255, 80};
    for (uint32_t i = 0; i < n_det; i++) {
        const ps_tags_det_t *d = &det[i];
        for (int k = 0; k < 4; k++)
            image_u8x3_draw_line(im, d->corners_px[k][0], d->corners_px[k][1],
                                 d->corners_px[(k + 1) % 4][0], d->corners_px[(k + 1) % 4][1],
                                 (uint8_t *)(uintptr_t)GREEN, 2);
        image_u8x3_draw_line(im, d->centre_px[0] - 4, d->centre_px[1], d->centre_px[0] + 4,
                             d->centre_px[1], (uint8_t *)(uintptr_t)RED, 1);
        image_u8x3_draw_line(im, d->centre_px[0], d->centre_px[1] - 4, d->centre_px[0],
                             d->centre_px[1] + 4, (uint8_t *)(uintptr_t)RED, 1);
        const double dist = sqrt((double)d->pos_cam_m[0] * d->pos_cam_m[0] +
                                 (double)d->pos_cam_m[1] * d->pos_cam_m[1] +
                                 (double)d->pos_cam_m[2] * d->pos_cam_m[2]);
        char label[32]; /* "<id><L|R> <distance>m": tag 7, right shoulder of neighbour 3 */
        snprintf(label, sizeof(label), "%d%s %.2fm", d->id, d->id % 2 ? "R" : "L", dist);
        float top = d->corners_px[0][1], bottom = top, left = d->corners_px[0][0];
        for (int k = 1; k < 4; k++) {
            top = fminf(top, d->corners_px[k][1]);
            bottom = fmaxf(bottom, d->corners_px[k][1]);
            left = fminf(left, d->corners_px[k][0]);
        }
        /* left shoulders' labels above the tag, right shoulders' below: the
         * two tags of a person stand side by side */
        const int tw = (int)strlen(label) * GLYPH_W;
        const int tx = (int)fmaxf(2, fminf(left, (float)width - (float)tw - 2));
        const int ty = d->id % 2 == 0 ? (int)fmaxf(2, top - GLYPH_H - 3)
                                      : (int)fminf((float)height - GLYPH_H, bottom + 4);
        draw_text(im, tx, ty, label, YELLOW);
    }
    png_image png;
    memset(&png, 0, sizeof(png));
    png.version = PNG_IMAGE_VERSION;
    png.width = width;
    png.height = height;
    png.format = PNG_FORMAT_RGB;
    const int is_ok = png_image_write_to_file(&png, path, 0, im->buf, im->stride, NULL);
    image_u8x3_destroy(im);
    if (!is_ok) {
        ps_err_format(err, err_len, "%s: %s", path, png.message);
        return -EIO;
    }
    return 0;
}

/* ---- the run ------------------------------------------------------------------ */

static void sleep_ns(int64_t ns)
{
    const struct timespec ts = {(time_t)(ns / PS_NS_PER_S), (long)(ns % PS_NS_PER_S)};
    nanosleep(&ts, NULL);
}

static double ms(int64_t ns)
{
    return (double)ns * 1e-6;
}

/* The last frame's detections against the simulated camera's truth: how many
 * of the tags the camera saw whole were found, and the largest error. */
static void compare_truth(ps_app_t *app, const ps_tags_det_t *det, uint32_t n_det, uint64_t seq,
                          cJSON *json)
{
    ps_camera_sim_tag_t truth[PS_CAMERA_SIM_MAX_TAGS];
    uint64_t truth_seq = 0;
    const int n = ps_camera_sim_truth(app->camera_sim, truth, PS_CAMERA_SIM_MAX_TAGS, &truth_seq);
    if (n < 0 || truth_seq != seq)
        return;
    uint32_t n_visible = 0, n_found = 0;
    double worst = 0;
    for (int t = 0; t < n; t++) {
        if (!(truth[t].is_facing && truth[t].is_in_view && truth[t].is_unoccluded))
            continue;
        n_visible++;
        for (uint32_t i = 0; i < n_det; i++) {
            if (det[i].id != truth[t].id)
                continue;
            n_found++;
            double e2 = 0;
            for (int k = 0; k < 3; k++)
                e2 += pow(det[i].pos_robot_m[k] - truth[t].pos_robot_m[k], 2);
            worst = fmax(worst, sqrt(e2));
        }
    }
    printf("truth: the scene has %d tags, %u seen whole by the camera, %u of them detected, "
           "largest position error %.1f mm (robot frame)\n",
           n, n_visible, n_found, worst * 1e3);
    cJSON *t = cJSON_AddObjectToObject(json, "truth");
    cJSON_AddNumberToObject(t, "tags_in_scene", n);
    cJSON_AddNumberToObject(t, "tags_seen_whole", n_visible);
    cJSON_AddNumberToObject(t, "tags_detected", n_found);
    cJSON_AddNumberToObject(t, "max_error_mm", worst * 1e3);
}

static cJSON *stats_json(const ps_perception_stats_t *st, double span_s)
{
    cJSON *j = cJSON_CreateObject();
    cJSON_AddNumberToObject(j, "frames", (double)st->n_frames);
    cJSON_AddNumberToObject(j, "frames_per_s", span_s > 0 ? (st->n_published - 1.0) / span_s : 0);
    cJSON_AddNumberToObject(j, "tags", (double)st->n_tags);
    cJSON_AddNumberToObject(j, "tags_per_s", span_s > 0 ? st->n_tags / span_s : 0);
    cJSON_AddNumberToObject(j, "errors", (double)st->n_errors);
    cJSON_AddNumberToObject(j, "timeouts", (double)st->n_timeouts);
    const struct {
        const char *name;
        const ps_perf_hist_t *h;
    } hs[] = {{"latency_ms", &st->latency}, {"detect_ms", &st->detect}};
    for (size_t i = 0; i < 2; i++) {
        cJSON *h = cJSON_AddObjectToObject(j, hs[i].name);
        cJSON_AddNumberToObject(h, "n", (double)hs[i].h->n);
        cJSON_AddNumberToObject(h, "min", ms(hs[i].h->min_ns));
        cJSON_AddNumberToObject(h, "p50", ms(ps_perf_quantile_ns(hs[i].h, 0.5)));
        cJSON_AddNumberToObject(h, "p90", ms(ps_perf_quantile_ns(hs[i].h, 0.9)));
        cJSON_AddNumberToObject(h, "p99", ms(ps_perf_quantile_ns(hs[i].h, 0.99)));
        cJSON_AddNumberToObject(h, "max", ms(hs[i].h->max_ns));
        cJSON_AddNumberToObject(h, "mean", ps_perf_mean_ns(hs[i].h) * 1e-6);
    }
    return j;
}

static int write_text(const char *path, const char *text)
{
    FILE *f = fopen(path, "w");
    if (f == NULL)
        return -errno;
    const bool is_ok = fputs(text, f) >= 0 && fputc('\n', f) != EOF;
    return fclose(f) == 0 && is_ok ? 0 : -EIO;
}

static int report(ps_app_t *app, const camview_opts_t *o)
{
    const ps_camera_cfg_t *cc = &app->board.perception.camera;
    ps_perception_stats_t st;
    ps_perception_get_stats(&app->perception, &st);
    const double span_s = ps_ns_to_s(st.t_last_mono_ns - st.t_first_mono_ns);
    const double fps = span_s > 0 ? (st.n_published - 1.0) / span_s : 0;
    printf("camera: %llu frames (%.1f/s), %llu tags (%.1f/s), %llu errors, %llu timeouts\n",
           (unsigned long long)st.n_frames, fps, (unsigned long long)st.n_tags,
           span_s > 0 ? st.n_tags / span_s : 0, (unsigned long long)st.n_errors,
           (unsigned long long)st.n_timeouts);
    printf("latency, exposure to mailbox: min %.1f p50 %.1f p99 %.1f max %.1f ms; detection "
           "(grey + tags) p50 %.1f p99 %.1f ms\n",
           ms(st.latency.min_ns), ms(ps_perf_quantile_ns(&st.latency, 0.5)),
           ms(ps_perf_quantile_ns(&st.latency, 0.99)), ms(st.latency.max_ns),
           ms(ps_perf_quantile_ns(&st.detect, 0.5)), ms(ps_perf_quantile_ns(&st.detect, 0.99)));
    cJSON *json = cJSON_CreateObject();
    cJSON_AddStringToObject(json, "board", app->board_path);
    cJSON_AddStringToObject(json, "source", ps_camera_source_name(cc->source));
    cJSON_AddNumberToObject(json, "width", cc->width);
    cJSON_AddNumberToObject(json, "height", cc->height);
    cJSON_AddNumberToObject(json, "fps_asked", cc->fps);
    cJSON_AddItemToObject(json, "stats", stats_json(&st, span_s));
    const size_t n_px = (size_t)cc->width * cc->height;
    uint8_t *grey = malloc(n_px);
    ps_tags_det_t det[PS_TAGS_MAX_DETECTIONS];
    uint64_t seq = 0;
    const int n = grey != NULL ? ps_perception_snapshot(&app->perception, grey, n_px, det,
                                                        PS_TAGS_MAX_DETECTIONS, &seq)
                               : -ENOMEM;
    int rc = 0;
    if (n >= 0) {
        cJSON *arr = cJSON_AddArrayToObject(json, "last_frame_detections");
        for (int i = 0; i < n; i++) {
            cJSON *d = cJSON_CreateObject();
            cJSON_AddNumberToObject(d, "id", det[i].id);
            cJSON_AddNumberToObject(d, "neighbour", det[i].id / 2);
            cJSON_AddStringToObject(d, "side", det[i].id % 2 ? "right" : "left");
            cJSON_AddItemToObject(d, "pos_robot_m",
                                  cJSON_CreateFloatArray(det[i].pos_robot_m, 3));
            cJSON_AddNumberToObject(d, "confidence", det[i].confidence);
            cJSON_AddNumberToObject(d, "margin", det[i].margin);
            cJSON_AddItemToArray(arr, d);
            printf("  tag %d (neighbour %d, %s shoulder): %.3f %.3f %.3f m, confidence %.2f\n",
                   det[i].id, det[i].id / 2, det[i].id % 2 ? "right" : "left",
                   det[i].pos_robot_m[0], det[i].pos_robot_m[1], det[i].pos_robot_m[2],
                   det[i].confidence);
        }
        if (app->camera_sim != NULL)
            compare_truth(app, det, (uint32_t)n, seq, json);
        char path[PATH_MAX], err[PS_ERR_MSG_LEN];
        snprintf(path, sizeof(path), "%s/camera.png", o->out_dir);
        rc = ps_camview_write_png(path, grey, cc->width, cc->height, det, (uint32_t)n, err,
                                  sizeof(err));
        if (rc < 0)
            fprintf(stderr, "pushstep camera: %s\n", err);
        else
            printf("wrote %s (frame %llu, %d tags drawn)\n", path, (unsigned long long)seq, n);
    } else {
        fprintf(stderr, "pushstep camera: no frame came from the camera\n");
        rc = -ENODATA;
    }
    free(grey);
    char path[PATH_MAX];
    snprintf(path, sizeof(path), "%s/camera.json", o->out_dir);
    char *text = cJSON_Print(json);
    const int wrc = text != NULL ? write_text(path, text) : -ENOMEM;
    if (wrc < 0) {
        fprintf(stderr, "pushstep camera: %s: %s\n", path, ps_strerror(wrc));
        rc = rc < 0 ? rc : wrc;
    } else {
        printf("wrote %s\n", path);
    }
    free(text);
    cJSON_Delete(json);
    return rc;
}

int ps_camview_main(int argc, char **argv, const char *data_dir)
{
    camview_opts_t o;
    if (parse(argc, argv, &o) < 0)
        return 2;
    if (mkdir(o.out_dir, 0755) < 0 && errno != EEXIST) {
        fprintf(stderr, "pushstep camera: --out %s: %s\n", o.out_dir, strerror(errno));
        return 2;
    }
    struct sigaction sa;
    memset(&sa, 0, sizeof(sa));
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    (void)sigaction(SIGINT, &sa, NULL); /* cannot fail for these signals */
    (void)sigaction(SIGTERM, &sa, NULL);
    static ps_app_t app; /* large */
    const ps_app_opts_t ao = {.data_dir = data_dir,
                              .board = o.board,
                              .robot = o.robot,
                              .scenario = o.scenario,
                              .is_camera_only = true};
    char err[PS_ERR_MSG_LEN];
    const int rc = ps_app_init(&app, &ao, err, sizeof(err));
    if (rc < 0) {
        fprintf(stderr, "pushstep camera: %s\n", err);
        return rc == -PS_ERR_CONFIG || rc == -ENOENT ? 2 : 1;
    }
    const ps_camera_cfg_t *cc = &app.board.perception.camera;
    printf("camera: %s source on board %s (%s), %ux%u%s%s at %.1f frames/s; %.1f s\n",
           ps_camera_source_name(cc->source), app.board.name, app.board_path, cc->width,
           cc->height, cc->source == PS_CAMERA_SRC_LIBCAMERA ? " " : "",
           cc->source == PS_CAMERA_SRC_LIBCAMERA ? ps_camera_format_name(cc->format) : "",
           (double)cc->fps, o.duration_s);
    fflush(stdout);
    const int64_t end_ns = ps_s_to_ns(o.duration_s);
    for (int64_t t = 0; t < end_ns && !g_stop && !ps_perception_has_ended(&app.perception);
         t += POLL_NS)
        sleep_ns(POLL_NS);
    ps_perception_stop(&app.perception); /* the last frame's snapshot and truth agree */
    const int report_rc = report(&app, &o);
    ps_app_deinit(&app);
    return report_rc < 0 ? 1 : 0;
}
