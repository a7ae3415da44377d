/*
 * Tests for the e-stop software debounce of drivers/ps_gpio_gpiod
 * (ps_gpio_debounce_*): hand-worked timelines of edges and polls, with a
 * 2 ms debounce (what the real boards use) unless a test says otherwise;
 * and the record button's rule (ps_gpio_button_pressed), case by case.
 * Times are ms from an arbitrary origin, written as integers of ns through
 * MS()/US(), so every boundary is exact.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <stdbool.h>

#include "../drivers/ps_gpio_gpiod.h"

#define US(x)    ((int64_t)(x)*1000LL)
#define MS(x)    ((int64_t)(x)*1000000LL)
#define DEBOUNCE MS(2)

/* poll at t, then take */
static bool take_at(ps_gpio_debounce_t *d, int64_t t_ns)
{
    ps_gpio_debounce_poll(d, t_ns);
    return ps_gpio_debounce_take_pressed(d);
}

static void test_debounce_press_counted_after_stable_time(void **state)
{
    (void)state;
    ps_gpio_debounce_t d;
    ps_gpio_debounce_init(&d, DEBOUNCE, false, MS(0));
    assert_false(take_at(&d, MS(5)));
    ps_gpio_debounce_edge(&d, true, MS(10));
    assert_false(take_at(&d, MS(10)));
    assert_false(take_at(&d, MS(11)));
    assert_false(take_at(&d, MS(12) - 1)); /* 1 ns short of the stable time */
    assert_true(take_at(&d, MS(12)));      /* held for exactly 2 ms */
    assert_true(take_at(&d, MS(13)));      /* still held: pressed now */
    assert_true(d.is_pressed);
}

static void test_debounce_glitch_ignored(void **state)
{
    (void)state;
    ps_gpio_debounce_t d;
    ps_gpio_debounce_init(&d, DEBOUNCE, false, MS(0));
    ps_gpio_debounce_edge(&d, true, MS(10));
    ps_gpio_debounce_edge(&d, false, MS(11)); /* 1 ms < 2 ms */
    assert_false(take_at(&d, MS(20)));
    /* 1 ns short of the debounce is still a glitch */
    ps_gpio_debounce_edge(&d, true, MS(30));
    ps_gpio_debounce_edge(&d, false, MS(32) - 1);
    assert_false(take_at(&d, MS(40)));
    assert_false(d.is_pressed);
}

/* A press that held long enough and was released between two reads is
 * reported by the next read, once, judged from the edges' own times. */
static void test_debounce_press_between_reads_latched_until_taken(void **state)
{
    (void)state;
    ps_gpio_debounce_t d;
    ps_gpio_debounce_init(&d, DEBOUNCE, false, MS(0));
    assert_false(take_at(&d, MS(1)));
    ps_gpio_debounce_edge(&d, true, MS(10));
    ps_gpio_debounce_edge(&d, false, MS(13)); /* held 3 ms */
    ps_gpio_debounce_poll(&d, MS(20));
    assert_false(d.is_pressed); /* released for 7 ms: not pressed now */
    assert_true(ps_gpio_debounce_take_pressed(&d));
    assert_false(take_at(&d, MS(21))); /* the latch was cleared */
}

/* Bouncing contact on press: 10.0 P, 10.3 R, 10.5 P, 10.9 R, 11.0 P, then
 * held. The last change is at 11.0, so the press counts at 13.0. */
static void test_debounce_bounce_on_press_counted_from_last_edge(void **state)
{
    (void)state;
    ps_gpio_debounce_t d;
    ps_gpio_debounce_init(&d, DEBOUNCE, false, MS(0));
    ps_gpio_debounce_edge(&d, true, US(10000));
    ps_gpio_debounce_edge(&d, false, US(10300));
    ps_gpio_debounce_edge(&d, true, US(10500));
    ps_gpio_debounce_edge(&d, false, US(10900));
    ps_gpio_debounce_edge(&d, true, US(11000));
    assert_false(take_at(&d, US(12000)));
    assert_false(take_at(&d, US(12999)));
    assert_true(take_at(&d, US(13000)));
}

