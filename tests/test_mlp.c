/*
 * Tests of policy/ps_mlp.c (the inference engine) and policy/ps_weights.c
 * (policy files) against PyTorch: the networks and vectors in
 * tests/data/policy/ were made by policy/train/make_golden.py with
 * python3-torch (seed 1), one of them exported to ONNX and imported by
 * policy/train/onnx2policy.py. Tolerance 1e-5 on every output.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../policy/ps_mlp.h"
#include "../policy/ps_safetensors.h"
#include "../policy/ps_weights.h"

#define DATA "tests/data/policy/"
#define TOL  1e-5

static void load_vec(const char *name, float *out, size_t n_max, uint32_t *out_rows,
                     uint32_t *out_cols)
{
    ps_st_file_t st;
    char err[512];
    if (ps_st_load(&st, DATA "golden_vectors.safetensors", err, sizeof(err)) != 0)
        fail_msg("%s", err);
    const ps_st_tensor_t *t = ps_st_find(&st, name);
    assert_non_null(t);
    assert_int_equal(t->n_dims, 2);
    assert_true(ps_st_copy_f32(&st, t, out, n_max, err, sizeof(err)) > 0);
    *out_rows = (uint32_t)t->shape[0];
    *out_cols = (uint32_t)t->shape[1];
    ps_st_free(&st);
}

/* Run a policy file on the golden inputs; worst |C - PyTorch| over all. */
static double golden_error(const char *file, const char *key)
{
    char err[512], name[64];
    ps_weights_t w;
    if (ps_weights_load(&w, file, err, sizeof(err)) != 0)
        fail_msg("%s", err);
    static float in[64 * 64], extra[64 * 64], want[64 * 64];
    uint32_t rows, n_in, rows2, n_out, n_extra = 0;
    snprintf(name, sizeof(name), "%s.in", key);
    load_vec(name, in, 64 * 64, &rows, &n_in);
    snprintf(name, sizeof(name), "%s.out", key);
    load_vec(name, want, 64 * 64, &rows2, &n_out);
    assert_int_equal(rows, rows2);
    assert_int_equal(n_in, w.mlp.n_in);
    assert_int_equal(n_out, w.mlp.n_out);
    if (w.mlp.n_extra > 0) {
        snprintf(name, sizeof(name), "%s.extra", key);
        load_vec(name, extra, 64 * 64, &rows2, &n_extra);
        assert_int_equal(n_extra, w.mlp.n_extra);
    }
    double worst = 0.0;
    for (uint32_t r = 0; r < rows; r++) {
        float out[64];
        assert_int_equal(
            ps_mlp_forward(&w.mlp, in + r * n_in, n_extra ? extra + r * n_extra : NULL, out), 0);
        for (uint32_t o = 0; o < n_out; o++) {
            const double e = fabs((double)out[o] - (double)want[r * n_out + o]);
            worst = e > worst ? e : worst;
        }
    }
    ps_weights_free(&w);
    return worst;
}

static void test_ps_mlp_forward_matches_pytorch_base_elu(void **st)
{
    (void)st;
    const double e = golden_error(DATA "golden_base.safetensors", "base");
    printf("  base 15-64-64-4 ELU: max |C - PyTorch| = %.2e\n", e);
    assert_true(e <= TOL);
}

static void test_ps_mlp_forward_matches_pytorch_adapters(void **st)
{
    (void)st;
    const double e = golden_error(DATA "golden_adapt.safetensors", "adapt");
    printf("  internal adapters + latent injection: max |C - PyTorch| = %.2e\n", e);
    assert_true(e <= TOL);
}

static void test_ps_mlp_forward_matches_pytorch_every_activation(void **st)
{
    (void)st;
    const double e = golden_error(DATA "golden_acts.safetensors", "acts");
    printf("  sigmoid/tanh/relu/silu: max |C - PyTorch| = %.2e\n", e);
    assert_true(e <= TOL);
}

static void test_ps_mlp_forward_matches_pytorch_onnx_import(void **st)
{
    (void)st;
    const double e = golden_error(DATA "golden_from_onnx.safetensors", "base");
    printf("  torch.onnx.export -> onnx2policy: max |C - PyTorch| = %.2e\n", e);
    assert_true(e <= TOL);
}

/* The base network with zero-initialised adapters on every layer and a
 * latent injection whose last layer is zero (its first is not): outputs
 * bit for bit those of the base alone, whatever the extra inputs. */
