/*
 * Tests of ps_guard, built twice: plain (build/tests/test_guard), where the
 * guard interposes malloc & co. and the lock calls, and with ASan and UBSan
 * (build/tests/san/test_guard), where ASan owns malloc and the guard counts
 * through ASan's allocator hooks (the lock calls interposed as in the plain
 * build). The counts are the same in both except where a test says so.
 *
 * Allocations go through volatile function pointers so the compiler cannot
 * elide a malloc/free pair or fold calloc into malloc + memset. Nothing
 * between arm and disarm may allocate, so the asserts come after disarm.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <malloc.h>
#include <pthread.h>
#include <semaphore.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include "../rt/ps_guard.h"

#if defined(__SANITIZE_ADDRESS__)
#define IS_ASAN 1
#else
#define IS_ASAN 0
#endif

static void *(*volatile p_malloc)(size_t) = malloc;
static void *(*volatile p_calloc)(size_t, size_t) = calloc;
static void *(*volatile p_realloc)(void *, size_t) = realloc;
static void (*volatile p_free)(void *) = free;
static int (*volatile p_posix_memalign)(void **, size_t, size_t) = posix_memalign;
static void *(*volatile p_aligned_alloc)(size_t, size_t) = aligned_alloc;
static void *(*volatile p_memalign)(size_t, size_t) = memalign;
static void *(*volatile p_valloc)(size_t) = valloc;
static void *(*volatile p_pvalloc)(size_t) = pvalloc;
static char *(*volatile p_strdup)(const char *) = strdup;

static int (*volatile p_mutex_lock)(pthread_mutex_t *) = pthread_mutex_lock;
static int (*volatile p_mutex_trylock)(pthread_mutex_t *) = pthread_mutex_trylock;
static int (*volatile p_mutex_timedlock)(pthread_mutex_t *,
                                         const struct timespec *) = pthread_mutex_timedlock;
static int (*volatile p_rwlock_rdlock)(pthread_rwlock_t *) = pthread_rwlock_rdlock;
static int (*volatile p_rwlock_wrlock)(pthread_rwlock_t *) = pthread_rwlock_wrlock;
static int (*volatile p_rwlock_tryrdlock)(pthread_rwlock_t *) = pthread_rwlock_tryrdlock;
static int (*volatile p_rwlock_trywrlock)(pthread_rwlock_t *) = pthread_rwlock_trywrlock;
static int (*volatile p_sem_wait)(sem_t *) = sem_wait;
static int (*volatile p_sem_trywait)(sem_t *) = sem_trywait;
static int (*volatile p_sem_timedwait)(sem_t *, const struct timespec *) = sem_timedwait;

static size_t page_size(void)
{
    return (size_t)sysconf(_SC_PAGESIZE);
}

/* Plain and under ASan alike (hooks installed): if this fails, every alloc
 * test below is meaningless. */
static void test_ps_guard_counts_allocs_true_plain_and_under_asan(void **state)
{
    (void)state;
    assert_true(ps_guard_counts_allocs());
}

static void test_ps_guard_is_armed_follows_arm_pause_disarm(void **state)
{
    (void)state;
    ps_guard_counts_t c;
    assert_false(ps_guard_is_armed());
    ps_guard_arm();
    assert_true(ps_guard_is_armed());
    ps_guard_pause();
    assert_false(ps_guard_is_armed());
    ps_guard_pause(); /* not nestable: no effect */
    ps_guard_resume();
    assert_true(ps_guard_is_armed());
    ps_guard_resume(); /* without pause: no effect */
    assert_true(ps_guard_is_armed());
    ps_guard_disarm(&c);
    assert_false(ps_guard_is_armed());
    ps_guard_pause(); /* disarmed: no effect */
    ps_guard_resume();
    assert_false(ps_guard_is_armed());
}

