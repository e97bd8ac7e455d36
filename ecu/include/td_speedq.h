/**
 * @file td_speedq.h
 * @brief Queue G of the last N wheel speeds and the CV of its last n values (paper eq. 2).
 *
 * CV = SD / mean * 100 %, SD the sample standard deviation (n - 1 in the denominator).
 * A queue holding fewer than n values, or with mean <= 0.05 km/h, has no defined CV:
 * td_speedq_cv_pct() returns a negative value, which the speed rule treats as "not uniform"
 * unless every value is zero (standing still counts as uniform, CV 0).
 */
#ifndef TD_SPEEDQ_H
#define TD_SPEEDQ_H

#include <stdint.h>

#define TD_SPEEDQ_MAX 16u

typedef struct {
    float v[TD_SPEEDQ_MAX];
    uint8_t len;    /**< N */
    uint8_t count;  /**< values held, <= len */
    uint8_t head;   /**< index of the next write */
} td_speedq_t;

int td_speedq_init(td_speedq_t *q, uint8_t len);
void td_speedq_push(td_speedq_t *q, float v_kmh);
/** CV in % of the last n values; -1 if fewer than n values; 0 if all of them are zero; -1 if the mean is ~0 but not all zero. */
float td_speedq_cv_pct(const td_speedq_t *q, uint8_t n);
/** Eq. 2 on a plain array (for tests and analysis). Same conventions. */
float td_cv_pct(const float *v, uint8_t n);

#endif /* TD_SPEEDQ_H */
