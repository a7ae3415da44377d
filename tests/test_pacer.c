/*
 * Tests of ps_pacer (with the fake clock) and of ps_clock_monotonic.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>

#include "../rt/ps_clock.h"
#include "../rt/ps_pacer.h"
#include "fakes/ps_clock_fake.h"

#define PERIOD_NS 1000000LL    /* 1 kHz */
#define START_NS  5000000123LL /* arbitrary, not a multiple of the period */

static int setup_fake(void **state)
{
    static ps_clock_fake_t fake;
    ps_clock_fake_init(&fake, START_NS - 250000);
    *state = &fake;
    return 0;
}

static void test_ps_pacer_init_bad_args_einval(void **state)
{
    ps_clock_fake_t *f = *state;
    ps_pacer_t p;
    assert_int_equal(ps_pacer_init(&p, &f->clock, 0, START_NS), -EINVAL);
    assert_int_equal(ps_pacer_init(&p, &f->clock, -PERIOD_NS, START_NS), -EINVAL);
    assert_int_equal(ps_pacer_init(&p, NULL, PERIOD_NS, START_NS), -EINVAL);
    assert_int_equal(ps_pacer_init(NULL, &f->clock, PERIOD_NS, START_NS), -EINVAL);
    assert_int_equal(ps_pacer_init(&p, &f->clock, PERIOD_NS, START_NS), 0);
    assert_true(p.next_ns == START_NS);
    assert_true(p.n_overruns == 0 && p.n_missed == 0 && p.tick == 0);
}

/* Every wake is late by a constant; a drifting pacer (now + period) would
 * slip by that latency each tick. */
static void test_ps_pacer_wait_late_wakes_no_drift(void **state)
{
    ps_clock_fake_t *f = *state;
    const int64_t late_ns = 37000;
    const unsigned n_ticks = 3000;
    f->wake_latency_ns = late_ns;
    ps_pacer_t p;
    assert_int_equal(ps_pacer_init(&p, &f->clock, PERIOD_NS, START_NS), 0);
    for (unsigned k = 0; k < n_ticks; k++) {
        const int64_t lat_ns = ps_pacer_wait(&p);
        assert_true(lat_ns == late_ns);
        assert_true(p.last_wake_latency_ns == late_ns);
        assert_true(p.tick == k);
        ps_clock_fake_advance(f, 200000); /* work: 0.2 ms */
        assert_int_equal(ps_pacer_end_tick(&p), 0);
    }
    assert_int_equal(f->n_sleep_calls, n_ticks);
    for (unsigned k = 0; k < n_ticks; k++)
        assert_true(f->sleep_deadlines_ns[k] == START_NS + (int64_t)k * PERIOD_NS);
    assert_true(p.next_ns == START_NS + (int64_t)n_ticks * PERIOD_NS);
    assert_true(p.n_overruns == 0 && p.n_missed == 0);
}

/* Varying scripted latencies are reported one by one, deadlines stay exact. */
static void test_ps_pacer_wait_scripted_latency_reported(void **state)
{
    ps_clock_fake_t *f = *state;
    static int64_t script_ns[500];
    uint32_t x = 12345u;
    for (size_t i = 0; i < 500; i++) {
        x = x * 1103515245u + 12345u;
        script_ns[i] = (int64_t)((x >> 8) % 400000u); /* 0..0.4 ms */
    }
    f->latency_script_ns = script_ns;
    f->n_latency_script = 500;
    ps_pacer_t p;
    assert_int_equal(ps_pacer_init(&p, &f->clock, PERIOD_NS, START_NS), 0);
    for (unsigned k = 0; k < 500; k++) {
        assert_true(ps_pacer_wait(&p) == script_ns[k]);
        assert_true(f->sleep_deadlines_ns[k] == START_NS + (int64_t)k * PERIOD_NS);
        assert_int_equal(ps_pacer_end_tick(&p), 0);
    }
}

/* Run tick 0, make it end at `end_offset_ns` after its own deadline, and
 * check what end_tick and the following wait do. */
static void check_overrun(ps_clock_fake_t *f, int64_t end_offset_ns, uint64_t want_missed)
{
    ps_pacer_t p;
    assert_int_equal(ps_pacer_init(&p, &f->clock, PERIOD_NS, START_NS), 0);
    assert_true(ps_pacer_wait(&p) == 0);
    assert_true(p.tick == 0);
    ps_clock_fake_set(f, START_NS + end_offset_ns);
    assert_int_equal(ps_pacer_end_tick(&p), want_missed);
    assert_int_equal(p.n_overruns, want_missed > 0 ? 1 : 0);
    assert_int_equal(p.n_missed, want_missed);
    const uint64_t next_idx = 1 + want_missed;
    assert_true(p.next_ns == START_NS + (int64_t)next_idx * PERIOD_NS);
    assert_true(p.next_ns > f->now_ns); /* strictly after now */
    assert_true(ps_pacer_wait(&p) == 0);
    assert_true(p.tick == next_idx);
    assert_true(f->sleep_deadlines_ns[1] == START_NS + (int64_t)next_idx * PERIOD_NS);
}

