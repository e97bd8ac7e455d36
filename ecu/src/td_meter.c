/**
 * @file td_meter.c
 * @brief Target metering speed, paper eq. 4.
 */
#include "td_meter.h"

float td_meter_target_rpm(float width_m, float rate_kg_ha, float v_kmh, float kg_per_rev, float min_speed_kmh) {
    if (!(kg_per_rev > 0.0f)) {
        return -1.0f;
    }
    /* !(a >= b) so that a NaN speed or rate gives zero, never a motor command */
    if (!(v_kmh >= min_speed_kmh) || !(rate_kg_ha > 0.0f) || !(width_m > 0.0f)) {
        return 0.0f;
    }
    return width_m * rate_kg_ha * v_kmh / (600.0f * kg_per_rev);
}

float td_meter_rate_kg_ha(float width_m, float meter_rpm, float v_kmh, float kg_per_rev, float min_speed_kmh) {
    if (!(kg_per_rev > 0.0f) || !(width_m > 0.0f)) {
        return -1.0f;
    }
    if (!(v_kmh >= min_speed_kmh) || !(v_kmh > 0.0f) || !(meter_rpm > 0.0f)) {
        return 0.0f;
    }
    return 600.0f * kg_per_rev * meter_rpm / (width_m * v_kmh);
}
