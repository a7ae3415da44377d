#include "ps_weights.h"

#include <cjson/cJSON.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../rt/ps_err.h"
#include "ps_safetensors.h"

void ps_weights_free(ps_weights_t *w)
{
    if (w == NULL)
        return;
    free(w->arena);
    memset(w, 0, sizeof(*w));
}

/* ---- contract --------------------------------------------------------- */

static int get_floats(const cJSON *o, const char *key, float *out, uint32_t n_max, uint32_t *out_n,
                      char *err, size_t err_len)
{
    const cJSON *a = cJSON_GetObjectItemCaseSensitive(o, key);
    if (!cJSON_IsArray(a) || (uint32_t)cJSON_GetArraySize(a) > n_max) {
        ps_err_format(err, err_len, "contract: %s is not a list of at most %u numbers", key, n_max);
        return -EINVAL;
    }
    uint32_t n = 0;
    const cJSON *v;
    cJSON_ArrayForEach(v, a)
    {
        if (!cJSON_IsNumber(v) || !isfinite(v->valuedouble)) {
            ps_err_format(err, err_len, "contract: %s[%u] is not a finite number", key, n);
            return -EINVAL;
        }
        out[n++] = (float)v->valuedouble;
    }
    *out_n = n;
    return 0;
}

static int get_names(const cJSON *o, const char *key, char (*out)[PS_NAME_LEN], uint32_t n_max,
                     uint32_t *out_n, char *err, size_t err_len)
{
    const cJSON *a = cJSON_GetObjectItemCaseSensitive(o, key);
    if (!cJSON_IsArray(a) || (uint32_t)cJSON_GetArraySize(a) > n_max) {
        ps_err_format(err, err_len, "contract: %s is not a list of at most %u names", key, n_max);
        return -EINVAL;
    }
    uint32_t n = 0;
    const cJSON *v;
    cJSON_ArrayForEach(v, a)
    {
        if (!cJSON_IsString(v) || strlen(v->valuestring) >= PS_NAME_LEN ||
            v->valuestring[0] == '\0') {
            ps_err_format(err, err_len, "contract: %s[%u] is not a name of 1..%u characters", key,
                          n, PS_NAME_LEN - 1u);
            return -EINVAL;
        }
        snprintf(out[n++], PS_NAME_LEN, "%s", v->valuestring);
    }
    *out_n = n;
    return 0;
}

/* action.base: absent or "stance", or "capture". */
static int get_base(const cJSON *act, ps_weights_base_t *out, char *err, size_t err_len)
{
    const cJSON *b = cJSON_GetObjectItemCaseSensitive(act, "base");
    *out = PS_WEIGHTS_BASE_STANCE;
    if (b == NULL)
        return 0;
    if (cJSON_IsString(b) && strcmp(b->valuestring, "stance") == 0)
        return 0;
    if (cJSON_IsString(b) && strcmp(b->valuestring, "capture") == 0) {
        *out = PS_WEIGHTS_BASE_CAPTURE;
        return 0;
    }
    ps_err_format(err, err_len, "contract: action.base %s is not \"stance\" or \"capture\"",
                  cJSON_IsString(b) ? b->valuestring : "(not a string)");
    return -EINVAL;
}

static int get_number(const cJSON *o, const char *key, double lo, double hi, double *out, char *err,
                      size_t err_len)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, key);
    if (!cJSON_IsNumber(v) || !(v->valuedouble >= lo) || !(v->valuedouble <= hi)) {
        ps_err_format(err, err_len, "contract: %s is not a number in [%g, %g]", key, lo, hi);
        return -EINVAL;
    }
    *out = v->valuedouble;
    return 0;
}

static int expect_n(const char *key, uint32_t got, uint32_t want, char *err, size_t err_len)
{
    if (got == want)
        return 0;
    ps_err_format(err, err_len, "contract: %s has %u entries, want %u", key, got, want);
    return -EINVAL;
}

/* Activations and groups of the layers. */
typedef struct {
    ps_mlp_act_t act[PS_MLP_MAX_LAYERS], embed_act[PS_MLP_MAX_EMBED];
    uint32_t n_act, n_embed_act, inject_layer;
    uint32_t groups[PS_MLP_MAX_LAYERS], n_groups; /**< n_groups 0: every layer dense */
} net_spec_t;

