#include "ps_trace.h"

#include <errno.h>
#include <fcntl.h>
#include <string.h>
#include <unistd.h>

#include "ps_err.h"

static const char *const DEFAULT_PATHS[] = {
    "/sys/kernel/tracing/trace_marker",
    "/sys/kernel/debug/tracing/trace_marker",
};

void ps_trace_init(ps_trace_t *t)
{
    memset(t, 0, sizeof(*t));
    t->fd = -1;
}

void ps_trace_close(ps_trace_t *t)
{
    if (t->is_open)
        (void)close(t->fd); /* nothing to flush: marks are already in the kernel */
    t->is_open = false;
    t->fd = -1;
}

int ps_trace_open(ps_trace_t *t, const char *path, char *err, size_t err_len)
{
    ps_trace_close(t);
    ps_trace_init(t);
    const char *const *paths = path ? &path : DEFAULT_PATHS;
    size_t n = path ? 1 : sizeof(DEFAULT_PATHS) / sizeof(DEFAULT_PATHS[0]);
    int rc = -ENOENT;
    size_t used = 0;
    if (err != NULL && err_len > 0)
        err[0] = '\0';
    for (size_t i = 0; i < n; i++) {
        t->fd = open(paths[i], O_WRONLY | O_NONBLOCK | O_CLOEXEC);
        if (t->fd >= 0) {
            t->is_open = true;
            return 0;
        }
        rc = -errno;
        if (err != NULL && used < err_len) {
            ps_err_format(err + used, err_len - used, "%s%s: %s", used ? "; " : "", paths[i],
                          strerror(errno));
            used = strlen(err);
        }
    }
    return rc;
}

static size_t put_str(char *buf, size_t at, size_t cap, const char *s)
{
    while (*s != '\0' && at < cap)
        buf[at++] = *s++;
    return at;
}

/* Decimal without printf: async-signal-safe and allocation-free. */
static size_t put_int(char *buf, size_t at, size_t cap, int64_t v)
{
    char digits[24];
    size_t n = 0;
    uint64_t u = v < 0 ? (uint64_t)0 - (uint64_t)v : (uint64_t)v;
    do {
        digits[n++] = (char)('0' + u % 10u);
        u /= 10u;
    } while (u != 0);
    if (v < 0 && at < cap)
        buf[at++] = '-';
    while (n > 0 && at < cap)
        buf[at++] = digits[--n];
    return at;
}

void ps_trace_mark(ps_trace_t *t, const char *what, const char *key1, int64_t v1, const char *key2,
                   int64_t v2)
{
    if (t == NULL || !t->is_open)
        return;
    char line[160];
    const size_t cap = sizeof(line) - 1;
    size_t at = put_str(line, 0, cap, "pushstep: ");
    at = put_str(line, at, cap, what);
    at = put_str(line, at, cap, " ");
    at = put_str(line, at, cap, key1);
    at = put_str(line, at, cap, "=");
    at = put_int(line, at, cap, v1);
    if (key2 != NULL) {
        at = put_str(line, at, cap, " ");
        at = put_str(line, at, cap, key2);
        at = put_str(line, at, cap, "=");
        at = put_int(line, at, cap, v2);
    }
    line[at++] = '\n';
    t->n_marks++;
    if (write(t->fd, line, at) != (ssize_t)at)
        t->n_failed++;
}
