/*
 * ps_mcap: MCAP writer and reader. Record layouts follow the MCAP
 * specification (version 0): every record is <opcode u8><length u64><body>,
 * integers little endian, strings <u32 length><bytes>, maps <u32 byte
 * length><entries>. CRC32 is zlib's (the IEEE polynomial MCAP uses).
 */
#include "ps_mcap.h"

#include <errno.h>
#include <lz4frame.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>
#include <zstd.h>

#include "ps_err.h"

enum {
    OP_HEADER = 0x01,
    OP_FOOTER = 0x02,
    OP_SCHEMA = 0x03,
    OP_CHANNEL = 0x04,
    OP_MESSAGE = 0x05,
    OP_CHUNK = 0x06,
    OP_MESSAGE_INDEX = 0x07,
    OP_CHUNK_INDEX = 0x08,
    OP_STATISTICS = 0x0B,
    OP_METADATA = 0x0C,
    OP_METADATA_INDEX = 0x0D,
    OP_SUMMARY_OFFSET = 0x0E,
    OP_DATA_END = 0x0F,
};

static const uint8_t MAGIC[PS_MCAP_MAGIC_LEN] = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};

#define REC_HEAD_LEN     9u /* opcode + u64 length */
#define DEFAULT_CHUNK    (512u * 1024u)
#define MESSAGE_HEAD_LEN (2u + 4u + 8u + 8u)
#define MAX_READ_REC_LEN (1ull << 31) /* a record this long is damage, not data */
#define MAX_UNCOMPRESSED (1ull << 31)

/* ---- a growable byte buffer ------------------------------------------------ */

typedef struct {
    uint8_t *p;
    size_t len, cap;
    bool is_oom;
} buf_t;

static bool buf_reserve(buf_t *b, size_t more)
{
    if (b->is_oom)
        return false;
    if (b->len + more <= b->cap)
        return true;
    size_t cap = b->cap ? b->cap : 256;
    while (cap < b->len + more)
        cap *= 2;
    uint8_t *p = realloc(b->p, cap);
    if (p == NULL) {
        b->is_oom = true;
        return false;
    }
    b->p = p;
    b->cap = cap;
    return true;
}

static void put(buf_t *b, const void *p, size_t n)
{
    if (n == 0 || !buf_reserve(b, n))
        return;
    memcpy(b->p + b->len, p, n);
    b->len += n;
}

static void put_u8(buf_t *b, uint8_t v)
{
    put(b, &v, 1);
}
static void put_u16(buf_t *b, uint16_t v)
{
    const uint8_t le[2] = {(uint8_t)v, (uint8_t)(v >> 8)};
    put(b, le, 2);
}
static void put_u32(buf_t *b, uint32_t v)
{
    const uint8_t le[4] = {(uint8_t)v, (uint8_t)(v >> 8), (uint8_t)(v >> 16), (uint8_t)(v >> 24)};
    put(b, le, 4);
}
static void put_u64(buf_t *b, uint64_t v)
{
    put_u32(b, (uint32_t)v);
    put_u32(b, (uint32_t)(v >> 32));
}
static void put_str(buf_t *b, const char *s)
{
    const size_t n = s ? strlen(s) : 0;
    put_u32(b, (uint32_t)n);
    put(b, s, n);
}

static void set_u32_at(uint8_t *p, uint32_t v)
{
    for (int i = 0; i < 4; i++)
        p[i] = (uint8_t)(v >> (8 * i));
}
static void set_u64_at(uint8_t *p, uint64_t v)
{
    for (int i = 0; i < 8; i++)
        p[i] = (uint8_t)(v >> (8 * i));
}

/* Opens a record: opcode and a length patched by rec_end. @return its start */
static size_t rec_begin(buf_t *b, uint8_t op)
{
    const size_t at = b->len;
    put_u8(b, op);
    put_u64(b, 0);
    return at;
}

static void rec_end(buf_t *b, size_t at)
{
    if (!b->is_oom)
        set_u64_at(b->p + at + 1, (uint64_t)(b->len - at - REC_HEAD_LEN));
}

/* A map<string,string>: <u32 byte length><key><value>... */
static void put_kv_map(buf_t *b, const ps_mcap_kv_t *kv, size_t n)
{
    const size_t at = b->len;
    put_u32(b, 0);
    for (size_t i = 0; i < n; i++) {
        put_str(b, kv[i].key);
        put_str(b, kv[i].value);
    }
    if (!b->is_oom)
        set_u32_at(b->p + at, (uint32_t)(b->len - at - 4));
}

/* ---- writer ----------------------------------------------------------------- */

const char *ps_mcap_compression_name(ps_mcap_compression_t c)
{
    return c == PS_MCAP_COMPRESS_ZSTD ? "zstd" : c == PS_MCAP_COMPRESS_LZ4 ? "lz4" : "";
}

int ps_mcap_parse_compression(const char *s, ps_mcap_compression_t *out)
{
    if (strcmp(s, "zstd") == 0)
        *out = PS_MCAP_COMPRESS_ZSTD;
    else if (strcmp(s, "lz4") == 0)
        *out = PS_MCAP_COMPRESS_LZ4;
    else if (strcmp(s, "none") == 0)
        *out = PS_MCAP_COMPRESS_NONE;
    else
        return -EINVAL;
    return 0;
}

