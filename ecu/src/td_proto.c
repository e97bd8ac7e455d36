/**
 * @file td_proto.c
 * @brief Physical, validated view of the CAN protocol on top of the generated codec (td_can.c).
 *
 * Bit layout comes from the generated pack/unpack functions. Scaling is done here in float with
 * round-to-nearest and saturation (the generated *_encode helpers truncate, so 1.2 km/h could
 * become 11 raw units), and every decoded value is checked before anyone acts on it.
 */
#include "td_proto.h"

#include <stddef.h>
#include "td_can.h"
#include "td_common.h"
#include "td_params.h"
#include "td_version.h"

#define TD_GNSS_RAW_NA 0xFFu
#define TD_GNSS_RAW_MAX 250u   /* 25.0 km/h; 251..254 are out of range */
#define TD_CV_RAW_UNDEFINED 0xFFFFu

/** round(phys / scale) clamped to [0, raw_max]; NaN and negatives give 0. */
static uint32_t to_raw(float phys, float scale, uint32_t raw_max) {
    const float r = phys / scale + 0.5f;
    if (!(r >= 1.0f)) {
        return 0u;
    }
    if (r >= (float)raw_max) {
        return raw_max;
    }
    return (uint32_t)r;
}

/** round(phys / scale) clamped to [raw_min, raw_max] (signed fields); NaN gives 0. */
static int32_t to_raw_signed(float phys, float scale, int32_t raw_min, int32_t raw_max) {
    const float r = phys / scale;
    if (!(r == r)) {
        return 0;
    }
    if (r <= (float)raw_min) {
        return raw_min;
    }
    if (r >= (float)raw_max) {
        return raw_max;
    }
    return (int32_t)(r < 0.0f ? r - 0.5f : r + 0.5f);
}

static void frame_head(td_can_frame_t *f, uint32_t id) {
    f->id = id;
    f->extended = 1u;
    f->dlc = 8u;
}

int td_proto_decode_command(const td_can_frame_t *f, td_command_t *out) {
    if (f == NULL || out == NULL) {
        return TD_E_ARG;
    }
    if (f->dlc != TD_CAN_PC_COMMAND_LENGTH) {
        return TD_E_LENGTH;
    }
    struct td_can_pc_command_t m;
    (void)td_can_pc_command_unpack(&m, f->data, TD_CAN_PC_COMMAND_LENGTH);
    if ((m.start_stop != TD_RUN_STOPPED && m.start_stop != TD_RUN_RUNNING) ||
        !td_can_pc_command_fan_speed_is_in_range(m.fan_speed) ||
        !td_can_pc_command_upper_rate_is_in_range(m.upper_rate) ||
        !td_can_pc_command_lower_rate_is_in_range(m.lower_rate) ||
        (m.gnss_speed > TD_GNSS_RAW_MAX && m.gnss_speed != TD_GNSS_RAW_NA)) {
        return TD_E_RANGE;
    }
    out->start = (m.start_stop == TD_RUN_RUNNING);
    out->fan_rpm = (float)m.fan_speed;
    out->rate_kg_ha[TD_UPPER] = (float)m.upper_rate * 0.01f;
    out->rate_kg_ha[TD_LOWER] = (float)m.lower_rate * 0.01f;
    out->gnss_valid = (m.gnss_speed != TD_GNSS_RAW_NA);
    out->gnss_kmh = out->gnss_valid ? (float)m.gnss_speed * 0.1f : 0.0f;
    return TD_OK;
}

int td_proto_encode_command(const td_command_t *c, td_can_frame_t *f) {
    if (c == NULL || f == NULL) {
        return TD_E_ARG;
    }
    if (!(c->fan_rpm >= 0.0f && c->fan_rpm <= 6000.0f) ||
        !(c->rate_kg_ha[TD_UPPER] >= 0.0f && c->rate_kg_ha[TD_UPPER] <= 600.0f) ||
        !(c->rate_kg_ha[TD_LOWER] >= 0.0f && c->rate_kg_ha[TD_LOWER] <= 600.0f) ||
        (c->gnss_valid && !(c->gnss_kmh >= 0.0f && c->gnss_kmh <= 25.04f))) {
        return TD_E_RANGE;
    }
    struct td_can_pc_command_t m;
    m.start_stop = c->start ? TD_RUN_RUNNING : TD_RUN_STOPPED;
    m.fan_speed = (uint16_t)to_raw(c->fan_rpm, 1.0f, 6000u);
    m.upper_rate = (uint16_t)to_raw(c->rate_kg_ha[TD_UPPER], 0.01f, 60000u);
    m.lower_rate = (uint16_t)to_raw(c->rate_kg_ha[TD_LOWER], 0.01f, 60000u);
    m.gnss_speed = c->gnss_valid ? (uint8_t)to_raw(c->gnss_kmh, 0.1f, TD_GNSS_RAW_MAX) : (uint8_t)TD_GNSS_RAW_NA;
    frame_head(f, TD_ID_PC_COMMAND);
    (void)td_can_pc_command_pack(f->data, &m, sizeof f->data);
    return TD_OK;
}

