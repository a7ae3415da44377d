/* libFuzzer target: the MCAP reader behind `pushstep log` (rt/ps_mcap.c
 * reading, rt/ps_rosmsg.c parsing the file's schemas and decoding its CDR
 * messages, rt/ps_reclog.c's summary), on a file held in memory (memfd).
 *
 * Contract: ps_mcap_read_file returns 0, -EPROTO (not MCAP) or a negative
 * errno with a message; the strings it hands over are terminated; the
 * messages it counts are the ones it delivered; valid_bytes <= file_bytes.
 * Each ros2msg schema parses or is refused with a documented code; each
 * message of a parsed schema decodes or is refused with -EPROTO, every value
 * naming a field of the schema and a string's text inside the message's
 * length. `pushstep log FILE` on a file the reader took exits 0 or 1. */
#include <errno.h>

#include "../../rt/ps_mcap.h"
#include "../../rt/ps_reclog.h"
#include "../../rt/ps_rosmsg.h"
#include "fuzz.h"

#define MAX_SCHEMAS  16u
#define MAX_CHANNELS 32u

typedef struct {
    bool has_def[MAX_SCHEMAS];
    ps_rosmsg_parsed_t def[MAX_SCHEMAS];
    uint16_t channel_schema[MAX_CHANNELS];
    bool has_channel[MAX_CHANNELS];
    uint64_t n_messages;
    size_t msg_len;
    const ps_rosmsg_parsed_t *cur;
} reader_t;

static int on_schema(void *ctx, uint16_t id, const char *name, const char *enc, const uint8_t *d,
                     size_t len)
{
    reader_t *r = ctx;
    FUZZ_CHECK(name != NULL && enc != NULL && (d != NULL || len == 0), "schema %u strings", id);
    if (id >= MAX_SCHEMAS || strcmp(enc, "ros2msg") != 0)
        return 0;
    char *copy = malloc(len + 1); /* exact size: ASan sees a read past the text */
    if (copy == NULL)
        return -ENOMEM;
    memcpy(copy, d, len);
    char err[160];
    const int rc = ps_rosmsg_parse(copy, len, &r->def[id], err, sizeof err);
    free(copy);
    FUZZ_CHECK(rc == 0 || rc == -ENOTSUP || rc == -EINVAL || rc == -E2BIG,
               "ps_rosmsg_parse returned %d", rc);
    r->has_def[id] = rc == 0;
    if (rc == 0)
        FUZZ_CHECK(r->def[id].n_fields <= PS_ROSMSG_MAX_FIELDS, "%u fields", r->def[id].n_fields);
    return 0;
}

static int on_channel(void *ctx, uint16_t id, uint16_t schema, const char *topic, const char *enc)
{
    reader_t *r = ctx;
    FUZZ_CHECK(topic != NULL && enc != NULL, "channel %u strings", id);
    if (id < MAX_CHANNELS) {
        r->has_channel[id] = true;
        r->channel_schema[id] = schema;
    }
    return 0;
}

static void on_value(void *ctx, const ps_rosmsg_value_t *v)
{
    const reader_t *r = ctx;
    FUZZ_CHECK(v->field_idx < r->cur->n_fields, "value of field %u of %u", v->field_idx,
               r->cur->n_fields);
    if (v->is_string)
        FUZZ_CHECK(v->text != NULL && v->text_len <= r->msg_len, "string of %u bytes in %zu",
                   v->text_len, r->msg_len);
}

static int on_message(void *ctx, uint16_t ch, uint32_t seq, uint64_t t, const uint8_t *d,
                      size_t len)
{
    reader_t *r = ctx;
    (void)seq;
    (void)t;
    r->n_messages++;
    if (ch >= MAX_CHANNELS || !r->has_channel[ch] || r->channel_schema[ch] >= MAX_SCHEMAS ||
        !r->has_def[r->channel_schema[ch]])
        return 0;
    uint8_t *copy = malloc(len > 0 ? len : 1);
    if (copy == NULL)
        return -ENOMEM;
    memcpy(copy, d, len);
    r->cur = &r->def[r->channel_schema[ch]];
    r->msg_len = len;
    const int rc = ps_rosmsg_decode(r->cur, copy, len, on_value, r);
    free(copy);
    FUZZ_CHECK(rc == 0 || rc == -EPROTO, "ps_rosmsg_decode returned %d", rc);
    return 0;
}

static int on_metadata(void *ctx, const char *name, const ps_mcap_kv_t *kv, size_t n)
{
    (void)ctx;
    FUZZ_CHECK(name != NULL && (kv != NULL || n == 0), "metadata strings");
    for (size_t i = 0; i < n; i++)
        FUZZ_CHECK(kv[i].key != NULL && kv[i].value != NULL, "metadata %zu", i);
    return 0;
}

int LLVMFuzzerInitialize(int *argc, char ***argv);
int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc;
    (void)argv;
    if (freopen("/dev/null", "w", stdout) == NULL) /* the summary's lines */
        return 0;
    return 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char path[64], err[256];
    const int fd = fuzz_memfd(data, size, path, sizeof path);
    if (fd < 0)
        return 0;
    static reader_t r;
    memset(&r, 0, sizeof r);
    const ps_mcap_read_ops_t ops = {on_schema, on_channel, on_message, on_metadata};
    ps_mcap_read_info_t info;
    memset(&info, 0, sizeof info);
    const int rc = ps_mcap_read_file(path, &ops, &r, &info, err, sizeof err);
    FUZZ_CHECK(rc <= 0, "ps_mcap_read_file returned %d", rc);
    if (rc < 0) {
        FUZZ_CHECK(err[0] != '\0' && memchr(err, '\0', sizeof err) != NULL,
                   "refused (%d) without a message", rc);
    } else {
        FUZZ_CHECK(info.valid_bytes <= info.file_bytes && info.file_bytes == size,
                   "valid %llu of %llu bytes (file %zu)", (unsigned long long)info.valid_bytes,
                   (unsigned long long)info.file_bytes, size);
        FUZZ_CHECK(info.n_messages == r.n_messages, "%llu messages counted, %llu delivered",
                   (unsigned long long)info.n_messages, (unsigned long long)r.n_messages);
        FUZZ_CHECK(memchr(info.stop_reason, '\0', sizeof info.stop_reason) != NULL,
                   "stop reason not terminated");
        char *argv[] = {"log", path, NULL};
        const int status = ps_reclog_main(2, argv);
        FUZZ_CHECK(status == 0 || status == 1, "pushstep log exited %d", status);
    }
    close(fd);
    return 0;
}
