/**
 * @file td_claim.h
 * @brief J1939-81 / ISO 11783-5 address claim: claim a preferred address, defend it by NAME,
 *        move to a free address of a fallback range when a lower NAME takes it, and send
 *        Cannot Claim Address when the range is exhausted.
 *
 * Timing: an address counts as claimed 250 ms after our Address Claimed went out without a
 * contest lost. A Request for Address Claimed (to global or to us) is answered at once.
 * Every address another node claims is remembered (256-bit map) so a re-claim picks a free one.
 */
#ifndef TD_CLAIM_H
#define TD_CLAIM_H

#include <stdbool.h>
#include <stdint.h>

#include "td_ib.h"

#define TD_CLAIM_WAIT_US 250000u /**< contest window after an Address Claimed */

typedef enum {
    TD_CLAIM_IDLE = 0,     /**< not started */
    TD_CLAIM_CLAIMING = 1, /**< Address Claimed sent, 250 ms window running */
    TD_CLAIM_CLAIMED = 2,  /**< address ours: may send */
    TD_CLAIM_FAILED = 3    /**< Cannot Claim Address sent: silent except for Requests */
} td_claim_state_t;

typedef struct {
    uint64_t name;
    uint8_t preferred;    /**< preferred address */
    uint8_t range_lo;     /**< fallback range, inclusive (self-configurable NAMEs only) */
    uint8_t range_hi;
    uint8_t address;      /**< address being claimed or claimed; TD_IB_ADDR_NULL when none */
    td_claim_state_t state;
    uint32_t since_us;    /**< time our last Address Claimed went out */
    uint32_t used[8];     /**< addresses other NAMEs hold (bit per address) */
    uint32_t contests_won;
    uint32_t contests_lost;
} td_claim_t;

/** Sets up the claimer. The fallback range is only used if bit 63 of `name` (self-configurable)
 *  is set. TD_IB_E_ARG for addresses above 253 or an empty range. */
int td_claim_init(td_claim_t *c, uint64_t name, uint8_t preferred, uint8_t range_lo,
                  uint8_t range_hi);
/** Starts (or restarts) the claim: Address Claimed with the preferred address is queued. */
int td_claim_start(td_claim_t *c, uint32_t now_us, td_ib_txq_t *q);
/** Feeds a received frame. Returns 1 if it was an address-claim frame or Request for it that
 *  this module handled, 0 if not its frame, negative on error. */
int td_claim_rx(td_claim_t *c, const td_can_frame_t *f, uint32_t now_us, td_ib_txq_t *q);
/** Advances the 250 ms window. */
void td_claim_step(td_claim_t *c, uint32_t now_us);
/** The address we may send from, or TD_IB_ADDR_NULL while not claimed. */
uint8_t td_claim_address(const td_claim_t *c);

#endif
