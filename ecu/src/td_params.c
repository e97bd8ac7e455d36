/**
 * @file td_params.c
 * @brief Parameter defaults, ranges (those of PcParamSet in protocol/topdress.dbc) and access by id.
 */
#include "td_params.h"

#include <stddef.h>
#include "td_cal.h"
#include "td_proto.h"

typedef enum { TD_PF32, TD_PU8, TD_PU16 } td_ptype_t;

typedef struct {
    uint16_t offset;   /* offsetof the field in td_params_t */
    uint8_t type;      /* td_ptype_t */
    float scale;       /* physical units per raw DBC unit */
    uint32_t raw_min, raw_max;
} td_pdesc_t;

/* Index = parameter id - 1: the table of td_dbc.h, generated from PcParamSet's multiplexed
 * signals (their TdField attribute names the field). */
#define TD_PDESC(id, signal, field, type, scale, lo, hi) \
    { (uint16_t)offsetof(td_params_t, field), (uint8_t)(type), (scale), (lo), (hi) },
static const td_pdesc_t k_desc[TD_PARAM_COUNT] = { TD_PARAM_TABLE(TD_PDESC) };

/* Each field is stored as the table says (a build error otherwise: an array of size -1). */
#define TD_PSIZE_TD_PF32 sizeof(float)
#define TD_PSIZE_TD_PU8 sizeof(uint8_t)
#define TD_PSIZE_TD_PU16 sizeof(uint16_t)
#define TD_PCHECK(id, signal, field, type, scale, lo, hi) \
    typedef char td_pcheck_##signal[sizeof(((td_params_t *)0)->field) == TD_PSIZE_##type ? 1 : -1];
TD_PARAM_TABLE(TD_PCHECK)

/* Float rounding of a value that went through raw * scale stays well inside this many raw units. */
#define TD_RAW_TOL 0.05f
#define TD_FAN_RPM_FULL_MAX 60000.0f

/* A configurable identifier (status, command) must not be that of another frame of the protocol. */
#define TD_TAKEN(frame_id) (id != TD_ID_ECU_STATUS && id != TD_ID_PC_COMMAND && id == (frame_id)) ||
static bool id_taken(uint32_t id) {
    return TD_FRAME_IDS(TD_TAKEN) false;
}

void td_params_default(td_params_t *p) {
    if (p == NULL) {
        return;
    }
    p->working_width_m = 3.6f;
    p->kg_per_rev[TD_UPPER] = 0.3f;
    p->kg_per_rev[TD_LOWER] = 0.3f;
    p->wheel_radius_m = 0.0615f;
    p->wheel_ppr = 500u;
    p->queue_len = 5u;
    p->cv_window = 5u;
    p->cv_threshold_pct = 4.2f;
    p->switch_speed_kmh = 6.0f;
    p->speed_mode = (uint8_t)TD_MODE_DUAL;
    p->switch_compare = (uint8_t)TD_CMP_GNSS;
    /* Tuned on the reference metering motor (1.0 duty -> 60 r/min, tau 0.15 s, 10 ms period):
     * the feed-forward does most of the work, P speeds it up, a small I removes the residual
     * error without winding up during the transient (overshoot ~2 %, settled in ~0.2 s). The
     * measured speed is a 100 ms count window, too coarse for a useful derivative: kd = 0. */
    p->pid_kp = 0.015f;
    p->pid_ki = 0.01f;
    p->pid_kd = 0.0f;
    p->pid_kff = 1.0f / 60.0f;
    p->cmd_timeout_ms = 1500u;
    p->gnss_timeout_ms = 1200u;
    p->min_work_speed_kmh = 0.5f;
    p->wheel_update_ms = 500u;
    p->wheel_samples = 4u;
    p->meter_counts_per_rev = 6400u;
    p->fan_min_rpm = 2000u;
    p->fan_ppr = 30u;
    p->enc_fault_gnss_kmh = 2.0f;
    p->enc_fault_time_ms = 2000u;
    p->blocked_time_ms = 1000u;
    p->status_period_ms = 100u;
    p->slip_comp = (uint8_t)TD_SLIP_OFF;
    p->gnss_lag_ms = 0u;
    p->lead_meter_ms = 0u;
    p->lead_air_ms = 0u;
    p->fused_jerk_ms3 = 0.3f;
    p->fused_gnss_std_kmh = 0.2f;
    p->fused_wheel_noise_pct = 15.0f;
    p->wheel_stop_ms = 300u;
    p->drive_adapt = 1u;
    p->meter_tau_ms = 200u;
    p->lead_stop_ms = 0u;
    p->gnss_lag_auto = 1u;
    p->fan_rpm_at_full_duty = 4000.0f;
    p->fan_spinup_ms = 3000u;
    p->status_id = TD_ID_ECU_STATUS;
    p->command_id = TD_ID_PC_COMMAND;
}

