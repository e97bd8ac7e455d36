/**
 * @file td_lag.c
 * @brief The GNSS lag learned against the wheel's history (td_lag.h).
 */
#include "td_lag.h"

#include <stddef.h>

#define LAG_MEMORY_S 20.0f   /* the fit forgets with this time constant of speed change */
#define LAG_WEIGHT_MAX_S 1.0f
#define LAG_SPAN_MS 0.3f     /* the speed changes: the candidates' speeds span more than this */
#define LAG_EVIDENCE_S 1.5f  /* learned after this much speed change */

void td_lag_init(td_lag_t *l) {
    l->s_zz = 0.0f;
    for (unsigned k = 0u; k < TD_LAG_N; k++) {
        l->s_zu[k] = 0.0f;
        l->s_uu[k] = 0.0f;
    }
    l->evidence_s = 0.0f;
    l->lag_s = 0.0f;
    l->fit = 1.0f;
    l->learned = false;
}

/* 1 - the squared correlation of z and u_k through the origin: 0 = a perfect fit */
static float misfit(const td_lag_t *l, unsigned k) {
    const float den = l->s_zz * l->s_uu[k];
    return den > 0.0f ? 1.0f - l->s_zu[k] * l->s_zu[k] / den : 1.0f;
}

bool td_lag_fix(td_lag_t *l, const td_fused_t *f, float z_ms, float age_s, float weight_s) {
    if (!(z_ms >= 0.0f && age_s >= 0.0f && weight_s > 0.0f)) {
        return false;
    }
    float u[TD_LAG_N];
    float lo = 1.0e9f;
    float hi = 0.0f;
    for (unsigned k = 0u; k < TD_LAG_N; k++) {
        float w = 0.0f;
        if (!td_fused_wheel_at(f, age_s + (float)k * TD_LAG_STEP_S, &w)) {
            return false;
        }
        /* ground speed as the estimate reads the wheel (one pass through the slip shape) */
        const float v = w / f->scale;
        u[k] = v / td_fused_shape(f, v, NULL);
        lo = u[k] < lo ? u[k] : lo;
        hi = u[k] > hi ? u[k] : hi;
    }
    if (!(hi - lo > LAG_SPAN_MS)) {
        return false; /* steady or standing: every candidate fits alike */
    }
    const float w = weight_s < LAG_WEIGHT_MAX_S ? weight_s : LAG_WEIGHT_MAX_S;
    const float keep = 1.0f - w / LAG_MEMORY_S;
    l->s_zz = keep * l->s_zz + w * z_ms * z_ms;
    for (unsigned k = 0u; k < TD_LAG_N; k++) {
        l->s_zu[k] = keep * l->s_zu[k] + w * z_ms * u[k];
        l->s_uu[k] = keep * l->s_uu[k] + w * u[k] * u[k];
    }
    l->evidence_s = keep * l->evidence_s + w;
    unsigned best = 0u;
    float r_min = misfit(l, 0u);
    float r_max = r_min;
    for (unsigned k = 1u; k < TD_LAG_N; k++) {
        const float r = misfit(l, k);
        if (r < r_min) {
            r_min = r;
            best = k;
        }
        r_max = r > r_max ? r : r_max;
    }
    float lag = (float)best;
    if (best > 0u && best + 1u < TD_LAG_N) {
        /* the vertex of the parabola through the minimum and its neighbours */
        const float rm = misfit(l, best - 1u);
        const float rp = misfit(l, best + 1u);
        const float c = rm - 2.0f * r_min + rp;
        if (c > 0.0f) {
            float x = 0.5f * (rm - rp) / c;
            x = x > 0.5f ? 0.5f : (x < -0.5f ? -0.5f : x);
            lag += x;
        }
    }
    l->lag_s = lag * TD_LAG_STEP_S;
    l->fit = r_max > 0.0f ? r_min / r_max : 1.0f;
    if (l->evidence_s >= LAG_EVIDENCE_S && l->fit < TD_LAG_CLEAR) {
        l->learned = true;
    }
    return true;
}
