/*
 * Tests of ps_ring: argument checks, order, full/empty, and a two-thread
 * stress test.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>

#include "../rt/ps_ring.h"

typedef struct {
    uint64_t seq;
    uint64_t check; /* ~seq * odd constant: a torn record would not match */
    uint32_t pad[3];
} rec_t;

static uint64_t check_of(uint64_t seq)
{
    return ~seq * 0x9e3779b97f4a7c15ull;
}

static void test_ps_ring_init_bad_args_einval(void **state)
{
    (void)state;
    ps_ring_t r;
    rec_t storage[8];
    assert_int_equal(ps_ring_init(&r, storage, 0, sizeof(rec_t)), -EINVAL);
    assert_int_equal(ps_ring_init(&r, storage, 1, sizeof(rec_t)), -EINVAL);
    assert_int_equal(ps_ring_init(&r, storage, 3, sizeof(rec_t)), -EINVAL);
    assert_int_equal(ps_ring_init(&r, storage, 6, sizeof(rec_t)), -EINVAL);
    assert_int_equal(ps_ring_init(&r, storage, 0x80000001u, sizeof(rec_t)), -EINVAL);
    assert_int_equal(ps_ring_init(&r, storage, 0xffffffffu, sizeof(rec_t)), -EINVAL);
    assert_int_equal(ps_ring_init(&r, storage, 8, 0), -EINVAL);
    assert_int_equal(ps_ring_init(&r, NULL, 8, sizeof(rec_t)), -EINVAL);
    assert_int_equal(ps_ring_init(NULL, storage, 8, sizeof(rec_t)), -EINVAL);
    assert_int_equal(ps_ring_init(&r, storage, 2, sizeof(rec_t)), 0);
    assert_int_equal(ps_ring_init(&r, storage, 8, sizeof(rec_t)), 0);
}

static void test_ps_ring_push_pop_fifo_order(void **state)
{
    (void)state;
    ps_ring_t r;
    rec_t storage[4];
    assert_int_equal(ps_ring_init(&r, storage, 4, sizeof(rec_t)), 0);
    /* Several laps, so slots wrap around. */
    uint64_t next_in = 0, next_out = 0;
    for (int lap = 0; lap < 10; lap++) {
        for (int i = 0; i < 3; i++) {
            const rec_t in = {.seq = next_in, .check = check_of(next_in)};
            assert_int_equal(ps_ring_push(&r, &in), 0);
            next_in++;
        }
        assert_int_equal(ps_ring_count(&r), 3);
        for (int i = 0; i < 3; i++) {
            rec_t out;
            assert_int_equal(ps_ring_pop(&r, &out), 0);
            assert_int_equal(out.seq, next_out);
            assert_true(out.check == check_of(next_out));
            next_out++;
        }
        assert_int_equal(ps_ring_count(&r), 0);
    }
    assert_int_equal(ps_ring_dropped(&r), 0);
}

static void test_ps_ring_push_full_eagain_dropped(void **state)
{
    (void)state;
    ps_ring_t r;
    rec_t storage[4];
    assert_int_equal(ps_ring_init(&r, storage, 4, sizeof(rec_t)), 0);
    for (uint64_t i = 0; i < 4; i++) {
        const rec_t in = {.seq = i};
        assert_int_equal(ps_ring_push(&r, &in), 0);
    }
    assert_int_equal(ps_ring_count(&r), 4);
    const rec_t extra = {.seq = 99};
    assert_int_equal(ps_ring_push(&r, &extra), -EAGAIN);
    assert_int_equal(ps_ring_push(&r, &extra), -EAGAIN);
    assert_int_equal(ps_ring_dropped(&r), 2);
    /* The refused records did not overwrite anything. */
    for (uint64_t i = 0; i < 4; i++) {
        rec_t out;
        assert_int_equal(ps_ring_pop(&r, &out), 0);
        assert_int_equal(out.seq, i);
    }
    /* Room again after popping. */
    assert_int_equal(ps_ring_push(&r, &extra), 0);
    assert_int_equal(ps_ring_dropped(&r), 2);
}

static void test_ps_ring_pop_empty_eagain(void **state)
{
    (void)state;
    ps_ring_t r;
    rec_t storage[2];
    assert_int_equal(ps_ring_init(&r, storage, 2, sizeof(rec_t)), 0);
    rec_t out = {.seq = 1234};
    assert_int_equal(ps_ring_pop(&r, &out), -EAGAIN);
    assert_int_equal(out.seq, 1234); /* untouched */
    const rec_t in = {.seq = 7};
    assert_int_equal(ps_ring_push(&r, &in), 0);
    assert_int_equal(ps_ring_pop(&r, &out), 0);
    assert_int_equal(ps_ring_pop(&r, &out), -EAGAIN);
}

#define STRESS_N     1000000u
#define STRESS_SLOTS 16u

typedef struct {
    ps_ring_t ring;
    rec_t storage[STRESS_SLOTS];
    atomic_bool is_done;
    uint64_t n_pushed_ok;
} stress_t;

static void *producer(void *arg)
{
    stress_t *s = arg;
    for (uint64_t i = 0; i < STRESS_N; i++) {
        const rec_t in = {.seq = i, .check = check_of(i)};
        if (ps_ring_push(&s->ring, &in) == 0)
            s->n_pushed_ok++;
    }
    atomic_store_explicit(&s->is_done, true, memory_order_release);
    return NULL;
}

static void test_ps_ring_two_threads_ordered_nothing_lost(void **state)
{
    (void)state;
    static stress_t s;
    assert_int_equal(ps_ring_init(&s.ring, s.storage, STRESS_SLOTS, sizeof(rec_t)), 0);
    atomic_init(&s.is_done, false);
    s.n_pushed_ok = 0;
    pthread_t th;
    assert_int_equal(pthread_create(&th, NULL, producer, &s), 0);
    uint64_t n_received = 0, n_bad = 0;
    int64_t last = -1;
    for (;;) {
        /* Read is_done before popping, so a record pushed before done is
         * still drained by the pop that follows. */
        const bool is_done = atomic_load_explicit(&s.is_done, memory_order_acquire);
        rec_t out;
        if (ps_ring_pop(&s.ring, &out) == 0) {
            if ((int64_t)out.seq <= last || out.check != check_of(out.seq))
                n_bad++;
            last = (int64_t)out.seq;
            n_received++;
        } else if (is_done) {
            break;
        }
    }
    assert_int_equal(pthread_join(th, NULL), 0);
    assert_int_equal(n_bad, 0);
    assert_int_equal(n_received, s.n_pushed_ok);
    assert_int_equal(n_received + ps_ring_dropped(&s.ring), STRESS_N);
    assert_true(n_received > 0);
    print_message("      received %llu, dropped %llu\n", (unsigned long long)n_received,
                  (unsigned long long)ps_ring_dropped(&s.ring));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ps_ring_init_bad_args_einval),
        cmocka_unit_test(test_ps_ring_push_pop_fifo_order),
        cmocka_unit_test(test_ps_ring_push_full_eagain_dropped),
        cmocka_unit_test(test_ps_ring_pop_empty_eagain),
        cmocka_unit_test(test_ps_ring_two_threads_ordered_nothing_lost),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
