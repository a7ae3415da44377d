/*
 * ps_rtsetup: mlockall, SCHED_FIFO, affinity and prefaulting.
 */
#include "ps_rtsetup.h"

#include <stdbool.h>

#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <sched.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "ps_err.h"

/* Last failed attempt of each step (errno 0: no failure seen). Atomics
 * because the loop, plant and worker threads each set themselves up and the
 * main thread describes. */
static atomic_int g_mlock_errno;
static atomic_int g_cpu_latency_errno;
static atomic_int g_fifo_errno;
static atomic_uint g_fifo_priority;
static atomic_int g_affinity_errno;
static atomic_int g_affinity_cpu;

int ps_rtsetup_lock_memory(void)
{
    if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0) {
        const int err = errno;
        atomic_store(&g_mlock_errno, err);
        return -err;
    }
    return 0;
}

int ps_rtsetup_hold_cpu_latency(int *out_fd)
{
    int fd = open("/dev/cpu_dma_latency", O_WRONLY | O_CLOEXEC);
    const int32_t zero_us = 0;
    if (fd < 0 || write(fd, &zero_us, sizeof(zero_us)) != (ssize_t)sizeof(zero_us)) {
        const int err = errno;
        if (fd >= 0)
            (void)close(fd); /* the request failed; nothing held */
        atomic_store(&g_cpu_latency_errno, err);
        return -err;
    }
    *out_fd = fd;
    return 0;
}

void ps_rtsetup_release_cpu_latency(int fd)
{
    if (fd >= 0)
        (void)close(fd); /* closing ends the PM QoS request */
}

static int set_fifo(unsigned priority)
{
    const int min = sched_get_priority_min(SCHED_FIFO);
    const int max = sched_get_priority_max(SCHED_FIFO);
    if (min < 0 || max < 0 || priority < (unsigned)min || priority > (unsigned)max)
        return EINVAL;
    const struct sched_param sp = {.sched_priority = (int)priority};
    /* pthread_* return the error number, they do not set errno. */
    return pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
}

static int set_affinity(int cpu)
{
    if (cpu < 0 || cpu >= CPU_SETSIZE)
        return EINVAL;
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET((size_t)cpu, &set);
    return pthread_setaffinity_np(pthread_self(), sizeof(set), &set);
}

static unsigned setup_thread(unsigned priority, int cpu, bool is_recorded)
{
    unsigned missing = 0;
    if (priority > 0) {
        const int err = set_fifo(priority);
        if (err != 0 && is_recorded) {
            atomic_store(&g_fifo_errno, err);
            atomic_store(&g_fifo_priority, priority);
        }
        missing |= err != 0 ? PS_RT_MISSING_FIFO : 0u;
    }
    if (cpu != -1) {
        const int err = set_affinity(cpu);
        if (err != 0 && is_recorded) {
            atomic_store(&g_affinity_errno, err);
            atomic_store(&g_affinity_cpu, cpu);
        }
        missing |= err != 0 ? PS_RT_MISSING_AFFINITY : 0u;
    }
    return missing;
}

unsigned ps_rtsetup_thread(unsigned priority, int cpu)
{
    return setup_thread(priority, cpu, true);
}

unsigned ps_rtsetup_thread_best_effort(unsigned priority, int cpu)
{
    return setup_thread(priority, cpu, false);
}

static size_t page_size(void)
{
    const long ps = sysconf(_SC_PAGESIZE);
    return ps > 0 ? (size_t)ps : 4096u;
}

/* noinline: the array must live in a frame below the caller's, and the
 * volatile stores cannot be elided, so the pages are really written
 * (a write, not a read: a read of a fresh stack page would map the zero
 * page and the first real write would fault again). */
static __attribute__((noinline)) void touch_stack(size_t n_bytes, size_t page)
{
    unsigned char buf[n_bytes];
    volatile unsigned char *const p = buf;
    for (size_t i = 0; i < n_bytes; i += page)
        p[i] = 0;
    p[n_bytes - 1] = 0;
}

void ps_rtsetup_prefault_stack(size_t stack_bytes)
{
    if (stack_bytes == 0)
        return;
    touch_stack(stack_bytes, page_size());
}

/* Not instrumented: under ASan a read of an arbitrary page (a heap redzone,
 * a freed block) is a report, but here it is only a page-table warm-up. */
__attribute__((no_sanitize_address)) static void touch_pages(uintptr_t start, uintptr_t end,
                                                             size_t page)
{
    for (uintptr_t a = start; a < end; a += page)
        (void)*(const volatile unsigned char *)a;
}

static int has_prefix(const char *s, const char *prefix)
{
    return strncmp(s, prefix, strlen(prefix)) == 0;
}

static int has_suffix(const char *s, const char *suffix)
{
    const size_t n = strlen(s), m = strlen(suffix);
    return n >= m && strcmp(s + n - m, suffix) == 0;
}