/* "groups": one whole number >= 1 per base layer (optional). */
static int get_groups(const cJSON *o, net_spec_t *ns, char *err, size_t err_len)
{
    float g[PS_MLP_MAX_LAYERS];
    int rc = get_floats(o, "groups", g, PS_MLP_MAX_LAYERS, &ns->n_groups, err, err_len);
    for (uint32_t k = 0; rc == 0 && k < ns->n_groups; k++) {
        if (!(g[k] >= 1.0f && g[k] <= (float)PS_MLP_MAX_WIDTH && g[k] == floorf(g[k]))) {
            ps_err_format(err, err_len, "contract: groups[%u] is %g, not a whole number >= 1", k,
                          (double)g[k]);
            return -EINVAL;
        }
        ns->groups[k] = (uint32_t)g[k];
    }
    return rc;
}

static int get_acts(const cJSON *o, const char *key, ps_mlp_act_t *out, uint32_t n_max,
                    uint32_t *out_n, char *err, size_t err_len)
{
    char names[PS_MLP_MAX_LAYERS][PS_NAME_LEN];
    int rc = get_names(o, key, names, n_max, out_n, err, err_len);
    for (uint32_t i = 0; rc == 0 && i < *out_n; i++) {
        const int a = ps_mlp_act_find(names[i]);
        if (a < 0) {
            ps_err_format(err, err_len,
                          "contract: %s[%u] '%s' is not an activation (identity, relu, elu, "
                          "tanh, sigmoid, silu)",
                          key, i, names[i]);
            return -EINVAL;
        }
        out[i] = (ps_mlp_act_t)a;
    }
    return rc;
}

