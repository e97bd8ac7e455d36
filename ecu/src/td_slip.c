/**
 * @file td_slip.c
 * @brief Ground-wheel slip: eq. 3 (measured over a run) and the eq. 5 model (wheat stubble).
 */
#include "td_slip.h"

#include <math.h>

#define TD_TWO_PI 6.28318531f
#define SLIP_A 0.167f
#define SLIP_B (-0.296f)
#define SLIP_C 0.773f

float td_slip_measured_pct(float revolutions, float radius_m, float distance_m) {
    if (!(distance_m > 0.0f)) {
        return -1.0f;
    }
    return fabsf(TD_TWO_PI * radius_m * revolutions - distance_m) / distance_m * 100.0f;
}

float td_slip_model_pct(float v_kmh) {
    return (SLIP_A * v_kmh + SLIP_B) * v_kmh + SLIP_C;
}

float td_slip_model_speed_kmh(float slip_pct) {
    /* larger root of A v^2 + B v + (C - slip) = 0 */
    const float disc = SLIP_B * SLIP_B - 4.0f * SLIP_A * (SLIP_C - slip_pct);
    if (!(disc >= 0.0f)) {
        return -1.0f;
    }
    const float v = (-SLIP_B + sqrtf(disc)) / (2.0f * SLIP_A);
    return v >= 0.0f ? v : -1.0f;
}
