/*
 * ps_perf: latency accounting in fixed-size log-linear histograms.
 *
 * Buckets: values below PS_PERF_SUB_BUCKETS ns get one bucket per ns; above,
 * each power-of-two range [2^k, 2^(k+1)) ns is split into PS_PERF_SUB_BUCKETS
 * equal buckets (HdrHistogram-style), giving a relative resolution of 1/PS_PERF_SUB_BUCKETS
 * (about 3 %) from 1 ns up to ~68 s, in a fixed array. Percentiles are read
 * from the bucket counts (upper bucket edge, clamped to the exact max).
 *
 * Threads: a histogram has one writer (the loop); readers take a snapshot by
 * copying (ps_perf_copy) from another thread and accept a torn read of a
 * bucket under way. Allocation: none.
 */
#ifndef PS_PERF_H
#define PS_PERF_H

#include <stdint.h>

#define PS_PERF_SUB_BITS    5u /* 32 sub-buckets per octave */
#define PS_PERF_SUB_BUCKETS (1u << PS_PERF_SUB_BITS)
#define PS_PERF_OCTAVES     37u /* up to 2^36 ns = 68.7 s */
#define PS_PERF_N_BUCKETS   (PS_PERF_SUB_BUCKETS * PS_PERF_OCTAVES)

typedef struct {
    uint64_t n;
    int64_t min_ns, max_ns;
    int64_t sum_ns;
    uint64_t n_over; /**< samples beyond the top bucket (counted in the top bucket too) */
    uint32_t buckets[PS_PERF_N_BUCKETS];
} ps_perf_hist_t;

/** @post h empty  @rt RT-SAFE (touches the whole array: call at init to prefault) */
void ps_perf_reset(ps_perf_hist_t *h);

/** Record one sample; negative values count as 0. @rt RT-SAFE O(1) */
void ps_perf_record(ps_perf_hist_t *h, int64_t value_ns);

/** @pre 0 <= q <= 1  @return the q-quantile (0 when empty)  @units ns  @rt NON-RT O(buckets) */
int64_t ps_perf_quantile_ns(const ps_perf_hist_t *h, double q);

/** @return mean (0 when empty)  @units ns */
double ps_perf_mean_ns(const ps_perf_hist_t *h);

/** Bucket index of a value and a bucket's [lo, hi) edges, exposed for tests. */
unsigned ps_perf_bucket_of(int64_t value_ns);
int64_t ps_perf_bucket_lo_ns(unsigned idx);
int64_t ps_perf_bucket_hi_ns(unsigned idx);

#endif /* PS_PERF_H */
