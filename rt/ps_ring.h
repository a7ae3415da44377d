/*
 * ps_ring: single-producer / single-consumer lock-free ring of fixed-size
 * records (C11 atomics, acquire/release). The producer (the RT loop) never
 * blocks: when the ring is full the NEW record is dropped (the one being
 * pushed; the oldest records already in the ring are kept) and counted in
 * n_dropped. For status records that is the intended trade (a late reader
 * loses the newest status, not history); a consumer that must see the
 * latest state should read it elsewhere (ps_loop_get_state) and check
 * ps_ring_dropped().
 *
 * Threads: exactly one producer thread and one consumer thread.
 * Allocation: none; the caller provides the storage (n_slots * record_size
 * bytes, n_slots a power of two).
 */
#ifndef PS_RING_H
#define PS_RING_H

#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

typedef struct {
    uint8_t *storage;
    size_t record_size;
    uint32_t mask;              /**< n_slots - 1 */
    _Atomic uint32_t head;      /**< next slot to write (producer-owned) */
    _Atomic uint32_t tail;      /**< next slot to read (consumer-owned) */
    _Atomic uint64_t n_dropped; /**< records refused because full */
} ps_ring_t;

/** @pre storage holds n_slots * record_size bytes, n_slots power of two >= 2
 *  (at most 2^31), record_size > 0  @post ring empty, n_dropped 0
 *  @return 0 | -EINVAL (NULL pointer, record_size 0, n_slots not a power of
 *  two in [2, 2^31])  @rt INIT, before either thread uses it */
int ps_ring_init(ps_ring_t *r, void *storage, uint32_t n_slots, size_t record_size);

/** Copy one record in. @return 0 | -EAGAIN full (this, the newest, record
 *  dropped and counted; the ring is unchanged)
 *  @rt RT-SAFE O(record_size), producer thread only */
int ps_ring_push(ps_ring_t *r, const void *record);

/** Copy one record out. @return 0 | -EAGAIN empty  @rt RT-SAFE, consumer thread only */
int ps_ring_pop(ps_ring_t *r, void *out_record);

/** @return records waiting, 0..n_slots (approximate from the other thread)
 *  @rt RT-SAFE, any thread */
uint32_t ps_ring_count(const ps_ring_t *r);

/** @return records dropped so far  @rt RT-SAFE, any thread */
uint64_t ps_ring_dropped(const ps_ring_t *r);

#endif /* PS_RING_H */