/* Bouncing contact on release: held since start, 10.0 R, 10.4 P, 10.8 R,
 * then released. Pressed until 12.8, released from then on. */
static void test_debounce_bounce_on_release_needs_stable_time(void **state)
{
    (void)state;
    ps_gpio_debounce_t d;
    ps_gpio_debounce_init(&d, DEBOUNCE, true, MS(0));
    assert_true(take_at(&d, MS(1)));
    ps_gpio_debounce_edge(&d, false, US(10000));
    ps_gpio_debounce_edge(&d, true, US(10400));
    ps_gpio_debounce_edge(&d, false, US(10800));
    assert_true(take_at(&d, US(12000)));
    assert_true(take_at(&d, US(12799)));
    assert_false(take_at(&d, US(12800)));
    assert_false(take_at(&d, MS(20)));
}

/* A release shorter than the debounce does not end a press. */
static void test_debounce_release_glitch_ignored(void **state)
{
    (void)state;
    ps_gpio_debounce_t d;
    ps_gpio_debounce_init(&d, DEBOUNCE, true, MS(0));
    assert_true(take_at(&d, MS(1)));
    ps_gpio_debounce_edge(&d, false, MS(10));
    ps_gpio_debounce_edge(&d, true, US(11500));
    assert_true(take_at(&d, MS(20)));
    assert_true(d.is_pressed);
}

/* Held at start: the first take says pressed at once, with no wait for the
 * stable time (it has been held for longer than anyone can tell); a release
 * then needs the stable time like any other. */
static void test_debounce_held_at_start_counted_at_once(void **state)
{
    (void)state;
    ps_gpio_debounce_t d;
    ps_gpio_debounce_init(&d, DEBOUNCE, true, MS(100));
    assert_true(take_at(&d, MS(100)));
    ps_gpio_debounce_edge(&d, false, MS(101));
    assert_true(take_at(&d, MS(102)));
    assert_false(take_at(&d, MS(103)));

    /* Held at start and released before the first read: still reported. */
    ps_gpio_debounce_init(&d, DEBOUNCE, true, MS(0));
    ps_gpio_debounce_edge(&d, false, US(500));
    ps_gpio_debounce_poll(&d, MS(50));
    assert_true(ps_gpio_debounce_take_pressed(&d));
    assert_false(take_at(&d, MS(51)));
}

/* Debounce 0: every press edge counts at once, even one released 1 ns later;
 * releases count at once too. */
static void test_debounce_zero_first_edge_counts(void **state)
{
    (void)state;
    ps_gpio_debounce_t d;
    ps_gpio_debounce_init(&d, 0, false, MS(0));
    assert_false(take_at(&d, MS(1)));
    ps_gpio_debounce_edge(&d, true, MS(10));
    assert_true(d.is_pressed);
    assert_true(take_at(&d, MS(10)));
    ps_gpio_debounce_edge(&d, false, MS(11));
    assert_false(d.is_pressed);
    assert_false(take_at(&d, MS(11)));
    ps_gpio_debounce_edge(&d, true, MS(20));
    ps_gpio_debounce_edge(&d, false, MS(20) + 1);
    assert_true(take_at(&d, MS(21)));
    assert_false(take_at(&d, MS(22)));

    /* A negative debounce is taken as 0. */
    ps_gpio_debounce_init(&d, -5, false, MS(0));
    ps_gpio_debounce_edge(&d, true, MS(1));
    assert_true(take_at(&d, MS(1)));
}

/* The same level twice (a repeated event, or the level check after an event
 * it already brought) does not restart the stable time. */
static void test_debounce_repeated_level_no_restart(void **state)
{
    (void)state;
    ps_gpio_debounce_t d;
    ps_gpio_debounce_init(&d, DEBOUNCE, false, MS(0));
    ps_gpio_debounce_edge(&d, true, MS(10));
    ps_gpio_debounce_edge(&d, true, MS(11));
    assert_true(take_at(&d, MS(12)));
    ps_gpio_debounce_edge(&d, false, MS(20));
    ps_gpio_debounce_edge(&d, false, MS(21));
    assert_true(take_at(&d, MS(21)));
    assert_false(take_at(&d, MS(22)));
}

