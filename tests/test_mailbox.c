/*
 * Tests of ps_mailbox: argument checks, a read before any publish, newest
 * wins, neither side waits for the other (a writer that keeps its slot, a
 * reader that keeps its value), and two threads: a fast writer with a slow
 * reader and the reverse, checking that no value is ever torn, sequence
 * numbers never go back and the last value published is the one read at the
 * end. The same file is also built with ThreadSanitizer (make test runs
 * build/tests/tsan/test_mailbox), which checks the atomics' orders.
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
#include <string.h>
#include <time.h>

#include "../rt/ps_mailbox.h"
#include "../rt/ps_neighbours.h"

/* A value as big as the loop's neighbour list, every word derived from seq:
 * a torn value (half old, half new) fails check(). */
#define N_WORDS (sizeof(ps_neighbours_t) / sizeof(uint64_t))

typedef struct {
    uint64_t seq;
    uint64_t word[N_WORDS];
} val_t;

static uint64_t word_of(uint64_t seq, size_t i)
{
    return (seq + 1u) * 0x9e3779b97f4a7c15ull ^ (uint64_t)i * 0xbf58476d1ce4e5b9ull;
}

static void fill(val_t *v, uint64_t seq)
{
    v->seq = seq;
    for (size_t i = 0; i < N_WORDS; i++)
        v->word[i] = word_of(seq, i);
}

/* Whole: every word matches seq; or the all-zero value of an empty mailbox. */
static bool is_whole(const val_t *v)
{
    const val_t zero = {0};
    if (memcmp(v, &zero, sizeof(zero)) == 0)
        return true;
    for (size_t i = 0; i < N_WORDS; i++)
        if (v->word[i] != word_of(v->seq, i))
            return false;
    return true;
}

static void sleep_ns(long ns)
{
    const struct timespec ts = {0, ns};
    nanosleep(&ts, NULL);
}

static void test_ps_mailbox_init_bad_args_einval(void **state)
{
    (void)state;
    ps_mailbox_t mb;
    val_t storage[PS_MAILBOX_SLOTS];
    assert_int_equal(ps_mailbox_init(NULL, storage, sizeof(val_t)), -EINVAL);
    assert_int_equal(ps_mailbox_init(&mb, NULL, sizeof(val_t)), -EINVAL);
    assert_int_equal(ps_mailbox_init(&mb, storage, 0), -EINVAL);
    assert_int_equal(ps_mailbox_init(&mb, storage, sizeof(val_t)), 0);
}

static void test_ps_mailbox_read_before_publish_zero_not_new(void **state)
{
    (void)state;
    ps_mailbox_t mb;
    val_t storage[PS_MAILBOX_SLOTS];
    memset(storage, 0xa5, sizeof(storage));
    assert_int_equal(ps_mailbox_init(&mb, storage, sizeof(val_t)), 0);
    bool is_new = true;
    const val_t *v = ps_mailbox_read(&mb, &is_new);
    assert_false(is_new);
    const val_t zero = {0};
    assert_memory_equal(v, &zero, sizeof(zero));
    assert_int_equal(ps_mailbox_n_published(&mb), 0);
    assert_int_equal(ps_mailbox_n_taken(&mb), 0);
}

static void test_ps_mailbox_read_after_many_publishes_newest_wins(void **state)
{
    (void)state;
    ps_mailbox_t mb;
    val_t storage[PS_MAILBOX_SLOTS];
    assert_int_equal(ps_mailbox_init(&mb, storage, sizeof(val_t)), 0);
    val_t v;
    for (uint64_t s = 1; s <= 5; s++) {
        fill(&v, s);
        ps_mailbox_put(&mb, &v);
    }
    bool is_new = false;
    const val_t *r = ps_mailbox_read(&mb, &is_new);
    assert_true(is_new);
    assert_int_equal(r->seq, 5);
    assert_true(is_whole(r));
    /* Nothing new since: the same value, not new. */
    r = ps_mailbox_read(&mb, &is_new);
    assert_false(is_new);
    assert_int_equal(r->seq, 5);
    assert_int_equal(ps_mailbox_n_published(&mb), 5);
    assert_int_equal(ps_mailbox_n_taken(&mb), 1); /* 4 were replaced unread */
    /* Alternating one publish, one read: every value is taken. */
    for (uint64_t s = 6; s <= 20; s++) {
        fill(&v, s);
        ps_mailbox_put(&mb, &v);
        r = ps_mailbox_read(&mb, &is_new);
        assert_true(is_new);
        assert_int_equal(r->seq, s);
    }
}

/* The writer takes its slot and stops half-way (a stalled producer): the
 * reader still gets the last published value at once, again and again. */
static void test_ps_mailbox_read_while_writer_stalled_returns_last(void **state)
{
    (void)state;
    ps_mailbox_t mb;
    val_t storage[PS_MAILBOX_SLOTS];
    assert_int_equal(ps_mailbox_init(&mb, storage, sizeof(val_t)), 0);
    val_t v;
    fill(&v, 7);
    ps_mailbox_put(&mb, &v);
    val_t *w = ps_mailbox_write_slot(&mb);
    fill(w, 8);
    w->word[0] = 0; /* half-written, never published */
    for (int i = 0; i < 3; i++) {
        const val_t *r = ps_mailbox_read(&mb, NULL);
        assert_ptr_not_equal(r, w);
        assert_int_equal(r->seq, 7);
        assert_true(is_whole(r));
    }
}

