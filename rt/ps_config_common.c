/*
 * ps_config_common: what every configuration file kind shares; see
 * ps_config_common.h for the pipeline and why a position tree is kept next
 * to libcyaml.
 *
 * Pipeline per file:
 *   1. read the whole file once (errno of fopen is kept: -ENOENT for a missing
 *      file; a directory says so);
 *   2. parse the buffer with libyaml's event API into a small node tree that
 *      keeps every node's line and column;
 *   3. load the same buffer with libcyaml into the file kind's "raw" structs;
 *      on failure, the node tree and the schema explain where and why;
 *   4. walk the tree with the schema for what libcyaml accepts too leniently:
 *      booleans other than true/false, integers written as "2.5" or "1e30";
 *   5. (per file kind) copy, apply defaults, ps_cfg_check_ranges, semantic rules.
 */
#include "ps_config_common.h"
#include "ps_config.h"

#include <ctype.h>
#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <float.h>
#include <unistd.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <yaml.h>

#include "ps_err.h"

#define MAX_FILE_BYTES  (1024u * 1024u) /* configs are small; refuse anything odd */
#define MAX_DEPTH       32u
#define CYAML_LOG_BYTES 2048u

static void tree_free(ps_cfg_ytree_t *t)
{
    for (int i = 0; i < t->n_nodes; i++) {
        free(t->nodes[i].key);
        free(t->nodes[i].value);
    }
    free(t->nodes);
    t->nodes = NULL;
    t->n_nodes = 0;
    t->cap_nodes = 0;
}

static char *dup_bytes(const unsigned char *s, size_t len)
{
    char *d = malloc(len + 1u);
    if (d != NULL) {
        memcpy(d, s, len);
        d[len] = '\0';
    }
    return d;
}

/* Appends a node under parent_idx (-1: root). @return index | -ENOMEM */
static int tree_add(ps_cfg_ytree_t *t, ps_cfg_ynode_type_t type, int parent_idx,
                    const yaml_mark_t *mark)
{
    if (t->n_nodes == t->cap_nodes) {
        const int cap = t->cap_nodes == 0 ? 64 : t->cap_nodes * 2;
        ps_cfg_ynode_t *n = realloc(t->nodes, (size_t)cap * sizeof(*n));
        if (n == NULL)
            return -ENOMEM;
        t->nodes = n;
        t->cap_nodes = cap;
    }
    const int idx = t->n_nodes++;
    ps_cfg_ynode_t *n = &t->nodes[idx];
    memset(n, 0, sizeof(*n));
    n->type = type;
    n->parent_idx = parent_idx;
    n->first_child_idx = -1;
    n->last_child_idx = -1;
    n->next_idx = -1;
    n->line = mark->line;
    n->col = mark->column;
    if (parent_idx >= 0) {
        ps_cfg_ynode_t *p = &t->nodes[parent_idx];
        if (p->last_child_idx >= 0)
            t->nodes[p->last_child_idx].next_idx = idx;
        else
            p->first_child_idx = idx;
        p->last_child_idx = idx;
        p->n_children++;
    }
    return idx;
}

static int tree_child_by_key(const ps_cfg_ytree_t *t, int node_idx, const char *key, size_t key_len)
{
    if (node_idx < 0 || t->nodes[node_idx].type != PS_CFG_YN_MAP)
        return -1;
    for (int c = t->nodes[node_idx].first_child_idx; c >= 0; c = t->nodes[c].next_idx) {
        const char *k = t->nodes[c].key;
        if (k != NULL && strlen(k) == key_len && strncmp(k, key, key_len) == 0)
            return c;
    }
    return -1;
}

static int tree_child_at(const ps_cfg_ytree_t *t, int node_idx, uint32_t pos)
{
    if (node_idx < 0 || t->nodes[node_idx].type != PS_CFG_YN_SEQ)
        return -1;
    int c = t->nodes[node_idx].first_child_idx;
    for (uint32_t i = 0; c >= 0 && i < pos; i++)
        c = t->nodes[c].next_idx;
    return c;
}

/* Resolves a field path such as "joints[3].driver" or "pushes[0].force_n[2]".
 * @return node index | -1 when the path does not exist in the file */
static int tree_find(const ps_cfg_ytree_t *t, const char *field_path)
{
    if (t->n_nodes == 0)
        return -1;
    int node_idx = 0;
    const char *p = field_path;
    while (*p != '\0' && node_idx >= 0) {
        if (*p == '.') {
            p++;
        } else if (*p == '[') {
            char *end = NULL;
            const unsigned long pos = strtoul(p + 1, &end, 10);
            if (end == NULL || *end != ']')
                return -1;
            node_idx = tree_child_at(t, node_idx, (uint32_t)pos);
            p = end + 1;
        } else {
            const size_t len = strcspn(p, ".[");
            node_idx = tree_child_by_key(t, node_idx, p, len);
            p += len;
        }
    }
    return node_idx;
}

