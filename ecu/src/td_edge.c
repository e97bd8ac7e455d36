/**
 * @file td_edge.c
 * @brief Ground-wheel speed from pulse periods at every step (capture timer or step clock).
 */
#include "td_edge.h"

#include <stddef.h>
#include "td_common.h"

#define TD_TWO_PI 6.28318531f
#define TD_BACKWARD_LIMIT 0x80000000u

int td_edge_init(td_edge_t *e, float radius_m, uint16_t ppr, uint16_t stop_ms) {
    if (e == NULL || !(radius_m > 0.0f) || ppr == 0u || stop_ms == 0u) {
        return TD_E_ARG;
    }
    e->m_per_pulse = TD_TWO_PI * radius_m / (float)ppr;
    e->stop_us = (uint32_t)stop_ms * 1000u;
    e->last_count = 0u;
    e->last_step_us = 0u;
    e->edge_us = 0u;
    e->have_edge = false;
    e->started = false;
    e->moving = false;
    e->timed = false;
    e->speed_ms = 0.0f;
    e->span_s = 0.0f;
    return TD_OK;
}

float td_edge_step(td_edge_t *e, uint32_t now_us, uint32_t count, uint32_t edge_us, bool edge_valid) {
    if (!e->started) {
        e->started = true;
        e->last_count = count;
        e->last_step_us = now_us;
        return 0.0f;
    }
    uint32_t n = count - e->last_count;
    if (n >= TD_BACKWARD_LIMIT) {
        n = 0u; /* running backwards: no forward motion */
    }
    e->last_count = count;
    const uint32_t prev_step_us = e->last_step_us;
    e->last_step_us = now_us;
    if (n > 0u) {
        /* the edge must lie within (previous edge, now]; otherwise time the pulses by the step */
        bool timed = edge_valid && (int32_t)(now_us - edge_us) >= 0;
        if (timed && e->have_edge && (int32_t)(edge_us - e->edge_us) <= 0) {
            timed = false;
        }
        const uint32_t t_edge = timed ? edge_us : now_us;
        e->timed = timed;
        if (e->have_edge && td_elapsed_us(t_edge, e->edge_us) <= e->stop_us) {
            const uint32_t span_us = td_elapsed_us(t_edge, e->edge_us);
            if (span_us > 0u) {
                e->span_s = (float)span_us * 1.0e-6f;
                e->speed_ms = (float)n * e->m_per_pulse / e->span_s;
            }
        } else {
            /* first motion: n - 1 periods fit in the time since the previous step at most */
            const uint32_t win_us = td_elapsed_us(t_edge, prev_step_us);
            e->span_s = 0.0f;
            e->speed_ms = (n > 1u && win_us > 0u) ? (float)(n - 1u) * e->m_per_pulse / ((float)win_us * 1.0e-6f) : 0.0f;
        }
        e->edge_us = t_edge;
        e->have_edge = true;
        e->moving = true;
    } else if (e->have_edge) {
        const uint32_t since_us = td_age_us(now_us, e->edge_us);
        if (since_us > e->stop_us) {
            e->have_edge = false;
            e->moving = false;
            e->speed_ms = 0.0f;
            e->span_s = 0.0f;
        } else if (since_us > 0u) {
            /* no pulse yet: the next one is at least since_us away */
            const float bound = e->m_per_pulse / ((float)since_us * 1.0e-6f);
            if (bound < e->speed_ms) {
                e->speed_ms = bound;
                e->span_s = 0.0f;
            }
        }
    }
    return e->speed_ms;
}
