/*
 * What the end-to-end tests judge in their sanitized build
 * (build/tests/san/<name>: ASan and UBSan, from the sanitized objects). The
 * same assertions run in both builds, except where ASan itself changes what
 * is measured; those are reported on a line of their own that starts with
 * PS_SAN_NOT_ASSERTED and says why, never passed in silence:
 *
 *  - page faults of the loop thread: ASan ignores mlockall (its shadow
 *    memory spans terabytes; the runtime does not lock or prefault under
 *    sanitizers), so the first touch of a page, or of its shadow, faults
 *    where the plain build faults nothing;
 *  - how fresh the camera's lists are in real time: the instrumented
 *    perception runs two to three times slower.
 *
 * Allocations, frees and locks of the loop thread are counted in both
 * builds (rt/ps_guard.h: interposed plain, ASan's allocator hooks here) and
 * asserted zero in both. tools/run-tests.sh counts the PS_SAN_NOT_ASSERTED
 * lines into its summary.
 *
 * In the sanitized build the command-line tests run the sanitized runtime
 * (tests/fakes/ps_cli.h), with ASAN_OPTIONS exitcode=66 (unless set) so that
 * a report in the child is an exit status no test expects.
 *
 * Threads: the test's. Allocation: none.
 */
#ifndef PS_SAN_H
#define PS_SAN_H

#include <stdbool.h>
#include <stdint.h>

#include "../../rt/ps_guard.h"

#define PS_SAN_NOT_ASSERTED "[ NOT ASSERTED ]"

/** Why a check is not asserted in the sanitized build. */
typedef enum {
    PS_SAN_PAGE_FAULTS, /**< the loop thread's page faults */
    PS_SAN_CPU_TIME,    /**< CPU time against a period or an age */
} ps_san_why_t;

/** @return true in a build with AddressSanitizer  @rt RT-SAFE */
bool ps_san_is_asan(void);

/* Each check below is a macro, so that a failure names the caller's line. */

/** Plain build: assert n == 0 (a failure names what and n). ASan build:
 *  print "PS_SAN_NOT_ASSERTED what: n (why)" and go on. */
#define ps_san_assert_zero(n, why, what) ps_san_assert_zero_at(n, why, what, __FILE__, __LINE__)
void ps_san_assert_zero_at(uint64_t n, ps_san_why_t why, const char *what, const char *file,
                           int line);

/** Plain build: assert is_ok (a failure names what). ASan build: print
 *  "PS_SAN_NOT_ASSERTED what: holds|does not hold (why)" and go on. */
#define ps_san_assert_true(is_ok, why, what)                                                       \
    ps_san_assert_true_at(is_ok, why, what, __FILE__, __LINE__)
void ps_san_assert_true_at(bool is_ok, ps_san_why_t why, const char *what, const char *file,
                           int line);

/** The loop thread after init: no allocation, free or lock (both builds),
 *  no page fault (plain build; reported under ASan). what names the span. */
#define ps_san_assert_guard_clean(c, what) ps_san_assert_guard_clean_at(c, what, __FILE__, __LINE__)
void ps_san_assert_guard_clean_at(const ps_guard_counts_t *c, const char *what, const char *file,
                                  int line);

/** A sanitizer's report in a child's captured output fails the test (the
 *  output's first 3000 characters on stderr). */
#define ps_san_assert_no_report(output) ps_san_assert_no_report_at(output, __FILE__, __LINE__)
void ps_san_assert_no_report_at(const char *output, const char *file, int line);

#endif /* PS_SAN_H */