/* Builds "joints[3].driver" for a node (the inverse of tree_find). */
static void tree_path_of(const ps_cfg_ytree_t *t, int node_idx, char *out, size_t out_len)
{
    int chain[MAX_DEPTH + 1];
    int depth = 0;
    for (int n = node_idx; n > 0 && depth < (int)MAX_DEPTH; n = t->nodes[n].parent_idx)
        chain[depth++] = n;
    size_t used = 0;
    out[0] = '\0';
    for (int i = depth - 1; i >= 0 && used < out_len; i--) {
        const ps_cfg_ynode_t *n = &t->nodes[chain[i]];
        const ps_cfg_ynode_t *par = &t->nodes[n->parent_idx];
        int w;
        if (par->type == PS_CFG_YN_MAP) {
            w = snprintf(out + used, out_len - used, "%s%s", used > 0 ? "." : "",
                         n->key != NULL ? n->key : "?");
        } else {
            uint32_t pos = 0;
            for (int c = par->first_child_idx; c >= 0 && c != chain[i]; c = t->nodes[c].next_idx)
                pos++;
            w = snprintf(out + used, out_len - used, "[%u]", pos);
        }
        if (w < 0)
            return;
        used += (size_t)w;
    }
}

/* Parses the first YAML document of buf. On a syntax error writes *out_line
 * (1-based, 0: unknown), a static problem text and, where libyaml has one,
 * the construct it was parsing into out_context. @return 0 | -PS_ERR_CONFIG | -ENOMEM */
static int tree_build(ps_cfg_ytree_t *t, const unsigned char *buf, size_t len, size_t *out_line,
                      const char **out_problem, char *out_context, size_t out_context_len)
{
    yaml_parser_t parser;
    int stack[MAX_DEPTH];
    bool expect_key[MAX_DEPTH];
    int depth = 0;
    char *pending_key = NULL;
    size_t pending_key_line = 0;
    int rc = 0;
    bool is_done = false;
    unsigned n_documents = 0;

    if (!yaml_parser_initialize(&parser))
        return -ENOMEM;
    yaml_parser_set_input_string(&parser, buf, len);
    while (!is_done && rc == 0) {
        yaml_event_t ev;
        if (!yaml_parser_parse(&parser, &ev)) {
            *out_line = parser.problem_mark.line + 1u;
            *out_problem = parser.problem != NULL ? parser.problem : "syntax error";
            if (parser.context != NULL && out_context_len > 0)
                (void)snprintf(out_context, out_context_len, " (%s at line %zu)", parser.context,
                               parser.context_mark.line + 1u);
            rc = -PS_ERR_CONFIG;
            break;
        }
        ps_cfg_ynode_type_t type = PS_CFG_YN_SCALAR;
        bool is_node = false;
        switch (ev.type) {
        case YAML_SCALAR_EVENT:
            type = PS_CFG_YN_SCALAR;
            is_node = true;
            break;
        case YAML_ALIAS_EVENT:
            /* libcyaml would take the anchor's text without the checks the
             * tree's walk adds (a word where a boolean belongs, a fraction
             * for an integer): refuse aliases instead of resolving them. */
            *out_line = ev.start_mark.line + 1u;
            *out_problem = "YAML aliases (*name) are not supported; write the value";
            rc = -PS_ERR_CONFIG;
            break;
        case YAML_DOCUMENT_START_EVENT:
            if (++n_documents > 1u) {
                *out_line = ev.start_mark.line + 1u;
                *out_problem = "one YAML document per file (a second one starts here)";
                rc = -PS_ERR_CONFIG;
            }
            break;
        case YAML_MAPPING_START_EVENT:
            type = PS_CFG_YN_MAP;
            is_node = true;
            break;
        case YAML_SEQUENCE_START_EVENT:
            type = PS_CFG_YN_SEQ;
            is_node = true;
            break;
        case YAML_MAPPING_END_EVENT:
        case YAML_SEQUENCE_END_EVENT:
            depth--;
            if (depth > 0 && t->nodes[stack[depth - 1]].type == PS_CFG_YN_MAP)
                expect_key[depth - 1] = true;
            break;
        case YAML_STREAM_END_EVENT:
            is_done = true;
            break;
        default:
            break;
        }
        if (is_node) {
            const bool is_key = depth > 0 && t->nodes[stack[depth - 1]].type == PS_CFG_YN_MAP &&
                                expect_key[depth - 1];
            if (is_key && type == PS_CFG_YN_SCALAR) {
                pending_key = dup_bytes(ev.data.scalar.value, ev.data.scalar.length);
                pending_key_line = ev.start_mark.line;
                expect_key[depth - 1] = false;
                if (pending_key == NULL)
                    rc = -ENOMEM;
            } else if (is_key) {
                /* Non-scalar key: libcyaml rejects it; nothing sensible to index. */
                *out_line = ev.start_mark.line + 1u;
                *out_problem = "mapping keys must be plain strings";
                rc = -PS_ERR_CONFIG;
            } else {
                const int idx =
                    tree_add(t, type, depth > 0 ? stack[depth - 1] : -1, &ev.start_mark);
                if (idx < 0) {
                    rc = idx;
                } else {
                    ps_cfg_ynode_t *n = &t->nodes[idx];
                    n->key = pending_key;
                    n->key_line = pending_key_line;
                    pending_key = NULL;
                    if (type == PS_CFG_YN_SCALAR) {
                        n->is_plain = ev.data.scalar.plain_implicit != 0;
                        n->value = dup_bytes(ev.data.scalar.value, ev.data.scalar.length);
                        if (n->value == NULL)
                            rc = -ENOMEM;
                    }
                    if (type == PS_CFG_YN_MAP || type == PS_CFG_YN_SEQ) {
                        if (depth == (int)MAX_DEPTH) {
                            *out_line = ev.start_mark.line + 1u;
                            *out_problem = "nesting too deep";
                            rc = -PS_ERR_CONFIG;
                        } else {
                            stack[depth] = idx;
                            expect_key[depth] = true;
                            depth++;
                        }
                    } else if (depth > 0 && t->nodes[stack[depth - 1]].type == PS_CFG_YN_MAP) {
                        expect_key[depth - 1] = true;
                    }
                }
            }
        }
        yaml_event_delete(&ev);
    }
    free(pending_key);
    yaml_parser_delete(&parser);
    return rc;
}

