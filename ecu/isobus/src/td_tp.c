#include "td_tp.h"

#include <stddef.h>
#include <string.h>

#define TP_PRIORITY 7u

/* control bytes */
#define CM_RTS 16u
#define CM_CTS 17u
#define CM_EOMA 19u
#define CM_BAM 32u
#define ETP_RTS 20u
#define ETP_CTS 21u
#define ETP_DPO 22u
#define ETP_EOMA 23u
#define CM_ABORT 255u

static uint32_t packets_of(uint32_t size) {
    return (size + 6u) / 7u;
}

static uint32_t cm_pgn(td_tp_kind_t k) {
    return k == TD_TP_KIND_ETP ? TD_IB_PGN_ETP_CM : TD_IB_PGN_TP_CM;
}

static uint32_t dt_pgn(td_tp_kind_t k) {
    return k == TD_TP_KIND_ETP ? TD_IB_PGN_ETP_DT : TD_IB_PGN_TP_DT;
}

static void send_cm(td_ib_txq_t *q, td_tp_kind_t k, uint8_t da, uint8_t sa, uint8_t *d,
                    uint32_t pgn) {
    td_ib_put_u24(&d[5], pgn);
    (void)td_ib_send8(q, TP_PRIORITY, cm_pgn(k), da, sa, d);
}

static void send_abort(td_ib_txq_t *q, td_tp_kind_t k, uint8_t da, uint8_t sa, uint32_t pgn,
                       uint8_t reason) {
    uint8_t d[8] = {CM_ABORT, 0u, 0xFFu, 0xFFu, 0xFFu, 0u, 0u, 0u};
    d[1] = reason;
    send_cm(q, k, da, sa, d, pgn);
}

int td_tp_init(td_tp_t *tp, uint8_t *conn_buf, uint32_t conn_cap, uint8_t *bam_buf,
               uint32_t bam_cap) {
    if (tp == NULL || (conn_buf == NULL && conn_cap != 0u) || (bam_buf == NULL && bam_cap != 0u)) {
        return TD_IB_E_ARG;
    }
    memset(tp, 0, sizeof *tp);
    tp->conn.buf = conn_buf;
    tp->conn.cap = conn_cap;
    tp->bam.buf = bam_buf;
    tp->bam.cap = bam_cap;
    return TD_IB_OK;
}

/* ---------------------------------------------------------------- sending */

static void tx_end(td_tp_tx_t *t, td_tp_tx_state_t s) {
    t->state = s;
    t->kind = TD_TP_KIND_NONE;
}

static void send_dt(td_tp_tx_t *t, td_ib_txq_t *q) {
    uint8_t d[8];
    const uint32_t off = t->next_packet * 7u;
    uint32_t n = t->size - off;
    uint32_t seq = t->next_packet + 1u;
    if (t->kind == TD_TP_KIND_ETP) {
        seq = t->next_packet - t->dpo_offset + 1u;
    }
    if (n > 7u) {
        n = 7u;
    }
    memset(d, 0xFF, sizeof d);
    d[0] = (uint8_t)(seq & 0xFFu);
    memcpy(&d[1], &t->data[off], n);
    (void)td_ib_send8(q, TP_PRIORITY, dt_pgn(t->kind), t->da, t->sa, d);
    t->next_packet++;
}

/* Connection mode: as many packets of the window as the queue takes now. */
static void tx_pump(td_tp_tx_t *t, uint32_t now_us, td_ib_txq_t *q) {
    if (t->state != TD_TP_TX_BUSY || t->waiting) {
        return;
    }
    if (t->kind == TD_TP_KIND_BAM) {
        if (td_ib_elapsed_us(now_us, t->last_us) >= TD_TP_BAM_GAP_US && q->count < TD_IB_TXQ_LEN) {
            send_dt(t, q);
            t->last_us = now_us;
            if (t->next_packet >= t->packets) {
                tx_end(t, TD_TP_TX_DONE);
            }
        }
        return;
    }
    while (t->next_packet < t->window_end && q->count < TD_IB_TXQ_LEN) {
        send_dt(t, q);
    }
    if (t->next_packet >= t->window_end) {
        t->waiting = true;
        t->last_us = now_us;
        t->timeout_us = TD_TP_T3_US;
    }
}

