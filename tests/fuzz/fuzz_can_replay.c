/* libFuzzer target: the candump-log replay (drivers/ps_can_replay.c,
 * `pushstep --replay`) on a whole log as an in-memory file.
 *
 * Four buses can0..can3 and a robot of three joints (RobStride drive 0x01 on
 * can0, moteus 0x0B on can1, MIT 0x01 replying on 0x101 on can3, as in
 * tests/data/robots/ps1-mixed.yaml and ps1-moteus.yaml) with a pushstep IMU
 * at 0x080 on can3 classify the frames. Contract: measure and init
 * return 0 or a documented code with a message naming the file; init into
 * storage of the measured size never says -ENOSPC; replaying the whole log
 * (the clock moved tick by tick to the log's last frame, every bus drained)
 * hands over only valid frames, none stamped after the clock's now (in file
 * order per bus: a log whose times go back is handed over as written), all
 * of them by the end, and exactly as many as the stats count as fed. */
#include <errno.h>

#include "../../drivers/ps_can_replay.h"
#include "../../drivers/ps_imu.h"
#include "../../rt/ps_err.h"
#include "../fakes/ps_test_wire.h"
#include "fuzz.h"

#define PERIOD_NS 1000000LL
#define MAX_TICKS 2000 /* a log longer than 2 s is replayed in part */

static void robot(ps_act_cfg_t act[3])
{
    memset(act, 0, 3 * sizeof act[0]);
    for (int j = 0; j < 3; j++) {
        act[j].wire = ps_test_wire_ak();
        act[j].gear_ratio = 1.0f;
        act[j].direction = 1.0f;
        act[j].kt_nm_a = 0.1f;
        act[j].temp_max_c = 80.0f;
        act[j].rate_div = 1;
    }
    act[0].protocol = PS_ACT_PROTO_MIT;
    act[0].bus_idx = 3;
    act[0].can_id = 0x01;
    act[0].reply_id = 0x101;
    act[1].protocol = PS_ACT_PROTO_ROBSTRIDE;
    act[1].bus_idx = 0;
    act[1].can_id = 0x01;
    act[1].reply_id = 0xFD;
    act[2].protocol = PS_ACT_PROTO_MOTEUS;
    act[2].bus_idx = 1;
    act[2].can_id = 0x0B;
    act[2].reply_id = 0x01;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char path[64], err[512];
    const int fd = fuzz_memfd(data, size, path, sizeof path);
    if (fd < 0)
        return 0;
    static ps_act_cfg_t act[3];
    robot(act);
    ps_can_replay_cfg_t cfg;
    memset(&cfg, 0, sizeof cfg);
    cfg.path = path;
    cfg.n_buses = 4;
    cfg.ifname[0] = "can0";
    cfg.ifname[1] = "can1";
    cfg.ifname[2] = "can2";
    cfg.ifname[3] = "can3";
    cfg.act = act;
    cfg.n_joints = 3;
    cfg.imu_bus_idx = 3;
    const ps_imu_cfg_t imu = {
        .bus_idx = 3, .base_id = 0x080, .rate_div = 1, .protocol = PS_IMU_PROTO_PUSHSTEP};
    uint8_t lens[PS_IMU_MAX_FRAMES];
    cfg.n_imu_ids = ps_imu_frames(&imu, cfg.imu_ids, lens);
    cfg.period_ns = PERIOD_NS;

    ps_can_replay_size_t sz;
    int rc = ps_can_replay_measure(&cfg, &sz, err, sizeof err);
    FUZZ_CHECK(rc == 0 || rc == -PS_ERR_PROTOCOL || rc == -PS_ERR_CONFIG || rc == -EIO,
               "measure returned %d (%s)", rc, err);
    if (rc < 0) {
        FUZZ_CHECK(strncmp(err, path, strlen(path)) == 0, "a message not naming the file: %s", err);
        close(fd);
        return 0;
    }
    ps_can_replay_entry_t *entries = calloc(sz.n_entries > 0 ? sz.n_entries : 1, sizeof(*entries));
    uint8_t *pool = sz.n_data > 0 ? malloc(sz.n_data) : NULL;
    static ps_can_replay_t r;
    rc = entries != NULL && (pool != NULL || sz.n_data == 0)
             ? ps_can_replay_init(&r, &cfg, entries, sz.n_entries, pool, sz.n_data, err, sizeof err)
             : -ENOMEM;
    close(fd);
    FUZZ_CHECK(rc == 0 || rc == -ENOMEM, "init after a measure that passed returned %d (%s)", rc,
               err);
    if (rc == 0) {
        const ps_clock_t *clk = ps_can_replay_clock(&r);
        ps_can_port_t port[4];
        for (uint32_t b = 0; b < 4; b++)
            port[b] = ps_can_replay_port(&r, b);
        uint64_t n_fed = 0;
        const int64_t end_ns = ps_can_replay_last_ns(&r);
        bool is_past_end = false;
        int64_t now = clk->now_ns(clk->ctx);
        FUZZ_CHECK(now == ps_can_replay_start_ns(&r) && now >= PERIOD_NS, "clock starts at %lld",
                   (long long)now);
        for (int tick = 0; tick < MAX_TICKS; tick++) {
            for (int b = 0; b < 4; b++) {
                ps_can_frame_t f[16];
                int n;
                while ((n = ps_can_recv_batch(&port[b], f, 16)) > 0) {
                    for (int k = 0; k < n; k++) {
                        FUZZ_CHECK(ps_can_is_valid_frame(&f[k]), "handed over an invalid frame");
                        FUZZ_CHECK(f[k].t_ns <= now, "frame at %lld handed over at %lld",
                                   (long long)f[k].t_ns, (long long)now);
                    }
                    n_fed += (uint64_t)n;
                }
                FUZZ_CHECK(n == 0, "recv_batch returned %d", n);
            }
            if (now > end_ns) {
                is_past_end = true; /* drained at a time after the last frame */
                break;
            }
            FUZZ_CHECK(clk->sleep_until_ns(clk->ctx, now + PERIOD_NS) == 0, "sleep refused");
            now = clk->now_ns(clk->ctx);
        }
        ps_can_replay_stats_t st;
        ps_can_replay_get_stats(&r, &st);
        FUZZ_CHECK(!is_past_end || st.n_fed == st.n_fed_logged,
                   "%llu of %llu fed frames handed over by the end", (unsigned long long)st.n_fed,
                   (unsigned long long)st.n_fed_logged);
        FUZZ_CHECK(st.n_fed == n_fed, "stats say %llu fed, %llu were", (unsigned long long)st.n_fed,
                   (unsigned long long)n_fed);
        ps_can_replay_deinit(&r);
    }
    free(entries);
    free(pool);
    return 0;
}
