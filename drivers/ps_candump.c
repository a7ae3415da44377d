#include "ps_candump.h"

#include <stdbool.h>
#include <stdint.h>
#include <string.h>

#include "../rt/ps_err.h"

#define CANDUMP_ERR_FLAG   0x20000000u /* SocketCAN's CAN_ERR_FLAG, as candump prints it */
#define CANDUMP_FD_BRS     0x1u
#define CANDUMP_FD_ESI     0x2u
#define CANDUMP_FD_FDF     0x4u /* newer can-utils set it on every FD frame */
#define CANDUMP_SFF_DIGITS 3u
#define CANDUMP_EFF_DIGITS 8u
#define CANDUMP_US_DIGITS  6u
#define CANDUMP_S_DIGITS   10u

static const char HEX_UPPER[] = "0123456789ABCDEF";

/* Writes into a bounded buffer; once it runs out every later put is a no-op
 * and the line is refused as a whole. */
typedef struct {
    char *buf;
    size_t len;
    size_t at;
    bool is_full;
} line_writer_t;

static void put_char(line_writer_t *w, char c)
{
    if (w->at + 1 >= w->len) {
        w->is_full = true;
        return;
    }
    w->buf[w->at++] = c;
}

static void put_hex(line_writer_t *w, uint32_t v, unsigned digits)
{
    for (unsigned i = digits; i-- > 0;)
        put_char(w, HEX_UPPER[(v >> (4u * i)) & 0xfu]);
}

static void put_decimal(line_writer_t *w, uint64_t v, unsigned digits)
{
    char tmp[20];
    for (unsigned i = digits; i-- > 0; v /= 10u)
        tmp[i] = (char)('0' + (int)(v % 10u));
    for (unsigned i = 0; i < digits; i++)
        put_char(w, tmp[i]);
}

bool ps_candump_is_valid_ifname(const char *ifname)
{
    const size_t n = strnlen(ifname, PS_CANDUMP_IFNAME_MAX);
    if (n == 0 || n >= PS_CANDUMP_IFNAME_MAX)
        return false;
    for (size_t i = 0; i < n; i++) {
        if (ifname[i] == ' ' || ifname[i] == '\t' || ifname[i] == '\n' || ifname[i] == '(')
            return false;
    }
    return true;
}

int ps_candump_format(const ps_can_frame_t *f, const char *ifname, char *buf, size_t len)
{
    if (f->t_ns < 0 || !ps_candump_is_valid_ifname(ifname) || !ps_can_is_valid_frame(f))
        return -EINVAL;
    line_writer_t w = {.buf = buf, .len = len};
    const uint64_t us = (uint64_t)f->t_ns / 1000u;
    put_char(&w, '(');
    put_decimal(&w, us / 1000000u, CANDUMP_S_DIGITS);
    put_char(&w, '.');
    put_decimal(&w, us % 1000000u, CANDUMP_US_DIGITS);
    put_char(&w, ')');
    put_char(&w, ' ');
    for (const char *c = ifname; *c != '\0'; c++)
        put_char(&w, *c);
    put_char(&w, ' ');
    put_hex(&w, f->id, f->is_ext ? CANDUMP_EFF_DIGITS : CANDUMP_SFF_DIGITS);
    put_char(&w, '#');
    if (f->is_fd) {
        put_char(&w, '#');
        put_hex(&w, f->is_brs ? CANDUMP_FD_BRS : 0u, 1);
    }
    for (unsigned i = 0; i < f->len; i++)
        put_hex(&w, f->data[i], 2);
    put_char(&w, '\n');
    if (w.is_full || len == 0)
        return -ENOSPC;
    buf[w.at] = '\0';
    return (int)w.at;
}

/* ---- reading ----------------------------------------------------------- */

typedef struct {
    const char *line;
    size_t at;
    char *err;
    size_t err_len;
} line_reader_t;

static int refuse(const line_reader_t *r, const char *what)
{
    ps_err_format(r->err, r->err_len, "column %zu: %s", r->at + 1, what);
    return -PS_ERR_PROTOCOL;
}

static int hex_value(char c)
{
    if (c >= '0' && c <= '9')
        return c - '0';
    if (c >= 'A' && c <= 'F')
        return c - 'A' + 10;
    if (c >= 'a' && c <= 'f')
        return c - 'a' + 10;
    return -1;
}

static int expect(line_reader_t *r, char c, const char *what)
{
    if (r->line[r->at] != c)
        return refuse(r, what);
    r->at++;
    return 0;
}

/* Digits, at least one and at most max; *n_digits says how many. */
static int read_decimal(line_reader_t *r, unsigned max, uint64_t *v, unsigned *n_digits)
{
    *v = 0;
    *n_digits = 0;
    while (r->line[r->at] >= '0' && r->line[r->at] <= '9') {
        if (*n_digits == max)
            return refuse(r, "too many digits in the timestamp");
        *v = *v * 10u + (uint64_t)(r->line[r->at] - '0');
        (*n_digits)++;
        r->at++;
    }
    return *n_digits == 0 ? refuse(r, "timestamp digits expected") : 0;
}