/* The reader holds a value (a slow consumer): the writer publishes on
 * without waiting, never into the reader's slot. */
static void test_ps_mailbox_publish_while_reader_holds_never_touches_it(void **state)
{
    (void)state;
    ps_mailbox_t mb;
    val_t storage[PS_MAILBOX_SLOTS];
    assert_int_equal(ps_mailbox_init(&mb, storage, sizeof(val_t)), 0);
    val_t v;
    fill(&v, 1);
    ps_mailbox_put(&mb, &v);
    const val_t *held = ps_mailbox_read(&mb, NULL);
    val_t copy = *held;
    for (uint64_t s = 2; s <= 1000; s++) {
        val_t *w = ps_mailbox_write_slot(&mb);
        assert_ptr_not_equal(w, held);
        fill(w, s);
        ps_mailbox_publish(&mb);
    }
    assert_memory_equal(held, &copy, sizeof(copy));
    bool is_new = false;
    const val_t *r = ps_mailbox_read(&mb, &is_new);
    assert_true(is_new);
    assert_int_equal(r->seq, 1000);
}

typedef struct {
    ps_mailbox_t mb;
    val_t storage[PS_MAILBOX_SLOTS];
    uint64_t n_values;    /* writer publishes 1..n_values */
    long writer_pause_ns; /* between publishes (0: none) */
    long reader_pause_ns; /* between reads (0: none) */
    atomic_bool is_writer_done;
    /* reader results */
    uint64_t n_reads, n_new, n_torn, n_backwards, last_seq;
} pair_t;

static void *writer_main(void *arg)
{
    pair_t *p = arg;
    for (uint64_t s = 1; s <= p->n_values; s++) {
        fill(ps_mailbox_write_slot(&p->mb), s);
        ps_mailbox_publish(&p->mb);
        if (p->writer_pause_ns > 0)
            sleep_ns(p->writer_pause_ns);
    }
    atomic_store(&p->is_writer_done, true);
    return NULL;
}

static void reader_loop(pair_t *p)
{
    uint64_t prev = 0;
    bool is_done = false;
    while (!is_done) {
        is_done = atomic_load(&p->is_writer_done); /* one more read after the end */
        bool is_new = false;
        const val_t *r = ps_mailbox_read(&p->mb, &is_new);
        p->n_reads++;
        p->n_new += is_new;
        p->n_torn += !is_whole(r);
        p->n_backwards += r->seq < prev || (is_new && r->seq == prev);
        prev = r->seq;
        if (p->reader_pause_ns > 0)
            sleep_ns(p->reader_pause_ns);
    }
    p->last_seq = prev;
}

static void run_pair(pair_t *p)
{
    assert_int_equal(ps_mailbox_init(&p->mb, p->storage, sizeof(val_t)), 0);
    atomic_init(&p->is_writer_done, false);
    pthread_t th;
    assert_int_equal(pthread_create(&th, NULL, writer_main, p), 0);
    reader_loop(p);
    assert_int_equal(pthread_join(th, NULL), 0);
    assert_int_equal(p->n_torn, 0);
    assert_int_equal(p->n_backwards, 0);
    assert_int_equal(p->last_seq, p->n_values); /* the newest value wins */
    assert_int_equal(ps_mailbox_n_published(&p->mb), p->n_values);
    assert_int_equal(ps_mailbox_n_taken(&p->mb), p->n_new);
}

static void test_ps_mailbox_fast_writer_slow_reader_newest_no_tear(void **state)
{
    (void)state;
    static pair_t p;
    memset(&p, 0, sizeof(p));
    p.n_values = 200000;
    p.reader_pause_ns = 50000; /* 50 us: the writer laps the reader many times */
    run_pair(&p);
    assert_true(p.n_new < p.n_values); /* values were replaced unread */
}

static void test_ps_mailbox_slow_writer_fast_reader_never_twice_no_tear(void **state)
{
    (void)state;
    static pair_t p;
    memset(&p, 0, sizeof(p));
    p.n_values = 300;
    p.writer_pause_ns = 200000; /* 200 us between values; the reader spins */
    run_pair(&p);
    assert_true(p.n_reads > p.n_new); /* reads that found nothing new returned the last */
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ps_mailbox_init_bad_args_einval),
        cmocka_unit_test(test_ps_mailbox_read_before_publish_zero_not_new),
        cmocka_unit_test(test_ps_mailbox_read_after_many_publishes_newest_wins),
        cmocka_unit_test(test_ps_mailbox_read_while_writer_stalled_returns_last),
        cmocka_unit_test(test_ps_mailbox_publish_while_reader_holds_never_touches_it),
        cmocka_unit_test(test_ps_mailbox_fast_writer_slow_reader_newest_no_tear),
        cmocka_unit_test(test_ps_mailbox_slow_writer_fast_reader_never_twice_no_tear),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