/* ====================================================================== */
/* messages                                                               */
/* ====================================================================== */

/* Writes "FILE:LINE: FIELD: text" (line 0 and empty field are left out).
 * @return -PS_ERR_CONFIG, so callers can `return ps_cfg_fail_at(...)`. */
static int vfail_at(ps_cfg_ctx_t *c, size_t line, const char *field, const char *fmt, va_list ap)
{
    if (c->err == NULL || c->err_len == 0)
        return -PS_ERR_CONFIG;
    char text[PS_ERR_MSG_LEN];
    (void)vsnprintf(text, sizeof(text), fmt, ap); /* truncation is acceptable */
    char where[32] = "";
    if (line > 0)
        (void)snprintf(where, sizeof(where), ":%zu", line);
    const bool has_field = field != NULL && field[0] != '\0';
    (void)snprintf(c->err, c->err_len, "%s%s: %s%s%s", c->path, where, has_field ? field : "",
                   has_field ? ": " : "", text);
    return -PS_ERR_CONFIG;
}

int ps_cfg_fail_at(ps_cfg_ctx_t *c, size_t line, const char *field, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    const int rc = vfail_at(c, line, field, fmt, ap);
    va_end(ap);
    return rc;
}

uint32_t ps_cfg_line_of(const ps_cfg_ctx_t *c, const char *field)
{
    const int node_idx = tree_find(&c->tree, field);
    return node_idx >= 0 ? (uint32_t)c->tree.nodes[node_idx].line + 1u : 0u;
}

int ps_cfg_fail_field(ps_cfg_ctx_t *c, const char *field, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    const int rc = vfail_at(c, ps_cfg_line_of(c, field), field, fmt, ap);
    va_end(ap);
    return rc;
}

/* ====================================================================== */
/* table-driven range checks                                              */
/* ====================================================================== */

static void fmt_num(char *out, size_t out_len, double v, ps_cfg_num_t type, unsigned flags)
{
    if (type == PS_CFG_NUM_F32)
        (void)snprintf(out, out_len, "%g", v);
    else if ((flags & PS_CFG_RANGE_HEX) != 0u)
        (void)snprintf(out, out_len, "0x%llx", (unsigned long long)v);
    else
        (void)snprintf(out, out_len, "%lld", (long long)v);
}

