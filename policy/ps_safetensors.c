#include "ps_safetensors.h"

#include <cjson/cJSON.h>
#include <errno.h>
#include <math.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../rt/ps_err.h"
#include "../rt/ps_limits.h"

void ps_st_free(ps_st_file_t *st)
{
    if (st == NULL)
        return;
    free(st->file);
    for (uint32_t i = 0; i < st->n_meta && i < PS_ST_MAX_META; i++)
        free(st->meta_val[i]);
    memset(st, 0, sizeof(*st));
}

static uint64_t le64(const uint8_t *p)
{
    uint64_t v = 0;
    for (int i = 7; i >= 0; i--)
        v = (v << 8) | p[i];
    return v;
}

/* A non-negative integer that a double holds exactly. */
static bool as_u64(const cJSON *n, uint64_t *out)
{
    if (!cJSON_IsNumber(n) || !(n->valuedouble >= 0.0) || n->valuedouble > 9007199254740992.0 ||
        n->valuedouble != floor(n->valuedouble))
        return false;
    *out = (uint64_t)n->valuedouble;
    return true;
}

static int parse_metadata(ps_st_file_t *st, const cJSON *meta, char *err, size_t err_len)
{
    if (!cJSON_IsObject(meta)) {
        ps_err_format(err, err_len, "__metadata__ is not an object");
        return -EINVAL;
    }
    const cJSON *kv;
    cJSON_ArrayForEach(kv, meta)
    {
        if (!cJSON_IsString(kv)) {
            ps_err_format(err, err_len, "__metadata__.%s: value is not a string", kv->string);
            return -EINVAL;
        }
        if (st->n_meta >= PS_ST_MAX_META || strlen(kv->string) >= PS_ST_NAME_LEN) {
            ps_err_format(err, err_len, "__metadata__: more than %u keys or a key longer than %u",
                          PS_ST_MAX_META, PS_ST_NAME_LEN - 1u);
            return -EINVAL;
        }
        snprintf(st->meta_key[st->n_meta], PS_ST_NAME_LEN, "%s", kv->string);
        st->meta_val[st->n_meta] = strdup(kv->valuestring);
        if (st->meta_val[st->n_meta] == NULL)
            return -ENOMEM;
        st->n_meta++;
    }
    return 0;
}

static int parse_tensor(ps_st_tensor_t *t, const cJSON *e, uint64_t data_len, char *err,
                        size_t err_len)
{
    const char *name = e->string;
    if (strlen(name) >= PS_ST_NAME_LEN) {
        ps_err_format(err, err_len, "tensor name '%.40s...' longer than %u", name,
                      PS_ST_NAME_LEN - 1u);
        return -EINVAL;
    }
    snprintf(t->name, sizeof(t->name), "%s", name);
    if (!cJSON_IsObject(e)) {
        ps_err_format(err, err_len, "tensor %s: entry is not an object", name);
        return -EINVAL;
    }
    const cJSON *kv;
    cJSON_ArrayForEach(kv, e)
    {
        if (strcmp(kv->string, "dtype") != 0 && strcmp(kv->string, "shape") != 0 &&
            strcmp(kv->string, "data_offsets") != 0) {
            ps_err_format(err, err_len, "tensor %s: unknown key '%s'", name, kv->string);
            return -EINVAL;
        }
    }
    const cJSON *dt = cJSON_GetObjectItemCaseSensitive(e, "dtype");
    const cJSON *sh = cJSON_GetObjectItemCaseSensitive(e, "shape");
    const cJSON *of = cJSON_GetObjectItemCaseSensitive(e, "data_offsets");
    if (!cJSON_IsString(dt) || !cJSON_IsArray(sh) || !cJSON_IsArray(of) ||
        cJSON_GetArraySize(of) != 2) {
        ps_err_format(err, err_len, "tensor %s: needs dtype (string), shape (list) and "
                                    "data_offsets ([begin, end])",
                      name);
        return -EINVAL;
    }
    if (strcmp(dt->valuestring, "F32") != 0) {
        ps_err_format(err, err_len, "tensor %s: dtype %s, only F32 is supported", name,
                      dt->valuestring);
        return -ENOTSUP;
    }
    const int nd = cJSON_GetArraySize(sh);
    if (nd > (int)PS_ST_MAX_DIMS) {
        ps_err_format(err, err_len, "tensor %s: %d dimensions, at most %u", name, nd,
                      PS_ST_MAX_DIMS);
        return -EINVAL;
    }
    t->n_dims = (uint32_t)nd;
    t->n_elems = 1;
    for (int d = 0; d < nd; d++) {
        if (!as_u64(cJSON_GetArrayItem(sh, d), &t->shape[d]) || t->shape[d] > PS_ST_MAX_FILE) {
            ps_err_format(err, err_len, "tensor %s: shape[%d] is not a size", name, d);
            return -EINVAL;
        }
        t->n_elems *= t->shape[d];
        if (t->n_elems > PS_ST_MAX_FILE) {
            ps_err_format(err, err_len, "tensor %s: more than %u elements", name, PS_ST_MAX_FILE);
            return -EINVAL;
        }
    }
    if (!as_u64(cJSON_GetArrayItem(of, 0), &t->begin) ||
        !as_u64(cJSON_GetArrayItem(of, 1), &t->end) || t->end < t->begin) {
        ps_err_format(err, err_len, "tensor %s: data_offsets are not [begin, end] with begin <= end",
                      name);
        return -EINVAL;
    }
    if (t->end > data_len) {
        ps_err_format(err, err_len,
                      "tensor %s: data_offsets [%llu, %llu) beyond the data section (%llu bytes)",
                      name, (unsigned long long)t->begin, (unsigned long long)t->end,
                      (unsigned long long)data_len);
        return -EINVAL;
    }
    if (t->end - t->begin != 4u * t->n_elems) {
        ps_err_format(err, err_len,
                      "tensor %s: %llu bytes for %llu F32 elements (shape), want %llu", name,
                      (unsigned long long)(t->end - t->begin), (unsigned long long)t->n_elems,
                      (unsigned long long)(4u * t->n_elems));
        return -EINVAL;
    }
    return 0;
}

