/*
 * ps_guard: malloc interposer and per-thread page-fault accounting.
 *
 * The interposers are plain definitions of malloc & co. in the executable;
 * the dynamic linker binds every library's malloc (libc's own internal calls
 * included, as glibc supports replacing malloc) to them, and they forward to
 * glibc's exported __libc_* entry points. State is thread-local with the
 * initial-exec model so reading it never calls __tls_get_addr (which may
 * allocate) and works from the first malloc of a new thread.
 */
#include "ps_guard.h"

#include <errno.h>
#include <malloc.h>
#include <stddef.h>
#include <stdlib.h>
#include <sys/resource.h>
#include <unistd.h>

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define PS_GUARD_NO_INTERPOSE 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) ||                         \
    __has_feature(memory_sanitizer)
#define PS_GUARD_NO_INTERPOSE 1
#endif
#endif

#define TLS _Thread_local __attribute__((tls_model("initial-exec")))

static TLS bool g_is_armed;
static TLS bool g_is_paused;
static TLS uint64_t g_n_allocs;
static TLS uint64_t g_n_frees;
static TLS uint64_t g_faults_done;    /* faults of completed unpaused spans */
static TLS uint64_t g_faults_span_at; /* rusage reading at the start of the open span */

static inline bool is_counting(void)
{
    return g_is_armed && !g_is_paused;
}

#ifndef PS_GUARD_NO_INTERPOSE

extern void *__libc_malloc(size_t size);
extern void *__libc_calloc(size_t n, size_t size);
extern void *__libc_realloc(void *ptr, size_t size);
extern void __libc_free(void *ptr);
extern void *__libc_memalign(size_t alignment, size_t size);

static inline void count_alloc(void)
{
    if (is_counting())
        g_n_allocs++;
}

void *malloc(size_t size)
{
    count_alloc();
    return __libc_malloc(size);
}

void *calloc(size_t n, size_t size)
{
    count_alloc();
    return __libc_calloc(n, size);
}

void *realloc(void *ptr, size_t size)
{
    count_alloc();
    return __libc_realloc(ptr, size);
}

void free(void *ptr)
{
    if (is_counting())
        g_n_frees++;
    __libc_free(ptr);
}

void *memalign(size_t alignment, size_t size)
{
    count_alloc();
    return __libc_memalign(alignment, size);
}

void *aligned_alloc(size_t alignment, size_t size)
{
    count_alloc();
    return __libc_memalign(alignment, size);
}

int posix_memalign(void **memptr, size_t alignment, size_t size)
{
    count_alloc();
    /* POSIX: a power of two multiple of sizeof(void *); *memptr untouched on error. */
    if (alignment < sizeof(void *) || (alignment & (alignment - 1)) != 0)
        return EINVAL;
    void *p = __libc_memalign(alignment, size);
    if (p == NULL)
        return ENOMEM;
    *memptr = p;
    return 0;
}

/* sysconf is async-signal-safe and does not allocate; the page size is
 * cached by glibc. */
static size_t page_size(void)
{
    const long ps = sysconf(_SC_PAGESIZE);
    return ps > 0 ? (size_t)ps : 4096u;
}

void *valloc(size_t size)
{
    count_alloc();
    return __libc_memalign(page_size(), size);
}

void *pvalloc(size_t size)
{
    count_alloc();
    const size_t page = page_size();
    size_t rounded;
    if (__builtin_add_overflow(size, page - 1, &rounded)) {
        errno = ENOMEM;
        return NULL;
    }
    return __libc_memalign(page, rounded & ~(page - 1));
}

#endif /* !PS_GUARD_NO_INTERPOSE */

bool ps_guard_counts_allocs(void)
{
#ifdef PS_GUARD_NO_INTERPOSE
    return false;
#else
    return true;
#endif
}

static uint64_t thread_faults(void)
{
    struct rusage ru;
    /* RUSAGE_THREAD with a valid pointer cannot fail on Linux >= 2.6.26. */
    if (getrusage(RUSAGE_THREAD, &ru) != 0)
        return 0;
    return (uint64_t)ru.ru_minflt + (uint64_t)ru.ru_majflt;
}

void ps_guard_arm(void)
{
    g_is_armed = false; /* nothing counted while the counters are reset */
    g_n_allocs = 0;
    g_n_frees = 0;
    g_faults_done = 0;
    g_is_paused = false;
    g_faults_span_at = thread_faults();
    g_is_armed = true;
}

void ps_guard_pause(void)
{
    if (!is_counting())
        return;
    g_is_paused = true; /* first: the syscall below is not the loop's either */
    g_faults_done += thread_faults() - g_faults_span_at;
}

void ps_guard_resume(void)
{
    if (!g_is_armed || !g_is_paused)
        return;
    g_faults_span_at = thread_faults();
    g_is_paused = false;
}

void ps_guard_read(ps_guard_counts_t *out)
{
    uint64_t faults = g_faults_done;
    if (is_counting())
        faults += thread_faults() - g_faults_span_at;
    out->n_allocs = g_n_allocs;
    out->n_frees = g_n_frees;
    out->n_faults = faults;
}

void ps_guard_disarm(ps_guard_counts_t *out)
{
    ps_guard_read(out);
    g_faults_done = out->n_faults; /* frozen: a later read repeats these counts */
    g_is_armed = false;
    g_is_paused = false;
}

bool ps_guard_is_armed(void)
{
    return is_counting();
}
