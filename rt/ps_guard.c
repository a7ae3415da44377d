/*
 * ps_guard: malloc and lock interposers, per-thread page-fault accounting.
 *
 * The interposers are plain definitions of malloc & co. in the executable;
 * the dynamic linker binds every library's malloc (libc's own internal calls
 * included, as glibc supports replacing malloc) to them, and they forward to
 * glibc's exported __libc_* entry points. State is thread-local with the
 * initial-exec model so reading it never calls __tls_get_addr (which may
 * allocate) and works from the first malloc of a new thread.
 */
#include "ps_guard.h"

#include <dlfcn.h>
#include <errno.h>
#include <malloc.h>
#include <pthread.h>
#include <semaphore.h>
#include <stddef.h>
#include <stdlib.h>
#include <sys/resource.h>
#include <unistd.h>

/* Under AddressSanitizer (PS_GUARD_ASAN_HOOKS) ASan owns malloc: the guard
 * counts through the allocator hooks ASan calls on every allocation and free
 * it serves, and interposes the lock calls as the plain build does (each
 * forwards to the next definition, ASan's interceptor, then glibc's). Under
 * ThreadSanitizer or MemorySanitizer (PS_GUARD_NO_INTERPOSE) nothing is
 * interposed or hooked. */
#if defined(__SANITIZE_ADDRESS__)
#define PS_GUARD_ASAN_HOOKS 1
#elif defined(__SANITIZE_THREAD__)
#define PS_GUARD_NO_INTERPOSE 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define PS_GUARD_ASAN_HOOKS 1
#elif __has_feature(thread_sanitizer) || __has_feature(memory_sanitizer)
#define PS_GUARD_NO_INTERPOSE 1
#endif
#endif

#define TLS _Thread_local __attribute__((tls_model("initial-exec")))

static TLS bool g_is_armed;
static TLS bool g_is_paused;
static TLS uint64_t g_n_allocs;
static TLS uint64_t g_n_frees;
static TLS uint64_t g_n_locks;
static TLS uint64_t g_faults_done;    /* faults of completed unpaused spans */
static TLS uint64_t g_faults_span_at; /* rusage reading at the start of the open span */

static inline bool is_counting(void)
{
    return g_is_armed && !g_is_paused;
}

#ifdef PS_GUARD_ASAN_HOOKS

/* sanitizer/allocator_interface.h, which GCC does not ship: ASan calls each
 * installed pair after every allocation and before every free it serves
 * (a failed allocation and free(NULL) do not reach them; a realloc that
 * moves a block is one allocation and one free). @return nonzero if installed */
int __sanitizer_install_malloc_and_free_hooks(void (*malloc_hook)(const volatile void *, size_t),
                                              void (*free_hook)(const volatile void *));

static void on_asan_malloc(const volatile void *ptr, size_t size)
{
    (void)ptr;
    (void)size;
    if (is_counting())
        g_n_allocs++;
}

static void on_asan_free(const volatile void *ptr)
{
    (void)ptr;
    if (is_counting())
        g_n_frees++;
}

static bool g_has_hooks; /* written once by the constructor, before main */

__attribute__((constructor)) static void install_asan_hooks(void)
{
    g_has_hooks = __sanitizer_install_malloc_and_free_hooks(on_asan_malloc, on_asan_free) != 0;
}

#elif !defined(PS_GUARD_NO_INTERPOSE)

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

#endif /* malloc interposers */

#ifndef PS_GUARD_NO_INTERPOSE

/* ---- locks ------------------------------------------------------------ */

static inline void count_lock(void)
{
    if (is_counting())
        g_n_locks++;
}

/* Each forwards to the next definition (glibc's), looked up once by a
 * constructor before main. (glibc's __pthread_* aliases are compat symbols
 * that a new program cannot link against.) A call before the constructor
 * (another library's constructor) looks the function up itself; dlsym may
 * allocate, which is INIT. */
typedef int (*mutex_fn)(pthread_mutex_t *);
typedef int (*mutex_timed_fn)(pthread_mutex_t *, const struct timespec *);
typedef int (*rwlock_fn)(pthread_rwlock_t *);
typedef int (*rwlock_timed_fn)(pthread_rwlock_t *, const struct timespec *);
typedef int (*sem_fn)(sem_t *);
typedef int (*sem_timed_fn)(sem_t *, const struct timespec *);

static struct {
    mutex_fn mutex_lock, mutex_trylock;
    mutex_timed_fn mutex_timedlock;
    rwlock_fn rwlock_rdlock, rwlock_wrlock, rwlock_tryrdlock, rwlock_trywrlock;
    rwlock_timed_fn rwlock_timedrdlock, rwlock_timedwrlock;
    sem_fn sem_wait, sem_trywait;
    sem_timed_fn sem_timedwait;
} g_next;

