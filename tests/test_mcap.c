/*
 * rt/ps_mcap (MCAP writer and reader) and rt/ps_rosmsg (ros2msg schemas and
 * CDR): golden bytes of a CDR message, schema text, parse and decode round
 * trips; MCAP files written into memory and read back whole, cut at every
 * byte (a power cut), with a damaged chunk, and written onto a disk that
 * fills up.
 */
#include <errno.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

#include "../rt/ps_mcap.h"
#include "../rt/ps_rosmsg.h"

/* ---- CDR ----------------------------------------------------------------- */

typedef struct {
    uint8_t a;
    double b;
    float c[4];
    char s[8];
    uint8_t f[2];
} small_t;

static const ps_rosmsg_field_t SMALL_FIELDS[] = {
    {"a", PS_ROSMSG_UINT8, PS_ROSMSG_SCALAR, 0, 1, offsetof(small_t, a), NULL},
    {"b", PS_ROSMSG_FLOAT64, PS_ROSMSG_SCALAR, 0, 1, offsetof(small_t, b), "metres"},
    {"c", PS_ROSMSG_FLOAT32, PS_ROSMSG_SEQUENCE, 0, 4, offsetof(small_t, c), NULL},
    {"s", PS_ROSMSG_STRING, PS_ROSMSG_SCALAR, 0, 8, offsetof(small_t, s), NULL},
    {"f", PS_ROSMSG_BOOL, PS_ROSMSG_ARRAY, 0, 2, offsetof(small_t, f), NULL},
};
static const ps_rosmsg_def_t SMALL = {"t/msg/Small", SMALL_FIELDS, 5};

/* Worked by hand from the CDR rules (alignment counted after the 4-byte
 * encapsulation header): a at 0; b aligned to 8; c's count at 16, its two
 * floats at 20; s's length (3, with the NUL) at 28, "hi\0" at 32; f at 35. */
static const uint8_t SMALL_GOLDEN[] = {
    0x00, 0x01, 0x00, 0x00,                         /* CDR_LE */
    0x07, 0,    0,    0,    0,    0,    0,    0,    /* a = 7, padding */
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xf8, 0x3f, /* b = 1.5 */
    0x02, 0x00, 0x00, 0x00,                         /* c: 2 elements */
    0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0xc0, /* 1.0f, -2.0f */
    0x03, 0x00, 0x00, 0x00, 'h',  'i',  0x00,       /* s = "hi" */
    0x01, 0x00,                                     /* f = {true, false} */
};

static void test_rosmsg_encode_small_matches_golden_bytes(void **state)
{
    (void)state;
    small_t m = {.a = 7, .b = 1.5, .c = {1.0f, -2.0f, 9.0f, 9.0f}, .s = "hi", .f = {5, 0}};
    const uint32_t counts[1] = {2};
    uint8_t buf[128];
    int n = ps_rosmsg_encode(&SMALL, &m, counts, buf, sizeof(buf));
    assert_int_equal(n, sizeof(SMALL_GOLDEN));
    assert_memory_equal(buf, SMALL_GOLDEN, sizeof(SMALL_GOLDEN));
    assert_int_equal(ps_rosmsg_encode(&SMALL, &m, counts, buf, sizeof(SMALL_GOLDEN) - 1), -ENOSPC);
}

static void test_rosmsg_schema_text_lists_fields(void **state)
{
    (void)state;
    char text[256];
    int n = ps_rosmsg_schema_text(&SMALL, text, sizeof(text));
    assert_true(n > 0);
    assert_string_equal(text, "uint8 a\nfloat64 b  # metres\nfloat32[] c\nstring s\nbool[2] f\n");
    assert_int_equal(ps_rosmsg_schema_text(&SMALL, text, 10), -ENOSPC);
}

typedef struct {
    double v[16];
    char text[16];
    uint32_t n;
} collect_t;

static void collect(void *ctx, const ps_rosmsg_value_t *v)
{
    collect_t *c = ctx;
    if (v->is_string)
        snprintf(c->text, sizeof(c->text), "%.*s", (int)v->text_len, v->text);
    else if (c->n < 16)
        c->v[c->n++] = v->value;
}