/* "[lo, hi]" or "(lo, hi]" of a rule. */
static void fmt_range(char *out, size_t out_len, const ps_cfg_rule_t *r)
{
    char lo[32], hi[32];
    fmt_num(lo, sizeof(lo), r->min, (ps_cfg_num_t)r->type, r->flags);
    fmt_num(hi, sizeof(hi), r->max, (ps_cfg_num_t)r->type, r->flags);
    (void)snprintf(out, out_len, "%s%s, %s]", (r->flags & PS_CFG_RANGE_OPEN_MIN) != 0u ? "(" : "[",
                   lo, hi);
}

/* The rules' macros checked the member's type at compile time, so each type
 * tag reads exactly the type the member has. */
static double read_num(const unsigned char *p, ps_cfg_num_t type)
{
    switch (type) {
    case PS_CFG_NUM_U32: {
        uint32_t v;
        memcpy(&v, p, sizeof(v));
        return (double)v;
    }
    case PS_CFG_NUM_I32: {
        int32_t v;
        memcpy(&v, p, sizeof(v));
        return (double)v;
    }
    default: {
        float v;
        memcpy(&v, p, sizeof(v));
        return (double)v;
    }
    }
}

/* Checks one value; NaN and infinities fail every range. */
static int check_rule(ps_cfg_ctx_t *c, const ps_cfg_rule_t *r, const unsigned char *p,
                      const char *field)
{
    const double v = read_num(p, (ps_cfg_num_t)r->type);
    const bool is_low_ok = (r->flags & PS_CFG_RANGE_OPEN_MIN) != 0u ? v > r->min : v >= r->min;
    if (is_low_ok && v <= r->max)
        return 0;
    char vs[32], range[80];
    fmt_num(vs, sizeof(vs), v, (ps_cfg_num_t)r->type, r->flags);
    fmt_range(range, sizeof(range), r);
    return ps_cfg_fail_field(c, field, "value %s outside %s", vs, range);
}

int ps_cfg_check_ranges(ps_cfg_ctx_t *c, const void *work)
{
    const unsigned char *base = work;
    char field[PS_CFG_FIELD_PATH_LEN];
    for (size_t i = 0; i < c->n_rules; i++) {
        const ps_cfg_rule_t *r = &c->rules[i];
        if (r->arr_idx == 0) {
            const int rc = check_rule(c, r, base + r->off, r->key);
            if (rc != 0)
                return rc;
            continue;
        }
        const ps_cfg_array_t *a = &c->arrays[r->arr_idx - 1u];
        uint32_t n;
        memcpy(&n, base + a->count_off, sizeof(n));
        for (uint32_t k = 0; k < n; k++) {
            (void)snprintf(field, sizeof(field), "%s[%u].%s", a->name, k, r->key);
            const int rc = check_rule(c, r, base + a->off + k * a->stride + r->off, field);
            if (rc != 0)
                return rc;
        }
    }
    return 0;
}

/* The rule for a field path such as "joints[3].rate_div", or NULL. */
static const ps_cfg_rule_t *rule_of(const ps_cfg_ctx_t *c, const char *field)
{
    for (size_t i = 0; i < c->n_rules; i++) {
        const ps_cfg_rule_t *r = &c->rules[i];
        if (r->arr_idx == 0) {
            if (strcmp(r->key, field) == 0)
                return r;
            continue;
        }
        const char *name = c->arrays[r->arr_idx - 1u].name;
        const size_t len = strlen(name);
        if (strncmp(field, name, len) != 0 || field[len] != '[')
            continue;
        const char *p = field + len + 1;
        while (*p >= '0' && *p <= '9')
            p++;
        if (p[0] == ']' && p[1] == '.' && strcmp(p + 2, r->key) == 0)
            return r;
    }
    return NULL;
}

/* Integers as the docs allow them: an optional sign, then decimal digits
 * without a leading zero, or 0x and hex digits. libcyaml 1.3.1 reads them
 * with strtoll/strtoull and ignores what follows the digits, so "2.5" loads
 * as 2, "1e30" and "0x1.8p1" as 1, and "010" is octal 8.
 * @return true and *out_v when text is one */
