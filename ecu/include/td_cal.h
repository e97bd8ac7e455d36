/**
 * @file td_cal.h
 * @brief Metering catch test: one layer's meter turns a set number of revolutions with the
 *        machine standing, so the operator can weigh what came out (kg/rev = kg / revolutions).
 *
 * Driven by PcCalCommand (TD_ID_PC_CAL_COMMAND), reported by EcuCalStatus (TD_ID_ECU_CAL_STATUS)
 * every status period while not idle. Safety: accepted only while stopped (no start command in
 * force); a start command, the ground wheel turning (> TD_CAL_MAX_WHEEL_KMH), a meter that does
 * not turn for blocked_time_ms or a test longer than its time budget abort it and the meter stops.
 * The revolutions reported are those counted on the meter encoder since the test began,
 * coasting after the stop included: what fell into the catch bag.
 *
 * Action 2, the look-ahead test (terminal/leadcal.py): the same run, but accepted only while a
 * start command is in force, so the fans run under their normal control and the product goes
 * down the air line to the outlet; the machine stands, so td_app's own meter control holds the
 * meters at 0 and only the layer under test turns. A stop command (fans off) aborts it
 * (TD_CAL_R_FANS_OFF); the ground wheel turning aborts it as it does a catch test.
 *
 * Timing: td_cal_step() once per td_app_step(), after the normal meter control; it overrides
 * the duty of the layer under test only while the test runs.
 */
#ifndef TD_CAL_H
#define TD_CAL_H

#include <stdbool.h>
#include <stdint.h>
#include "td_params.h"
#include "td_pid.h"
#include "td_port.h"


#define TD_CAL_MAX_WHEEL_KMH 0.5f  /**< ground wheel faster than this: the machine moves, abort */
#define TD_CAL_MIN_RPM 0.5f        /**< slowest meter speed of a catch test, r/min */
#define TD_CAL_MAX_RPM 100.0f      /**< fastest, r/min */
#define TD_CAL_MAX_REV 1000.0f     /**< most revolutions of one catch test */
#define TD_CAL_SLACK_S 10.0f       /**< time budget: twice the nominal duration plus this, s */

/* td_cal_state_t (EcuCalStatus.CalState) and td_cal_reason_t (CalReason): td_dbc.h. The reasons:
 * NONE running or done normally; RESET the PC sent reset during the test; RUNNING a start
 * command is in force (refused, or aborted by a start); MOVING the ground wheel turns; BLOCKED
 * the meter does not turn; TIMEOUT longer than the time budget; BAD_VALUE revolutions or speed
 * outside their range; FANS_OFF a look-ahead test without a start command in force (no fans). */

/** What the catch test reads each step (from td_app's inputs and state). */
typedef struct {
    bool running;              /**< a start command is in force */
    float v_wheel_kmh;         /**< fed-back wheel speed, km/h */
    uint32_t meter_count[2];   /**< cumulative metering encoder counts */
    float meter_rpm[2];        /**< measured metering speed, r/min */
} td_cal_io_t;

typedef struct {
    uint8_t state;             /**< td_cal_state_t */
    uint8_t layer;             /**< TD_UPPER / TD_LOWER */
    uint8_t reason;            /**< td_cal_reason_t */
    uint8_t seq;               /**< CalSeq of the command that began or ended the test */
    float target_rev;          /**< revolutions to run */
    float speed_rpm;           /**< metering speed to run at, r/min */
    float done_rev;            /**< revolutions counted since the test began */
    float meter_rpm;           /**< last measured speed of the layer under test */
    uint32_t start_count;
    uint32_t start_us;
    uint32_t last_status_us;
    uint32_t slow_since_us;
    bool counting;             /**< start_count holds the first count of the test */
    bool slow;                 /**< the meter turns below 10 % of its speed (blocked check) */
    bool announce;             /**< send a status frame at the next step */
    bool with_fans;            /**< the look-ahead test: runs while started (fans on), standing */
    td_pid_t pid;
} td_cal_t;

/** Idle, nothing running. */
void td_cal_init(td_cal_t *cal);

/**
 * Take a PcCalCommand. TD_OK when acted on (a refusal is reported in the status: ABORTED with
 * its reason), TD_E_LENGTH for DLC != 8, TD_E_RANGE for an undefined action or layer.
 */
int td_cal_rx(td_cal_t *cal, const td_can_frame_t *frame, bool running, uint32_t now_us);

/** True while a catch test drives a meter. */
bool td_cal_active(const td_cal_t *cal);

/**
 * One step, after td_app's meter control: while running, drives the layer's meter duty in
 * `out` with the meter PID gains of `p`. Returns 1 and fills `status` when an EcuCalStatus is
 * due (every p->status_period_ms while not idle, and at once on a change), else 0.
 */
int td_cal_step(td_cal_t *cal, uint32_t now_us, float dt_s, const td_params_t *p, const td_cal_io_t *io,
                td_io_out_t *out, td_can_frame_t *status);

#endif /* TD_CAL_H */
