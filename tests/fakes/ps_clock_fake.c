#include "ps_clock_fake.h"

#include <string.h>

static int64_t fake_now_ns(void *ctx)
{
    ps_clock_fake_t *f = ctx;
    const int64_t t_ns = f->now_ns;
    if (f->n_now_calls < f->n_now_extra_script)
        f->now_ns += f->now_extra_script_ns[f->n_now_calls];
    f->n_now_calls++;
    return t_ns;
}

static int fake_sleep_until_ns(void *ctx, int64_t deadline_ns)
{
    ps_clock_fake_t *f = ctx;
    const size_t i = f->n_sleep_calls++;
    if (i < PS_CLOCK_FAKE_MAX_CALLS)
        f->sleep_deadlines_ns[i] = deadline_ns;
    if (i < f->n_rc_script && f->rc_script[i] < 0)
        return f->rc_script[i];
    const int64_t latency_ns =
        i < f->n_latency_script ? f->latency_script_ns[i] : f->wake_latency_ns;
    if (deadline_ns > f->now_ns)
        f->now_ns = deadline_ns;
    f->now_ns += latency_ns;
    return 0;
}

void ps_clock_fake_init(ps_clock_fake_t *f, int64_t start_ns)
{
    memset(f, 0, sizeof(*f));
    f->clock.now_ns = fake_now_ns;
    f->clock.sleep_until_ns = fake_sleep_until_ns;
    f->clock.ctx = f;
    f->now_ns = start_ns;
}

void ps_clock_fake_set(ps_clock_fake_t *f, int64_t t_ns)
{
    f->now_ns = t_ns;
}

void ps_clock_fake_advance(ps_clock_fake_t *f, int64_t dt_ns)
{
    f->now_ns += dt_ns;
}
