#include "ps_rosmsg.h"

#include <ctype.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ps_err.h"

static const struct {
    const char *name;
    size_t size;
} TYPES[PS_ROSMSG_TYPE_COUNT] = {
    [PS_ROSMSG_BOOL] = {"bool", 1},       [PS_ROSMSG_UINT8] = {"uint8", 1},
    [PS_ROSMSG_INT8] = {"int8", 1},       [PS_ROSMSG_UINT16] = {"uint16", 2},
    [PS_ROSMSG_INT16] = {"int16", 2},     [PS_ROSMSG_UINT32] = {"uint32", 4},
    [PS_ROSMSG_INT32] = {"int32", 4},     [PS_ROSMSG_UINT64] = {"uint64", 8},
    [PS_ROSMSG_INT64] = {"int64", 8},     [PS_ROSMSG_FLOAT32] = {"float32", 4},
    [PS_ROSMSG_FLOAT64] = {"float64", 8}, [PS_ROSMSG_STRING] = {"string", 1},
};

const char *ps_rosmsg_type_name(ps_rosmsg_type_t t)
{
    return t < PS_ROSMSG_TYPE_COUNT ? TYPES[t].name : "?";
}

size_t ps_rosmsg_type_size(ps_rosmsg_type_t t)
{
    return t < PS_ROSMSG_TYPE_COUNT ? TYPES[t].size : 0;
}

int ps_rosmsg_schema_text(const ps_rosmsg_def_t *def, char *buf, size_t cap)
{
    size_t used = 0;
    if (cap > 0)
        buf[0] = '\0';
    for (uint32_t i = 0; i < def->n_fields; i++) {
        const ps_rosmsg_field_t *f = &def->fields[i];
        if (f->type >= PS_ROSMSG_TYPE_COUNT || f->kind > PS_ROSMSG_SEQUENCE)
            return -EINVAL;
        char dims[16] = "";
        if (f->kind == PS_ROSMSG_ARRAY)
            snprintf(dims, sizeof(dims), "[%u]", f->count);
        else if (f->kind == PS_ROSMSG_SEQUENCE)
            snprintf(dims, sizeof(dims), "[]");
        int n = snprintf(buf + used, cap - used, "%s%s %s%s%s\n", TYPES[f->type].name, dims,
                         f->name, f->doc ? "  # " : "", f->doc ? f->doc : "");
        if (n < 0 || (size_t)n >= cap - used)
            return -ENOSPC;
        used += (size_t)n;
    }
    return (int)used;
}

/* ---- encoding ----------------------------------------------------------- */

typedef struct {
    uint8_t *buf;
    size_t cap, pos;
    bool is_full;
} cdr_out_t;

/* Alignment counts from the end of the encapsulation header. */
static void put_align(cdr_out_t *o, size_t size)
{
    while (((o->pos - PS_ROSMSG_HEADER_LEN) % size) != 0) {
        if (o->pos >= o->cap) {
            o->is_full = true;
            return;
        }
        o->buf[o->pos++] = 0;
    }
}

static void put_bytes(cdr_out_t *o, const void *p, size_t n)
{
    if (o->is_full || n > o->cap - o->pos) {
        o->is_full = true;
        return;
    }
    memcpy(o->buf + o->pos, p, n);
    o->pos += n;
}

static void put_u32(cdr_out_t *o, uint32_t v)
{
    put_align(o, 4);
    put_bytes(o, &v, 4); /* little-endian hosts only (checked in encode) */
}

static void put_elems(cdr_out_t *o, ps_rosmsg_type_t t, const uint8_t *src, uint32_t n)
{
    const size_t sz = TYPES[t].size;
    if (n == 0)
        return;
    put_align(o, sz);
    if (t == PS_ROSMSG_BOOL) {
        for (uint32_t k = 0; k < n; k++) {
            uint8_t b = src[k] != 0;
            put_bytes(o, &b, 1);
        }
        return;
    }
    put_bytes(o, src, sz * n); /* elements are contiguous and already aligned to their size */
}

static void put_string(cdr_out_t *o, const char *s, size_t cap)
{
    size_t len = strnlen(s, cap);
    put_u32(o, (uint32_t)(len + 1u));
    put_bytes(o, s, len);
    const uint8_t nul = 0;
    put_bytes(o, &nul, 1);
}