int ps_mcap_error(const ps_mcap_writer_t *w)
{
    return w->err;
}

/* Every byte of the file goes through here; the data section's CRC runs
 * over everything before Data End. */
static int write_out(ps_mcap_writer_t *w, const void *p, size_t n, bool is_data)
{
    if (w->err != 0)
        return w->err;
    int rc = w->cfg.io.write(w->cfg.io_ctx, p, n);
    if (rc < 0) {
        w->err = rc;
        return rc;
    }
    if (is_data)
        w->crc = (uint32_t)crc32(w->crc, p, (uInt)n);
    w->pos += n;
    return 0;
}

int ps_mcap_open(ps_mcap_writer_t *w, const ps_mcap_cfg_t *cfg)
{
    if (w == NULL || cfg == NULL || cfg->io.write == NULL)
        return -EINVAL;
    memset(w, 0, sizeof(*w));
    w->cfg = *cfg;
    if (w->cfg.chunk_size == 0)
        w->cfg.chunk_size = DEFAULT_CHUNK;
    if (w->cfg.zstd_level == 0)
        w->cfg.zstd_level = 1;
    w->chunk_cap = w->cfg.chunk_size + 64u * 1024u;
    w->chunk = malloc(w->chunk_cap);
    w->zbuf_cap = ZSTD_compressBound(w->chunk_cap) + 64u * 1024u;
    const size_t lz4_cap = LZ4F_compressFrameBound(w->chunk_cap, NULL) + 64u * 1024u;
    if (lz4_cap > w->zbuf_cap)
        w->zbuf_cap = lz4_cap;
    w->zbuf = malloc(w->zbuf_cap);
    if (cfg->compression == PS_MCAP_COMPRESS_ZSTD)
        w->zctx = ZSTD_createCCtx();
    w->crc = (uint32_t)crc32(0L, Z_NULL, 0);
    w->is_open = true;
    if (w->chunk == NULL || w->zbuf == NULL ||
        (cfg->compression == PS_MCAP_COMPRESS_ZSTD && w->zctx == NULL)) {
        (void)ps_mcap_close(w); /* frees what was allocated */
        return -ENOMEM;
    }
    buf_t b = {0};
    put(&b, MAGIC, sizeof(MAGIC));
    size_t at = rec_begin(&b, OP_HEADER);
    put_str(&b, cfg->profile ? cfg->profile : "");
    put_str(&b, cfg->library ? cfg->library : "pushstep");
    rec_end(&b, at);
    int rc = b.is_oom ? -ENOMEM : write_out(w, b.p, b.len, true);
    free(b.p);
    return rc;
}

int ps_mcap_add_schema(ps_mcap_writer_t *w, const char *name, const char *encoding,
                       const void *data, size_t len)
{
    if (w->n_schemas >= PS_MCAP_MAX_SCHEMAS)
        return -ENOSPC;
    const uint16_t id = (uint16_t)(w->n_schemas + 1u);
    buf_t b = {0};
    size_t at = rec_begin(&b, OP_SCHEMA);
    put_u16(&b, id);
    put_str(&b, name);
    put_str(&b, encoding);
    put_u32(&b, (uint32_t)len);
    put(&b, data, len);
    rec_end(&b, at);
    if (b.is_oom) {
        free(b.p);
        return -ENOMEM;
    }
    w->schema_rec[id] = b.p;
    w->schema_len[id] = b.len;
    w->n_schemas = id;
    return id;
}

int ps_mcap_add_channel(ps_mcap_writer_t *w, uint16_t schema_id, const char *topic,
                        const char *message_encoding, const ps_mcap_kv_t *meta, size_t n_meta)
{
    if (w->n_channels >= PS_MCAP_MAX_WRITE_CHANNELS)
        return -ENOSPC;
    if (schema_id > w->n_schemas)
        return -EINVAL;
    const uint16_t id = w->n_channels;
    buf_t b = {0};
    size_t at = rec_begin(&b, OP_CHANNEL);
    put_u16(&b, id);
    put_u16(&b, schema_id);
    put_str(&b, topic);
    put_str(&b, message_encoding);
    put_kv_map(&b, meta, n_meta);
    rec_end(&b, at);
    if (b.is_oom) {
        free(b.p);
        return -ENOMEM;
    }
    w->channel_rec[id] = b.p;
    w->channel_len[id] = b.len;
    w->channel_schema[id] = schema_id;
    w->n_channels = (uint16_t)(id + 1u);
    return id;
}

static bool chunk_append(ps_mcap_writer_t *w, const void *p, size_t n)
{
    if (w->chunk_len + n > w->chunk_cap) {
        size_t cap = (w->chunk_len + n) * 2;
        uint8_t *q = realloc(w->chunk, cap);
        if (q == NULL)
            return false;
        w->chunk = q;
        w->chunk_cap = cap;
    }
    memcpy(w->chunk + w->chunk_len, p, n);
    w->chunk_len += n;
    return true;
}