static void test_ps_pacer_end_tick_just_in_time_no_overrun(void **state)
{
    check_overrun(*state, PERIOD_NS - 1, 0);
}

static void test_ps_pacer_end_tick_on_next_deadline_missed_1(void **state)
{
    check_overrun(*state, PERIOD_NS, 1); /* now == deadline counts as late */
}

static void test_ps_pacer_end_tick_overrun_1_period_missed_2(void **state)
{
    /* Ends one full period after the deadline it should have met. */
    check_overrun(*state, 2 * PERIOD_NS, 2);
}

static void test_ps_pacer_end_tick_overrun_half_period_missed_1(void **state)
{
    check_overrun(*state, PERIOD_NS + PERIOD_NS / 2, 1);
}

static void test_ps_pacer_end_tick_overrun_3_5_periods_missed_4(void **state)
{
    /* Ends 3.5 periods after the next deadline: D1, D2, D3, D4 are gone. */
    check_overrun(*state, PERIOD_NS + 3 * PERIOD_NS + PERIOD_NS / 2, 4);
}

/* Overruns accumulate and the grid holds across them; work time comes from
 * the fake's per-now() script (second now() of each tick is end_tick's). */
static void test_ps_pacer_end_tick_overruns_accumulate_on_grid(void **state)
{
    ps_clock_fake_t *f = *state;
    /* now() calls: wait0, end0, wait1, end1, ... Extra time after wait's
     * reading is the tick's work. */
    static const int64_t work_ns[] = {
        100000,  0, /* tick 0: 0.1 ms, on time */
        1500000, 0, /* tick 1: 1.5 periods -> misses D2 */
        300000,  0, /* tick 3: on time */
        3500000, 0, /* tick 4: 3.5 periods -> misses D5, D6, D7 */
        0,       0, /* tick 8 */
    };
    static const uint64_t want_tick[] = {0, 1, 3, 4, 8};
    static const uint64_t want_missed[] = {0, 1, 0, 3, 0};
    f->now_extra_script_ns = work_ns;
    f->n_now_extra_script = sizeof(work_ns) / sizeof(work_ns[0]);
    ps_pacer_t p;
    assert_int_equal(ps_pacer_init(&p, &f->clock, PERIOD_NS, START_NS), 0);
    for (unsigned i = 0; i < 5; i++) {
        assert_true(ps_pacer_wait(&p) >= 0);
        assert_int_equal(p.tick, want_tick[i]);
        assert_true(f->sleep_deadlines_ns[i] == ps_pacer_deadline_ns(&p, want_tick[i]));
        assert_int_equal(ps_pacer_end_tick(&p), want_missed[i]);
        assert_int_equal((p.next_ns - START_NS) % PERIOD_NS, 0);
    }
    assert_int_equal(p.n_overruns, 2);
    assert_int_equal(p.n_missed, 4);
}

static void test_ps_pacer_wait_eintr_retried(void **state)
{
    ps_clock_fake_t *f = *state;
    static const int rc[] = {-EINTR, -EINTR, 0};
    f->rc_script = rc;
    f->n_rc_script = 3;
    f->wake_latency_ns = 1000;
    ps_pacer_t p;
    assert_int_equal(ps_pacer_init(&p, &f->clock, PERIOD_NS, START_NS), 0);
    assert_true(ps_pacer_wait(&p) == 1000);
    assert_int_equal(f->n_sleep_calls, 3);
    for (unsigned i = 0; i < 3; i++)
        assert_true(f->sleep_deadlines_ns[i] == START_NS);
    assert_true(p.next_ns == START_NS + PERIOD_NS);
}

static void test_ps_pacer_wait_clock_error_returned_unchanged(void **state)
{
    ps_clock_fake_t *f = *state;
    static const int rc[] = {-EINVAL, 0};
    f->rc_script = rc;
    f->n_rc_script = 2;
    ps_pacer_t p;
    assert_int_equal(ps_pacer_init(&p, &f->clock, PERIOD_NS, START_NS), 0);
    assert_true(ps_pacer_wait(&p) == -EINVAL);
    assert_true(p.next_ns == START_NS);
    assert_true(p.tick == 0);
    assert_true(ps_pacer_wait(&p) == 0); /* the same deadline, retried */
    assert_true(f->sleep_deadlines_ns[1] == START_NS);
    assert_true(p.next_ns == START_NS + PERIOD_NS);
}

static void test_ps_pacer_wait_early_wake_clamped_zero(void **state)
{
    ps_clock_fake_t *f = *state;
    static const int64_t script_ns[] = {-5000};
    f->latency_script_ns = script_ns;
    f->n_latency_script = 1;
    ps_pacer_t p;
    assert_int_equal(ps_pacer_init(&p, &f->clock, PERIOD_NS, START_NS), 0);
    assert_true(ps_pacer_wait(&p) == 0);
    assert_true(p.last_wake_latency_ns == 0);
    assert_true(f->now_ns == START_NS - 5000); /* the fake did wake early */
}

