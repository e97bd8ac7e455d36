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

/**
 * Eq. 4 inverted: the rate in kg/ha that a metering shaft speed meter_rpm (r/min) applies at
 * speed v_kmh (km/h) over width_m (m) with kg_per_rev (kg/r): q = 600*p*R / (w*v).
 * Zero when v < min_speed_kmh, v <= 0 or meter_rpm <= 0 (also for a NaN input): at a standstill
 * the mass per area is not defined, the kg are counted by the caller; -1 if p <= 0 or w <= 0.
 * Check: R = 24 r/min, w = 3.6 m, v = 6 km/h, p = 0.3 kg/r -> 200 kg/ha.
 */
float td_meter_rate_kg_ha(float width_m, float meter_rpm, float v_kmh, float kg_per_rev, float min_speed_kmh);

#endif /* TD_METER_H */
