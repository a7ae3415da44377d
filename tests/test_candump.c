/*
 * Tests of drivers/ps_candump: frames as can-utils log lines and back, each
 * against a line written out by hand from the format candump -L prints, the
 * refusals with their column, and can-utils' own log2long reading the lines
 * the runtime writes (can-utils is a test dependency: `make test` installs it).
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../drivers/ps_candump.h"
#include "../rt/ps_err.h"
#include "../rt/ps_limits.h"

static ps_can_frame_t frame(uint32_t id, bool is_ext, bool is_fd, bool is_brs, uint8_t len,
                            int64_t t_ns)
{
    ps_can_frame_t f;
    memset(&f, 0, sizeof(f));
    f.id = id;
    f.is_ext = is_ext;
    f.is_fd = is_fd;
    f.is_brs = is_brs;
    f.len = len;
    f.t_ns = t_ns;
    for (uint8_t i = 0; i < len; i++)
        f.data[i] = (uint8_t)(i * 0x11u);
    return f;
}

static void assert_formats_as(const ps_can_frame_t *f, const char *ifname, const char *want)
{
    char line[PS_CANDUMP_LINE_MAX];
    const int n = ps_candump_format(f, ifname, line, sizeof(line));
    assert_int_equal(n, (int)strlen(want));
    assert_string_equal(line, want);
}

/* ---- writing ---------------------------------------------------------- */

static void test_format_classical_11_bit_hand_line(void **state)
{
    (void)state;
    ps_can_frame_t f = frame(0x123, false, false, false, 4, 1500007999);
    memcpy(f.data, "\xDE\xAD\xBE\xEF", 4);
    /* microseconds truncated, not rounded: 1.500007999 s -> 1.500007 */
    assert_formats_as(&f, "can0", "(0000000001.500007) can0 123#DEADBEEF\n");
}

static void test_format_29_bit_and_empty_payload_hand_lines(void **state)
{
    (void)state;
    /* a RobStride motion-control id: type 1, torque word 0x00FD, drive 0x01 */
    ps_can_frame_t f = frame(0x0100FD01, true, false, false, 8, 12000000000);
    assert_formats_as(&f, "can1", "(0000000012.000000) can1 0100FD01#0011223344556677\n");
    ps_can_frame_t e = frame(0x7FF, false, false, false, 0, 0);
    assert_formats_as(&e, "vcan0", "(0000000000.000000) vcan0 7FF#\n");
    ps_can_frame_t z = frame(0x5, true, false, false, 1, 0);
    assert_formats_as(&z, "can0", "(0000000000.000000) can0 00000005#00\n");
}

static void test_format_fd_flags_nibble_hand_lines(void **state)
{
    (void)state;
    ps_can_frame_t f = frame(0x123, false, true, true, 12, 2000000);
    assert_formats_as(&f, "can2", "(0000000000.002000) can2 123##100112233445566778899AABB\n");
    ps_can_frame_t g = frame(0x8001, true, true, false, 0, 2000000);
    assert_formats_as(&g, "can2", "(0000000000.002000) can2 00008001##0\n");
}

static void test_format_longest_line_fits_line_max(void **state)
{
    (void)state;
    ps_can_frame_t f = frame(PS_CAN_EFF_MASK, true, true, true, 64, INT64_MAX);
    char line[PS_CANDUMP_LINE_MAX];
    const int n = ps_candump_format(&f, "abcdefghijklmno", line, sizeof(line));
    assert_int_equal(n, (int)PS_CANDUMP_LINE_MAX - 1);
    assert_int_equal(strncmp(line, "(9223372036.854775) abcdefghijklmno 1FFFFFFF##1", 47), 0);
    /* one byte short of the line and its NUL: refused, not cut */
    assert_int_equal(ps_candump_format(&f, "abcdefghijklmno", line, (size_t)n), -ENOSPC);
    assert_int_equal(ps_candump_format(&f, "abcdefghijklmno", line, (size_t)n + 1), n);
    /* and the latest time a line can carry reads back */
    ps_can_frame_t back;
    char ifname[PS_CANDUMP_IFNAME_MAX];
    char err[PS_ERR_MSG_LEN] = "";
    assert_int_equal(ps_candump_parse(line, &back, ifname, sizeof(ifname), err, sizeof(err)), 0);
    assert_true(back.t_ns == INT64_MAX / 1000 * 1000);
}

