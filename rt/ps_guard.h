/*
 * ps_guard: proves the tick allocates nothing and takes no page faults.
 *
 * ps_guard.c interposes malloc, calloc, realloc, free, posix_memalign,
 * aligned_alloc, memalign, valloc and pvalloc for the whole process and
 * forwards to glibc's __libc_* functions (same heap, so malloc_usable_size
 * and friends stay valid). While a thread is armed and not paused
 * (thread-local flags), each call from it is counted; the wrappers take no
 * lock and allocate nothing. Page faults of the armed thread are taken from
 * getrusage(RUSAGE_THREAD) (minor + major) at arm, at pause and resume (so
 * paused spans are excluded) and at read/disarm. Work that is not the loop's
 * but runs on its thread (the lockstep plant step) is bracketed by
 * ps_guard_pause()/ps_guard_resume() and excluded from both counts.
 *
 * Locks: ps_guard.c also interposes pthread_mutex_lock, _trylock and
 * _timedlock, pthread_rwlock_rdlock, _wrlock, _tryrdlock, _trywrlock,
 * _timedrdlock and _timedwrlock, sem_wait, sem_trywait and sem_timedwait,
 * and counts each call from an armed, unpaused thread (a try that fails
 * counts too: the loop asked for a lock). They forward to glibc's (the
 * next definition, found by dlsym(RTLD_NEXT) in a constructor before main,
 * so the hot path does no lookup). Locks glibc takes inside
 * itself (stdio, the malloc arena) do not go through these symbols and are
 * not counted; their callers (printf, malloc) are what the rules forbid.
 *
 * Sanitizers: under AddressSanitizer, which owns malloc, ps_guard.c
 * defines no malloc interposers but installs ASan's allocator hooks
 * (__sanitizer_install_malloc_and_free_hooks), which ASan calls for every
 * allocation and free it serves: n_allocs and n_frees count those (a failed
 * allocation and free(NULL) do not reach them; a realloc that moves a block
 * counts one allocation and one free), and the lock interposers stay
 * (forwarding through ASan's interceptors). Zero means zero in both builds.
 * Under ThreadSanitizer nothing is interposed or hooked: n_allocs, n_frees
 * and n_locks read 0 (ps_guard_counts_allocs() and _locks() say so). n_faults
 * works in every build; under ASan, whose mlockall is a no-op and whose
 * shadow memory maps on first touch, it counts faults the plain build has not.
 *
 * Threads: per-thread state; counters are read by the same thread.
 * Allocation: none.
 */
#ifndef PS_GUARD_H
#define PS_GUARD_H

#include <stdbool.h>
#include <stdint.h>

typedef struct {
    uint64_t n_allocs; /**< malloc/calloc/realloc/memalign/posix_memalign/aligned_alloc/
                            valloc/pvalloc calls while armed and not paused */
    uint64_t n_frees;  /**< free calls while armed and not paused (free(NULL) included) */
    uint64_t n_faults; /**< minor + major page faults while armed, not paused */
    uint64_t n_locks;  /**< mutex/rwlock lock and sem_wait calls (try and timed variants
                            included) while armed and not paused */
} ps_guard_counts_t;

/** Start counting for the calling thread (zeroes its counts, clears pause).
 *  @post ps_guard_is_armed()  @rt INIT, the thread itself */
void ps_guard_arm(void);

/** Stop counting. @pre out != NULL  @post *out = counts since arm (zeros if
 *  never armed); the thread is disarmed  @rt INIT, the thread itself */
void ps_guard_disarm(ps_guard_counts_t *out);

/** Exclude what follows from the counts until resume. Nestable: no (a second
 *  pause, or a resume without pause, does nothing). No effect when disarmed.
 *  @rt RT-SAFE (one getrusage syscall), the armed thread */
void ps_guard_pause(void);
void ps_guard_resume(void);

/** @pre out != NULL  @post *out = counts so far for the calling thread
 *  (syscall for faults); an armed thread stays armed; after disarm, the
 *  counts disarm returned  @rt NON-RT, the thread itself */
void ps_guard_read(ps_guard_counts_t *out);

/** @return true while the calling thread is armed and not paused  @rt RT-SAFE */
bool ps_guard_is_armed(void);

/** @return true when this build counts allocations: interposed malloc, or
 *  ASan's hooks installed (false under TSan: n_allocs and n_frees stay 0)
 *  @rt RT-SAFE */
bool ps_guard_counts_allocs(void);

/** @return true when this build interposes the lock calls (false under
 *  TSan: n_locks stays 0)  @rt RT-SAFE */
bool ps_guard_counts_locks(void);

#endif /* PS_GUARD_H */
