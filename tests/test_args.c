/*
 * ps_args: the seconds every subcommand's options take.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <math.h>

#include "../rt/ps_args.h"

static void test_args_seconds_accepts_numbers_in_range(void **state)
{
    (void)state;
    double v = -1.0;
    assert_int_equal(ps_args_seconds("0", 0.0, 10.0, false, &v), 0);
    assert_true(v == 0.0);
    assert_int_equal(ps_args_seconds("2.5", 0.0, 10.0, false, &v), 0);
    assert_true(v == 2.5);
    assert_int_equal(ps_args_seconds("1e1", 0.0, 10.0, false, &v), 0); /* the bound itself */
    assert_true(v == 10.0);
    assert_int_equal(ps_args_seconds(".5", 0.0, 10.0, true, &v), 0);
    assert_true(v == 0.5);
}

static void test_args_seconds_refuses_junk_and_leaves_out_alone(void **state)
{
    (void)state;
    static const char *const BAD[] = {"",    " ",   "abc",  "1s",    "1.5 ", "--1",
                                      "nan", "inf", "-inf", "1e999", "0x",   "1,5"};
    for (size_t i = 0; i < sizeof(BAD) / sizeof(BAD[0]); i++) {
        double v = 42.0;
        assert_int_equal(ps_args_seconds(BAD[i], 0.0, 1e9, false, &v), -EINVAL);
        assert_true(v == 42.0);
    }
    double v = 0.0;
    assert_int_equal(ps_args_seconds(NULL, 0.0, 1.0, false, &v), -EINVAL);
    assert_int_equal(ps_args_seconds("1", 0.0, 1.0, false, NULL), -EINVAL);
}

static void test_args_seconds_range_and_open_minimum(void **state)
{
    (void)state;
    double v = 42.0;
    assert_int_equal(ps_args_seconds("-0.001", 0.0, 10.0, false, &v), -EINVAL);
    assert_int_equal(ps_args_seconds("10.001", 0.0, 10.0, false, &v), -EINVAL);
    assert_int_equal(ps_args_seconds("0", 0.0, 10.0, true, &v), -EINVAL); /* (0, 10] */
    assert_true(v == 42.0);
    assert_int_equal(ps_args_seconds("0", 0.0, 10.0, false, &v), 0); /* [0, 10] */
    assert_true(v == 0.0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_args_seconds_accepts_numbers_in_range),
        cmocka_unit_test(test_args_seconds_refuses_junk_and_leaves_out_alone),
        cmocka_unit_test(test_args_seconds_range_and_open_minimum),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