static int read_time(line_reader_t *r, int64_t *t_ns)
{
    uint64_t s, us;
    unsigned n;
    int rc = expect(r, '(', "'(' expected: a candump -L line starts with (SECONDS.MICROSECONDS)");
    if (rc == 0)
        rc = read_decimal(r, CANDUMP_S_DIGITS, &s, &n);
    const uint64_t s_max = (uint64_t)INT64_MAX / 1000000000u;
    if (rc == 0 && s > s_max)
        return refuse(r, "timestamp beyond what int64_t nanoseconds hold");
    if (rc == 0)
        rc = expect(r, '.', "'.' expected in the timestamp");
    if (rc == 0)
        rc = read_decimal(r, CANDUMP_US_DIGITS, &us, &n);
    if (rc == 0 && n != CANDUMP_US_DIGITS)
        return refuse(r, "six microsecond digits expected in the timestamp");
    if (rc == 0 && s == s_max && us * 1000u > (uint64_t)INT64_MAX % 1000000000u)
        return refuse(r, "timestamp beyond what int64_t nanoseconds hold");
    if (rc == 0)
        rc = expect(r, ')', "')' expected after the timestamp");
    if (rc == 0)
        rc = expect(r, ' ', "a space expected after the timestamp");
    if (rc == 0)
        *t_ns = (int64_t)(s * 1000000000u + us * 1000u);
    return rc;
}

static int read_ifname(line_reader_t *r, char *ifname, size_t ifname_len)
{
    size_t n = 0;
    while (r->line[r->at] != ' ' && r->line[r->at] != '\0' && r->line[r->at] != '\n') {
        if (n + 1 >= PS_CANDUMP_IFNAME_MAX || n + 1 >= ifname_len)
            return refuse(r, "interface name longer than 15 bytes");
        /* what ps_candump_is_valid_ifname refuses: no line could carry it back */
        if (r->line[r->at] == '(' || r->line[r->at] == '\t')
            return refuse(r, "'(' or a tab in the interface name");
        ifname[n++] = r->line[r->at++];
    }
    ifname[n] = '\0';
    if (n == 0)
        return refuse(r, "interface name expected");
    return expect(r, ' ', "a space expected after the interface name");
}

static int read_id(line_reader_t *r, ps_can_frame_t *out)
{
    const size_t start = r->at;
    uint32_t id = 0;
    int v;
    while ((v = hex_value(r->line[r->at])) >= 0) {
        if (r->at - start == CANDUMP_EFF_DIGITS)
            return refuse(r, "identifier longer than 8 hex digits");
        id = (id << 4) | (uint32_t)v;
        r->at++;
    }
    const size_t digits = r->at - start;
    if (digits != CANDUMP_SFF_DIGITS && digits != CANDUMP_EFF_DIGITS) {
        r->at = start;
        return refuse(r, "identifier of 3 (11-bit) or 8 (29-bit) hex digits expected");
    }
    out->is_ext = digits == CANDUMP_EFF_DIGITS;
    if (out->is_ext && (id & CANDUMP_ERR_FLAG) != 0) {
        r->at = start;
        return refuse(r, "error frame (CAN_ERR_FLAG set): not replayed, only data frames are");
    }
    if (id > (out->is_ext ? PS_CAN_EFF_MASK : PS_CAN_SFF_MASK)) {
        r->at = start;
        return refuse(r, out->is_ext ? "29-bit identifier above 0x1fffffff"
                                     : "11-bit identifier above 0x7ff");
    }
    out->id = id;
    return expect(r, '#', "'#' expected after the identifier");
}

static int read_fd_flags(line_reader_t *r, ps_can_frame_t *out)
{
    out->is_fd = r->line[r->at] == '#';
    if (!out->is_fd)
        return 0;
    r->at++;
    const int flags = hex_value(r->line[r->at]);
    if (flags < 0 || (flags & ~(int)(CANDUMP_FD_BRS | CANDUMP_FD_ESI | CANDUMP_FD_FDF)) != 0)
        return refuse(r, "CAN FD flags nibble expected (bit 0 BRS, bit 1 ESI, bit 2 FDF)");
    out->is_brs = (flags & (int)CANDUMP_FD_BRS) != 0;
    r->at++;
    return 0;
}

static bool is_line_end(const char *s)
{
    return s[0] == '\0' || (s[0] == '\n' && s[1] == '\0') ||
           (s[0] == '\r' && s[1] == '\n' && s[2] == '\0');
}

static int read_data(line_reader_t *r, ps_can_frame_t *out)
{
    if (r->line[r->at] == 'R' || r->line[r->at] == 'r')
        return refuse(r, "remote frame (RTR): not replayed, only data frames are");
    const size_t max = out->is_fd ? PS_CAN_FD_MAX_DLEN : PS_CAN_MAX_DLEN;
    size_t n = 0;
    while (!is_line_end(&r->line[r->at])) {
        if (n > 0 && r->line[r->at] == '.')
            r->at++;
        const int hi = hex_value(r->line[r->at]);
        const int lo = hi < 0 ? -1 : hex_value(r->line[r->at + 1]);
        if (lo < 0)
            return refuse(r, "data byte of two hex digits expected");
        if (n == max)
            return refuse(r, out->is_fd ? "more than 64 data bytes" : "more than 8 data bytes");
        out->data[n++] = (uint8_t)((hi << 4) | lo);
        r->at += 2;
    }
    out->len = (uint8_t)n;
    if (!ps_can_is_valid_len(out->len, out->is_fd != 0))
        return refuse(r, "a CAN FD frame carries 0..8, 12, 16, 20, 24, 32, 48 or 64 bytes");
    return 0;
}

int ps_candump_parse(const char *line, ps_can_frame_t *out, char *ifname, size_t ifname_len,
                     char *err, size_t err_len)
{
    line_reader_t r = {.line = line, .err = err, .err_len = err_len};
    ps_can_frame_t f;
    memset(&f, 0, sizeof(f));
    int rc = read_time(&r, &f.t_ns);
    if (rc == 0)
        rc = read_ifname(&r, ifname, ifname_len);
    if (rc == 0)
        rc = read_id(&r, &f);
    if (rc == 0)
        rc = read_fd_flags(&r, &f);
    if (rc == 0)
        rc = read_data(&r, &f);
    if (rc == 0)
        *out = f;
    return rc;
}
