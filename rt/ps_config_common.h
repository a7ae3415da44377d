/*
 * ps_config_common: the part of the configuration loader that every file kind
 * shares (internal: included only by rt/ps_config_board.c, ps_config_robot.c
 * and ps_config_scenario.c). It reads a file once, builds a position tree for
 * messages, loads the same buffer with libcyaml, explains libcyaml's failures,
 * refuses what libcyaml accepts too leniently (booleans, integers) and checks
 * numeric fields against typed range tables.
 *
 * Why a position tree next to libcyaml: libcyaml 1.3.1 reports a position
 * only inside the text of its error log ("Load: Backtrace: ... (line: L,
 * column: C)"); cyaml_err_t carries none, and the data it loads keeps none.
 * Range checks and the checks between files happen after a successful load,
 * so they need the lines from elsewhere: a libyaml event pass over the same
 * in-memory buffer. The file is read once; libyaml runs twice over the buffer
 * (here and inside cyaml_load_data, which takes no pre-parsed events).
 *
 * Threads: INIT only (main thread). Allocation: the tree and the captured log
 * live from ps_cfg_ctx_open to ps_cfg_ctx_close.
 */
#ifndef PS_CONFIG_COMMON_H
#define PS_CONFIG_COMMON_H

#include <assert.h>
#include <cyaml/cyaml.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "ps_limits.h"

#define PS_CFG_FIELD_PATH_LEN 128u /**< "pushes[63].force_n[2]" and the like */

/* ---- position tree ------------------------------------------------------ */

typedef enum {
    PS_CFG_YN_SCALAR,
    PS_CFG_YN_MAP,
    PS_CFG_YN_SEQ,
    PS_CFG_YN_ALIAS
} ps_cfg_ynode_type_t;

typedef struct {
    ps_cfg_ynode_type_t type;
    int parent_idx;
    int first_child_idx;
    int last_child_idx;
    int next_idx;
    uint32_t n_children;
    size_t line; /**< 0-based, libyaml's mark of the value node */
    size_t col;
    char *key;       /**< key under which this node sits in its parent mapping */
    size_t key_line; /**< 0-based */
    char *value;     /**< scalars only */
    bool is_plain;   /**< scalars only: written without quotes or tags */
} ps_cfg_ynode_t;

typedef struct {
    ps_cfg_ynode_t *nodes;
    int n_nodes;
    int cap_nodes;
} ps_cfg_ytree_t;

/* ---- typed range rules -------------------------------------------------- */

typedef enum { PS_CFG_NUM_U32, PS_CFG_NUM_I32, PS_CFG_NUM_F32 } ps_cfg_num_t;

enum {
    PS_CFG_RANGE_OPEN_MIN = 1u << 0, /**< (min, max] instead of [min, max] */
    PS_CFG_RANGE_HEX = 1u << 1,      /**< print value and bounds in hex (CAN ids) */
};

/** An array of the checked struct that rules may refer to. */
typedef struct {
    const char *name; /**< YAML key of the sequence */
    size_t off;       /**< offset of element 0 */
    size_t stride;    /**< sizeof one element */
    size_t count_off; /**< offset of the uint32_t entry count */
} ps_cfg_array_t;

/** One numeric field: YAML path, where it lives, its type and bounds. Write
 *  rules with PS_CFG_RULE_U32/I32/F32 and arrays with PS_CFG_ARRAY only: they
 *  take the member, not an offset, and refuse to compile when the member's
 *  type is not the rule's. */
typedef struct {
    uint8_t arr_idx; /**< 0: not in an array, else 1 + index into the array table */
    uint8_t type;    /**< ps_cfg_num_t */
    uint8_t flags;   /**< PS_CFG_RANGE_* */
    const char *key; /**< path in the file, relative to the array element if any */
    size_t off;      /**< offset in the struct, or in the array element */
    double min, max;
} ps_cfg_rule_t;

/* offsetof(S, m), but only when S.m has type T: _Generic has no association
 * for any other type, so a mismatch is a compile error. For example
 *   PS_CFG_RULE_U32(0, 0, "bus_budget", ps_board_cfg_t, bus_budget, 0, 1)
 * (bus_budget is a float) fails with
 *   error: '_Generic' selector of type 'float' is not compatible with any association
 * The rule then reads the member as exactly that type. */