static bool parse_int_text(const char *text, long double *out_v)
{
    const char *p = text;
    const bool is_neg = *p == '-';
    if (*p == '-' || *p == '+')
        p++;
    unsigned base = 10;
    if (p[0] == '0' && (p[1] == 'x' || p[1] == 'X')) {
        base = 16;
        p += 2;
    } else if (p[0] == '0' && p[1] != '\0') {
        return false;
    }
    if (*p == '\0')
        return false;
    long double v = 0.0L;
    for (; *p != '\0'; p++) {
        unsigned d;
        if (*p >= '0' && *p <= '9')
            d = (unsigned)(*p - '0');
        else if (base == 16 && *p >= 'a' && *p <= 'f')
            d = 10u + (unsigned)(*p - 'a');
        else if (base == 16 && *p >= 'A' && *p <= 'F')
            d = 10u + (unsigned)(*p - 'A');
        else
            return false;
        v = v * base + d; /* exact up to 2^64: long double has a 64-bit mantissa */
        if (v > 1e20L)
            v = 1e20L; /* far outside every integer type we load */
    }
    *out_v = is_neg ? -v : v;
    return true;
}

/* A float field: the whole scalar must be a number (libcyaml 1.3.1 reads
 * "1.0abc" and "1_0" as 1). NaN and infinities parse and then fail every
 * range. @return true when a message was written */
static bool explain_float(ps_cfg_ctx_t *c, const ps_cfg_ynode_t *n, const char *field)
{
    const ps_cfg_rule_t *rule = rule_of(c, field);
    char range[80] = "", bounds[72];
    if (rule != NULL) {
        fmt_range(bounds, sizeof(bounds), rule);
        (void)snprintf(range, sizeof(range), " in %s", bounds);
    }
    if (!n->is_plain) {
        (void)ps_cfg_fail_at(c, n->line + 1u, field,
                             "value \"%s\" is quoted or tagged, not a number%s", n->value, range);
        return true;
    }
    char *end = NULL;
    errno = 0;
    const double v = strtod(n->value, &end);
    const bool is_hex = strpbrk(n->value, "xX") != NULL; /* strtod reads hex floats; we do not */
    if (end == n->value || end == NULL || *end != '\0' || isspace((unsigned char)n->value[0]) ||
        is_hex) {
        (void)ps_cfg_fail_at(c, n->line + 1u, field, "value \"%s\" is not a number%s", n->value,
                             range);
        return true;
    }
    /* A written number that a float cannot hold (1e39) or that it would
     * round to zero (1e-50): say so rather than load inf or 0. */
    if (isfinite(v) && (errno == ERANGE || fabs(v) > FLT_MAX || (v != 0.0 && fabs(v) < FLT_MIN))) {
        (void)ps_cfg_fail_at(c, n->line + 1u, field, "value %s is outside the float range%s",
                             n->value, range);
        return true;
    }
    return false;
}

/* An integer field: refuses a scalar that is not an integer, or one outside
 * the member's type. The message gives the field's rule range when it has
 * one, else the type's. @return true when a message was written */
static bool explain_int(ps_cfg_ctx_t *c, const cyaml_schema_value_t *sv, const ps_cfg_ynode_t *n,
                        const char *field)
{
    const bool is_signed = sv->type == CYAML_INT;
    const unsigned bits = sv->data_size * 8u;
    ps_cfg_rule_t type_rule = {
        .type = is_signed ? PS_CFG_NUM_I32 : PS_CFG_NUM_U32,
        .min = is_signed ? -ldexp(1.0, (int)bits - 1) : 0.0,
        .max = is_signed ? ldexp(1.0, (int)bits - 1) - 1.0 : ldexp(1.0, (int)bits) - 1.0,
    };
    const ps_cfg_rule_t *rule = rule_of(c, field);
    if (rule == NULL)
        rule = &type_rule;
    char range[80];
    fmt_range(range, sizeof(range), rule);
    if (!n->is_plain) {
        (void)ps_cfg_fail_at(c, n->line + 1u, field,
                             "value \"%s\" is quoted or tagged, not an integer in %s", n->value,
                             range);
        return true;
    }
    long double v = 0.0L;
    if (!parse_int_text(n->value, &v)) {
        (void)ps_cfg_fail_at(c, n->line + 1u, field, "value \"%s\" is not an integer in %s",
                             n->value, range);
        return true;
    }
    if (v < (long double)type_rule.min || v > (long double)type_rule.max) {
        (void)ps_cfg_fail_at(c, n->line + 1u, field, "value %s outside %s", n->value, range);
        return true;
    }
    return false; /* in the type: the range rules check the rest */
}

/* ====================================================================== */
/* libcyaml glue                                                          */
/* ====================================================================== */

