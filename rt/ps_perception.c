#include "ps_perception.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "ps_clock.h"
#include "ps_err.h"
#include "ps_rtsetup.h"

/* How long the thread waits for a frame before it looks at is_running again. */
#define FRAME_WAIT_NS (100 * PS_NS_PER_MS)
/* After a camera error, before the next try (no busy loop on a dead camera). */
#define ERROR_PAUSE_NS (20 * PS_NS_PER_MS)

int ps_perception_init(ps_perception_t *p, const ps_perception_cfg_t *cfg,
                       ps_camera_port_t port, bool keep_snapshot, char *err, size_t err_len)
{
    if (p == NULL || cfg == NULL || port.ops == NULL)
        return -EINVAL;
    memset(p, 0, sizeof(*p));
    p->cfg = *cfg;
    p->port = port;
    p->cpu = -1;
    atomic_init(&p->is_running, false);
    atomic_init(&p->has_ended, false);
    const size_t n_px = (size_t)cfg->camera.width * cfg->camera.height;
    if (n_px == 0 || cfg->camera.width > PS_CAMERA_MAX_WIDTH ||
        cfg->camera.height > PS_CAMERA_MAX_HEIGHT) {
        ps_err_format(err, err_len, "camera: image size %ux%u", cfg->camera.width,
                      cfg->camera.height);
        return -EINVAL;
    }
    int rc = ps_tags_create(&cfg->tags, &p->tags, err, err_len);
    if (rc < 0)
        return rc;
    p->grey = malloc(n_px);
    p->is_snapshot_kept = keep_snapshot;
    if (keep_snapshot)
        p->snap_grey = malloc(n_px);
    if (p->grey == NULL || (keep_snapshot && p->snap_grey == NULL)) {
        ps_err_format(err, err_len, "camera: no memory for a %ux%u image", cfg->camera.width,
                      cfg->camera.height);
        ps_perception_deinit(p);
        return -ENOMEM;
    }
    rc = ps_mailbox_init(&p->mailbox, p->mailbox_slots, sizeof(p->mailbox_slots[0]));
    if (rc == 0)
        rc = -pthread_mutex_init(&p->mu, NULL);
    p->has_mutex = rc == 0;
    if (rc == 0)
        rc = sem_init(&p->started, 0, 0) == 0 ? 0 : -errno;
    p->has_sem = rc == 0;
    if (rc < 0) {
        ps_err_format(err, err_len, "camera: %s", ps_strerror(rc));
        ps_perception_deinit(p);
        return rc;
    }
    ps_perf_reset(&p->stats.latency);
    ps_perf_reset(&p->stats.detect);
    return 0;
}

ps_mailbox_t *ps_perception_mailbox(ps_perception_t *p)
{
    return &p->mailbox;
}

static void pause_ns(int64_t ns)
{
    const ps_clock_t *mono = ps_clock_monotonic();
    (void)ps_clock_sleep_until_ns(mono, ps_clock_now_ns(mono) + ns); /* EINTR: shorter */
}

/* One frame: grey, detect, publish; the figures and the snapshot after. */
static void process(ps_perception_t *p, const ps_camera_frame_t *fr)
{
    const ps_clock_t *mono = ps_clock_monotonic();
    const int64_t t0 = ps_clock_now_ns(mono);
    const ps_camera_cfg_t *c = &p->cfg.camera;
    const size_t n_px = (size_t)c->width * c->height;
    const bool is_size_ok = fr->width == c->width && fr->height == c->height;
    const int conv_rc = is_size_ok ? ps_camera_to_grey(fr, p->grey, n_px) : -EINVAL;
    const int64_t t_ns = fr->t_ns, t_mono_ns = fr->t_mono_ns;
    const uint64_t seq = fr->seq;
    p->port.ops->release(p->port.ctx, fr); /* the buffer goes back to the camera now */
    ps_tags_det_t det[PS_TAGS_MAX_DETECTIONS];
    const int n = conv_rc == 0 ? ps_tags_detect(p->tags, p->grey, c->width, c->height, c->width,
                                                det, PS_TAGS_MAX_DETECTIONS)
                               : conv_rc;
    const int64_t t1 = ps_clock_now_ns(mono);
    uint32_t n_left_out = 0;
    if (n >= 0) {
        ps_neighbours_t *slot = ps_mailbox_write_slot(&p->mailbox);
        n_left_out = ps_tags_to_neighbours(det, (uint32_t)n, t_ns, seq, slot);
        ps_mailbox_publish(&p->mailbox);
    }
    const int64_t t2 = ps_clock_now_ns(mono);
    pthread_mutex_lock(&p->mu);
    ps_perception_stats_t *s = &p->stats;
    s->n_frames++;
    if (n < 0) {
        s->n_errors++;
    } else {
        s->n_tags += (uint64_t)n;
        s->n_published++;
        s->n_left_out += n_left_out;
        if (s->t_first_mono_ns == 0)
            s->t_first_mono_ns = t2;
        s->t_last_mono_ns = t2;
        ps_perf_record(&s->latency, t2 - t_mono_ns);
        ps_perf_record(&s->detect, t1 - t0);
        if (p->is_snapshot_kept) {
            memcpy(p->snap_grey, p->grey, n_px);
            memcpy(p->snap_det, det, (size_t)n * sizeof(det[0]));
            p->n_snap_det = (uint32_t)n;
            p->snap_seq = seq;
            p->has_snap = true;
        }
    }
    pthread_mutex_unlock(&p->mu);
}