static void test_ps_guard_arm_malloc_calloc_realloc_free_counted_exactly(void **state)
{
    (void)state;
    ps_guard_counts_t c;
    ps_guard_arm();
    void *a = p_malloc(100);
    void *b = p_calloc(4, 32);
    a = p_realloc(a, 5000);
    void *d = p_realloc(NULL, 10); /* realloc as malloc: one call, one alloc */
    p_free(a);
    p_free(b);
    p_free(d);
    p_free(NULL);
    ps_guard_disarm(&c);
    assert_non_null(a);
    assert_non_null(b);
    assert_int_equal(c.n_allocs, 4);
    /* Plain: four free calls, free(NULL) included. ASan: the realloc that
     * moved a is an allocation and a free, and free(NULL) reaches no hook. */
    assert_int_equal(c.n_frees, IS_ASAN ? 1 + 3 : 4);
}

static void test_ps_guard_arm_aligned_allocs_counted(void **state)
{
    (void)state;
    ps_guard_counts_t c;
    void *p[5] = {0};
    void *untouched = (void *)0x1;
    ps_guard_arm();
    const int rc_ok = p_posix_memalign(&p[0], 64, 100);
    /* A bad alignment: the guard's own posix_memalign refuses it (counted:
     * the loop asked). Under ASan there is no guard posix_memalign to test
     * and ASan reports the call as an error, so it is not made. */
    int rc_bad = EINVAL;
    if (!IS_ASAN)
        rc_bad = p_posix_memalign(&untouched, 3, 100);
    p[1] = p_aligned_alloc(128, 256);
    p[2] = p_memalign(256, 10);
    p[3] = p_valloc(10);
    p[4] = p_pvalloc(10);
    for (int i = 0; i < 5; i++)
        p_free(p[i]);
    ps_guard_disarm(&c);
    assert_int_equal(rc_ok, 0);
    if (IS_ASAN)
        print_message("      ASan build: the guard's posix_memalign refusal of a bad alignment "
                      "is not built, not tested here (the plain build tests it)\n");
    assert_int_equal(rc_bad, EINVAL);
    assert_ptr_equal(untouched, (void *)0x1);
    assert_int_equal((uintptr_t)p[0] % 64, 0);
    assert_int_equal((uintptr_t)p[1] % 128, 0);
    assert_int_equal((uintptr_t)p[2] % 256, 0);
    assert_int_equal((uintptr_t)p[3] % page_size(), 0);
    assert_int_equal((uintptr_t)p[4] % page_size(), 0);
    assert_int_equal(c.n_allocs, IS_ASAN ? 5 : 6);
    assert_int_equal(c.n_frees, 5);
}

/* glibc's own internal mallocs are interposed too: strdup is counted. */
static void test_ps_guard_arm_libc_internal_malloc_counted(void **state)
{
    (void)state;
    ps_guard_counts_t c;
    ps_guard_arm();
    char *s = p_strdup("pushstep");
    p_free(s);
    ps_guard_disarm(&c);
    assert_string_equal(s == NULL ? "" : "ok", "ok");
    assert_int_equal(c.n_allocs, 1);
    assert_int_equal(c.n_frees, 1);
}

static void test_ps_guard_pause_excludes_allocs(void **state)
{
    (void)state;
    ps_guard_counts_t c, mid;
    ps_guard_arm();
    void *a = p_malloc(10);
    ps_guard_pause();
    for (int i = 0; i < 3; i++)
        p_free(p_malloc(64));
    ps_guard_resume();
    ps_guard_read(&mid); /* stays armed */
    p_free(a);
    ps_guard_disarm(&c);
    assert_int_equal(mid.n_allocs, 1);
    assert_int_equal(mid.n_frees, 0);
    assert_int_equal(c.n_allocs, 1);
    assert_int_equal(c.n_frees, 1);
}

static void test_ps_guard_disarm_then_allocs_not_counted(void **state)
{
    (void)state;
    ps_guard_counts_t c, c2;
    ps_guard_arm();
    p_free(p_malloc(8));
    ps_guard_disarm(&c);
    p_free(p_malloc(8)); /* disarmed */
    ps_guard_read(&c2);
    assert_int_equal(c.n_allocs, 1);
    assert_int_equal(c2.n_allocs, 1); /* read after disarm: the frozen counts */
    ps_guard_arm();                   /* re-arm zeroes */
    ps_guard_disarm(&c);
    assert_int_equal(c.n_allocs, 0);
    assert_int_equal(c.n_frees, 0);
}

