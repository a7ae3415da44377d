/*
 * ps_config: YAML configuration loader.
 *
 * Pipeline per file:
 *   1. read the whole file (errno of fopen is kept: -ENOENT for a missing file);
 *   2. parse it with libyaml's event API into a small node tree that keeps
 *      every node's line and column (libcyaml 1.3.1 exposes no positions in the
 *      loaded data, only in its error backtrace);
 *   3. load it with libcyaml into "raw" structs that mirror the YAML;
 *      on failure, the node tree and the schema explain where and why;
 *   4. copy the raw structs into the caller-layout work struct, apply defaults,
 *      cyaml_free;
 *   5. check every numeric field against one range table per file kind, then
 *      the semantic rules that relate fields to each other;
 *   6. copy the work struct to *out.
 *
 * Allocation: the node tree and libcyaml's data live only during the call.
 */
#include "ps_config.h"

#include <assert.h>
#include <cyaml/cyaml.h>
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <yaml.h>

#include "ps_err.h"

#define MAX_FILE_BYTES     (1024u * 1024u) /* configs are small; refuse anything odd */
#define MAX_DEPTH          32u
#define FIELD_PATH_LEN     128u
#define CYAML_LOG_BYTES    2048u
#define DEFAULT_BUS_BUDGET 0.8f
#define MAX_DRIVERS        8u
#define MAX_GPIO_LINE      1023u
#define MAX_RATE_DIV       64u
#define MAX_CAN_ID         0x7ffu
#define MAX_OVERRUN_LIMIT  PS_LOOP_MAX_OVERRUN_LIMIT
/* Stale data is judged within a few command periods, never seconds: a
 * timeout above this many periods of the fastest joint (or of the IMU) is
 * refused. */
#define MAX_TIMEOUT_PERIODS 10u

/* ====================================================================== */
/* node tree built with libyaml: positions for every value and every key  */
/* ====================================================================== */

typedef enum { YN_SCALAR, YN_MAP, YN_SEQ, YN_ALIAS } ynode_type_t;

typedef struct {
    ynode_type_t type;
    int parent_idx;
    int first_child_idx;
    int last_child_idx;
    int next_idx;
    uint32_t n_children;
    size_t line; /* 0-based, libyaml's mark of the value node */
    size_t col;
    char *key;       /* key under which this node sits in its parent mapping */
    size_t key_line; /* 0-based */
    char *value;     /* scalars only */
} ynode_t;

typedef struct {
    ynode_t *nodes;
    int n_nodes;
    int cap_nodes;
} ytree_t;

/* Per-call context: where messages go and what they refer to. */
typedef struct {
    const char *path;
    char *err;
    size_t err_len;
    ytree_t tree;
    char *cyaml_log; /* libcyaml's messages, one per line */
    size_t cyaml_log_used;
} ctx_t;

static void tree_free(ytree_t *t)
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
static int tree_add(ytree_t *t, ynode_type_t type, int parent_idx, const yaml_mark_t *mark)
{
    if (t->n_nodes == t->cap_nodes) {
        const int cap = t->cap_nodes == 0 ? 64 : t->cap_nodes * 2;
        ynode_t *n = realloc(t->nodes, (size_t)cap * sizeof(*n));
        if (n == NULL)
            return -ENOMEM;
        t->nodes = n;
        t->cap_nodes = cap;
    }
    const int idx = t->n_nodes++;
    ynode_t *n = &t->nodes[idx];
    memset(n, 0, sizeof(*n));
    n->type = type;
    n->parent_idx = parent_idx;
    n->first_child_idx = -1;
    n->last_child_idx = -1;
    n->next_idx = -1;
    n->line = mark->line;
    n->col = mark->column;
    if (parent_idx >= 0) {
        ynode_t *p = &t->nodes[parent_idx];
        if (p->last_child_idx >= 0)
            t->nodes[p->last_child_idx].next_idx = idx;
        else
            p->first_child_idx = idx;
        p->last_child_idx = idx;
        p->n_children++;
    }
    return idx;
}

static int tree_child_by_key(const ytree_t *t, int node_idx, const char *key, size_t key_len)
{
    if (node_idx < 0 || t->nodes[node_idx].type != YN_MAP)
        return -1;
    for (int c = t->nodes[node_idx].first_child_idx; c >= 0; c = t->nodes[c].next_idx) {
        const char *k = t->nodes[c].key;
        if (k != NULL && strlen(k) == key_len && strncmp(k, key, key_len) == 0)
            return c;
    }
    return -1;
}

static int tree_child_at(const ytree_t *t, int node_idx, uint32_t pos)
{
    if (node_idx < 0 || t->nodes[node_idx].type != YN_SEQ)
        return -1;
    int c = t->nodes[node_idx].first_child_idx;
    for (uint32_t i = 0; c >= 0 && i < pos; i++)
        c = t->nodes[c].next_idx;
    return c;
}

/* Resolves a field path such as "joints[3].driver" or "pushes[0].force_n[2]".
 * @return node index | -1 when the path does not exist in the file */