static int parse_contract(const char *json, ps_weights_contract_t *c, net_spec_t *ns, char *err,
                          size_t err_len)
{
    cJSON *root = cJSON_Parse(json);
    if (!cJSON_IsObject(root)) {
        ps_err_format(err, err_len, "contract: metadata %s is not a JSON object",
                      PS_WEIGHTS_CONTRACT_KEY);
        cJSON_Delete(root);
        return -EINVAL;
    }
    memset(c, 0, sizeof(*c));
    memset(ns, 0, sizeof(*ns));
    double v = 0.0;
    uint32_t n = 0;
    int rc = get_number(root, "version", 1, 1000, &v, err, err_len);
    if (rc == 0 && (uint32_t)v != PS_WEIGHTS_VERSION) {
        ps_err_format(err, err_len, "contract: version %g, this runtime reads version %u", v,
                      PS_WEIGHTS_VERSION);
        rc = -EINVAL;
    }
    c->version = (uint32_t)v;
    const cJSON *robot = cJSON_GetObjectItemCaseSensitive(root, "robot");
    if (rc == 0 && cJSON_IsString(robot))
        snprintf(c->robot, sizeof(c->robot), "%s", robot->valuestring);
    const cJSON *by = cJSON_GetObjectItemCaseSensitive(root, "trained_by");
    if (rc == 0 && cJSON_IsString(by))
        snprintf(c->trained_by, sizeof(c->trained_by), "%s", by->valuestring);
    if (rc == 0)
        rc = get_number(root, "policy_hz", 1, 10000, &v, err, err_len);
    c->policy_hz = (uint32_t)v;
    if (rc == 0)
        rc = get_names(root, "joints", c->joint_name, PS_MAX_JOINTS, &c->n_joints, err, err_len);
    if (rc == 0)
        rc = get_floats(root, "kp", c->kp_nm_rad, PS_MAX_JOINTS, &n, err, err_len);
    if (rc == 0)
        rc = expect_n("kp", n, c->n_joints, err, err_len);
    if (rc == 0)
        rc = get_floats(root, "kd", c->kd_nm_s_rad, PS_MAX_JOINTS, &n, err, err_len);
    if (rc == 0)
        rc = expect_n("kd", n, c->n_joints, err, err_len);
    if (rc == 0)
        rc = get_floats(root, "stance", c->stance_rad, PS_MAX_JOINTS, &n, err, err_len);
    if (rc == 0)
        rc = expect_n("stance", n, c->n_joints, err, err_len);

    const cJSON *act = cJSON_GetObjectItemCaseSensitive(root, "action");
    char act_names[PS_MAX_JOINTS][PS_NAME_LEN];
    if (rc == 0 && !cJSON_IsObject(act)) {
        ps_err_format(err, err_len, "contract: action is not an object");
        rc = -EINVAL;
    }
    if (rc == 0)
        rc = get_names(act, "joints", act_names, PS_MAX_JOINTS, &c->n_act, err, err_len);
    for (uint32_t a = 0; rc == 0 && a < c->n_act; a++) {
        uint32_t j = 0;
        while (j < c->n_joints && strcmp(c->joint_name[j], act_names[a]) != 0)
            j++;
        if (j == c->n_joints) {
            ps_err_format(err, err_len, "contract: action.joints[%u] '%s' is not in joints", a,
                          act_names[a]);
            rc = -EINVAL;
        }
        c->act_joint[a] = j;
    }
    if (rc == 0)
        rc = get_floats(act, "scale", c->act_scale, PS_MAX_JOINTS, &n, err, err_len);
    if (rc == 0)
        rc = expect_n("action.scale", n, c->n_act, err, err_len);
    if (rc == 0)
        rc = get_number(act, "clip", 1e-6, 1e6, &v, err, err_len);
    c->act_clip = (float)v;
    if (rc == 0)
        rc = get_base(act, &c->act_base, err, err_len);

    const cJSON *obs = cJSON_GetObjectItemCaseSensitive(root, "observation");
    char fnames[PS_OBS_MAX_FIELDS][PS_NAME_LEN];
    if (rc == 0 && !cJSON_IsObject(obs)) {
        ps_err_format(err, err_len, "contract: observation is not an object");
        rc = -EINVAL;
    }
    if (rc == 0)
        rc = get_names(obs, "fields", fnames, PS_OBS_MAX_FIELDS, &c->n_fields, err, err_len);
    for (uint32_t f = 0; rc == 0 && f < c->n_fields; f++) {
        const int id = ps_obs_field_find(fnames[f]);
        if (id < 0) {
            ps_err_format(err, err_len,
                          "contract: observation.fields[%u] '%s' is not a field of "
                          "the observation builder (policy/ps_obs.h)",
                          f, fnames[f]);
            rc = -EINVAL;
        } else if (id == PS_OBS_BASE_ACTION && c->act_base != PS_WEIGHTS_BASE_CAPTURE) {
            ps_err_format(err, err_len,
                          "contract: observation.fields[%u] 'base_action' needs "
                          "action.base \"capture\" (a residual policy): there is no base",
                          f);
            rc = -EINVAL;
        } else {
            c->fields[f] = (ps_obs_field_t)id;
            c->n_obs += ps_obs_field_size(c->fields[f], c->n_joints, c->n_act);
        }
    }
    if (rc == 0 && c->n_obs > PS_OBS_MAX) {
        ps_err_format(err, err_len, "contract: %u observation floats, at most %u", c->n_obs,
                      PS_OBS_MAX);
        rc = -EINVAL;
    }
    if (rc == 0)
        rc = get_floats(obs, "mean", c->obs_mean, PS_OBS_MAX, &n, err, err_len);
    if (rc == 0)
        rc = expect_n("observation.mean", n, c->n_obs, err, err_len);
    if (rc == 0)
        rc = get_floats(obs, "std", c->obs_std, PS_OBS_MAX, &n, err, err_len);
    if (rc == 0)
        rc = expect_n("observation.std", n, c->n_obs, err, err_len);
    for (uint32_t i = 0; rc == 0 && i < c->n_obs; i++)
        if (!(c->obs_std[i] > 0.0f)) {
            ps_err_format(err, err_len, "contract: observation.std[%u] = %g is not > 0", i,
                          (double)c->obs_std[i]);
            rc = -EINVAL;
        }
    if (rc == 0)
        rc = get_number(obs, "clip", 1e-6, 1e6, &v, err, err_len);
    c->obs_clip = (float)v;

    if (rc == 0)
        rc = get_acts(root, "activations", ns->act, PS_MLP_MAX_LAYERS, &ns->n_act, err, err_len);
    const cJSON *ea = cJSON_GetObjectItemCaseSensitive(root, "embed_activations");
    if (rc == 0 && ea != NULL)
        rc = get_acts(root, "embed_activations", ns->embed_act, PS_MLP_MAX_EMBED, &ns->n_embed_act,
                      err, err_len);
    if (rc == 0 && cJSON_GetObjectItemCaseSensitive(root, "groups") != NULL)
        rc = get_groups(root, ns, err, err_len);
    if (rc == 0 && cJSON_GetObjectItemCaseSensitive(root, "inject_layer") != NULL) {
        rc = get_number(root, "inject_layer", 0, PS_MLP_MAX_LAYERS - 1, &v, err, err_len);
        ns->inject_layer = (uint32_t)v;
    }
    if (rc == 0 && cJSON_GetObjectItemCaseSensitive(root, "extra_size") != NULL) {
        rc = get_number(root, "extra_size", 0, PS_MLP_MAX_WIDTH, &v, err, err_len);
        c->n_extra = (uint32_t)v;
    }
    cJSON_Delete(root);
    return rc;
}

