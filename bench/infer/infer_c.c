/*
 * Inference at batch 1 (make bench): the policy engine (policy/ps_mlp) beside
 * an OpenBLAS cblas_sgemv chain on the same network, alternating blocks in
 * one process; prints JSON. The weights go to a file for the libtorch
 * comparison (bench/infer/infer_torch.cpp), which checks it gets the same
 * outputs. Usage: infer_c SIZES WEIGHTS_OUT  (SIZES like 100,256,256,128,20)
 */
#include <cblas.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../../policy/ps_mlp.h"

#define REPS   10000
#define BLOCKS 10

static double now_ns(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec * 1e9 + (double)t.tv_nsec;
}

static int cmp(const void *a, const void *b)
{
    const double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : (x > y ? 1 : 0);
}

static uint64_t rs = 88172645463325252ull;
static float frand(void)
{
    rs ^= rs << 13, rs ^= rs >> 7, rs ^= rs << 17;
    return (float)((double)(rs >> 11) * 0x1.0p-53 * 2.0 - 1.0);
}

int main(int argc, char **argv)
{
    if (argc < 3)
        return 2;
    uint32_t sz[9], n = 0;
    char spec[256];
    snprintf(spec, sizeof(spec), "%s", argv[1]);
    for (char *s = strtok(spec, ","); s && n < 9; s = strtok(NULL, ","))
        sz[n++] = (uint32_t)atoi(s);
    const uint32_t nl = n - 1;
    ps_mlp_desc_t d;
    memset(&d, 0, sizeof(d));
    d.n_layers = nl;
    float *w[8], *b[8];
    FILE *f = fopen(argv[2], "wb");
    for (uint32_t k = 0; k < nl; k++) {
        w[k] = malloc(sizeof(float) * sz[k] * sz[k + 1]);
        b[k] = malloc(sizeof(float) * sz[k + 1]);
        const float sc = 1.0f / sqrtf((float)sz[k]);
        for (uint32_t i = 0; i < sz[k] * sz[k + 1]; i++)
            w[k][i] = frand() * sc;
        for (uint32_t i = 0; i < sz[k + 1]; i++)
            b[k][i] = frand() * 0.1f;
        fwrite(w[k], sizeof(float), sz[k] * sz[k + 1], f);
        fwrite(b[k], sizeof(float), sz[k + 1], f);
        d.base[k] = (ps_mlp_dense_desc_t){sz[k], sz[k + 1], w[k], b[k], 1};
        d.act[k] = k + 1 < nl ? PS_MLP_ACT_ELU : PS_MLP_ACT_IDENTITY;
    }
    float in[1024], out_e[1024], out_b[1024], h0[1024], h1[1024];
    for (uint32_t i = 0; i < sz[0]; i++)
        in[i] = frand();
    fwrite(in, sizeof(float), sz[0], f);
    fclose(f);
    const size_t na = ps_mlp_arena_floats(&d);
    float *arena = malloc(na * sizeof(float));
    ps_mlp_t m;
    if (ps_mlp_init(&m, &d, arena, na) != 0)
        return 1;
    static double te[REPS * BLOCKS / 2], tb[REPS * BLOCKS / 2];
    size_t ne = 0, nb = 0;
    double macs = 0;
    for (uint32_t k = 0; k < nl; k++)
        macs += (double)sz[k] * sz[k + 1];
    for (int blk = 0; blk < BLOCKS; blk++) {
        for (int r = 0; r < REPS / 2 + 100; r++) {
            const double t0 = now_ns();
            if (blk % 2 == 0) {
                ps_mlp_forward(&m, in, NULL, out_e);
            } else {
                const float *x = in;
                float *bufs[2] = {h0, h1};
                for (uint32_t k = 0; k < nl; k++) {
                    float *y = k + 1 == nl ? out_b : bufs[k & 1];
                    memcpy(y, b[k], sz[k + 1] * sizeof(float));
                    cblas_sgemv(CblasRowMajor, CblasNoTrans, (int)sz[k + 1], (int)sz[k], 1.0f, w[k],
                                (int)sz[k], x, 1, 1.0f, y, 1);
                    if (k + 1 < nl)
                        for (uint32_t i = 0; i < sz[k + 1]; i++)
                            y[i] = y[i] > 0.0f ? y[i] : expm1f(y[i]);
                    x = y;
                }
            }
            const double dt = now_ns() - t0;
            if (r >= 100) { /* warm-up excluded */
                if (blk % 2 == 0)
                    te[ne++] = dt;
                else
                    tb[nb++] = dt;
            }
        }
    }
    qsort(te, ne, sizeof(double), cmp);
    qsort(tb, nb, sizeof(double), cmp);
    double diff = 0;
    for (uint32_t i = 0; i < sz[n - 1]; i++)
        diff = fmax(diff, fabs((double)out_e[i] - out_b[i]));
    printf("{\"net\": \"%s\", \"macs\": %.0f, \"engine_ns\": {\"p50\": %.0f, \"p99\": %.0f}, "
           "\"openblas_ns\": {\"p50\": %.0f, \"p99\": %.0f}, \"max_abs_diff\": %.3g, "
           "\"out0\": %.6f, \"n\": %zu}\n",
           argv[1], macs, te[ne / 2], te[ne * 99 / 100], tb[nb / 2], tb[nb * 99 / 100], diff,
           (double)out_e[0], ne);
    return 0;
}