static bool index_append(ps_mcap_writer_t *w, uint16_t ch, uint64_t t, uint64_t off)
{
    if (w->mi_len[ch] + 1u > w->mi_cap[ch]) {
        uint32_t cap = w->mi_cap[ch] ? w->mi_cap[ch] * 2u : 1024u;
        uint64_t *p = realloc(w->mi[ch], (size_t)cap * 2u * sizeof(uint64_t));
        if (p == NULL)
            return false;
        w->mi[ch] = p;
        w->mi_cap[ch] = cap;
    }
    w->mi[ch][2u * w->mi_len[ch]] = t;
    w->mi[ch][2u * w->mi_len[ch] + 1u] = off;
    w->mi_len[ch]++;
    return true;
}

static size_t compress_records(ps_mcap_writer_t *w, uint8_t *dst, size_t cap, int *out_rc)
{
    *out_rc = 0;
    if (w->cfg.compression == PS_MCAP_COMPRESS_ZSTD) {
        size_t n = ZSTD_compressCCtx(w->zctx, dst, cap, w->chunk, w->chunk_len, w->cfg.zstd_level);
        if (ZSTD_isError(n)) {
            *out_rc = -EIO;
            return 0;
        }
        return n;
    }
    if (w->cfg.compression == PS_MCAP_COMPRESS_LZ4) {
        size_t n = LZ4F_compressFrame(dst, cap, w->chunk, w->chunk_len, NULL);
        if (LZ4F_isError(n)) {
            *out_rc = -EIO;
            return 0;
        }
        return n;
    }
    if (w->chunk_len > cap) {
        *out_rc = -ENOSPC;
        return 0;
    }
    memcpy(dst, w->chunk, w->chunk_len);
    return w->chunk_len;
}

static void reset_chunk(ps_mcap_writer_t *w)
{
    w->chunk_len = 0;
    w->chunk_n_messages = 0;
    w->chunk_start_time = w->chunk_end_time = 0;
    for (uint16_t c = 0; c < w->n_channels; c++)
        w->mi_len[c] = 0;
}

/* The chunk record and its message indexes, built in one buffer: the
 * compressed records are written straight into it. */
static int build_chunk(ps_mcap_writer_t *w, buf_t *b, ps_mcap_chunk_entry_t *e)
{
    const char *comp = ps_mcap_compression_name(w->cfg.compression);
    const uint32_t crc = (uint32_t)crc32(crc32(0L, Z_NULL, 0), w->chunk, (uInt)w->chunk_len);
    size_t at = rec_begin(b, OP_CHUNK);
    put_u64(b, w->chunk_start_time);
    put_u64(b, w->chunk_end_time);
    put_u64(b, w->chunk_len);
    put_u32(b, crc);
    put_str(b, comp);
    const size_t size_at = b->len;
    put_u64(b, 0);
    const size_t bound = w->zbuf_cap > b->len ? w->zbuf_cap - b->len : 0;
    if (!buf_reserve(b, bound))
        return -ENOMEM;
    int rc = 0;
    const size_t n = compress_records(w, b->p + b->len, bound, &rc);
    if (rc < 0)
        return rc;
    b->len += n;
    set_u64_at(b->p + size_at, n);
    rec_end(b, at);
    *e = (ps_mcap_chunk_entry_t){
        .start_time = w->chunk_start_time,
        .end_time = w->chunk_end_time,
        .offset = w->pos,
        .length = b->len,
        .compressed_size = n,
        .uncompressed_size = w->chunk_len,
    };
    for (uint16_t c = 0; c < w->n_channels; c++) {
        if (w->mi_len[c] == 0)
            continue;
        e->index_offset[c] = w->pos + b->len;
        size_t mat = rec_begin(b, OP_MESSAGE_INDEX);
        put_u16(b, c);
        put_u32(b, w->mi_len[c] * 16u);
        for (uint32_t k = 0; k < 2u * w->mi_len[c]; k++)
            put_u64(b, w->mi[c][k]);
        rec_end(b, mat);
    }
    e->index_length = w->pos + b->len - e->offset - e->length;
    return b->is_oom ? -ENOMEM : 0;
}

static bool chunk_entry_append(ps_mcap_writer_t *w, const ps_mcap_chunk_entry_t *e)
{
    if (w->n_chunks + 1u > w->chunks_cap) {
        uint32_t cap = w->chunks_cap ? w->chunks_cap * 2u : 64u;
        ps_mcap_chunk_entry_t *p = realloc(w->chunks, (size_t)cap * sizeof(*p));
        if (p == NULL)
            return false;
        w->chunks = p;
        w->chunks_cap = cap;
    }
    w->chunks[w->n_chunks++] = *e;
    return true;
}