/* ---- tensors ------------------------------------------------------------ */

/* "base.3.weight" -> kind 0, index 3, is_bias false. */
static int tensor_role(const char *name, int *kind, uint32_t *idx, bool *is_bias)
{
    static const char *const KINDS[3] = {"base.", "adapt.", "embed."};
    for (int k = 0; k < 3; k++) {
        const size_t n = strlen(KINDS[k]);
        if (strncmp(name, KINDS[k], n) != 0)
            continue;
        char *end = NULL;
        const unsigned long i = strtoul(name + n, &end, 10);
        if (end == name + n || i >= PS_MLP_MAX_LAYERS)
            return -EINVAL;
        if (strcmp(end, ".weight") == 0)
            *is_bias = false;
        else if (strcmp(end, ".bias") == 0)
            *is_bias = true;
        else
            return -EINVAL;
        *kind = k;
        *idx = (uint32_t)i;
        return 0;
    }
    return -EINVAL;
}

/* Values of every tensor, finite, in one temporary buffer; layer
 * descriptions point into it. */
static int build_desc(const ps_st_file_t *st, const net_spec_t *ns, ps_mlp_desc_t *d,
                      float **out_vals, char *err, size_t err_len)
{
    size_t total = 0;
    for (uint32_t i = 0; i < st->n_tensors; i++)
        total += st->tensors[i].n_elems;
    float *vals = malloc((total > 0 ? total : 1u) * sizeof(float));
    if (vals == NULL)
        return -ENOMEM;
    *out_vals = vals;
    memset(d, 0, sizeof(*d));
    ps_mlp_dense_desc_t *layers[3] = {d->base, d->adapt, d->embed};
    uint32_t count[3] = {0, 0, 0};
    size_t at = 0;
    for (uint32_t i = 0; i < st->n_tensors; i++) {
        const ps_st_tensor_t *t = &st->tensors[i];
        int kind = 0;
        uint32_t idx = 0;
        bool is_bias = false;
        if (tensor_role(t->name, &kind, &idx, &is_bias) != 0 ||
            (kind == 2 && idx >= PS_MLP_MAX_EMBED)) {
            ps_err_format(err, err_len,
                          "tensor %s: not a layer of a policy file (base.K, adapt.K or embed.J "
                          ".weight/.bias)",
                          t->name);
            return -EINVAL;
        }
        const int rc = ps_st_copy_f32(st, t, vals + at, total - at, err, err_len);
        if (rc < 0)
            return rc;
        ps_mlp_dense_desc_t *l = &layers[kind][idx];
        if (is_bias) {
            if (t->n_dims != 1) {
                ps_err_format(err, err_len, "tensor %s: a bias has 1 dimension, not %u", t->name,
                              t->n_dims);
                return -EINVAL;
            }
            l->b = vals + at;
            if (l->n_out != 0 && l->n_out != t->shape[0]) {
                ps_err_format(err, err_len, "tensor %s: %llu outputs, its weight has %u", t->name,
                              (unsigned long long)t->shape[0], l->n_out);
                return -EINVAL;
            }
            l->n_out = (uint32_t)t->shape[0];
        } else {
            if (t->n_dims != 2 || t->shape[0] > PS_MLP_MAX_WIDTH ||
                t->shape[1] > PS_MLP_MAX_WIDTH) {
                ps_err_format(err, err_len, "tensor %s: a weight is [out, in] with sizes up to %u",
                              t->name, PS_MLP_MAX_WIDTH);
                return -EINVAL;
            }
            if (l->b != NULL && l->n_out != t->shape[0]) {
                ps_err_format(err, err_len, "tensor %s: %llu outputs, its bias has %u", t->name,
                              (unsigned long long)t->shape[0], l->n_out);
                return -EINVAL;
            }
            l->w = vals + at;
            l->n_out = (uint32_t)t->shape[0];
            l->n_in = (uint32_t)t->shape[1];
            count[kind] = idx + 1 > count[kind] ? idx + 1 : count[kind];
        }
        at += t->n_elems;
    }
    d->n_layers = count[0];
    d->n_embed = count[2];
    for (int k = 0; k < 3; k++)
        for (uint32_t i = 0; i < (k == 2 ? PS_MLP_MAX_EMBED : PS_MLP_MAX_LAYERS); i++) {
            const ps_mlp_dense_desc_t *l = &layers[k][i];
            const bool is_used = i < count[k];
            if ((l->b != NULL && l->w == NULL) || (k != 1 && is_used && l->w == NULL)) {
                static const char *const KN[3] = {"base", "adapt", "embed"};
                ps_err_format(err, err_len, "tensor %s.%u.weight is missing", KN[k], i);
                return -EINVAL;
            }
        }
    if (d->n_layers == 0) {
        ps_err_format(err, err_len, "no base.0.weight: not a policy file");
        return -EINVAL;
    }
    if (ns->n_act != d->n_layers || ns->n_embed_act != d->n_embed) {
        ps_err_format(err, err_len,
                      "contract: %u activations for %u base layers, %u embed_activations for %u "
                      "embedding layers",
                      ns->n_act, d->n_layers, ns->n_embed_act, d->n_embed);
        return -EINVAL;
    }
    if (ns->n_groups != 0 && ns->n_groups != d->n_layers) {
        ps_err_format(err, err_len, "contract: %u groups for %u base layers", ns->n_groups,
                      d->n_layers);
        return -EINVAL;
    }
    /* a grouped layer's weight is [out, in / G]: its input is G times wider */
    for (uint32_t k = 0; k < ns->n_groups; k++) {
        ps_mlp_dense_desc_t *l = &d->base[k];
        const uint64_t n_in = (uint64_t)l->n_in * ns->groups[k];
        if (n_in > PS_MLP_MAX_WIDTH || l->n_out % ns->groups[k] != 0u) {
            ps_err_format(err, err_len,
                          "tensor base.%u.weight: [%u, %u] in %u groups (inputs %llu, at most "
                          "%u; outputs a multiple of the groups)",
                          k, l->n_out, l->n_in, ns->groups[k], (unsigned long long)n_in,
                          PS_MLP_MAX_WIDTH);
            return -EINVAL;
        }
        l->n_in = (uint32_t)n_in;
        l->n_groups = ns->groups[k];
    }
    memcpy(d->act, ns->act, sizeof(d->act));
    memcpy(d->embed_act, ns->embed_act, sizeof(d->embed_act));
    d->inject_layer = ns->inject_layer;
    return 0;
}