int td_tp_send(td_tp_t *tp, uint32_t pgn, uint8_t sa, uint8_t da, const uint8_t *data,
               uint32_t len, uint32_t now_us, td_ib_txq_t *q) {
    td_tp_tx_t *t;
    uint8_t d[8];
    if (tp == NULL || data == NULL || q == NULL || len < 9u || sa > 253u || pgn > 0x3FFFFu) {
        return TD_IB_E_ARG;
    }
    t = &tp->tx;
    if (t->state == TD_TP_TX_BUSY) {
        return TD_IB_E_BUSY;
    }
    if (len > TD_TP_MAX_ETP || (da == TD_IB_ADDR_GLOBAL && len > TD_TP_MAX_TP)) {
        return TD_IB_E_TOO_LONG;
    }
    memset(t, 0, sizeof *t);
    t->state = TD_TP_TX_BUSY;
    t->sa = sa;
    t->da = da;
    t->pgn = pgn;
    t->data = data;
    t->size = len;
    t->packets = packets_of(len);
    t->last_us = now_us;
    t->waiting = true;
    t->timeout_us = TD_TP_T3_US;
    memset(d, 0xFF, sizeof d);
    if (da == TD_IB_ADDR_GLOBAL) {
        t->kind = TD_TP_KIND_BAM;
        d[0] = CM_BAM;
        d[1] = (uint8_t)(len & 0xFFu);
        d[2] = (uint8_t)(len >> 8);
        d[3] = (uint8_t)t->packets;
        t->waiting = false;
        t->window_end = t->packets;
    } else if (len <= TD_TP_MAX_TP) {
        t->kind = TD_TP_KIND_TP;
        d[0] = CM_RTS;
        d[1] = (uint8_t)(len & 0xFFu);
        d[2] = (uint8_t)(len >> 8);
        d[3] = (uint8_t)t->packets;
        d[4] = 0xFFu; /* no limit: the receiver's CTS decides */
    } else {
        t->kind = TD_TP_KIND_ETP;
        d[0] = ETP_RTS;
        td_ib_put_u32(&d[1], len);
    }
    send_cm(q, t->kind, da, sa, d, pgn);
    return TD_IB_OK;
}

static void tx_on_cm(td_tp_t *tp, const td_ib_id_t *id, const uint8_t *d, uint32_t now_us,
                     td_ib_txq_t *q) {
    td_tp_tx_t *t = &tp->tx;
    const bool etp = id->pgn == TD_IB_PGN_ETP_CM;
    if (t->state != TD_TP_TX_BUSY || t->kind == TD_TP_KIND_BAM || id->sa != t->da ||
        (t->kind == TD_TP_KIND_ETP) != etp || td_ib_get_u24(&d[5]) != t->pgn) {
        return;
    }
    if (d[0] == CM_ABORT) {
        t->abort_reason = d[1];
        tx_end(t, TD_TP_TX_ABORTED);
        return;
    }
    if (d[0] == CM_EOMA || d[0] == ETP_EOMA) {
        if (t->next_packet >= t->packets) {
            tx_end(t, TD_TP_TX_DONE);
        }
        return;
    }
    if (d[0] == CM_CTS || d[0] == ETP_CTS) {
        const uint32_t n = d[1];
        const uint32_t next = etp ? td_ib_get_u24(&d[2]) : d[2];
        if (!t->waiting) {
            send_abort(q, t->kind, t->da, t->sa, t->pgn, TD_TP_ABORT_CTS_IN_DT);
            t->abort_reason = TD_TP_ABORT_CTS_IN_DT;
            tx_end(t, TD_TP_TX_ABORTED);
            return;
        }
        t->last_us = now_us;
        if (n == 0u) {
            t->timeout_us = TD_TP_T4_US; /* hold */
            return;
        }
        if (next == 0u || next > t->packets) {
            send_abort(q, t->kind, t->da, t->sa, t->pgn, TD_TP_ABORT_BAD_SEQUENCE);
            t->abort_reason = TD_TP_ABORT_BAD_SEQUENCE;
            tx_end(t, TD_TP_TX_ABORTED);
            return;
        }
        t->next_packet = next - 1u;
        t->window_end = t->next_packet + n;
        if (t->window_end > t->packets) {
            t->window_end = t->packets;
        }
        if (etp) {
            uint8_t dpo[8] = {ETP_DPO, 0u, 0u, 0u, 0u, 0u, 0u, 0u};
            dpo[1] = (uint8_t)(t->window_end - t->next_packet);
            td_ib_put_u24(&dpo[2], t->next_packet);
            t->dpo_offset = t->next_packet;
            send_cm(q, t->kind, t->da, t->sa, dpo, t->pgn);
        }
        t->waiting = false;
        tx_pump(t, now_us, q);
    }
}

