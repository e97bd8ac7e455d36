/**
 * @file td_wheel.c
 * @brief Ground-wheel speed (paper eq. 1) as the mean of `samples` frequency samples.
 */
#include "td_wheel.h"

#include <stddef.h>
#include "td_common.h"

#define TD_TWO_PI 6.28318531f
/* A counter step larger than this is the counter running backwards, not a forward move. */
#define TD_BACKWARD_LIMIT 0x80000000u

float td_wheel_speed_kmh(float f_hz, float radius_m, uint16_t ppr) {
    if (ppr == 0u) {
        return 0.0f;
    }
    return TD_TWO_PI * f_hz * radius_m * 3.6f / (float)ppr;
}

int td_wheel_init(td_wheel_t *w, float radius_m, uint16_t ppr, uint8_t samples, uint16_t update_ms) {
    if (w == NULL || samples < 1u || samples > TD_WHEEL_MAX_SAMPLES || update_ms < samples || ppr < 1u ||
        !(radius_m > 0.0f)) {
        return TD_E_ARG;
    }
    w->radius_m = radius_m;
    w->ppr = ppr;
    w->samples = samples;
    w->sample_us = (uint32_t)update_ms * 1000u / samples;
    w->last_sample_us = 0u;
    w->last_count = 0u;
    for (uint8_t i = 0u; i < TD_WHEEL_MAX_SAMPLES; i++) {
        w->freq_hz[i] = 0.0f;
    }
    w->n_freq = 0u;
    w->started = false;
    w->speed_kmh = 0.0f;
    w->due_us = 0u;
    return TD_OK;
}

bool td_wheel_step(td_wheel_t *w, uint32_t now_us, uint32_t count, float *speed_kmh) {
    if (!w->started) {
        w->started = true;
        w->last_sample_us = now_us;
        w->last_count = count;
        w->due_us = now_us + w->sample_us;
        return false;
    }
    /* Due when now has reached due_us (signed distance, so correct across the wrap). */
    if ((int32_t)(now_us - w->due_us) < 0) {
        return false;
    }
    const uint32_t elapsed_us = td_elapsed_us(now_us, w->last_sample_us);
    uint32_t pulses = count - w->last_count;
    if (pulses >= TD_BACKWARD_LIMIT) {
        pulses = 0u;
    }
    /* The frequency is measured over the real elapsed time, whatever the step jitter. */
    w->freq_hz[w->n_freq++] = (float)pulses * 1.0e6f / (float)elapsed_us;
    w->last_sample_us = now_us;
    w->last_count = count;
    /* Keep the sample grid; after a gap longer than a sample period restart it from now. */
    w->due_us += w->sample_us;
    if ((int32_t)(now_us - w->due_us) >= 0) {
        w->due_us = now_us + w->sample_us;
    }
    if (w->n_freq < w->samples) {
        return false;
    }
    float sum = 0.0f;
    for (uint8_t i = 0u; i < w->samples; i++) {
        sum += w->freq_hz[i];
    }
    w->n_freq = 0u;
    w->speed_kmh = td_wheel_speed_kmh(sum / (float)w->samples, w->radius_m, w->ppr);
    if (speed_kmh != NULL) {
        *speed_kmh = w->speed_kmh;
    }
    return true;
}
