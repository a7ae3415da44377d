/*
 * Tests of drivers/ps_camera_libcamera on a real kernel camera, run inside
 * the qemu VM of `make test-hw`: the vimc test driver (built out of tree
 * from Debian's kernel source by tools/qemu/setup-all.sh, loaded by
 * tools/qemu/guest-modules.sh) seen through the host's libcamera 0.0.3 (its
 * vimc pipeline handler, and libcamera-ipa's vimc IPA module), which finds
 * the media devices through udev (tools/qemu/in-vm.sh runs udevd around this
 * binary). vimc's "Sensor B" camera streams a test pattern, BGR888.
 *
 * - frames come in order, on CLOCK_MONOTONIC, with the pattern in them, and
 *   every buffer goes back (more frames than buffers);
 * - through the perception thread into the mailbox: the loop's side takes
 *   fresh lists (no tags in the pattern: empty, but valid);
 * - `pushstep camera --board tests/data/boards/vm-camera.yaml` runs on it;
 * - a camera that is not there, and a format it cannot give, are refused
 *   with what libcamera sees / offers.
 *
 * Timing under qemu TCG is slow (a few frames a second at 640 x 480): waits
 * are long, and nothing here measures speed.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "../../drivers/ps_camera_libcamera.h"
#include "../../rt/ps_clock.h"
#include "../../rt/ps_err.h"
#include "../../rt/ps_perception.h"

/* libcamera 0.0.3's vimc pipeline adjusts 640 x 480 to 636 x 480 (its
 * scaler's steps); the board's intrinsics hold for one size, so ask for it. */
#define W 636u
#define H 480u
#define FRAME_WAIT_NS (10 * PS_NS_PER_S)

static ps_camera_cfg_t vimc_cfg(void)
{
    return (ps_camera_cfg_t){.source = PS_CAMERA_SRC_LIBCAMERA,
                             .id = "vimc",
                             .width = W,
                             .height = H,
                             .format = PS_PIX_BGR888,
                             .fps = 30.0f};
}

static void test_hw_camera_vimc_frames_in_order_monotonic_buffers_reused(void **state)
{
    (void)state;
    const ps_camera_cfg_t cfg = vimc_cfg();
    ps_camera_libcamera_t *c = NULL;
    assert_int_equal(ps_camera_libcamera_create(&cfg, &c, NULL, 0), 0);
    ps_camera_port_t port = ps_camera_libcamera_port(c);
    char err[PS_ERR_MSG_LEN] = "";
    const int rc = port.ops->start(port.ctx, err, sizeof(err));
    if (rc != 0)
        fail_msg("start: %s (%s)", err, ps_strerror(rc));
    uint64_t prev_seq = 0;
    int64_t prev_t = 0;
    const unsigned n = 2 * PS_CAMERA_LIBCAMERA_BUFFERS + 2; /* every buffer twice */
    for (unsigned i = 0; i < n; i++) {
        ps_camera_frame_t fr;
        const int r = port.ops->next(port.ctx, &fr, FRAME_WAIT_NS);
        if (r != 0)
            fail_msg("frame %u: %s", i, ps_strerror(r));
        const int64_t now = ps_clock_now_ns(ps_clock_monotonic());
        assert_int_equal(fr.width, W);
        assert_int_equal(fr.height, H);
        assert_int_equal(fr.format, PS_PIX_BGR888);
        assert_true(fr.stride >= 3 * W);
        assert_true(fr.n_bytes >= (size_t)(H - 1) * fr.stride + 3 * W);
        assert_true(fr.t_ns > 0 && fr.t_ns <= now && fr.t_ns > now - 5 * PS_NS_PER_S);
        assert_int_equal(fr.t_mono_ns, fr.t_ns);
        if (i > 0) {
            assert_true(fr.seq > prev_seq);
            assert_true(fr.t_ns > prev_t);
        }
        prev_seq = fr.seq;
        prev_t = fr.t_ns;
        /* the test pattern: not one colour */
        unsigned lo = 255, hi = 0;
        for (uint32_t x = 0; x < 3 * W; x++) {
            const uint8_t v = fr.data[(H / 2) * fr.stride + x];
            lo = v < lo ? v : lo;
            hi = v > hi ? v : hi;
        }
        assert_true(hi - lo > 50);
        port.ops->release(port.ctx, &fr);
    }
    print_message("%u frames from %s, seq up to %llu, %lu bad\n", n, cfg.id,
                  (unsigned long long)prev_seq, ps_camera_libcamera_n_bad_frames(c));
    port.ops->stop(port.ctx);
    port.ops->stop(port.ctx); /* twice is fine */
    ps_camera_libcamera_destroy(c);
}

