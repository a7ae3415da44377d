/*
 * Trace points: open failures name the paths, marks are whole lines in the
 * documented format, a closed trace is a no-op, failed writes are counted.
 * A regular file stands in for trace_marker.
 */
#include <errno.h>
#include <fcntl.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

#include "../rt/ps_trace.h"

static void read_file(const char *path, char *buf, size_t len)
{
    FILE *f = fopen(path, "r");
    assert_non_null(f);
    size_t n = fread(buf, 1, len - 1, f);
    buf[n] = '\0';
    fclose(f);
}

static void test_ps_trace_open_missing_path_names_it(void **state)
{
    (void)state;
    ps_trace_t t;
    ps_trace_init(&t);
    char err[256];
    assert_int_equal(ps_trace_open(&t, "/nonexistent/trace_marker", err, sizeof(err)), -ENOENT);
    assert_non_null(strstr(err, "/nonexistent/trace_marker"));
    ps_trace_mark(&t, "tick", "n", 1, NULL, 0); /* closed: no-op */
    assert_int_equal(t.n_marks, 0);
}

static void test_ps_trace_mark_writes_lines(void **state)
{
    (void)state;
    char path[] = "/tmp/ps_trace_XXXXXX";
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    close(fd);
    ps_trace_t t;
    ps_trace_init(&t);
    char err[256];
    assert_int_equal(ps_trace_open(&t, path, err, sizeof(err)), 0);
    ps_trace_mark(&t, "tick", "n", 42, "wake_ns", 12345);
    ps_trace_mark(&t, "state", "from", 2, "to", 3);
    ps_trace_mark(&t, "x", "v", -9223372036854775807LL - 1, NULL, 0);
    ps_trace_close(&t);
    ps_trace_close(&t); /* twice is safe */
    char buf[512];
    read_file(path, buf, sizeof(buf));
    assert_string_equal(buf, "pushstep: tick n=42 wake_ns=12345\n"
                             "pushstep: state from=2 to=3\n"
                             "pushstep: x v=-9223372036854775808\n");
    assert_int_equal(t.n_marks, 3);
    assert_int_equal(t.n_failed, 0);
    unlink(path);
}

static void test_ps_trace_mark_failed_write_counted(void **state)
{
    (void)state;
    ps_trace_t t;
    ps_trace_init(&t);
    char err[256];
    assert_int_equal(ps_trace_open(&t, "/dev/full", err, sizeof(err)), 0);
    ps_trace_mark(&t, "tick", "n", 1, NULL, 0);
    assert_int_equal(t.n_failed, 1);
    ps_trace_close(&t);
}

/* Deinit on a zeroed struct must not close fd 0 (stdin). */
static void test_ps_trace_close_zeroed_leaves_fd0(void **state)
{
    (void)state;
    ps_trace_t t;
    memset(&t, 0, sizeof(t));
    ps_trace_close(&t);
    assert_true(fcntl(0, F_GETFD) >= 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ps_trace_open_missing_path_names_it),
        cmocka_unit_test(test_ps_trace_mark_writes_lines),
        cmocka_unit_test(test_ps_trace_mark_failed_write_counted),
        cmocka_unit_test(test_ps_trace_close_zeroed_leaves_fd0),
    };
    return cmocka_run_group_tests_name("trace", tests, NULL, NULL);
}