int ps_mcap_flush(ps_mcap_writer_t *w)
{
    if (!w->is_open)
        return -EINVAL;
    if (w->err != 0) {
        w->n_lost += w->chunk_n_messages;
        reset_chunk(w);
        return w->err;
    }
    if (w->chunk_len == 0)
        return 0;
    buf_t b = {.p = w->zbuf, .cap = w->zbuf_cap};
    ps_mcap_chunk_entry_t e;
    int rc = build_chunk(w, &b, &e);
    w->zbuf = b.p; /* it may have grown */
    w->zbuf_cap = b.cap;
    /* The chunk first: once it is in the file its messages count, whatever
     * happens to the index records behind it (a reader needs only the chunk). */
    if (rc == 0)
        rc = write_out(w, b.p, (size_t)e.length, true);
    if (rc < 0 || !chunk_entry_append(w, &e)) {
        if (w->err == 0)
            w->err = rc < 0 ? rc : -ENOMEM;
        w->n_lost += w->chunk_n_messages;
        reset_chunk(w);
        return w->err;
    }
    rc = write_out(w, b.p + e.length, b.len - (size_t)e.length, true);
    if (rc == 0 && w->cfg.is_sync_chunks && w->cfg.io.sync != NULL) {
        rc = w->cfg.io.sync(w->cfg.io_ctx);
        if (rc < 0)
            w->err = rc;
    }
    /* the chunk is in the file: its messages count */
    if (w->n_messages == 0 || e.start_time < w->start_time)
        w->start_time = e.start_time;
    if (e.end_time > w->end_time)
        w->end_time = e.end_time;
    w->n_messages += w->chunk_n_messages;
    for (uint16_t c = 0; c < w->n_channels; c++)
        w->channel_n_messages[c] += w->mi_len[c];
    reset_chunk(w);
    return rc;
}

int ps_mcap_write_message(ps_mcap_writer_t *w, uint16_t channel_id, uint32_t sequence,
                          uint64_t log_time_ns, uint64_t publish_time_ns, const void *data,
                          size_t len)
{
    if (!w->is_open || channel_id >= w->n_channels)
        return -EINVAL;
    if (w->err != 0) {
        w->n_lost++;
        return w->err;
    }
    if (!w->is_channel_written[channel_id]) {
        const uint16_t s = w->channel_schema[channel_id];
        if (s != 0 && !w->is_schema_written[s]) {
            if (!chunk_append(w, w->schema_rec[s], w->schema_len[s]))
                return -ENOMEM;
            w->is_schema_written[s] = true;
        }
        if (!chunk_append(w, w->channel_rec[channel_id], w->channel_len[channel_id]))
            return -ENOMEM;
        w->is_channel_written[channel_id] = true;
    }
    buf_t h = {0};
    uint8_t head[REC_HEAD_LEN + MESSAGE_HEAD_LEN];
    h.p = head;
    h.cap = sizeof(head);
    put_u8(&h, OP_MESSAGE);
    put_u64(&h, MESSAGE_HEAD_LEN + len);
    put_u16(&h, channel_id);
    put_u32(&h, sequence);
    put_u64(&h, log_time_ns);
    put_u64(&h, publish_time_ns);
    const uint64_t offset = w->chunk_len;
    if (!index_append(w, channel_id, log_time_ns, offset) || !chunk_append(w, head, h.len) ||
        !chunk_append(w, data, len))
        return -ENOMEM;
    if (w->chunk_n_messages == 0 || log_time_ns < w->chunk_start_time)
        w->chunk_start_time = log_time_ns;
    if (log_time_ns > w->chunk_end_time)
        w->chunk_end_time = log_time_ns;
    w->chunk_n_messages++;
    return w->chunk_len >= w->cfg.chunk_size ? ps_mcap_flush(w) : 0;
}

int ps_mcap_write_metadata(ps_mcap_writer_t *w, const char *name, const ps_mcap_kv_t *kv,
                           size_t n_kv)
{
    if (!w->is_open)
        return -EINVAL;
    if (w->err != 0)
        return w->err;
    buf_t b = {0};
    size_t at = rec_begin(&b, OP_METADATA);
    put_str(&b, name);
    put_kv_map(&b, kv, n_kv);
    rec_end(&b, at);
    if (w->n_metadata + 1u > w->metas_cap) {
        uint32_t cap = w->metas_cap ? w->metas_cap * 2u : 16u;
        ps_mcap_meta_entry_t *p = realloc(w->metas, (size_t)cap * sizeof(*p));
        if (p == NULL)
            b.is_oom = true;
        else {
            w->metas = p;
            w->metas_cap = cap;
        }
    }
    if (b.is_oom) {
        free(b.p);
        return -ENOMEM;
    }
    ps_mcap_meta_entry_t *e = &w->metas[w->n_metadata];
    e->offset = w->pos;
    e->length = b.len;
    snprintf(e->name, sizeof(e->name), "%s", name);
    int rc = write_out(w, b.p, b.len, true);
    free(b.p);
    if (rc == 0)
        w->n_metadata++;
    return rc;
}

typedef struct {
    uint8_t op;
    uint64_t start, len;
} group_t;

/* Summary section, Summary Offset section and Footer with magic, in b;
 * offsets count from base (the file position of b's first byte). */