/* Captures libcyaml's messages instead of printing them. */
static void cyaml_capture(cyaml_log_t level, void *vctx, const char *fmt, va_list args)
{
    ps_cfg_ctx_t *c = vctx;
    (void)level;
    if (c->cyaml_log == NULL || c->cyaml_log_used + 1u >= CYAML_LOG_BYTES)
        return;
    const int w =
        vsnprintf(c->cyaml_log + c->cyaml_log_used, CYAML_LOG_BYTES - c->cyaml_log_used, fmt, args);
    if (w > 0)
        c->cyaml_log_used += (size_t)w;
    if (c->cyaml_log_used >= CYAML_LOG_BYTES)
        c->cyaml_log_used = CYAML_LOG_BYTES - 1u;
}

/* Walks the node tree alongside the schema and explains the first structural
 * problem: unknown or duplicate key, missing field, sequence length, string
 * length, enum or boolean value. Leaves number syntax and scalar/container mismatches to
 * libcyaml's own text. @return true when a message was written */
static bool explain_walk(ps_cfg_ctx_t *c, const cyaml_schema_value_t *sv, int node_idx)
{
    const ps_cfg_ytree_t *t = &c->tree;
    const ps_cfg_ynode_t *n = &t->nodes[node_idx];
    char field[PS_CFG_FIELD_PATH_LEN];
    tree_path_of(t, node_idx, field, sizeof(field));

    switch (sv->type) {
    case CYAML_MAPPING: {
        if (n->type != PS_CFG_YN_MAP)
            return false;
        for (int ch = n->first_child_idx; ch >= 0; ch = t->nodes[ch].next_idx) {
            const ps_cfg_ynode_t *child = &t->nodes[ch];
            for (int prev = n->first_child_idx; prev != ch; prev = t->nodes[prev].next_idx) {
                if (strcmp(t->nodes[prev].key, child->key) == 0) {
                    (void)ps_cfg_fail_at(c, child->key_line + 1u, field, "duplicate key \"%s\"",
                                         child->key);
                    return true;
                }
            }
            const cyaml_schema_field_t *f = sv->mapping.fields;
            while (f->key != NULL && strcmp(f->key, child->key) != 0)
                f++;
            if (f->key == NULL) {
                (void)ps_cfg_fail_at(c, child->key_line + 1u, field, "unknown key \"%s\"",
                                     child->key);
                return true;
            }
            if (explain_walk(c, &f->value, ch))
                return true;
        }
        for (const cyaml_schema_field_t *f = sv->mapping.fields; f->key != NULL; f++) {
            if ((f->value.flags & CYAML_FLAG_OPTIONAL) == 0 &&
                tree_child_by_key(t, node_idx, f->key, strlen(f->key)) < 0) {
                /* The document root has no useful line; nested ones do. */
                (void)ps_cfg_fail_at(c, node_idx == 0 ? 0u : n->line + 1u, field,
                                     "missing field \"%s\"", f->key);
                return true;
            }
        }
        return false;
    }
    case CYAML_SEQUENCE:
    case CYAML_SEQUENCE_FIXED:
        if (n->type != PS_CFG_YN_SEQ)
            return false;
        if (n->n_children < sv->sequence.min || n->n_children > sv->sequence.max) {
            if (sv->sequence.min == sv->sequence.max)
                (void)ps_cfg_fail_at(c, n->line + 1u, field, "%u entries, need exactly %u",
                                     n->n_children, sv->sequence.min);
            else
                (void)ps_cfg_fail_at(c, n->line + 1u, field, "%u entries outside [%u, %u]",
                                     n->n_children, sv->sequence.min, sv->sequence.max);
            return true;
        }
        for (int ch = n->first_child_idx; ch >= 0; ch = t->nodes[ch].next_idx) {
            if (explain_walk(c, sv->sequence.entry, ch))
                return true;
        }
        return false;
    case CYAML_ENUM:
        if (n->type != PS_CFG_YN_SCALAR)
            return false;
        for (uint32_t i = 0; i < sv->enumeration.count; i++) {
            if (strcmp(sv->enumeration.strings[i].str, n->value) == 0)
                return false;
        }
        {
            char allowed[PS_ERR_MSG_LEN / 2] = "";
            size_t used = 0;
            for (uint32_t i = 0; i < sv->enumeration.count && used < sizeof(allowed); i++) {
                const int w = snprintf(allowed + used, sizeof(allowed) - used, "%s%s",
                                       i > 0 ? ", " : "", sv->enumeration.strings[i].str);
                if (w < 0)
                    break;
                used += (size_t)w;
            }
            (void)ps_cfg_fail_at(c, n->line + 1u, field, "unknown value \"%s\" (allowed: %s)",
                                 n->value, allowed);
        }
        return true;
    case CYAML_BOOL:
        /* libcyaml 1.3.1 reads every string but false/no/disable/0 as true,
         * so "off" or a typo would arm the opposite polarity: allow only
         * the two YAML 1.2 spellings. */
        if (n->type != PS_CFG_YN_SCALAR)
            return false;
        if (!n->is_plain && (strcmp(n->value, "true") == 0 || strcmp(n->value, "false") == 0)) {
            /* "true" in quotes is a string in YAML, not a boolean */
            (void)ps_cfg_fail_at(c, n->line + 1u, field,
                                 "value \"%s\" is quoted or tagged (allowed: true, false)",
                                 n->value);
            return true;
        }
        if (strcmp(n->value, "true") == 0 || strcmp(n->value, "false") == 0)
            return false;
        (void)ps_cfg_fail_at(c, n->line + 1u, field, "unknown value \"%s\" (allowed: true, false)",
                             n->value);
        return true;
    case CYAML_INT:
    case CYAML_UINT:
        return n->type == PS_CFG_YN_SCALAR && explain_int(c, sv, n, field);
    case CYAML_FLOAT:
        return n->type == PS_CFG_YN_SCALAR && explain_float(c, n, field);
    case CYAML_STRING: {
        if (n->type != PS_CFG_YN_SCALAR)
            return false;
        /* libcyaml 1.3.1 stores a YAML null (~, null) as that text */
        static const char *const NULLS[] = {"~", "null", "Null", "NULL"};
        for (size_t i = 0; n->is_plain && i < sizeof(NULLS) / sizeof(NULLS[0]); i++) {
            if (strcmp(n->value, NULLS[i]) == 0) {
                (void)ps_cfg_fail_at(c, n->line + 1u, field, "value %s is null, not a string",
                                     n->value);
                return true;
            }
        }
        const size_t len = strlen(n->value);
        if (len < sv->string.min || len > sv->string.max) {
            (void)ps_cfg_fail_at(c, n->line + 1u, field,
                                 "string \"%s\" length %zu outside [%u, %u]", n->value, len,
                                 sv->string.min, sv->string.max);
            return true;
        }
        return false;
    }
    default:
        return false;
    }
}