static void *perception_main(void *arg)
{
    ps_perception_t *p = arg;
    (void)ps_rtsetup_thread_best_effort(0, p->cpu); /* non-RT: only the CPU */
    p->start_rc = p->port.ops->start(p->port.ctx, p->start_err, sizeof(p->start_err));
    const bool is_ok = p->start_rc == 0;
    (void)sem_post(&p->started); /* cannot fail: the count is far from its limit */
    while (is_ok && atomic_load(&p->is_running)) {
        ps_camera_frame_t fr;
        const int rc = p->port.ops->next(p->port.ctx, &fr, FRAME_WAIT_NS);
        if (rc == 0) {
            process(p, &fr);
        } else if (rc == -ETIMEDOUT) {
            pthread_mutex_lock(&p->mu);
            p->stats.n_timeouts++;
            pthread_mutex_unlock(&p->mu);
        } else if (rc == -ENODATA) {
            atomic_store(&p->has_ended, true);
            break;
        } else {
            pthread_mutex_lock(&p->mu);
            p->stats.n_errors++;
            pthread_mutex_unlock(&p->mu);
            pause_ns(ERROR_PAUSE_NS);
        }
    }
    p->port.ops->stop(p->port.ctx);
    return NULL;
}

int ps_perception_start(ps_perception_t *p, int cpu, char *err, size_t err_len)
{
    if (p == NULL || p->tags == NULL || p->is_thread)
        return -EINVAL;
    p->cpu = cpu;
    p->start_rc = 0;
    p->start_err[0] = '\0';
    atomic_store(&p->is_running, true);
    int rc = -pthread_create(&p->thread, NULL, perception_main, p);
    if (rc < 0) {
        atomic_store(&p->is_running, false);
        ps_err_format(err, err_len, "camera: cannot start its thread: %s", ps_strerror(rc));
        return rc;
    }
    p->is_thread = true;
    while (sem_wait(&p->started) != 0 && errno == EINTR) {
    }
    if (p->start_rc < 0) {
        ps_err_format(err, err_len, "%s", p->start_err[0] ? p->start_err : "camera: start failed");
        rc = p->start_rc;
        ps_perception_stop(p);
        return rc;
    }
    return 0;
}

void ps_perception_stop(ps_perception_t *p)
{
    if (p == NULL || !p->is_thread)
        return;
    atomic_store(&p->is_running, false);
    (void)pthread_join(p->thread, NULL); /* joinable and ours: cannot fail */
    p->is_thread = false;
}

/* A list no thread of ours could have made: more shoulders than it holds, a
 * position or confidence that is not a number in range, a side that is
 * neither, an exposure further in the future than a list may be old (it
 * would never age). */
static bool is_list_sane(const ps_neighbours_t *n, int64_t now_ns, int64_t max_age_ns)
{
    if (n->n_shoulders > PS_MAX_SHOULDERS || n->t_exposure_ns - now_ns > max_age_ns)
        return false;
    for (uint32_t i = 0; i < n->n_shoulders; i++) {
        const ps_shoulder_t *s = &n->shoulders[i];
        if (!isfinite(s->pos_robot_m[0]) || !isfinite(s->pos_robot_m[1]) ||
            !isfinite(s->pos_robot_m[2]) || !(s->confidence >= 0.0f && s->confidence <= 1.0f) ||
            s->side > PS_SHOULDER_RIGHT)
            return false;
    }
    return true;
}

bool ps_perception_take(ps_mailbox_t *mb, int64_t now_ns, int64_t max_age_ns,
                        ps_neighbours_t *inout)
{
    bool is_new = false;
    const ps_neighbours_t *latest = ps_mailbox_read(mb, &is_new);
    if (is_new) {
        *inout = *latest;
        if (!is_list_sane(inout, now_ns, max_age_ns))
            inout->t_exposure_ns = 0; /* refused: no neighbour information until a sane one */
    }
    const bool has_any = inout->t_exposure_ns != 0;
    const int64_t age = now_ns - inout->t_exposure_ns;
    inout->age_ns = has_any ? (age > 0 ? age : 0) : 0;
    inout->is_valid = has_any && inout->age_ns <= max_age_ns;
    if (!inout->is_valid)
        inout->n_shoulders = 0; /* no neighbour information */
    return is_new;
}

void ps_perception_get_stats(ps_perception_t *p, ps_perception_stats_t *out)
{
    pthread_mutex_lock(&p->mu);
    *out = p->stats;
    pthread_mutex_unlock(&p->mu);
}

int ps_perception_snapshot(ps_perception_t *p, uint8_t *grey, size_t grey_len,
                           ps_tags_det_t *det, uint32_t max, uint64_t *out_seq)
{
    const size_t n_px = (size_t)p->cfg.camera.width * p->cfg.camera.height;
    if (!p->is_snapshot_kept || grey == NULL || grey_len < n_px || (det == NULL && max > 0))
        return -EINVAL;
    pthread_mutex_lock(&p->mu);
    int rc = -ENODATA;
    if (p->has_snap) {
        memcpy(grey, p->snap_grey, n_px);
        const uint32_t n = p->n_snap_det < max ? p->n_snap_det : max;
        memcpy(det, p->snap_det, (size_t)n * sizeof(det[0]));
        if (out_seq != NULL)
            *out_seq = p->snap_seq;
        rc = (int)n;
    }
    pthread_mutex_unlock(&p->mu);
    return rc;
}

bool ps_perception_has_ended(ps_perception_t *p)
{
    return atomic_load(&p->has_ended);
}

void ps_perception_deinit(ps_perception_t *p)
{
    if (p == NULL)
        return;
    ps_perception_stop(p);
    ps_tags_destroy(p->tags);
    p->tags = NULL;
    free(p->grey);
    free(p->snap_grey);
    p->grey = p->snap_grey = NULL;
    if (p->has_mutex)
        pthread_mutex_destroy(&p->mu);
    if (p->has_sem)
        sem_destroy(&p->started);
    p->has_mutex = p->has_sem = false;
}
