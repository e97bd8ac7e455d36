/**
 * @file td_drive.h
 * @brief Metering drive control: feed-forward with a learned slope, a reference model, and the
 *        PID on what the feed-forward gets wrong.
 *
 * duty = kff * target + PID(reference - measured), the reference being the target through a
 * first-order model of the drive and its speed window (time constant tau_s): while the drive
 * follows a target step as the feed-forward makes it, the error is zero and neither P nor the
 * integral pushes it past the new target (the integral no longer winds up during a step).
 *
 * Slope learning (adapt): a DC metering drive is affine in duty above breakaway,
 * speed = g * (duty - d0). Every step in which the drive turns and the duty is not saturated,
 * the pair (duty through the same model lag, measured speed) goes into exponentially weighted
 * least squares (forgetting time 60 s); once the duties seen span enough (SD >= 0.03), kff
 * moves slowly (time constant 2 s) towards 1/g, bounded to 0.5..2 x the configured kff. The
 * offset d0 stays with the integral. A kff change moves the integral by the opposite amount
 * (bumpless). Without adapt, or with tau_s = 0, this is the PID of td_pid.h as configured.
 */
#ifndef TD_DRIVE_H
#define TD_DRIVE_H

#include <stdbool.h>
#include "td_pid.h"

typedef struct {
    td_pid_t pid;              /**< gains as configured; its kff is the one in use */
    float kff_cfg;             /**< the configured feed-forward, duty per r/min */
    float tau_s;               /**< reference model time constant, s (0: reference = target) */
    bool adapt;                /**< learn the slope */
    float ref_rpm;             /**< reference model output, r/min */
    float duty_lag;            /**< duty through the model lag */
    float sn, su, sw, suu, suw; /**< weighted sums of the regression speed = g * duty + c */
} td_drive_t;

/** Initialise with the PID gains, the model time constant and whether to learn the slope. */
void td_drive_init(td_drive_t *d, float kp, float ki, float kd, float kff, float tau_s, bool adapt);
/** New configuration (a parameter write): gains and tau take effect, the learned slope restarts. */
void td_drive_config(td_drive_t *d, float kp, float ki, float kd, float kff, float tau_s, bool adapt);
/** The drive stops (target 0): controller memory cleared, the learned slope kept. */
void td_drive_reset(td_drive_t *d);
/** One step: the duty, 0..1, for target_rpm (> 0) with the drive measured at meas_rpm. */
float td_drive_step(td_drive_t *d, float target_rpm, float meas_rpm, float dt_s);
/** The slope in use, r/min per unit duty (1 / kff). */
float td_drive_rpm_per_duty(const td_drive_t *d);

#endif /* TD_DRIVE_H */
