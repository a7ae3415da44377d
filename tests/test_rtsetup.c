/*
 * Tests of ps_rtsetup. They run unprivileged or privileged: where a step may
 * or may not be permitted, both outcomes are checked for consistency, and
 * anything granted is undone.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <stdbool.h>
#include <fcntl.h>

#include <errno.h>
#include <pthread.h>
#include <sched.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "../rt/ps_err.h"
#include "../rt/ps_rtsetup.h"

static void test_ps_rtsetup_thread_nothing_asked_zero(void **state)
{
    (void)state;
    int policy_before;
    struct sched_param sp_before;
    assert_int_equal(pthread_getschedparam(pthread_self(), &policy_before, &sp_before), 0);
    assert_int_equal(ps_rtsetup_thread(0, -1), 0);
    int policy_after;
    struct sched_param sp_after;
    assert_int_equal(pthread_getschedparam(pthread_self(), &policy_after, &sp_after), 0);
    assert_int_equal(policy_after, policy_before);
}

static void test_ps_rtsetup_describe_nothing_missing_empty(void **state)
{
    (void)state;
    char buf[64];
    memset(buf, 'x', sizeof(buf));
    ps_rtsetup_describe(0, buf, sizeof(buf));
    assert_string_equal(buf, "");
}

/* Invalid requests are refused before the kernel is asked: deterministic. */
static void test_ps_rtsetup_thread_bad_priority_and_cpu_described(void **state)
{
    (void)state;
    const unsigned missing = ps_rtsetup_thread(1000, CPU_SETSIZE + 5);
    assert_int_equal(missing, PS_RT_MISSING_FIFO | PS_RT_MISSING_AFFINITY);
    char buf[256];
    ps_rtsetup_describe(missing, buf, sizeof(buf));
    char want[256];
    snprintf(want, sizeof(want), "SCHED_FIFO priority 1000 (%s), CPU affinity cpu %d (%s)",
             strerror(EINVAL), CPU_SETSIZE + 5, strerror(EINVAL));
    assert_string_equal(buf, want);
    assert_int_equal(ps_rtsetup_thread(0, -7), PS_RT_MISSING_AFFINITY);
}

/* A helper thread's failure must not replace the loop's in the report. */
static void test_ps_rtsetup_thread_best_effort_not_recorded(void **state)
{
    (void)state;
    assert_int_equal(ps_rtsetup_thread(1000, CPU_SETSIZE + 5),
                     PS_RT_MISSING_FIFO | PS_RT_MISSING_AFFINITY);
    assert_int_equal(ps_rtsetup_thread_best_effort(999, CPU_SETSIZE + 9),
                     PS_RT_MISSING_FIFO | PS_RT_MISSING_AFFINITY);
    char buf[256];
    ps_rtsetup_describe(PS_RT_MISSING_FIFO | PS_RT_MISSING_AFFINITY, buf, sizeof(buf));
    char want[256];
    snprintf(want, sizeof(want), "SCHED_FIFO priority 1000 (%s), CPU affinity cpu %d (%s)",
             strerror(EINVAL), CPU_SETSIZE + 5, strerror(EINVAL));
    assert_string_equal(buf, want);
}

/* Held (root): an open descriptor; refused: the reason names the file. */
static void test_ps_rtsetup_hold_cpu_latency_held_or_described(void **state)
{
    (void)state;
    int fd = -1;
    int rc = ps_rtsetup_hold_cpu_latency(&fd);
    if (rc == 0) {
        assert_true(fd >= 0);
        assert_true(fcntl(fd, F_GETFD) >= 0);
        ps_rtsetup_release_cpu_latency(fd);
        assert_true(fcntl(fd, F_GETFD) < 0); /* released */
    } else {
        assert_true(rc < 0);
        assert_int_equal(fd, -1); /* untouched on failure */
        char buf[256];
        ps_rtsetup_describe(PS_RT_MISSING_CPU_LATENCY, buf, sizeof(buf));
        assert_non_null(strstr(buf, "/dev/cpu_dma_latency ("));
    }
    ps_rtsetup_release_cpu_latency(-1); /* safe */
}

static void test_ps_rtsetup_describe_truncates_nul_terminated(void **state)
{
    (void)state;
    (void)ps_rtsetup_thread(1000, CPU_SETSIZE + 5); /* makes long reasons */
    char buf[12];
    memset(buf, 'x', sizeof(buf));
    ps_rtsetup_describe(PS_RT_MISSING_FIFO | PS_RT_MISSING_AFFINITY, buf, sizeof(buf));
    assert_int_equal(strlen(buf), sizeof(buf) - 1);
    assert_memory_equal(buf, "SCHED_FIFO ", 11);
    char one[1] = {'x'};
    ps_rtsetup_describe(PS_RT_MISSING_FIFO, one, 1);
    assert_int_equal(one[0], '\0');
    ps_rtsetup_describe(PS_RT_MISSING_FIFO, NULL, 0); /* len 0: buffer untouched */
}

