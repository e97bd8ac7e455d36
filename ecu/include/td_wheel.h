/**
 * @file td_wheel.h
 * @brief Ground-wheel speed from encoder pulses (paper eq. 1), mean of several frequency samples.
 *
 * A frequency sample f_i = pulses / elapsed time is taken every update_ms / samples
 * (125 ms with the defaults); every update_ms the fed-back wheel speed is the mean of
 * the last `samples` frequency samples through eq. 1: V = 2*pi*f*r*3.6/K.
 */
#ifndef TD_WHEEL_H
#define TD_WHEEL_H

#include <stdbool.h>
#include <stdint.h>

#define TD_WHEEL_MAX_SAMPLES 16u

/** Eq. 1: wheel speed in km/h from pulse frequency f_hz, radius r_m and K pulses per revolution. */
float td_wheel_speed_kmh(float f_hz, float radius_m, uint16_t ppr);

typedef struct {
    float radius_m;
    uint16_t ppr;
    uint8_t samples;
    uint32_t sample_us;            /**< update_ms * 1000 / samples */
    uint32_t last_sample_us;
    uint32_t last_count;
    float freq_hz[TD_WHEEL_MAX_SAMPLES];
    uint8_t n_freq;                /**< samples taken since the last update */
    bool started;
    float speed_kmh;               /**< last fed-back speed */
    uint32_t due_us;               /**< when the next sample is due (fixed grid, so updates keep their period) */
} td_wheel_t;

/** Initialise. Returns TD_E_ARG on a bad argument (samples 1..16, update_ms >= samples, ppr >= 1, radius > 0). */
int td_wheel_init(td_wheel_t *w, float radius_m, uint16_t ppr, uint8_t samples, uint16_t update_ms);

/**
 * Feed the cumulative counter at time now_us; call at the control period.
 * Returns true when a new fed-back speed is ready (every update_ms), written to *speed_kmh.
 */
bool td_wheel_step(td_wheel_t *w, uint32_t now_us, uint32_t count, float *speed_kmh);

#endif /* TD_WHEEL_H */