typedef struct {
    sem_t go, done;
    size_t n_pages;
    ps_guard_counts_t own; /* the worker's own counts, armed around its second round */
} worker_t;

static void *worker(void *arg)
{
    worker_t *w = arg;
    for (int round = 0; round < 3; round++) {
        if (sem_wait(&w->go) != 0)
            return NULL;
        if (round == 2)
            ps_guard_arm();
        for (int i = 0; i < 10; i++)
            p_free(p_malloc(32));
        const size_t len = w->n_pages * page_size();
        unsigned char *m =
            mmap(NULL, len, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
        if (m != MAP_FAILED) {
            for (size_t off = 0; off < len; off += page_size())
                ((volatile unsigned char *)m)[off] = 1;
            (void)munmap(m, len);
        }
        if (round == 2)
            ps_guard_disarm(&w->own);
        if (sem_post(&w->done) != 0)
            return NULL;
    }
    return NULL;
}

/* Another (unarmed) thread's allocations and faults are not the armed
 * thread's; an armed worker counts its own. */
static void test_ps_guard_arm_other_thread_not_counted(void **state)
{
    (void)state;
    if (getenv("PS_QEMU_USER") != NULL)
        skip(); /* under qemu-user (tools/test-aarch64.sh) the faults are the emulator's */
    static worker_t w;
    w.n_pages = 32;
    assert_int_equal(sem_init(&w.go, 0, 0), 0);
    assert_int_equal(sem_init(&w.done, 0, 0), 0);
    pthread_t th;
    assert_int_equal(pthread_create(&th, NULL, worker, &w), 0);
    /* Round 0 warms up the handshake code paths (their first use faults). */
    assert_int_equal(sem_post(&w.go), 0);
    assert_int_equal(sem_wait(&w.done), 0);

    ps_guard_counts_t c;
    ps_guard_arm();
    const int rc_post = sem_post(&w.go);
    const int rc_wait = sem_wait(&w.done);
    ps_guard_disarm(&c);
    assert_int_equal(rc_post, 0);
    assert_int_equal(rc_wait, 0);
    assert_int_equal(c.n_allocs, 0);
    assert_int_equal(c.n_frees, 0);
    assert_int_equal(c.n_faults, 0);
    assert_int_equal(c.n_locks, 1); /* its own sem_wait, not the worker's */

    assert_int_equal(sem_post(&w.go), 0); /* round 2: the worker armed itself */
    assert_int_equal(sem_wait(&w.done), 0);
    assert_int_equal(pthread_join(th, NULL), 0);
    assert_int_equal(w.own.n_allocs, 10);
    assert_int_equal(w.own.n_frees, 10);
    assert_int_equal(w.own.n_locks, 0); /* armed after its sem_wait */
    assert_true(w.own.n_faults >= w.n_pages);
    assert_int_equal(sem_destroy(&w.go), 0);
    assert_int_equal(sem_destroy(&w.done), 0);
}

#define N_FAULT_PAGES 64u

static unsigned char *map_fresh(void)
{
    unsigned char *m = mmap(NULL, N_FAULT_PAGES * page_size(), PROT_READ | PROT_WRITE,
                            MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    assert_true(m != MAP_FAILED);
    return m;
}

static void touch(unsigned char *m)
{
    for (size_t i = 0; i < N_FAULT_PAGES; i++)
        ((volatile unsigned char *)m)[i * page_size()] = (unsigned char)i;
}

static void test_ps_guard_arm_fresh_pages_faults_counted(void **state)
{
    (void)state;
    unsigned char *m = map_fresh();
    ps_guard_counts_t c;
    ps_guard_arm();
    touch(m);
    ps_guard_disarm(&c);
    print_message("      %u fresh pages: %llu faults\n", N_FAULT_PAGES,
                  (unsigned long long)c.n_faults);
    assert_true(c.n_faults >= N_FAULT_PAGES);
    assert_int_equal(c.n_allocs, 0);
    ps_guard_counts_t after;
    ps_guard_read(&after); /* disarmed: the frozen counts */
    assert_memory_equal(&after, &c, sizeof(c));
    /* Touching them again: resident now, no faults. */
    ps_guard_arm();
    touch(m);
    ps_guard_disarm(&c);
    assert_int_equal(c.n_faults, 0);
    assert_int_equal(munmap(m, N_FAULT_PAGES * page_size()), 0);
}

static void test_ps_guard_pause_fresh_pages_faults_excluded(void **state)
{
    (void)state;
    unsigned char *m = map_fresh();
    unsigned char *m2 = map_fresh();
    ps_guard_counts_t c, mid;
    ps_guard_arm();
    ps_guard_pause();
    touch(m);
    ps_guard_resume();
    ps_guard_read(&mid);
    ps_guard_disarm(&c);
    assert_int_equal(mid.n_faults, 0);
    assert_int_equal(c.n_faults, 0);
    /* Faults before and after a paused span add up; the span does not. */
    ps_guard_arm();
    touch(m2);
    ps_guard_pause();
    ps_guard_read(&mid);
    ps_guard_resume();
    ps_guard_disarm(&c);
    assert_true(mid.n_faults >= N_FAULT_PAGES);
    assert_true(c.n_faults == mid.n_faults);
    assert_int_equal(munmap(m, N_FAULT_PAGES * page_size()), 0);
    assert_int_equal(munmap(m2, N_FAULT_PAGES * page_size()), 0);
}

static void test_ps_guard_arm_pure_arithmetic_zero_counts(void **state)
{
    (void)state;
    ps_guard_counts_t c;
    volatile uint64_t acc = 1;
    ps_guard_arm();
    for (uint32_t i = 0; i < 1000000u; i++)
        acc = acc * 6364136223846793005ull + i;
    ps_guard_disarm(&c);
    (void)acc; /* volatile: the loop is not optimised away */
    assert_int_equal(c.n_allocs, 0);
    assert_int_equal(c.n_frees, 0);
    assert_int_equal(c.n_faults, 0);
}

/* ---- locks --------------------------------------------------------------- */

static void test_ps_guard_counts_locks_true_plain_and_under_asan(void **state)
{
    (void)state;
    assert_true(ps_guard_counts_locks());
}

/* Every lock entry point on the armed thread counts once per call, whether
 * it gets the lock or not (a failed try is still a lock the loop asked for);
 * unlocks and posts do not count. */
static void test_ps_guard_arm_mutex_rwlock_sem_counted_exactly(void **state)
{
    (void)state;
    static pthread_mutex_t mu = PTHREAD_MUTEX_INITIALIZER;
    static pthread_rwlock_t rw = PTHREAD_RWLOCK_INITIALIZER;
    sem_t sem;
    assert_int_equal(sem_init(&sem, 0, 3), 0);
    struct timespec soon;
    assert_int_equal(clock_gettime(CLOCK_REALTIME, &soon), 0);
    soon.tv_sec += 1;
    ps_guard_counts_t c;
    int rc[12];
    ps_guard_arm();
    rc[0] = p_mutex_lock(&mu);
    rc[1] = p_mutex_trylock(&mu); /* held: EBUSY, still counted */
    rc[2] = pthread_mutex_unlock(&mu);
    rc[3] = p_mutex_timedlock(&mu, &soon);
    rc[4] = pthread_mutex_unlock(&mu);
    rc[5] = p_rwlock_rdlock(&rw);
    rc[6] = p_rwlock_tryrdlock(&rw);
    rc[7] = p_rwlock_trywrlock(&rw); /* read-held: EBUSY */
    (void)pthread_rwlock_unlock(&rw);
    (void)pthread_rwlock_unlock(&rw);
    rc[8] = p_rwlock_wrlock(&rw);
    (void)pthread_rwlock_unlock(&rw);
    rc[9] = p_sem_wait(&sem);
    rc[10] = p_sem_trywait(&sem);
    rc[11] = p_sem_timedwait(&sem, &soon);
    ps_guard_disarm(&c);
    assert_int_equal(rc[0], 0);
    assert_int_equal(rc[1], EBUSY);
    assert_int_equal(rc[2], 0);
    assert_int_equal(rc[3], 0);
    assert_int_equal(rc[4], 0);
    assert_int_equal(rc[5], 0);
    assert_int_equal(rc[6], 0);
    assert_int_equal(rc[7], EBUSY);
    assert_int_equal(rc[8], 0);
    assert_int_equal(rc[9], 0);
    assert_int_equal(rc[10], 0);
    assert_int_equal(rc[11], 0);
    assert_int_equal(c.n_locks, 10);
    assert_int_equal(c.n_allocs, 0);
    assert_int_equal(sem_destroy(&sem), 0);
}

static void test_ps_guard_pause_or_disarm_mutex_not_counted(void **state)
{
    (void)state;
    static pthread_mutex_t mu = PTHREAD_MUTEX_INITIALIZER;
    ps_guard_counts_t c, mid;
    ps_guard_arm();
    assert_int_equal(p_mutex_lock(&mu), 0);
    assert_int_equal(pthread_mutex_unlock(&mu), 0);
    ps_guard_pause();
    for (int i = 0; i < 3; i++) {
        assert_int_equal(p_mutex_lock(&mu), 0);
        assert_int_equal(pthread_mutex_unlock(&mu), 0);
    }
    ps_guard_resume();
    ps_guard_read(&mid);
    ps_guard_disarm(&c);
    assert_int_equal(p_mutex_lock(&mu), 0); /* disarmed */
    assert_int_equal(pthread_mutex_unlock(&mu), 0);
    ps_guard_counts_t after;
    ps_guard_read(&after);
    assert_int_equal(mid.n_locks, 1);
    assert_int_equal(c.n_locks, 1);
    assert_int_equal(after.n_locks, 1); /* frozen at disarm */
    ps_guard_arm();                     /* re-arm zeroes */
    ps_guard_disarm(&c);
    assert_int_equal(c.n_locks, 0);
}

typedef struct {
    pthread_mutex_t *mu;
    int n_ok;
} locker_t;

static void *locker(void *arg)
{
    locker_t *l = arg;
    for (int i = 0; i < 100; i++)
        if (p_mutex_lock(l->mu) == 0 && pthread_mutex_unlock(l->mu) == 0)
            l->n_ok++;
    return NULL;
}

/* Another (unarmed) thread's locks are not the armed thread's, even on the
 * same mutex, and the armed thread's join is no lock either. */
static void test_ps_guard_arm_mutex_on_other_thread_not_counted(void **state)
{
    (void)state;
    static pthread_mutex_t mu = PTHREAD_MUTEX_INITIALIZER;
    static locker_t l;
    l = (locker_t){.mu = &mu};
    pthread_t th;
    assert_int_equal(pthread_create(&th, NULL, locker, &l), 0); /* may allocate: before arm */
    ps_guard_counts_t c;
    ps_guard_arm();
    const int rc_join = pthread_join(th, NULL);
    ps_guard_disarm(&c);
    assert_int_equal(rc_join, 0);
    assert_int_equal(l.n_ok, 100);
    assert_int_equal(c.n_locks, 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ps_guard_counts_allocs_true_plain_and_under_asan),
        cmocka_unit_test(test_ps_guard_is_armed_follows_arm_pause_disarm),
        cmocka_unit_test(test_ps_guard_arm_malloc_calloc_realloc_free_counted_exactly),
        cmocka_unit_test(test_ps_guard_arm_aligned_allocs_counted),
        cmocka_unit_test(test_ps_guard_arm_libc_internal_malloc_counted),
        cmocka_unit_test(test_ps_guard_pause_excludes_allocs),
        cmocka_unit_test(test_ps_guard_disarm_then_allocs_not_counted),
        cmocka_unit_test(test_ps_guard_arm_other_thread_not_counted),
        cmocka_unit_test(test_ps_guard_arm_fresh_pages_faults_counted),
        cmocka_unit_test(test_ps_guard_pause_fresh_pages_faults_excluded),
        cmocka_unit_test(test_ps_guard_arm_pure_arithmetic_zero_counts),
        cmocka_unit_test(test_ps_guard_counts_locks_true_plain_and_under_asan),
        cmocka_unit_test(test_ps_guard_arm_mutex_rwlock_sem_counted_exactly),
        cmocka_unit_test(test_ps_guard_pause_or_disarm_mutex_not_counted),
        cmocka_unit_test(test_ps_guard_arm_mutex_on_other_thread_not_counted),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
