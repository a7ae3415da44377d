#include "ps_mailbox.h"

#include <errno.h>
#include <string.h>

/* Bit of `middle` set while the middle slot holds a value not read yet. */
#define PS_MAILBOX_FRESH 0x4u
#define PS_MAILBOX_IDX   0x3u

int ps_mailbox_init(ps_mailbox_t *mb, void *storage, size_t slot_size)
{
    if (mb == NULL || storage == NULL || slot_size == 0)
        return -EINVAL;
    memset(storage, 0, PS_MAILBOX_SLOTS * slot_size);
    mb->storage = storage;
    mb->slot_size = slot_size;
    mb->front_idx = 0;
    mb->back_idx = 2;
    atomic_init(&mb->middle, 1u);
    atomic_init(&mb->n_published, 0u);
    atomic_init(&mb->n_taken, 0u);
    return 0;
}

void *ps_mailbox_write_slot(ps_mailbox_t *mb)
{
    return mb->storage + (size_t)mb->back_idx * mb->slot_size;
}

void ps_mailbox_publish(ps_mailbox_t *mb)
{
    /* Release: the slot's content is visible before the reader can take it.
     * Acquire: the slot handed back was released by the reader's exchange,
     * so its reads of that slot are over before this thread writes it. */
    const uint32_t old =
        atomic_exchange_explicit(&mb->middle, mb->back_idx | PS_MAILBOX_FRESH, memory_order_acq_rel);
    mb->back_idx = old & PS_MAILBOX_IDX;
    atomic_fetch_add_explicit(&mb->n_published, 1u, memory_order_relaxed);
}

void ps_mailbox_put(ps_mailbox_t *mb, const void *value)
{
    memcpy(ps_mailbox_write_slot(mb), value, mb->slot_size);
    ps_mailbox_publish(mb);
}

const void *ps_mailbox_read(ps_mailbox_t *mb, bool *out_is_new)
{
    const bool is_new =
        (atomic_load_explicit(&mb->middle, memory_order_relaxed) & PS_MAILBOX_FRESH) != 0u;
    if (is_new) {
        /* Only the reader clears FRESH, so it is still set here; the writer
         * may have swapped a newer slot in meanwhile, which is what we take. */
        const uint32_t old =
            atomic_exchange_explicit(&mb->middle, mb->front_idx, memory_order_acq_rel);
        mb->front_idx = old & PS_MAILBOX_IDX;
        atomic_fetch_add_explicit(&mb->n_taken, 1u, memory_order_relaxed);
    }
    if (out_is_new != NULL)
        *out_is_new = is_new;
    return mb->storage + (size_t)mb->front_idx * mb->slot_size;
}

uint64_t ps_mailbox_n_published(const ps_mailbox_t *mb)
{
    return atomic_load_explicit(&mb->n_published, memory_order_relaxed);
}

uint64_t ps_mailbox_n_taken(const ps_mailbox_t *mb)
{
    return atomic_load_explicit(&mb->n_taken, memory_order_relaxed);
}
