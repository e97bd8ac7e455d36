/**
 * @file td_ring.c
 * @brief SPSC rings (td_ring.h).
 */
#include "td_ring.h"

#include <stddef.h>
#include <string.h>

#define LOAD_ACQ(p) __atomic_load_n((p), __ATOMIC_ACQUIRE)
#define STORE_REL(p, v) __atomic_store_n((p), (v), __ATOMIC_RELEASE)
#define LOAD_OWN(p) __atomic_load_n((p), __ATOMIC_RELAXED)

void td_frame_ring_init(td_frame_ring_t *r) {
    memset(r, 0, sizeof *r);
}

bool td_frame_ring_push(td_frame_ring_t *r, const td_can_frame_t *f) {
    const uint32_t head = LOAD_OWN(&r->head);
    if (head - LOAD_ACQ(&r->tail) >= TD_FRAME_RING_LEN) {
        r->dropped++;
        return false;
    }
    r->slot[head & (TD_FRAME_RING_LEN - 1u)] = *f;
    STORE_REL(&r->head, head + 1u); /* the slot is written before the consumer may see it */
    return true;
}

bool td_frame_ring_pop(td_frame_ring_t *r, td_can_frame_t *f) {
    const uint32_t tail = LOAD_OWN(&r->tail);
    if (LOAD_ACQ(&r->head) == tail) {
        return false;
    }
    *f = r->slot[tail & (TD_FRAME_RING_LEN - 1u)];
    STORE_REL(&r->tail, tail + 1u); /* the slot is read before the producer may reuse it */
    return true;
}

uint32_t td_frame_ring_count(const td_frame_ring_t *r) {
    return LOAD_ACQ(&r->head) - LOAD_ACQ(&r->tail);
}

void td_byte_ring_init(td_byte_ring_t *r) {
    memset(r, 0, sizeof *r);
}

bool td_byte_ring_push(td_byte_ring_t *r, uint8_t b) {
    return td_byte_ring_write(r, &b, 1u);
}

bool td_byte_ring_write(td_byte_ring_t *r, const uint8_t *b, uint32_t n) {
    const uint32_t head = LOAD_OWN(&r->head);
    if (TD_BYTE_RING_LEN - (head - LOAD_ACQ(&r->tail)) < n) {
        r->dropped += n;
        return false;
    }
    for (uint32_t i = 0u; i < n; i++) {
        r->slot[(head + i) & (TD_BYTE_RING_LEN - 1u)] = b[i];
    }
    STORE_REL(&r->head, head + n);
    return true;
}

bool td_byte_ring_pop(td_byte_ring_t *r, uint8_t *b) {
    const uint32_t tail = LOAD_OWN(&r->tail);
    if (LOAD_ACQ(&r->head) == tail) {
        return false;
    }
    *b = r->slot[tail & (TD_BYTE_RING_LEN - 1u)];
    STORE_REL(&r->tail, tail + 1u);
    return true;
}

uint32_t td_byte_ring_count(const td_byte_ring_t *r) {
    return LOAD_ACQ(&r->head) - LOAD_ACQ(&r->tail);
}