static void test_format_refuses_invalid_frames_and_names(void **state)
{
    (void)state;
    char line[PS_CANDUMP_LINE_MAX];
    ps_can_frame_t f = frame(0x123, false, false, false, 2, 0);
    assert_int_equal(ps_candump_format(&f, "", line, sizeof(line)), -EINVAL);
    assert_int_equal(ps_candump_format(&f, "abcdefghijklmnop", line, sizeof(line)), -EINVAL);
    assert_int_equal(ps_candump_format(&f, "can 0", line, sizeof(line)), -EINVAL);
    f.t_ns = -1;
    assert_int_equal(ps_candump_format(&f, "can0", line, sizeof(line)), -EINVAL);
    ps_can_frame_t big_id = frame(0x800, false, false, false, 0, 0);
    assert_int_equal(ps_candump_format(&big_id, "can0", line, sizeof(line)), -EINVAL);
    ps_can_frame_t long_classic = frame(0x1, false, false, false, 9, 0);
    assert_int_equal(ps_candump_format(&long_classic, "can0", line, sizeof(line)), -EINVAL);
    ps_can_frame_t fd_len_9 = frame(0x1, false, true, false, 9, 0);
    assert_int_equal(ps_candump_format(&fd_len_9, "can0", line, sizeof(line)), -EINVAL);
    ps_can_frame_t brs_classic = frame(0x1, false, false, true, 1, 0);
    assert_int_equal(ps_candump_format(&brs_classic, "can0", line, sizeof(line)), -EINVAL);
}

/* ---- reading ---------------------------------------------------------- */

static void parse_ok(const char *line, ps_can_frame_t *f, char *ifname)
{
    char err[PS_ERR_MSG_LEN] = "";
    const int rc = ps_candump_parse(line, f, ifname, PS_CANDUMP_IFNAME_MAX, err, sizeof(err));
    if (rc != 0)
        fail_msg("\"%s\": %s", line, err);
}

static void test_parse_candump_lines_by_hand(void **state)
{
    (void)state;
    ps_can_frame_t f;
    char ifname[PS_CANDUMP_IFNAME_MAX];
    parse_ok("(1345212884.318850) can0 123#DEADBEEF\n", &f, ifname);
    assert_string_equal(ifname, "can0");
    assert_true(f.t_ns == 1345212884318850000LL);
    assert_int_equal(f.id, 0x123);
    assert_false(f.is_ext);
    assert_false(f.is_fd);
    assert_int_equal(f.len, 4);
    assert_memory_equal(f.data, "\xDE\xAD\xBE\xEF", 4);
    /* lower case and '.' between bytes, as cansend takes them; CRLF */
    parse_ok("(0000000001.000001) vcan1 0100fd01#de.ad.be.ef.00.01.02.03\r\n", &f, ifname);
    assert_string_equal(ifname, "vcan1");
    assert_true(f.t_ns == 1000001000LL);
    assert_int_equal(f.id, 0x0100FD01);
    assert_true(f.is_ext);
    assert_int_equal(f.len, 8);
    assert_memory_equal(f.data, "\xDE\xAD\xBE\xEF\x00\x01\x02\x03", 8);
    /* FD: BRS|ESI (3) keeps BRS; FDF alone (4, newer can-utils) is FD without BRS */
    parse_ok("(0000000002.000000) can2 123##3000102030405060708090A0B", &f, ifname);
    assert_true(f.is_fd);
    assert_true(f.is_brs);
    assert_int_equal(f.len, 12);
    assert_int_equal(f.data[11], 0x0B);
    parse_ok("(0000000002.000000) can2 123##4", &f, ifname);
    assert_true(f.is_fd);
    assert_false(f.is_brs);
    assert_int_equal(f.len, 0);
}

static void test_parse_round_trips_what_format_writes(void **state)
{
    (void)state;
    const ps_can_frame_t frames[] = {
        frame(0x000, false, false, false, 0, 0),
        frame(0x7FF, false, false, false, 8, 999999999999),
        frame(0x1FFFFFFF, true, false, false, 3, 5000),
        frame(0x12, true, true, true, 64, 1234567000),
        frame(0x12, false, true, false, 48, 1234567000),
    };
    for (size_t i = 0; i < sizeof(frames) / sizeof(frames[0]); i++) {
        char line[PS_CANDUMP_LINE_MAX];
        assert_true(ps_candump_format(&frames[i], "can3", line, sizeof(line)) > 0);
        ps_can_frame_t back;
        char ifname[PS_CANDUMP_IFNAME_MAX];
        parse_ok(line, &back, ifname);
        assert_string_equal(ifname, "can3");
        assert_int_equal(back.id, frames[i].id);
        assert_int_equal(back.is_ext, frames[i].is_ext);
        assert_int_equal(back.is_fd, frames[i].is_fd);
        assert_int_equal(back.is_brs, frames[i].is_brs);
        assert_int_equal(back.len, frames[i].len);
        assert_memory_equal(back.data, frames[i].data, frames[i].len);
        assert_true(back.t_ns == frames[i].t_ns / 1000 * 1000);
    }
}

static void assert_refused(const char *line, const char *column, const char *what)
{
    ps_can_frame_t f = frame(0x55, false, false, false, 1, 77);
    const ps_can_frame_t before = f;
    char ifname[PS_CANDUMP_IFNAME_MAX];
    char err[PS_ERR_MSG_LEN] = "";
    assert_int_equal(ps_candump_parse(line, &f, ifname, sizeof(ifname), err, sizeof(err)),
                     -PS_ERR_PROTOCOL);
    if (strncmp(err, column, strlen(column)) != 0 || strstr(err, what) == NULL)
        fail_msg("\"%s\": got \"%s\", want \"%s...%s\"", line, err, column, what);
    /* a refused line leaves the caller's frame as it was */
    assert_memory_equal(&f, &before, sizeof(f));
}