int td_proto_encode_status(const td_status_t *s, td_can_frame_t *f) {
    if (s == NULL || f == NULL) {
        return TD_E_ARG;
    }
    struct td_can_ecu_status_t m;
    m.run_state = s->running ? TD_RUN_RUNNING : TD_RUN_STOPPED;
    m.upper_meter_speed = (uint16_t)to_raw(s->meter_rpm[TD_UPPER], 0.01f, 0xFFFFu);
    m.lower_meter_speed = (uint16_t)to_raw(s->meter_rpm[TD_LOWER], 0.01f, 0xFFFFu);
    m.upper_fan_speed = (uint8_t)to_raw(s->fan_rpm[TD_UPPER], 20.0f, 0xFFu);
    m.lower_fan_speed = (uint8_t)to_raw(s->fan_rpm[TD_LOWER], 20.0f, 0xFFu);
    m.wheel_speed = (uint8_t)to_raw(s->wheel_kmh, 0.1f, 0xFFu);
    frame_head(f, TD_ID_ECU_STATUS);
    (void)td_can_ecu_status_pack(f->data, &m, sizeof f->data);
    return TD_OK;
}

int td_proto_decode_status(const td_can_frame_t *f, td_status_t *out) {
    if (f == NULL || out == NULL) {
        return TD_E_ARG;
    }
    if (f->dlc != TD_CAN_ECU_STATUS_LENGTH) {
        return TD_E_LENGTH;
    }
    struct td_can_ecu_status_t m;
    (void)td_can_ecu_status_unpack(&m, f->data, TD_CAN_ECU_STATUS_LENGTH);
    if (m.run_state != TD_RUN_STOPPED && m.run_state != TD_RUN_RUNNING) {
        return TD_E_RANGE;
    }
    out->running = (m.run_state == TD_RUN_RUNNING);
    out->meter_rpm[TD_UPPER] = (float)m.upper_meter_speed * 0.01f;
    out->meter_rpm[TD_LOWER] = (float)m.lower_meter_speed * 0.01f;
    out->fan_rpm[TD_UPPER] = (float)m.upper_fan_speed * 20.0f;
    out->fan_rpm[TD_LOWER] = (float)m.lower_fan_speed * 20.0f;
    out->wheel_kmh = (float)m.wheel_speed * 0.1f;
    return TD_OK;
}

int td_proto_encode_diag(const td_diag_t *d, td_can_frame_t *f) {
    if (d == NULL || f == NULL || d->source > 3u || d->mode > 3u || d->compare > 1u) {
        return TD_E_ARG;
    }
    struct td_can_ecu_diag_t m;
    m.speed_source = d->source;
    m.speed_mode = d->mode;
    m.gnss_valid = d->gnss_valid ? 1u : 0u;
    m.uniform = d->uniform ? 1u : 0u;
    m.switch_compare = d->compare;
    m.cv = d->cv_pct < 0.0f ? (uint16_t)TD_CV_RAW_UNDEFINED : (uint16_t)to_raw(d->cv_pct, 0.01f, 0xFFFFu);
    m.fault_word = d->faults;
    m.wheel_pulses = d->wheel_pulses & 0xFFFFFFu;
    frame_head(f, TD_ID_ECU_DIAG);
    (void)td_can_ecu_diag_pack(f->data, &m, sizeof f->data);
    return TD_OK;
}

int td_proto_encode_speeds(const td_speeds_t *s, td_can_frame_t *f) {
    if (s == NULL || f == NULL) {
        return TD_E_ARG;
    }
    struct td_can_ecu_speeds_t m;
    m.wheel_speed_fine = (uint16_t)to_raw(s->wheel_kmh, 0.01f, 0xFFFFu);
    /* a negative GNSS speed is the caller's "not valid": same raw value as 655.35 */
    m.gnss_speed_fine = s->gnss_kmh < 0.0f ? 0xFFFFu : (uint16_t)to_raw(s->gnss_kmh, 0.01f, 0xFFFFu);
    m.selected_speed = (uint16_t)to_raw(s->selected_kmh, 0.01f, 0xFFFFu);
    m.rx_rejected = s->rx_rejected;
    frame_head(f, TD_ID_ECU_SPEEDS);
    (void)td_can_ecu_speeds_pack(f->data, &m, sizeof f->data);
    return TD_OK;
}

