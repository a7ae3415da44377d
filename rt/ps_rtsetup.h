/*
 * ps_rtsetup: real-time process and thread setup, when permitted.
 *
 * mlockall(MCL_CURRENT | MCL_FUTURE), SCHED_FIFO priority, CPU affinity and a
 * prefaulted stack. When a step is not permitted the result says which
 * (bits below) and the caller prints one warning line and runs on, unless
 * --require-rt makes it fatal. Without mlockall, ps_rtsetup_prefault_maps()
 * touches every readable mapping so later code paths do not page-fault.
 *
 * Threads: call from the thread being set up. Allocation: none.
 */
#ifndef PS_RTSETUP_H
#define PS_RTSETUP_H

#include <stddef.h>
#include <stdint.h>

typedef enum {
    PS_RT_MISSING_MLOCK = 1u << 0,
    PS_RT_MISSING_FIFO = 1u << 1,
    PS_RT_MISSING_AFFINITY = 1u << 2,
} ps_rt_missing_t;

/** Lock all memory of the process. @return 0 | -errno  @rt INIT */
int ps_rtsetup_lock_memory(void);

/** Give the calling thread SCHED_FIFO at priority (0: leave SCHED_OTHER) and
 *  pin it to cpu (-1: no pinning). @return bitmask of ps_rt_missing_t (0: all done)
 *  @rt INIT, the thread itself */
unsigned ps_rtsetup_thread(unsigned priority, int cpu);

/** Touch stack_bytes of stack below the caller so it is resident. @rt INIT */
void ps_rtsetup_prefault_stack(size_t stack_bytes);

/** Read one byte of every page of every readable private/file mapping so the
 *  page tables are populated (fallback when mlockall is not permitted).
 *  @return pages touched | -errno  @rt INIT */
long ps_rtsetup_prefault_maps(void);

/** Describe missing bits in one line, e.g. "mlockall (EPERM), SCHED_FIFO
 *  (EPERM)". @post buf NUL-terminated  @rt INIT */
void ps_rtsetup_describe(unsigned missing, char *buf, size_t len);

#endif /* PS_RTSETUP_H */
