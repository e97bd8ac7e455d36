/**
 * @file td_tp.h
 * @brief Transport protocols of J1939-21 / ISO 11783-3: TP (BAM to all, CMDT to one node,
 *        9..1785 bytes) and ETP (to one node, 1786..117,440,505 bytes), sending and receiving,
 *        with aborts and the standard timeouts.
 *
 * One session per direction and kind runs at a time: one connection-mode receive (TP or ETP),
 * one broadcast (BAM) receive and one send. A second RTS while the receive session runs is
 * answered with Abort reason 1 (already in a session). Buffers belong to the caller: the
 * receive buffers are given at init, the data of a send must stay unchanged until the send ends.
 *
 * Timeouts (J1939-21): T1 750 ms between data packets, T2 1250 ms after our CTS, T3 1250 ms
 * waiting for CTS/EOMA after our last packet, T4 1050 ms after a CTS that holds (0 packets),
 * Tr 200 ms for our own answer is met because every answer is queued at once. BAM packets go
 * out 50 ms apart. A receive that times out sends Abort reason 3 and is dropped; a send that
 * times out sends Abort reason 3 and ends as TD_TP_TX_TIMEOUT.
 */
#ifndef TD_TP_H
#define TD_TP_H

#include <stdbool.h>
#include <stdint.h>

#include "td_ib.h"

#define TD_TP_MAX_TP 1785u         /**< 255 packets of 7 bytes */
#define TD_TP_MAX_ETP 117440505u   /**< 2^24-1 packets of 7 bytes */
#define TD_TP_PACKETS_PER_CTS 16u  /**< packets we ask for (and offer) per CTS */
#define TD_TP_T1_US 750000u
#define TD_TP_T2_US 1250000u
#define TD_TP_T3_US 1250000u
#define TD_TP_T4_US 1050000u
#define TD_TP_BAM_GAP_US 50000u

/** Abort reasons (J1939-21 Table 7 / ISO 11783-3). */
typedef enum {
    TD_TP_ABORT_BUSY = 1,        /**< already in one or more connection-managed sessions */
    TD_TP_ABORT_RESOURCES = 2,   /**< system resources needed elsewhere (message too long) */
    TD_TP_ABORT_TIMEOUT = 3,     /**< a timeout occurred */
    TD_TP_ABORT_CTS_IN_DT = 4,   /**< CTS received while data transfer in progress */
    TD_TP_ABORT_BAD_SEQUENCE = 7 /**< bad sequence number */
} td_tp_abort_t;

typedef enum { TD_TP_KIND_NONE = 0, TD_TP_KIND_BAM, TD_TP_KIND_TP, TD_TP_KIND_ETP } td_tp_kind_t;

/** Outcome of the last send. */
typedef enum {
    TD_TP_TX_IDLE = 0,  /**< nothing sent yet */
    TD_TP_TX_BUSY,      /**< running */
    TD_TP_TX_DONE,      /**< BAM sent / EOMA received */
    TD_TP_TX_ABORTED,   /**< the receiver aborted (reason in tx.abort_reason) */
    TD_TP_TX_TIMEOUT    /**< no CTS/EOMA in time: we aborted */
} td_tp_tx_state_t;

/** A receive session (connection mode or BAM). */
typedef struct {
    td_tp_kind_t kind;
    uint8_t sa, da;
    uint32_t pgn;
    uint32_t size;        /**< bytes announced */
    uint32_t next_packet; /**< 0-based index of the next expected packet */
    uint32_t window_end;  /**< packets below this index are asked for by our last CTS */
    uint32_t dpo_offset;  /**< ETP: packet offset of the current DPO */
    bool dpo_seen;        /**< ETP: DPO of the current window received */
    uint8_t max_per_cts;  /**< TP: the sender's limit of packets per CTS (0xFF none) */
    uint32_t last_us;     /**< time of the last event */
    uint32_t timeout_us;  /**< allowed gap after the last event */
    uint8_t *buf;
    uint32_t cap;
} td_tp_rx_t;

/** A complete received message; `data` points into the receive buffer and stays valid until
 *  the next session of its kind starts. */
typedef struct {
    uint32_t pgn;
    uint8_t sa, da;
    const uint8_t *data;
    uint32_t len;
} td_tp_msg_t;

typedef struct {
    td_tp_kind_t kind;
    td_tp_tx_state_t state;
    uint8_t sa, da;
    uint32_t pgn;
    const uint8_t *data;
    uint32_t size;
    uint32_t packets;     /**< total packets */
    uint32_t next_packet; /**< 0-based index of the next packet to send */
    uint32_t window_end;  /**< send packets below this index, then wait */
    uint32_t dpo_offset;  /**< ETP: offset announced by our last DPO */
    bool waiting;         /**< waiting for CTS or EOMA */
    uint32_t last_us;
    uint32_t timeout_us;
    uint8_t abort_reason; /**< reason of the abort that ended the send */
} td_tp_tx_t;

typedef struct {
    td_tp_rx_t conn;  /**< TP CMDT or ETP receive */
    td_tp_rx_t bam;   /**< broadcast receive */
    td_tp_tx_t tx;
    td_tp_msg_t msg;  /**< the last complete message */
    uint32_t rx_done, rx_aborts, rx_timeouts, rx_ignored;
} td_tp_t;

/** `conn_buf` takes connection-mode messages (a TC's messages to the ECU), `bam_buf` broadcasts. */
int td_tp_init(td_tp_t *tp, uint8_t *conn_buf, uint32_t conn_cap, uint8_t *bam_buf,
               uint32_t bam_cap);
/** Starts a send of 9..TD_TP_MAX_ETP bytes. `da` global: BAM (max 1785 B); otherwise TP up to
 *  1785 B, ETP above. TD_IB_E_BUSY while a send runs, TD_IB_E_TOO_LONG, TD_IB_E_ARG. */
int td_tp_send(td_tp_t *tp, uint32_t pgn, uint8_t sa, uint8_t da, const uint8_t *data,
               uint32_t len, uint32_t now_us, td_ib_txq_t *q);
/** Feeds a received frame; `my_addr` is our claimed address. Returns 1 when a message is
 *  complete (read it from tp->msg), 0 if the frame was taken or not a transport frame,
 *  negative when it was malformed (counted in rx_ignored). */
int td_tp_rx(td_tp_t *tp, const td_can_frame_t *f, uint8_t my_addr, uint32_t now_us,
             td_ib_txq_t *q);
/** Sends due packets and runs the timeouts. */
void td_tp_step(td_tp_t *tp, uint32_t now_us, td_ib_txq_t *q);
/** Ends the running send with an Abort (reason 2) to its receiver. */
void td_tp_cancel(td_tp_t *tp, td_ib_txq_t *q);

#endif
