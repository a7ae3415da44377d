/*
 * ps_mailbox: a latest-wins mailbox between one writer thread and one reader
 * thread (a triple buffer over C11 atomics). The writer fills its own slot and
 * publishes it; the reader takes the newest published slot. Neither side ever
 * waits for the other, spins, or retries: each operation is one atomic
 * exchange (wait-free, O(1) besides the caller's own copy), so the real-time
 * loop can read what the non-real-time perception thread writes at any rate.
 *
 * How: three slots, each owned by exactly one party at any time: the writer's
 * back slot, the reader's front slot, and the middle slot that an exchange
 * hands over, with a "fresh" bit saying it holds a value the reader has not
 * taken. Publishing swaps back and middle (setting fresh); reading, when
 * fresh is set, swaps front and middle. A slot is never written while the
 * reader holds it, so reads are never torn; a value published over another
 * that was not read yet replaces it (the older one is dropped, counted).
 *
 * Threads: exactly one writer thread and one reader thread (they may be the
 * same). Allocation: none; the caller provides 3 * slot_size bytes.
 */
#ifndef PS_MAILBOX_H
#define PS_MAILBOX_H

#include <stdatomic.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#define PS_MAILBOX_SLOTS 3u

typedef struct {
    uint8_t *storage;            /**< PS_MAILBOX_SLOTS * slot_size bytes */
    size_t slot_size;            /**< read-only */
    uint32_t back_idx;           /**< writer-owned */
    uint32_t front_idx;          /**< reader-owned */
    _Atomic uint32_t middle;     /**< slot index | PS_MAILBOX_FRESH */
    _Atomic uint64_t n_published; /**< values published so far */
    _Atomic uint64_t n_taken;     /**< values the reader took */
} ps_mailbox_t;

/** Set up an empty mailbox. Every slot is zeroed, so a read before the first
 *  publish returns an all-zero value (is_new false).
 *  @pre storage holds PS_MAILBOX_SLOTS * slot_size bytes  @post n_published 0
 *  @return 0 | -EINVAL (NULL pointer, slot_size 0)
 *  @rt INIT, before either thread uses it */
int ps_mailbox_init(ps_mailbox_t *mb, void *storage, size_t slot_size);

/** The writer's slot: fill it, then ps_mailbox_publish. Its content is
 *  whatever the slot last held (not necessarily the last value published).
 *  @return slot_size bytes, owned by the writer until publish
 *  @rt RT-SAFE O(1), writer thread only */
void *ps_mailbox_write_slot(ps_mailbox_t *mb);

/** Hand the writer's slot to the reader; the writer gets another slot.
 *  @post the next read returns this value (or a newer one)
 *  @rt RT-SAFE O(1) (one atomic exchange), wait-free, writer thread only */
void ps_mailbox_publish(ps_mailbox_t *mb);

/** Copy value (slot_size bytes) into the writer's slot and publish it.
 *  @rt RT-SAFE O(slot_size), wait-free, writer thread only */
void ps_mailbox_put(ps_mailbox_t *mb, const void *value);

/** The newest value published. out_is_new (may be NULL) says whether it was
 *  published since the previous read.
 *  @return slot_size bytes owned by the reader until its next read (the
 *  writer never touches them meanwhile)
 *  @rt RT-SAFE O(1) (at most one atomic exchange), wait-free, reader thread only */
const void *ps_mailbox_read(ps_mailbox_t *mb, bool *out_is_new);

/** @return values published, and values the reader took (the difference,
 *  published - taken, were replaced before being read)
 *  @rt RT-SAFE, any thread (relaxed loads) */
uint64_t ps_mailbox_n_published(const ps_mailbox_t *mb);
uint64_t ps_mailbox_n_taken(const ps_mailbox_t *mb);

#endif /* PS_MAILBOX_H */