static void test_rosmsg_parse_decode_round_trip(void **state)
{
    (void)state;
    char text[256], err[128];
    assert_true(ps_rosmsg_schema_text(&SMALL, text, sizeof(text)) > 0);
    ps_rosmsg_parsed_t def;
    assert_int_equal(ps_rosmsg_parse(text, strlen(text), &def, err, sizeof(err)), 0);
    assert_int_equal(def.n_fields, 5);
    assert_string_equal(def.fields[2].name, "c");
    assert_int_equal(def.fields[2].kind, PS_ROSMSG_SEQUENCE);
    assert_int_equal(def.fields[4].kind, PS_ROSMSG_ARRAY);
    assert_int_equal(def.fields[4].count, 2);
    collect_t c = {0};
    assert_int_equal(ps_rosmsg_decode(&def, SMALL_GOLDEN, sizeof(SMALL_GOLDEN), collect, &c), 0);
    assert_int_equal(c.n, 6); /* a, b, c[0], c[1], f[0], f[1] */
    assert_true(c.v[0] == 7 && c.v[1] == 1.5 && c.v[2] == 1.0 && c.v[3] == -2.0);
    assert_true(c.v[4] == 1 && c.v[5] == 0);
    assert_string_equal(c.text, "hi");
    /* a message cut short is refused, not read past its end */
    for (size_t len = 0; len < sizeof(SMALL_GOLDEN); len++) {
        collect_t d = {0};
        assert_int_equal(ps_rosmsg_decode(&def, SMALL_GOLDEN, len, collect, &d), -EPROTO);
    }
}

static void test_rosmsg_parse_rejects_nested_and_malformed(void **state)
{
    (void)state;
    ps_rosmsg_parsed_t def;
    char err[128];
    const char *nested = "std_msgs/Header header\nfloat32 x\n";
    assert_int_equal(ps_rosmsg_parse(nested, strlen(nested), &def, err, sizeof(err)), -ENOTSUP);
    assert_non_null(strstr(err, "line 1"));
    const char *bad = "float32[abc] x\n";
    assert_int_equal(ps_rosmsg_parse(bad, strlen(bad), &def, err, sizeof(err)), -EINVAL);
    const char *ok = "# comment\nint32 K=5\n\nfloat64[3] v # c\nuint8[<=4] w\n====\nMSG: x\n";
    assert_int_equal(ps_rosmsg_parse(ok, strlen(ok), &def, err, sizeof(err)), 0);
    assert_int_equal(def.n_fields, 2);
    assert_int_equal(def.fields[0].count, 3);
    assert_int_equal(def.fields[1].kind, PS_ROSMSG_SEQUENCE);
}

/* ---- MCAP ---------------------------------------------------------------- */

typedef struct {
    uint8_t *p;
    size_t len, cap;
    size_t fail_after; /* 0: never; else the "disk" holds this many bytes */
    unsigned n_syncs;
} mem_io_t;

static int mem_write(void *ctx, const void *buf, size_t len)
{
    mem_io_t *m = ctx;
    size_t take = len;
    if (m->fail_after != 0 && m->len + len > m->fail_after)
        take = m->fail_after - m->len; /* a partial write, then the disk is full */
    if (m->len + take > m->cap) {
        m->cap = (m->len + take) * 2;
        m->p = realloc(m->p, m->cap);
        assert_non_null(m->p);
    }
    memcpy(m->p + m->len, buf, take);
    m->len += take;
    return take < len ? -ENOSPC : 0;
}

static int mem_sync(void *ctx)
{
    ((mem_io_t *)ctx)->n_syncs++;
    return 0;
}

static char tmp_path[64];

static void save(const mem_io_t *m, size_t len)
{
    FILE *f = fopen(tmp_path, "wb");
    assert_non_null(f);
    assert_int_equal(fwrite(m->p, 1, len, f), len);
    fclose(f);
}

typedef struct {
    uint64_t n_by_channel[4];
    uint64_t last_seq[4];
    bool is_order_bad, is_payload_bad;
    uint32_t n_schemas, n_channels, n_meta;
    char topic[4][32];
} got_t;

