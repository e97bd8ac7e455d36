/**
 * @file td_meter.h
 * @brief Target metering speed (paper eq. 4): R = w*q*v / (600*p).
 */
#ifndef TD_METER_H
#define TD_METER_H

/**
 * Target metering shaft speed in r/min for width w_m (m), rate q (kg/ha), speed v (km/h)
 * and p (kg per metering revolution). Zero when v < min_speed_kmh, q <= 0 or w <= 0 (also for a NaN input); -1 if p <= 0.
 * Check: w = 3.6 m, q = 200 kg/ha, v = 6 km/h, p = 0.3 kg/r -> 24.0 r/min.
 */
float td_meter_target_rpm(float width_m, float rate_kg_ha, float v_kmh, float kg_per_rev, float min_speed_kmh);

#endif /* TD_METER_H */