/* Turns a libcyaml failure into one line: first the schema walk (precise
 * positions for structural errors), else libcyaml's own first message with the
 * position from its backtrace ("(line: L, column: C)") mapped to a field path. */
static int explain_cyaml_error(ps_cfg_ctx_t *c, const cyaml_schema_value_t *schema,
                               cyaml_err_t cerr)
{
    if (c->tree.n_nodes == 0)
        return ps_cfg_fail_at(c, 0, NULL, "empty document");
    if (explain_walk(c, schema, 0))
        return -PS_ERR_CONFIG;

    const char *msg = NULL;
    size_t msg_len = 0;
    size_t line = 0, col = 0;
    bool has_pos = false;
    for (char *l = c->cyaml_log; l != NULL && *l != '\0';) {
        char *nl = strchr(l, '\n');
        const size_t len = nl != NULL ? (size_t)(nl - l) : strlen(l);
        if (strncmp(l, "  in ", 5) == 0) {
            const char *pos = strstr(l, "(line: ");
            if (!has_pos && pos != NULL && pos < l + len &&
                sscanf(pos, "(line: %zu, column: %zu)", &line, &col) == 2)
                has_pos = true;
        } else if (msg == NULL && strncmp(l, "Load: Backtrace:", 16) != 0) {
            msg = l;
            msg_len = len;
            if (strncmp(msg, "Load: ", 6) == 0) {
                msg += 6;
                msg_len -= 6;
            }
        }
        l = nl != NULL ? nl + 1 : NULL;
    }
    char text[PS_ERR_MSG_LEN / 2];
    if (msg != NULL)
        (void)snprintf(text, sizeof(text), "%.*s", (int)msg_len, msg);
    else
        (void)snprintf(text, sizeof(text), "%s", cyaml_strerror(cerr));

    char field[PS_CFG_FIELD_PATH_LEN] = "";
    if (has_pos) {
        for (int i = 0; i < c->tree.n_nodes; i++) {
            const ps_cfg_ynode_t *n = &c->tree.nodes[i];
            if (n->line + 1u == line && n->col + 1u == col) {
                tree_path_of(&c->tree, i, field, sizeof(field));
                break;
            }
        }
    }
    return ps_cfg_fail_at(c, has_pos ? line : 0u, field, "%s", text);
}

