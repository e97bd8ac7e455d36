/**
 * @file td_proto.h
 * @brief The CAN protocol of protocol/topdress.dbc, in physical units, validated.
 *
 * Built on the codec generated from the DBC (ecu/src/gen/td_can.[ch], never edited by hand).
 * Decoders reject a frame (and say why) instead of returning a half-valid value:
 * wrong DLC -> TD_E_LENGTH, a value outside the DBC range or an undefined enum -> TD_E_RANGE.
 */
#ifndef TD_PROTO_H
#define TD_PROTO_H

#include <stdbool.h>
#include <stdint.h>
#include "td_common.h"
#include "td_port.h"

/* Frame identifiers (TD_ID_*), EcuStatus.RunState (TD_RUN_*) and EcuIdent's targets,
 * transports and reset causes (td_target_t, td_transport_t, td_reset_cause_t): td_dbc.h, from
 * the DBC. */

/** PcCommand (paper Table 1), physical. */
typedef struct {
    bool start;                /**< byte 0: 0x0A start, 0x00 stop (any other value rejected) */
    float fan_rpm;             /**< bytes 1-2, 1 rpm, 0..6000 */
    float rate_kg_ha[2];       /**< bytes 3-4 upper, 5-6 lower, 0.01 kg/ha, 0..600 */
    bool gnss_valid;           /**< byte 7 != 0xFF */
    float gnss_kmh;            /**< byte 7, 0.1 km/h, 0..25.0; raw 251..254 rejected */
} td_command_t;

/** EcuStatus (paper Table 1), physical. */
typedef struct {
    bool running;
    float meter_rpm[2];        /**< 0.01 r/min */
    float fan_rpm[2];          /**< 20 rpm steps, saturates at 5100 */
    float wheel_kmh;           /**< 0.1 km/h, saturates at 25.5 */
} td_status_t;

typedef struct {
    uint8_t source;            /**< td_source_t */
    uint8_t mode;              /**< td_speed_mode_t */
    bool gnss_valid;
    bool uniform;              /**< CV defined and below threshold */
    uint8_t compare;           /**< td_compare_t */
    float cv_pct;              /**< 0.01 %, saturates at 655.35; undefined CV is sent as 655.35 */
    uint16_t faults;
    uint32_t wheel_pulses;     /**< cumulative, mod 2^24 */
} td_diag_t;

typedef struct {
    float wheel_kmh, gnss_kmh, selected_kmh;  /**< 0.01 km/h; gnss 655.35 = not valid */
    uint16_t rx_rejected;
} td_speeds_t;

typedef struct {
    float target_rpm[2];
    float meter_duty_pct[2];
    float fan_duty_pct[2];
} td_targets_t;

typedef struct {
    uint8_t param_id;
    uint8_t result;            /**< td_ack_result_t */
    uint32_t raw;              /**< the value now in force, raw DBC units */
} td_param_ack_t;

/** PcGnssTime: the GNSS speed with its age, so that the ECU applies it at its time of validity. */
typedef struct {
    bool valid;                /**< GnssSpeedPrecise != 0xFFFF */
    float speed_kmh;           /**< bytes 0-1, 0.01 km/h, 0..25; raw 2501..65534 rejected */
    uint16_t age_ms;           /**< bytes 2-3, 1 ms, 0..10000: fix (its sentence's arrival at the PC) to sending */
    uint8_t seq;               /**< byte 4, counts fixes; a repeated seq is not applied again */
} td_gnss_time_t;

/** EcuFused: the fused estimate (td_fused.h). */
typedef struct {
    float speed_kmh;           /**< 0.01 km/h, 0..655.35 */
    float accel_ms2;           /**< 0.001 m/s^2, saturating at +-32.767 */
    float slip_pct;            /**< slip applied at the current speed, (1 - wheel / ground) x 100, 0.01 %, signed */
    float innov_kmh;           /**< last GNSS innovation, 0.05 km/h, saturating at -6.4..6.35 */
    bool slip_learning;        /**< the scale is being learned now */
    bool edge_timing;          /**< the port supplies wheel edge times */
    bool gnss_fused;           /**< a GNSS speed was applied within gnss_timeout_ms */
    float speed_std_kmh;       /**< 1 sigma of speed_kmh, 0.05 km/h, saturating at 1.55 */
} td_fused_diag_t;