int ps_weights_load(ps_weights_t *w, const char *path, char *err, size_t err_len)
{
    if (w == NULL || path == NULL)
        return -EINVAL;
    memset(w, 0, sizeof(*w));
    ps_st_file_t st;
    int rc = ps_st_load(&st, path, err, err_len);
    if (rc != 0)
        return rc;
    char why[PS_ERR_MSG_LEN] = "";
    net_spec_t ns;
    const char *json = ps_st_metadata(&st, PS_WEIGHTS_CONTRACT_KEY);
    if (json == NULL) {
        ps_err_format(why, sizeof(why), "no metadata %s: not a pushstep policy file",
                      PS_WEIGHTS_CONTRACT_KEY);
        rc = -EINVAL;
    }
    if (rc == 0)
        rc = parse_contract(json, &w->contract, &ns, why, sizeof(why));
    float *vals = NULL;
    ps_mlp_desc_t d;
    if (rc == 0)
        rc = build_desc(&st, &ns, &d, &vals, why, sizeof(why));
    const ps_weights_contract_t *c = &w->contract;
    if (rc == 0 && d.base[0].n_in != c->n_obs) {
        ps_err_format(why, sizeof(why),
                      "base.0 takes %u inputs, the contract's observation has %u floats",
                      d.base[0].n_in, c->n_obs);
        rc = -EINVAL;
    }
    if (rc == 0 && d.base[d.n_layers - 1].n_out != c->n_act) {
        ps_err_format(why, sizeof(why), "base.%u gives %u outputs, the contract has %u actions",
                      d.n_layers - 1, d.base[d.n_layers - 1].n_out, c->n_act);
        rc = -EINVAL;
    }
    if (rc == 0 && d.n_embed > 0 && d.embed[0].n_in != c->n_extra) {
        ps_err_format(why, sizeof(why), "embed.0 takes %u inputs, the contract's extra_size is %u",
                      d.embed[0].n_in, c->n_extra);
        rc = -EINVAL;
    }
    if (rc == 0) {
        w->n_arena = ps_mlp_arena_floats(&d);
        if (w->n_arena == 0) {
            ps_err_format(why, sizeof(why),
                          "the layers do not chain (each input the previous output; adapters "
                          "the shape of their layer; the embedding's output that of layer "
                          "inject_layer)");
            rc = -EINVAL;
        }
    }
    if (rc == 0) {
        w->arena = malloc(w->n_arena * sizeof(float));
        rc = w->arena == NULL ? -ENOMEM : ps_mlp_init(&w->mlp, &d, w->arena, w->n_arena);
    }
    free(vals);
    ps_st_free(&st);
    if (rc != 0) {
        ps_err_format(err, err_len, "%s: %s", path, why);
        ps_weights_free(w);
    }
    return rc;
}