static void test_parse_refusals_name_column_and_problem(void **state)
{
    (void)state;
    assert_refused("1.000000 can0 123#00", "column 1:", "'(' expected");
    assert_refused("(1.5) can0 123#00", "column 5:", "six microsecond digits");
    assert_refused("(12345678901.000000) can0 123#00", "column 12:", "too many digits");
    assert_refused("(9999999999.000000) can0 123#00", "column 12:", "int64_t");
    assert_refused("(9223372036.854776) can0 123#00", "column 19:", "int64_t");
    assert_refused("(1.000000)can0 123#00", "column 11:", "space expected");
    assert_refused("(1.000000) abcdefghijklmnop 123#00", "column 27:", "longer than 15");
    assert_refused("(1.000000) can0 123#R", "column 21:", "remote frame");
    assert_refused("(1.000000) can0 20000080#0000000000000000", "column 17:", "error frame");
    assert_refused("(1.000000) can0 800#00", "column 17:", "above 0x7ff");
    assert_refused("(1.000000) can0 1234#00", "column 17:", "3 (11-bit) or 8 (29-bit)");
    assert_refused("(1.000000) can0 123456789#00", "column 25:", "longer than 8");
    assert_refused("(1.000000) can0 123:00", "column 20:", "'#' expected");
    assert_refused("(1.000000) can0 123#ABC", "column 23:", "two hex digits");
    assert_refused("(1.000000) can0 123#00 x", "column 23:", "two hex digits");
    assert_refused("(1.000000) can0 123#000102030405060708", "column 37:", "more than 8");
    assert_refused("(1.000000) can0 123##8", "column 22:", "flags nibble");
    assert_refused("(1.000000) can0 123##1000102030405060708", "column 41:", "carries 0..8, 12");
    /* Found by tests/fuzz/fuzz_candump: a name ps_candump_is_valid_ifname
     * refuses (and ps_candump_format would not write) was read. */
    assert_refused("(0000000001.376820) 8(0000000001a0n 02c003FD#7C70",
                   "column 22:", "'(' or a tab in the interface name");
    assert_refused("(1.000000) can\t0 123#00", "column 15:", "'(' or a tab");
}

/* ---- can-utils reads what the runtime writes ---------------------------- */

static void test_log2long_reads_formatted_lines(void **state)
{
    (void)state;
    char path[] = "/tmp/ps_candump_XXXXXX";
    const int fd = mkstemp(path);
    assert_true(fd >= 0);
    FILE *log = fdopen(fd, "w");
    assert_non_null(log);
    ps_can_frame_t a = frame(0x123, false, false, false, 4, 1500007000);
    memcpy(a.data, "\xDE\xAD\xBE\xEF", 4);
    const ps_can_frame_t frames[] = {a, frame(0x0200FD01, true, false, false, 8, 1500008000),
                                     frame(0x7FF, false, false, false, 0, 1700000000),
                                     frame(0x123, false, true, true, 12, 1600000000)};
    const char *want[] = {
        "(0000000001.500007)  can0       123   [4]  DE AD BE EF",
        "(0000000001.500008)  can0  0200FD01   [8]  00 11 22 33 44 55 66 77",
        "(0000000001.700000)  can0       7FF   [0]",
        "(0000000001.600000)  can0       123  [12]  00 11 22 33 44 55 66 77 88 99 AA BB",
    };
    for (size_t i = 0; i < 4; i++) {
        char line[PS_CANDUMP_LINE_MAX];
        assert_true(ps_candump_format(&frames[i], "can0", line, sizeof(line)) > 0);
        assert_int_equal(fputs(line, log) >= 0, 1);
    }
    assert_int_equal(fclose(log), 0);
    char cmd[128];
    snprintf(cmd, sizeof(cmd), "log2long < %s", path);
    FILE *p = popen(cmd, "r");
    assert_non_null(p);
    char out[4096];
    const size_t n = fread(out, 1, sizeof(out) - 1, p);
    out[n] = '\0';
    const int status = pclose(p);
    unlink(path);
    if (status != 0)
        fail_msg("log2long (can-utils) failed, status %d: is can-utils installed?\n%s", status,
                 out);
    const char *at = out;
    for (size_t i = 0; i < 4; i++) {
        const char *hit = strstr(at, want[i]);
        if (hit == NULL)
            fail_msg("log2long line %zu: want \"%s\" in:\n%s", i + 1, want[i], out);
        at = hit + strlen(want[i]);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_format_classical_11_bit_hand_line),
        cmocka_unit_test(test_format_29_bit_and_empty_payload_hand_lines),
        cmocka_unit_test(test_format_fd_flags_nibble_hand_lines),
        cmocka_unit_test(test_format_longest_line_fits_line_max),
        cmocka_unit_test(test_format_refuses_invalid_frames_and_names),
        cmocka_unit_test(test_parse_candump_lines_by_hand),
        cmocka_unit_test(test_parse_round_trips_what_format_writes),
        cmocka_unit_test(test_parse_refusals_name_column_and_problem),
        cmocka_unit_test(test_log2long_reads_formatted_lines),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