/** EcuFusedAux: edge-timed wheel speed, look-ahead speed, learned drive slopes, GNSS delay. */
typedef struct {
    float wheel_edge_kmh;      /**< 0.01 km/h, raw wheel (no slip correction) */
    float lead_kmh;            /**< speed predicted at t + lead, that drives eq. 4, 0.01 km/h */
    float drive_rpm_per_duty[2]; /**< learned metering drive slope, 0.5 r/min per unit duty, 0..127.5 */
    uint16_t gnss_delay_ms;    /**< delay (age + lag) of the last GNSS speed applied, ms, saturating */
} td_fused_aux_t;

/** EcuGnssLag: the GNSS lag in use, learned, and where it comes from (td_lag.h). */
typedef struct {
    uint16_t in_use_ms;        /**< lag added to every GNSS speed's age, ms */
    uint16_t learned_ms;       /**< learned lag, ms; 0xFFFF = not learned yet */
    float evidence_s;          /**< seconds of speed change behind it, 0.1 s, saturating at 25.5 */
    float fit;                 /**< misfit r_min / r_max, 0..1 (sent in whole %) */
    uint8_t state;             /**< td_lag_state_t */
    bool automatic;            /**< GnssLagAuto */
} td_gnss_lag_t;
/** What the port says of itself (td_app_set_ident); the versions come from td_version.h. */
typedef struct {
    uint8_t target;            /**< td_target_t */
    uint8_t transport;         /**< td_transport_t */
    uint8_t reset_cause;       /**< td_reset_cause_t of the last reset */
    bool clock_fallback;       /**< the crystal did not start: running on the internal oscillator */
} td_ident_t;

int td_proto_decode_command(const td_can_frame_t *f, td_command_t *out);
int td_proto_encode_command(const td_command_t *c, td_can_frame_t *f);
int td_proto_encode_status(const td_status_t *s, td_can_frame_t *f);
int td_proto_decode_status(const td_can_frame_t *f, td_status_t *out);
int td_proto_encode_diag(const td_diag_t *d, td_can_frame_t *f);
int td_proto_encode_speeds(const td_speeds_t *s, td_can_frame_t *f);
int td_proto_encode_targets(const td_targets_t *t, td_can_frame_t *f);
int td_proto_encode_param_ack(const td_param_ack_t *a, td_can_frame_t *f);
int td_proto_decode_gnss_time(const td_can_frame_t *f, td_gnss_time_t *out);
int td_proto_encode_gnss_time(const td_gnss_time_t *g, td_can_frame_t *f);
int td_proto_encode_fused(const td_fused_diag_t *d, td_can_frame_t *f);
int td_proto_encode_fused_aux(const td_fused_aux_t *a, td_can_frame_t *f);
int td_proto_encode_gnss_lag(const td_gnss_lag_t *g, td_can_frame_t *f);
/** EcuIdent: the port's identity with the firmware and protocol versions of td_version.h, and
 *  `on_defaults`: no PcParamSet taken since power-up (tells a power-up from a command timeout).
 *  TD_E_ARG for a target, transport or reset cause outside its value table. */
int td_proto_encode_ident(const td_ident_t *id, bool on_defaults, td_can_frame_t *f);
/**
 * Decode PcParamSet into the parameter id and its physical value (units of td_params.h).
 * TD_E_UNKNOWN_PARAM for an id outside 1..TD_PARAM_COUNT, TD_E_RANGE outside the DBC range.
 */
int td_proto_decode_param_set(const td_can_frame_t *f, uint8_t *param_id, float *value);
/** Physical value -> raw DBC units of parameter `param_id` (for the acknowledgement). */
uint32_t td_proto_param_raw(uint8_t param_id, float value);

#endif /* TD_PROTO_H */
