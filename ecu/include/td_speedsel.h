/**
 * @file td_speedsel.h
 * @brief The dual speed mode: which speed the ECU trusts (the paper's contribution).
 *
 * Rule (paper, conclusions): use GNSS speed when CV < cv_threshold AND v > switch_speed,
 * otherwise the wheel speed. `v` is the GNSS speed by default (switch_compare = TD_CMP_GNSS:
 * above ~6 km/h the wheel under-reads by its slip exactly where the comparison matters, and
 * in uniform motion the GNSS speed is accurate); TD_CMP_WHEEL compares the wheel speed instead.
 * Both comparisons are strict, as in the paper: CV == threshold or v == switch speed -> wheel.
 *
 * TD_MODE_FUSED: both usable -> TD_SRC_FUSED (the estimate of td_fused.h fed by both).
 *
 * Fail-safes layered on top, in every mode: GNSS invalid -> wheel (GNSS_LOST);
 * wheel encoder fault -> GNSS; both unusable -> TD_SRC_NONE.
 */
#ifndef TD_SPEEDSEL_H
#define TD_SPEEDSEL_H

#include <stdbool.h>
#include "td_common.h"

/**
 * The pure rule. cv_pct < 0 means "undefined" (-> not uniform). Returns TD_SRC_WHEEL,
 * TD_SRC_GNSS, TD_SRC_FUSED or TD_SRC_NONE.
 */
td_source_t td_speedsel_rule(td_speed_mode_t mode, td_compare_t compare, float cv_pct,
                             float cv_threshold_pct, float switch_speed_kmh, float v_wheel_kmh,
                             float v_gnss_kmh, bool gnss_valid, bool wheel_valid);

#endif /* TD_SPEEDSEL_H */
