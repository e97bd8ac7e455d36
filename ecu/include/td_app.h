/**
 * @file td_app.h
 * @brief The ECU application: commands in, speed selection, metering targets, PID, fail-safes, frames out.
 *
 * Timing (defaults): td_app_step() every control period (10 ms): edge-timed wheel speed, the
 * fused estimate (GNSS speeds applied at the next step, at their time of validity), the
 * look-ahead speed, fail-safes and the drives; the paper's wheel speed and the
 * source decision every wheel_update_ms (500 ms); EcuStatus, EcuDiag, EcuSpeeds and
 * EcuTargets, EcuFused and EcuFusedAux every status_period_ms (100 ms); PcCommand expected every 500 ms, timeout
 * cmd_timeout_ms (1.5 s). Metering speeds are measured over the last 100 ms of counts.
 *
 * Metering is allowed for a layer only when: running (last command was start), no
 * command timeout, a usable speed >= min_work_speed_kmh, the layer's fan >= fan_min_rpm
 * and the layer's motor not latched as blocked. Otherwise its target is 0 and its PID is reset.
 *
 * Source: td_speedsel_rule() every wheel update, on GNSS validity changes, on encoder-fault and
 * GNSS_FROZEN changes and on parameter writes. On top of the rule: while the wheel reads ~0 and
 * GNSS says > enc_fault_gnss_kmh, the dual mode keeps the wheel until the encoder check decides
 * (GNSS value changed meanwhile -> WHEEL_ENCODER, GNSS used; never changed -> GNSS_FROZEN,
 * GNSS not used).
 */
#ifndef TD_APP_H
#define TD_APP_H

#include <stdbool.h>
#include <stdint.h>
#include "td_cal.h"
#include "td_common.h"
#include "td_drive.h"
#include "td_edge.h"
#include "td_fused.h"
#include "td_lag.h"
#include "td_params.h"
#include "td_pid.h"
#include "td_port.h"
#include "td_proto.h"
#include "td_speedq.h"
#include "td_wheel.h"

#define TD_TXQ_LEN 16u       /**< transmit queue length, frames; a full queue drops the newest (cnt.tx_dropped) */
#define TD_RATE_WINDOW 10u   /**< control steps in the metering/fan speed window */

/** Everything a port, the simulator or a test may want to see; read-only for them.
 *  Per-layer arrays are [TD_UPPER, TD_LOWER]. Updated by td_app_step() unless said otherwise. */
