/*
 * Tests of ps_perf: bucket layout, recording, quantiles.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>
#include <errno.h>
#include <stdio.h>

#include <math.h>
#include <stdlib.h>

#include "../rt/ps_perf.h"

static int setup_hist(void **state)
{
    ps_perf_hist_t *h = malloc(sizeof(*h));
    if (h == NULL)
        return -1;
    ps_perf_reset(h);
    *state = h;
    return 0;
}

static int teardown_hist(void **state)
{
    free(*state);
    return 0;
}

static void test_ps_perf_bucket_edges_contiguous_monotonic(void **state)
{
    (void)state;
    assert_int_equal(ps_perf_bucket_lo_ns(0), 0);
    for (unsigned i = 0; i < PS_PERF_N_BUCKETS; i++) {
        const int64_t lo = ps_perf_bucket_lo_ns(i);
        const int64_t hi = ps_perf_bucket_hi_ns(i);
        assert_true(hi > lo);
        if (i + 1 < PS_PERF_N_BUCKETS)
            assert_true(ps_perf_bucket_lo_ns(i + 1) == hi);
        /* Both edges of a bucket map back to it. */
        assert_int_equal(ps_perf_bucket_of(lo), i);
        assert_int_equal(ps_perf_bucket_of(hi - 1), i);
    }
    assert_true(ps_perf_bucket_hi_ns(PS_PERF_N_BUCKETS - 1) == ((int64_t)1 << 41));
    assert_true(ps_perf_bucket_lo_ns(PS_PERF_N_BUCKETS) == -1);
    assert_true(ps_perf_bucket_hi_ns(PS_PERF_N_BUCKETS) == -1);
}

static void test_ps_perf_bucket_width_relative_error_bounded(void **state)
{
    (void)state;
    for (unsigned i = 0; i < PS_PERF_N_BUCKETS; i++) {
        const int64_t lo = ps_perf_bucket_lo_ns(i);
        const int64_t width = ps_perf_bucket_hi_ns(i) - lo;
        if (lo < 32)
            assert_true(width == 1);
        else
            assert_true((double)width / (double)lo <= 1.0 / 32.0);
    }
}

static void test_ps_perf_bucket_of_matches_edges_for_random_values(void **state)
{
    (void)state;
    uint64_t x = 88172645463325252ull;
    for (int i = 0; i < 100000; i++) {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        const int64_t v = (int64_t)(x >> (23 + (x & 31))); /* spread over magnitudes */
        const unsigned idx = ps_perf_bucket_of(v);
        assert_true(ps_perf_bucket_lo_ns(idx) <= v);
        assert_true(v < ps_perf_bucket_hi_ns(idx) || idx == PS_PERF_N_BUCKETS - 1);
    }
}

static void test_ps_perf_record_uniform_quantiles_within_bucket(void **state)
{
    ps_perf_hist_t *h = *state;
    const int64_t n = 100000;
    /* Record in a scrambled order: order must not matter. */
    for (int64_t i = 0; i < n; i++)
        ps_perf_record(h, ((i * 7919) % n) + 1);
    assert_int_equal(h->n, n);
    assert_true(h->min_ns == 1);
    assert_true(h->max_ns == n);
    assert_true(ps_perf_mean_ns(h) == (double)(n + 1) / 2.0);
    static const double qs[] = {0.01, 0.1, 0.25, 0.5, 0.9, 0.99, 0.999, 0.9999};
    for (size_t j = 0; j < sizeof(qs) / sizeof(qs[0]); j++) {
        const int64_t exact = (int64_t)ceil(qs[j] * (double)n);
        const int64_t got = ps_perf_quantile_ns(h, qs[j]);
        const unsigned b = ps_perf_bucket_of(exact);
        const int64_t width = ps_perf_bucket_hi_ns(b) - ps_perf_bucket_lo_ns(b);
        assert_true(got >= exact);
        assert_true(got - exact < width);
    }
    assert_true(ps_perf_quantile_ns(h, 0.0) == 1);
    assert_true(ps_perf_quantile_ns(h, 1.0) == n);
    assert_int_equal(h->n_over, 0);
}

