/**
 * @file td_bxcan.c
 * @brief bxCAN bit timing, filters and mailbox words (td_bxcan.h).
 */
#include "td_bxcan.h"

#include <stddef.h>
#include "td_common.h"

#define TS1_MAX 16u
#define TS2_MIN 2u   /* the information processing time: phase 2 is at least 2 tq */
#define TS2_MAX 8u
#define TQ_MIN 8u
#define TQ_MAX 25u
#define BRP_MAX 1024u
#define ID_EXT_MAX 0x1FFFFFFFu
#define ID_STD_MAX 0x7FFu

int td_bxcan_timing(uint32_t pclk_hz, uint32_t bitrate, uint16_t sample_permille, td_bxcan_timing_t *out) {
    if (out == NULL || pclk_hz == 0u || bitrate == 0u || sample_permille < 500u || sample_permille > 950u) {
        return TD_E_ARG;
    }
    bool found = false;
    uint32_t best_err = 0u;
    for (uint32_t tq = TQ_MAX; tq >= TQ_MIN; tq--) {
        const uint64_t per_bit = (uint64_t)bitrate * tq;
        if (pclk_hz % per_bit != 0u || pclk_hz / per_bit > BRP_MAX) {
            continue;
        }
        for (uint32_t ts2 = TS2_MIN; ts2 <= TS2_MAX; ts2++) {
            const uint32_t ts1 = tq - 1u - ts2;
            if (ts1 < 1u || ts1 > TS1_MAX) {
                continue;
            }
            const uint32_t sp = (1000u * (1u + ts1) + tq / 2u) / tq;
            const uint32_t err = sp > sample_permille ? sp - sample_permille : sample_permille - sp;
            if (!found || err < best_err) { /* strict: among equals the first, the most quanta */
                found = true;
                best_err = err;
                out->brp = (uint16_t)(pclk_hz / per_bit);
                out->ts1 = (uint8_t)ts1;
                out->ts2 = (uint8_t)ts2;
                out->sjw = (uint8_t)(ts2 < 4u ? ts2 : 4u);
                out->sample_permille = (uint16_t)sp;
            }
        }
    }
    if (!found) {
        return TD_E_RANGE;
    }
    out->btr = ((uint32_t)(out->sjw - 1u) << 24) | ((uint32_t)(out->ts2 - 1u) << 20) |
               ((uint32_t)(out->ts1 - 1u) << 16) | (uint32_t)(out->brp - 1u);
    return TD_OK;
}

uint32_t td_bxcan_id_word(uint32_t id, bool extended, bool remote) {
    const uint32_t rtr = remote ? TD_BXCAN_RTR : 0u;
    if (extended) {
        return ((id & ID_EXT_MAX) << 3) | TD_BXCAN_IDE | rtr;
    }
    return ((id & ID_STD_MAX) << 21) | rtr;
}

int td_bxcan_filters_ext(const uint32_t *ids, unsigned n, td_bxcan_bank_t *banks, unsigned max_banks) {
    if ((ids == NULL && n > 0u) || (banks == NULL && max_banks > 0u)) {
        return TD_E_ARG;
    }
    if (n > 2u * max_banks) {
        return TD_E_FULL;
    }
    for (unsigned i = 0u; i < n; i++) {
        if (ids[i] > ID_EXT_MAX) {
            return TD_E_ARG;
        }
    }
    unsigned used = 0u;
    for (unsigned i = 0u; i < n; i += 2u) {
        banks[used].fr1 = td_bxcan_id_word(ids[i], true, false);
        banks[used].fr2 = td_bxcan_id_word(ids[i + 1u < n ? i + 1u : i], true, false);
        used++;
    }
    return (int)used;
}

bool td_bxcan_accepts(const td_bxcan_bank_t *banks, unsigned nbanks, uint32_t id, bool extended, bool remote) {
    /* list mode compares every bit of the word but the TXRQ position (bit 0, reserved) */
    const uint32_t w = td_bxcan_id_word(id, extended, remote);
    for (unsigned i = 0u; i < nbanks; i++) {
        if ((banks[i].fr1 & ~1u) == w || (banks[i].fr2 & ~1u) == w) {
            return true;
        }
    }
    return false;
}

bool td_bxcan_rx_frame(uint32_t rir, uint32_t rdtr, uint32_t rdlr, uint32_t rdhr, td_can_frame_t *f) {
    if ((rir & TD_BXCAN_RTR) != 0u) {
        return false;
    }
    f->extended = (rir & TD_BXCAN_IDE) != 0u ? 1u : 0u;
    f->id = f->extended != 0u ? (rir >> 3) & ID_EXT_MAX : (rir >> 21) & ID_STD_MAX;
    const uint8_t dlc = (uint8_t)(rdtr & 0x0Fu);
    f->dlc = dlc > 8u ? 8u : dlc; /* 9..15 mean 8 bytes in classic CAN */
    for (unsigned i = 0u; i < 4u; i++) {
        f->data[i] = (uint8_t)(rdlr >> (8u * i));
        f->data[4u + i] = (uint8_t)(rdhr >> (8u * i));
    }
    return true;
}

void td_bxcan_tx_words(const td_can_frame_t *f, uint32_t *tir, uint32_t *tdtr, uint32_t *tdlr, uint32_t *tdhr) {
    *tir = td_bxcan_id_word(f->id, f->extended != 0u, false);
    *tdtr = f->dlc > 8u ? 8u : f->dlc;
    uint32_t lo = 0u;
    uint32_t hi = 0u;
    for (unsigned i = 0u; i < 4u; i++) {
        lo |= (uint32_t)f->data[i] << (8u * i);
        hi |= (uint32_t)f->data[4u + i] << (8u * i);
    }
    *tdlr = lo;
    *tdhr = hi;
}
