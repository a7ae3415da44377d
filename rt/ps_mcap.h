/*
 * ps_mcap: an MCAP file writer and reader (MCAP format version 0, the
 * specification at mcap.dev/spec; what Foxglove, PlotJuggler and ROS 2 bag
 * storage read).
 *
 * Writer: magic, Header, then the data section as Chunks (zstd or lz4 frame
 * compressed, or stored) each followed by its Message Index records; a chunk
 * is closed when its records reach chunk_size bytes or on ps_mcap_flush.
 * Schemas and channels go into the first chunk that uses them. Metadata
 * records go between chunks. ps_mcap_close writes Data End (with the data
 * section's CRC32), the summary section (Schema and Channel copies,
 * Statistics with per-channel message counts, Metadata Index, Chunk Index),
 * Summary Offset records, the Footer (with the summary's CRC32) and the
 * closing magic. Every chunk carries the CRC32 of its uncompressed records.
 *
 * Power cut: a chunk reaches the file in one write of the chunk and its
 * message indexes, then (is_sync_chunks) fdatasync; a file cut anywhere is
 * readable with every message of the chunks before the cut (the spec's
 * records are length-prefixed, so a reader stops at the incomplete one).
 *
 * Errors: the first failed write or sync puts the writer in a failed state
 * (ps_mcap_error): from then on nothing more is written, messages are
 * counted in n_lost (those of the chunk that failed, and every later one),
 * and calls return that error. The file keeps what was written before.
 *
 * Reader: ps_mcap_read_file walks a file from the start (no index needed,
 * so a truncated file works), decompresses chunks, checks their CRCs, and
 * calls back for schemas, channels, messages and metadata; it stops at the
 * footer or at the first record that is incomplete or damaged and says
 * where (ps_mcap_read_info_t).
 *
 * Threads: one writer per thread, not thread-safe. Allocation: NON-RT; the
 * writer allocates its buffers at open and grows its index lists as the
 * file grows (one entry per chunk and per metadata record).
 * Compression: libzstd and liblz4 (lz4frame), Debian's.
 */
#ifndef PS_MCAP_H
#define PS_MCAP_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#define PS_MCAP_MAX_SCHEMAS  64u
#define PS_MCAP_MAX_CHANNELS 64u /**< the reader's; a file of any writer */
/** Channels one writer defines. Every chunk's index entry keeps a message
 *  index offset per channel until close (the summary needs them all), so
 *  this bounds what a long recording holds per chunk: 184 bytes at 16. */
#define PS_MCAP_MAX_WRITE_CHANNELS 16u
#define PS_MCAP_MAGIC_LEN          8u

typedef enum {
    PS_MCAP_COMPRESS_NONE = 0,
    PS_MCAP_COMPRESS_ZSTD,
    PS_MCAP_COMPRESS_LZ4,
} ps_mcap_compression_t;

/** Where the bytes go. */
typedef struct {
    /** Write all len bytes. @return 0 | -errno (ENOSPC, EIO, EFBIG...) */
    int (*write)(void *ctx, const void *buf, size_t len);
    /** Make what was written durable (fdatasync). NULL: nothing to do.
     *  @return 0 | -errno */
    int (*sync)(void *ctx);
} ps_mcap_io_t;

typedef struct {
    ps_mcap_io_t io;
    void *io_ctx;
    ps_mcap_compression_t compression;
    int zstd_level;      /**< 0: 1 (fastest) */
    size_t chunk_size;   /**< close a chunk at this many record bytes; 0: 512 KiB */
    bool is_sync_chunks; /**< io.sync after every chunk */
    const char *profile; /**< Header profile; "ros2" for ros2msg/cdr channels */
    const char *library; /**< Header library */
} ps_mcap_cfg_t;

typedef struct {
    const char *key;
    const char *value;
} ps_mcap_kv_t;

typedef struct {
    uint64_t start_time, end_time; /**< message log times; 0, 0 when empty */
    uint64_t offset, length;       /**< of the chunk record */
    uint64_t index_length;         /**< message index records after it */
    uint64_t compressed_size, uncompressed_size;
    uint64_t index_offset[PS_MCAP_MAX_WRITE_CHANNELS]; /**< 0: no message on that channel */
} ps_mcap_chunk_entry_t;

typedef struct {
    uint64_t offset, length;
    char name[64];
} ps_mcap_meta_entry_t;

typedef struct {
    ps_mcap_cfg_t cfg;
    int err;        /**< 0, or the first write/sync error (read-only) */
    uint64_t pos;   /**< bytes written to the file (read-only) */
    uint32_t crc;   /**< running CRC32 of the data section */
    uint8_t *chunk; /**< uncompressed records of the open chunk */
    size_t chunk_len, chunk_cap;
    uint8_t *zbuf; /**< compressed chunk record + message indexes */
    size_t zbuf_cap;
    void *zctx; /**< ZSTD_CCtx */
    uint64_t chunk_start_time, chunk_end_time;
    uint32_t chunk_n_messages;
    /* message index of the open chunk, per channel: (log_time, offset) pairs */
    uint64_t *mi[PS_MCAP_MAX_CHANNELS];
    uint32_t mi_len[PS_MCAP_MAX_CHANNELS], mi_cap[PS_MCAP_MAX_CHANNELS];
    /* schemas and channels as serialized records (for chunks and the summary) */
    uint8_t *schema_rec[PS_MCAP_MAX_SCHEMAS + 1]; /**< by id; [0] unused */
    size_t schema_len[PS_MCAP_MAX_SCHEMAS + 1];
    bool is_schema_written[PS_MCAP_MAX_SCHEMAS + 1];
    uint16_t n_schemas;
    uint8_t *channel_rec[PS_MCAP_MAX_CHANNELS];
    size_t channel_len[PS_MCAP_MAX_CHANNELS];
    uint16_t channel_schema[PS_MCAP_MAX_CHANNELS];
    bool is_channel_written[PS_MCAP_MAX_CHANNELS];
    uint16_t n_channels;
    /* statistics */
    uint64_t n_messages; /**< messages written to the file (read-only) */
    uint64_t n_lost;     /**< messages that never reached the file (read-only) */
    uint64_t channel_n_messages[PS_MCAP_MAX_CHANNELS]; /**< in the file (read-only) */
    uint64_t start_time, end_time;
    uint32_t n_metadata;
    ps_mcap_chunk_entry_t *chunks;
    uint32_t n_chunks, chunks_cap;
    ps_mcap_meta_entry_t *metas;
    uint32_t metas_cap;
    bool is_open;
} ps_mcap_writer_t;

