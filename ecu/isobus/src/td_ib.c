#include "td_ib.h"

#include <stddef.h>
#include <string.h>

void td_ib_txq_init(td_ib_txq_t *q) {
    if (q != NULL) {
        memset(q, 0, sizeof *q);
    }
}

int td_ib_txq_push(td_ib_txq_t *q, const td_can_frame_t *f) {
    if (q == NULL || f == NULL) {
        return TD_IB_E_ARG;
    }
    if (q->count >= TD_IB_TXQ_LEN) {
        q->dropped++;
        return TD_IB_E_FULL;
    }
    q->f[(q->head + q->count) % TD_IB_TXQ_LEN] = *f;
    q->count++;
    return TD_IB_OK;
}

bool td_ib_txq_pop(td_ib_txq_t *q, td_can_frame_t *out) {
    if (q == NULL || out == NULL || q->count == 0u) {
        return false;
    }
    *out = q->f[q->head];
    q->head = (uint8_t)((q->head + 1u) % TD_IB_TXQ_LEN);
    q->count--;
    return true;
}

uint32_t td_ib_id_pack(uint8_t priority, uint32_t pgn, uint8_t da, uint8_t sa) {
    uint32_t id = ((uint32_t)(priority & 7u) << 26) | ((pgn & 0x3FFFFu) << 8) | sa;
    const uint32_t pf = (pgn >> 8) & 0xFFu;
    if (pf < 240u) {
        id = (id & ~(0xFFu << 8)) | ((uint32_t)da << 8);
    }
    return id;
}

td_ib_id_t td_ib_id_unpack(uint32_t id) {
    td_ib_id_t r;
    const uint32_t pf = (id >> 16) & 0xFFu;
    r.priority = (uint8_t)((id >> 26) & 7u);
    r.sa = (uint8_t)(id & 0xFFu);
    if (pf < 240u) {
        r.pgn = (id >> 8) & 0x3FF00u;
        r.da = (uint8_t)((id >> 8) & 0xFFu);
    } else {
        r.pgn = (id >> 8) & 0x3FFFFu;
        r.da = TD_IB_ADDR_GLOBAL;
    }
    return r;
}

int td_ib_send8(td_ib_txq_t *q, uint8_t priority, uint32_t pgn, uint8_t da, uint8_t sa,
                const uint8_t data[8]) {
    td_can_frame_t f;
    if (data == NULL) {
        return TD_IB_E_ARG;
    }
    f.id = td_ib_id_pack(priority, pgn, da, sa);
    f.extended = 1u;
    f.dlc = 8u;
    memcpy(f.data, data, 8u);
    return td_ib_txq_push(q, &f);
}
