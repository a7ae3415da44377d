/* libFuzzer target: scenario files (rt/ps_config_scenario.c, scenarios/ *.yaml)
 * through ps_config_load_scenario (tests/fuzz/fuzz_config.h). A loaded
 * scenario has at most PS_MAX_PUSHES pushes and PS_MAX_EVENTS events, every
 * time, duration and force finite, times and durations not negative. */
#include "../../rt/ps_config_sim.h"
#include "fuzz_config.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static ps_scenario_cfg_t s;
    char path[64], err[FUZZ_CONFIG_ERR_LEN];
    const int fd = fuzz_memfd(data, size, path, sizeof path);
    if (fd < 0)
        return 0;
    const int rc = ps_config_load_scenario(path, &s, err, sizeof err);
    close(fd);
    fuzz_config_check_err(rc, path, err);
    if (rc == 0) {
        FUZZ_CHECK(s.n_pushes <= PS_MAX_PUSHES && s.n_events <= PS_MAX_EVENTS,
                   "%u pushes, %u events", s.n_pushes, s.n_events);
        FUZZ_CHECK(fuzz_in_range(s.duration_s, 0.0f, INFINITY), "duration_s %g", s.duration_s);
        for (uint32_t i = 0; i < s.n_pushes; i++) {
            const ps_push_cfg_t *p = &s.pushes[i];
            FUZZ_CHECK(fuzz_in_range(p->t_s, 0.0f, INFINITY) &&
                           fuzz_in_range(p->duration_s, 0.0f, INFINITY) &&
                           isfinite(p->force_n[0]) && isfinite(p->force_n[1]) &&
                           isfinite(p->force_n[2]),
                       "push %u: t %g duration %g", i, p->t_s, p->duration_s);
        }
        for (uint32_t i = 0; i < s.n_events; i++)
            FUZZ_CHECK(fuzz_in_range(s.events[i].t_s, 0.0f, INFINITY) &&
                           (unsigned)s.events[i].kind < PS_EVENT_COUNT &&
                           fuzz_in_range(s.events[i].duration_s, 0.0f, INFINITY),
                       "event %u: t %g kind %d", i, s.events[i].t_s, (int)s.events[i].kind);
    }
    return 0;
}
