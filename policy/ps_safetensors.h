/*
 * ps_safetensors: a checked reader of the safetensors format
 * (huggingface.co/docs/safetensors): an 8-byte little-endian header length
 * N, N bytes of JSON (parsed with cJSON), then the raw tensor bytes. The
 * header maps each tensor name to {"dtype", "shape", "data_offsets":
 * [begin, end)} relative to the byte after the header, and may hold a
 * "__metadata__" object of string values.
 *
 * Everything is checked before anything is used, and a refusal names what
 * is wrong: the file shorter than 8 bytes or than its header, a header
 * length beyond PS_ST_MAX_HEADER or not JSON, a tensor entry without dtype,
 * shape or offsets or with extra keys, a dtype other than F32 (the only one
 * the engine runs; "F16" etc. are named), a shape whose element count does
 * not match end - begin, offsets outside the data section or overlapping
 * another tensor, bytes of the data section no tensor covers, metadata
 * values that are not strings, and (ps_st_copy_f32) NaN or infinite values.
 *
 * Threads: INIT only. Allocation: load reads the file into one malloc'd
 * buffer owned by the struct (ps_st_free releases it).
 */
#ifndef PS_SAFETENSORS_H
#define PS_SAFETENSORS_H

#include <stddef.h>
#include <stdint.h>

#define PS_ST_MAX_HEADER  (1u << 20) /**< header bytes we accept */
#define PS_ST_MAX_TENSORS 64u
#define PS_ST_MAX_DIMS    4u
#define PS_ST_NAME_LEN    64u
#define PS_ST_MAX_FILE    (256u << 20)
#define PS_ST_MAX_META    16u

typedef struct {
    char name[PS_ST_NAME_LEN];
    uint32_t n_dims;
    uint64_t shape[PS_ST_MAX_DIMS];
    uint64_t n_elems;
    uint64_t begin, end; /**< byte offsets in the data section */
} ps_st_tensor_t;

typedef struct {
    uint8_t *file; /**< whole file (owned) */
    size_t file_len;
    size_t data_off; /**< 8 + header length */
    uint32_t n_tensors;
    ps_st_tensor_t tensors[PS_ST_MAX_TENSORS];
    uint32_t n_meta;
    char meta_key[PS_ST_MAX_META][PS_ST_NAME_LEN];
    char *meta_val[PS_ST_MAX_META]; /**< owned */
} ps_st_file_t;

/** Read and check a safetensors file.
 *  @post on success *st owns the file's bytes; err holds "PATH: problem" on
 *        failure (st is then empty, nothing to free)
 *  @return 0 | -ENOENT cannot open | -EIO read error | -EINVAL malformed (err
 *          says what) | -ENOTSUP a dtype other than F32 | -ENOMEM  @rt INIT */
int ps_st_load(ps_st_file_t *st, const char *path, char *err, size_t err_len);

/** Same checks on bytes in memory (copied).  @rt INIT */
int ps_st_parse(ps_st_file_t *st, const uint8_t *bytes, size_t len, char *err, size_t err_len);

/** @return the tensor of that name, NULL if absent */
const ps_st_tensor_t *ps_st_find(const ps_st_file_t *st, const char *name);

/** Copy a tensor's values into out (n_max floats), checking each is finite.
 *  @return elements copied | -ENOSPC out too small | -ERANGE a NaN or
 *          infinite value (err names the tensor and the index)  @rt INIT */
int ps_st_copy_f32(const ps_st_file_t *st, const ps_st_tensor_t *t, float *out, size_t n_max,
                   char *err, size_t err_len);

/** The string value of metadata key, NULL if absent (valid until ps_st_free).
 *  @rt INIT */
const char *ps_st_metadata(const ps_st_file_t *st, const char *key);

/** Release the buffers; safe on a zeroed struct and twice. */
void ps_st_free(ps_st_file_t *st);

#endif /* PS_SAFETENSORS_H */