static int got_schema(void *ctx, uint16_t id, const char *name, const char *enc,
                      const uint8_t *data, size_t len)
{
    got_t *g = ctx;
    (void)id;
    (void)data;
    g->n_schemas++;
    assert_string_equal(enc, "ros2msg");
    assert_non_null(strstr(name, "Small"));
    assert_true(len > 0);
    return 0;
}

static int got_channel(void *ctx, uint16_t id, uint16_t schema, const char *topic, const char *enc)
{
    got_t *g = ctx;
    assert_true(id < 4 && schema >= 1);
    assert_string_equal(enc, "cdr");
    snprintf(g->topic[id], sizeof(g->topic[id]), "%s", topic);
    g->n_channels++;
    return 0;
}

/* Message k on channel c carries k in its first payload byte and k + 1 in
 * its sequence; log time 1000 * k. */
static int got_message(void *ctx, uint16_t ch, uint32_t seq, uint64_t t, const uint8_t *data,
                       size_t len)
{
    got_t *g = ctx;
    assert_true(ch < 4);
    if (seq != g->last_seq[ch] + 1 || t != 1000u * seq)
        g->is_order_bad = true;
    if (len != 20 || data[0] != (uint8_t)seq || data[19] != (uint8_t)ch)
        g->is_payload_bad = true;
    g->last_seq[ch] = seq;
    g->n_by_channel[ch]++;
    return 0;
}

static int got_meta(void *ctx, const char *name, const ps_mcap_kv_t *kv, size_t n)
{
    got_t *g = ctx;
    assert_string_equal(name, "run");
    assert_int_equal(n, 2);
    assert_string_equal(kv[1].key, "robot");
    assert_string_equal(kv[1].value, "ps1");
    g->n_meta++;
    return 0;
}

static const ps_mcap_read_ops_t GOT_OPS = {got_schema, got_channel, got_message, got_meta};

/* Three channels; channel 2 gets every third message. */
static uint64_t write_file(ps_mcap_writer_t *w, mem_io_t *io, ps_mcap_compression_t comp,
                           uint32_t n, size_t chunk_size)
{
    ps_mcap_cfg_t cfg = {.io = {mem_write, mem_sync},
                         .io_ctx = io,
                         .compression = comp,
                         .chunk_size = chunk_size,
                         .is_sync_chunks = true,
                         .profile = "ros2"};
    assert_int_equal(ps_mcap_open(w, &cfg), 0);
    const char schema[] = "uint8[20] x\n";
    int s = ps_mcap_add_schema(w, "t/msg/Small", "ros2msg", schema, strlen(schema));
    assert_int_equal(s, 1);
    const ps_mcap_kv_t meta[] = {{"offered_qos_profiles", ""}};
    for (int c = 0; c < 3; c++) {
        char topic[16];
        snprintf(topic, sizeof(topic), "/ch%d", c);
        assert_int_equal(ps_mcap_add_channel(w, (uint16_t)s, topic, "cdr", meta, 1), c);
    }
    const ps_mcap_kv_t run[] = {{"board", "sim"}, {"robot", "ps1"}};
    assert_int_equal(ps_mcap_write_metadata(w, "run", run, 2), 0);
    uint32_t seq[3] = {0};
    uint64_t n_written = 0;
    for (uint32_t k = 0; k < n; k++) {
        for (uint16_t c = 0; c < 3; c++) {
            if (c == 2 && k % 3 != 0)
                continue;
            uint8_t payload[20];
            memset(payload, 0xa5, sizeof(payload));
            seq[c]++;
            payload[0] = (uint8_t)seq[c];
            payload[19] = (uint8_t)c;
            if (ps_mcap_write_message(w, c, seq[c], 1000u * seq[c], 1000u * seq[c], payload,
                                      sizeof(payload)) == 0)
                n_written++;
        }
    }
    return n_written;
}

static void read_back(size_t len, got_t *g, ps_mcap_read_info_t *info)
{
    memset(g, 0, sizeof(*g));
    char err[128];
    assert_int_equal(ps_mcap_read_file(tmp_path, &GOT_OPS, g, info, err, sizeof(err)), 0);
    (void)len;
}

