/**
 * @file td_params.h
 * @brief The ECU parameter set: units, ranges, defaults, validation.
 *
 * Every parameter can be written over CAN with PcParamSet (id in parentheses,
 * range as in protocol/topdress.dbc), only while the ECU is stopped.
 * Defaults are the paper's values where it gives one.
 */
#ifndef TD_PARAMS_H
#define TD_PARAMS_H

#include <stdint.h>
#include "td_common.h"

typedef struct {
    /* machine */
    float working_width_m;          /**< (1) 0.5..30, default 3.6 (6 rows x 0.60 m) */
    float kg_per_rev[2];            /**< (2,3) fertilizer per metering revolution, kg/rev, 0.001..5, default 0.3 */
    float wheel_radius_m;           /**< (4) 0.02..1, default 0.0615 (12.3 cm diameter) */
    uint16_t wheel_ppr;             /**< (5) wheel encoder pulses/rev, 1..10000, default 500 */
    /* dual speed rule */
    uint8_t queue_len;              /**< (6) N, length of queue G, 2..16, default 5 */
    uint8_t cv_window;              /**< (7) n, last values of G used for the CV, 2..queue_len, default 5 */
    float cv_threshold_pct;         /**< (8) CV threshold, %, 0.1..50, default 4.2 */
    float switch_speed_kmh;         /**< (9) V_Grmax, km/h, 0..25, default 6.0 */
    uint8_t speed_mode;             /**< (10) td_speed_mode_t, default TD_MODE_DUAL */
    uint8_t switch_compare;         /**< (11) td_compare_t, default TD_CMP_GNSS */
    /* metering motor PID (duty per r/min) */
    float pid_kp;                   /**< (12) 0..10, default see td_params.c */
    float pid_ki;                   /**< (13) 0..10, per second */
    float pid_kd;                   /**< (14) 0..10, seconds */
    float pid_kff;                  /**< (15) feed-forward duty per r/min of target, 0..1 */
    /* timing and fail-safes */
    uint16_t cmd_timeout_ms;        /**< (16) 100..10000, default 1500 */
    uint16_t gnss_timeout_ms;       /**< (17) GNSS speed older than this is stale, 100..10000, default 1200 */
    float min_work_speed_kmh;       /**< (18) below this speed the meters stop, 0..10, default 0.5 */
    uint16_t wheel_update_ms;       /**< (19) wheel speed update period, 50..5000, default 500 */
    uint8_t wheel_samples;          /**< (20) frequency samples averaged per update, 1..16, default 4 */
    uint16_t meter_counts_per_rev;  /**< (21) metering shaft encoder counts/rev, 1..65535, default 6400 */
    uint16_t fan_min_rpm;           /**< (22) 0..6000, default 2000 */
    uint8_t fan_ppr;                /**< (23) fan tachometer pulses/rev, 1..255, default 30 */
    float enc_fault_gnss_kmh;       /**< (24) 0.5..25, default 2.0 */
    uint16_t enc_fault_time_ms;     /**< (25) 100..30000, default 2000 */
    uint16_t blocked_time_ms;       /**< (26) 100..30000, default 1000 */
    uint16_t status_period_ms;      /**< (27) 20..1000, default 100 */
    /* fused speed estimate, slip compensation, look-ahead, metering drive (docs/speed.md) */
    uint8_t slip_comp;              /**< (28) td_slip_comp_t, 0..2, default TD_SLIP_OFF: modes dual/wheel/GNSS: off, the learned
                                         constant scale, eq. 5; the fused mode: eq. 5's shape x a learned factor, unless
                                         TD_SLIP_LEARNED (a learned constant scale) */
    uint16_t gnss_lag_ms;           /**< (29) added to every GNSS speed's age: receiver latency + velocity filter lag, 0..3000,
                                         default 0; with gnss_lag_auto the start value until the lag is learned */
    uint16_t lead_meter_ms;         /**< (30) look-ahead: metering drive response, 0..3000, default 0 (off) */
    uint16_t lead_air_ms;           /**< (31) look-ahead: air-line transport, 0..5000, default 0 (off) */
    float fused_jerk_ms3;           /**< (32) process noise: white-jerk density sqrt, m/s^3 per sqrt(Hz), 0.01..50, default 0.3 */
    float fused_gnss_std_kmh;       /**< (33) GNSS speed noise, 1 sigma, km/h, 0.01..10, default 0.2 */
    float fused_wheel_noise_pct;    /**< (34) wheel speed noise (bounce), 1 sigma, % of speed, 0.1..50, default 15 */
    uint16_t wheel_stop_ms;         /**< (35) no wheel edge for this long = standstill, 20..5000, default 300 */
    uint8_t drive_adapt;            /**< (36) learn the metering drives' slope (feed-forward), 0..1, default 1 */
    uint16_t meter_tau_ms;          /**< (37) time constant of the metering drive + speed window (reference model), 0..2000, default 200 */
    uint16_t lead_stop_ms;          /**< (38) look-ahead while the speed falls (slowing, the stop), 0..5000, default 0:
                                         the same as rising, lead_meter_ms + lead_air_ms */
    uint8_t gnss_lag_auto;          /**< (39) 1 (default): the GNSS lag is learned from the wheel (td_lag.h), gnss_lag_ms only
                                         its start value; 0: gnss_lag_ms is used unless the learned lag differs by more than
                                         0.3 s (then the learned one, state Overruled) */
    /* not on CAN: fixed properties of the build */
    float fan_rpm_at_full_duty;     /**< fan feed-forward scale, rpm, (0, 60000], default 4000 */
    uint16_t fan_spinup_ms;         /**< grace after start before FAN_LOW is flagged, default 3000 */
    uint32_t status_id;             /**< EcuStatus identifier, 29-bit, default TD_ID_ECU_STATUS */
    uint32_t command_id;            /**< PcCommand identifier, 29-bit, default TD_ID_PC_COMMAND; the two differ and take no other frame's id */
} td_params_t;

/* TD_PARAM_COUNT, the number of the highest parameter id: td_dbc.h (PcParamSet). */

/** Fill `p` with the defaults. */
void td_params_default(td_params_t *p);

/** Check every range and cross-constraint. Returns TD_OK or TD_E_RANGE / TD_E_INCONSISTENT / TD_E_ARG. */
int td_params_validate(const td_params_t *p);

/**
 * Set parameter `param_id` (1..TD_PARAM_COUNT) from its physical value (units as above).
 * Leaves `p` unchanged on error. Returns TD_OK, TD_E_UNKNOWN_PARAM, TD_E_RANGE or TD_E_INCONSISTENT.
 */
int td_params_set(td_params_t *p, uint8_t param_id, float value);

/** Read parameter `param_id` as a physical value into *value. Returns TD_OK or TD_E_UNKNOWN_PARAM. */
int td_params_get(const td_params_t *p, uint8_t param_id, float *value);

/**
 * DBC encoding of parameter `param_id`: physical units per raw unit and the raw range
 * (PcParamSet, EcuParamAck). Returns TD_OK or TD_E_UNKNOWN_PARAM.
 */
int td_params_encoding(uint8_t param_id, float *scale, uint32_t *raw_min, uint32_t *raw_max);

#endif /* TD_PARAMS_H */