/* The symbol name of each field. */
#define SYM_mutex_lock         "pthread_mutex_lock"
#define SYM_mutex_trylock      "pthread_mutex_trylock"
#define SYM_mutex_timedlock    "pthread_mutex_timedlock"
#define SYM_rwlock_rdlock      "pthread_rwlock_rdlock"
#define SYM_rwlock_wrlock      "pthread_rwlock_wrlock"
#define SYM_rwlock_tryrdlock   "pthread_rwlock_tryrdlock"
#define SYM_rwlock_trywrlock   "pthread_rwlock_trywrlock"
#define SYM_rwlock_timedrdlock "pthread_rwlock_timedrdlock"
#define SYM_rwlock_timedwrlock "pthread_rwlock_timedwrlock"
#define SYM_sem_wait           "sem_wait"
#define SYM_sem_trywait        "sem_trywait"
#define SYM_sem_timedwait      "sem_timedwait"

#define NEXT(field, type)                                                                          \
    (g_next.field != NULL ? g_next.field : (g_next.field = (type)dlsym(RTLD_NEXT, SYM_##field)))

__attribute__((constructor)) static void resolve_next(void)
{
    (void)NEXT(mutex_lock, mutex_fn);
    (void)NEXT(mutex_trylock, mutex_fn);
    (void)NEXT(mutex_timedlock, mutex_timed_fn);
    (void)NEXT(rwlock_rdlock, rwlock_fn);
    (void)NEXT(rwlock_wrlock, rwlock_fn);
    (void)NEXT(rwlock_tryrdlock, rwlock_fn);
    (void)NEXT(rwlock_trywrlock, rwlock_fn);
    (void)NEXT(rwlock_timedrdlock, rwlock_timed_fn);
    (void)NEXT(rwlock_timedwrlock, rwlock_timed_fn);
    (void)NEXT(sem_wait, sem_fn);
    (void)NEXT(sem_trywait, sem_fn);
    (void)NEXT(sem_timedwait, sem_timed_fn);
}

#define FORWARD_PTHREAD(field, type, ...)                                                          \
    do {                                                                                           \
        count_lock();                                                                              \
        type f = NEXT(field, type);                                                                \
        return f != NULL ? f(__VA_ARGS__) : ENOSYS;                                                \
    } while (0)

int pthread_mutex_lock(pthread_mutex_t *m)
{
    FORWARD_PTHREAD(mutex_lock, mutex_fn, m);
}

int pthread_mutex_trylock(pthread_mutex_t *m)
{
    FORWARD_PTHREAD(mutex_trylock, mutex_fn, m);
}

int pthread_mutex_timedlock(pthread_mutex_t *m, const struct timespec *abstime)
{
    FORWARD_PTHREAD(mutex_timedlock, mutex_timed_fn, m, abstime);
}

int pthread_rwlock_rdlock(pthread_rwlock_t *l)
{
    FORWARD_PTHREAD(rwlock_rdlock, rwlock_fn, l);
}

int pthread_rwlock_wrlock(pthread_rwlock_t *l)
{
    FORWARD_PTHREAD(rwlock_wrlock, rwlock_fn, l);
}

int pthread_rwlock_tryrdlock(pthread_rwlock_t *l)
{
    FORWARD_PTHREAD(rwlock_tryrdlock, rwlock_fn, l);
}

int pthread_rwlock_trywrlock(pthread_rwlock_t *l)
{
    FORWARD_PTHREAD(rwlock_trywrlock, rwlock_fn, l);
}

int pthread_rwlock_timedrdlock(pthread_rwlock_t *l, const struct timespec *abstime)
{
    FORWARD_PTHREAD(rwlock_timedrdlock, rwlock_timed_fn, l, abstime);
}

int pthread_rwlock_timedwrlock(pthread_rwlock_t *l, const struct timespec *abstime)
{
    FORWARD_PTHREAD(rwlock_timedwrlock, rwlock_timed_fn, l, abstime);
}

/* sem_*: -1 with errno, like the real ones, if glibc's cannot be found. */
#define FORWARD_SEM(field, type, ...)                                                              \
    do {                                                                                           \
        count_lock();                                                                              \
        type f = NEXT(field, type);                                                                \
        if (f == NULL) {                                                                           \
            errno = ENOSYS;                                                                        \
            return -1;                                                                             \
        }                                                                                          \
        return f(__VA_ARGS__);                                                                     \
    } while (0)

int sem_wait(sem_t *s)
{
    FORWARD_SEM(sem_wait, sem_fn, s);
}

int sem_trywait(sem_t *s)
{
    FORWARD_SEM(sem_trywait, sem_fn, s);
}

int sem_timedwait(sem_t *s, const struct timespec *abstime)
{
    FORWARD_SEM(sem_timedwait, sem_timed_fn, s, abstime);
}

#endif /* !PS_GUARD_NO_INTERPOSE */

bool ps_guard_counts_allocs(void)
{
#if defined(PS_GUARD_ASAN_HOOKS)
    return g_has_hooks;
#elif defined(PS_GUARD_NO_INTERPOSE)
    return false;
#else
    return true;
#endif
}

bool ps_guard_counts_locks(void)
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
    g_n_locks = 0;
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
    out->n_locks = g_n_locks;
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
