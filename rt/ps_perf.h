/*
 * ps_perf: latency accounting in fixed-size log-linear histograms.
 *
 * Buckets: values below PS_PERF_SUB_BUCKETS (32) ns get one bucket per ns;
 * above, each power-of-two range [2^k, 2^(k+1)) ns, k >= 5, is split into
 * PS_PERF_SUB_BUCKETS equal buckets (HdrHistogram-style), so a bucket's width
 * is at most 1/32 of its lower edge (about 3 %). Bucket index 32*o + s:
 * o = 0 is the linear range [0, 32), o >= 1 the octave [2^(o+4), 2^(o+5)).
 * With PS_PERF_OCTAVES = 37 the top octave is [2^40, 2^41) ns, i.e. the
 * histogram resolves up to 2^41 ns (about 36.6 min); larger values go into
 * the top bucket and are also counted in n_over. Quantiles are read from the
 * bucket counts: the largest value of the bucket holding the rank (hi - 1),
 * clamped to [min, max] (so q = 0 gives min and q = 1 gives max exactly).
 *
 * Threads: a histogram has one writer (the loop); readers take a snapshot by
 * copying (ps_perf_copy) from another thread and accept a torn read of a
 * bucket under way. Allocation: none.
 */
#ifndef PS_PERF_H
#define PS_PERF_H

#include <stdint.h>
#include <stdio.h>

#define PS_PERF_SUB_BITS    5u /* 32 sub-buckets per octave */
#define PS_PERF_SUB_BUCKETS (1u << PS_PERF_SUB_BITS)
#define PS_PERF_OCTAVES     37u /* linear [0,32) + octaves up to 2^41 ns */
#define PS_PERF_N_BUCKETS   (PS_PERF_SUB_BUCKETS * PS_PERF_OCTAVES)

typedef struct {
    uint64_t n;
    int64_t min_ns, max_ns; /**< exact; 0 when empty */
    int64_t sum_ns;         /**< exact unless it would overflow: saturates at INT64_MAX */
    uint64_t n_over;        /**< samples beyond the top bucket (counted in the top bucket too) */
    uint32_t buckets[PS_PERF_N_BUCKETS];
} ps_perf_hist_t;

/** @pre h != NULL  @post h empty  @rt RT-SAFE (touches the whole array: call at init to prefault)
 */
void ps_perf_reset(ps_perf_hist_t *h);

/** Record one sample; negative values count as 0.
 *  @pre h != NULL  @units ns  @rt RT-SAFE O(1), the writer thread */
void ps_perf_record(ps_perf_hist_t *h, int64_t value_ns);

/** Snapshot a histogram (memcpy); from another thread a bucket being written
 *  may be torn, and n/min/max/sum may disagree by the sample under way.
 *  @pre out, h != NULL  @post *out = *h  @rt RT-SAFE O(buckets), any thread */
void ps_perf_copy(ps_perf_hist_t *out, const ps_perf_hist_t *h);

/** @pre 0 <= q <= 1 (clamped)  @return the q-quantile: the sample of rank
 *  ceil(q * n) (at least 1) rounded up to its bucket's largest value, clamped
 *  to [min, max]; 0 when empty  @units ns  @rt NON-RT O(buckets) */
int64_t ps_perf_quantile_ns(const ps_perf_hist_t *h, double q);

/** @return mean (0 when empty)  @units ns  @rt RT-SAFE O(1) */
double ps_perf_mean_ns(const ps_perf_hist_t *h);

/** Bucket index of a value and a bucket's [lo, hi) edges, exposed for tests.
 *  bucket_of: negative -> 0, beyond the top -> PS_PERF_N_BUCKETS - 1.
 *  lo/hi: @pre idx < PS_PERF_N_BUCKETS (else -1); the top bucket's hi is 2^41
 *  although it also holds the n_over samples.  @units ns  @rt RT-SAFE O(1) */
unsigned ps_perf_bucket_of(int64_t value_ns);
int64_t ps_perf_bucket_lo_ns(unsigned idx);
int64_t ps_perf_bucket_hi_ns(unsigned idx);

/* ---- linear 1-us histogram, cyclictest's layout -------------------------
 * Wake-up latency is also kept the way cyclictest keeps it (`-h N`): one
 * bucket per whole microsecond (ns / 1000, truncated), the samples beyond the
 * last bucket counted as overflows with the tick index of the first
 * PS_PERF_US_MAX_OVERFLOW_TICKS of them. ps_perf_us_write_cyclictest() prints
 * it in cyclictest's text format, so its plotting scripts read ours. */

#define PS_PERF_US_BUCKETS            10000u /**< 0 .. 9999 us */
#define PS_PERF_US_MAX_OVERFLOW_TICKS 1000u

typedef struct {
    uint32_t n_buckets; /**< buckets in use (cyclictest's -h N) */
    uint64_t n;
    int64_t min_ns, max_ns, sum_ns;
    uint64_t n_overflow;
    uint32_t n_overflow_ticks; /**< entries used in overflow_ticks */
    uint64_t overflow_ticks[PS_PERF_US_MAX_OVERFLOW_TICKS];
    uint32_t buckets[PS_PERF_US_BUCKETS];
} ps_perf_us_hist_t;

/** @pre 1 <= n_buckets <= PS_PERF_US_BUCKETS  @post h empty with n_buckets
 *  1-us buckets, every page touched  @return 0 | -EINVAL  @rt INIT */
int ps_perf_us_reset(ps_perf_us_hist_t *h, unsigned n_buckets);

/** Record a sample taken on tick `tick`. @units ns  @rt RT-SAFE O(1), writer thread */
void ps_perf_us_record(ps_perf_us_hist_t *h, int64_t value_ns, uint64_t tick);

/** Print in the format of `cyclictest -h N` for one thread: "# Histogram",
 *  then "%06u %06u" per bucket, then the "# Total", "# Min/Avg/Max Latencies",
 *  "# Histogram Overflows" and "# Histogram Overflow at cycle number" lines.
 *  @return 0 | -EIO  @rt NON-RT */
int ps_perf_us_write_cyclictest(const ps_perf_us_hist_t *h, FILE *out);

#endif /* PS_PERF_H */