static float field_get(const td_params_t *p, const td_pdesc_t *d) {
    const unsigned char *base = (const unsigned char *)p + d->offset;
    switch (d->type) {
    case TD_PU8:
        return (float)*(const uint8_t *)(const void *)base;
    case TD_PU16:
        return (float)*(const uint16_t *)(const void *)base;
    default:
        return *(const float *)(const void *)base;
    }
}

static void field_set(td_params_t *p, const td_pdesc_t *d, float value) {
    unsigned char *base = (unsigned char *)p + d->offset;
    switch (d->type) {
    case TD_PU8:
        *(uint8_t *)(void *)base = (uint8_t)(value + 0.5f);
        break;
    case TD_PU16:
        *(uint16_t *)(void *)base = (uint16_t)(value + 0.5f);
        break;
    default:
        *(float *)(void *)base = value;
        break;
    }
}

static bool in_range(const td_pdesc_t *d, float value) {
    const float raw = value / d->scale;
    /* written so that NaN fails */
    return raw >= (float)d->raw_min - TD_RAW_TOL && raw <= (float)d->raw_max + TD_RAW_TOL;
}

int td_params_validate(const td_params_t *p) {
    if (p == NULL) {
        return TD_E_ARG;
    }
    for (uint8_t i = 0u; i < TD_PARAM_COUNT; i++) {
        if (!in_range(&k_desc[i], field_get(p, &k_desc[i]))) {
            return TD_E_RANGE;
        }
    }
    if (!(p->fan_rpm_at_full_duty > 0.0f && p->fan_rpm_at_full_duty <= TD_FAN_RPM_FULL_MAX) ||
        p->status_id > 0x1FFFFFFFu || p->command_id > 0x1FFFFFFFu) {
        return TD_E_RANGE;
    }
    if (p->cv_window > p->queue_len || p->status_id == p->command_id || id_taken(p->status_id) ||
        id_taken(p->command_id)) {
        return TD_E_INCONSISTENT;
    }
    return TD_OK;
}

int td_params_set(td_params_t *p, uint8_t param_id, float value) {
    if (p == NULL) {
        return TD_E_ARG;
    }
    if (param_id < 1u || param_id > TD_PARAM_COUNT) {
        return TD_E_UNKNOWN_PARAM;
    }
    const td_pdesc_t *d = &k_desc[param_id - 1u];
    if (!in_range(d, value)) {
        return TD_E_RANGE;
    }
    td_params_t next = *p;
    field_set(&next, d, value);
    const int rc = td_params_validate(&next);
    if (rc != TD_OK) {
        return rc;
    }
    *p = next;
    return TD_OK;
}

int td_params_get(const td_params_t *p, uint8_t param_id, float *value) {
    if (p == NULL || value == NULL) {
        return TD_E_ARG;
    }
    if (param_id < 1u || param_id > TD_PARAM_COUNT) {
        return TD_E_UNKNOWN_PARAM;
    }
    *value = field_get(p, &k_desc[param_id - 1u]);
    return TD_OK;
}

int td_params_encoding(uint8_t param_id, float *scale, uint32_t *raw_min, uint32_t *raw_max) {
    if (param_id < 1u || param_id > TD_PARAM_COUNT) {
        return TD_E_UNKNOWN_PARAM;
    }
    const td_pdesc_t *d = &k_desc[param_id - 1u];
    if (scale != NULL) {
        *scale = d->scale;
    }
    if (raw_min != NULL) {
        *raw_min = d->raw_min;
    }
    if (raw_max != NULL) {
        *raw_max = d->raw_max;
    }
    return TD_OK;
}