typedef struct {
    bool running;              /**< the last valid PcCommand said start (set by td_app_rx) */
    td_source_t source;        /**< the speed that drives eq. 4 */
    float cv_pct;              /**< CV of the last n values of queue G, %, >= 0; < 0: undefined; every wheel update */
    bool uniform;              /**< CV defined and below cv_threshold_pct */
    float v_wheel_kmh;         /**< fed-back wheel speed (eq. 1), km/h, every wheel_update_ms */
    float v_gnss_kmh;          /**< last GNSS speed of a PcCommand, km/h, 0..25 */
    bool gnss_valid;           /**< a GNSS speed arrived within gnss_timeout_ms and was not 0xFF */
    float v_kmh;               /**< the selected speed that drives eq. 4, km/h; 0 with no source */
    float rate_kg_ha[2];       /**< commanded rate, kg/ha, 0..600 (set by td_app_rx) */
    float target_rpm[2];       /**< eq. 4 target of the metering shaft, r/min; 0 when not allowed */
    float meter_rpm[2];        /**< measured metering shaft speed, r/min, over the last TD_RATE_WINDOW steps */
    float fan_rpm[2];          /**< measured fan speed, rpm, same window */
    float fan_target_rpm;      /**< commanded fan speed, rpm, 0..6000 (set by td_app_rx) */
    float meter_duty[2];       /**< metering motor PWM duty applied, 0..1 */
    float fan_duty[2];         /**< fan PWM duty applied, 0..1 */
    uint16_t faults;           /**< fault word, TD_FAULT_* bits */
    uint32_t wheel_updates;    /**< count of wheel-speed updates (each one a source decision) */
    uint32_t wheel_pulses;     /**< cumulative wheel pulses seen */
    /* fused estimate, slip, look-ahead, drives (td_fused.h, td_edge.h, td_drive.h): every step, in every mode */
    float v_fused_kmh;         /**< fused speed estimate, km/h, >= 0 */
    float a_fused_ms2;         /**< fused acceleration, m/s^2 */
    float slip_pct;            /**< wheel slip the estimate applies at its speed, (1 - wheel / ground speed) x 100, % */
    float innov_kmh;           /**< last GNSS innovation (speed minus estimate at its time of validity), km/h */
    float speed_std_kmh;       /**< 1 sigma of v_fused_kmh, km/h */
    float v_edge_kmh;          /**< wheel speed from pulse timing, km/h, no slip correction */
    float v_lead_kmh;          /**< speed predicted lead_meter_ms + lead_air_ms ahead, km/h: drives eq. 4 (= v_kmh without look-ahead) */
    float drive_rpm_per_duty[2]; /**< metering drive slope in use (learned), r/min per unit duty */
    uint16_t gnss_delay_ms;    /**< delay (age + lag) of the last GNSS speed applied to the estimate, ms */
    uint16_t gnss_lag_ms;      /**< the GNSS lag in use, ms (GnssLag, or the learned lag: lag_state) */
    uint16_t lag_learned_ms;   /**< the lag learned from the wheel, ms; 0xFFFF until learned (td_lag.h) */
    uint8_t lag_state;         /**< td_lag_state_t: where gnss_lag_ms comes from */
    uint8_t lag_overruled;     /**< times a fixed GnssLag was overruled by the data (wrapping) */
    float lag_evidence_s;      /**< seconds of speed change (the windows) behind the learned lag */
    float lag_fit;             /**< the last result's distance from the lag before it, share of it, 0..1 (1: none yet) */
    bool slip_learning;        /**< the wheel scale is being learned now (GNSS good, motion steady) */
    bool edge_timing;          /**< the port supplied a wheel edge time at the last step */
    bool gnss_fused;           /**< the estimate accepted a GNSS speed within gnss_timeout_ms */
    uint32_t gnss_fixes;       /**< GNSS speeds accepted by the estimate */
    uint32_t gnss_rejected;    /**< GNSS speeds refused by the estimate's gate (frozen or wild receiver) */
    uint32_t wheel_rejected;   /**< wheel measurements refused by the gate (bounce, cut cable) */
} td_state_t;

/** Frame counters, wrapping. Every received frame lands in exactly one of the rx_* counters. */
typedef struct {
    uint32_t rx_ok;              /**< acted on: a PcCommand, a PcGnssTime, or a PcParamSet that was accepted */
    uint32_t rx_unknown_id;      /**< an identifier the ECU does not take (also 11-bit frames) */
    uint32_t rx_bad_length;      /**< a known identifier with DLC != 8 */
    uint32_t rx_out_of_range;    /**< a PcCommand or PcGnssTime with a value outside its range or an undefined enum */
    uint32_t rx_param_rejected;  /**< a PcParamSet refused: unknown id, range, busy, inconsistent */
    uint32_t tx_dropped;         /**< frames dropped because the transmit queue was full */
} td_counters_t;