static void test_ps_mlp_zero_adapters_reproduce_base_exactly(void **st)
{
    (void)st;
    char err[512];
    ps_st_file_t f;
    if (ps_st_load(&f, DATA "golden_base.safetensors", err, sizeof(err)) != 0)
        fail_msg("%s", err);
    static float vals[3][64 * 64], bias[3][64];
    ps_mlp_desc_t d;
    memset(&d, 0, sizeof(d));
    d.n_layers = 3;
    for (uint32_t k = 0; k < 3; k++) {
        char nm[32];
        snprintf(nm, sizeof(nm), "base.%u.weight", k);
        const ps_st_tensor_t *t = ps_st_find(&f, nm);
        assert_true(ps_st_copy_f32(&f, t, vals[k], 64 * 64, err, sizeof(err)) > 0);
        d.base[k] = (ps_mlp_dense_desc_t){(uint32_t)t->shape[1], (uint32_t)t->shape[0], vals[k],
                                          bias[k], 1};
        snprintf(nm, sizeof(nm), "base.%u.bias", k);
        assert_true(ps_st_copy_f32(&f, ps_st_find(&f, nm), bias[k], 64, err, sizeof(err)) > 0);
        d.act[k] = k < 2 ? PS_MLP_ACT_ELU : PS_MLP_ACT_IDENTITY;
    }
    ps_st_free(&f);
    static float base_arena[20000], ad_arena[40000];
    ps_mlp_t base, ad;
    assert_int_equal(ps_mlp_init(&base, &d, base_arena, 20000), 0);
    static float zeros[64 * 64], e1_w[16 * 5], e1_b[16];
    for (int i = 0; i < 16 * 5; i++)
        e1_w[i] = 0.1f * (float)(i % 7) - 0.3f;
    for (uint32_t k = 0; k < 3; k++)
        d.adapt[k] = (ps_mlp_dense_desc_t){d.base[k].n_in, d.base[k].n_out, zeros, zeros, 1};
    d.n_embed = 2;
    d.embed[0] = (ps_mlp_dense_desc_t){5, 16, e1_w, e1_b, 1};
    d.embed[1] = (ps_mlp_dense_desc_t){16, 64, zeros, zeros, 1};
    d.embed_act[0] = PS_MLP_ACT_TANH;
    d.embed_act[1] = PS_MLP_ACT_IDENTITY;
    d.inject_layer = 1;
    assert_true(ps_mlp_arena_floats(&d) <= 40000);
    assert_int_equal(ps_mlp_init(&ad, &d, ad_arena, 40000), 0);
    assert_int_equal(ad.n_extra, 5);
    float in[15], extra[5], o1[4], o2[4];
    for (int r = 0; r < 50; r++) {
        for (int i = 0; i < 15; i++)
            in[i] = sinf((float)(r * 15 + i)) * 3.0f;
        for (int i = 0; i < 5; i++)
            extra[i] = cosf((float)(r * 5 + i)) * 2.0f;
        assert_int_equal(ps_mlp_forward(&base, in, NULL, o1), 0);
        assert_int_equal(ps_mlp_forward(&ad, in, extra, o2), 0);
        assert_memory_equal(o1, o2, sizeof(o1));
    }
}

/* A grouped layer computes its block-diagonal dense layer bit for bit (the
 * zeros' products leave every sum as it is): a net of two grouped layers
 * (30 -> 12 in 3 groups of 10 inputs: the 8-wide pass and its tail; 12 -> 6 in
 * 3 groups) and a dense one, against the same net with the zeros written. */
static void test_ps_mlp_grouped_layers_equal_block_diagonal_dense(void **st)
{
    (void)st;
    enum { G = 3, N0 = 30, N1 = 12, N2 = 6, N3 = 3 };
    static float w0g[N1 * (N0 / G)], w1g[N2 * (N1 / G)], w2[N3 * N2], b0[N1], b1[N2], b2[N3];
    static float w0d[N1 * N0], w1d[N2 * N1];
    uint32_t seed = 7u;
    float *all[] = {w0g, w1g, w2, b0, b1, b2};
    const size_t n_all[] = {N1 * (N0 / G), N2 * (N1 / G), N3 * N2, N1, N2, N3};
    for (size_t a = 0; a < 6; a++)
        for (size_t i = 0; i < n_all[a]; i++) {
            seed = seed * 1664525u + 1013904223u;
            all[a][i] = (float)((int32_t)(seed >> 8) % 2001 - 1000) * 1e-3f;
        }
    /* the dense forms: row o holds its group's weights at its group's inputs */
    for (uint32_t o = 0; o < N1; o++)
        for (uint32_t i = 0; i < N0 / G; i++)
            w0d[o * N0 + (o / (N1 / G)) * (N0 / G) + i] = w0g[o * (N0 / G) + i];
    for (uint32_t o = 0; o < N2; o++)
        for (uint32_t i = 0; i < N1 / G; i++)
            w1d[o * N1 + (o / (N2 / G)) * (N1 / G) + i] = w1g[o * (N1 / G) + i];
    ps_mlp_desc_t dg, dd;
    memset(&dg, 0, sizeof(dg));
    dg.n_layers = 3;
    dg.base[0] = (ps_mlp_dense_desc_t){N0, N1, w0g, b0, G};
    dg.base[1] = (ps_mlp_dense_desc_t){N1, N2, w1g, b1, G};
    dg.base[2] = (ps_mlp_dense_desc_t){N2, N3, w2, b2, 1};
    dg.act[0] = dg.act[1] = PS_MLP_ACT_ELU;
    dd = dg;
    dd.base[0] = (ps_mlp_dense_desc_t){N0, N1, w0d, b0, 0};
    dd.base[1] = (ps_mlp_dense_desc_t){N1, N2, w1d, b1, 0};
    assert_true(ps_mlp_arena_floats(&dg) < ps_mlp_arena_floats(&dd)); /* no zeros held */
    static float ag[4096], ad[4096];
    ps_mlp_t mg, md;
    assert_int_equal(ps_mlp_init(&mg, &dg, ag, 4096), 0);
    assert_int_equal(ps_mlp_init(&md, &dd, ad, 4096), 0);
    for (int r = 0; r < 20; r++) {
        float in[N0], og[N3], od[N3];
        for (int i = 0; i < N0; i++) {
            seed = seed * 1664525u + 1013904223u;
            in[i] = (float)((int32_t)(seed >> 8) % 4001 - 2000) * 1e-3f;
        }
        assert_int_equal(ps_mlp_forward(&mg, in, NULL, og), 0);
        assert_int_equal(ps_mlp_forward(&md, in, NULL, od), 0);
        assert_memory_equal(og, od, sizeof(og));
        assert_true(og[0] != 0.0f);
    }
}