void td_tp_cancel(td_tp_t *tp, td_ib_txq_t *q) {
    td_tp_tx_t *t;
    if (tp == NULL || q == NULL) {
        return;
    }
    t = &tp->tx;
    if (t->state == TD_TP_TX_BUSY) {
        if (t->kind != TD_TP_KIND_BAM) {
            send_abort(q, t->kind, t->da, t->sa, t->pgn, TD_TP_ABORT_RESOURCES);
        }
        t->abort_reason = TD_TP_ABORT_RESOURCES;
        tx_end(t, TD_TP_TX_ABORTED);
    }
}

/* ---------------------------------------------------------------- receiving */

static void rx_drop(td_tp_rx_t *r) {
    r->kind = TD_TP_KIND_NONE;
}

static void rx_abort(td_tp_t *tp, td_tp_rx_t *r, td_ib_txq_t *q, uint8_t reason) {
    send_abort(q, r->kind, r->sa, r->da, r->pgn, reason);
    tp->rx_aborts++;
    rx_drop(r);
}

static void send_cts(td_tp_rx_t *r, uint32_t now_us, td_ib_txq_t *q) {
    uint8_t d[8] = {0u, 0u, 0u, 0u, 0u, 0u, 0u, 0u};
    uint32_t n = packets_of(r->size) - r->next_packet;
    if (n > TD_TP_PACKETS_PER_CTS) {
        n = TD_TP_PACKETS_PER_CTS;
    }
    if (r->kind == TD_TP_KIND_TP && r->max_per_cts != 0u && n > r->max_per_cts) {
        n = r->max_per_cts;
    }
    d[1] = (uint8_t)n;
    if (r->kind == TD_TP_KIND_ETP) {
        d[0] = ETP_CTS;
        td_ib_put_u24(&d[2], r->next_packet + 1u);
    } else {
        d[0] = CM_CTS;
        d[2] = (uint8_t)(r->next_packet + 1u);
        d[3] = 0xFFu;
        d[4] = 0xFFu;
    }
    r->window_end = r->next_packet + n;
    r->dpo_seen = false;
    r->last_us = now_us;
    r->timeout_us = TD_TP_T2_US;
    send_cm(q, r->kind, r->sa, r->da, d, r->pgn);
}

static int rx_complete(td_tp_t *tp, td_tp_rx_t *r, td_ib_txq_t *q) {
    if (r->kind != TD_TP_KIND_BAM) {
        uint8_t d[8] = {CM_EOMA, 0u, 0u, 0u, 0xFFu, 0u, 0u, 0u};
        if (r->kind == TD_TP_KIND_ETP) {
            d[0] = ETP_EOMA;
            td_ib_put_u32(&d[1], r->size);
        } else {
            d[1] = (uint8_t)(r->size & 0xFFu);
            d[2] = (uint8_t)(r->size >> 8);
            d[3] = (uint8_t)packets_of(r->size);
        }
        send_cm(q, r->kind, r->sa, r->da, d, r->pgn);
    }
    tp->msg.pgn = r->pgn;
    tp->msg.sa = r->sa;
    tp->msg.da = r->da;
    tp->msg.data = r->buf;
    tp->msg.len = r->size;
    tp->rx_done++;
    rx_drop(r);
    return 1;
}