static int cmp_begin(const void *a, const void *b)
{
    const ps_st_tensor_t *x = a, *y = b;
    return x->begin < y->begin ? -1 : (x->begin > y->begin ? 1 : 0);
}

/* Tensors must tile the data section: no overlap, no hole, nothing left. */
static int check_layout(const ps_st_file_t *st, uint64_t data_len, char *err, size_t err_len)
{
    ps_st_tensor_t sorted[PS_ST_MAX_TENSORS];
    memcpy(sorted, st->tensors, st->n_tensors * sizeof(sorted[0]));
    qsort(sorted, st->n_tensors, sizeof(sorted[0]), cmp_begin);
    uint64_t at = 0;
    for (uint32_t i = 0; i < st->n_tensors; i++) {
        if (sorted[i].begin < at) {
            ps_err_format(err, err_len, "tensor %s: bytes [%llu, %llu) overlap tensor %s",
                          sorted[i].name, (unsigned long long)sorted[i].begin,
                          (unsigned long long)sorted[i].end, sorted[i - 1].name);
            return -EINVAL;
        }
        if (sorted[i].begin > at) {
            ps_err_format(err, err_len, "bytes [%llu, %llu) of the data section belong to no tensor",
                          (unsigned long long)at, (unsigned long long)sorted[i].begin);
            return -EINVAL;
        }
        at = sorted[i].end;
    }
    if (at != data_len) {
        ps_err_format(err, err_len, "bytes [%llu, %llu) of the data section belong to no tensor",
                      (unsigned long long)at, (unsigned long long)data_len);
        return -EINVAL;
    }
    return 0;
}

static int parse_owned(ps_st_file_t *st, char *err, size_t err_len)
{
    if (st->file_len < 8u) {
        ps_err_format(err, err_len, "%zu bytes: shorter than the 8-byte header length",
                      st->file_len);
        return -EINVAL;
    }
    const uint64_t n = le64(st->file);
    if (n == 0 || n > PS_ST_MAX_HEADER || n > st->file_len - 8u) {
        ps_err_format(err, err_len, "header length %llu: beyond the file (%zu bytes) or %u",
                      (unsigned long long)n, st->file_len, PS_ST_MAX_HEADER);
        return -EINVAL;
    }
    st->data_off = 8u + (size_t)n;
    const uint64_t data_len = st->file_len - st->data_off;
    cJSON *root = cJSON_ParseWithLength((const char *)st->file + 8, (size_t)n);
    if (root == NULL || !cJSON_IsObject(root)) {
        ps_err_format(err, err_len, "header is not a JSON object");
        cJSON_Delete(root);
        return -EINVAL;
    }
    int rc = 0;
    const cJSON *e;
    cJSON_ArrayForEach(e, root)
    {
        if (strcmp(e->string, "__metadata__") == 0) {
            rc = parse_metadata(st, e, err, err_len);
        } else if (st->n_tensors >= PS_ST_MAX_TENSORS) {
            ps_err_format(err, err_len, "more than %u tensors", PS_ST_MAX_TENSORS);
            rc = -EINVAL;
        } else {
            for (uint32_t i = 0; i < st->n_tensors && rc == 0; i++)
                if (strcmp(st->tensors[i].name, e->string) == 0) {
                    ps_err_format(err, err_len, "tensor %s: listed twice", e->string);
                    rc = -EINVAL;
                }
            if (rc == 0)
                rc = parse_tensor(&st->tensors[st->n_tensors++], e, data_len, err, err_len);
        }
        if (rc != 0)
            break;
    }
    cJSON_Delete(root);
    if (rc == 0)
        rc = check_layout(st, data_len, err, err_len);
    return rc;
}

