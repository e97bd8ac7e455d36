/**
 * @file td_isob.h
 * @brief The topdress implement's ISOBUS node: address claim, TP/ETP and the TC client behind
 *        one receive call, one step and one transmit queue (what a port or the simulator wires
 *        to its CAN driver).
 *
 * Port contract: call td_isob_rx() for every extended frame received, td_isob_step() every
 * control period (10 ms) with the time and the implement's odometer, and send what
 * td_isob_tx() hands out until it returns false. No heap, no globals; the state's size on a
 * Cortex-M4 is isobus_cm4_state_bytes of docs/figures.md (most of it the DDOP copy with our
 * NAME).
 */
#ifndef TD_ISOB_H
#define TD_ISOB_H

#include <stdbool.h>
#include <stdint.h>

#include "td_claim.h"
#include "td_prop.h"
#include "td_tc.h"
#include "td_tp.h"

#define TD_ISOB_CONN_BUF 64u /**< connection-mode messages to us: the TC sends nothing longer */
#define TD_ISOB_BAM_BUF 32u  /**< broadcasts: none is needed; kept short */

typedef struct {
    td_claim_t claim;
    td_tp_t tp;
    td_tc_t tc;
    td_ib_txq_t q;
    uint8_t conn_buf[TD_ISOB_CONN_BUF];
    uint8_t bam_buf[TD_ISOB_BAM_BUF];
    uint32_t rx_frames; /**< frames taken */
    uint32_t rx_errors; /**< malformed frames (counted, dropped) */
    uint32_t prop_rx;           /**< the terminal's private frames taken (td_isob_prop_rx) */
    uint32_t prop_wrong_source; /**< private frames from an address not our TC's (dropped) */
} td_isob_t;

/** `name` from td_ibname_encode(); the preferred address and fallback range as td_claim_init;
 *  `tc_timeout_us` the loss of the TC (the cab PC's command timeout). */
int td_isob_init(td_isob_t *n, uint64_t name, uint8_t preferred, uint8_t range_lo,
                 uint8_t range_hi, uint32_t tc_timeout_us);
/** Starts the address claim. */
int td_isob_start(td_isob_t *n, uint32_t now_us);
/** One received frame. Returns 0 when taken or ignored, negative when malformed. */
int td_isob_rx(td_isob_t *n, const td_can_frame_t *f, uint32_t now_us);
/** The control period's work. */
void td_isob_step(td_isob_t *n, uint32_t now_us, uint32_t distance_mm);
/**
 * A received frame that is one of the terminal's private frames (td_prop.h) from the address
 * of our Task Controller (the terminal): 1, `core` then holds it with the paper's fixed
 * identifier for the control core; 0 for other traffic; TD_IB_E_SOURCE when it came from
 * another address or no TC is known: dropped and counted in `prop_wrong_source`.
 */
int td_isob_prop_rx(td_isob_t *n, const td_can_frame_t *f, td_can_frame_t *core);
/**
 * A frame of the control core as it goes on the ISOBUS: from our claimed address (to the TC
 * for Proprietary A). TD_IB_E_NO_ADDRESS before the claim or, for Proprietary A, without a TC;
 * TD_IB_E_FRAME for a frame with no ISOBUS form. Either way nothing is to be sent.
 */
int td_isob_prop_tx(const td_isob_t *n, const td_can_frame_t *core, td_can_frame_t *out);
/** The next frame to send; false when none. */
bool td_isob_tx(td_isob_t *n, td_can_frame_t *out);

#endif