static void test_ps_perf_record_small_values_exact_quantiles(void **state)
{
    ps_perf_hist_t *h = *state;
    for (int64_t v = 0; v < 32; v++)
        ps_perf_record(h, v);
    /* One bucket per ns below 32: quantiles are exact. */
    assert_true(ps_perf_quantile_ns(h, 0.5) == 15);
    assert_true(ps_perf_quantile_ns(h, 1.0 / 32.0) == 0);
    assert_true(ps_perf_quantile_ns(h, 0.75) == 23);
}

static void test_ps_perf_record_negative_counts_as_zero(void **state)
{
    ps_perf_hist_t *h = *state;
    ps_perf_record(h, -5);
    ps_perf_record(h, INT64_MIN);
    assert_int_equal(h->n, 2);
    assert_int_equal(h->buckets[0], 2);
    assert_true(h->min_ns == 0 && h->max_ns == 0 && h->sum_ns == 0);
    assert_true(ps_perf_bucket_of(-1) == 0);
}

static void test_ps_perf_record_huge_top_bucket_counted_over(void **state)
{
    ps_perf_hist_t *h = *state;
    const int64_t top_ns = (int64_t)1 << 41;
    ps_perf_record(h, 1000);
    ps_perf_record(h, top_ns - 1); /* last value that fits: not over */
    ps_perf_record(h, top_ns);
    ps_perf_record(h, INT64_MAX);
    assert_int_equal(h->n_over, 2);
    assert_int_equal(h->buckets[PS_PERF_N_BUCKETS - 1], 3);
    assert_true(h->max_ns == INT64_MAX);
    assert_true(h->sum_ns == INT64_MAX); /* saturated, not wrapped */
    assert_true(ps_perf_mean_ns(h) > 0.0);
    assert_true(ps_perf_quantile_ns(h, 1.0) == INT64_MAX);
    assert_true(ps_perf_quantile_ns(h, 0.25) == ps_perf_bucket_hi_ns(ps_perf_bucket_of(1000)) - 1);
}

static void test_ps_perf_quantile_empty_zero(void **state)
{
    ps_perf_hist_t *h = *state;
    assert_true(ps_perf_quantile_ns(h, 0.5) == 0);
    assert_true(ps_perf_mean_ns(h) == 0.0);
    assert_true(h->min_ns == 0 && h->max_ns == 0);
}

static void test_ps_perf_quantile_clamped_to_max(void **state)
{
    ps_perf_hist_t *h = *state;
    /* 1000 lies in a bucket whose largest value is above 1000. */
    ps_perf_record(h, 1000);
    const unsigned b = ps_perf_bucket_of(1000);
    assert_true(ps_perf_bucket_hi_ns(b) - 1 > 1000);
    assert_true(ps_perf_quantile_ns(h, 0.5) == 1000);
    assert_true(ps_perf_quantile_ns(h, 0.99) == 1000);
}

static void test_ps_perf_mean_min_max_exact(void **state)
{
    ps_perf_hist_t *h = *state;
    static const int64_t v[] = {12345, 7, 999999, 31, 64, 5000000};
    int64_t sum = 0;
    for (size_t i = 0; i < sizeof(v) / sizeof(v[0]); i++) {
        ps_perf_record(h, v[i]);
        sum += v[i];
    }
    assert_true(h->min_ns == 7);
    assert_true(h->max_ns == 5000000);
    assert_true(h->sum_ns == sum);
    assert_true(ps_perf_mean_ns(h) == (double)sum / 6.0);
}

static void test_ps_perf_copy_equal_and_reset_empties(void **state)
{
    ps_perf_hist_t *h = *state;
    for (int64_t i = 0; i < 1000; i++)
        ps_perf_record(h, i * 1000);
    ps_perf_hist_t *c = malloc(sizeof(*c));
    assert_non_null(c);
    ps_perf_copy(c, h);
    assert_memory_equal(c, h, sizeof(*h));
    assert_true(ps_perf_quantile_ns(c, 0.9) == ps_perf_quantile_ns(h, 0.9));
    ps_perf_reset(h);
    assert_int_equal(h->n, 0);
    uint64_t total = 0;
    for (unsigned i = 0; i < PS_PERF_N_BUCKETS; i++)
        total += h->buckets[i];
    assert_int_equal(total, 0);
    assert_int_equal(c->n, 1000);
    free(c);
}

/* ---- linear 1-us histogram and its cyclictest text ----------------------- */