int ps_rosmsg_encode(const ps_rosmsg_def_t *def, const void *src, const uint32_t *counts,
                     uint8_t *buf, size_t cap)
{
    _Static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "CDR_LE written as host order");
    cdr_out_t o = {.buf = buf, .cap = cap};
    static const uint8_t HEADER[PS_ROSMSG_HEADER_LEN] = {0x00, 0x01, 0x00, 0x00};
    put_bytes(&o, HEADER, sizeof(HEADER));
    const uint8_t *base = src;
    for (uint32_t i = 0; i < def->n_fields && !o.is_full; i++) {
        const ps_rosmsg_field_t *f = &def->fields[i];
        const uint8_t *p = base + f->offset;
        if (f->type == PS_ROSMSG_STRING) {
            put_string(&o, (const char *)p, f->count);
            continue;
        }
        uint32_t n = 1;
        if (f->kind == PS_ROSMSG_ARRAY)
            n = f->count;
        if (f->kind == PS_ROSMSG_SEQUENCE) {
            n = counts != NULL ? counts[f->count_idx] : 0u;
            n = n < f->count ? n : f->count;
            put_u32(&o, n);
        }
        put_elems(&o, (ps_rosmsg_type_t)f->type, p, n);
    }
    return o.is_full ? -ENOSPC : (int)o.pos;
}

/* ---- parsing .msg text ------------------------------------------------- */

static int type_from_name(const char *s, size_t n)
{
    for (int t = 0; t < PS_ROSMSG_TYPE_COUNT; t++)
        if (strlen(TYPES[t].name) == n && strncmp(TYPES[t].name, s, n) == 0)
            return t;
    /* ROS 1 aliases that ROS 2 .msg still accepts */
    if (n == 4 && strncmp(s, "byte", 4) == 0)
        return PS_ROSMSG_UINT8;
    if (n == 4 && strncmp(s, "char", 4) == 0)
        return PS_ROSMSG_UINT8;
    return -1;
}

static int parse_line(const char *line, size_t len, ps_rosmsg_pfield_t *f)
{
    size_t i = 0;
    while (i < len && isspace((unsigned char)line[i]))
        i++;
    const char *type = line + i;
    while (i < len && !isspace((unsigned char)line[i]) && line[i] != '[')
        i++;
    const size_t type_len = (size_t)(line + i - type);
    f->kind = PS_ROSMSG_SCALAR;
    f->count = 1;
    if (i < len && line[i] == '[') {
        const char *close = memchr(line + i, ']', len - i);
        if (close == NULL)
            return -EINVAL;
        const char *num = line + i + 1;
        if (num < close && num[0] == '<' && num + 1 < close && num[1] == '=') {
            f->kind = PS_ROSMSG_SEQUENCE; /* bounded sequence: same wire form */
            f->count = 0;
        } else if (num == close) {
            f->kind = PS_ROSMSG_SEQUENCE;
            f->count = 0;
        } else {
            char *end = NULL;
            unsigned long v = strtoul(num, &end, 10);
            if (end != close || v == 0 || v > 1000000ul)
                return -EINVAL;
            f->kind = PS_ROSMSG_ARRAY;
            f->count = (uint32_t)v;
        }
        i = (size_t)(close - line) + 1;
    }
    const int t = type_from_name(type, type_len);
    if (t < 0)
        return type_len > 0 ? -ENOTSUP : -EINVAL;
    f->type = (uint8_t)t;
    while (i < len && isspace((unsigned char)line[i]))
        i++;
    const char *name = line + i;
    while (i < len && !isspace((unsigned char)line[i]) && line[i] != '#')
        i++;
    const size_t name_len = (size_t)(line + i - name);
    if (name_len == 0 || name_len >= PS_ROSMSG_NAME_LEN)
        return -EINVAL;
    memcpy(f->name, name, name_len);
    f->name[name_len] = '\0';
    return 0;
}

int ps_rosmsg_parse(const char *text, size_t len, ps_rosmsg_parsed_t *out, char *err,
                    size_t err_len)
{
    memset(out, 0, sizeof(*out));
    size_t pos = 0;
    unsigned line_no = 0;
    while (pos < len) {
        const char *line = text + pos;
        const char *nl = memchr(line, '\n', len - pos);
        size_t n = nl ? (size_t)(nl - line) : len - pos;
        pos += n + (nl ? 1u : 0u);
        line_no++;
        if (n >= 4 && strncmp(line, "====", 4) == 0)
            break; /* nested definitions follow: not used by a flat message */
        const char *hash = memchr(line, '#', n);
        size_t body = hash ? (size_t)(hash - line) : n;
        bool is_blank = true;
        for (size_t k = 0; k < body; k++)
            is_blank &= isspace((unsigned char)line[k]) != 0;
        const char *eq = memchr(line, '=', body);
        if (is_blank || (eq != NULL && !(eq > line && eq[-1] == '<')))
            continue; /* comment, blank or constant (NAME=VALUE; not a bound [<=N]) */
        if (out->n_fields >= PS_ROSMSG_MAX_FIELDS) {
            ps_err_format(err, err_len, "line %u: more than %u fields", line_no,
                          PS_ROSMSG_MAX_FIELDS);
            return -E2BIG;
        }
        int rc = parse_line(line, body, &out->fields[out->n_fields]);
        if (rc < 0) {
            ps_err_format(err, err_len, "line %u: %s: \"%.*s\"", line_no,
                          rc == -ENOTSUP ? "not a primitive type (nested messages unsupported)"
                                         : "not TYPE NAME",
                          (int)(body > 80 ? 80 : body), line);
            return rc;
        }
        out->n_fields++;
    }
    return 0;
}