static void test_ps_rtsetup_lock_memory_result_described(void **state)
{
    (void)state;
    const int rc = ps_rtsetup_lock_memory();
    char buf[128];
    ps_rtsetup_describe(PS_RT_MISSING_MLOCK, buf, sizeof(buf));
    if (rc < 0) {
        char want[128];
        snprintf(want, sizeof(want), "mlockall (%s)", strerror(-rc));
        assert_string_equal(buf, want);
    } else {
        assert_int_equal(rc, 0);
        assert_int_equal(munlockall(), 0);
        /* Never failed: only the name. */
        assert_string_equal(buf, "mlockall");
    }
}

/* A legal FIFO priority and the current CPU: granted or EPERM-style refusal,
 * consistent with what the thread's attributes say afterwards. */
static void test_ps_rtsetup_thread_fifo_affinity_consistent(void **state)
{
    (void)state;
    cpu_set_t mask_before;
    assert_int_equal(pthread_getaffinity_np(pthread_self(), sizeof(mask_before), &mask_before), 0);
    const int cpu = sched_getcpu();
    assert_true(cpu >= 0);
    const unsigned missing = ps_rtsetup_thread(1, cpu);
    int policy;
    struct sched_param sp;
    assert_int_equal(pthread_getschedparam(pthread_self(), &policy, &sp), 0);
    if (missing & PS_RT_MISSING_FIFO) {
        assert_int_not_equal(policy, SCHED_FIFO);
        char buf[128];
        ps_rtsetup_describe(PS_RT_MISSING_FIFO, buf, sizeof(buf));
        assert_non_null(strstr(buf, "SCHED_FIFO priority 1 ("));
    } else {
        assert_int_equal(policy, SCHED_FIFO);
        assert_int_equal(sp.sched_priority, 1);
        const struct sched_param other = {.sched_priority = 0};
        assert_int_equal(pthread_setschedparam(pthread_self(), SCHED_OTHER, &other), 0);
    }
    cpu_set_t mask;
    assert_int_equal(pthread_getaffinity_np(pthread_self(), sizeof(mask), &mask), 0);
    if (!(missing & PS_RT_MISSING_AFFINITY)) {
        assert_int_equal(CPU_COUNT(&mask), 1);
        assert_true(CPU_ISSET(cpu, &mask));
    }
    assert_int_equal(pthread_setaffinity_np(pthread_self(), sizeof(mask_before), &mask_before), 0);
}

static size_t n_resident(void *addr, size_t n_pages)
{
    unsigned char vec[64];
    assert_true(n_pages <= sizeof(vec));
    assert_int_equal(mincore(addr, n_pages * (size_t)sysconf(_SC_PAGESIZE), vec), 0);
    size_t n = 0;
    for (size_t i = 0; i < n_pages; i++)
        n += vec[i] & 1u;
    return n;
}