int ps_cfg_load_file(ps_cfg_ctx_t *c, const cyaml_schema_value_t *schema, void **out_data)
{
    /* O_NONBLOCK: a FIFO would otherwise wait for a writer forever (with
     * SIGINT still held off during start-up); only regular files are read. */
    const int fd = open(c->path, O_RDONLY | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0) {
        const int e = errno;
        (void)ps_cfg_fail_at(c, 0, NULL, "cannot open: %s", strerror(e));
        return e == ENOENT ? -ENOENT : -PS_ERR_CONFIG;
    }
    struct stat st;
    if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
        const bool is_dir = S_ISDIR(st.st_mode);
        (void)close(fd); /* read-only: nothing to flush */
        return ps_cfg_fail_at(c, 0, NULL, is_dir ? "is a directory" : "not a regular file");
    }
    unsigned char *buf = malloc(MAX_FILE_BYTES + 1u);
    if (buf == NULL) {
        (void)close(fd);
        return -ENOMEM;
    }
    size_t len = 0;
    int read_errno = 0;
    while (len <= MAX_FILE_BYTES) {
        const ssize_t k = read(fd, buf + len, MAX_FILE_BYTES + 1u - len);
        if (k < 0 && errno == EINTR)
            continue;
        if (k < 0)
            read_errno = errno;
        if (k <= 0)
            break;
        len += (size_t)k;
    }
    (void)close(fd); /* read-only: nothing to flush */
    int rc = 0;
    if (read_errno != 0) {
        rc = ps_cfg_fail_at(c, 0, NULL, "read error: %s", strerror(read_errno));
    } else if (len > MAX_FILE_BYTES) {
        rc = ps_cfg_fail_at(c, 0, NULL, "file larger than %u bytes", MAX_FILE_BYTES);
    } else {
        size_t syntax_line = 0;
        const char *problem = NULL;
        char context[96] = "";
        rc = tree_build(&c->tree, buf, len, &syntax_line, &problem, context, sizeof(context));
        if (rc == -PS_ERR_CONFIG) {
            (void)ps_cfg_fail_at(c, syntax_line, NULL, "YAML syntax error: %s%s", problem, context);
        } else if (rc == 0) {
            /* The same buffer: the file is read once (see the header on why
             * libyaml runs twice over it). */
            const cyaml_err_t cerr = cyaml_load_data(buf, len, &c->cyaml, schema, out_data, NULL);
            if (cerr != CYAML_OK)
                rc = cerr == CYAML_ERR_OOM ? -ENOMEM : explain_cyaml_error(c, schema, cerr);
            else if (*out_data == NULL || c->tree.n_nodes == 0)
                rc = ps_cfg_fail_at(c, 0, NULL, "empty document");
            else if (explain_walk(c, schema, 0))
                rc = -PS_ERR_CONFIG; /* what libcyaml accepts too leniently */
            if (rc != 0 && *out_data != NULL) {
                (void)cyaml_free(&c->cyaml, schema, *out_data, 0); /* fails on NULL schema only */
                *out_data = NULL;
            }
        }
    }
    free(buf);
    return rc;
}

int ps_cfg_ctx_open(ps_cfg_ctx_t *c, const char *path, char *err, size_t err_len,
                    const ps_cfg_array_t *arrays, const ps_cfg_rule_t *rules, size_t n_rules)
{
    memset(c, 0, sizeof(*c));
    c->path = path;
    c->err = err;
    c->err_len = err_len;
    c->arrays = arrays;
    c->rules = rules;
    c->n_rules = n_rules;
    if (err != NULL && err_len > 0)
        err[0] = '\0';
    c->cyaml.log_fn = cyaml_capture;
    c->cyaml.log_ctx = c;
    c->cyaml.mem_fn = cyaml_mem;
    c->cyaml.log_level = CYAML_LOG_ERROR;
    c->cyaml.flags = CYAML_CFG_DEFAULT;
    c->cyaml_log = calloc(1, CYAML_LOG_BYTES);
    return c->cyaml_log == NULL ? -ENOMEM : 0;
}

void ps_cfg_ctx_close(ps_cfg_ctx_t *c)
{
    tree_free(&c->tree);
    free(c->cyaml_log);
    c->cyaml_log = NULL;
}

static bool is_file_arg(const char *arg)
{
    size_t n = strlen(arg);
    return strchr(arg, '/') != NULL || (n > 5 && strcmp(arg + n - 5, ".yaml") == 0);
}

void ps_config_resolve(const char *data_dir, const char *arg, const char *dir, const char *fallback,
                       char *out, size_t len)
{
    if (arg != NULL && is_file_arg(arg))
        snprintf(out, len, "%s", arg);
    else
        snprintf(out, len, "%s/%s/%s.yaml", data_dir, dir, arg ? arg : fallback);
}
