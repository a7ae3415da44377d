/* libFuzzer target: candump -L log lines (drivers/ps_candump.c), the format
 * `pushstep --replay` and `pushstep monitor --log` read.
 *
 * The input is split into lines; each goes to ps_candump_parse as an
 * exact-size NUL-terminated heap copy (ASan sees a read past it).
 * Contract: 0 or -PS_ERR_PROTOCOL with "column N: ..." in err; a parsed
 * frame is valid (ps_can_is_valid_frame), not negative in time, with an
 * interface name ps_candump_is_valid_ifname accepts; written back by
 * ps_candump_format and parsed again it is the same frame. */
#include "../../drivers/ps_candump.h"
#include "../../rt/ps_err.h"
#include "fuzz.h"

static void one_line(const char *line)
{
    ps_can_frame_t f, g;
    memset(&f, 0, sizeof f);
    char ifname[PS_CANDUMP_IFNAME_MAX], ifname2[PS_CANDUMP_IFNAME_MAX], err[160];
    const int rc = ps_candump_parse(line, &f, ifname, sizeof ifname, err, sizeof err);
    FUZZ_CHECK(rc == 0 || rc == -PS_ERR_PROTOCOL, "ps_candump_parse returned %d", rc);
    if (rc < 0) {
        FUZZ_CHECK(strncmp(err, "column ", 7) == 0, "message \"%s\"", err);
        return;
    }
    FUZZ_CHECK(ps_can_is_valid_frame(&f), "parsed an invalid frame: id 0x%x len %u ext %u fd %u",
               f.id, f.len, f.is_ext, f.is_fd);
    FUZZ_CHECK(f.t_ns >= 0, "negative time %lld", (long long)f.t_ns);
    FUZZ_CHECK(ps_candump_is_valid_ifname(ifname), "interface \"%s\"", ifname);
    char buf[PS_CANDUMP_LINE_MAX];
    const int n = ps_candump_format(&f, ifname, buf, sizeof buf);
    FUZZ_CHECK(n > 0, "a parsed frame does not format: %d", n);
    memset(&g, 0, sizeof g);
    FUZZ_CHECK(ps_candump_parse(buf, &g, ifname2, sizeof ifname2, err, sizeof err) == 0,
               "its own line does not parse: %s (%s)", buf, err);
    FUZZ_CHECK(g.id == f.id && g.len == f.len && g.is_ext == f.is_ext && g.is_fd == f.is_fd &&
                   g.is_brs == f.is_brs && g.t_ns == f.t_ns && !memcmp(g.data, f.data, f.len) &&
                   !strcmp(ifname, ifname2),
               "round trip changed the frame: %s", buf);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    size_t start = 0;
    while (start < size) {
        const uint8_t *nl = memchr(data + start, '\n', size - start);
        const size_t end = nl != NULL ? (size_t)(nl - data) + 1 : size;
        const size_t len = end - start;
        if (memchr(data + start, '\0', len) == NULL) { /* a C string has no NUL inside */
            char *line = malloc(len + 1);
            if (line == NULL)
                return 0;
            memcpy(line, data + start, len);
            line[len] = '\0';
            one_line(line);
            free(line);
        }
        start = end;
    }
    return 0;
}