/* ---- decoding ----------------------------------------------------------- */

typedef struct {
    const uint8_t *msg;
    size_t len, pos;
} cdr_in_t;

static bool get_align(cdr_in_t *in, size_t size)
{
    size_t pad = (size - (in->pos - PS_ROSMSG_HEADER_LEN) % size) % size;
    if (pad > in->len - in->pos)
        return false;
    in->pos += pad;
    return true;
}

static bool get_bytes(cdr_in_t *in, void *out, size_t n)
{
    if (n > in->len - in->pos)
        return false;
    memcpy(out, in->msg + in->pos, n);
    in->pos += n;
    return true;
}

static double elem_value(ps_rosmsg_type_t t, const uint8_t *p)
{
    union {
        uint8_t u8;
        int8_t i8;
        uint16_t u16;
        int16_t i16;
        uint32_t u32;
        int32_t i32;
        uint64_t u64;
        int64_t i64;
        float f32;
        double f64;
    } u;
    memcpy(&u, p, TYPES[t].size);
    switch (t) {
    case PS_ROSMSG_BOOL:
    case PS_ROSMSG_UINT8:
        return u.u8;
    case PS_ROSMSG_INT8:
        return u.i8;
    case PS_ROSMSG_UINT16:
        return u.u16;
    case PS_ROSMSG_INT16:
        return u.i16;
    case PS_ROSMSG_UINT32:
        return u.u32;
    case PS_ROSMSG_INT32:
        return u.i32;
    case PS_ROSMSG_UINT64:
        return (double)u.u64;
    case PS_ROSMSG_INT64:
        return (double)u.i64;
    case PS_ROSMSG_FLOAT32:
        return u.f32;
    case PS_ROSMSG_FLOAT64:
        return u.f64;
    default:
        return 0.0;
    }
}

static int decode_field(cdr_in_t *in, const ps_rosmsg_pfield_t *f, uint32_t idx,
                        void (*on_value)(void *, const ps_rosmsg_value_t *), void *ctx)
{
    uint32_t n = f->kind == PS_ROSMSG_ARRAY ? f->count : 1u;
    if (f->kind == PS_ROSMSG_SEQUENCE && (!get_align(in, 4) || !get_bytes(in, &n, 4)))
        return -EPROTO;
    const ps_rosmsg_type_t t = (ps_rosmsg_type_t)f->type;
    for (uint32_t k = 0; k < n; k++) {
        ps_rosmsg_value_t v = {.field_idx = idx, .elem_idx = k};
        if (t == PS_ROSMSG_STRING) {
            uint32_t slen = 0;
            if (!get_align(in, 4) || !get_bytes(in, &slen, 4) || slen > in->len - in->pos)
                return -EPROTO;
            v.is_string = true;
            v.text = (const char *)in->msg + in->pos;
            v.text_len = slen > 0 ? slen - 1u : 0u; /* without the NUL */
            in->pos += slen;
        } else {
            const size_t sz = TYPES[t].size;
            if (!get_align(in, sz) || sz > in->len - in->pos)
                return -EPROTO;
            v.value = elem_value(t, in->msg + in->pos);
            in->pos += sz;
        }
        on_value(ctx, &v);
    }
    return 0;
}

int ps_rosmsg_decode(const ps_rosmsg_parsed_t *def, const uint8_t *msg, size_t len,
                     void (*on_value)(void *ctx, const ps_rosmsg_value_t *v), void *ctx)
{
    if (len < PS_ROSMSG_HEADER_LEN || msg[0] != 0x00 || msg[1] != 0x01)
        return -EPROTO;
    cdr_in_t in = {.msg = msg, .len = len, .pos = PS_ROSMSG_HEADER_LEN};
    for (uint32_t i = 0; i < def->n_fields; i++) {
        int rc = decode_field(&in, &def->fields[i], i, on_value, ctx);
        if (rc < 0)
            return rc;
    }
    return 0;
}
