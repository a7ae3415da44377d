/*
 * ps_ring: SPSC ring of fixed-size records.
 *
 * head and tail are free-running 32-bit counters (slot = counter & mask), so
 * full is head - tail == n_slots and no slot is wasted; unsigned wrap-around
 * keeps the difference right as long as n_slots <= 2^31. The producer
 * publishes a record with a release store of head after copying it in; the
 * consumer's acquire load of head makes the copy visible. Symmetrically the
 * consumer releases the slot with a release store of tail.
 */
#include "ps_ring.h"

#include <errno.h>
#include <string.h>

int ps_ring_init(ps_ring_t *r, void *storage, uint32_t n_slots, size_t record_size)
{
    if (r == NULL || storage == NULL || record_size == 0)
        return -EINVAL;
    if (n_slots < 2 || n_slots > (UINT32_C(1) << 31) || (n_slots & (n_slots - 1u)) != 0)
        return -EINVAL;
    r->storage = storage;
    r->record_size = record_size;
    r->mask = n_slots - 1u;
    atomic_init(&r->head, 0);
    atomic_init(&r->tail, 0);
    atomic_init(&r->n_dropped, 0);
    return 0;
}

int ps_ring_push(ps_ring_t *r, const void *record)
{
    const uint32_t head = atomic_load_explicit(&r->head, memory_order_relaxed);
    const uint32_t tail = atomic_load_explicit(&r->tail, memory_order_acquire);
    if (head - tail > r->mask) {
        atomic_fetch_add_explicit(&r->n_dropped, 1, memory_order_relaxed);
        return -EAGAIN;
    }
    memcpy(r->storage + (size_t)(head & r->mask) * r->record_size, record, r->record_size);
    atomic_store_explicit(&r->head, head + 1u, memory_order_release);
    return 0;
}

int ps_ring_pop(ps_ring_t *r, void *out_record)
{
    const uint32_t tail = atomic_load_explicit(&r->tail, memory_order_relaxed);
    const uint32_t head = atomic_load_explicit(&r->head, memory_order_acquire);
    if (head == tail)
        return -EAGAIN;
    memcpy(out_record, r->storage + (size_t)(tail & r->mask) * r->record_size, r->record_size);
    atomic_store_explicit(&r->tail, tail + 1u, memory_order_release);
    return 0;
}

uint32_t ps_ring_count(const ps_ring_t *r)
{
    /* tail first: it only grows, so head - tail cannot go negative; from a
     * third thread head may have moved on meanwhile, hence the clamp. */
    const uint32_t tail = atomic_load_explicit(&r->tail, memory_order_acquire);
    const uint32_t head = atomic_load_explicit(&r->head, memory_order_acquire);
    const uint32_t n = head - tail;
    return n > r->mask + 1u ? r->mask + 1u : n;
}

uint64_t ps_ring_dropped(const ps_ring_t *r)
{
    return atomic_load_explicit(&r->n_dropped, memory_order_relaxed);
}
