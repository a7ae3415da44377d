#include "ps_camview.h"

#include <cairo.h>
#include <cjson/cJSON.h>
#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>

#include "ps_app.h"
#include "ps_err.h"

#define CAPTION_PX 22
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
    const char *out_dir;
    double duration_s;
} camview_opts_t;

static const char USAGE[] =
    "usage: pushstep camera --board NAME|FILE [--robot FILE] [--duration S] [--out DIR]\n"
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
    "  --duration S        run S seconds (default 5; an image folder ends sooner\n"
    "                      only when Ctrl-C stops it)\n"
    "  --out DIR           output folder (default ./camera)\n";

static int parse(int argc, char **argv, camview_opts_t *o)
{
    static const struct option LONG[] = {
        {"board", required_argument, NULL, 'b'},    {"robot", required_argument, NULL, 'r'},
        {"duration", required_argument, NULL, 'd'}, {"out", required_argument, NULL, 'o'},
        {"help", no_argument, NULL, 'h'},           {NULL, 0, NULL, 0},
    };
    *o = (camview_opts_t){.out_dir = "camera", .duration_s = 5.0};
    int c;
    char *end;
    while ((c = getopt_long(argc, argv, "h", LONG, NULL)) != -1) {
        switch (c) {
        case 'b':
            o->board = optarg;
            break;
        case 'r':
            o->robot = optarg;
            break;
        case 'o':
            o->out_dir = optarg;
            break;
        case 'd':
            o->duration_s = strtod(optarg, &end);
            if (*end != '\0' || !isfinite(o->duration_s) || o->duration_s <= 0 ||
                o->duration_s > 86400) {
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

int ps_camview_write_png(const char *path, const uint8_t *grey, uint32_t width, uint32_t height,
                         const ps_tags_det_t *det, uint32_t n_det, const char *caption,
                         char *err, size_t err_len)
{
    cairo_surface_t *s =
        cairo_image_surface_create(CAIRO_FORMAT_RGB24, (int)width, (int)height + CAPTION_PX);
    if (cairo_surface_status(s) != CAIRO_STATUS_SUCCESS) {
        ps_err_format(err, err_len, "%s: %s", path,
                      cairo_status_to_string(cairo_surface_status(s)));
        cairo_surface_destroy(s);
        return -ENOMEM;
    }
    cairo_surface_flush(s);
    uint8_t *px = cairo_image_surface_get_data(s);
    const int stride = cairo_image_surface_get_stride(s);
    for (uint32_t y = 0; y < height; y++) {
        uint32_t *row = (uint32_t *)(void *)(px + (size_t)(y + CAPTION_PX) * (size_t)stride);
        for (uint32_t x = 0; x < width; x++)
            row[x] = 0x010101u * grey[(size_t)y * width + x];
    }
    cairo_surface_mark_dirty(s);
    cairo_t *cr = cairo_create(s);
    cairo_set_source_rgb(cr, 0.1, 0.1, 0.1);
    cairo_rectangle(cr, 0, 0, width, CAPTION_PX);
    cairo_fill(cr);
    cairo_select_font_face(cr, "monospace", CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_NORMAL);
    cairo_set_font_size(cr, 12);
    cairo_set_source_rgb(cr, 1, 1, 1);
    cairo_move_to(cr, 4, 15);
    cairo_show_text(cr, caption);
    cairo_translate(cr, 0, CAPTION_PX);
    cairo_set_line_width(cr, 2);
    for (uint32_t i = 0; i < n_det; i++) {
        const ps_tags_det_t *d = &det[i];
        cairo_set_source_rgb(cr, 0.1, 0.9, 0.2);
        cairo_move_to(cr, d->corners_px[0][0], d->corners_px[0][1]);
        for (int k = 1; k < 4; k++)
            cairo_line_to(cr, d->corners_px[k][0], d->corners_px[k][1]);
        cairo_close_path(cr);
        cairo_stroke(cr);
        cairo_set_source_rgb(cr, 1.0, 0.2, 0.2);
        cairo_move_to(cr, d->centre_px[0] - 4, d->centre_px[1]);
        cairo_line_to(cr, d->centre_px[0] + 4, d->centre_px[1]);
        cairo_move_to(cr, d->centre_px[0], d->centre_px[1] - 4);
        cairo_line_to(cr, d->centre_px[0], d->centre_px[1] + 4);
        cairo_stroke(cr);
        const double dist = sqrt((double)d->pos_cam_m[0] * d->pos_cam_m[0] +
                                 (double)d->pos_cam_m[1] * d->pos_cam_m[1] +
                                 (double)d->pos_cam_m[2] * d->pos_cam_m[2]);
        char label[64];
        snprintf(label, sizeof(label), "id %d n%d %s %.2fm", d->id, d->id / 2,
                 d->id % 2 ? "R" : "L", dist);
        double top = d->corners_px[0][1], bottom = top, left = d->corners_px[0][0];
        for (int k = 1; k < 4; k++) {
            top = fmin(top, d->corners_px[k][1]);
            bottom = fmax(bottom, d->corners_px[k][1]);
            left = fmin(left, d->corners_px[k][0]);
        }
        cairo_text_extents_t te;
        cairo_text_extents(cr, label, &te);
        /* left shoulders' labels above the tag, right shoulders' below: the
         * two tags of a person stand side by side */
        const double tx = fmax(0, fmin(left, width - te.x_advance - 2));
        const double ty = d->id % 2 == 0 ? fmax(te.height + 2, top - 4)
                                         : fmin(height - 3.0, bottom + te.height + 4);
        cairo_set_source_rgb(cr, 0, 0, 0);
        cairo_rectangle(cr, tx - 1, ty - te.height - 2, te.x_advance + 2, te.height + 4);
        cairo_fill(cr);
        cairo_set_source_rgb(cr, 1, 1, 0.3);
        cairo_move_to(cr, tx, ty);
        cairo_show_text(cr, label);
    }
    cairo_destroy(cr);
    const cairo_status_t st = cairo_surface_write_to_png(s, path);
    cairo_surface_destroy(s);
    if (st != CAIRO_STATUS_SUCCESS) {
        ps_err_format(err, err_len, "%s: %s", path, cairo_status_to_string(st));
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
    const ps_camera_cfg_t *cc = &app->board.camera.camera;
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
        char path[PATH_MAX], caption[160], err[PS_ERR_MSG_LEN];
        snprintf(path, sizeof(path), "%s/camera.png", o->out_dir);
        snprintf(caption, sizeof(caption),
                 "frame %llu  %ux%u %s  %.1f frames/s  %d tags  exposure->mailbox p50 %.1f ms",
                 (unsigned long long)seq, cc->width, cc->height,
                 ps_camera_source_name(cc->source), fps, n,
                 ms(ps_perf_quantile_ns(&st.latency, 0.5)));
        rc = ps_camview_write_png(path, grey, cc->width, cc->height, det, (uint32_t)n, caption,
                                  err, sizeof(err));
        if (rc < 0)
            fprintf(stderr, "pushstep camera: %s\n", err);
        else
            printf("wrote %s (%d tags drawn)\n", path, n);
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
    const ps_app_opts_t ao = {
        .data_dir = data_dir, .board = o.board, .robot = o.robot, .is_camera_only = true};
    char err[PS_ERR_MSG_LEN];
    const int rc = ps_app_init(&app, &ao, err, sizeof(err));
    if (rc < 0) {
        fprintf(stderr, "pushstep camera: %s\n", err);
        return rc == -PS_ERR_CONFIG || rc == -ENOENT ? 2 : 1;
    }
    const ps_camera_cfg_t *cc = &app.board.camera.camera;
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