static void build_summary(const ps_mcap_writer_t *w, buf_t *b, uint64_t base)
{
    group_t groups[5];
    unsigned n_groups = 0;
    size_t g0 = b->len;
    for (uint16_t s = 1; s <= w->n_schemas; s++)
        if (w->is_schema_written[s])
            put(b, w->schema_rec[s], w->schema_len[s]);
    if (b->len > g0)
        groups[n_groups++] = (group_t){OP_SCHEMA, base + g0, b->len - g0};
    g0 = b->len;
    uint16_t n_channels = 0, n_schemas = 0;
    for (uint16_t c = 0; c < w->n_channels; c++)
        if (w->is_channel_written[c]) {
            put(b, w->channel_rec[c], w->channel_len[c]);
            n_channels++;
        }
    for (uint16_t s = 1; s <= w->n_schemas; s++)
        n_schemas += w->is_schema_written[s];
    if (b->len > g0)
        groups[n_groups++] = (group_t){OP_CHANNEL, base + g0, b->len - g0};
    g0 = b->len;
    size_t at = rec_begin(b, OP_STATISTICS);
    put_u64(b, w->n_messages);
    put_u16(b, n_schemas);
    put_u32(b, n_channels);
    put_u32(b, 0); /* attachments */
    put_u32(b, w->n_metadata);
    put_u32(b, w->n_chunks);
    put_u64(b, w->start_time);
    put_u64(b, w->end_time);
    put_u32(b, (uint32_t)n_channels * 10u);
    for (uint16_t c = 0; c < w->n_channels; c++)
        if (w->is_channel_written[c]) {
            put_u16(b, c);
            put_u64(b, w->channel_n_messages[c]);
        }
    rec_end(b, at);
    groups[n_groups++] = (group_t){OP_STATISTICS, base + g0, b->len - g0};
    g0 = b->len;
    for (uint32_t i = 0; i < w->n_metadata; i++) {
        at = rec_begin(b, OP_METADATA_INDEX);
        put_u64(b, w->metas[i].offset);
        put_u64(b, w->metas[i].length);
        put_str(b, w->metas[i].name);
        rec_end(b, at);
    }
    if (b->len > g0)
        groups[n_groups++] = (group_t){OP_METADATA_INDEX, base + g0, b->len - g0};
    g0 = b->len;
    for (uint32_t i = 0; i < w->n_chunks; i++) {
        const ps_mcap_chunk_entry_t *e = &w->chunks[i];
        at = rec_begin(b, OP_CHUNK_INDEX);
        put_u64(b, e->start_time);
        put_u64(b, e->end_time);
        put_u64(b, e->offset);
        put_u64(b, e->length);
        uint32_t n_idx = 0;
        for (uint16_t c = 0; c < w->n_channels; c++)
            n_idx += e->index_offset[c] != 0;
        put_u32(b, n_idx * 10u);
        for (uint16_t c = 0; c < w->n_channels; c++)
            if (e->index_offset[c] != 0) {
                put_u16(b, c);
                put_u64(b, e->index_offset[c]);
            }
        put_u64(b, e->index_length);
        put_str(b, ps_mcap_compression_name(w->cfg.compression));
        put_u64(b, e->compressed_size);
        put_u64(b, e->uncompressed_size);
        rec_end(b, at);
    }
    if (b->len > g0)
        groups[n_groups++] = (group_t){OP_CHUNK_INDEX, base + g0, b->len - g0};
    const uint64_t summary_offset_start = base + b->len;
    for (unsigned i = 0; i < n_groups; i++) {
        at = rec_begin(b, OP_SUMMARY_OFFSET);
        put_u8(b, groups[i].op);
        put_u64(b, groups[i].start);
        put_u64(b, groups[i].len);
        rec_end(b, at);
    }
    put_u8(b, OP_FOOTER);
    put_u64(b, 8u + 8u + 4u); /* the length is part of what the CRC covers */
    put_u64(b, base);         /* summary_start: there is always Statistics */
    put_u64(b, summary_offset_start);
    if (!b->is_oom) {
        /* CRC of the summary up to the footer's summary_crc field */
        const uint32_t crc = (uint32_t)crc32(crc32(0L, Z_NULL, 0), b->p, (uInt)b->len);
        put_u32(b, crc);
    }
    put(b, MAGIC, sizeof(MAGIC));
}

int ps_mcap_close(ps_mcap_writer_t *w)
{
    if (w == NULL || !w->is_open)
        return 0;
    int rc = ps_mcap_flush(w);
    if (w->err == 0) {
        buf_t b = {0};
        size_t at = rec_begin(&b, OP_DATA_END);
        put_u32(&b, w->crc); /* over everything before Data End */
        rec_end(&b, at);
        const uint64_t base = w->pos + b.len;
        buf_t s = {0};
        build_summary(w, &s, base);
        put(&b, s.p, s.len);
        rc = b.is_oom || s.is_oom ? -ENOMEM : write_out(w, b.p, b.len, false);
        free(s.p);
        free(b.p);
        if (rc == 0 && w->cfg.io.sync != NULL && w->cfg.is_sync_chunks)
            rc = w->cfg.io.sync(w->cfg.io_ctx);
    }
    if (rc == 0)
        rc = w->err;
    free(w->chunk);
    free(w->zbuf);
    ZSTD_freeCCtx(w->zctx); /* NULL is fine */
    for (unsigned c = 0; c < PS_MCAP_MAX_CHANNELS; c++) {
        free(w->mi[c]);
        free(w->channel_rec[c]);
    }
    for (unsigned s = 0; s <= PS_MCAP_MAX_SCHEMAS; s++)
        free(w->schema_rec[s]);
    free(w->chunks);
    free(w->metas);
    const int err = w->err;
    const uint64_t pos = w->pos, n_messages = w->n_messages, n_lost = w->n_lost;
    uint64_t counts[PS_MCAP_MAX_CHANNELS];
    memcpy(counts, w->channel_n_messages, sizeof(counts));
    const uint32_t n_chunks = w->n_chunks, n_metadata = w->n_metadata;
    const uint16_t n_channels = w->n_channels;
    memset(w, 0, sizeof(*w));
    /* what happened stays readable after close */
    w->err = err;
    w->pos = pos;
    w->n_messages = n_messages;
    w->n_lost = n_lost;
    memcpy(w->channel_n_messages, counts, sizeof(counts));
    w->n_chunks = n_chunks;
    w->n_metadata = n_metadata;
    w->n_channels = n_channels;
    return rc;
}

