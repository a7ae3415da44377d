/*
 * fuzz: helpers the libFuzzer targets in tests/fuzz/ share (docs/fuzzing.md).
 *
 * Each target is one file fuzz_<what>.c with LLVMFuzzerTestOneInput; it feeds
 * the input to one parser of outside input and checks the parser's contract:
 * a negative error code, or a result that is validated (finite, inside the
 * protocol's stated ranges). A broken contract aborts with a message, which
 * libFuzzer reports as a crash and saves as crash-<sha1>. AddressSanitizer
 * and UBSan (-fsanitize=fuzzer,address,undefined) catch reads past the input,
 * leaks and undefined behaviour.
 *
 * Frames: the CAN frame struct always has 64 payload bytes, so a read past
 * f->len is not an overflow ASan could see. fuzz_frame_poison fills the bytes
 * past len with a pattern; a target decodes each frame twice with different
 * patterns and requires the same result.
 *
 * Files: the loaders of files (YAML, policy files, MCAP, candump logs) take a
 * path. fuzz_memfd puts the input in an anonymous in-memory file (memfd) and
 * gives its /proc/self/fd path, so the real entry point runs, file read
 * included, without touching a disk.
 */
#ifndef PS_FUZZ_H
#define PS_FUZZ_H

#include <math.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "../../drivers/ps_can.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* A broken contract: print why and abort (libFuzzer saves the input). */
__attribute__((format(printf, 1, 2), noreturn)) static inline void fuzz_fail(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    fputs("fuzz: contract broken: ", stderr);
    vfprintf(stderr, fmt, ap);
    fputc('\n', stderr);
    va_end(ap);
    abort();
}

#define FUZZ_CHECK(cond, ...)                                                                      \
    do {                                                                                           \
        if (!(cond))                                                                               \
            fuzz_fail(__VA_ARGS__);                                                                \
    } while (0)

/* A read cursor over the input. */
typedef struct {
    const uint8_t *p;
    size_t n;
} fuzz_in_t;

static inline uint8_t fuzz_u8(fuzz_in_t *in)
{
    if (in->n == 0)
        return 0;
    in->n--;
    return *in->p++;
}

static inline uint32_t fuzz_u32(fuzz_in_t *in)
{
    uint32_t v = 0;
    for (int i = 0; i < 4; i++)
        v |= (uint32_t)fuzz_u8(in) << (8 * i);
    return v;
}

static inline float fuzz_f32(fuzz_in_t *in)
{
    const uint32_t u = fuzz_u32(in);
    float f;
    memcpy(&f, &u, sizeof f);
    return f;
}

/* One frame record: flags (bit 0 29-bit id, bit 1 FD, bit 2 BRS), id (4
 * bytes LE, masked to the id width, as a CAN controller delivers it), len (1
 * byte, capped at 64), then min(len, what is left) payload bytes: len is the
 * number actually taken. t_ns: the caller's. @return false at the end. */
static inline bool fuzz_next_frame(fuzz_in_t *in, ps_can_frame_t *f, int64_t t_ns)
{
    if (in->n == 0)
        return false;
    memset(f, 0, sizeof(*f));
    const uint8_t flags = fuzz_u8(in);
    f->is_ext = (uint8_t)(flags & 1u);
    f->is_fd = (uint8_t)((flags >> 1) & 1u);
    f->is_brs = (uint8_t)((flags >> 2) & 1u);
    f->id = fuzz_u32(in) & (f->is_ext ? PS_CAN_EFF_MASK : PS_CAN_SFF_MASK);
    size_t len = fuzz_u8(in);
    if (len > PS_CAN_FD_MAX_DLEN)
        len = PS_CAN_FD_MAX_DLEN;
    if (len > in->n)
        len = in->n;
    f->len = (uint8_t)len;
    memcpy(f->data, in->p, len);
    in->p += len;
    in->n -= len;
    f->t_ns = t_ns;
    return true;
}

/* Fill the payload bytes past f->len with pattern. */
static inline void fuzz_frame_poison(ps_can_frame_t *f, uint8_t pattern)
{
    if (f->len < PS_CAN_FD_MAX_DLEN)
        memset(&f->data[f->len], pattern, PS_CAN_FD_MAX_DLEN - f->len);
}

static inline bool fuzz_in_range(float x, float lo, float hi)
{
    return isfinite(x) && x >= lo && x <= hi;
}

/* The input as an in-memory file. @post path holds "/proc/self/fd/N"
 * @return the fd (close it after use) or -1. */
static inline int fuzz_memfd(const uint8_t *data, size_t size, char *path, size_t path_len)
{
    const int fd = memfd_create("fuzz", MFD_CLOEXEC);
    if (fd < 0)
        return -1;
    size_t off = 0;
    while (off < size) {
        const ssize_t w = write(fd, data + off, size - off);
        if (w <= 0) {
            close(fd);
            return -1;
        }
        off += (size_t)w;
    }
    snprintf(path, path_len, "/proc/self/fd/%d", fd);
    return fd;
}

#endif /* PS_FUZZ_H */