static void test_ps_mlp_init_rejects_bad_descriptions(void **st)
{
    (void)st;
    static float w[64], b[8], arena[1000];
    ps_mlp_desc_t d;
    memset(&d, 0, sizeof(d));
    d.n_layers = 2;
    d.base[0] = (ps_mlp_dense_desc_t){4, 8, w, b, 1};
    d.base[1] = (ps_mlp_dense_desc_t){8, 2, w, b, 1};
    ps_mlp_t m;
    assert_int_equal(ps_mlp_init(&m, &d, arena, 1000), 0);
    assert_int_equal(ps_mlp_init(&m, &d, arena, ps_mlp_arena_floats(&d) - 1), -ENOSPC);
    ps_mlp_desc_t bad = d;
    bad.base[1].n_in = 7; /* does not chain */
    assert_int_equal(ps_mlp_arena_floats(&bad), 0);
    assert_int_equal(ps_mlp_init(&m, &bad, arena, 1000), -EINVAL);
    bad = d;
    bad.adapt[0] = (ps_mlp_dense_desc_t){4, 7, w, b, 1}; /* adapter of another shape */
    assert_int_equal(ps_mlp_init(&m, &bad, arena, 1000), -EINVAL);
    bad = d;
    bad.act[1] = PS_MLP_ACT_COUNT;
    assert_int_equal(ps_mlp_init(&m, &bad, arena, 1000), -EINVAL);
    bad = d;
    bad.n_embed = 1;
    bad.embed[0] = (ps_mlp_dense_desc_t){3, 5, w, b, 1}; /* not layer 0's 8 outputs */
    assert_int_equal(ps_mlp_init(&m, &bad, arena, 1000), -EINVAL);
    bad = d;
    bad.base[1].w = NULL;
    assert_int_equal(ps_mlp_init(&m, &bad, arena, 1000), -EINVAL);
    bad = d;
    bad.base[1].n_groups = 3; /* 8 inputs do not split into 3 groups */
    assert_int_equal(ps_mlp_init(&m, &bad, arena, 1000), -EINVAL);
    bad.base[1].n_groups = 4; /* nor 2 outputs into 4 */
    assert_int_equal(ps_mlp_init(&m, &bad, arena, 1000), -EINVAL);
    bad = d;
    bad.base[0].n_groups = 2; /* 4 -> 8 in 2 groups: fine */
    assert_int_equal(ps_mlp_init(&m, &bad, arena, 1000), 0);
    bad.adapt[0] = (ps_mlp_dense_desc_t){4, 8, w, b, 2}; /* adapters are dense */
    assert_int_equal(ps_mlp_init(&m, &bad, arena, 1000), -EINVAL);
    bad = d;
    bad.n_embed = 1;
    bad.embed[0] = (ps_mlp_dense_desc_t){4, 8, w, b, 2}; /* so are embeddings */
    assert_int_equal(ps_mlp_init(&m, &bad, arena, 1000), -EINVAL);
    bad.embed[0].n_groups = 1;
    assert_int_equal(ps_mlp_init(&m, &bad, arena, 1000), 0);
    assert_int_equal(ps_mlp_forward(NULL, w, NULL, b), -EINVAL);
    assert_int_equal(ps_mlp_act_find("elu"), PS_MLP_ACT_ELU);
    assert_int_equal(ps_mlp_act_find("gelu"), -ENOENT);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ps_mlp_forward_matches_pytorch_base_elu),
        cmocka_unit_test(test_ps_mlp_forward_matches_pytorch_adapters),
        cmocka_unit_test(test_ps_mlp_forward_matches_pytorch_every_activation),
        cmocka_unit_test(test_ps_mlp_forward_matches_pytorch_onnx_import),
        cmocka_unit_test(test_ps_mlp_zero_adapters_reproduce_base_exactly),
        cmocka_unit_test(test_ps_mlp_grouped_layers_equal_block_diagonal_dense),
        cmocka_unit_test(test_ps_mlp_init_rejects_bad_descriptions),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