static void round_trip(ps_mcap_compression_t comp)
{
    ps_mcap_writer_t w;
    mem_io_t io = {0};
    write_file(&w, &io, comp, 3000, 4096);
    assert_true(w.chunk_len > 0); /* the last chunk is still open */
    assert_int_equal(ps_mcap_close(&w), 0);
    assert_true(w.n_chunks > 10);
    assert_int_equal(w.n_messages, 3000 + 3000 + 1000);
    assert_int_equal(w.channel_n_messages[2], 1000);
    assert_true(io.n_syncs >= w.n_chunks);
    save(&io, io.len);
    got_t g;
    ps_mcap_read_info_t info;
    read_back(io.len, &g, &info);
    assert_true(info.has_footer);
    assert_true(info.has_data_end);
    assert_string_equal(info.stop_reason, "");
    assert_int_equal(info.valid_bytes, io.len);
    assert_int_equal(info.n_chunks, w.n_chunks);
    assert_int_equal(info.n_messages, 7000);
    assert_true(info.has_statistics);
    assert_int_equal(info.stat_n_messages, 7000);
    assert_int_equal(info.stat_n_channels, 3);
    assert_int_equal(info.stat_n_schemas, 1);
    assert_int_equal(info.stat_n_chunks, w.n_chunks);
    assert_int_equal(g.n_schemas, 1); /* the summary's copies are not delivered twice */
    assert_int_equal(g.n_channels, 3);
    assert_int_equal(g.n_meta, 1);
    assert_int_equal(g.n_by_channel[0], 3000);
    assert_int_equal(g.n_by_channel[2], 1000);
    assert_string_equal(g.topic[1], "/ch1");
    assert_false(g.is_order_bad);
    assert_false(g.is_payload_bad);
    free(io.p);
}

static void test_mcap_zstd_round_trip_all_messages_and_statistics(void **state)
{
    (void)state;
    round_trip(PS_MCAP_COMPRESS_ZSTD);
}

static void test_mcap_lz4_round_trip_all_messages_and_statistics(void **state)
{
    (void)state;
    round_trip(PS_MCAP_COMPRESS_LZ4);
}

static void test_mcap_stored_round_trip_all_messages_and_statistics(void **state)
{
    (void)state;
    round_trip(PS_MCAP_COMPRESS_NONE);
}

/* A power cut: the file cut at every byte gives exactly the messages of
 * the chunks that end before the cut, never an error. */
static void test_mcap_cut_anywhere_reads_every_complete_chunk(void **state)
{
    (void)state;
    ps_mcap_writer_t w;
    mem_io_t io = {0};
    write_file(&w, &io, PS_MCAP_COMPRESS_ZSTD, 400, 2048);
    assert_int_equal(ps_mcap_flush(&w), 0);
    /* what each chunk holds, before close frees the index */
    const uint32_t n_chunks = w.n_chunks;
    uint64_t end[64], count[64];
    assert_true(n_chunks > 3 && n_chunks < 64);
    uint64_t before = 0;
    for (uint32_t i = 0; i < n_chunks; i++) {
        end[i] = w.chunks[i].offset + w.chunks[i].length;
        count[i] = 0;
    }
    /* messages per chunk: the ones each flush added (recount by reading) */
    assert_int_equal(ps_mcap_close(&w), 0);
    save(&io, io.len);
    for (uint32_t i = 0; i < n_chunks; i++) {
        got_t g;
        ps_mcap_read_info_t info;
        save(&io, end[i]);
        read_back(end[i], &g, &info);
        count[i] = info.n_messages - before;
        before = info.n_messages;
        assert_int_equal(info.n_chunks, i + 1);
    }
    assert_int_equal(before, 400 + 400 + 134);
    /* every byte near a chunk's end, and a stride through the rest */
    size_t cuts[4096], n_cuts = 0;
    for (uint32_t i = 0; i < n_chunks; i++)
        for (int d = -2; d <= 2; d++)
            cuts[n_cuts++] = (size_t)((int64_t)end[i] + d);
    for (size_t cut = 0; cut <= io.len && n_cuts < 4096; cut += io.len / 400 + 1)
        cuts[n_cuts++] = cut;
    cuts[n_cuts++] = io.len;
    for (size_t k = 0; k < n_cuts; k++) {
        const size_t cut = cuts[k];
        uint64_t expected = 0;
        for (uint32_t i = 0; i < n_chunks; i++)
            if (end[i] <= cut)
                expected += count[i];
        save(&io, cut);
        got_t g;
        ps_mcap_read_info_t info;
        memset(&g, 0, sizeof(g));
        char err[128];
        int rc = ps_mcap_read_file(tmp_path, &GOT_OPS, &g, &info, err, sizeof(err));
        if (cut < PS_MCAP_MAGIC_LEN) {
            assert_int_equal(rc, -EPROTO); /* not even the magic */
            continue;
        }
        assert_int_equal(rc, 0);
        if (info.n_messages != expected)
            fail_msg("cut at %zu of %zu: %llu messages, expected %llu (%s)", cut, io.len,
                     (unsigned long long)info.n_messages, (unsigned long long)expected,
                     info.stop_reason);
        assert_false(g.is_payload_bad);
        assert_int_equal(info.has_footer, cut == io.len);
    }
    free(io.p);
}