int td_proto_encode_targets(const td_targets_t *t, td_can_frame_t *f) {
    if (t == NULL || f == NULL) {
        return TD_E_ARG;
    }
    struct td_can_ecu_targets_t m;
    m.upper_target_speed = (uint16_t)to_raw(t->target_rpm[TD_UPPER], 0.01f, 0xFFFFu);
    m.lower_target_speed = (uint16_t)to_raw(t->target_rpm[TD_LOWER], 0.01f, 0xFFFFu);
    m.upper_duty = (uint8_t)to_raw(t->meter_duty_pct[TD_UPPER], 0.5f, 200u);
    m.lower_duty = (uint8_t)to_raw(t->meter_duty_pct[TD_LOWER], 0.5f, 200u);
    m.upper_fan_duty = (uint8_t)to_raw(t->fan_duty_pct[TD_UPPER], 0.5f, 200u);
    m.lower_fan_duty = (uint8_t)to_raw(t->fan_duty_pct[TD_LOWER], 0.5f, 200u);
    frame_head(f, TD_ID_ECU_TARGETS);
    (void)td_can_ecu_targets_pack(f->data, &m, sizeof f->data);
    return TD_OK;
}

int td_proto_encode_param_ack(const td_param_ack_t *a, td_can_frame_t *f) {
    if (a == NULL || f == NULL) {
        return TD_E_ARG;
    }
    struct td_can_ecu_param_ack_t m;
    m.ack_param_id = a->param_id;
    m.ack_result = a->result;
    m.ack_raw = a->raw;
    frame_head(f, TD_ID_ECU_PARAM_ACK);
    (void)td_can_ecu_param_ack_pack(f->data, &m, sizeof f->data);
    return TD_OK;
}

int td_proto_decode_param_set(const td_can_frame_t *f, uint8_t *param_id, float *value) {
    if (f == NULL || param_id == NULL || value == NULL) {
        return TD_E_ARG;
    }
    if (f->dlc != TD_CAN_PC_PARAM_SET_LENGTH) {
        return TD_E_LENGTH;
    }
    const uint8_t id = f->data[0];
    float scale;
    uint32_t raw_min;
    uint32_t raw_max;
    if (td_params_encoding(id, &scale, &raw_min, &raw_max) != TD_OK) {
        return TD_E_UNKNOWN_PARAM;
    }
    /* Every multiplexed value of PcParamSet is the same unsigned little-endian 32-bit field
     * (bits 32..63), so one read serves all of them; test_proto checks it against td_can_pc_param_set_unpack. */
    const uint32_t raw = (uint32_t)f->data[4] | ((uint32_t)f->data[5] << 8) | ((uint32_t)f->data[6] << 16) |
                         ((uint32_t)f->data[7] << 24);
    if (raw < raw_min || raw > raw_max) {
        return TD_E_RANGE;
    }
    *param_id = id;
    *value = (float)raw * scale;
    return TD_OK;
}

uint32_t td_proto_param_raw(uint8_t param_id, float value) {
    float scale;
    if (td_params_encoding(param_id, &scale, NULL, NULL) != TD_OK) {
        return 0u;
    }
    return to_raw(value, scale, 0xFFFFFFFFu);
}

#define TD_GNSS_FINE_NA 0xFFFFu
#define TD_GNSS_FINE_MAX 2500u /* 25.00 km/h, as PcCommand */

int td_proto_decode_gnss_time(const td_can_frame_t *f, td_gnss_time_t *out) {
    if (f == NULL || out == NULL) {
        return TD_E_ARG;
    }
    if (f->dlc != TD_CAN_PC_GNSS_TIME_LENGTH) {
        return TD_E_LENGTH;
    }
    struct td_can_pc_gnss_time_t m;
    (void)td_can_pc_gnss_time_unpack(&m, f->data, TD_CAN_PC_GNSS_TIME_LENGTH);
    if ((m.gnss_speed_precise > TD_GNSS_FINE_MAX && m.gnss_speed_precise != TD_GNSS_FINE_NA) ||
        !td_can_pc_gnss_time_gnss_fix_age_is_in_range(m.gnss_fix_age)) {
        return TD_E_RANGE;
    }
    out->valid = m.gnss_speed_precise != TD_GNSS_FINE_NA;
    out->speed_kmh = out->valid ? (float)m.gnss_speed_precise * 0.01f : 0.0f;
    out->age_ms = m.gnss_fix_age;
    out->seq = m.gnss_seq;
    return TD_OK;
}

int td_proto_encode_gnss_time(const td_gnss_time_t *g, td_can_frame_t *f) {
    if (g == NULL || f == NULL) {
        return TD_E_ARG;
    }
    if ((g->valid && !(g->speed_kmh >= 0.0f && g->speed_kmh <= 25.004f)) || g->age_ms > 10000u) {
        return TD_E_RANGE;
    }
    struct td_can_pc_gnss_time_t m;
    m.gnss_speed_precise =
        g->valid ? (uint16_t)to_raw(g->speed_kmh, 0.01f, TD_GNSS_FINE_MAX) : (uint16_t)TD_GNSS_FINE_NA;
    m.gnss_fix_age = g->age_ms;
    m.gnss_seq = g->seq;
    frame_head(f, TD_ID_PC_GNSS_TIME);
    (void)td_can_pc_gnss_time_pack(f->data, &m, sizeof f->data);
    return TD_OK;
}

