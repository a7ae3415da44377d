/*
 * ps_guard: proves the tick allocates nothing and takes no page faults.
 *
 * ps_guard.c interposes malloc, calloc, realloc, free (and posix_memalign,
 * aligned_alloc) for the whole process and forwards to glibc's __libc_*
 * functions. While a thread is armed (thread-local flag), each call from it
 * is counted. Page faults of the armed thread are taken from
 * getrusage(RUSAGE_THREAD) at arm and at report. Work that is not the loop's
 * but runs on its thread (the lockstep plant step) is bracketed by
 * ps_guard_pause()/ps_guard_resume() and excluded from both counts.
 *
 * Threads: per-thread state; counters are read by the same thread.
 * Allocation: none.
 */
#ifndef PS_GUARD_H
#define PS_GUARD_H

#include <stdbool.h>
#include <stdint.h>

typedef struct {
    uint64_t n_allocs;   /**< malloc/calloc/realloc/memalign calls while armed */
    uint64_t n_frees;    /**< free calls while armed (free(NULL) included) */
    uint64_t n_faults;   /**< minor + major page faults while armed, not paused */
} ps_guard_counts_t;

/** Start counting for the calling thread (zeroes its counts). @rt INIT */
void ps_guard_arm(void);

/** Stop counting; @post *out = counts since arm  @rt INIT */
void ps_guard_disarm(ps_guard_counts_t *out);

/** Exclude what follows from the counts until resume. Nestable: no.  @rt RT-SAFE */
void ps_guard_pause(void);
void ps_guard_resume(void);

/** @return counts so far for the calling thread (syscall for faults)  @rt NON-RT */
void ps_guard_read(ps_guard_counts_t *out);

/** @return true while the calling thread is armed and not paused  @rt RT-SAFE */
bool ps_guard_is_armed(void);

#endif /* PS_GUARD_H */