static void test_hw_camera_vimc_through_perception_into_mailbox(void **state)
{
    (void)state;
    ps_perception_cfg_t pc = {
        .camera = vimc_cfg(),
        .tags = {.k = {600, 600, 318, 240}, .tag_size_m = 0.12f, .n_threads = 1,
                 .decimate = 2.0f, .min_margin = 20.0f},
        .max_age_s = 2.0f,
    };
    ps_camera_libcamera_t *c = NULL;
    assert_int_equal(ps_camera_libcamera_create(&pc.camera, &c, NULL, 0), 0);
    static ps_perception_t p;
    char err[PS_ERR_MSG_LEN] = "";
    assert_int_equal(ps_perception_init(&p, &pc, ps_camera_libcamera_port(c), false, err,
                                        sizeof(err)),
                     0);
    if (ps_perception_start(&p, -1, err, sizeof(err)) != 0)
        fail_msg("start: %s", err);
    ps_mailbox_t *mb = ps_perception_mailbox(&p);
    ps_neighbours_t nb;
    memset(&nb, 0, sizeof(nb));
    unsigned n_taken = 0, n_valid = 0;
    const int64_t end = ps_clock_now_ns(ps_clock_monotonic()) + 30 * PS_NS_PER_S;
    while (n_taken < 5 && ps_clock_now_ns(ps_clock_monotonic()) < end) {
        const struct timespec ts = {0, 10 * 1000 * 1000};
        nanosleep(&ts, NULL);
        const int64_t now = ps_clock_now_ns(ps_clock_monotonic());
        if (ps_perception_take(mb, now, ps_s_to_ns(pc.max_age_s), &nb)) {
            n_taken++;
            n_valid += nb.is_valid;
            assert_int_equal(nb.n_shoulders, 0); /* a test pattern has no tags */
            assert_true(nb.t_exposure_ns <= now);
        }
    }
    ps_perception_stop(&p);
    ps_perception_stats_t st;
    ps_perception_get_stats(&p, &st);
    print_message("mailbox: %u lists taken, %u fresh; %llu frames, exposure to mailbox p50 "
                  "%.1f ms in the VM\n",
                  n_taken, n_valid, (unsigned long long)st.n_frames,
                  (double)ps_perf_quantile_ns(&st.latency, 0.5) * 1e-6);
    assert_true(n_taken >= 5);
    assert_true(n_valid >= 1);
    assert_int_equal(st.n_errors, 0);
    assert_true(st.n_published >= n_taken);
    ps_perception_deinit(&p);
    ps_camera_libcamera_destroy(c);
}

/* `pushstep camera` on the VM's camera: frames counted, a PNG and JSON
 * written, exit 0. */
static void test_hw_camera_pushstep_camera_tool_on_vimc(void **state)
{
    (void)state;
    char dir[] = "build/hw_camera_XXXXXX"; /* the repository is shared with the host */
    assert_non_null(mkdtemp(dir));
    char cmd[512];
    snprintf(cmd, sizeof(cmd),
             "build/pushstep camera --board tests/data/boards/vm-camera.yaml --duration 4 "
             "--out %s 2>&1",
             dir);
    FILE *p = popen(cmd, "r");
    assert_non_null(p);
    static char out[16384];
    const size_t n = fread(out, 1, sizeof(out) - 1, p);
    out[n] = '\0';
    const int status = pclose(p);
    print_message("%s", out);
    assert_true(WIFEXITED(status) && WEXITSTATUS(status) == 0);
    unsigned long long frames = 0;
    const char *line = strstr(out, "camera: ");
    line = line != NULL ? strstr(line + 1, "camera: ") : NULL; /* the report, after the banner */
    assert_non_null(line);
    assert_int_equal(sscanf(line, "camera: %llu frames", &frames), 1);
    assert_true(frames >= 2);
    char path[128];
    snprintf(path, sizeof(path), "%s/camera.png", dir);
    assert_int_equal(access(path, R_OK), 0);
    snprintf(path, sizeof(path), "%s/camera.json", dir);
    assert_int_equal(access(path, R_OK), 0);
    snprintf(cmd, sizeof(cmd), "rm -rf '%s'", dir);
    assert_int_equal(system(cmd), 0);
}

static void test_hw_camera_missing_camera_enodev_lists_cameras(void **state)
{
    (void)state;
    ps_camera_cfg_t cfg = vimc_cfg();
    snprintf(cfg.id, sizeof(cfg.id), "imx999");
    ps_camera_libcamera_t *c = NULL;
    assert_int_equal(ps_camera_libcamera_create(&cfg, &c, NULL, 0), 0);
    ps_camera_port_t port = ps_camera_libcamera_port(c);
    char err[PS_ERR_MSG_LEN] = "";
    assert_int_equal(port.ops->start(port.ctx, err, sizeof(err)), -ENODEV);
    print_message("%s\n", err);
    assert_non_null(strstr(err, "no camera \"imx999\""));
    assert_non_null(strstr(err, "vimc"));
    ps_camera_libcamera_destroy(c);
}

static void test_hw_camera_format_not_offered_einval_says_offer(void **state)
{
    (void)state;
    ps_camera_cfg_t cfg = vimc_cfg();
    cfg.format = PS_PIX_R8; /* vimc's capture gives BGR888 only */
    ps_camera_libcamera_t *c = NULL;
    assert_int_equal(ps_camera_libcamera_create(&cfg, &c, NULL, 0), 0);
    ps_camera_port_t port = ps_camera_libcamera_port(c);
    char err[PS_ERR_MSG_LEN] = "";
    assert_int_equal(port.ops->start(port.ctx, err, sizeof(err)), -EINVAL);
    print_message("%s\n", err);
    assert_non_null(strstr(err, "cannot stream 636x480 R8"));
    assert_non_null(strstr(err, "it offers"));
    ps_camera_libcamera_destroy(c);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_hw_camera_vimc_frames_in_order_monotonic_buffers_reused),
        cmocka_unit_test(test_hw_camera_vimc_through_perception_into_mailbox),
        cmocka_unit_test(test_hw_camera_pushstep_camera_tool_on_vimc),
        cmocka_unit_test(test_hw_camera_missing_camera_enodev_lists_cameras),
        cmocka_unit_test(test_hw_camera_format_not_offered_einval_says_offer),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