typedef struct {
    td_params_t p;
    td_state_t st;
    td_counters_t cnt;
    td_wheel_t wheel;
    td_speedq_t q;
    td_drive_t meter_drive[2];
    td_pid_t fan_pid[2];
    /* timing */
    uint32_t last_step_us;
    uint32_t last_cmd_us;
    uint32_t last_gnss_us;
    uint32_t last_status_us;
    uint32_t start_us;         /**< time of the last stop->start transition */
    uint32_t enc_fault_since_us;
    uint32_t blocked_since_us[2];
    bool have_cmd, have_gnss, stepped, enc_suspect, blocked_suspect[2];
    bool spun_up;              /**< the fan spin-up grace after the last start is over */
    bool gnss_moved;           /**< the GNSS value changed since the wheel/GNSS conflict began */
    /* metering/fan speed windows (ring of counts over TD_RATE_WINDOW steps) */
    uint32_t meter_hist[TD_RATE_WINDOW][2];
    uint32_t fan_hist[TD_RATE_WINDOW][2];
    uint32_t time_hist[TD_RATE_WINDOW];
    uint8_t hist_head, hist_count;
    uint32_t wheel_last_count;
    /* fused estimate */
    td_edge_t edge;
    td_fused_t fused;
    td_lag_t lag;              /**< the GNSS lag learned against the wheel's history */
    float gnss_pend_ms;        /**< GNSS speed waiting for the next step, m/s */
    uint32_t gnss_pend_us;     /**< its time of validity as the PC gave it (reception - age) */
    uint32_t gnss_fused_us;    /**< last GNSS speed the estimate accepted */
    uint32_t steady_since_us;  /**< start of the current steady motion */
    uint8_t gnss_seq;          /**< GnssSeq of the last PcGnssTime applied */
    bool gnss_pend, have_gnss_time, have_seq, have_fused, steady;
    /* transmit queue */
    td_can_frame_t txq[TD_TXQ_LEN];
    uint8_t tx_head, tx_count;
    td_cal_t cal;              /**< metering catch test (td_cal.h) */
    td_ident_t ident;          /**< who the ECU is (EcuIdent); host until the port says otherwise */
    bool ident_due;            /**< EcuIdent goes out at the next step */
    bool params_taken;         /**< a PcParamSet was taken since power-up (EcuIdent.OnDefaults 0) */
} td_app_t;

/** Initialise with a parameter set (validated: TD_E_RANGE / TD_E_INCONSISTENT on a bad one). */
int td_app_init(td_app_t *app, const td_params_t *params, uint32_t now_us);

/**
 * Take one received frame. Returns TD_OK when acted on, TD_E_UNKNOWN_ID, TD_E_LENGTH or
 * TD_E_RANGE when rejected (counted in cnt, never acted on). PcParamSet is always
 * answered with an EcuParamAck, and returns the parameter error (TD_E_BUSY, ...) if refused.
 * `now_us` is the reception time; it may be up to 35 min ahead of the next step's time (taken
 * as age 0), so an interrupt may stamp frames with a fresh clock read.
 */
int td_app_rx(td_app_t *app, const td_can_frame_t *frame, uint32_t now_us);

/** One control step. `in` are the cumulative counters read now; `out` the duties to apply. */
int td_app_step(td_app_t *app, uint32_t now_us, const td_io_in_t *in, td_io_out_t *out);

/** Pop the oldest frame to send. Returns 1 and fills *frame, or 0 when the queue is empty. */
int td_app_tx_pop(td_app_t *app, td_can_frame_t *frame);

/**
 * The port's identity for EcuIdent: target, transport, reset cause, clock fallback. td_app_init()
 * sets {TD_TARGET_HOST, TD_TRANSPORT_IN_PROCESS, TD_RESET_UNKNOWN, false}; a port on a target
 * calls this right after td_app_init(). EcuIdent goes out at the next step (after any status
 * frames of that step), and again at the next step after the first valid PcCommand following
 * power-up or a command timeout (a PC that (re)connects learns who it talks to at once).
 * TD_E_ARG for a value outside its enum.
 */
int td_app_set_ident(td_app_t *app, const td_ident_t *ident);

/**
 * EcuIdent again at the next step, with the identity set before: for a port whose link to the
 * cab PC has just come up in a way the core cannot see (on an ISOBUS, the node connected to its
 * Task Controller; EcuIdent sent before the address claim went nowhere). TD_E_ARG for NULL.
 */
int td_app_announce(td_app_t *app);

/** Read-only view of the state. */
const td_state_t *td_app_state(const td_app_t *app);

#endif /* TD_APP_H */
