/**
 * @file td_ib.h
 * @brief Shared pieces of the topdress ISOBUS (ISO 11783 / SAE J1939) layer: error codes,
 *        identifier packing and the small transmit queue every module writes into.
 *
 * Same rules as the control core: no heap, no globals, no clock reads. Every function that
 * depends on time takes `now_us` (the port's free-running microsecond counter, differences
 * taken modulo 2^32). Errors are negative codes.
 */
#ifndef TD_IB_H
#define TD_IB_H

#include <stdbool.h>
#include <stdint.h>

#include "td_port.h"

/* ---- error codes of the ISOBUS layer (negative, below the core's) ---- */
#define TD_IB_OK 0
#define TD_IB_E_ARG (-20)       /**< NULL pointer or argument outside its domain */
#define TD_IB_E_FRAME (-21)     /**< frame not for this module, 11-bit, or wrong DLC */
#define TD_IB_E_BUSY (-22)      /**< a session of this kind is already running */
#define TD_IB_E_FULL (-23)      /**< transmit queue full: frame dropped */
#define TD_IB_E_TOO_LONG (-24)  /**< message longer than the buffer or the protocol allows */
#define TD_IB_E_NO_ADDRESS (-25) /**< no address claimed (yet, or cannot claim) */

#define TD_IB_ADDR_GLOBAL 0xFFu /**< destination "all" */
#define TD_IB_ADDR_NULL 0xFEu   /**< source of a Cannot Claim Address */

/** Parameter group numbers used by the layer. */
#define TD_IB_PGN_REQUEST 0x00EA00u       /**< Request (J1939-21) */
#define TD_IB_PGN_ADDRESS_CLAIM 0x00EE00u /**< Address Claimed / Cannot Claim (J1939-81) */
#define TD_IB_PGN_TP_CM 0x00EC00u         /**< TP connection management */
#define TD_IB_PGN_TP_DT 0x00EB00u         /**< TP data transfer */
#define TD_IB_PGN_ETP_CM 0x00C800u        /**< ETP connection management (ISO 11783-3) */
#define TD_IB_PGN_ETP_DT 0x00C700u        /**< ETP data transfer */

/** Capacity of the transmit queue (frames). */
#define TD_IB_TXQ_LEN 16u

/** Frames waiting for the CAN controller; the port drains it with td_ib_txq_pop(). */
typedef struct {
    td_can_frame_t f[TD_IB_TXQ_LEN];
    uint8_t head;  /**< index of the oldest frame */
    uint8_t count; /**< frames queued, 0..TD_IB_TXQ_LEN */
    uint32_t dropped; /**< frames lost because the queue was full */
} td_ib_txq_t;

/** A decoded 29-bit identifier. For PDU1 (PF < 240) `pgn` has its PS byte zeroed and `da` is
 *  the destination; for PDU2 `pgn` includes the group extension and `da` is TD_IB_ADDR_GLOBAL. */
typedef struct {
    uint8_t priority; /**< 0..7 */
    uint32_t pgn;     /**< 18-bit parameter group number */
    uint8_t sa;       /**< source address */
    uint8_t da;       /**< destination address */
} td_ib_id_t;

void td_ib_txq_init(td_ib_txq_t *q);
/** Appends a frame; TD_IB_E_FULL (and `dropped` counted) when full. */
int td_ib_txq_push(td_ib_txq_t *q, const td_can_frame_t *f);
/** Takes the oldest frame; false when empty. */
bool td_ib_txq_pop(td_ib_txq_t *q, td_can_frame_t *out);

/** Packs priority, PGN, destination and source into a 29-bit identifier (PDU2 ignores `da`). */
uint32_t td_ib_id_pack(uint8_t priority, uint32_t pgn, uint8_t da, uint8_t sa);
/** Unpacks a 29-bit identifier. */
td_ib_id_t td_ib_id_unpack(uint32_t id);

/** Queues one frame of 8 bytes (`data` exactly 8) with the given identifier fields. */
int td_ib_send8(td_ib_txq_t *q, uint8_t priority, uint32_t pgn, uint8_t da, uint8_t sa,
                const uint8_t data[8]);

/** Time from `since_us` to `now_us`, modulo 2^32. */
static inline uint32_t td_ib_elapsed_us(uint32_t now_us, uint32_t since_us) {
    return now_us - since_us;
}

/** Little-endian helpers. */
static inline uint32_t td_ib_get_u24(const uint8_t *p) {
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16);
}
static inline uint32_t td_ib_get_u32(const uint8_t *p) {
    return td_ib_get_u24(p) | ((uint32_t)p[3] << 24);
}
static inline void td_ib_put_u24(uint8_t *p, uint32_t v) {
    p[0] = (uint8_t)(v & 0xFFu);
    p[1] = (uint8_t)((v >> 8) & 0xFFu);
    p[2] = (uint8_t)((v >> 16) & 0xFFu);
}
static inline void td_ib_put_u32(uint8_t *p, uint32_t v) {
    td_ib_put_u24(p, v);
    p[3] = (uint8_t)((v >> 24) & 0xFFu);
}

#endif