/* ---- reader ------------------------------------------------------------------ */

typedef struct {
    const uint8_t *p;
    size_t len, pos;
    bool is_bad;
} rd_t;

static uint64_t get_le(rd_t *r, unsigned n)
{
    if (r->is_bad || n > r->len - r->pos) {
        r->is_bad = true;
        return 0;
    }
    uint64_t v = 0;
    for (unsigned i = 0; i < n; i++)
        v |= (uint64_t)r->p[r->pos + i] << (8 * i);
    r->pos += n;
    return v;
}

/* A string copied NUL-terminated into out (truncated to cap). */
static void get_str(rd_t *r, char *out, size_t cap)
{
    const uint64_t n = get_le(r, 4);
    if (r->is_bad || n > r->len - r->pos) {
        r->is_bad = true;
        out[0] = '\0';
        return;
    }
    const size_t k = n < cap - 1 ? (size_t)n : cap - 1;
    memcpy(out, r->p + r->pos, k);
    out[k] = '\0';
    r->pos += (size_t)n;
}

typedef struct {
    const ps_mcap_read_ops_t *ops;
    void *ctx;
    ps_mcap_read_info_t *info;
    uint8_t seen_schema[65536 / 8];
    uint8_t seen_channel[65536 / 8];
    bool is_summary; /* after Data End: schema and channel copies */
    char *s1, *s2;   /* scratch strings */
} rctx_t;

#define STR_CAP 4096u

static bool test_and_set(uint8_t *bits, uint16_t id)
{
    const bool was = (bits[id / 8] >> (id % 8)) & 1u;
    bits[id / 8] |= (uint8_t)(1u << (id % 8));
    return was;
}

static int on_schema_rec(rctx_t *c, rd_t *r)
{
    const uint16_t id = (uint16_t)get_le(r, 2);
    get_str(r, c->s1, STR_CAP);
    get_str(r, c->s2, STR_CAP);
    const uint64_t n = get_le(r, 4);
    if (r->is_bad || n > r->len - r->pos)
        return -EPROTO;
    const uint8_t *data = r->p + r->pos;
    r->pos += (size_t)n;
    if (id == 0 || test_and_set(c->seen_schema, id) || c->ops->on_schema == NULL)
        return 0;
    return c->ops->on_schema(c->ctx, id, c->s1, c->s2, data, (size_t)n);
}

static int on_channel_rec(rctx_t *c, rd_t *r)
{
    const uint16_t id = (uint16_t)get_le(r, 2);
    const uint16_t schema = (uint16_t)get_le(r, 2);
    get_str(r, c->s1, STR_CAP);
    get_str(r, c->s2, STR_CAP);
    if (r->is_bad)
        return -EPROTO;
    if (test_and_set(c->seen_channel, id) || c->ops->on_channel == NULL)
        return 0;
    return c->ops->on_channel(c->ctx, id, schema, c->s1, c->s2);
}

static int on_message_rec(rctx_t *c, rd_t *r)
{
    const uint16_t ch = (uint16_t)get_le(r, 2);
    const uint32_t seq = (uint32_t)get_le(r, 4);
    const uint64_t t = get_le(r, 8);
    (void)get_le(r, 8); /* publish time */
    if (r->is_bad)
        return -EPROTO;
    c->info->n_messages++;
    if (c->ops->on_message == NULL)
        return 0;
    return c->ops->on_message(c->ctx, ch, seq, t, r->p + r->pos, r->len - r->pos);
}

#define MAX_KV 64u

static int on_metadata_rec(rctx_t *c, rd_t *r)
{
    char name[256];
    get_str(r, name, sizeof(name));
    const uint64_t map_len = get_le(r, 4);
    if (r->is_bad || map_len > r->len - r->pos)
        return -EPROTO;
    rd_t m = {.p = r->p + r->pos, .len = (size_t)map_len};
    ps_mcap_kv_t kv[MAX_KV];
    char *store = malloc((size_t)map_len + 2u * MAX_KV + 1u);
    if (store == NULL)
        return -ENOMEM;
    size_t used = 0, n = 0;
    while (m.pos < m.len && n < MAX_KV && !m.is_bad) {
        for (int k = 0; k < 2; k++) {
            const uint64_t len = get_le(&m, 4);
            if (m.is_bad || len > m.len - m.pos) {
                m.is_bad = true;
                break;
            }
            memcpy(store + used, m.p + m.pos, (size_t)len);
            store[used + len] = '\0';
            if (k == 0)
                kv[n].key = store + used;
            else
                kv[n].value = store + used;
            used += (size_t)len + 1u;
            m.pos += (size_t)len;
        }
        n += !m.is_bad;
    }
    c->info->n_metadata++;
    int rc = m.is_bad                      ? -EPROTO
             : c->ops->on_metadata != NULL ? c->ops->on_metadata(c->ctx, name, kv, n)
                                           : 0;
    free(store);
    return rc;
}