static void test_ps_rtsetup_prefault_maps_fresh_mapping_resident(void **state)
{
    (void)state;
    if (getenv("PS_QEMU_USER") != NULL)
        skip(); /* qemu-user's own /proc/self/maps and residency: not the kernel's */
    const size_t page = (size_t)sysconf(_SC_PAGESIZE);
    const size_t n_fresh = 64;
    void *m =
        mmap(NULL, n_fresh * page, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    assert_true(m != MAP_FAILED);
    /* PROT_NONE guard must be skipped (reading it would crash the test). */
    void *guard = mmap(NULL, 16 * page, PROT_NONE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    assert_true(guard != MAP_FAILED);
    assert_int_equal(n_resident(m, n_fresh), 0);
    const long n = ps_rtsetup_prefault_maps();
    print_message("      prefaulted %ld pages\n", n);
    assert_true(n >= (long)n_fresh);
    assert_int_equal(n_resident(m, n_fresh), n_fresh);
    assert_int_equal(n_resident(guard, 16), 0);
    assert_int_equal(munmap(guard, 16 * page), 0);
    assert_int_equal(munmap(m, n_fresh * page), 0);
}

/* A file mapping longer than its file: pages past the end would SIGBUS. */
static void test_ps_rtsetup_prefault_maps_file_past_eof_skipped(void **state)
{
    (void)state;
    const size_t page = (size_t)sysconf(_SC_PAGESIZE);
    char path[] = "/tmp/ps_rtsetup_test_XXXXXX";
    const int fd = mkstemp(path);
    assert_true(fd >= 0);
    assert_int_equal(unlink(path) == 0 ? 0 : -1, 0);
    /* unlinked: the mapping shows "(deleted)" and is skipped entirely; keep
     * a named one too. */
    char path2[] = "/tmp/ps_rtsetup_test_XXXXXX";
    const int fd2 = mkstemp(path2);
    assert_true(fd2 >= 0);
    assert_int_equal(ftruncate(fd2, (off_t)(page + 10)), 0);
    void *m = mmap(NULL, 8 * page, PROT_READ, MAP_SHARED, fd2, 0);
    assert_true(m != MAP_FAILED);
    void *m_del = mmap(NULL, 4 * page, PROT_READ, MAP_SHARED, fd, 0);
    assert_true(m_del != MAP_FAILED);
    const long n = ps_rtsetup_prefault_maps();
    assert_true(n > 0);
    /* The two pages holding file data are mapped, none past the end. */
    assert_int_equal(n_resident(m, 2), 2);
    assert_int_equal(munmap(m_del, 4 * page), 0);
    assert_int_equal(munmap(m, 8 * page), 0);
    assert_int_equal(close(fd), 0);
    assert_int_equal(close(fd2), 0);
    assert_int_equal(unlink(path2), 0);
}

#define STACK_MAP_BYTES (1024u * 1024u)

typedef struct {
    bool is_prefault;
    unsigned char *map; /**< the thread's stack mapping, fresh (never touched) */
    size_t n_resident;  /**< of the 64 pages below the thread's frame, after */
    size_t n_checked;
} stack_probe_t;

static void *stack_probe(void *arg)
{
    stack_probe_t *p = arg;
    const size_t page = (size_t)sysconf(_SC_PAGESIZE);
    if (p->is_prefault) {
        ps_rtsetup_prefault_stack(256 * 1024);
        ps_rtsetup_prefault_stack(1); /* tiny and zero sizes are fine too */
        ps_rtsetup_prefault_stack(0);
    }
    volatile unsigned char here = 0;
    /* 48 pages (192 KiB) from 2 pages below this frame: well inside the
     * 256 KiB (64 pages) touched below the prefault's own frame. */
    uintptr_t top = ((uintptr_t)&here & ~(uintptr_t)(page - 1)) - 2 * page;
    uintptr_t lo = top - 47 * page;
    if (lo < (uintptr_t)p->map)
        return NULL;
    unsigned char vec[48];
    if (mincore((void *)lo, 48 * page, vec) != 0)
        return NULL;
    for (size_t i = 0; i < 48; i++)
        p->n_resident += vec[i] & 1u;
    p->n_checked = 48;
    (void)here;
    return NULL;
}

static void run_stack_probe(stack_probe_t *p)
{
    p->map = mmap(NULL, STACK_MAP_BYTES, PROT_READ | PROT_WRITE,
                  MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
    assert_true(p->map != MAP_FAILED);
    pthread_attr_t attr;
    assert_int_equal(pthread_attr_init(&attr), 0);
    assert_int_equal(pthread_attr_setstack(&attr, p->map, STACK_MAP_BYTES), 0);
    pthread_t th;
    assert_int_equal(pthread_create(&th, &attr, stack_probe, p), 0);
    assert_int_equal(pthread_join(th, NULL), 0);
    assert_int_equal(pthread_attr_destroy(&attr), 0);
    assert_int_equal(munmap(p->map, STACK_MAP_BYTES), 0);
    assert_int_equal(p->n_checked, 48);
}

/* On a fresh stack mapping the pages below the frame are not resident
 * until something touches them; after ps_rtsetup_prefault_stack(256 KiB)
 * all of them are (mincore), without the thread having used them. Skipped
 * under mlockall(MCL_FUTURE), which would populate the mapping itself. */
static void test_ps_rtsetup_prefault_stack_pages_below_frame_resident(void **state)
{
    (void)state;
    stack_probe_t without = {.is_prefault = false}, with = {.is_prefault = true};
    run_stack_probe(&without);
    if (without.n_resident == 48)
        skip(); /* memory locked by this process: nothing to show */
    run_stack_probe(&with);
    assert_true(without.n_resident < 8);
    assert_int_equal(with.n_resident, 48);
}

static void *stack_thread(void *arg)
{
    (void)arg;
    ps_rtsetup_prefault_stack(256 * 1024);
    return (void *)1;
}

static void test_ps_rtsetup_prefault_stack_other_thread_ok(void **state)
{
    (void)state;
    pthread_t th;
    assert_int_equal(pthread_create(&th, NULL, stack_thread, NULL), 0);
    void *ret = NULL;
    assert_int_equal(pthread_join(th, &ret), 0);
    assert_ptr_equal(ret, (void *)1);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ps_rtsetup_thread_nothing_asked_zero),
        cmocka_unit_test(test_ps_rtsetup_describe_nothing_missing_empty),
        cmocka_unit_test(test_ps_rtsetup_thread_bad_priority_and_cpu_described),
        cmocka_unit_test(test_ps_rtsetup_thread_best_effort_not_recorded),
        cmocka_unit_test(test_ps_rtsetup_hold_cpu_latency_held_or_described),
        cmocka_unit_test(test_ps_rtsetup_describe_truncates_nul_terminated),
        cmocka_unit_test(test_ps_rtsetup_lock_memory_result_described),
        cmocka_unit_test(test_ps_rtsetup_thread_fifo_affinity_consistent),
        cmocka_unit_test(test_ps_rtsetup_prefault_maps_fresh_mapping_resident),
        cmocka_unit_test(test_ps_rtsetup_prefault_maps_file_past_eof_skipped),
        cmocka_unit_test(test_ps_rtsetup_prefault_stack_pages_below_frame_resident),
        cmocka_unit_test(test_ps_rtsetup_prefault_stack_other_thread_ok),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