/* @return pages touched for one maps line (0 when skipped) */
static long prefault_line(char *line, size_t page)
{
    unsigned long start, end, offset, inode;
    unsigned dev_major, dev_minor;
    char perms[5];
    int name_pos = 0;
    if (sscanf(line, "%lx-%lx %4s %lx %x:%x %lu %n", &start, &end, perms, &offset, &dev_major,
               &dev_minor, &inode, &name_pos) < 7)
        return 0;
    const char *name = line + name_pos;
    if (perms[0] != 'r' || end <= start)
        return 0; /* guard pages, PROT_NONE reservations */
    if (has_prefix(name, "[vvar") || has_prefix(name, "[vsyscall"))
        return 0; /* reading some vvar pages faults (timens, hv clock) */
    if (end - start > PS_RTSETUP_PREFAULT_MAX_MAPPING_BYTES)
        return 0;
    uintptr_t stop = end;
    if (name[0] == '/') {
        if (has_suffix(name, " (deleted)"))
            return 0;
        struct stat st;
        if (stat(name, &st) != 0 || !S_ISREG(st.st_mode))
            return 0; /* device mappings (/dev/...), vanished files */
        /* Pages wholly past the end of the file raise SIGBUS when read. */
        if ((unsigned long long)st.st_size <= offset)
            return 0;
        const unsigned long long in_file = (unsigned long long)st.st_size - offset;
        if (in_file < end - start)
            stop = start + (uintptr_t)in_file;
    } else if (inode != 0) {
        return 0; /* a file we cannot name: do not guess its size */
    }
    /* anonymous, [heap], [stack], [vdso], [anon:...] */
    touch_pages(start, stop, page);
    return (long)((stop - start + page - 1) / page);
}

long ps_rtsetup_prefault_maps(void)
{
    const int fd = open("/proc/self/maps", O_RDONLY | O_CLOEXEC);
    if (fd < 0)
        return -errno;
    const size_t page = page_size();
    /* Lines are read into a fixed buffer; a line longer than it (a path
     * near PATH_MAX) is dropped rather than split. */
    char buf[8192];
    size_t used = 0;
    long n_pages = 0;
    int is_skipping = 0;
    for (;;) {
        const ssize_t got = read(fd, buf + used, sizeof(buf) - 1 - used);
        if (got < 0) {
            if (errno == EINTR)
                continue;
            const int err = errno;
            (void)close(fd); /* read error wins */
            return -err;
        }
        if (got == 0)
            break;
        used += (size_t)got;
        buf[used] = '\0';
        char *line = buf;
        char *nl;
        while ((nl = memchr(line, '\n', used - (size_t)(line - buf))) != NULL) {
            *nl = '\0';
            if (!is_skipping)
                n_pages += prefault_line(line, page);
            is_skipping = 0;
            line = nl + 1;
        }
        used -= (size_t)(line - buf);
        memmove(buf, line, used);
        if (used == sizeof(buf) - 1) {
            is_skipping = 1; /* overlong line: drop its head, then its tail */
            used = 0;
        }
    }
    if (used > 0 && !is_skipping) {
        buf[used] = '\0';
        n_pages += prefault_line(buf, page);
    }
    (void)close(fd); /* read-only fd: nothing to lose */
    return n_pages;
}

/* Append to buf at *off; stops quietly when full (vsnprintf truncates). */
__attribute__((format(printf, 4, 5))) static void append(char *buf, size_t len, size_t *off,
                                                         const char *fmt, ...)
{
    if (*off + 1 >= len)
        return;
    va_list ap;
    va_start(ap, fmt);
    const int w = vsnprintf(buf + *off, len - *off, fmt, ap);
    va_end(ap);
    if (w < 0)
        return;
    *off += (size_t)w < len - *off ? (size_t)w : len - *off - 1;
}

/* One item: name, optional detail, and the errno text if a failure was seen. */
static void append_item(char *buf, size_t len, size_t *off, const char *name, int err,
                        const char *detail, long value)
{
    append(buf, len, off, "%s%s", *off > 0 ? ", " : "", name);
    if (err == 0)
        return; /* never failed here (not attempted, or failed in another way) */
    if (detail != NULL)
        append(buf, len, off, " %s %ld", detail, value);
    append(buf, len, off, " (%s)", ps_strerror(err));
}

void ps_rtsetup_describe(unsigned missing, char *buf, size_t len)
{
    if (len == 0)
        return;
    buf[0] = '\0';
    size_t off = 0;
    if (missing & PS_RT_MISSING_MLOCK)
        append_item(buf, len, &off, "mlockall", atomic_load(&g_mlock_errno), NULL, 0);
    if (missing & PS_RT_MISSING_FIFO)
        append_item(buf, len, &off, "SCHED_FIFO", atomic_load(&g_fifo_errno), "priority",
                    (long)atomic_load(&g_fifo_priority));
    if (missing & PS_RT_MISSING_AFFINITY)
        append_item(buf, len, &off, "CPU affinity", atomic_load(&g_affinity_errno), "cpu",
                    (long)atomic_load(&g_affinity_cpu));
    if (missing & PS_RT_MISSING_CPU_LATENCY)
        append_item(buf, len, &off, "/dev/cpu_dma_latency", atomic_load(&g_cpu_latency_errno), NULL,
                    0);
}