static void test_ps_perf_us_reset_bad_size_einval(void **state)
{
    (void)state;
    static ps_perf_us_hist_t h;
    assert_int_equal(ps_perf_us_reset(&h, 0), -EINVAL);
    assert_int_equal(ps_perf_us_reset(&h, PS_PERF_US_BUCKETS + 1), -EINVAL);
    assert_int_equal(ps_perf_us_reset(&h, PS_PERF_US_BUCKETS), 0);
}

static void test_ps_perf_us_record_truncates_to_us_and_counts_overflows(void **state)
{
    (void)state;
    static ps_perf_us_hist_t h;
    assert_int_equal(ps_perf_us_reset(&h, 5), 0);
    ps_perf_us_record(&h, 999, 0);   /* 0 us */
    ps_perf_us_record(&h, 1000, 1);  /* 1 us */
    ps_perf_us_record(&h, 4999, 2);  /* 4 us: last bucket */
    ps_perf_us_record(&h, 5000, 3);  /* 5 us: overflow, tick 3 */
    ps_perf_us_record(&h, -7, 4);    /* negative counts as 0 */
    ps_perf_us_record(&h, 90000, 5); /* overflow, tick 5 */
    assert_int_equal(h.buckets[0], 2);
    assert_int_equal(h.buckets[1], 1);
    assert_int_equal(h.buckets[4], 1);
    assert_int_equal(h.n, 6);
    assert_int_equal(h.n_overflow, 2);
    assert_int_equal(h.n_overflow_ticks, 2);
    assert_int_equal(h.overflow_ticks[0], 3);
    assert_int_equal(h.overflow_ticks[1], 5);
    assert_int_equal(h.min_ns, 0);
    assert_int_equal(h.max_ns, 90000);
}

/* The text must match what `cyclictest -h 5` prints for one thread, line by
 * line (format taken from rt-tests 2.x output on Debian 12). */
static void test_ps_perf_us_write_cyclictest_exact_text(void **state)
{
    (void)state;
    static ps_perf_us_hist_t h;
    assert_int_equal(ps_perf_us_reset(&h, 5), 0);
    ps_perf_us_record(&h, 3000, 0);
    ps_perf_us_record(&h, 3500, 1);
    ps_perf_us_record(&h, 12000, 2);
    char buf[1024] = "";
    FILE *f = fmemopen(buf, sizeof(buf), "w");
    assert_non_null(f);
    assert_int_equal(ps_perf_us_write_cyclictest(&h, f), 0);
    fclose(f);
    const char *expected = "# Histogram\n"
                           "000000 000000\n"
                           "000001 000000\n"
                           "000002 000000\n"
                           "000003 000002\n"
                           "000004 000000\n"
                           "# Total: 000000002\n"
                           "# Min Latencies: 00003\n"
                           "# Avg Latencies: 00006\n" /* (3000 + 3500 + 12000) / 3 = 6166 ns */
                           "# Max Latencies: 00012\n"
                           "# Histogram Overflows: 00001\n"
                           "# Histogram Overflow at cycle number:\n"
                           "# Thread 0: 00002\n";
    assert_string_equal(buf, expected);
}

int main(void)
{
#define T(f) cmocka_unit_test_setup_teardown(f, setup_hist, teardown_hist)
    const struct CMUnitTest tests[] = {
        T(test_ps_perf_bucket_edges_contiguous_monotonic),
        T(test_ps_perf_bucket_width_relative_error_bounded),
        T(test_ps_perf_bucket_of_matches_edges_for_random_values),
        T(test_ps_perf_record_uniform_quantiles_within_bucket),
        T(test_ps_perf_record_small_values_exact_quantiles),
        T(test_ps_perf_record_negative_counts_as_zero),
        T(test_ps_perf_record_huge_top_bucket_counted_over),
        T(test_ps_perf_quantile_empty_zero),
        T(test_ps_perf_quantile_clamped_to_max),
        T(test_ps_perf_mean_min_max_exact),
        T(test_ps_perf_copy_equal_and_reset_empties),
        cmocka_unit_test(test_ps_perf_us_reset_bad_size_einval),
        cmocka_unit_test(test_ps_perf_us_record_truncates_to_us_and_counts_overflows),
        cmocka_unit_test(test_ps_perf_us_write_cyclictest_exact_text),
    };
#undef T
    return cmocka_run_group_tests(tests, NULL, NULL);
}
