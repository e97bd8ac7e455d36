/* Shared helpers of the ISOBUS layer's tests: cmocka and frame builders. */
#ifndef IB_TEST_H
#define IB_TEST_H

#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>
#include <cmocka.h>

#include "td_ib.h"

static inline td_can_frame_t ib_frame(uint8_t prio, uint32_t pgn, uint8_t da, uint8_t sa,
                                      const uint8_t d[8]) {
    td_can_frame_t f;
    f.id = td_ib_id_pack(prio, pgn, da, sa);
    f.extended = 1u;
    f.dlc = 8u;
    memcpy(f.data, d, 8u);
    return f;
}

/* Pops every queued frame into `out` (up to n); returns how many. */
static inline unsigned ib_drain(td_ib_txq_t *q, td_can_frame_t *out, unsigned n) {
    unsigned k = 0u;
    td_can_frame_t f;
    while (td_ib_txq_pop(q, &f)) {
        if (k < n) {
            out[k] = f;
        }
        k++;
    }
    return k;
}

#endif
