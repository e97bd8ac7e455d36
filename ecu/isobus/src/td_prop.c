#include "td_prop.h"

#include <stdbool.h>
#include <stddef.h>
#include <string.h>

#include "td_prop_gen.h"

typedef struct {
    uint32_t fixed_id;
    uint32_t pgn;
    uint8_t priority;
    uint8_t by_ecu;
} td_prop_row_t;

#define TD_PROP_ROW(name, id, pgn, prio, ecu) { (id), (pgn), (prio), (ecu) },
static const td_prop_row_t rows[TD_PROP_COUNT] = { TD_PROP_TABLE(TD_PROP_ROW) };
#undef TD_PROP_ROW

static bool is_prop_a(uint32_t pgn) {
    return pgn == TD_PROP_PGN_A || pgn == TD_PROP_PGN_A2;
}

static bool is_address(uint8_t a) {
    return a != TD_IB_ADDR_NULL && a != TD_IB_ADDR_GLOBAL;
}

int td_prop_to_bus(const td_can_frame_t *core, td_prop_side_t side, uint8_t sa, uint8_t da,
                   td_can_frame_t *out) {
    if (core == NULL || out == NULL) {
        return TD_IB_E_ARG;
    }
    for (unsigned i = 0u; i < TD_PROP_COUNT; i++) {
        const td_prop_row_t *r = &rows[i];
        if (core->extended == 0u || r->fixed_id != core->id || r->by_ecu != (uint8_t)side) {
            continue;
        }
        if (!is_address(sa) || (is_prop_a(r->pgn) && !is_address(da))) {
            return TD_IB_E_NO_ADDRESS;
        }
        *out = *core;
        out->id = td_ib_id_pack(r->priority, r->pgn, da, sa);
        return TD_IB_OK;
    }
    return TD_IB_E_FRAME;
}

int td_prop_from_bus(const td_can_frame_t *bus, td_prop_side_t side, uint8_t peer,
                     uint8_t my_addr, td_can_frame_t *core) {
    td_ib_id_t id;
    if (bus == NULL || core == NULL) {
        return TD_IB_E_ARG;
    }
    if (bus->extended == 0u) {
        return 0;
    }
    id = td_ib_id_unpack(bus->id);
    for (unsigned i = 0u; i < TD_PROP_COUNT; i++) {
        const td_prop_row_t *r = &rows[i];
        if (r->pgn != id.pgn || r->by_ecu != (uint8_t)side) {
            continue;
        }
        if (is_prop_a(r->pgn) && id.da != my_addr) {
            return 0; /* another node's proprietary A: none of ours */
        }
        if (!is_address(peer) || id.sa != peer) {
            return TD_IB_E_SOURCE;
        }
        *core = *bus;
        core->id = r->fixed_id;
        return 1;
    }
    return 0;
}