static void test_mcap_damaged_chunk_stops_reading_with_reason(void **state)
{
    (void)state;
    ps_mcap_writer_t w;
    mem_io_t io = {0};
    write_file(&w, &io, PS_MCAP_COMPRESS_NONE, 200, 2048);
    assert_int_equal(ps_mcap_flush(&w), 0);
    const uint64_t second = w.chunks[1].offset, second_len = w.chunks[1].length;
    assert_int_equal(ps_mcap_close(&w), 0);
    io.p[second + second_len / 2] ^= 0x40; /* a bit flips inside chunk 2's records */
    save(&io, io.len);
    got_t g;
    ps_mcap_read_info_t info;
    read_back(io.len, &g, &info);
    assert_int_equal(info.n_chunks, 1);
    assert_false(info.has_footer);
    assert_non_null(strstr(info.stop_reason, "CRC"));
    free(io.p);
}

/* The disk fills up after the second chunk: the writer fails, every later
 * message is counted lost, and the file reads up to its last whole chunk. */
static void test_mcap_disk_full_counts_lost_keeps_complete_chunks(void **state)
{
    (void)state;
    ps_mcap_writer_t w;
    mem_io_t probe = {0};
    write_file(&w, &probe, PS_MCAP_COMPRESS_ZSTD, 400, 2048);
    assert_int_equal(ps_mcap_flush(&w), 0);
    const size_t limit = (size_t)(w.chunks[1].offset + w.chunks[1].length + 100);
    assert_int_equal(ps_mcap_close(&w), 0);
    free(probe.p);

    mem_io_t io = {.fail_after = limit};
    const uint64_t n_ok = write_file(&w, &io, PS_MCAP_COMPRESS_ZSTD, 400, 2048);
    assert_int_equal(ps_mcap_error(&w), -ENOSPC);
    assert_int_equal(ps_mcap_close(&w), -ENOSPC);
    assert_int_equal(io.len, limit);
    assert_true(w.n_lost > 0);
    assert_int_equal(w.n_messages + w.n_lost, 934); /* every message accounted for */
    assert_true(n_ok < 934);
    save(&io, io.len);
    got_t g;
    ps_mcap_read_info_t info;
    read_back(io.len, &g, &info);
    assert_int_equal(info.n_chunks, w.n_chunks);
    assert_true(info.n_chunks >= 2);
    assert_int_equal(info.n_messages, w.n_messages);
    assert_false(g.is_payload_bad);
    free(io.p);
}

/* A writer takes PS_MCAP_MAX_WRITE_CHANNELS channels and refuses the next:
 * each chunk's index entry, held until close, has a slot per channel. */
