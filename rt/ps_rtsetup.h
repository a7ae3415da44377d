/*
 * ps_rtsetup: real-time process and thread setup, when permitted.
 *
 * mlockall(MCL_CURRENT | MCL_FUTURE), SCHED_FIFO priority, CPU affinity and a
 * prefaulted stack. When a step is not permitted the result says which
 * (bits below) and the caller prints one warning line and runs on, unless
 * --require-rt makes it fatal. Without mlockall, ps_rtsetup_prefault_maps()
 * touches every readable mapping so later code paths do not page-fault.
 *
 * The module remembers, process-wide, the errno (and the priority or CPU
 * asked) of the most recent FAILED attempt of each step, so that
 * ps_rtsetup_describe() can name the reason; a later success does not erase
 * it (the bits passed to describe say what is missing).
 *
 * Threads: call from the thread being set up; describe from any thread after
 * the setup calls returned. Allocation: none.
 */
#ifndef PS_RTSETUP_H
#define PS_RTSETUP_H

#include <stddef.h>
#include <stdint.h>

/** Real-time placement of a board's threads (board file, `rt:`). */
typedef struct {
    uint32_t priority;  /**< SCHED_FIFO priority of the loop thread, 1..98 */
    int32_t loop_cpu;   /**< CPU the loop is pinned to, -1: no pinning */
    int32_t plant_cpu;  /**< CPU of the sim plant thread, -1: no pinning */
    int32_t worker_cpu; /**< CPU of the non-RT logger thread, -1: no pinning */
} ps_rt_cfg_t;

typedef enum {
    PS_RT_MISSING_MLOCK = 1u << 0,
    PS_RT_MISSING_FIFO = 1u << 1,
    PS_RT_MISSING_AFFINITY = 1u << 2,
    PS_RT_MISSING_CPU_LATENCY = 1u << 3,
} ps_rt_missing_t;

/** Mappings larger than this are skipped by ps_rtsetup_prefault_maps(): they
 *  are address-space reservations (sanitizer shadow, allocator arenas), not
 *  memory the loop uses, and touching them would take seconds. */
#define PS_RTSETUP_PREFAULT_MAX_MAPPING_BYTES ((size_t)1 << 30)

/** Lock all memory of the process (MCL_CURRENT | MCL_FUTURE).
 *  @post on failure the errno is remembered for describe
 *  @return 0 | -errno (-EPERM without CAP_IPC_LOCK / RLIMIT_MEMLOCK, -ENOMEM)
 *  @rt INIT, any thread */
int ps_rtsetup_lock_memory(void);

/** Give the calling thread SCHED_FIFO at priority (0: leave its policy alone)
 *  and pin it to cpu (-1: no pinning). A priority outside
 *  sched_get_priority_min/max(SCHED_FIFO) or a cpu outside [0, CPU_SETSIZE)
 *  is reported missing with EINVAL without asking the kernel.
 *  @post on failure the step's errno and the priority / cpu are remembered
 *  @return bitmask of PS_RT_MISSING_FIFO | PS_RT_MISSING_AFFINITY (0: all done)
 *  @rt INIT, the thread itself */
unsigned ps_rtsetup_thread(unsigned priority, int cpu);

/** As ps_rtsetup_thread, for helper threads (sim plant, logger) whose
 *  failures are not the loop's: nothing is recorded for ps_rtsetup_describe().
 *  @return bitmask of ps_rt_missing_t  @rt INIT, the thread itself */
unsigned ps_rtsetup_thread_best_effort(unsigned priority, int cpu);

/** Touch stack_bytes of stack below the caller (one write per page) so it
 *  is resident. @pre stack_bytes well below the thread's stack size minus
 *  what is in use (e.g. 256 KiB on an 8 MiB stack)  @rt INIT, the thread itself */
void ps_rtsetup_prefault_stack(size_t stack_bytes);

/** Read one byte of every page of every readable mapping in /proc/self/maps
 *  so the page tables are populated (fallback when mlockall is not
 *  permitted). Skipped: mappings without read permission (guard pages),
 *  [vvar*] and [vsyscall], device mappings and anything that is not a
 *  regular file or anonymous, pages of a file mapping beyond the file's end
 *  (they would SIGBUS), deleted files, and mappings larger than
 *  PS_RTSETUP_PREFAULT_MAX_MAPPING_BYTES. Reading a never-written anonymous
 *  page maps the shared zero page: its first write still faults, so memory
 *  the loop writes must be written at init (ps_perf_reset, memset).
 *  @return pages touched (> 0) | -errno opening/reading /proc/self/maps
 *  @rt INIT, main thread, before other threads create or drop mappings */
long ps_rtsetup_prefault_maps(void);

/** Ask the kernel's PM QoS for a 0 us CPU wake-up latency (no deep C-states)
 *  by writing 0 to /dev/cpu_dma_latency and keeping it open, as cyclictest
 *  does: the request holds while the descriptor is open.
 *  @post *out_fd open on success  @return 0 | -errno  @rt INIT */
int ps_rtsetup_hold_cpu_latency(int *out_fd);

/** Drop the request. Safe with fd < 0. @rt INIT */
void ps_rtsetup_release_cpu_latency(int fd);

/** Describe missing bits in one line, comma-separated, each with the errno
 *  text of its last failed attempt when there was one, e.g.
 *  "mlockall (Operation not permitted), SCHED_FIFO priority 80 (Operation not
 *  permitted), CPU affinity cpu 3 (Invalid argument)"; "" for missing == 0.
 *  @pre buf != NULL or len == 0  @post buf NUL-terminated (truncated to len)
 *  @rt INIT, any thread */
void ps_rtsetup_describe(unsigned missing, char *buf, size_t len);

#endif /* PS_RTSETUP_H */