static int tree_find(const ytree_t *t, const char *field_path)
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
static void tree_path_of(const ytree_t *t, int node_idx, char *out, size_t out_len)
{
    int chain[MAX_DEPTH + 1];
    int depth = 0;
    for (int n = node_idx; n > 0 && depth < (int)MAX_DEPTH; n = t->nodes[n].parent_idx)
        chain[depth++] = n;
    size_t used = 0;
    out[0] = '\0';
    for (int i = depth - 1; i >= 0 && used < out_len; i--) {
        const ynode_t *n = &t->nodes[chain[i]];
        const ynode_t *par = &t->nodes[n->parent_idx];
        int w;
        if (par->type == YN_MAP) {
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
static int tree_build(ytree_t *t, const unsigned char *buf, size_t len, size_t *out_line,
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
        ynode_type_t type = YN_SCALAR;
        bool is_node = false;
        switch (ev.type) {
        case YAML_SCALAR_EVENT:
            type = YN_SCALAR;
            is_node = true;
            break;
        case YAML_ALIAS_EVENT:
            type = YN_ALIAS;
            is_node = true;
            break;
        case YAML_MAPPING_START_EVENT:
            type = YN_MAP;
            is_node = true;
            break;
        case YAML_SEQUENCE_START_EVENT:
            type = YN_SEQ;
            is_node = true;
            break;
        case YAML_MAPPING_END_EVENT:
        case YAML_SEQUENCE_END_EVENT:
            depth--;
            if (depth > 0 && t->nodes[stack[depth - 1]].type == YN_MAP)
                expect_key[depth - 1] = true;
            break;
        case YAML_DOCUMENT_END_EVENT:
        case YAML_STREAM_END_EVENT:
            is_done = true; /* like libcyaml, only the first document counts */
            break;
        default:
            break;
        }
        if (is_node) {
            const bool is_key =
                depth > 0 && t->nodes[stack[depth - 1]].type == YN_MAP && expect_key[depth - 1];
            if (is_key && type == YN_SCALAR) {
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
                    ynode_t *n = &t->nodes[idx];
                    n->key = pending_key;
                    n->key_line = pending_key_line;
                    pending_key = NULL;
                    if (type == YN_SCALAR) {
                        n->value = dup_bytes(ev.data.scalar.value, ev.data.scalar.length);
                        if (n->value == NULL)
                            rc = -ENOMEM;
                    }
                    if (type == YN_MAP || type == YN_SEQ) {
                        if (depth == (int)MAX_DEPTH) {
                            *out_line = ev.start_mark.line + 1u;
                            *out_problem = "nesting too deep";
                            rc = -PS_ERR_CONFIG;
                        } else {
                            stack[depth] = idx;
                            expect_key[depth] = true;
                            depth++;
                        }
                    } else if (depth > 0 && t->nodes[stack[depth - 1]].type == YN_MAP) {
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
 * @return -PS_ERR_CONFIG, so callers can `return fail_at(...)`. */
static int vfail_at(ctx_t *c, size_t line, const char *field, const char *fmt, va_list ap)
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

static int fail_at(ctx_t *c, size_t line, const char *field, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
static int fail_at(ctx_t *c, size_t line, const char *field, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    const int rc = vfail_at(c, line, field, fmt, ap);
    va_end(ap);
    return rc;
}

/* Same, with the line looked up from the field path (its value's line). */
static int fail_field(ctx_t *c, const char *field, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
static int fail_field(ctx_t *c, const char *field, const char *fmt, ...)
{
    const int node_idx = tree_find(&c->tree, field);
    const size_t line = node_idx >= 0 ? c->tree.nodes[node_idx].line + 1u : 0u;
    va_list ap;
    va_start(ap, fmt);
    const int rc = vfail_at(c, line, field, fmt, ap);
    va_end(ap);
    return rc;
}

/* ====================================================================== */
/* libcyaml glue                                                          */
/* ====================================================================== */

/* Captures libcyaml's messages instead of printing them. */
static void cyaml_capture(cyaml_log_t level, void *vctx, const char *fmt, va_list args)
{
    ctx_t *c = vctx;
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
static bool explain_walk(ctx_t *c, const cyaml_schema_value_t *sv, int node_idx)
{
    const ytree_t *t = &c->tree;
    const ynode_t *n = &t->nodes[node_idx];
    char field[FIELD_PATH_LEN];
    tree_path_of(t, node_idx, field, sizeof(field));

    switch (sv->type) {
    case CYAML_MAPPING: {
        if (n->type != YN_MAP)
            return false;
        for (int ch = n->first_child_idx; ch >= 0; ch = t->nodes[ch].next_idx) {
            const ynode_t *child = &t->nodes[ch];
            for (int prev = n->first_child_idx; prev != ch; prev = t->nodes[prev].next_idx) {
                if (strcmp(t->nodes[prev].key, child->key) == 0) {
                    (void)fail_at(c, child->key_line + 1u, field, "duplicate key \"%s\"",
                                  child->key);
                    return true;
                }
            }
            const cyaml_schema_field_t *f = sv->mapping.fields;
            while (f->key != NULL && strcmp(f->key, child->key) != 0)
                f++;
            if (f->key == NULL) {
                (void)fail_at(c, child->key_line + 1u, field, "unknown key \"%s\"", child->key);
                return true;
            }
            if (explain_walk(c, &f->value, ch))
                return true;
        }
        for (const cyaml_schema_field_t *f = sv->mapping.fields; f->key != NULL; f++) {
            if ((f->value.flags & CYAML_FLAG_OPTIONAL) == 0 &&
                tree_child_by_key(t, node_idx, f->key, strlen(f->key)) < 0) {
                /* The document root has no useful line; nested ones do. */
                (void)fail_at(c, node_idx == 0 ? 0u : n->line + 1u, field, "missing field \"%s\"",
                              f->key);
                return true;
            }
        }
        return false;
    }
    case CYAML_SEQUENCE:
    case CYAML_SEQUENCE_FIXED:
        if (n->type != YN_SEQ)
            return false;
        if (n->n_children < sv->sequence.min || n->n_children > sv->sequence.max) {
            if (sv->sequence.min == sv->sequence.max)
                (void)fail_at(c, n->line + 1u, field, "%u entries, need exactly %u", n->n_children,
                              sv->sequence.min);
            else
                (void)fail_at(c, n->line + 1u, field, "%u entries outside [%u, %u]", n->n_children,
                              sv->sequence.min, sv->sequence.max);
            return true;
        }
        for (int ch = n->first_child_idx; ch >= 0; ch = t->nodes[ch].next_idx) {
            if (explain_walk(c, sv->sequence.entry, ch))
                return true;
        }
        return false;
    case CYAML_ENUM:
        if (n->type != YN_SCALAR)
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
            (void)fail_at(c, n->line + 1u, field, "unknown value \"%s\" (allowed: %s)", n->value,
                          allowed);
        }
        return true;
    case CYAML_BOOL:
        /* libcyaml 1.3.1 reads every string but false/no/disable/0 as true,
         * so "off" or a typo would arm the opposite polarity: allow only
         * the two YAML 1.2 spellings. */
        if (n->type != YN_SCALAR || strcmp(n->value, "true") == 0 || strcmp(n->value, "false") == 0)
            return false;
        (void)fail_at(c, n->line + 1u, field, "unknown value \"%s\" (allowed: true, false)",
                      n->value);
        return true;
    case CYAML_STRING: {
        if (n->type != YN_SCALAR)
            return false;
        const size_t len = strlen(n->value);
        if (len < sv->string.min || len > sv->string.max) {
            (void)fail_at(c, n->line + 1u, field, "string \"%s\" length %zu outside [%u, %u]",
                          n->value, len, sv->string.min, sv->string.max);
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
static int explain_cyaml_error(ctx_t *c, const cyaml_schema_value_t *schema, cyaml_err_t cerr)
{
    if (c->tree.n_nodes == 0)
        return fail_at(c, 0, NULL, "empty document");
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

    char field[FIELD_PATH_LEN] = "";
    if (has_pos) {
        for (int i = 0; i < c->tree.n_nodes; i++) {
            const ynode_t *n = &c->tree.nodes[i];
            if (n->line + 1u == line && n->col + 1u == col) {
                tree_path_of(&c->tree, i, field, sizeof(field));
                break;
            }
        }
    }
    return fail_at(c, has_pos ? line : 0u, field, "%s", text);
}

/* Reads path, builds the node tree and loads it with libcyaml.
 * @post on 0, *out_data holds libcyaml's data; c->tree is built either way
 * @return 0 | -ENOENT | -PS_ERR_CONFIG | -ENOMEM */
static int load_common(ctx_t *c, const cyaml_config_t *cfg, const cyaml_schema_value_t *schema,
                       void **out_data)
{
    FILE *f = fopen(c->path, "rb");
    if (f == NULL) {
        const int e = errno;
        (void)fail_at(c, 0, NULL, "cannot open: %s", strerror(e));
        return e == ENOENT ? -ENOENT : -PS_ERR_CONFIG;
    }
    unsigned char *buf = malloc(MAX_FILE_BYTES + 1u);
    if (buf == NULL) {
        (void)fclose(f);
        return -ENOMEM;
    }
    const size_t len = fread(buf, 1, MAX_FILE_BYTES + 1u, f);
    const bool is_read_error = ferror(f) != 0;
    (void)fclose(f); /* read-only stream: nothing to flush */
    int rc = 0;
    if (is_read_error) {
        rc = fail_at(c, 0, NULL, "read error");
    } else if (len > MAX_FILE_BYTES) {
        rc = fail_at(c, 0, NULL, "file larger than %u bytes", MAX_FILE_BYTES);
    } else {
        size_t syntax_line = 0;
        const char *problem = NULL;
        char context[96] = "";
        rc = tree_build(&c->tree, buf, len, &syntax_line, &problem, context, sizeof(context));
        if (rc == -PS_ERR_CONFIG) {
            (void)fail_at(c, syntax_line, NULL, "YAML syntax error: %s%s", problem, context);
        } else if (rc == 0) {
            const cyaml_err_t cerr = cyaml_load_data(buf, len, cfg, schema, out_data, NULL);
            if (cerr != CYAML_OK)
                rc = cerr == CYAML_ERR_OOM ? -ENOMEM : explain_cyaml_error(c, schema, cerr);
            else if (*out_data == NULL || c->tree.n_nodes == 0)
                rc = fail_at(c, 0, NULL, "empty document");
            else if (explain_walk(c, schema, 0))
                rc = -PS_ERR_CONFIG; /* what libcyaml accepts too leniently (booleans) */
        }
    }
    free(buf);
    return rc;
}

/* ====================================================================== */
/* table-driven range checks                                              */
/* ====================================================================== */

typedef enum { NUM_U32, NUM_I32, NUM_F32 } num_type_t;

enum {
    RANGE_OPEN_MIN = 1u << 0, /* (min, max] instead of [min, max] */
    RANGE_HEX = 1u << 1,      /* print value and bounds in hex (CAN ids) */
};

/* An array of the work struct that rows may refer to. */
typedef struct {
    const char *name; /* YAML key of the sequence */
    size_t off;       /* offset of element 0 in the work struct */
    size_t stride;    /* sizeof one element */
    size_t count_off; /* offset of the uint32_t entry count */
} range_array_t;

/* One numeric field: YAML path, where it lives, its type and bounds. */
typedef struct {
    uint8_t arr_idx; /* 0: not in an array, else 1 + index into the array table */
    uint8_t type;    /* num_type_t */
    uint8_t flags;   /* RANGE_* */
    const char *key; /* path in the file, relative to the array element if any */
    size_t off;      /* offset in the work struct, or in the array element */
    double min, max;
} range_rule_t;

static void fmt_num(char *out, size_t out_len, double v, num_type_t type, unsigned flags)
{
    if (type == NUM_F32)
        (void)snprintf(out, out_len, "%g", v);
    else if ((flags & RANGE_HEX) != 0u)
        (void)snprintf(out, out_len, "0x%llx", (unsigned long long)v);
    else
        (void)snprintf(out, out_len, "%lld", (long long)v);
}

static double read_num(const unsigned char *p, num_type_t type)
{
    switch (type) {
    case NUM_U32: {
        uint32_t v;
        memcpy(&v, p, sizeof(v));
        return (double)v;
    }
    case NUM_I32: {
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
static int check_rule(ctx_t *c, const range_rule_t *r, const unsigned char *p, const char *field)
{
    const double v = read_num(p, (num_type_t)r->type);
    const bool is_low_ok = (r->flags & RANGE_OPEN_MIN) != 0u ? v > r->min : v >= r->min;
    if (is_low_ok && v <= r->max)
        return 0;
    char vs[32], lo[32], hi[32];
    fmt_num(vs, sizeof(vs), v, (num_type_t)r->type, r->flags);
    fmt_num(lo, sizeof(lo), r->min, (num_type_t)r->type, r->flags);
    fmt_num(hi, sizeof(hi), r->max, (num_type_t)r->type, r->flags);
    return fail_field(c, field, "value %s outside %s%s, %s]", vs,
                      (r->flags & RANGE_OPEN_MIN) != 0u ? "(" : "[", lo, hi);
}

static int check_ranges(ctx_t *c, const void *work, const range_array_t *arrays,
                        const range_rule_t *rules, size_t n_rules)
{
    const unsigned char *base = work;
    char field[FIELD_PATH_LEN];
    for (size_t i = 0; i < n_rules; i++) {
        const range_rule_t *r = &rules[i];
        if (r->arr_idx == 0) {
            const int rc = check_rule(c, r, base + r->off, r->key);
            if (rc != 0)
                return rc;
            continue;
        }
        const range_array_t *a = &arrays[r->arr_idx - 1u];
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

/* ====================================================================== */
/* board                                                                  */
/* ====================================================================== */

/* One bus as written; fd and data_bitrate are optional (NULL when absent). */
typedef struct {
    char ifname[PS_NAME_LEN];
    uint32_t bitrate;
    bool *is_fd;
    uint32_t *data_bitrate;
} bus_raw_t;

typedef struct {
    char name[PS_NAME_LEN];
    ps_board_kind_t kind;
    float *bus_budget; /* optional: NULL when absent */
    bus_raw_t *buses;
    uint32_t n_buses;
    ps_gpio_cfg_t gpio;
    ps_rt_cfg_t rt;
} board_raw_t;

static const cyaml_strval_t BOARD_KINDS[] = {
    {"sim", PS_BOARD_SIM},
    {"linux", PS_BOARD_LINUX},
};

static const cyaml_schema_field_t BUS_FIELDS[] = {
    CYAML_FIELD_STRING("ifname", CYAML_FLAG_DEFAULT, bus_raw_t, ifname, 1),
    CYAML_FIELD_UINT("bitrate", CYAML_FLAG_DEFAULT, bus_raw_t, bitrate),
    CYAML_FIELD_BOOL_PTR("fd", CYAML_FLAG_OPTIONAL | CYAML_FLAG_STRICT, bus_raw_t, is_fd),
    CYAML_FIELD_UINT_PTR("data_bitrate", CYAML_FLAG_OPTIONAL, bus_raw_t, data_bitrate),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t BUS_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_DEFAULT, bus_raw_t, BUS_FIELDS),
};
static const cyaml_schema_field_t GPIO_FIELDS[] = {
    CYAML_FIELD_STRING("chip", CYAML_FLAG_DEFAULT, ps_gpio_cfg_t, chip, 1),
    CYAML_FIELD_UINT("estop_line", CYAML_FLAG_DEFAULT, ps_gpio_cfg_t, estop_line),
    CYAML_FIELD_BOOL("estop_active_low", CYAML_FLAG_STRICT, ps_gpio_cfg_t, is_estop_active_low),
    CYAML_FIELD_UINT("enable_line", CYAML_FLAG_DEFAULT, ps_gpio_cfg_t, enable_line),
    CYAML_FIELD_UINT("led_line", CYAML_FLAG_DEFAULT, ps_gpio_cfg_t, led_line),
    CYAML_FIELD_END,
};
static const cyaml_schema_field_t RT_FIELDS[] = {
    CYAML_FIELD_UINT("priority", CYAML_FLAG_DEFAULT, ps_rt_cfg_t, priority),
    CYAML_FIELD_INT("loop_cpu", CYAML_FLAG_DEFAULT, ps_rt_cfg_t, loop_cpu),
    CYAML_FIELD_INT("plant_cpu", CYAML_FLAG_DEFAULT, ps_rt_cfg_t, plant_cpu),
    CYAML_FIELD_INT("worker_cpu", CYAML_FLAG_DEFAULT, ps_rt_cfg_t, worker_cpu),
    CYAML_FIELD_END,
};
static const cyaml_schema_field_t BOARD_FIELDS[] = {
    CYAML_FIELD_STRING("name", CYAML_FLAG_DEFAULT, board_raw_t, name, 1),
    CYAML_FIELD_ENUM("kind", CYAML_FLAG_STRICT, board_raw_t, kind, BOARD_KINDS,
                     CYAML_ARRAY_LEN(BOARD_KINDS)),
    CYAML_FIELD_FLOAT_PTR("bus_budget", CYAML_FLAG_OPTIONAL, board_raw_t, bus_budget),
    CYAML_FIELD_SEQUENCE_COUNT("buses", CYAML_FLAG_POINTER, board_raw_t, buses, n_buses,
                               &BUS_SCHEMA, 1, PS_MAX_BUSES),
    CYAML_FIELD_MAPPING("gpio", CYAML_FLAG_DEFAULT, board_raw_t, gpio, GPIO_FIELDS),
    CYAML_FIELD_MAPPING("rt", CYAML_FLAG_DEFAULT, board_raw_t, rt, RT_FIELDS),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t BOARD_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_POINTER, board_raw_t, BOARD_FIELDS),
};

#define B_OFF(m) offsetof(ps_board_cfg_t, m)
static const range_array_t BOARD_ARRAYS[] = {
    {"buses", B_OFF(buses), sizeof(ps_canbus_bus_cfg_t), B_OFF(n_buses)},
};
static const range_rule_t BOARD_RANGES[] = {
    {0, NUM_F32, RANGE_OPEN_MIN, "bus_budget", B_OFF(bus_budget), 0.0, 1.0},
    {1, NUM_U32, 0, "bitrate", offsetof(ps_canbus_bus_cfg_t, bitrate), 10000.0, 1000000.0},
    {0, NUM_U32, 0, "gpio.estop_line", B_OFF(gpio.estop_line), 0.0, MAX_GPIO_LINE},
    {0, NUM_U32, 0, "gpio.enable_line", B_OFF(gpio.enable_line), 0.0, MAX_GPIO_LINE},
    {0, NUM_U32, 0, "gpio.led_line", B_OFF(gpio.led_line), 0.0, MAX_GPIO_LINE},
    {0, NUM_U32, 0, "rt.priority", B_OFF(rt.priority), 0.0, 98.0},
    {0, NUM_I32, 0, "rt.loop_cpu", B_OFF(rt.loop_cpu), -1.0, 1023.0},
    {0, NUM_I32, 0, "rt.plant_cpu", B_OFF(rt.plant_cpu), -1.0, 1023.0},
    {0, NUM_I32, 0, "rt.worker_cpu", B_OFF(rt.worker_cpu), -1.0, 1023.0},
};
#undef B_OFF

static int check_board(ctx_t *c, const ps_board_cfg_t *b)
{
    int rc = check_ranges(c, b, BOARD_ARRAYS, BOARD_RANGES,
                          sizeof(BOARD_RANGES) / sizeof(BOARD_RANGES[0]));
    if (rc != 0)
        return rc;
    char field[FIELD_PATH_LEN];
    for (uint32_t i = 0; i < b->n_buses; i++) {
        const ps_canbus_bus_cfg_t *bus = &b->buses[i];
        /* ISO 11898-1 FD controllers: data phase 1..8 Mbit/s in practice,
         * never slower than the arbitration phase. */
        if (!bus->is_fd && bus->data_bitrate != bus->bitrate) {
            (void)snprintf(field, sizeof(field), "buses[%u].data_bitrate", i);
            return fail_field(c, field, "a data bit rate needs a CAN FD bus (fd: true)");
        }
        if (bus->is_fd && (bus->data_bitrate < bus->bitrate || bus->data_bitrate > 8000000u)) {
            (void)snprintf(field, sizeof(field), "buses[%u].data_bitrate", i);
            return fail_field(c, field, "value %u outside [bitrate %u, 8000000]", bus->data_bitrate,
                              bus->bitrate);
        }
        for (uint32_t k = 0; k < i; k++) {
            if (strcmp(b->buses[i].ifname, b->buses[k].ifname) == 0) {
                (void)snprintf(field, sizeof(field), "buses[%u].ifname", i);
                return fail_field(c, field, "duplicate interface \"%s\" (also buses[%u])",
                                  b->buses[i].ifname, k);
            }
        }
    }
    const struct {
        const char *key;
        uint32_t line;
    } lines[] = {
        {"gpio.estop_line", b->gpio.estop_line},
        {"gpio.enable_line", b->gpio.enable_line},
        {"gpio.led_line", b->gpio.led_line},
    };
    for (size_t i = 1; i < sizeof(lines) / sizeof(lines[0]); i++) {
        for (size_t k = 0; k < i; k++) {
            if (lines[i].line == lines[k].line)
                return fail_field(c, lines[i].key, "line %u already used by %s", lines[i].line,
                                  lines[k].key);
        }
    }
    return 0;
}

static void init_cyaml_cfg(cyaml_config_t *cfg, ctx_t *c)
{
    memset(cfg, 0, sizeof(*cfg));
    cfg->log_fn = cyaml_capture;
    cfg->log_ctx = c;
    cfg->mem_fn = cyaml_mem;
    cfg->log_level = CYAML_LOG_ERROR;
    cfg->flags = CYAML_CFG_DEFAULT;
}

static int ctx_open(ctx_t *c, const char *path, char *err, size_t err_len)
{
    memset(c, 0, sizeof(*c));
    c->path = path;
    c->err = err;
    c->err_len = err_len;
    if (err != NULL && err_len > 0)
        err[0] = '\0';
    c->cyaml_log = calloc(1, CYAML_LOG_BYTES);
    return c->cyaml_log == NULL ? -ENOMEM : 0;
}

static void ctx_close(ctx_t *c)
{
    tree_free(&c->tree);
    free(c->cyaml_log);
    c->cyaml_log = NULL;
}

int ps_config_load_board(const char *path, ps_board_cfg_t *out, char *err, size_t err_len)
{
    if (path == NULL || out == NULL)
        return -EINVAL;
    ctx_t c;
    int rc = ctx_open(&c, path, err, err_len);
    cyaml_config_t cfg;
    init_cyaml_cfg(&cfg, &c);
    board_raw_t *raw = NULL;
    if (rc == 0)
        rc = load_common(&c, &cfg, &BOARD_SCHEMA, (void **)&raw);

    ps_board_cfg_t b;
    memset(&b, 0, sizeof(b));
    if (rc == 0) {
        memcpy(b.name, raw->name, sizeof(b.name));
        b.kind = raw->kind;
        b.bus_budget = raw->bus_budget != NULL ? *raw->bus_budget : DEFAULT_BUS_BUDGET;
        b.n_buses = raw->n_buses; /* libcyaml enforced <= PS_MAX_BUSES */
        for (uint32_t i = 0; i < raw->n_buses; i++) {
            const bus_raw_t *r = &raw->buses[i];
            memcpy(b.buses[i].ifname, r->ifname, sizeof(b.buses[i].ifname));
            b.buses[i].bitrate = r->bitrate;
            b.buses[i].is_fd = r->is_fd != NULL && *r->is_fd;
            /* Without FD the data phase is the arbitration phase. */
            b.buses[i].data_bitrate = r->data_bitrate != NULL ? *r->data_bitrate : r->bitrate;
        }
        b.gpio = raw->gpio;
        b.rt = raw->rt;
    }
    if (raw != NULL)
        (void)cyaml_free(&cfg, &BOARD_SCHEMA, raw, 0); /* only fails on a NULL schema */
    if (rc == 0)
        rc = check_board(&c, &b);
    if (rc == 0)
        *out = b;
    ctx_close(&c);
    return rc;
}

/* ====================================================================== */
/* robot                                                                  */
/* ====================================================================== */

typedef struct {
    char name[PS_NAME_LEN];
    ps_act_range_t r;
} driver_raw_t;

/* The robot file's own shape, flat as written; checked here, then composed
 * into the modules' structs (ps_act_cfg_t, ps_servo_joint_cfg_t, ...). */
typedef struct {
    uint32_t servo_hz, policy_hz;
    float ramp_s, damping_s, damping_kd_nm_s_rad, still_vel_rad_s;
    float reply_timeout_s, imu_timeout_s, policy_deadline_s;
    uint32_t overrun_limit;
    float overrun_window_s, hold_s;
} control_file_t;

typedef struct {
    char name[PS_NAME_LEN];
    uint32_t bus_idx, can_id, reply_id;
    ps_act_proto_id_t protocol;
    ps_act_range_t wire; /* the driver's, motor side */
    float pos_min_rad, pos_max_rad, vel_max_rad_s, torque_max_nm;
    float kp_nm_rad, kd_nm_s_rad, kp_max_nm_rad, kd_max_nm_s_rad;
    float stance_rad, kt_nm_a, temp_max_c;
    uint32_t rate_div;
    float gear_ratio, direction, zero_offset_rad; /* defaults 1, +1, 0 */
} joint_file_t;

typedef struct {
    char name[PS_NAME_LEN];
    char model[PS_PATH_LEN];
    control_file_t control;
    uint32_t n_joints;
    joint_file_t joints[PS_MAX_JOINTS];
    ps_imu_cfg_t imu;
    ps_kinematics_cfg_t kin;
    ps_sim_devices_cfg_t sim;
} robot_file_t;

typedef struct {
    joint_file_t j; /* everything except `wire` and the optional fields comes from here */
    char driver[PS_NAME_LEN];
    float *gear_ratio, *direction, *zero_offset_rad; /* optional: NULL when absent */
} joint_raw_t;

typedef struct {
    char name[PS_NAME_LEN];
    char model[PS_PATH_LEN];
    control_file_t control;
    ps_imu_cfg_t imu;
    ps_kinematics_cfg_t kin;
    ps_sim_devices_cfg_t sim;
    driver_raw_t *drivers;
    uint32_t n_drivers;
    joint_raw_t *joints;
    uint32_t n_joints;
} robot_raw_t;

/* One CAN identifier in use on a bus, and which field claimed it. */
typedef struct {
    uint32_t bus_idx;
    uint32_t id;
    bool is_ext;
    char field[FIELD_PATH_LEN];
} id_use_t;

/* The file's struct plus what only the checks need. */
typedef struct {
    robot_file_t cfg;
    uint32_t n_drivers;
    driver_raw_t drivers[MAX_DRIVERS];
    char joint_driver[PS_MAX_JOINTS][PS_NAME_LEN];
    id_use_t id_uses[2u * PS_MAX_JOINTS + 2u]; /* command + reply per joint, IMU's two */
} robot_work_t;

static const cyaml_strval_t PROTOCOLS[] = {
    {"mit", PS_ACT_PROTO_MIT},
};
static_assert(sizeof(PROTOCOLS) / sizeof(PROTOCOLS[0]) == PS_ACT_PROTO_COUNT,
              "one YAML name per actuator protocol");

static const cyaml_schema_field_t CONTROL_FIELDS[] = {
    CYAML_FIELD_UINT("servo_hz", CYAML_FLAG_DEFAULT, control_file_t, servo_hz),
    CYAML_FIELD_UINT("policy_hz", CYAML_FLAG_DEFAULT, control_file_t, policy_hz),
    CYAML_FIELD_FLOAT("ramp_s", CYAML_FLAG_DEFAULT, control_file_t, ramp_s),
    CYAML_FIELD_FLOAT("damping_s", CYAML_FLAG_DEFAULT, control_file_t, damping_s),
    CYAML_FIELD_FLOAT("damping_kd_nm_s_rad", CYAML_FLAG_DEFAULT, control_file_t,
                      damping_kd_nm_s_rad),
    CYAML_FIELD_FLOAT("still_vel_rad_s", CYAML_FLAG_DEFAULT, control_file_t, still_vel_rad_s),
    CYAML_FIELD_FLOAT("reply_timeout_s", CYAML_FLAG_DEFAULT, control_file_t, reply_timeout_s),
    CYAML_FIELD_FLOAT("imu_timeout_s", CYAML_FLAG_DEFAULT, control_file_t, imu_timeout_s),
    CYAML_FIELD_FLOAT("policy_deadline_s", CYAML_FLAG_DEFAULT, control_file_t, policy_deadline_s),
    CYAML_FIELD_UINT("overrun_limit", CYAML_FLAG_DEFAULT, control_file_t, overrun_limit),
    CYAML_FIELD_FLOAT("overrun_window_s", CYAML_FLAG_DEFAULT, control_file_t, overrun_window_s),
    CYAML_FIELD_FLOAT("hold_s", CYAML_FLAG_DEFAULT, control_file_t, hold_s),
    CYAML_FIELD_END,
};
static const cyaml_schema_field_t IMU_FIELDS[] = {
    CYAML_FIELD_UINT("bus", CYAML_FLAG_DEFAULT, ps_imu_cfg_t, bus_idx),
    CYAML_FIELD_UINT("base_id", CYAML_FLAG_DEFAULT, ps_imu_cfg_t, base_id),
    CYAML_FIELD_UINT("rate_div", CYAML_FLAG_DEFAULT, ps_imu_cfg_t, rate_div),
    CYAML_FIELD_END,
};
static const cyaml_schema_field_t KIN_FIELDS[] = {
    CYAML_FIELD_FLOAT("mass_kg", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, mass_kg),
    CYAML_FIELD_FLOAT("hip_offset_y_m", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, hip_offset_y_m),
    CYAML_FIELD_FLOAT("hip_offset_z_m", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, hip_offset_z_m),
    CYAML_FIELD_FLOAT("thigh_m", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, thigh_m),
    CYAML_FIELD_FLOAT("shank_m", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, shank_m),
    CYAML_FIELD_FLOAT("ankle_height_m", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, ankle_height_m),
    CYAML_FIELD_FLOAT("foot_length_m", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, foot_length_m),
    CYAML_FIELD_FLOAT("foot_width_m", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, foot_width_m),
    CYAML_FIELD_FLOAT("foot_offset_x_m", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, foot_offset_x_m),
    CYAML_FIELD_FLOAT("com_offset_z_m", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, com_offset_z_m),
    CYAML_FIELD_FLOAT("fall_tilt_rad", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t, fall_tilt_rad),
    CYAML_FIELD_FLOAT("fall_com_height_m", CYAML_FLAG_DEFAULT, ps_kinematics_cfg_t,
                      fall_com_height_m),
    CYAML_FIELD_END,
};
static const cyaml_schema_field_t SIM_FIELDS[] = {
    CYAML_FIELD_FLOAT("gyro_noise_rad_s", CYAML_FLAG_DEFAULT, ps_sim_devices_cfg_t,
                      gyro_noise_rad_s),
    CYAML_FIELD_FLOAT("gyro_bias_rad_s", CYAML_FLAG_DEFAULT, ps_sim_devices_cfg_t, gyro_bias_rad_s),
    CYAML_FIELD_FLOAT("accel_noise_m_s2", CYAML_FLAG_DEFAULT, ps_sim_devices_cfg_t,
                      accel_noise_m_s2),
    CYAML_FIELD_FLOAT("accel_bias_m_s2", CYAML_FLAG_DEFAULT, ps_sim_devices_cfg_t, accel_bias_m_s2),
    CYAML_FIELD_FLOAT("reply_latency_s", CYAML_FLAG_DEFAULT, ps_sim_devices_cfg_t, reply_latency_s),
    CYAML_FIELD_FLOAT("thermal_r_c_w", CYAML_FLAG_DEFAULT, ps_sim_devices_cfg_t, thermal_r_c_w),
    CYAML_FIELD_FLOAT("thermal_tau_s", CYAML_FLAG_DEFAULT, ps_sim_devices_cfg_t, thermal_tau_s),
    CYAML_FIELD_FLOAT("winding_r_ohm", CYAML_FLAG_DEFAULT, ps_sim_devices_cfg_t, winding_r_ohm),
    CYAML_FIELD_FLOAT("ambient_c", CYAML_FLAG_DEFAULT, ps_sim_devices_cfg_t, ambient_c),
    CYAML_FIELD_END,
};
static const cyaml_schema_field_t DRIVER_FIELDS[] = {
    CYAML_FIELD_STRING("name", CYAML_FLAG_DEFAULT, driver_raw_t, name, 1),
    CYAML_FIELD_FLOAT("p_min_rad", CYAML_FLAG_DEFAULT, driver_raw_t, r.p_min_rad),
    CYAML_FIELD_FLOAT("p_max_rad", CYAML_FLAG_DEFAULT, driver_raw_t, r.p_max_rad),
    CYAML_FIELD_FLOAT("v_min_rad_s", CYAML_FLAG_DEFAULT, driver_raw_t, r.v_min_rad_s),
    CYAML_FIELD_FLOAT("v_max_rad_s", CYAML_FLAG_DEFAULT, driver_raw_t, r.v_max_rad_s),
    CYAML_FIELD_FLOAT("kp_max_nm_rad", CYAML_FLAG_DEFAULT, driver_raw_t, r.kp_max_nm_rad),
    CYAML_FIELD_FLOAT("kd_max_nm_s_rad", CYAML_FLAG_DEFAULT, driver_raw_t, r.kd_max_nm_s_rad),
    CYAML_FIELD_FLOAT("t_min_nm", CYAML_FLAG_DEFAULT, driver_raw_t, r.t_min_nm),
    CYAML_FIELD_FLOAT("t_max_nm", CYAML_FLAG_DEFAULT, driver_raw_t, r.t_max_nm),
    CYAML_FIELD_FLOAT("i_min_a", CYAML_FLAG_DEFAULT, driver_raw_t, r.i_min_a),
    CYAML_FIELD_FLOAT("i_max_a", CYAML_FLAG_DEFAULT, driver_raw_t, r.i_max_a),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t DRIVER_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_DEFAULT, driver_raw_t, DRIVER_FIELDS),
};
static const cyaml_schema_field_t JOINT_FIELDS[] = {
    CYAML_FIELD_STRING("name", CYAML_FLAG_DEFAULT, joint_raw_t, j.name, 1),
    CYAML_FIELD_UINT("bus", CYAML_FLAG_DEFAULT, joint_raw_t, j.bus_idx),
    CYAML_FIELD_UINT("can_id", CYAML_FLAG_DEFAULT, joint_raw_t, j.can_id),
    CYAML_FIELD_UINT("reply_id", CYAML_FLAG_DEFAULT, joint_raw_t, j.reply_id),
    CYAML_FIELD_ENUM("protocol", CYAML_FLAG_STRICT, joint_raw_t, j.protocol, PROTOCOLS,
                     CYAML_ARRAY_LEN(PROTOCOLS)),
    CYAML_FIELD_STRING("driver", CYAML_FLAG_DEFAULT, joint_raw_t, driver, 1),
    CYAML_FIELD_FLOAT("pos_min_rad", CYAML_FLAG_DEFAULT, joint_raw_t, j.pos_min_rad),
    CYAML_FIELD_FLOAT("pos_max_rad", CYAML_FLAG_DEFAULT, joint_raw_t, j.pos_max_rad),
    CYAML_FIELD_FLOAT("vel_max_rad_s", CYAML_FLAG_DEFAULT, joint_raw_t, j.vel_max_rad_s),
    CYAML_FIELD_FLOAT("torque_max_nm", CYAML_FLAG_DEFAULT, joint_raw_t, j.torque_max_nm),
    CYAML_FIELD_FLOAT("kp_nm_rad", CYAML_FLAG_DEFAULT, joint_raw_t, j.kp_nm_rad),
    CYAML_FIELD_FLOAT("kd_nm_s_rad", CYAML_FLAG_DEFAULT, joint_raw_t, j.kd_nm_s_rad),
    CYAML_FIELD_FLOAT("kp_max_nm_rad", CYAML_FLAG_DEFAULT, joint_raw_t, j.kp_max_nm_rad),
    CYAML_FIELD_FLOAT("kd_max_nm_s_rad", CYAML_FLAG_DEFAULT, joint_raw_t, j.kd_max_nm_s_rad),
    CYAML_FIELD_FLOAT("stance_rad", CYAML_FLAG_DEFAULT, joint_raw_t, j.stance_rad),
    CYAML_FIELD_FLOAT("kt_nm_a", CYAML_FLAG_DEFAULT, joint_raw_t, j.kt_nm_a),
    CYAML_FIELD_FLOAT("temp_max_c", CYAML_FLAG_DEFAULT, joint_raw_t, j.temp_max_c),
    CYAML_FIELD_UINT("rate_div", CYAML_FLAG_DEFAULT, joint_raw_t, j.rate_div),
    CYAML_FIELD_FLOAT_PTR("gear_ratio", CYAML_FLAG_OPTIONAL, joint_raw_t, gear_ratio),
    CYAML_FIELD_FLOAT_PTR("direction", CYAML_FLAG_OPTIONAL, joint_raw_t, direction),
    CYAML_FIELD_FLOAT_PTR("zero_offset_rad", CYAML_FLAG_OPTIONAL, joint_raw_t, zero_offset_rad),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t JOINT_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_DEFAULT, joint_raw_t, JOINT_FIELDS),
};
static const cyaml_schema_field_t ROBOT_FIELDS[] = {
    CYAML_FIELD_STRING("name", CYAML_FLAG_DEFAULT, robot_raw_t, name, 1),
    CYAML_FIELD_STRING("model", CYAML_FLAG_DEFAULT, robot_raw_t, model, 1),
    CYAML_FIELD_MAPPING("control", CYAML_FLAG_DEFAULT, robot_raw_t, control, CONTROL_FIELDS),
    CYAML_FIELD_MAPPING("imu", CYAML_FLAG_DEFAULT, robot_raw_t, imu, IMU_FIELDS),
    CYAML_FIELD_MAPPING("kinematics", CYAML_FLAG_DEFAULT, robot_raw_t, kin, KIN_FIELDS),
    CYAML_FIELD_MAPPING("sim", CYAML_FLAG_DEFAULT, robot_raw_t, sim, SIM_FIELDS),
    CYAML_FIELD_SEQUENCE_COUNT("drivers", CYAML_FLAG_POINTER, robot_raw_t, drivers, n_drivers,
                               &DRIVER_SCHEMA, 1, MAX_DRIVERS),
    CYAML_FIELD_SEQUENCE_COUNT("joints", CYAML_FLAG_POINTER, robot_raw_t, joints, n_joints,
                               &JOINT_SCHEMA, 1, PS_MAX_JOINTS),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t ROBOT_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_POINTER, robot_raw_t, ROBOT_FIELDS),
};

#define R_OFF(m) offsetof(robot_work_t, m)
#define J_OFF(m) offsetof(joint_file_t, m)
#define D_OFF(m) offsetof(driver_raw_t, m)
static const range_array_t ROBOT_ARRAYS[] = {
    {"joints", R_OFF(cfg.joints), sizeof(joint_file_t), R_OFF(cfg.n_joints)},
    {"drivers", R_OFF(drivers), sizeof(driver_raw_t), R_OFF(n_drivers)},
};
enum { RA_JOINTS = 1, RA_DRIVERS = 2 };
static const range_rule_t ROBOT_RANGES[] = {
    {0, NUM_U32, 0, "control.servo_hz", R_OFF(cfg.control.servo_hz), 100.0, 4000.0},
    {0, NUM_U32, 0, "control.policy_hz", R_OFF(cfg.control.policy_hz), 1.0, 1000.0},
    {0, NUM_F32, 0, "control.ramp_s", R_OFF(cfg.control.ramp_s), 0.1, 10.0},
    {0, NUM_F32, 0, "control.damping_s", R_OFF(cfg.control.damping_s), 0.2, 60.0},
    {0, NUM_F32, 0, "control.damping_kd_nm_s_rad", R_OFF(cfg.control.damping_kd_nm_s_rad), 0.0,
     100.0},
    {0, NUM_F32, 0, "control.still_vel_rad_s", R_OFF(cfg.control.still_vel_rad_s), 0.0, 10.0},
    {0, NUM_F32, RANGE_OPEN_MIN, "control.reply_timeout_s", R_OFF(cfg.control.reply_timeout_s), 0.0,
     1.0},
    {0, NUM_F32, RANGE_OPEN_MIN, "control.imu_timeout_s", R_OFF(cfg.control.imu_timeout_s), 0.0,
     1.0},
    {0, NUM_F32, RANGE_OPEN_MIN, "control.policy_deadline_s", R_OFF(cfg.control.policy_deadline_s),
     0.0, 1.0},
    {0, NUM_U32, 0, "control.overrun_limit", R_OFF(cfg.control.overrun_limit), 1.0,
     MAX_OVERRUN_LIMIT},
    {0, NUM_F32, RANGE_OPEN_MIN, "control.overrun_window_s", R_OFF(cfg.control.overrun_window_s),
     0.0, 10.0},
    {0, NUM_F32, 0, "control.hold_s", R_OFF(cfg.control.hold_s), 0.0, 60.0},
    {0, NUM_U32, 0, "imu.bus", R_OFF(cfg.imu.bus_idx), 0.0, PS_MAX_BUSES - 1u},
    {0, NUM_U32, RANGE_HEX, "imu.base_id", R_OFF(cfg.imu.base_id), 1.0, MAX_CAN_ID - 1u},
    {0, NUM_U32, 0, "imu.rate_div", R_OFF(cfg.imu.rate_div), 1.0, MAX_RATE_DIV},
    {0, NUM_F32, RANGE_OPEN_MIN, "kinematics.mass_kg", R_OFF(cfg.kin.mass_kg), 0.0, 500.0},
    {0, NUM_F32, 0, "kinematics.hip_offset_y_m", R_OFF(cfg.kin.hip_offset_y_m), 0.0, 1.0},
    {0, NUM_F32, 0, "kinematics.hip_offset_z_m", R_OFF(cfg.kin.hip_offset_z_m), -1.0, 1.0},
    {0, NUM_F32, RANGE_OPEN_MIN, "kinematics.thigh_m", R_OFF(cfg.kin.thigh_m), 0.0, 2.0},
    {0, NUM_F32, RANGE_OPEN_MIN, "kinematics.shank_m", R_OFF(cfg.kin.shank_m), 0.0, 2.0},
    {0, NUM_F32, 0, "kinematics.ankle_height_m", R_OFF(cfg.kin.ankle_height_m), 0.0, 1.0},
    {0, NUM_F32, RANGE_OPEN_MIN, "kinematics.foot_length_m", R_OFF(cfg.kin.foot_length_m), 0.0,
     1.0},
    {0, NUM_F32, RANGE_OPEN_MIN, "kinematics.foot_width_m", R_OFF(cfg.kin.foot_width_m), 0.0, 1.0},
    {0, NUM_F32, 0, "kinematics.foot_offset_x_m", R_OFF(cfg.kin.foot_offset_x_m), -0.5, 0.5},
    {0, NUM_F32, 0, "kinematics.com_offset_z_m", R_OFF(cfg.kin.com_offset_z_m), -1.0, 1.0},
    {0, NUM_F32, RANGE_OPEN_MIN, "kinematics.fall_tilt_rad", R_OFF(cfg.kin.fall_tilt_rad), 0.0,
     1.5708},
    {0, NUM_F32, 0, "kinematics.fall_com_height_m", R_OFF(cfg.kin.fall_com_height_m), 0.0, 3.0},
    {0, NUM_F32, 0, "sim.gyro_noise_rad_s", R_OFF(cfg.sim.gyro_noise_rad_s), 0.0, 1.0},
    {0, NUM_F32, 0, "sim.gyro_bias_rad_s", R_OFF(cfg.sim.gyro_bias_rad_s), 0.0, 1.0},
    {0, NUM_F32, 0, "sim.accel_noise_m_s2", R_OFF(cfg.sim.accel_noise_m_s2), 0.0, 10.0},
    {0, NUM_F32, 0, "sim.accel_bias_m_s2", R_OFF(cfg.sim.accel_bias_m_s2), 0.0, 10.0},
    {0, NUM_F32, 0, "sim.reply_latency_s", R_OFF(cfg.sim.reply_latency_s), 0.0, 0.01},
    {0, NUM_F32, RANGE_OPEN_MIN, "sim.thermal_r_c_w", R_OFF(cfg.sim.thermal_r_c_w), 0.0, 100.0},
    {0, NUM_F32, RANGE_OPEN_MIN, "sim.thermal_tau_s", R_OFF(cfg.sim.thermal_tau_s), 0.0, 10000.0},
    {0, NUM_F32, RANGE_OPEN_MIN, "sim.winding_r_ohm", R_OFF(cfg.sim.winding_r_ohm), 0.0, 100.0},
    {0, NUM_F32, 0, "sim.ambient_c", R_OFF(cfg.sim.ambient_c), -40.0, 85.0},
    {RA_DRIVERS, NUM_F32, 0, "p_min_rad", D_OFF(r.p_min_rad), -1000.0, 1000.0},
    {RA_DRIVERS, NUM_F32, 0, "p_max_rad", D_OFF(r.p_max_rad), -1000.0, 1000.0},
    {RA_DRIVERS, NUM_F32, 0, "v_min_rad_s", D_OFF(r.v_min_rad_s), -10000.0, 10000.0},
    {RA_DRIVERS, NUM_F32, 0, "v_max_rad_s", D_OFF(r.v_max_rad_s), -10000.0, 10000.0},
    {RA_DRIVERS, NUM_F32, RANGE_OPEN_MIN, "kp_max_nm_rad", D_OFF(r.kp_max_nm_rad), 0.0, 5000.0},
    {RA_DRIVERS, NUM_F32, RANGE_OPEN_MIN, "kd_max_nm_s_rad", D_OFF(r.kd_max_nm_s_rad), 0.0, 500.0},
    {RA_DRIVERS, NUM_F32, 0, "t_min_nm", D_OFF(r.t_min_nm), -1000.0, 1000.0},
    {RA_DRIVERS, NUM_F32, 0, "t_max_nm", D_OFF(r.t_max_nm), -1000.0, 1000.0},
    {RA_DRIVERS, NUM_F32, 0, "i_min_a", D_OFF(r.i_min_a), -1000.0, 1000.0},
    {RA_DRIVERS, NUM_F32, 0, "i_max_a", D_OFF(r.i_max_a), -1000.0, 1000.0},
    {RA_JOINTS, NUM_U32, 0, "bus", J_OFF(bus_idx), 0.0, PS_MAX_BUSES - 1u},
    {RA_JOINTS, NUM_U32, RANGE_HEX, "can_id", J_OFF(can_id), 1.0, PS_CAN_EFF_MASK},
    {RA_JOINTS, NUM_U32, RANGE_HEX, "reply_id", J_OFF(reply_id), 1.0, PS_CAN_EFF_MASK},
    {RA_JOINTS, NUM_F32, 0, "pos_min_rad", J_OFF(pos_min_rad), -1000.0, 1000.0},
    {RA_JOINTS, NUM_F32, 0, "pos_max_rad", J_OFF(pos_max_rad), -1000.0, 1000.0},
    {RA_JOINTS, NUM_F32, RANGE_OPEN_MIN, "vel_max_rad_s", J_OFF(vel_max_rad_s), 0.0, 10000.0},
    {RA_JOINTS, NUM_F32, RANGE_OPEN_MIN, "torque_max_nm", J_OFF(torque_max_nm), 0.0, 1000.0},
    {RA_JOINTS, NUM_F32, 0, "kp_nm_rad", J_OFF(kp_nm_rad), 0.0, 5000.0},
    {RA_JOINTS, NUM_F32, 0, "kd_nm_s_rad", J_OFF(kd_nm_s_rad), 0.0, 500.0},
    {RA_JOINTS, NUM_F32, RANGE_OPEN_MIN, "kp_max_nm_rad", J_OFF(kp_max_nm_rad), 0.0, 5000.0},
    {RA_JOINTS, NUM_F32, RANGE_OPEN_MIN, "kd_max_nm_s_rad", J_OFF(kd_max_nm_s_rad), 0.0, 500.0},
    {RA_JOINTS, NUM_F32, 0, "stance_rad", J_OFF(stance_rad), -1000.0, 1000.0},
    {RA_JOINTS, NUM_F32, RANGE_OPEN_MIN, "kt_nm_a", J_OFF(kt_nm_a), 0.0, 100.0},
    {RA_JOINTS, NUM_F32, 0, "temp_max_c", J_OFF(temp_max_c), 20.0, 200.0},
    {RA_JOINTS, NUM_U32, 0, "rate_div", J_OFF(rate_div), 1.0, MAX_RATE_DIV},
    {RA_JOINTS, NUM_F32, RANGE_OPEN_MIN, "gear_ratio", J_OFF(gear_ratio), 0.0, 1000.0},
    {RA_JOINTS, NUM_F32, 0, "direction", J_OFF(direction), -1.0, 1.0},
    {RA_JOINTS, NUM_F32, 0, "zero_offset_rad", J_OFF(zero_offset_rad), -1000.0, 1000.0},
};
#undef R_OFF
#undef J_OFF
#undef D_OFF

/* Field name pairs that must satisfy min < max, per driver. */
static int check_drivers(ctx_t *c, const robot_work_t *w)
{
    char field[FIELD_PATH_LEN];
    for (uint32_t i = 0; i < w->n_drivers; i++) {
        const driver_raw_t *d = &w->drivers[i];
        for (uint32_t k = 0; k < i; k++) {
            if (strcmp(d->name, w->drivers[k].name) == 0) {
                (void)snprintf(field, sizeof(field), "drivers[%u].name", i);
                return fail_field(c, field, "duplicate driver name \"%s\" (also drivers[%u])",
                                  d->name, k);
            }
        }
        const struct {
            const char *min_key, *max_key;
            float min, max;
        } pairs[] = {
            {"p_min_rad", "p_max_rad", d->r.p_min_rad, d->r.p_max_rad},
            {"v_min_rad_s", "v_max_rad_s", d->r.v_min_rad_s, d->r.v_max_rad_s},
            {"t_min_nm", "t_max_nm", d->r.t_min_nm, d->r.t_max_nm},
            {"i_min_a", "i_max_a", d->r.i_min_a, d->r.i_max_a},
        };
        for (size_t p = 0; p < sizeof(pairs) / sizeof(pairs[0]); p++) {
            if (!(pairs[p].min < pairs[p].max)) {
                (void)snprintf(field, sizeof(field), "drivers[%u].%s", i, pairs[p].max_key);
                return fail_field(c, field, "value %g not above %s %g", (double)pairs[p].max,
                                  pairs[p].min_key, (double)pairs[p].min);
            }
        }
    }
    return 0;
}

/* Finds the driver of every joint and copies its wire ranges. */
static int resolve_drivers(ctx_t *c, robot_work_t *w)
{
    char field[FIELD_PATH_LEN];
    for (uint32_t i = 0; i < w->cfg.n_joints; i++) {
        uint32_t d = 0;
        while (d < w->n_drivers && strcmp(w->drivers[d].name, w->joint_driver[i]) != 0)
            d++;
        if (d < w->n_drivers) {
            w->cfg.joints[i].wire = w->drivers[d].r;
            continue;
        }
        char known[PS_ERR_MSG_LEN / 2] = "";
        size_t used = 0;
        for (uint32_t k = 0; k < w->n_drivers && used < sizeof(known); k++) {
            const int n = snprintf(known + used, sizeof(known) - used, "%s%s", k > 0 ? ", " : "",
                                   w->drivers[k].name);
            if (n < 0)
                break;
            used += (size_t)n;
        }
        (void)snprintf(field, sizeof(field), "joints[%u].driver", i);
        return fail_field(c, field, "unknown driver \"%s\" (known: %s)", w->joint_driver[i], known);
    }
    return 0;
}

/* Limits of one joint against each other and against its driver's wire range. */
/* The actuator part of a joint as the modules see it. */
static ps_act_cfg_t act_of(const joint_file_t *j)
{
    const ps_act_cfg_t a = {
        .bus_idx = j->bus_idx,
        .can_id = j->can_id,
        .reply_id = j->reply_id,
        .protocol = j->protocol,
        .wire = j->wire,
        .gear_ratio = j->gear_ratio,
        .direction = j->direction,
        .zero_offset_rad = j->zero_offset_rad,
        .kt_nm_a = j->kt_nm_a,
        .temp_max_c = j->temp_max_c,
        .rate_div = j->rate_div,
    };
    return a;
}

/* Limits of one joint against each other and against its driver's wire
 * range seen from the joint (gear ratio, direction and zero offset applied). */
static int check_joint_limits(ctx_t *c, const robot_work_t *w, uint32_t i)
{
    const joint_file_t *j = &w->cfg.joints[i];
    char field[FIELD_PATH_LEN];
    if (j->direction != 1.0f && j->direction != -1.0f) {
        (void)snprintf(field, sizeof(field), "joints[%u].direction", i);
        return fail_field(c, field, "value %g is not 1 or -1", (double)j->direction);
    }
    const ps_act_cfg_t act = act_of(j);
    const ps_act_proto_t *proto = ps_act_proto_get(j->protocol);
    if (j->can_id > proto->id_max || j->reply_id > proto->id_max) {
        const bool is_cmd = j->can_id > proto->id_max;
        (void)snprintf(field, sizeof(field), "joints[%u].%s", i, is_cmd ? "can_id" : "reply_id");
        return fail_field(c, field, "value 0x%x above protocol %s's %u-bit maximum 0x%x",
                          is_cmd ? j->can_id : j->reply_id, proto->name, proto->id_bits,
                          proto->id_max);
    }
    ps_act_range_t wire_joint;
    ps_act_joint_range(&act, &wire_joint);
    const ps_act_range_t *r = &wire_joint;
    const char *drv = w->joint_driver[i];
#define JFIELD(key) ((void)snprintf(field, sizeof(field), "joints[%u]." key, i), field)
    if (!(j->pos_min_rad < j->pos_max_rad))
        return fail_field(c, JFIELD("pos_max_rad"), "value %g not above pos_min_rad %g",
                          (double)j->pos_max_rad, (double)j->pos_min_rad);
    if (j->pos_min_rad < r->p_min_rad || j->pos_min_rad > r->p_max_rad)
        return fail_field(c, JFIELD("pos_min_rad"),
                          "value %g outside driver \"%s\" wire range [%g, %g]",
                          (double)j->pos_min_rad, drv, (double)r->p_min_rad, (double)r->p_max_rad);
    if (j->pos_max_rad < r->p_min_rad || j->pos_max_rad > r->p_max_rad)
        return fail_field(c, JFIELD("pos_max_rad"),
                          "value %g outside driver \"%s\" wire range [%g, %g]",
                          (double)j->pos_max_rad, drv, (double)r->p_min_rad, (double)r->p_max_rad);
    if (j->stance_rad < j->pos_min_rad || j->stance_rad > j->pos_max_rad)
        return fail_field(c, JFIELD("stance_rad"), "value %g outside joint limits [%g, %g]",
                          (double)j->stance_rad, (double)j->pos_min_rad, (double)j->pos_max_rad);
    if (-j->vel_max_rad_s < r->v_min_rad_s || j->vel_max_rad_s > r->v_max_rad_s)
        return fail_field(
            c, JFIELD("vel_max_rad_s"), "+/-%g outside driver \"%s\" wire range [%g, %g]",
            (double)j->vel_max_rad_s, drv, (double)r->v_min_rad_s, (double)r->v_max_rad_s);
    if (-j->torque_max_nm < r->t_min_nm || j->torque_max_nm > r->t_max_nm)
        return fail_field(c, JFIELD("torque_max_nm"),
                          "+/-%g outside driver \"%s\" wire range [%g, %g]",
                          (double)j->torque_max_nm, drv, (double)r->t_min_nm, (double)r->t_max_nm);
    if (j->kp_max_nm_rad > r->kp_max_nm_rad)
        return fail_field(c, JFIELD("kp_max_nm_rad"),
                          "value %g above driver \"%s\" kp_max_nm_rad %g", (double)j->kp_max_nm_rad,
                          drv, (double)r->kp_max_nm_rad);
    if (j->kd_max_nm_s_rad > r->kd_max_nm_s_rad)
        return fail_field(c, JFIELD("kd_max_nm_s_rad"),
                          "value %g above driver \"%s\" kd_max_nm_s_rad %g",
                          (double)j->kd_max_nm_s_rad, drv, (double)r->kd_max_nm_s_rad);
    if (j->kp_nm_rad > j->kp_max_nm_rad)
        return fail_field(c, JFIELD("kp_nm_rad"), "value %g above kp_max_nm_rad %g",
                          (double)j->kp_nm_rad, (double)j->kp_max_nm_rad);
    if (j->kd_nm_s_rad > j->kd_max_nm_s_rad)
        return fail_field(c, JFIELD("kd_nm_s_rad"), "value %g above kd_max_nm_s_rad %g",
                          (double)j->kd_nm_s_rad, (double)j->kd_max_nm_s_rad);
    if (w->cfg.control.damping_kd_nm_s_rad > j->kd_max_nm_s_rad)
        return fail_field(
            c, "control.damping_kd_nm_s_rad", "value %g above joints[%u].kd_max_nm_s_rad %g",
            (double)w->cfg.control.damping_kd_nm_s_rad, i, (double)j->kd_max_nm_s_rad);
#undef JFIELD
    return 0;
}

/* 11-bit and 29-bit identifiers are different frames even with one value. */
/* Timeouts in periods, not seconds: the policy runs inside one servo tick,
 * so its deadline is at most half the period (the other half is the rest of
 * the tick and the wake-up latency); a reply or IMU sample counts as stale
 * after at most MAX_TIMEOUT_PERIODS of its own period. */
static int check_timing(ctx_t *c, const robot_work_t *w)
{
    const control_file_t *ctl = &w->cfg.control;
    const double period_s = 1.0 / (double)ctl->servo_hz;
    if ((double)ctl->policy_deadline_s > 0.5 * period_s * (1.0 + 1e-6))
        return fail_field(c, "control.policy_deadline_s",
                          "value %g does not fit in the servo period: at most half of 1/servo_hz "
                          "= %g s",
                          (double)ctl->policy_deadline_s, 0.5 * period_s);
    uint32_t min_div = UINT32_MAX;
    for (uint32_t i = 0; i < w->cfg.n_joints; i++)
        min_div = w->cfg.joints[i].rate_div < min_div ? w->cfg.joints[i].rate_div : min_div;
    const double reply_max_s = MAX_TIMEOUT_PERIODS * (double)min_div * period_s;
    if (w->cfg.n_joints > 0 && (double)ctl->reply_timeout_s > reply_max_s * (1.0 + 1e-6))
        return fail_field(c, "control.reply_timeout_s",
                          "value %g is more than %u command periods of the fastest joint "
                          "(rate_div %u at %u Hz): at most %g s",
                          (double)ctl->reply_timeout_s, MAX_TIMEOUT_PERIODS, min_div, ctl->servo_hz,
                          reply_max_s);
    const double imu_max_s = MAX_TIMEOUT_PERIODS * (double)w->cfg.imu.rate_div * period_s;
    if ((double)ctl->imu_timeout_s > imu_max_s * (1.0 + 1e-6))
        return fail_field(c, "control.imu_timeout_s",
                          "value %g is more than %u IMU sample periods (rate_div %u at %u Hz): at "
                          "most %g s",
                          (double)ctl->imu_timeout_s, MAX_TIMEOUT_PERIODS, w->cfg.imu.rate_div,
                          ctl->servo_hz, imu_max_s);
    return 0;
}

static int claim_id(ctx_t *c, id_use_t *uses, uint32_t *n_uses, uint32_t bus_idx, uint32_t id,
                    bool is_ext, const char *field, const char *yaml_field)
{
    for (uint32_t k = 0; k < *n_uses; k++) {
        if (uses[k].bus_idx == bus_idx && uses[k].id == id && uses[k].is_ext == is_ext)
            return fail_field(c, yaml_field, "id 0x%03x on bus %u already used by %s", id, bus_idx,
                              uses[k].field);
    }
    uses[*n_uses].bus_idx = bus_idx;
    uses[*n_uses].id = id;
    uses[*n_uses].is_ext = is_ext;
    (void)snprintf(uses[*n_uses].field, sizeof(uses[0].field), "%s", field);
    (*n_uses)++;
    return 0;
}

static int check_robot(ctx_t *c, robot_work_t *w)
{
    int rc = check_ranges(c, w, ROBOT_ARRAYS, ROBOT_RANGES,
                          sizeof(ROBOT_RANGES) / sizeof(ROBOT_RANGES[0]));
    if (rc == 0)
        rc = check_drivers(c, w);
    if (rc == 0)
        rc = resolve_drivers(c, w);
    if (rc != 0)
        return rc;

    const control_file_t *ctl = &w->cfg.control;
    if (ctl->policy_hz > ctl->servo_hz || ctl->servo_hz % ctl->policy_hz != 0)
        return fail_field(c, "control.policy_hz", "servo_hz %u is not a multiple of policy_hz %u",
                          ctl->servo_hz, ctl->policy_hz);
    const int trc = check_timing(c, w);
    if (trc != 0)
        return trc;
    /* Every device is sampled on every policy tick only if its divider
     * divides the number of servo ticks per policy tick. */
    const uint32_t ticks_per_policy = ctl->servo_hz / ctl->policy_hz;
    if (ticks_per_policy % w->cfg.imu.rate_div != 0)
        return fail_field(c, "imu.rate_div", "value %u does not divide servo_hz/policy_hz = %u",
                          w->cfg.imu.rate_div, ticks_per_policy);

    char field[FIELD_PATH_LEN];
    id_use_t *uses = w->id_uses;
    uint32_t n_uses = 0;
    rc = claim_id(c, uses, &n_uses, w->cfg.imu.bus_idx, w->cfg.imu.base_id, false, "imu.base_id",
                  "imu.base_id");
    if (rc == 0)
        rc = claim_id(c, uses, &n_uses, w->cfg.imu.bus_idx, w->cfg.imu.base_id + 1u, false,
                      "imu.base_id+1", "imu.base_id");
    for (uint32_t i = 0; i < w->cfg.n_joints && rc == 0; i++) {
        const joint_file_t *j = &w->cfg.joints[i];
        const bool is_ext = ps_act_proto_get(j->protocol)->id_bits > 11u;
        for (uint32_t k = 0; k < i; k++) {
            if (strcmp(j->name, w->cfg.joints[k].name) == 0) {
                (void)snprintf(field, sizeof(field), "joints[%u].name", i);
                return fail_field(c, field, "duplicate joint name \"%s\" (also joints[%u])",
                                  j->name, k);
            }
        }
        rc = check_joint_limits(c, w, i);
        if (rc != 0)
            return rc;
        if (ticks_per_policy % j->rate_div != 0) {
            (void)snprintf(field, sizeof(field), "joints[%u].rate_div", i);
            return fail_field(c, field, "value %u does not divide servo_hz/policy_hz = %u",
                              j->rate_div, ticks_per_policy);
        }
        char owner[FIELD_PATH_LEN];
        (void)snprintf(owner, sizeof(owner), "joints[%u].can_id", i);
        rc = claim_id(c, uses, &n_uses, j->bus_idx, j->can_id, is_ext, owner, owner);
        if (rc == 0) {
            (void)snprintf(owner, sizeof(owner), "joints[%u].reply_id", i);
            rc = claim_id(c, uses, &n_uses, j->bus_idx, j->reply_id, is_ext, owner, owner);
        }
    }
    return rc;
}

/* The checked file into the modules' structs. */
static void compose_robot(const robot_file_t *f, ps_robot_cfg_t *out)
{
    memset(out, 0, sizeof(*out));
    memcpy(out->name, f->name, sizeof(out->name));
    memcpy(out->model, f->model, sizeof(out->model));
    const control_file_t *c = &f->control;
    out->control = (ps_control_cfg_t){
        .servo_hz = c->servo_hz,
        .policy_hz = c->policy_hz,
        .ramp_s = c->ramp_s,
        .damping_s = c->damping_s,
        .still_vel_rad_s = c->still_vel_rad_s,
        .reply_timeout_s = c->reply_timeout_s,
        .imu_timeout_s = c->imu_timeout_s,
        .policy_deadline_s = c->policy_deadline_s,
        .overrun_limit = c->overrun_limit,
        .overrun_window_s = c->overrun_window_s,
        .hold_s = c->hold_s,
    };
    out->servo_common.damping_kd_nm_s_rad = c->damping_kd_nm_s_rad;
    out->n_joints = f->n_joints;
    for (uint32_t i = 0; i < f->n_joints; i++) {
        const joint_file_t *j = &f->joints[i];
        memcpy(out->joint_name[i], j->name, PS_NAME_LEN);
        out->act[i] = act_of(j);
        ps_servo_joint_cfg_t *s = &out->servo[i];
        s->lim = (ps_act_limits_t){
            .pos_min_rad = j->pos_min_rad,
            .pos_max_rad = j->pos_max_rad,
            .vel_max_rad_s = j->vel_max_rad_s,
            .torque_max_nm = j->torque_max_nm,
            .kp_max_nm_rad = j->kp_max_nm_rad,
            .kd_max_nm_s_rad = j->kd_max_nm_s_rad,
        };
        s->kp_nm_rad = j->kp_nm_rad;
        s->kd_nm_s_rad = j->kd_nm_s_rad;
        s->stance_rad = j->stance_rad;
        ps_act_joint_range(&out->act[i], &s->wire);
    }
    out->imu = f->imu;
    out->kin = f->kin;
    out->sim = f->sim;
}

int ps_config_load_robot(const char *path, ps_robot_cfg_t *out, char *err, size_t err_len)
{
    if (path == NULL || out == NULL)
        return -EINVAL;
    ctx_t c;
    int rc = ctx_open(&c, path, err, err_len);
    cyaml_config_t cfg;
    init_cyaml_cfg(&cfg, &c);
    robot_raw_t *raw = NULL;
    if (rc == 0)
        rc = load_common(&c, &cfg, &ROBOT_SCHEMA, (void **)&raw);

    /* ~6 KB: heap, not the caller's (possibly small) stack. */
    robot_work_t *w = rc == 0 ? calloc(1, sizeof(*w)) : NULL;
    if (rc == 0 && w == NULL)
        rc = -ENOMEM;
    if (rc == 0) {
        robot_file_t *r = &w->cfg;
        memcpy(r->name, raw->name, sizeof(r->name));
        memcpy(r->model, raw->model, sizeof(r->model));
        r->control = raw->control;
        r->imu = raw->imu;
        r->kin = raw->kin;
        r->sim = raw->sim;
        w->n_drivers = raw->n_drivers; /* libcyaml enforced the maxima */
        memcpy(w->drivers, raw->drivers, raw->n_drivers * sizeof(w->drivers[0]));
        r->n_joints = raw->n_joints;
        for (uint32_t i = 0; i < raw->n_joints; i++) {
            const joint_raw_t *jr = &raw->joints[i];
            r->joints[i] = jr->j;
            r->joints[i].gear_ratio = jr->gear_ratio != NULL ? *jr->gear_ratio : 1.0f;
            r->joints[i].direction = jr->direction != NULL ? *jr->direction : 1.0f;
            r->joints[i].zero_offset_rad =
                jr->zero_offset_rad != NULL ? *jr->zero_offset_rad : 0.0f;
            memcpy(w->joint_driver[i], jr->driver, PS_NAME_LEN);
        }
    }
    if (raw != NULL)
        (void)cyaml_free(&cfg, &ROBOT_SCHEMA, raw, 0); /* only fails on a NULL schema */
    if (rc == 0)
        rc = check_robot(&c, w);
    if (rc == 0)
        compose_robot(&w->cfg, out);
    free(w);
    ctx_close(&c);
    return rc;
}

/* ====================================================================== */
/* scenario                                                               */
/* ====================================================================== */

typedef struct {
    char name[PS_NAME_LEN];
    float duration_s;
    uint32_t seed;
    ps_event_cfg_t *events;
    uint32_t n_events;
    ps_push_cfg_t *pushes;
    uint32_t n_pushes;
} scenario_raw_t;

static const cyaml_strval_t EVENT_KINDS[] = {
    {"start", PS_EVENT_START},
    {"stop", PS_EVENT_STOP},
    {"estop_press", PS_EVENT_ESTOP_PRESS},
    {"estop_release", PS_EVENT_ESTOP_RELEASE},
    {"reset", PS_EVENT_RESET},
    {"harness_release", PS_EVENT_HARNESS_RELEASE},
    {"drop_replies", PS_EVENT_DROP_REPLIES},
};
static_assert(sizeof(EVENT_KINDS) / sizeof(EVENT_KINDS[0]) == PS_EVENT_COUNT,
              "one YAML name per event kind");

static const cyaml_schema_value_t FLOAT_SCHEMA = {
    CYAML_VALUE_FLOAT(CYAML_FLAG_DEFAULT, float),
};
static const cyaml_schema_field_t EVENT_FIELDS[] = {
    CYAML_FIELD_FLOAT("t_s", CYAML_FLAG_DEFAULT, ps_event_cfg_t, t_s),
    CYAML_FIELD_ENUM("kind", CYAML_FLAG_STRICT, ps_event_cfg_t, kind, EVENT_KINDS,
                     CYAML_ARRAY_LEN(EVENT_KINDS)),
    CYAML_FIELD_STRING("joint", CYAML_FLAG_OPTIONAL, ps_event_cfg_t, joint, 1),
    CYAML_FIELD_FLOAT("duration_s", CYAML_FLAG_OPTIONAL, ps_event_cfg_t, duration_s),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t EVENT_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_DEFAULT, ps_event_cfg_t, EVENT_FIELDS),
};
static const cyaml_schema_field_t PUSH_FIELDS[] = {
    CYAML_FIELD_FLOAT("t_s", CYAML_FLAG_DEFAULT, ps_push_cfg_t, t_s),
    CYAML_FIELD_FLOAT("duration_s", CYAML_FLAG_DEFAULT, ps_push_cfg_t, duration_s),
    CYAML_FIELD_STRING("body", CYAML_FLAG_DEFAULT, ps_push_cfg_t, body, 1),
    CYAML_FIELD_SEQUENCE_FIXED("force_n", CYAML_FLAG_DEFAULT, ps_push_cfg_t, force_n, &FLOAT_SCHEMA,
                               3),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t PUSH_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_DEFAULT, ps_push_cfg_t, PUSH_FIELDS),
};
static const cyaml_schema_field_t SCENARIO_FIELDS[] = {
    CYAML_FIELD_STRING("name", CYAML_FLAG_DEFAULT, scenario_raw_t, name, 1),
    CYAML_FIELD_FLOAT("duration_s", CYAML_FLAG_DEFAULT, scenario_raw_t, duration_s),
    CYAML_FIELD_UINT("seed", CYAML_FLAG_DEFAULT, scenario_raw_t, seed),
    CYAML_FIELD_SEQUENCE_COUNT("events", CYAML_FLAG_POINTER | CYAML_FLAG_OPTIONAL, scenario_raw_t,
                               events, n_events, &EVENT_SCHEMA, 0, PS_MAX_EVENTS),
    CYAML_FIELD_SEQUENCE_COUNT("pushes", CYAML_FLAG_POINTER | CYAML_FLAG_OPTIONAL, scenario_raw_t,
                               pushes, n_pushes, &PUSH_SCHEMA, 0, PS_MAX_PUSHES),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t SCENARIO_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_POINTER, scenario_raw_t, SCENARIO_FIELDS),
};

#define S_OFF(m)         offsetof(ps_scenario_cfg_t, m)
#define MAX_PUSH_FORCE_N 2000.0
#define MAX_RUN_S        86400.0
static const range_array_t SCENARIO_ARRAYS[] = {
    {"events", S_OFF(events), sizeof(ps_event_cfg_t), S_OFF(n_events)},
    {"pushes", S_OFF(pushes), sizeof(ps_push_cfg_t), S_OFF(n_pushes)},
};
enum { SA_EVENTS = 1, SA_PUSHES = 2 };
static const range_rule_t SCENARIO_RANGES[] = {
    {0, NUM_F32, 0, "duration_s", S_OFF(duration_s), 0.0, MAX_RUN_S},
    {0, NUM_U32, 0, "seed", S_OFF(seed), 0.0, 4294967295.0},
    {SA_EVENTS, NUM_F32, 0, "t_s", offsetof(ps_event_cfg_t, t_s), 0.0, MAX_RUN_S},
    {SA_EVENTS, NUM_F32, 0, "duration_s", offsetof(ps_event_cfg_t, duration_s), 0.0, 3600.0},
    {SA_PUSHES, NUM_F32, 0, "t_s", offsetof(ps_push_cfg_t, t_s), 0.0, MAX_RUN_S},
    {SA_PUSHES, NUM_F32, RANGE_OPEN_MIN, "duration_s", offsetof(ps_push_cfg_t, duration_s), 0.0,
     10.0},
    {SA_PUSHES, NUM_F32, 0, "force_n[0]", offsetof(ps_push_cfg_t, force_n[0]), -MAX_PUSH_FORCE_N,
     MAX_PUSH_FORCE_N},
    {SA_PUSHES, NUM_F32, 0, "force_n[1]", offsetof(ps_push_cfg_t, force_n[1]), -MAX_PUSH_FORCE_N,
     MAX_PUSH_FORCE_N},
    {SA_PUSHES, NUM_F32, 0, "force_n[2]", offsetof(ps_push_cfg_t, force_n[2]), -MAX_PUSH_FORCE_N,
     MAX_PUSH_FORCE_N},
};
#undef S_OFF

static int check_scenario(ctx_t *c, const ps_scenario_cfg_t *s)
{
    int rc = check_ranges(c, s, SCENARIO_ARRAYS, SCENARIO_RANGES,
                          sizeof(SCENARIO_RANGES) / sizeof(SCENARIO_RANGES[0]));
    if (rc != 0)
        return rc;
    char field[FIELD_PATH_LEN];
    for (uint32_t i = 0; i < s->n_events; i++) {
        const ps_event_cfg_t *e = &s->events[i];
        const bool is_drop = e->kind == PS_EVENT_DROP_REPLIES;
        if (is_drop && e->joint[0] == '\0') {
            (void)snprintf(field, sizeof(field), "events[%u]", i);
            return fail_field(c, field, "drop_replies needs a \"joint\"");
        }
        if (!is_drop && e->joint[0] != '\0') {
            (void)snprintf(field, sizeof(field), "events[%u].joint", i);
            return fail_field(c, field, "only drop_replies takes a joint, not %s",
                              ps_config_event_name(e->kind));
        }
        if (!is_drop && e->duration_s != 0.0f) {
            (void)snprintf(field, sizeof(field), "events[%u].duration_s", i);
            return fail_field(c, field, "only drop_replies takes a duration, not %s",
                              ps_config_event_name(e->kind));
        }
        if (s->duration_s > 0.0f && e->t_s > s->duration_s) {
            (void)snprintf(field, sizeof(field), "events[%u].t_s", i);
            return fail_field(c, field, "value %g after the end of the run (duration_s %g)",
                              (double)e->t_s, (double)s->duration_s);
        }
    }
    for (uint32_t i = 0; i < s->n_pushes; i++) {
        const ps_push_cfg_t *p = &s->pushes[i];
        const double f =
            sqrt((double)p->force_n[0] * p->force_n[0] + (double)p->force_n[1] * p->force_n[1] +
                 (double)p->force_n[2] * p->force_n[2]);
        if (f > MAX_PUSH_FORCE_N) {
            (void)snprintf(field, sizeof(field), "pushes[%u].force_n", i);
            return fail_field(c, field, "magnitude %g N outside [0, %g]", f, MAX_PUSH_FORCE_N);
        }
        if (s->duration_s > 0.0f && p->t_s > s->duration_s) {
            (void)snprintf(field, sizeof(field), "pushes[%u].t_s", i);
            return fail_field(c, field, "value %g after the end of the run (duration_s %g)",
                              (double)p->t_s, (double)s->duration_s);
        }
    }
    return 0;
}

int ps_config_load_scenario(const char *path, ps_scenario_cfg_t *out, char *err, size_t err_len)
{
    if (path == NULL || out == NULL)
        return -EINVAL;
    ctx_t c;
    int rc = ctx_open(&c, path, err, err_len);
    cyaml_config_t cfg;
    init_cyaml_cfg(&cfg, &c);
    scenario_raw_t *raw = NULL;
    if (rc == 0)
        rc = load_common(&c, &cfg, &SCENARIO_SCHEMA, (void **)&raw);

    ps_scenario_cfg_t *s = rc == 0 ? calloc(1, sizeof(*s)) : NULL;
    if (rc == 0 && s == NULL)
        rc = -ENOMEM;
    if (rc == 0) {
        memcpy(s->name, raw->name, sizeof(s->name));
        s->duration_s = raw->duration_s;
        s->seed = raw->seed;
        s->n_events = raw->n_events; /* libcyaml enforced the maxima */
        if (raw->n_events > 0)
            memcpy(s->events, raw->events, raw->n_events * sizeof(s->events[0]));
        s->n_pushes = raw->n_pushes;
        if (raw->n_pushes > 0)
            memcpy(s->pushes, raw->pushes, raw->n_pushes * sizeof(s->pushes[0]));
    }
    if (raw != NULL)
        (void)cyaml_free(&cfg, &SCENARIO_SCHEMA, raw, 0); /* only fails on a NULL schema */
    if (rc == 0)
        rc = check_scenario(&c, s);
    if (rc == 0)
        *out = *s;
    free(s);
    ctx_close(&c);
    return rc;
}

/* ====================================================================== */
/* cross-file checks and look-ups                                         */
/* ====================================================================== */

#define PAIR_FAIL(...) (ps_err_format(__VA_ARGS__), -PS_ERR_CONFIG)

int ps_config_check_pair(const ps_board_cfg_t *b, const ps_robot_cfg_t *r,
                         const ps_scenario_cfg_t *s, char *err, size_t err_len)
{
    if (b == NULL || r == NULL)
        return -EINVAL;
    if (err != NULL && err_len > 0)
        err[0] = '\0';
    for (uint32_t i = 0; i < r->n_joints; i++) {
        if (r->act[i].bus_idx >= b->n_buses)
            return PAIR_FAIL(err, err_len,
                             "robot %s: joints[%u].bus: bus %u not on board %s (buses 0..%u)",
                             r->name, i, r->act[i].bus_idx, b->name, b->n_buses - 1u);
        const ps_act_proto_t *p = ps_act_proto_get(r->act[i].protocol);
        if (p != NULL && p->is_fd && !b->buses[r->act[i].bus_idx].is_fd)
            return PAIR_FAIL(err, err_len,
                             "robot %s: joints[%u].protocol: %s needs CAN FD but bus %u (%s) of "
                             "board %s is classical",
                             r->name, i, p->name, r->act[i].bus_idx,
                             b->buses[r->act[i].bus_idx].ifname, b->name);
    }
    if (r->imu.bus_idx >= b->n_buses)
        return PAIR_FAIL(err, err_len, "robot %s: imu.bus: bus %u not on board %s (buses 0..%u)",
                         r->name, r->imu.bus_idx, b->name, b->n_buses - 1u);
    if (s == NULL)
        return 0;
    for (uint32_t i = 0; i < s->n_events; i++) {
        const ps_event_cfg_t *e = &s->events[i];
        if (e->kind == PS_EVENT_DROP_REPLIES && ps_config_find_joint(r, e->joint) < 0)
            return PAIR_FAIL(err, err_len,
                             "scenario %s: events[%u].joint: no joint \"%s\" in robot %s", s->name,
                             i, e->joint, r->name);
    }
    /* Push bodies name bodies of the MuJoCo model, which only the sim knows. */
    return 0;
}

int ps_config_find_joint(const ps_robot_cfg_t *r, const char *name)
{
    if (r == NULL || name == NULL)
        return -ENOENT;
    for (uint32_t i = 0; i < r->n_joints && i < PS_MAX_JOINTS; i++) {
        if (strncmp(r->joint_name[i], name, PS_NAME_LEN) == 0)
            return (int)i;
    }
    return -ENOENT;
}

const char *ps_config_event_name(ps_event_kind_t k)
{
    if ((unsigned)k >= (unsigned)PS_EVENT_COUNT)
        return "unknown";
    return EVENT_KINDS[k].str; /* static_assert above keeps the table complete */
}