static void rx_start(td_tp_rx_t *r, td_tp_kind_t k, const td_ib_id_t *id, uint32_t size,
                     uint32_t pgn, uint32_t now_us) {
    r->kind = k;
    r->sa = id->sa;
    r->da = id->da;
    r->pgn = pgn;
    r->size = size;
    r->next_packet = 0u;
    r->window_end = packets_of(size);
    r->dpo_offset = 0u;
    r->dpo_seen = false;
    r->last_us = now_us;
    r->timeout_us = TD_TP_T1_US;
}

static int rx_on_cm(td_tp_t *tp, const td_ib_id_t *id, const uint8_t *d, uint8_t my_addr,
                    uint32_t now_us, td_ib_txq_t *q) {
    const bool etp = id->pgn == TD_IB_PGN_ETP_CM;
    const uint32_t pgn = td_ib_get_u24(&d[5]);
    td_tp_rx_t *r = &tp->conn;
    if (!etp && d[0] == CM_BAM) {
        const uint32_t size = (uint32_t)d[1] | ((uint32_t)d[2] << 8);
        if (id->da != TD_IB_ADDR_GLOBAL || size < 9u || size > TD_TP_MAX_TP ||
            d[3] != packets_of(size)) {
            tp->rx_ignored++;
            return TD_IB_E_FRAME;
        }
        if (size > tp->bam.cap) {
            tp->rx_ignored++; /* nothing of ours needs so long a broadcast */
            return 0;
        }
        rx_start(&tp->bam, TD_TP_KIND_BAM, id, size, pgn, now_us);
        return 0;
    }
    if (id->da != my_addr) {
        return 0;
    }
    if ((!etp && d[0] == CM_RTS) || (etp && d[0] == ETP_RTS)) {
        const uint32_t size = etp ? td_ib_get_u32(&d[1]) : ((uint32_t)d[1] | ((uint32_t)d[2] << 8));
        const td_tp_kind_t k = etp ? TD_TP_KIND_ETP : TD_TP_KIND_TP;
        if (r->kind != TD_TP_KIND_NONE && (r->sa != id->sa || r->kind != k)) {
            td_tp_rx_t other = *r;
            other.kind = k;
            other.sa = id->sa;
            other.da = id->da;
            other.pgn = pgn;
            rx_abort(tp, &other, q, TD_TP_ABORT_BUSY);
            return 0;
        }
        if ((!etp && (size < 9u || size > TD_TP_MAX_TP || d[3] != packets_of(size))) ||
            (etp && (size <= TD_TP_MAX_TP || size > TD_TP_MAX_ETP))) {
            tp->rx_ignored++;
            return TD_IB_E_FRAME;
        }
        rx_start(r, k, id, size, pgn, now_us);
        r->max_per_cts = etp ? 0xFFu : d[4];
        if (size > r->cap) {
            rx_abort(tp, r, q, TD_TP_ABORT_RESOURCES);
            return 0;
        }
        send_cts(r, now_us, q);
        return 0;
    }
    if (etp && d[0] == ETP_DPO) {
        const uint32_t off = td_ib_get_u24(&d[2]);
        if (r->kind != TD_TP_KIND_ETP || id->sa != r->sa || pgn != r->pgn) {
            tp->rx_ignored++;
            return 0;
        }
        if (off != r->next_packet || d[1] == 0u || off + d[1] > r->window_end) {
            rx_abort(tp, r, q, TD_TP_ABORT_BAD_SEQUENCE);
            return 0;
        }
        r->dpo_offset = off;
        r->dpo_seen = true;
        r->last_us = now_us;
        r->timeout_us = TD_TP_T1_US;
        return 0;
    }
    if (d[0] == CM_ABORT) {
        if (r->kind != TD_TP_KIND_NONE && id->sa == r->sa && pgn == r->pgn) {
            tp->rx_aborts++;
            rx_drop(r);
        }
        tx_on_cm(tp, id, d, now_us, q);
        return 0;
    }
    tx_on_cm(tp, id, d, now_us, q);
    return 0;
}

