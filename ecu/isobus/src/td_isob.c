#include "td_isob.h"

#include <stddef.h>
#include <string.h>

int td_isob_init(td_isob_t *n, uint64_t name, uint8_t preferred, uint8_t range_lo,
                 uint8_t range_hi, uint32_t tc_timeout_us) {
    int rc;
    if (n == NULL) {
        return TD_IB_E_ARG;
    }
    memset(n, 0, sizeof *n);
    rc = td_claim_init(&n->claim, name, preferred, range_lo, range_hi);
    if (rc == TD_IB_OK) {
        rc = td_tp_init(&n->tp, n->conn_buf, TD_ISOB_CONN_BUF, n->bam_buf, TD_ISOB_BAM_BUF);
    }
    if (rc == TD_IB_OK) {
        rc = td_tc_init(&n->tc, name, tc_timeout_us);
    }
    td_ib_txq_init(&n->q);
    return rc;
}

int td_isob_start(td_isob_t *n, uint32_t now_us) {
    if (n == NULL) {
        return TD_IB_E_ARG;
    }
    return td_claim_start(&n->claim, now_us, &n->q);
}

int td_isob_rx(td_isob_t *n, const td_can_frame_t *f, uint32_t now_us) {
    td_ib_id_t id;
    uint8_t my;
    int rc;
    if (n == NULL || f == NULL) {
        return TD_IB_E_ARG;
    }
    if (f->extended == 0u || f->dlc > 8u) {
        return f->dlc > 8u ? TD_IB_E_FRAME : 0;
    }
    n->rx_frames++;
    rc = td_claim_rx(&n->claim, f, now_us, &n->q);
    if (rc != 0) {
        n->rx_errors += rc < 0 ? 1u : 0u;
        return rc < 0 ? rc : 0;
    }
    my = td_claim_address(&n->claim);
    rc = td_tp_rx(&n->tp, f, my, now_us, &n->q);
    if (rc == 1) {
        rc = td_tc_rx(&n->tc, n->tp.msg.pgn, n->tp.msg.sa, n->tp.msg.da, n->tp.msg.data,
                      n->tp.msg.len, my, now_us, &n->q);
    } else if (rc == 0) {
        id = td_ib_id_unpack(f->id);
        rc = td_tc_rx(&n->tc, id.pgn, id.sa, id.da, f->data, f->dlc, my, now_us, &n->q);
    }
    if (rc < 0) {
        n->rx_errors++;
        return rc;
    }
    return 0;
}

void td_isob_step(td_isob_t *n, uint32_t now_us, uint32_t distance_mm) {
    if (n == NULL) {
        return;
    }
    td_claim_step(&n->claim, now_us);
    td_tp_step(&n->tp, now_us, &n->q);
    td_tc_step(&n->tc, td_claim_address(&n->claim), now_us, distance_mm, &n->tp, &n->q);
}

bool td_isob_tx(td_isob_t *n, td_can_frame_t *out) {
    return n != NULL && td_ib_txq_pop(&n->q, out);
}

int td_isob_prop_rx(td_isob_t *n, const td_can_frame_t *f, td_can_frame_t *core) {
    int rc;
    if (n == NULL) {
        return TD_IB_E_ARG;
    }
    rc = td_prop_from_bus(f, TD_PROP_TERMINAL, n->tc.tc_addr, td_claim_address(&n->claim), core);
    if (rc == 1) {
        n->prop_rx++;
    } else if (rc == TD_IB_E_SOURCE) {
        n->prop_wrong_source++;
    }
    return rc;
}

int td_isob_prop_tx(const td_isob_t *n, const td_can_frame_t *core, td_can_frame_t *out) {
    if (n == NULL) {
        return TD_IB_E_ARG;
    }
    return td_prop_to_bus(core, TD_PROP_ECU, td_claim_address(&n->claim), n->tc.tc_addr, out);
}