static void test_mcap_writer_refuses_a_channel_past_its_cap(void **state)
{
    (void)state;
    ps_mcap_writer_t w;
    mem_io_t io = {0};
    ps_mcap_cfg_t cfg = {.io = {mem_write, mem_sync},
                         .io_ctx = &io,
                         .compression = PS_MCAP_COMPRESS_NONE,
                         .chunk_size = 4096,
                         .profile = "ros2"};
    assert_int_equal(ps_mcap_open(&w, &cfg), 0);
    const char schema[] = "uint8 x\n";
    const int s = ps_mcap_add_schema(&w, "t/msg/X", "ros2msg", schema, strlen(schema));
    assert_true(s > 0);
    char topic[16];
    for (unsigned c = 0; c < PS_MCAP_MAX_WRITE_CHANNELS; c++) {
        snprintf(topic, sizeof(topic), "/c%u", c);
        assert_int_equal(ps_mcap_add_channel(&w, (uint16_t)s, topic, "cdr", NULL, 0), (int)c);
    }
    assert_int_equal(ps_mcap_add_channel(&w, (uint16_t)s, "/one_more", "cdr", NULL, 0), -ENOSPC);
    const uint8_t payload = 7;
    const uint16_t last = PS_MCAP_MAX_WRITE_CHANNELS - 1u;
    assert_int_equal(ps_mcap_write_message(&w, last, 1, 1000, 1000, &payload, 1), 0);
    assert_int_equal(ps_mcap_close(&w), 0);
    free(io.p);
}

static void test_mcap_read_refuses_non_mcap_and_missing_file(void **state)
{
    (void)state;
    FILE *f = fopen(tmp_path, "wb");
    assert_non_null(f);
    fputs("not an mcap file at all", f);
    fclose(f);
    ps_mcap_read_info_t info;
    char err[256];
    assert_int_equal(ps_mcap_read_file(tmp_path, &GOT_OPS, NULL, &info, err, sizeof(err)), -EPROTO);
    assert_non_null(strstr(err, "not an MCAP file"));
    assert_int_equal(
        ps_mcap_read_file("/nonexistent/x.mcap", &GOT_OPS, NULL, &info, err, sizeof(err)), -ENOENT);
    assert_non_null(strstr(err, "/nonexistent/x.mcap"));
}

static void test_mcap_parse_compression_names(void **state)
{
    (void)state;
    ps_mcap_compression_t c;
    assert_int_equal(ps_mcap_parse_compression("lz4", &c), 0);
    assert_int_equal(c, PS_MCAP_COMPRESS_LZ4);
    assert_int_equal(ps_mcap_parse_compression("none", &c), 0);
    assert_string_equal(ps_mcap_compression_name(c), "");
    assert_int_equal(ps_mcap_parse_compression("gzip", &c), -EINVAL);
}

static int setup(void **state)
{
    (void)state;
    snprintf(tmp_path, sizeof(tmp_path), "/tmp/test_mcap_XXXXXX");
    int fd = mkstemp(tmp_path);
    if (fd < 0)
        return -1;
    close(fd);
    return 0;
}

static int teardown(void **state)
{
    (void)state;
    unlink(tmp_path);
    return 0;
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_rosmsg_encode_small_matches_golden_bytes),
        cmocka_unit_test(test_rosmsg_schema_text_lists_fields),
        cmocka_unit_test(test_rosmsg_parse_decode_round_trip),
        cmocka_unit_test(test_rosmsg_parse_rejects_nested_and_malformed),
        cmocka_unit_test(test_mcap_zstd_round_trip_all_messages_and_statistics),
        cmocka_unit_test(test_mcap_lz4_round_trip_all_messages_and_statistics),
        cmocka_unit_test(test_mcap_stored_round_trip_all_messages_and_statistics),
        cmocka_unit_test(test_mcap_cut_anywhere_reads_every_complete_chunk),
        cmocka_unit_test(test_mcap_damaged_chunk_stops_reading_with_reason),
        cmocka_unit_test(test_mcap_disk_full_counts_lost_keeps_complete_chunks),
        cmocka_unit_test(test_mcap_writer_refuses_a_channel_past_its_cap),
        cmocka_unit_test(test_mcap_read_refuses_non_mcap_and_missing_file),
        cmocka_unit_test(test_mcap_parse_compression_names),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
