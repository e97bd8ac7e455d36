#include "td_claim.h"

#include <stddef.h>
#include <string.h>

#include "td_ibname.h"

#define CLAIM_PRIORITY 6u

static bool self_configurable(const td_claim_t *c) {
    return (c->name >> 63) != 0u;
}

static void mark_used(td_claim_t *c, uint8_t a, bool used) {
    const uint32_t bit = 1u << (a & 31u);
    if (used) {
        c->used[a >> 5] |= bit;
    } else {
        c->used[a >> 5] &= ~bit;
    }
}

static bool is_used(const td_claim_t *c, uint8_t a) {
    return (c->used[a >> 5] & (1u << (a & 31u))) != 0u;
}

static int send_claim(td_claim_t *c, uint8_t sa, td_ib_txq_t *q) {
    uint8_t d[8];
    td_ibname_to_bytes(c->name, d);
    return td_ib_send8(q, CLAIM_PRIORITY, TD_IB_PGN_ADDRESS_CLAIM, TD_IB_ADDR_GLOBAL, sa, d);
}

int td_claim_init(td_claim_t *c, uint64_t name, uint8_t preferred, uint8_t range_lo,
                  uint8_t range_hi) {
    if (c == NULL || preferred > 253u || range_hi > 253u || range_lo > range_hi) {
        return TD_IB_E_ARG;
    }
    memset(c, 0, sizeof *c);
    c->name = name;
    c->preferred = preferred;
    c->range_lo = range_lo;
    c->range_hi = range_hi;
    c->address = TD_IB_ADDR_NULL;
    c->state = TD_CLAIM_IDLE;
    return TD_IB_OK;
}

static int claim(td_claim_t *c, uint8_t a, uint32_t now_us, td_ib_txq_t *q) {
    c->address = a;
    c->state = TD_CLAIM_CLAIMING;
    c->since_us = now_us;
    return send_claim(c, a, q);
}

/* The next free address of the fallback range after the lost one (wrapping once round). */
static int reclaim(td_claim_t *c, uint32_t now_us, td_ib_txq_t *q) {
    if (self_configurable(c)) {
        const unsigned n = (unsigned)c->range_hi - c->range_lo + 1u;
        unsigned start = 0u;
        unsigned i;
        if (c->address >= c->range_lo && c->address <= c->range_hi) {
            start = (unsigned)c->address - c->range_lo + 1u;
        }
        for (i = 0u; i < n; i++) {
            const uint8_t a = (uint8_t)(c->range_lo + (start + i) % n);
            if (!is_used(c, a)) {
                return claim(c, a, now_us, q);
            }
        }
    }
    c->address = TD_IB_ADDR_NULL;
    c->state = TD_CLAIM_FAILED;
    return send_claim(c, TD_IB_ADDR_NULL, q);
}

int td_claim_start(td_claim_t *c, uint32_t now_us, td_ib_txq_t *q) {
    if (c == NULL || q == NULL) {
        return TD_IB_E_ARG;
    }
    if (is_used(c, c->preferred)) {
        return reclaim(c, now_us, q);
    }
    return claim(c, c->preferred, now_us, q);
}

static int on_claim(td_claim_t *c, const td_ib_id_t *id, const td_can_frame_t *f,
                    uint32_t now_us, td_ib_txq_t *q) {
    const uint64_t other = td_ibname_from_bytes(f->data);
    if (other == c->name) {
        return 1; /* our own frame echoed back by the bus adapter */
    }
    if (id->sa == TD_IB_ADDR_NULL) {
        return 1; /* another node cannot claim: nothing to do for us */
    }
    /* the other node moved away from any address it held before */
    mark_used(c, id->sa, true);
    if (id->sa != c->address || c->state == TD_CLAIM_IDLE || c->state == TD_CLAIM_FAILED) {
        return 1;
    }
    if (c->name < other) {
        c->contests_won++;
        mark_used(c, id->sa, false);
        (void)send_claim(c, c->address, q);
        return 1;
    }
    c->contests_lost++;
    (void)reclaim(c, now_us, q);
    return 1;
}

int td_claim_rx(td_claim_t *c, const td_can_frame_t *f, uint32_t now_us, td_ib_txq_t *q) {
    td_ib_id_t id;
    if (c == NULL || f == NULL || q == NULL) {
        return TD_IB_E_ARG;
    }
    if (f->extended == 0u) {
        return 0;
    }
    id = td_ib_id_unpack(f->id);
    if (id.pgn == TD_IB_PGN_ADDRESS_CLAIM) {
        if (f->dlc != 8u) {
            return TD_IB_E_FRAME;
        }
        return on_claim(c, &id, f, now_us, q);
    }
    if (id.pgn == TD_IB_PGN_REQUEST) {
        if (f->dlc < 3u) {
            return TD_IB_E_FRAME;
        }
        if (td_ib_get_u24(f->data) != TD_IB_PGN_ADDRESS_CLAIM) {
            return 0;
        }
        if (id.da != TD_IB_ADDR_GLOBAL && (id.da != c->address || c->address == TD_IB_ADDR_NULL)) {
            return 1;
        }
        if (c->state == TD_CLAIM_IDLE) {
            return 1;
        }
        (void)send_claim(c, c->state == TD_CLAIM_FAILED ? TD_IB_ADDR_NULL : c->address, q);
        return 1;
    }
    return 0;
}

void td_claim_step(td_claim_t *c, uint32_t now_us) {
    if (c != NULL && c->state == TD_CLAIM_CLAIMING &&
        td_ib_elapsed_us(now_us, c->since_us) >= TD_CLAIM_WAIT_US) {
        c->state = TD_CLAIM_CLAIMED;
    }
}

uint8_t td_claim_address(const td_claim_t *c) {
    if (c == NULL || c->state != TD_CLAIM_CLAIMED) {
        return TD_IB_ADDR_NULL;
    }
    return c->address;
}
