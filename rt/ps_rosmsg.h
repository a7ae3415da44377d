/*
 * ps_rosmsg: flat ROS 2 message definitions (.msg text, the MCAP schema
 * encoding "ros2msg") and their CDR encoding (the MCAP message encoding
 * "cdr"), both produced from one static field table so that the schema a
 * file carries and the bytes of its messages cannot disagree; and the
 * reverse, for `pushstep log`: a flat .msg text parsed back into fields and
 * a CDR message decoded field by field.
 *
 * Encoding (OMG CDR version 1 as ROS 2 uses it, @foxglove/cdr's CDR_LE): a
 * 4-byte encapsulation header 00 01 00 00 (little endian, plain CDR), then
 * the fields in order, each primitive aligned to its own size (8-byte types
 * to 8) counted from the end of the header; a sequence (`T[] name`) is a
 * uint32 element count, then the elements; a fixed array (`T[N] name`) its
 * N elements; a string a uint32 length counting the terminating NUL, the
 * bytes, the NUL. bool is one byte 0/1.
 *
 * Supported here: bool, uint8, int8, uint16, int16, uint32, int32, uint64,
 * int64, float32, float64, string, each as a scalar, fixed array or
 * unbounded sequence. No nested message types (our schemas are flat; a
 * nested schema is refused by the parser with -ENOTSUP).
 *
 * Threads: any; nothing shared. Allocation: none (caller's buffers).
 */
#ifndef PS_ROSMSG_H
#define PS_ROSMSG_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

typedef enum {
    PS_ROSMSG_BOOL = 0,
    PS_ROSMSG_UINT8,
    PS_ROSMSG_INT8,
    PS_ROSMSG_UINT16,
    PS_ROSMSG_INT16,
    PS_ROSMSG_UINT32,
    PS_ROSMSG_INT32,
    PS_ROSMSG_UINT64,
    PS_ROSMSG_INT64,
    PS_ROSMSG_FLOAT32,
    PS_ROSMSG_FLOAT64,
    PS_ROSMSG_STRING, /**< source: a NUL-terminated char array of `count` bytes */
    PS_ROSMSG_TYPE_COUNT
} ps_rosmsg_type_t;

typedef enum {
    PS_ROSMSG_SCALAR = 0,
    PS_ROSMSG_ARRAY,    /**< fixed length `count` */
    PS_ROSMSG_SEQUENCE, /**< length from the encoder's counts[count_idx], at most `count` */
} ps_rosmsg_kind_t;

/** One field of a message, read from a source struct at `offset`. Arrays and
 *  sequences are contiguous elements of the type's C size. */
typedef struct {
    const char *name;
    uint8_t type;      /**< ps_rosmsg_type_t */
    uint8_t kind;      /**< ps_rosmsg_kind_t */
    uint8_t count_idx; /**< SEQUENCE: which runtime count */
    uint16_t count;    /**< ARRAY: length; SEQUENCE: capacity; STRING: buffer size */
    size_t offset;     /**< byte offset in the source struct */
    const char *doc;   /**< comment written after the field in the .msg text; may be NULL */
} ps_rosmsg_field_t;

typedef struct {
    const char *name; /**< "pushstep_msgs/msg/Joints" */
    const ps_rosmsg_field_t *fields;
    uint32_t n_fields;
} ps_rosmsg_def_t;

/** Bytes of the CDR encapsulation header. */
#define PS_ROSMSG_HEADER_LEN 4u

/** @return the .msg name of a type ("float32")  @rt RT-SAFE */
const char *ps_rosmsg_type_name(ps_rosmsg_type_t t);

/** @return C size of one element (STRING: 1)  @rt RT-SAFE */
size_t ps_rosmsg_type_size(ps_rosmsg_type_t t);

/** Write the .msg text of def into buf.
 *  @return length without the NUL | -ENOSPC (buf too small) | -EINVAL
 *  (a field with an unknown type or kind)  @rt NON-RT, any thread */
int ps_rosmsg_schema_text(const ps_rosmsg_def_t *def, char *buf, size_t cap);

/** CDR-encode the fields of def read from src. counts[i]: length of the
 *  sequences with count_idx i (clamped to each field's capacity).
 *  @return bytes written | -ENOSPC  @rt RT-SAFE O(fields), any thread */
int ps_rosmsg_encode(const ps_rosmsg_def_t *def, const void *src, const uint32_t *counts,
                     uint8_t *buf, size_t cap);

/* ---- reading back ------------------------------------------------------ */

#define PS_ROSMSG_MAX_FIELDS 128u
#define PS_ROSMSG_NAME_LEN   48u

/** A field as parsed from .msg text. */
typedef struct {
    char name[PS_ROSMSG_NAME_LEN];
    uint8_t type; /**< ps_rosmsg_type_t */
    uint8_t kind; /**< ps_rosmsg_kind_t; SEQUENCE also for bounded `T[<=N]` */
    uint32_t count;
} ps_rosmsg_pfield_t;

typedef struct {
    ps_rosmsg_pfield_t fields[PS_ROSMSG_MAX_FIELDS];
    uint32_t n_fields;
} ps_rosmsg_parsed_t;

/** Parse flat .msg text: one `TYPE NAME` per line, TYPE with [], [N] or
 *  [<=N]; comments (#), blank lines and constants (NAME=VALUE) skipped;
 *  parsing stops at a "====" separator line (definitions of nested types).
 *  @return 0 | -ENOTSUP (a type that is not a primitive or string: nested)
 *  | -EINVAL (a malformed line) | -E2BIG (more than PS_ROSMSG_MAX_FIELDS);
 *  err names the line  @rt NON-RT */
int ps_rosmsg_parse(const char *text, size_t len, ps_rosmsg_parsed_t *out, char *err,
                    size_t err_len);

/** One decoded value: numbers as double (64-bit integers may lose
 *  precision beyond 2^53), strings as text. */
typedef struct {
    uint32_t field_idx;
    uint32_t elem_idx; /**< index in an array or sequence; 0 for a scalar */
    bool is_string;
    double value;
    const char *text; /**< is_string: points into a scratch buffer, valid during the call */
    uint32_t text_len;
} ps_rosmsg_value_t;

/** Decode a CDR message against a parsed definition, calling on_value for
 *  every element in order.
 *  @return 0 | -EPROTO (header not CDR little endian, or the message ends
 *  early, or a sequence longer than the message)  @rt NON-RT */
int ps_rosmsg_decode(const ps_rosmsg_parsed_t *def, const uint8_t *msg, size_t len,
                     void (*on_value)(void *ctx, const ps_rosmsg_value_t *v), void *ctx);

#endif /* PS_ROSMSG_H */