static int decompress(const char *comp, const uint8_t *src, size_t n, uint8_t *dst, size_t size)
{
    if (comp[0] == '\0') {
        if (n != size)
            return -EPROTO;
        memcpy(dst, src, n);
        return 0;
    }
    if (strcmp(comp, "zstd") == 0) {
        size_t got = ZSTD_decompress(dst, size, src, n);
        return ZSTD_isError(got) || got != size ? -EPROTO : 0;
    }
    if (strcmp(comp, "lz4") == 0) {
        LZ4F_dctx *d = NULL;
        if (LZ4F_isError(LZ4F_createDecompressionContext(&d, LZ4F_VERSION)))
            return -ENOMEM;
        size_t out_pos = 0, in_pos = 0;
        int rc = -EPROTO;
        for (;;) {
            size_t out_n = size - out_pos, in_n = n - in_pos;
            size_t hint = LZ4F_decompress(d, dst + out_pos, &out_n, src + in_pos, &in_n, NULL);
            if (LZ4F_isError(hint))
                break;
            out_pos += out_n;
            in_pos += in_n;
            if (hint == 0) {
                rc = out_pos == size ? 0 : -EPROTO;
                break;
            }
            if (in_n == 0 && out_n == 0)
                break; /* no progress: truncated frame */
        }
        LZ4F_freeDecompressionContext(d);
        return rc;
    }
    return -ENOTSUP;
}

static int dispatch(rctx_t *c, uint8_t op, rd_t *r, char *why, size_t why_len);

static int on_chunk_rec(rctx_t *c, rd_t *r, char *why, size_t why_len)
{
    (void)get_le(r, 8);
    (void)get_le(r, 8);
    const uint64_t size = get_le(r, 8);
    const uint32_t crc = (uint32_t)get_le(r, 4);
    char comp[16];
    get_str(r, comp, sizeof(comp));
    const uint64_t n = get_le(r, 8);
    if (r->is_bad || n > r->len - r->pos || size > MAX_UNCOMPRESSED) {
        snprintf(why, why_len, "malformed chunk");
        return -EPROTO;
    }
    uint8_t *buf = malloc(size > 0 ? (size_t)size : 1u);
    if (buf == NULL)
        return -ENOMEM;
    int rc = decompress(comp, r->p + r->pos, (size_t)n, buf, (size_t)size);
    if (rc < 0)
        snprintf(why, why_len, "chunk does not decompress (%s)", comp[0] ? comp : "stored");
    else if (crc != 0 && (uint32_t)crc32(crc32(0L, Z_NULL, 0), buf, (uInt)size) != crc) {
        snprintf(why, why_len, "chunk CRC mismatch");
        rc = -EPROTO;
    }
    rd_t in = {.p = buf, .len = (size_t)size};
    while (rc == 0 && in.pos < in.len) {
        const uint8_t op = (uint8_t)get_le(&in, 1);
        const uint64_t len = get_le(&in, 8);
        if (in.is_bad || len > in.len - in.pos) {
            snprintf(why, why_len, "record inside a chunk runs past its end");
            rc = -EPROTO;
            break;
        }
        rd_t body = {.p = in.p + in.pos, .len = (size_t)len};
        in.pos += (size_t)len;
        rc = dispatch(c, op, &body, why, why_len);
    }
    free(buf);
    if (rc == 0)
        c->info->n_chunks++;
    return rc;
}

static int on_statistics_rec(rctx_t *c, rd_t *r)
{
    ps_mcap_read_info_t *i = c->info;
    i->stat_n_messages = get_le(r, 8);
    i->stat_n_schemas = (uint16_t)get_le(r, 2);
    i->stat_n_channels = (uint32_t)get_le(r, 4);
    (void)get_le(r, 4);
    (void)get_le(r, 4);
    i->stat_n_chunks = (uint32_t)get_le(r, 4);
    i->has_statistics = !r->is_bad;
    return r->is_bad ? -EPROTO : 0;
}

static int dispatch(rctx_t *c, uint8_t op, rd_t *r, char *why, size_t why_len)
{
    switch (op) {
    case OP_SCHEMA:
        return on_schema_rec(c, r);
    case OP_CHANNEL:
        return on_channel_rec(c, r);
    case OP_MESSAGE:
        return on_message_rec(c, r);
    case OP_CHUNK:
        return on_chunk_rec(c, r, why, why_len);
    case OP_METADATA:
        return on_metadata_rec(c, r);
    case OP_STATISTICS:
        return on_statistics_rec(c, r);
    case OP_DATA_END:
        c->info->has_data_end = true;
        return 0;
    default:
        return 0; /* indexes, summary offsets, unknown records: not needed to read */
    }
}

