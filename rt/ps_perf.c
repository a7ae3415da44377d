/*
 * ps_perf: log-linear latency histograms.
 */
#include "ps_perf.h"

#include <errno.h>

#include <string.h>

/* First octave exponent: [2^5, 2^6) is octave index 1. */
#define TOP_IDX     (PS_PERF_N_BUCKETS - 1u)
#define TOP_EXCL_NS ((int64_t)1 << (PS_PERF_OCTAVES + PS_PERF_SUB_BITS - 1u))

_Static_assert(PS_PERF_OCTAVES + PS_PERF_SUB_BITS - 1u < 63u, "octaves exceed int64_t");

void ps_perf_reset(ps_perf_hist_t *h)
{
    /* memset writes every byte, which is what prefaults the array. */
    memset(h, 0, sizeof(*h));
}

unsigned ps_perf_bucket_of(int64_t value_ns)
{
    if (value_ns < (int64_t)PS_PERF_SUB_BUCKETS)
        return value_ns < 0 ? 0u : (unsigned)value_ns;
    if (value_ns >= TOP_EXCL_NS)
        return TOP_IDX;
    const uint64_t v = (uint64_t)value_ns;
    const unsigned k = 63u - (unsigned)__builtin_clzll(v); /* 2^k <= v < 2^(k+1), k >= 5 */
    const unsigned shift = k - PS_PERF_SUB_BITS;
    const unsigned octave = k - PS_PERF_SUB_BITS + 1u;
    const unsigned sub = (unsigned)(v >> shift) - PS_PERF_SUB_BUCKETS;
    return octave * PS_PERF_SUB_BUCKETS + sub;
}

int64_t ps_perf_bucket_lo_ns(unsigned idx)
{
    if (idx >= PS_PERF_N_BUCKETS)
        return -1;
    if (idx < PS_PERF_SUB_BUCKETS)
        return (int64_t)idx;
    const unsigned octave = idx / PS_PERF_SUB_BUCKETS;
    const unsigned sub = idx % PS_PERF_SUB_BUCKETS;
    return (int64_t)(PS_PERF_SUB_BUCKETS + sub) << (octave - 1u);
}

int64_t ps_perf_bucket_hi_ns(unsigned idx)
{
    if (idx >= PS_PERF_N_BUCKETS)
        return -1;
    if (idx < PS_PERF_SUB_BUCKETS)
        return (int64_t)idx + 1;
    const unsigned octave = idx / PS_PERF_SUB_BUCKETS;
    return ps_perf_bucket_lo_ns(idx) + ((int64_t)1 << (octave - 1u));
}

void ps_perf_record(ps_perf_hist_t *h, int64_t value_ns)
{
    if (value_ns < 0)
        value_ns = 0;
    if (h->n == 0) {
        h->min_ns = value_ns;
        h->max_ns = value_ns;
    } else {
        if (value_ns < h->min_ns)
            h->min_ns = value_ns;
        if (value_ns > h->max_ns)
            h->max_ns = value_ns;
    }
    h->n++;
    /* Saturate instead of wrapping: a wrapped sum would turn the mean
     * negative after one absurd sample. */
    if (__builtin_add_overflow(h->sum_ns, value_ns, &h->sum_ns))
        h->sum_ns = INT64_MAX;
    if (value_ns >= TOP_EXCL_NS)
        h->n_over++;
    h->buckets[ps_perf_bucket_of(value_ns)]++;
}

void ps_perf_copy(ps_perf_hist_t *out, const ps_perf_hist_t *h)
{
    memcpy(out, h, sizeof(*out));
}

int64_t ps_perf_quantile_ns(const ps_perf_hist_t *h, double q)
{
    if (h->n == 0)
        return 0;
    if (!(q > 0.0)) /* also catches NaN */
        return h->min_ns;
    if (q >= 1.0)
        return h->max_ns;
    /* rank in 1..n of the sample that is the q-quantile */
    double rank_d = q * (double)h->n;
    uint64_t rank = (uint64_t)rank_d;
    if ((double)rank < rank_d)
        rank++;
    if (rank < 1)
        rank = 1;
    if (rank > h->n)
        rank = h->n;
    uint64_t seen = 0;
    for (unsigned i = 0; i < PS_PERF_N_BUCKETS; i++) {
        seen += h->buckets[i];
        if (seen >= rank) {
            int64_t v = ps_perf_bucket_hi_ns(i) - 1;
            if (v > h->max_ns)
                v = h->max_ns;
            if (v < h->min_ns)
                v = h->min_ns;
            return v;
        }
    }
    /* Only reachable on a torn snapshot where n ran ahead of the buckets. */
    return h->max_ns;
}

double ps_perf_mean_ns(const ps_perf_hist_t *h)
{
    if (h->n == 0)
        return 0.0;
    return (double)h->sum_ns / (double)h->n;
}

/* ---- linear 1-us histogram ------------------------------------------------ */

int ps_perf_us_reset(ps_perf_us_hist_t *h, unsigned n_buckets)
{
    if (n_buckets == 0 || n_buckets > PS_PERF_US_BUCKETS)
        return -EINVAL;
    memset(h, 0, sizeof(*h));
    h->n_buckets = n_buckets;
    return 0;
}

void ps_perf_us_record(ps_perf_us_hist_t *h, int64_t value_ns, uint64_t tick)
{
    if (value_ns < 0)
        value_ns = 0;
    if (h->n == 0 || value_ns < h->min_ns)
        h->min_ns = value_ns;
    if (value_ns > h->max_ns)
        h->max_ns = value_ns;
    h->sum_ns = (h->sum_ns > INT64_MAX - value_ns) ? INT64_MAX : h->sum_ns + value_ns;
    h->n++;
    uint64_t us = (uint64_t)value_ns / 1000u;
    if (us < h->n_buckets) {
        h->buckets[us]++;
        return;
    }
    h->n_overflow++;
    if (h->n_overflow_ticks < PS_PERF_US_MAX_OVERFLOW_TICKS)
        h->overflow_ticks[h->n_overflow_ticks++] = tick;
}

int ps_perf_us_write_cyclictest(const ps_perf_us_hist_t *h, FILE *out)
{
    uint64_t total = 0;
    fputs("# Histogram\n", out);
    for (unsigned i = 0; i < h->n_buckets; i++) {
        fprintf(out, "%06u %06u\n", i, (unsigned)h->buckets[i]);
        total += h->buckets[i];
    }
    /* As cyclictest: Total counts the samples inside the histogram; the
     * latencies are whole microseconds (truncated) over all samples. */
    fprintf(out, "# Total: %09llu\n", (unsigned long long)total);
    fprintf(out, "# Min Latencies: %05lld\n", (long long)(h->min_ns / 1000));
    fprintf(out, "# Avg Latencies: %05lld\n",
            (long long)(h->n ? h->sum_ns / (int64_t)h->n / 1000 : 0));
    fprintf(out, "# Max Latencies: %05lld\n", (long long)(h->max_ns / 1000));
    fprintf(out, "# Histogram Overflows: %05llu\n", (unsigned long long)h->n_overflow);
    fputs("# Histogram Overflow at cycle number:\n# Thread 0:", out);
    for (uint32_t i = 0; i < h->n_overflow_ticks; i++)
        fprintf(out, " %05llu", (unsigned long long)h->overflow_ticks[i]);
    if (h->n_overflow > h->n_overflow_ticks)
        fprintf(out, " # %05llu others", (unsigned long long)(h->n_overflow - h->n_overflow_ticks));
    fputs("\n", out);
    return ferror(out) ? -EIO : 0;
}
