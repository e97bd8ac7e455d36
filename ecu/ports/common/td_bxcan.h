/**
 * @file td_bxcan.h
 * @brief The arithmetic of ST's bxCAN controller, free of registers so the host tests check it:
 *        bit timing (CAN_BTR), 32-bit identifier-list filters (CAN_FiR1/2), and the identifier
 *        and data words of the mailboxes. Section numbers are of RM0090 rev 19 (STM32F405/407).
 */
#ifndef TD_BXCAN_H
#define TD_BXCAN_H

#include <stdbool.h>
#include <stdint.h>
#include "td_port.h"

#define TD_BXCAN_IDE (1u << 2)   /**< identifier word: extended identifier (32.9.3 CAN_TIxR/RIxR) */
#define TD_BXCAN_RTR (1u << 1)   /**< identifier word: remote frame */
#define TD_BXCAN_BANKS 14u       /**< filter banks CAN1 owns with the reset split (CAN_FMR.CAN2SB = 14) */

/** One bit timing (32.7.7): bit = (1 + ts1 + ts2) time quanta of brp / f_pclk each. */
typedef struct {
    uint16_t brp;              /**< prescaler, 1..1024 */
    uint8_t ts1;               /**< time segment 1 (propagation + phase 1), 1..16 tq */
    uint8_t ts2;               /**< time segment 2 (phase 2), 2..8 tq */
    uint8_t sjw;               /**< resynchronisation jump width, 1..4 tq (= min(4, ts2)) */
    uint16_t sample_permille;  /**< sample point, (1 + ts1) / (1 + ts1 + ts2), per mille */
    uint32_t btr;              /**< the CAN_BTR value (32.9.2), normal mode */
} td_bxcan_timing_t;

/**
 * The exact bit timing for `bitrate` (bit/s) from the APB1 clock `pclk_hz` whose sample point is
 * nearest to `sample_permille` (875 = 87.5 %, CiA 301's recommendation); among equals, the most
 * quanta per bit. TD_E_RANGE when no prescaler gives the bit rate exactly (8..25 quanta per bit);
 * TD_E_ARG for a zero argument or a sample point outside 500..950.
 */
int td_bxcan_timing(uint32_t pclk_hz, uint32_t bitrate, uint16_t sample_permille, td_bxcan_timing_t *out);

/** Identifier word as CAN_TIxR, CAN_RIxR and the 32-bit filters hold it (32.9.3, 32.7.4). */
uint32_t td_bxcan_id_word(uint32_t id, bool extended, bool remote);

/** A 32-bit filter bank in identifier-list mode: two identifier words (32.7.4, figure 342). */
typedef struct {
    uint32_t fr1;
    uint32_t fr2;
} td_bxcan_bank_t;

/**
 * Identifier-list banks that pass exactly the extended data frames with identifiers `ids`
 * (29-bit), two per bank (an odd last one repeated). Returns the banks used, TD_E_ARG for an
 * identifier above 29 bits, TD_E_FULL when more than 2 x max_banks identifiers are asked for.
 */
int td_bxcan_filters_ext(const uint32_t *ids, unsigned n, td_bxcan_bank_t *banks, unsigned max_banks);

/** What the banks pass (the hardware's acceptance, for the tests and a software double check). */
bool td_bxcan_accepts(const td_bxcan_bank_t *banks, unsigned nbanks, uint32_t id, bool extended, bool remote);

/** A received mailbox (CAN_RIxR, CAN_RDTxR, CAN_RDLxR, CAN_RDHxR) as a frame; false for a
 *  remote frame (the ECU takes data frames only). */
bool td_bxcan_rx_frame(uint32_t rir, uint32_t rdtr, uint32_t rdlr, uint32_t rdhr, td_can_frame_t *f);

/** A frame as the words of a transmit mailbox (TIR without TXRQ, TDTR, TDLR, TDHR). */
void td_bxcan_tx_words(const td_can_frame_t *f, uint32_t *tir, uint32_t *tdtr, uint32_t *tdlr, uint32_t *tdhr);

#endif /* TD_BXCAN_H */