static int rx_on_dt(td_tp_t *tp, const td_ib_id_t *id, const uint8_t *d, uint8_t my_addr,
                    uint32_t now_us, td_ib_txq_t *q) {
    const bool etp = id->pgn == TD_IB_PGN_ETP_DT;
    td_tp_rx_t *r;
    uint32_t expect, off, n;
    if (!etp && id->da == TD_IB_ADDR_GLOBAL) {
        r = &tp->bam;
        if (r->kind != TD_TP_KIND_BAM || id->sa != r->sa) {
            return 0;
        }
    } else {
        r = &tp->conn;
        if (id->da != my_addr || r->kind == TD_TP_KIND_NONE || id->sa != r->sa ||
            (r->kind == TD_TP_KIND_ETP) != etp) {
            return 0;
        }
    }
    if (r->kind == TD_TP_KIND_ETP) {
        if (!r->dpo_seen) {
            rx_abort(tp, r, q, TD_TP_ABORT_BAD_SEQUENCE);
            return 0;
        }
        expect = r->next_packet - r->dpo_offset + 1u;
    } else {
        expect = r->next_packet + 1u;
    }
    if (d[0] != expect || r->next_packet >= r->window_end) {
        if (r->kind == TD_TP_KIND_BAM) {
            tp->rx_aborts++;
            rx_drop(r);
        } else {
            rx_abort(tp, r, q, TD_TP_ABORT_BAD_SEQUENCE);
        }
        return 0;
    }
    off = r->next_packet * 7u;
    n = r->size - off;
    if (n > 7u) {
        n = 7u;
    }
    memcpy(&r->buf[off], &d[1], n);
    r->next_packet++;
    r->last_us = now_us;
    r->timeout_us = TD_TP_T1_US;
    if (r->next_packet >= packets_of(r->size)) {
        return rx_complete(tp, r, q);
    }
    if (r->kind != TD_TP_KIND_BAM && r->next_packet >= r->window_end) {
        send_cts(r, now_us, q);
    }
    return 0;
}

int td_tp_rx(td_tp_t *tp, const td_can_frame_t *f, uint8_t my_addr, uint32_t now_us,
             td_ib_txq_t *q) {
    td_ib_id_t id;
    if (tp == NULL || f == NULL || q == NULL) {
        return TD_IB_E_ARG;
    }
    if (f->extended == 0u) {
        return 0;
    }
    id = td_ib_id_unpack(f->id);
    if (id.pgn != TD_IB_PGN_TP_CM && id.pgn != TD_IB_PGN_TP_DT && id.pgn != TD_IB_PGN_ETP_CM &&
        id.pgn != TD_IB_PGN_ETP_DT) {
        return 0;
    }
    if (id.sa == my_addr && my_addr != TD_IB_ADDR_NULL) {
        return 0; /* our own frame echoed back */
    }
    if (f->dlc != 8u) {
        tp->rx_ignored++;
        return TD_IB_E_FRAME;
    }
    if (id.pgn == TD_IB_PGN_TP_CM || id.pgn == TD_IB_PGN_ETP_CM) {
        return rx_on_cm(tp, &id, f->data, my_addr, now_us, q);
    }
    return rx_on_dt(tp, &id, f->data, my_addr, now_us, q);
}

void td_tp_step(td_tp_t *tp, uint32_t now_us, td_ib_txq_t *q) {
    td_tp_tx_t *t;
    if (tp == NULL || q == NULL) {
        return;
    }
    if (tp->conn.kind != TD_TP_KIND_NONE &&
        td_ib_elapsed_us(now_us, tp->conn.last_us) > tp->conn.timeout_us) {
        tp->rx_timeouts++;
        rx_abort(tp, &tp->conn, q, TD_TP_ABORT_TIMEOUT);
    }
    if (tp->bam.kind != TD_TP_KIND_NONE &&
        td_ib_elapsed_us(now_us, tp->bam.last_us) > tp->bam.timeout_us) {
        tp->rx_timeouts++;
        rx_drop(&tp->bam);
    }
    t = &tp->tx;
    if (t->state != TD_TP_TX_BUSY) {
        return;
    }
    if (t->waiting && td_ib_elapsed_us(now_us, t->last_us) > t->timeout_us) {
        send_abort(q, t->kind, t->da, t->sa, t->pgn, TD_TP_ABORT_TIMEOUT);
        t->abort_reason = TD_TP_ABORT_TIMEOUT;
        tx_end(t, TD_TP_TX_TIMEOUT);
        return;
    }
    tx_pump(t, now_us, q);
}