int td_proto_encode_fused(const td_fused_diag_t *d, td_can_frame_t *f) {
    if (d == NULL || f == NULL) {
        return TD_E_ARG;
    }
    struct td_can_ecu_fused_t m;
    m.fused_speed = (uint16_t)to_raw(d->speed_kmh, 0.01f, 0xFFFFu);
    m.fused_accel = (int16_t)to_raw_signed(d->accel_ms2, 0.001f, -32768, 32767);
    m.learned_slip = (int16_t)to_raw_signed(d->slip_pct, 0.01f, -32768, 32767);
    m.gnss_innovation = (int8_t)to_raw_signed(d->innov_kmh, 0.05f, -128, 127);
    m.slip_learning = d->slip_learning ? 1u : 0u;
    m.edge_timing = d->edge_timing ? 1u : 0u;
    m.gnss_fused = d->gnss_fused ? 1u : 0u;
    m.speed_std = (uint8_t)to_raw(d->speed_std_kmh, 0.05f, 31u);
    frame_head(f, TD_ID_ECU_FUSED);
    (void)td_can_ecu_fused_pack(f->data, &m, sizeof f->data);
    return TD_OK;
}

int td_proto_encode_fused_aux(const td_fused_aux_t *a, td_can_frame_t *f) {
    if (a == NULL || f == NULL) {
        return TD_E_ARG;
    }
    struct td_can_ecu_fused_aux_t m;
    m.wheel_edge_speed = (uint16_t)to_raw(a->wheel_edge_kmh, 0.01f, 0xFFFFu);
    m.lead_speed = (uint16_t)to_raw(a->lead_kmh, 0.01f, 0xFFFFu);
    m.upper_drive_slope = (uint8_t)to_raw(a->drive_rpm_per_duty[TD_UPPER], 0.5f, 0xFFu);
    m.lower_drive_slope = (uint8_t)to_raw(a->drive_rpm_per_duty[TD_LOWER], 0.5f, 0xFFu);
    m.gnss_delay = a->gnss_delay_ms;
    frame_head(f, TD_ID_ECU_FUSED_AUX);
    (void)td_can_ecu_fused_aux_pack(f->data, &m, sizeof f->data);
    return TD_OK;
}

int td_proto_encode_gnss_lag(const td_gnss_lag_t *g, td_can_frame_t *f) {
    if (g == NULL || f == NULL) {
        return TD_E_ARG;
    }
    struct td_can_ecu_gnss_lag_t m;
    m.lag_in_use = g->in_use_ms;
    m.lag_learned = g->learned_ms;
    m.lag_evidence = (uint8_t)to_raw(g->evidence_s, 0.1f, 0xFFu);
    m.lag_fit = (uint8_t)to_raw(g->fit, 0.01f, 100u);
    m.lag_state = (uint8_t)(g->state & 0x03u);
    m.lag_auto = g->automatic ? 1u : 0u;
    frame_head(f, TD_ID_ECU_GNSS_LAG);
    (void)td_can_ecu_gnss_lag_pack(f->data, &m, sizeof f->data);
    return TD_OK;
}

int td_proto_encode_ident(const td_ident_t *id, bool on_defaults, td_can_frame_t *f) {
    if (id == NULL || f == NULL || id->target > (uint8_t)TD_TARGET_STM32F4 ||
        id->transport > (uint8_t)TD_TRANSPORT_SLCAN_HIL || id->reset_cause > (uint8_t)TD_RESET_BROWN_OUT) {
        return TD_E_ARG;
    }
    struct td_can_ecu_ident_t m;
    m.target = id->target;
    m.firmware_major = (uint8_t)TD_FW_VERSION_MAJOR;
    m.firmware_minor = (uint8_t)TD_FW_VERSION_MINOR;
    m.firmware_patch = (uint8_t)TD_FW_VERSION_PATCH;
    m.protocol_major = (uint8_t)TD_PROTO_VERSION_MAJOR;
    m.protocol_minor = (uint8_t)TD_PROTO_VERSION_MINOR;
    m.transport = id->transport;
    m.reset_cause = id->reset_cause;
    m.clock_fallback = id->clock_fallback ? 1u : 0u;
    m.on_defaults = on_defaults ? 1u : 0u;
    frame_head(f, TD_ID_ECU_IDENT);
    (void)td_can_ecu_ident_pack(f->data, &m, sizeof f->data);
    return TD_OK;
}
