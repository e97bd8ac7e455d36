/**
 * @file td_speedq.c
 * @brief Queue G of wheel speeds and its coefficient of variation (paper eq. 2).
 */
#include "td_speedq.h"

#include <math.h>
#include <stddef.h>
#include "td_common.h"

/* Below this mean (km/h) the CV is meaningless (division by ~0). */
#define TD_CV_MIN_MEAN_KMH 0.05f

int td_speedq_init(td_speedq_t *q, uint8_t len) {
    if (q == NULL || len < 2u || len > TD_SPEEDQ_MAX) {
        return TD_E_ARG;
    }
    for (uint8_t i = 0u; i < TD_SPEEDQ_MAX; i++) {
        q->v[i] = 0.0f;
    }
    q->len = len;
    q->count = 0u;
    q->head = 0u;
    return TD_OK;
}

void td_speedq_push(td_speedq_t *q, float v_kmh) {
    q->v[q->head] = v_kmh;
    q->head = (uint8_t)((q->head + 1u) % q->len);
    if (q->count < q->len) {
        q->count++;
    }
}

/* Eq. 2 over n values read from a ring: element i is ring[(start + i) % mod]. */
static float cv_ring(const float *ring, uint8_t start, uint8_t mod, uint8_t n) {
    float sum = 0.0f;
    bool all_zero = true;
    for (uint8_t i = 0u; i < n; i++) {
        const float v = ring[(start + i) % mod];
        sum += v;
        all_zero = all_zero && (v == 0.0f);
    }
    if (all_zero) {
        return 0.0f;
    }
    const float mean = sum / (float)n;
    if (!(mean > TD_CV_MIN_MEAN_KMH)) {
        return -1.0f;
    }
    float ss = 0.0f;
    for (uint8_t i = 0u; i < n; i++) {
        const float d = ring[(start + i) % mod] - mean;
        ss += d * d;
    }
    return sqrtf(ss / (float)(n - 1u)) / mean * 100.0f;
}

float td_speedq_cv_pct(const td_speedq_t *q, uint8_t n) {
    if (q == NULL || n < 2u || n > q->len || q->count < n) {
        return -1.0f;
    }
    /* the last n values end just before head */
    const uint8_t start = (uint8_t)((q->head + q->len - n) % q->len);
    return cv_ring(q->v, start, q->len, n);
}

float td_cv_pct(const float *v, uint8_t n) {
    if (v == NULL || n < 2u) {
        return -1.0f;
    }
    return cv_ring(v, 0u, n, n);
}