/* Maps the file read-only: a truncated file needs no seeking, and a long
 * recording costs no copy. */
static int map_file(const char *path, uint8_t **out, size_t *out_len, char *err, size_t err_len)
{
    const int fd = open(path, O_RDONLY | O_CLOEXEC);
    if (fd < 0) {
        const int e = errno;
        ps_err_format(err, err_len, "%s: %s", path, strerror(e));
        return -e;
    }
    struct stat st;
    if (fstat(fd, &st) < 0 || !S_ISREG(st.st_mode)) {
        ps_err_format(err, err_len, "%s: not a regular file", path);
        close(fd);
        return -EINVAL;
    }
    *out_len = (size_t)st.st_size;
    *out = NULL;
    if (st.st_size > 0) {
        void *p = mmap(NULL, (size_t)st.st_size, PROT_READ, MAP_PRIVATE, fd, 0);
        if (p == MAP_FAILED) {
            const int e = errno;
            ps_err_format(err, err_len, "%s: cannot map: %s", path, strerror(e));
            close(fd);
            return -e;
        }
        *out = p;
    }
    close(fd); /* the mapping stays */
    return 0;
}

int ps_mcap_read_file(const char *path, const ps_mcap_read_ops_t *ops, void *ctx,
                      ps_mcap_read_info_t *out, char *err, size_t err_len)
{
    memset(out, 0, sizeof(*out));
    uint8_t *file = NULL;
    size_t len = 0;
    int rc = map_file(path, &file, &len, err, err_len);
    if (rc < 0)
        return rc;
    out->file_bytes = len;
    if (len < PS_MCAP_MAGIC_LEN || memcmp(file, MAGIC, PS_MCAP_MAGIC_LEN) != 0) {
        ps_err_format(err, err_len, "%s: not an MCAP file (no magic)", path);
        if (file != NULL)
            munmap(file, len);
        return -EPROTO;
    }
    rctx_t *c = calloc(1, sizeof(*c));
    char *strs = malloc(2u * STR_CAP);
    if (c == NULL || strs == NULL) {
        free(c);
        free(strs);
        munmap(file, len);
        return -ENOMEM;
    }
    *c = (rctx_t){.ops = ops, .ctx = ctx, .info = out, .s1 = strs, .s2 = strs + STR_CAP};
    size_t pos = PS_MCAP_MAGIC_LEN;
    out->valid_bytes = pos;
    bool has_header = false;
    char why[120] = "";
    rc = 0;
    while (rc == 0) {
        if (len - pos < REC_HEAD_LEN) {
            snprintf(why, sizeof(why), "%s",
                     len == pos ? "file ends without a footer" : "incomplete record header");
            break;
        }
        const uint8_t op = file[pos];
        rd_t h = {.p = file + pos + 1, .len = 8};
        const uint64_t rlen = get_le(&h, 8);
        if (rlen > len - pos - REC_HEAD_LEN || rlen > MAX_READ_REC_LEN) {
            snprintf(why, sizeof(why), "record (opcode 0x%02x, %llu bytes) runs past the end", op,
                     (unsigned long long)rlen);
            break;
        }
        rd_t body = {.p = file + pos + REC_HEAD_LEN, .len = (size_t)rlen};
        if (!has_header && op != OP_HEADER) {
            ps_err_format(err, err_len, "%s: first record is not a Header", path);
            rc = -EPROTO;
            break;
        }
        if (op == OP_HEADER) {
            has_header = true;
        } else if (op == OP_FOOTER) {
            const size_t end = pos + REC_HEAD_LEN + (size_t)rlen;
            if (len - end >= PS_MCAP_MAGIC_LEN &&
                memcmp(file + end, MAGIC, PS_MCAP_MAGIC_LEN) == 0) {
                out->has_footer = true;
                out->valid_bytes = end + PS_MCAP_MAGIC_LEN;
            } else {
                snprintf(why, sizeof(why), "footer without closing magic");
            }
            break;
        } else if ((op == OP_SCHEMA || op == OP_CHANNEL) && out->has_data_end) {
            /* summary copies of what the data section already gave */
        } else {
            const int drc = dispatch(c, op, &body, why, sizeof(why));
            if (drc == -EPROTO || drc == -ENOTSUP) {
                if (why[0] == '\0')
                    snprintf(why, sizeof(why), "malformed record (opcode 0x%02x)", op);
                break; /* damage: stop here, what came before stands */
            }
            if (drc < 0) {
                ps_err_format(err, err_len, "%s: reading stopped: %s", path, ps_strerror(drc));
                rc = drc;
                break;
            }
        }
        pos += REC_HEAD_LEN + (size_t)rlen;
        out->valid_bytes = pos;
    }
    if (rc == 0 && !out->has_footer)
        snprintf(out->stop_reason, sizeof(out->stop_reason), "at byte %llu of %llu: %s",
                 (unsigned long long)out->valid_bytes, (unsigned long long)len, why);
    free(strs);
    free(c);
    munmap(file, len);
    return rc;
}
