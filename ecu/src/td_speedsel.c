/**
 * @file td_speedsel.c
 * @brief The dual speed rule of the paper with its fail-safes.
 */
#include "td_speedsel.h"

td_source_t td_speedsel_rule(td_speed_mode_t mode, td_compare_t compare, float cv_pct,
                             float cv_threshold_pct, float switch_speed_kmh, float v_wheel_kmh,
                             float v_gnss_kmh, bool gnss_valid, bool wheel_valid) {
    if (!gnss_valid) {
        return wheel_valid ? TD_SRC_WHEEL : TD_SRC_NONE;
    }
    if (!wheel_valid) {
        return TD_SRC_GNSS;
    }
    if (mode == TD_MODE_WHEEL_ONLY) {
        return TD_SRC_WHEEL;
    }
    if (mode == TD_MODE_GNSS_ONLY) {
        return TD_SRC_GNSS;
    }
    if (mode == TD_MODE_FUSED) {
        return TD_SRC_FUSED;
    }
    const bool uniform = cv_pct >= 0.0f && cv_pct < cv_threshold_pct;
    const float v = (compare == TD_CMP_WHEEL) ? v_wheel_kmh : v_gnss_kmh;
    return (uniform && v > switch_speed_kmh) ? TD_SRC_GNSS : TD_SRC_WHEEL;
}