/* Without end_tick, a passed deadline is slept for anyway (returns at once)
 * and its lateness is the wake latency. */
static void test_ps_pacer_wait_passed_deadline_reports_lateness(void **state)
{
    ps_clock_fake_t *f = *state;
    ps_pacer_t p;
    assert_int_equal(ps_pacer_init(&p, &f->clock, PERIOD_NS, START_NS), 0);
    assert_true(ps_pacer_wait(&p) == 0);
    ps_clock_fake_advance(f, 2 * PERIOD_NS + 777);
    assert_true(ps_pacer_wait(&p) == PERIOD_NS + 777);
    assert_int_equal(p.tick, 1);
}

static void test_ps_clock_monotonic_now_increases(void **state)
{
    (void)state;
    const ps_clock_t *c = ps_clock_monotonic();
    int64_t prev = ps_clock_now_ns(c);
    assert_true(prev > 0);
    for (int i = 0; i < 1000; i++) {
        const int64_t t = ps_clock_now_ns(c);
        assert_true(t >= prev);
        prev = t;
    }
}

static void test_ps_clock_monotonic_sleep_past_returns_at_once(void **state)
{
    (void)state;
    const ps_clock_t *c = ps_clock_monotonic();
    const int64_t t0 = ps_clock_now_ns(c);
    assert_int_equal(ps_clock_sleep_until_ns(c, t0 - PS_NS_PER_S), 0);
    assert_int_equal(ps_clock_sleep_until_ns(c, -5), 0);
    assert_true(ps_clock_now_ns(c) - t0 < 100 * PS_NS_PER_MS);
    /* A short future sleep really sleeps until at least the deadline. */
    const int64_t dl = ps_clock_now_ns(c) + 2 * PS_NS_PER_MS;
    assert_int_equal(ps_clock_sleep_until_ns(c, dl), 0);
    assert_true(ps_clock_now_ns(c) >= dl);
}

static void test_ps_pacer_wait_real_clock_on_grid(void **state)
{
    (void)state;
    const ps_clock_t *c = ps_clock_monotonic();
    ps_pacer_t p;
    const int64_t t0 = ps_clock_now_ns(c) + PS_NS_PER_MS;
    assert_int_equal(ps_pacer_init(&p, c, PS_NS_PER_MS, t0), 0);
    uint64_t prev_tick = 0, prev_missed = 0;
    for (int i = 0; i < 50; i++) {
        const int64_t lat_ns = ps_pacer_wait(&p);
        assert_true(lat_ns >= 0);
        const int64_t deadline_ns = ps_pacer_deadline_ns(&p, p.tick);
        assert_true(ps_clock_now_ns(c) >= deadline_ns);
        /* Ticks are consecutive except where end_tick reported skipped
         * deadlines (a loaded host may overrun). */
        if (i > 0)
            assert_int_equal(p.tick, prev_tick + 1 + prev_missed);
        prev_tick = p.tick;
        prev_missed = ps_pacer_end_tick(&p);
    }
    assert_true(p.next_ns > ps_pacer_deadline_ns(&p, 49));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup(test_ps_pacer_init_bad_args_einval, setup_fake),
        cmocka_unit_test_setup(test_ps_pacer_wait_late_wakes_no_drift, setup_fake),
        cmocka_unit_test_setup(test_ps_pacer_wait_scripted_latency_reported, setup_fake),
        cmocka_unit_test_setup(test_ps_pacer_end_tick_just_in_time_no_overrun, setup_fake),
        cmocka_unit_test_setup(test_ps_pacer_end_tick_on_next_deadline_missed_1, setup_fake),
        cmocka_unit_test_setup(test_ps_pacer_end_tick_overrun_1_period_missed_2, setup_fake),
        cmocka_unit_test_setup(test_ps_pacer_end_tick_overrun_half_period_missed_1, setup_fake),
        cmocka_unit_test_setup(test_ps_pacer_end_tick_overrun_3_5_periods_missed_4, setup_fake),
        cmocka_unit_test_setup(test_ps_pacer_end_tick_overruns_accumulate_on_grid, setup_fake),
        cmocka_unit_test_setup(test_ps_pacer_wait_eintr_retried, setup_fake),
        cmocka_unit_test_setup(test_ps_pacer_wait_clock_error_returned_unchanged, setup_fake),
        cmocka_unit_test_setup(test_ps_pacer_wait_early_wake_clamped_zero, setup_fake),
        cmocka_unit_test_setup(test_ps_pacer_wait_passed_deadline_reports_lateness, setup_fake),
        cmocka_unit_test(test_ps_clock_monotonic_now_increases),
        cmocka_unit_test(test_ps_clock_monotonic_sleep_past_returns_at_once),
        cmocka_unit_test(test_ps_pacer_wait_real_clock_on_grid),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