int ps_weights_check_robot(const ps_weights_contract_t *c, uint32_t n_joints,
                           const char (*joint_name)[PS_NAME_LEN], const ps_servo_joint_cfg_t *servo,
                           uint32_t policy_hz, char *err, size_t err_len)
{
    if (c == NULL || joint_name == NULL || servo == NULL)
        return -EINVAL;
    if (c->policy_hz != policy_hz) {
        ps_err_format(err, err_len, "policy_hz: policy trained at %u Hz, robot file runs %u Hz",
                      c->policy_hz, policy_hz);
        return -PS_ERR_CONFIG;
    }
    const uint32_t n = c->n_joints < n_joints ? c->n_joints : n_joints;
    for (uint32_t j = 0; j < n; j++)
        if (strncmp(c->joint_name[j], joint_name[j], PS_NAME_LEN) != 0) {
            ps_err_format(err, err_len,
                          "joints[%u]: policy has %s, robot file has %s (trained for another "
                          "joint order or robot)",
                          j, c->joint_name[j], joint_name[j]);
            return -PS_ERR_CONFIG;
        }
    if (c->n_joints != n_joints) {
        ps_err_format(err, err_len, "joints: policy has %u joints, robot file %u", c->n_joints,
                      n_joints);
        return -PS_ERR_CONFIG;
    }
    for (uint32_t j = 0; j < n_joints; j++) {
        const ps_servo_joint_cfg_t *s = &servo[j];
        const struct {
            const char *key;
            float policy, robot, tol;
        } v[3] = {
            {"kp_nm_rad", c->kp_nm_rad[j], s->kp_nm_rad, 1e-3f * fmaxf(1.0f, s->kp_nm_rad)},
            {"kd_nm_s_rad", c->kd_nm_s_rad[j], s->kd_nm_s_rad, 1e-3f * fmaxf(1.0f, s->kd_nm_s_rad)},
            {"stance_rad", c->stance_rad[j], s->stance_rad, 1e-4f},
        };
        for (int k = 0; k < 3; k++)
            if (!(fabsf(v[k].policy - v[k].robot) <= v[k].tol)) {
                ps_err_format(err, err_len,
                              "joints[%u] %s: %s: policy trained with %g, robot file has %g", j,
                              joint_name[j], v[k].key, (double)v[k].policy, (double)v[k].robot);
                return -PS_ERR_CONFIG;
            }
    }
    return 0;
}
