/**
 * @file td_ring.h
 * @brief Lock-free single-producer single-consumer rings: CAN frames (receive interrupt -> main
 *        loop) and bytes (serial receive interrupt -> main loop, main loop -> transmit interrupt).
 *
 * One side only ever writes `head` (the producer), the other only `tail` (the consumer); both are
 * free-running uint32_t counters (their difference is the fill, modulo 2^32), so no slot is
 * wasted and no lock is taken. Indices are published with release stores and read with acquire
 * loads (GCC/Clang __atomic builtins: on a Cortex-M4 plain loads/stores with a DMB, on the host
 * what the sanitizers and the two-thread test check). The capacity is a power of two.
 * A full ring refuses the new element and counts it (`dropped`, written by the producer only).
 */
#ifndef TD_RING_H
#define TD_RING_H

#include <stdbool.h>
#include <stdint.h>
#include "td_port.h"

#define TD_FRAME_RING_LEN 32u   /**< received CAN frames held, power of two */
#define TD_BYTE_RING_LEN 512u   /**< serial bytes held, power of two */

typedef struct {
    uint32_t head;              /**< written by the producer only */
    uint32_t tail;              /**< written by the consumer only */
    uint32_t dropped;           /**< elements refused because the ring was full (producer) */
    td_can_frame_t slot[TD_FRAME_RING_LEN];
} td_frame_ring_t;

typedef struct {
    uint32_t head;
    uint32_t tail;
    uint32_t dropped;
    uint8_t slot[TD_BYTE_RING_LEN];
} td_byte_ring_t;

/** Empty ring. Not concurrent with anything. */
void td_frame_ring_init(td_frame_ring_t *r);
/** Producer: append a copy of *f. false (and dropped + 1) when full. */
bool td_frame_ring_push(td_frame_ring_t *r, const td_can_frame_t *f);
/** Consumer: take the oldest frame into *f. false when empty. */
bool td_frame_ring_pop(td_frame_ring_t *r, td_can_frame_t *f);
/** Either side: frames held now (a snapshot). */
uint32_t td_frame_ring_count(const td_frame_ring_t *r);

void td_byte_ring_init(td_byte_ring_t *r);
bool td_byte_ring_push(td_byte_ring_t *r, uint8_t b);
/** Producer: append all n bytes or none (a whole SLCAN line or nothing). */
bool td_byte_ring_write(td_byte_ring_t *r, const uint8_t *b, uint32_t n);
bool td_byte_ring_pop(td_byte_ring_t *r, uint8_t *b);
uint32_t td_byte_ring_count(const td_byte_ring_t *r);

#endif /* TD_RING_H */