/* An edge stamped before a poll already made (read late) counts as seen at
 * that poll: time never goes backwards, and no decision is undone. */
static void test_debounce_late_edge_taken_at_latest_time(void **state)
{
    (void)state;
    ps_gpio_debounce_t d;
    ps_gpio_debounce_init(&d, DEBOUNCE, false, MS(0));
    assert_false(take_at(&d, MS(20)));
    ps_gpio_debounce_edge(&d, true, MS(15)); /* taken as 20 */
    assert_false(take_at(&d, MS(21)));
    assert_true(take_at(&d, MS(22)));
}

/* Edges alone (no poll between them) judge a press by their own times. */
static void test_debounce_press_judged_at_next_edge(void **state)
{
    (void)state;
    ps_gpio_debounce_t d;
    ps_gpio_debounce_init(&d, DEBOUNCE, false, MS(0));
    ps_gpio_debounce_edge(&d, true, MS(10));
    ps_gpio_debounce_edge(&d, false, MS(12)); /* exactly 2 ms: counts */
    assert_true(d.is_latched);
    assert_true(d.is_pressed); /* the release itself needs its 2 ms */
    ps_gpio_debounce_edge(&d, true, MS(13));
    assert_true(ps_gpio_debounce_take_pressed(&d));
}

/* ---- the record button's rule (ps_gpio_button_pressed) ------------------ */

static void test_button_level_or_a_first_edge_after_released_is_a_press(void **state)
{
    (void)state;
    assert_false(ps_gpio_button_pressed(false, false, 0, 0)); /* nothing happened */
    assert_true(ps_gpio_button_pressed(true, true, 0, 0));    /* held */
    assert_true(ps_gpio_button_pressed(true, false, 1, 0));   /* pressed since */
    assert_true(ps_gpio_button_pressed(false, false, 1, 0));  /* a press edge, released again */
    assert_false(ps_gpio_button_pressed(false, true, 1, 0));  /* the release of a reported press */
    assert_true(ps_gpio_button_pressed(false, true, 2, 0));   /* released, pressed, released */
}

/* The CI case: a release edge stamped before the read that saw the button
 * released arrives only at the next read. Not a new press. */
static void test_button_one_late_edge_is_no_press(void **state)
{
    (void)state;
    assert_false(ps_gpio_button_pressed(false, false, 0, 1));
    assert_true(ps_gpio_button_pressed(true, true, 0, 1)); /* held: still pressed */
}

/* A press and release both between two reads, both queued after the second
 * read (which saw the button released): reported at the read that gets
 * them, not lost. */
static void test_button_two_late_edges_are_a_press(void **state)
{
    (void)state;
    assert_true(ps_gpio_button_pressed(false, false, 0, 2));
    assert_true(ps_gpio_button_pressed(false, false, 0, 3));
    assert_false(ps_gpio_button_pressed(false, true, 1, 1)); /* a late press, then its release */
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_debounce_press_counted_after_stable_time),
        cmocka_unit_test(test_debounce_glitch_ignored),
        cmocka_unit_test(test_debounce_press_between_reads_latched_until_taken),
        cmocka_unit_test(test_debounce_bounce_on_press_counted_from_last_edge),
        cmocka_unit_test(test_debounce_bounce_on_release_needs_stable_time),
        cmocka_unit_test(test_debounce_release_glitch_ignored),
        cmocka_unit_test(test_debounce_held_at_start_counted_at_once),
        cmocka_unit_test(test_debounce_zero_first_edge_counts),
        cmocka_unit_test(test_debounce_repeated_level_no_restart),
        cmocka_unit_test(test_debounce_late_edge_taken_at_latest_time),
        cmocka_unit_test(test_debounce_press_judged_at_next_edge),
        cmocka_unit_test(test_button_level_or_a_first_edge_after_released_is_a_press),
        cmocka_unit_test(test_button_one_late_edge_is_no_press),
        cmocka_unit_test(test_button_two_late_edges_are_a_press),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