#define PS_CFG_TYPED_OFF(T, S, m) _Generic(((S *)0)->m, T : offsetof(S, m))

#define PS_CFG_RULE_U32(arr, flags, key, S, m, lo, hi)                                             \
    {                                                                                              \
        (arr), PS_CFG_NUM_U32, (flags), (key), PS_CFG_TYPED_OFF(uint32_t, S, m), (lo), (hi)        \
    }
#define PS_CFG_RULE_I32(arr, flags, key, S, m, lo, hi)                                             \
    {                                                                                              \
        (arr), PS_CFG_NUM_I32, (flags), (key), PS_CFG_TYPED_OFF(int32_t, S, m), (lo), (hi)         \
    }
#define PS_CFG_RULE_F32(arr, flags, key, S, m, lo, hi)                                             \
    {                                                                                              \
        (arr), PS_CFG_NUM_F32, (flags), (key), PS_CFG_TYPED_OFF(float, S, m), (lo), (hi)           \
    }

/* An array member m[] of element type E with its uint32_t count n in S. */
#define PS_CFG_ARRAY(name, S, m, E, n)                                                             \
    {                                                                                              \
        (name),                                                                                    \
            _Generic(((S *)0)->m[0], E                                                             \
                     : offsetof(S, m)),                                                            \
            sizeof(E), PS_CFG_TYPED_OFF(uint32_t, S, n)                                            \
    }

#define PS_CFG_COUNT(a) (sizeof(a) / sizeof((a)[0]))

/* ---- per-call context --------------------------------------------------- */

typedef struct {
    const char *path;
    char *err;
    size_t err_len;
    ps_cfg_ytree_t tree;
    char *cyaml_log; /**< libcyaml's messages, one per line */
    size_t cyaml_log_used;
    cyaml_config_t cyaml;
    const ps_cfg_array_t *arrays; /**< the file kind's tables, for integer messages */
    const ps_cfg_rule_t *rules;
    size_t n_rules;
} ps_cfg_ctx_t;

/** @post c ready; err (if any) emptied; the rule tables are used to word
 *  integer errors with the field's range  @return 0 | -ENOMEM  @rt INIT */
int ps_cfg_ctx_open(ps_cfg_ctx_t *c, const char *path, char *err, size_t err_len,
                    const ps_cfg_array_t *arrays, const ps_cfg_rule_t *rules, size_t n_rules);

/** Frees the tree and log. Safe on a zeroed or half-opened context. @rt INIT */
void ps_cfg_ctx_close(ps_cfg_ctx_t *c);

/** Reads c->path once, builds the position tree, loads the buffer with
 *  libcyaml, then refuses what libcyaml accepts too leniently.
 *  @post on 0, *out_data holds libcyaml's data (free with cyaml_free and
 *        &c->cyaml); the tree is kept for later messages either way
 *  @return 0 | -ENOENT | -PS_ERR_CONFIG | -ENOMEM  @rt INIT */
int ps_cfg_load_file(ps_cfg_ctx_t *c, const cyaml_schema_value_t *schema, void **out_data);

/** Writes "FILE[:LINE]: [FIELD: ]text" (line 0 and an empty field are left
 *  out). @return -PS_ERR_CONFIG  @rt INIT */
int ps_cfg_fail_at(ps_cfg_ctx_t *c, size_t line, const char *field, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));

/** Same, with LINE the line of the field's value in the file.
 *  @return -PS_ERR_CONFIG  @rt INIT */
int ps_cfg_fail_field(ps_cfg_ctx_t *c, const char *field, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));

/** @return 1-based line of the value at a field path ("joints[2].bus"), 0 when
 *  the file has no such field  @rt INIT */
uint32_t ps_cfg_line_of(const ps_cfg_ctx_t *c, const char *field);

/** Checks every rule against the struct at base (arrays by their counts).
 *  NaN and infinities fail every range. @return 0 | -PS_ERR_CONFIG  @rt INIT */
int ps_cfg_check_ranges(ps_cfg_ctx_t *c, const void *base);

#endif /* PS_CONFIG_COMMON_H */
