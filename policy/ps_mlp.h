/*
 * ps_mlp: the float32 MLP inference engine of the policy slot, with
 * AdaptNet-style adapters (Xu et al., "AdaptNet: Policy Adaptation for
 * Physics-Based Character Control", SIGGRAPH Asia 2023; the crowd stage of
 * the Push-and-Step seed paper fine-tunes its policy this way):
 *
 *   base:      h_0 = in;  h_{k+1} = act_k(W_k h_k + b_k [+ adapters])
 *   internal adaptation: a dense layer A_k in parallel with base layer k,
 *              its output added to that layer's pre-activation:
 *              act_k(W_k h_k + b_k + A_k h_k + c_k)
 *   latent injection: extra inputs e go through an embedding MLP (dense
 *              layers E_j with their activations) whose output is added to
 *              the pre-activation of base layer inject_layer.
 *
 * The base stays frozen; an adapter whose last layer is zero (zero weights
 * and bias, the usual initialisation) adds exactly +0.0 to every
 * pre-activation, so the adapted network reproduces the base bit for bit.
 *
 * Descriptions take weights in PyTorch's layout ([n_out][n_in], row-major);
 * init copies them, transposed, into the caller's arena, so the forward pass
 * runs as axpy loops (y += W^T[i] * x[i] over the outputs) that GCC
 * vectorises on x86-64 and aarch64 without fast-math: each output's sum
 * keeps the same order as the scalar loop, so the result does not depend on
 * the vector width. (Measured: docs/policy.md, make bench.)
 *
 * Threads: init on the main thread; forward on one thread at a time (it
 * writes the scratch vectors in the arena). Allocation: none (the caller
 * owns the arena, sized by ps_mlp_arena_floats).
 */
#ifndef PS_MLP_H
#define PS_MLP_H

#include <stddef.h>
#include <stdint.h>

#define PS_MLP_MAX_LAYERS 8u    /**< base layers */
#define PS_MLP_MAX_EMBED  4u    /**< embedding layers of the latent injection */
#define PS_MLP_MAX_WIDTH  2048u /**< widest input, output or hidden vector */

typedef enum {
    PS_MLP_ACT_IDENTITY = 0,
    PS_MLP_ACT_RELU,
    PS_MLP_ACT_ELU, /**< alpha = 1, as torch.nn.ELU() */
    PS_MLP_ACT_TANH,
    PS_MLP_ACT_SIGMOID,
    PS_MLP_ACT_SILU,
    PS_MLP_ACT_COUNT
} ps_mlp_act_t;

/** One dense layer as described (PyTorch layout). A grouped layer (n_groups
 *  G > 1, as torch.nn.Conv1d's groups) is G dense blocks side by side: output
 *  block g (n_out / G outputs) reads input block g (n_in / G inputs) only,
 *  the block-diagonal matrix without its zeros (the hidden layers of an
 *  ensemble, policy/train/ensemble.py). */
typedef struct {
    uint32_t n_in, n_out;
    const float *w;    /**< [n_out][n_in / G]; NULL in adapt[k]: no adapter at layer k */
    const float *b;    /**< [n_out]; NULL: no bias */
    uint32_t n_groups; /**< G; 0 or 1: dense. Base layers only */
} ps_mlp_dense_desc_t;

typedef struct {
    uint32_t n_layers; /**< 1..PS_MLP_MAX_LAYERS */
    ps_mlp_dense_desc_t base[PS_MLP_MAX_LAYERS];
    ps_mlp_act_t act[PS_MLP_MAX_LAYERS];          /**< after each base layer */
    ps_mlp_dense_desc_t adapt[PS_MLP_MAX_LAYERS]; /**< same shape as base[k], or w NULL */
    uint32_t n_embed;                             /**< 0: no latent injection */
    ps_mlp_dense_desc_t embed[PS_MLP_MAX_EMBED];
    ps_mlp_act_t embed_act[PS_MLP_MAX_EMBED];
    uint32_t inject_layer; /**< embed output is added to this base layer's pre-activation */
} ps_mlp_desc_t;

/** A dense layer as the engine holds it (read-only). */
typedef struct {
    uint32_t n_in, n_out, n_groups;
    float *w_t; /**< per group [n_in / G][n_out / G]: transposed; NULL: absent */
    float *b;   /**< [n_out], zeros when the description had none */
} ps_mlp_dense_t;

typedef struct {
    uint32_t n_in, n_extra, n_out; /**< read-only */
    uint32_t n_layers, n_embed, inject_layer;
    ps_mlp_dense_t base[PS_MLP_MAX_LAYERS], adapt[PS_MLP_MAX_LAYERS], embed[PS_MLP_MAX_EMBED];
    ps_mlp_act_t act[PS_MLP_MAX_LAYERS], embed_act[PS_MLP_MAX_EMBED];
    float *h0, *h1, *e0, *e1; /**< scratch vectors, PS_MLP_MAX_WIDTH-bounded, in the arena */
    uint32_t max_width;
} ps_mlp_t;

/** Floats of arena ps_mlp_init needs for d (weights, biases, scratch), or 0
 *  when d is not a valid description (see ps_mlp_init).  @rt INIT */
size_t ps_mlp_arena_floats(const ps_mlp_desc_t *d);

/** Check d, copy its weights (transposed) and biases into arena.
 *  Valid: 1..MAX layers, base[0].n_in >= 1, each layer's n_in equal to the
 *  previous n_out, widths <= PS_MLP_MAX_WIDTH, every base weight present,
 *  each base layer's n_in and n_out multiples of its n_groups (adapters and
 *  embedding layers dense),
 *  activations inside the enum, each adapt[k] either absent (w NULL) or the
 *  shape of base[k]; with n_embed > 0: inject_layer < n_layers, the embedding
 *  layers chained and the last one's n_out equal to base[inject_layer].n_out.
 *  @pre arena holds n_floats floats (ps_mlp_arena_floats(d)); d's arrays are
 *       not kept
 *  @post m ready; m points into arena, which must outlive it
 *  @return 0 | -EINVAL invalid d (or NULL) | -ENOSPC n_floats too small
 *  @rt INIT */
int ps_mlp_init(ps_mlp_t *m, const ps_mlp_desc_t *d, float *arena, size_t n_floats);

/** One forward pass.
 *  @pre init ok; in has n_in floats, extra n_extra (may be NULL when
 *       n_extra is 0: then no injection runs), out n_out
 *  @post out written (NaN in the inputs propagates: the caller checks)
 *  @return 0 | -EINVAL NULL argument  @rt RT-SAFE O(weights), no allocation */
int ps_mlp_forward(ps_mlp_t *m, const float *in, const float *extra, float *out);

/** @return "identity", "relu", "elu", "tanh", "sigmoid", "silu"; NULL out of range */
const char *ps_mlp_act_name(ps_mlp_act_t a);

/** @return the activation of that name, -ENOENT unknown  @rt INIT */
int ps_mlp_act_find(const char *name);

#endif /* PS_MLP_H */
