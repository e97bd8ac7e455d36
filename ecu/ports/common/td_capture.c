/**
 * @file td_capture.c
 * @brief Counter extension and wheel capture (td_capture.h).
 */
#include "td_capture.h"

#include <string.h>

static uint32_t mask_of(uint8_t bits) {
    return bits >= 16u ? 0xFFFFu : ((1u << bits) - 1u);
}

void td_ctr_init(td_ctr_t *c, uint8_t bits, uint16_t raw) {
    c->bits = (uint8_t)(bits < 1u ? 1u : (bits > 16u ? 16u : bits));
    c->last = (uint16_t)(raw & mask_of(c->bits));
    c->total = 0u;
}

uint32_t td_ctr_update_signed(td_ctr_t *c, uint16_t raw) {
    const uint32_t m = mask_of(c->bits);
    const uint32_t now = raw & m;
    uint32_t d = (now - c->last) & m;
    if (d > (m >> 1)) { /* the upper half of the range is backward motion */
        d |= ~m;        /* sign-extend: the 32-bit total goes down by the difference */
    }
    c->total += d;
    c->last = (uint16_t)now;
    return c->total;
}

uint32_t td_ctr_update_up(td_ctr_t *c, uint16_t raw) {
    const uint32_t m = mask_of(c->bits);
    const uint32_t now = raw & m;
    c->total += (now - c->last) & m;
    c->last = (uint16_t)now;
    return c->total;
}

void td_wheel_capture_init(td_wheel_capture_t *w) {
    memset(w, 0, sizeof *w);
}

void td_wheel_capture_edge(td_wheel_capture_t *w, uint32_t ccr_us, bool overcapture) {
    w->count += overcapture ? 2u : 1u;
    if (overcapture) {
        w->overcaptures++;
    }
    w->edge_us = ccr_us;
    w->have_edge = true;
}
