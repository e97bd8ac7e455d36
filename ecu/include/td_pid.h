/**
 * @file td_pid.h
 * @brief PID with feed-forward, output limits, anti-windup (conditional integration with
 *        back-calculation clamp) and a first-order filtered derivative on the measurement.
 *
 * u = kff*setpoint + kp*e + I + D, clamped to [out_min, out_max];
 * I integrates ki*e*dt only while it does not push a saturated output further;
 * D = -kd * d(meas)/dt through a low-pass with time constant d_tau_s.
 */
#ifndef TD_PID_H
#define TD_PID_H

#include <stdbool.h>
#include <stdint.h>

typedef struct {
    float kp, ki, kd, kff;
    float d_tau_s;        /**< derivative filter time constant, s (default 0.05) */
    float out_min, out_max;
    float integ;          /**< integral term (in output units) */
    float d_filt;         /**< filtered derivative term */
    float prev_meas;
    bool primed;          /**< false until the first update */
} td_pid_t;

/**
 * Gains in output units per unit of the controlled quantity (for the metering motors: duty per
 * r/min; ki per second, kd times seconds, kff per unit of setpoint); output clamped to
 * [out_min, out_max].
 */
void td_pid_init(td_pid_t *pid, float kp, float ki, float kd, float kff, float out_min, float out_max);
/** Clear integral and derivative memory (e.g. when the motor is stopped). */
void td_pid_reset(td_pid_t *pid);
/** One update over dt_s (> 0) seconds. Returns the clamped output; out_min, state untouched, if dt_s <= 0 or NaN. */
float td_pid_step(td_pid_t *pid, float setpoint, float measured, float dt_s);
/**
 * Two degrees of freedom: the feed-forward acts on `setpoint`, P, I and D on the error from
 * `reference` (the response the feed-forward should produce, e.g. the setpoint through a model
 * of the drive), so the feedback corrects only what the feed-forward gets wrong.
 * td_pid_step(pid, sp, m, dt) is td_pid_step_ref(pid, sp, sp, m, dt).
 */
float td_pid_step_ref(td_pid_t *pid, float setpoint, float reference, float measured, float dt_s);

#endif /* TD_PID_H */