/** Allocate buffers, write magic and Header.
 *  @pre w zeroed or deinited, cfg->io.write set
 *  @return 0 | -ENOMEM | -EINVAL | the io error (the writer is then failed:
 *  still call ps_mcap_close)  @rt NON-RT */
int ps_mcap_open(ps_mcap_writer_t *w, const ps_mcap_cfg_t *cfg);

/** Register a schema (written with the first channel that uses it).
 *  @return id >= 1 | -ENOSPC (PS_MCAP_MAX_SCHEMAS) | -ENOMEM  @rt NON-RT */
int ps_mcap_add_schema(ps_mcap_writer_t *w, const char *name, const char *encoding,
                       const void *data, size_t len);

/** Register a channel (written before its first message).
 *  @return id >= 0 | -ENOSPC (PS_MCAP_MAX_WRITE_CHANNELS) | -EINVAL (unknown schema)
 *  | -ENOMEM  @rt NON-RT */
int ps_mcap_add_channel(ps_mcap_writer_t *w, uint16_t schema_id, const char *topic,
                        const char *message_encoding, const ps_mcap_kv_t *meta, size_t n_meta);

/** Append one message to the open chunk (closing it first when full).
 *  @units log_time_ns, publish_time_ns: the file's clock
 *  @return 0 | -EINVAL (unknown channel) | the writer's error (the message
 *  is counted in n_lost) | -ENOMEM  @rt NON-RT */
int ps_mcap_write_message(ps_mcap_writer_t *w, uint16_t channel_id, uint32_t sequence,
                          uint64_t log_time_ns, uint64_t publish_time_ns, const void *data,
                          size_t len);

/** Write a Metadata record (between chunks; the open chunk stays open).
 *  @return 0 | the writer's error | -ENOMEM  @rt NON-RT */
int ps_mcap_write_metadata(ps_mcap_writer_t *w, const char *name, const ps_mcap_kv_t *kv,
                           size_t n_kv);

/** Close the open chunk (written, then synced when is_sync_chunks).
 *  @return 0 | the writer's error  @rt NON-RT */
int ps_mcap_flush(ps_mcap_writer_t *w);

/** Flush, write Data End, the summary, Footer and magic (skipped when the
 *  writer has failed), free everything. Safe twice and on a zeroed writer.
 *  @return 0 | the writer's error  @rt NON-RT */
int ps_mcap_close(ps_mcap_writer_t *w);

/** @return 0 or the error that failed the writer  @rt any */
int ps_mcap_error(const ps_mcap_writer_t *w);

/** @return "zstd", "lz4" or "" (the spec's names)  @rt any */
const char *ps_mcap_compression_name(ps_mcap_compression_t c);

/** Parse "zstd", "lz4" or "none".  @return 0 | -EINVAL  @rt any */
int ps_mcap_parse_compression(const char *s, ps_mcap_compression_t *out);

/* ---- reading ----------------------------------------------------------- */

/** Callbacks; each may be NULL. Strings are NUL-terminated copies valid
 *  during the call. A negative return stops reading with that code. */
typedef struct {
    int (*on_schema)(void *ctx, uint16_t id, const char *name, const char *encoding,
                     const uint8_t *data, size_t len);
    int (*on_channel)(void *ctx, uint16_t id, uint16_t schema_id, const char *topic,
                      const char *message_encoding);
    int (*on_message)(void *ctx, uint16_t channel_id, uint32_t sequence, uint64_t log_time_ns,
                      const uint8_t *data, size_t len);
    int (*on_metadata)(void *ctx, const char *name, const ps_mcap_kv_t *kv, size_t n_kv);
} ps_mcap_read_ops_t;

typedef struct {
    uint64_t file_bytes;
    uint64_t valid_bytes; /**< up to the end of the last record read whole */
    uint32_t n_chunks;    /**< complete chunks read */
    uint64_t n_messages;  /**< messages delivered */
    uint32_t n_metadata;
    bool has_data_end;
    bool has_footer; /**< the file ends with Footer and magic: it was closed */
    bool has_statistics;
    uint64_t stat_n_messages; /**< from the Statistics record, when present */
    uint16_t stat_n_schemas;
    uint32_t stat_n_channels, stat_n_chunks;
    char stop_reason[160]; /**< why reading stopped before a footer; "" when closed */
} ps_mcap_read_info_t;

/** Read path from the start. A truncated or damaged tail is not an error:
 *  reading stops there and out->stop_reason says where.
 *  @return 0 | -errno (the file cannot be opened or read) | -EPROTO (not an
 *  MCAP file: bad magic, or no Header) | a callback's error; err says which
 *  @rt NON-RT */
int ps_mcap_read_file(const char *path, const ps_mcap_read_ops_t *ops, void *ctx,
                      ps_mcap_read_info_t *out, char *err, size_t err_len);

#endif /* PS_MCAP_H */
