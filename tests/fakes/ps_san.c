#include "ps_san.h"

#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#if defined(__SANITIZE_ADDRESS__)
#define IS_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define IS_ASAN 1
#endif
#endif
#ifndef IS_ASAN
#define IS_ASAN 0
#endif

#if IS_ASAN
/* For the children only: this process read its options before main. A
 * report ends a child with 66 (ASan's default, 1, is an exit status the
 * runtime gives for a failed recording); LeakSanitizer's too. */
__attribute__((constructor)) static void set_child_options(void)
{
    (void)setenv("ASAN_OPTIONS", "exitcode=66:detect_leaks=1", 0); /* keep a caller's */
    (void)setenv("UBSAN_OPTIONS", "print_stacktrace=1:halt_on_error=1", 0);
}
#endif

bool ps_san_is_asan(void)
{
    return IS_ASAN;
}

static const char *reason(ps_san_why_t why)
{
    switch (why) {
    case PS_SAN_PAGE_FAULTS:
        return "ASan build: nothing locked or prefaulted (ASan ignores mlockall, its shadow "
               "spans terabytes), so first touches fault";
    case PS_SAN_CPU_TIME:
        return "ASan build: its code runs 2-3x slower";
    }
    return "?";
}

/* cmocka's fail_msg, at the caller's file and line */
#define FAIL_AT(file, line, ...)                                                                   \
    do {                                                                                           \
        print_error("ERROR: " __VA_ARGS__);                                                        \
        print_error("\n");                                                                         \
        _fail(file, line);                                                                         \
    } while (0)

void ps_san_assert_zero_at(uint64_t n, ps_san_why_t why, const char *what, const char *file,
                           int line)
{
    if (IS_ASAN) {
        print_message("%s %s: %llu (%s; the plain build asserts 0)\n", PS_SAN_NOT_ASSERTED, what,
                      (unsigned long long)n, reason(why));
        return;
    }
    if (n != 0)
        FAIL_AT(file, line, "%s: %llu, want 0", what, (unsigned long long)n);
}

void ps_san_assert_true_at(bool is_ok, ps_san_why_t why, const char *what, const char *file,
                           int line)
{
    if (IS_ASAN) {
        print_message("%s %s: %s (%s; the plain build asserts it)\n", PS_SAN_NOT_ASSERTED, what,
                      is_ok ? "holds" : "does not hold", reason(why));
        return;
    }
    if (!is_ok)
        FAIL_AT(file, line, "%s: does not hold", what);
}

void ps_san_assert_guard_clean_at(const ps_guard_counts_t *c, const char *what, const char *file,
                                  int line)
{
    if (!ps_guard_counts_allocs() || !ps_guard_counts_locks())
        FAIL_AT(file, line, "%s: this build's guard counts no allocations or locks", what);
    if (c->n_allocs != 0 || c->n_frees != 0 || c->n_locks != 0)
        FAIL_AT(file, line, "%s: %llu mallocs, %llu frees, %llu locks on the loop thread, want 0",
                what, (unsigned long long)c->n_allocs, (unsigned long long)c->n_frees,
                (unsigned long long)c->n_locks);
    char faults[160];
    snprintf(faults, sizeof(faults), "%s, page faults", what);
    ps_san_assert_zero_at(c->n_faults, PS_SAN_PAGE_FAULTS, faults, file, line);
}

void ps_san_assert_no_report_at(const char *output, const char *file, int line)
{
    static const char *const MARKS[] = {"ERROR: AddressSanitizer", "ERROR: LeakSanitizer",
                                        "runtime error: "};
    for (size_t i = 0; i < sizeof(MARKS) / sizeof(MARKS[0]); i++)
        if (strstr(output, MARKS[i]) != NULL) {
            /* stderr: cmocka cuts a message at 1 KiB */
            fprintf(stderr, "%.3000s\n", output);
            FAIL_AT(file, line, "a sanitizer's report (\"%s\") in the output above", MARKS[i]);
        }
}