int ps_st_parse(ps_st_file_t *st, const uint8_t *bytes, size_t len, char *err, size_t err_len)
{
    if (st == NULL || bytes == NULL)
        return -EINVAL;
    memset(st, 0, sizeof(*st));
    st->file = malloc(len > 0 ? len : 1u);
    if (st->file == NULL)
        return -ENOMEM;
    memcpy(st->file, bytes, len);
    st->file_len = len;
    const int rc = parse_owned(st, err, err_len);
    if (rc != 0)
        ps_st_free(st);
    return rc;
}

int ps_st_load(ps_st_file_t *st, const char *path, char *err, size_t err_len)
{
    if (st == NULL || path == NULL)
        return -EINVAL;
    memset(st, 0, sizeof(*st));
    FILE *f = fopen(path, "rb");
    if (f == NULL) {
        const int e = errno;
        ps_err_format(err, err_len, "%s: cannot open: %s", path, strerror(e));
        return e == ENOENT ? -ENOENT : -EIO;
    }
    int rc = 0;
    long len = -1;
    if (fseek(f, 0, SEEK_END) == 0)
        len = ftell(f);
    if (len < 0 || (unsigned long)len > PS_ST_MAX_FILE || fseek(f, 0, SEEK_SET) != 0) {
        ps_err_format(err, err_len, "%s: not a regular file of at most %u bytes", path,
                      PS_ST_MAX_FILE);
        rc = -EINVAL;
    }
    if (rc == 0) {
        st->file = malloc(len > 0 ? (size_t)len : 1u);
        st->file_len = (size_t)len;
        if (st->file == NULL)
            rc = -ENOMEM;
        else if (fread(st->file, 1, (size_t)len, f) != (size_t)len) {
            ps_err_format(err, err_len, "%s: read error", path);
            rc = -EIO;
        }
    }
    (void)fclose(f); /* read-only: nothing to lose */
    if (rc == 0) {
        char why[PS_ERR_MSG_LEN] = "";
        rc = parse_owned(st, why, sizeof(why));
        if (rc != 0)
            ps_err_format(err, err_len, "%s: %s", path, why);
    }
    if (rc != 0)
        ps_st_free(st);
    return rc;
}

const ps_st_tensor_t *ps_st_find(const ps_st_file_t *st, const char *name)
{
    for (uint32_t i = 0; st != NULL && name != NULL && i < st->n_tensors; i++)
        if (strcmp(st->tensors[i].name, name) == 0)
            return &st->tensors[i];
    return NULL;
}

int ps_st_copy_f32(const ps_st_file_t *st, const ps_st_tensor_t *t, float *out, size_t n_max,
                   char *err, size_t err_len)
{
    if (st == NULL || t == NULL || out == NULL)
        return -EINVAL;
    if (t->n_elems > n_max) {
        ps_err_format(err, err_len, "tensor %s: %llu elements, room for %zu", t->name,
                      (unsigned long long)t->n_elems, n_max);
        return -ENOSPC;
    }
    const uint8_t *src = st->file + st->data_off + t->begin;
    for (uint64_t i = 0; i < t->n_elems; i++) {
        uint32_t u = (uint32_t)src[4 * i] | (uint32_t)src[4 * i + 1] << 8 |
                     (uint32_t)src[4 * i + 2] << 16 | (uint32_t)src[4 * i + 3] << 24;
        float v;
        memcpy(&v, &u, sizeof(v));
        if (!isfinite(v)) {
            ps_err_format(err, err_len, "tensor %s: element %llu is %s", t->name,
                          (unsigned long long)i, isnan(v) ? "NaN" : "infinite");
            return -ERANGE;
        }
        out[i] = v;
    }
    return (int)t->n_elems;
}

const char *ps_st_metadata(const ps_st_file_t *st, const char *key)
{
    for (uint32_t i = 0; st != NULL && key != NULL && i < st->n_meta; i++)
        if (strcmp(st->meta_key[i], key) == 0)
            return st->meta_val[i];
    return NULL;
}
