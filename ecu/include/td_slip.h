/**
 * @file td_slip.h
 * @brief Ground-wheel slip: measured (paper eq. 3) and the fitted model (eq. 5).
 */
#ifndef TD_SLIP_H
#define TD_SLIP_H

/** Eq. 3: |2*pi*r*n - L| / L * 100, in %. revolutions n, radius r_m, real distance L_m (> 0); L <= 0 -> -1. */
float td_slip_measured_pct(float revolutions, float radius_m, float distance_m);
/** Eq. 5: 0.167 v^2 - 0.296 v + 0.773, in %, v in km/h (wheat stubble). */
float td_slip_model_pct(float v_kmh);
/** The speed at which eq. 5 reaches `slip_pct` (the larger root); -1 if never. 5 % -> ~6.0 km/h. */
float td_slip_model_speed_kmh(float slip_pct);

#endif /* TD_SLIP_H */
