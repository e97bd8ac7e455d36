/**
 * @file td_drive.c
 * @brief Metering drive: feed-forward with a learned slope, reference model, PID (td_drive.h).
 */
#include "td_drive.h"

#include <math.h>
#include <stddef.h>

#define FORGET_S 60.0f      /* regression memory */
#define ADAPT_S 2.0f        /* kff follows the regression with this time constant */
#define MIN_DUTY_SD2 0.0009f /* duty spread needed before the slope is trusted (SD 0.03) */
#define MIN_RPM 1.0f
#define DUTY_LO 0.05f
#define DUTY_HI 0.95f
#define MIN_SETTLED_RPM 1.0f
#define MIN_SETTLED_SHARE 0.1f

static void clear_fit(td_drive_t *d) {
    d->sn = 0.0f;
    d->su = 0.0f;
    d->sw = 0.0f;
    d->suu = 0.0f;
    d->suw = 0.0f;
}

void td_drive_init(td_drive_t *d, float kp, float ki, float kd, float kff, float tau_s, bool adapt) {
    if (d == NULL) {
        return;
    }
    td_pid_init(&d->pid, kp, ki, kd, kff, 0.0f, 1.0f);
    td_drive_config(d, kp, ki, kd, kff, tau_s, adapt);
}

void td_drive_config(td_drive_t *d, float kp, float ki, float kd, float kff, float tau_s, bool adapt) {
    if (d == NULL) {
        return;
    }
    d->pid.kp = kp;
    d->pid.ki = ki;
    d->pid.kd = kd;
    d->pid.kff = kff;
    d->kff_cfg = kff;
    d->tau_s = tau_s > 0.0f ? tau_s : 0.0f;
    d->adapt = adapt;
    clear_fit(d);
    td_drive_reset(d);
}

void td_drive_reset(td_drive_t *d) {
    if (d == NULL) {
        return;
    }
    td_pid_reset(&d->pid);
    d->ref_rpm = 0.0f;
    d->duty_lag = 0.0f;
}

/* Weighted least squares speed = g * duty + c; kff drifts towards 1/g. */
static void learn(td_drive_t *d, float meas_rpm, float target_rpm, float dt_s) {
    const float keep = 1.0f - dt_s / FORGET_S;
    const float u = d->duty_lag;
    d->sn = d->sn * keep + 1.0f;
    d->su = d->su * keep + u;
    d->sw = d->sw * keep + meas_rpm;
    d->suu = d->suu * keep + u * u;
    d->suw = d->suw * keep + u * meas_rpm;
    const float mu = d->su / d->sn;
    const float var_u = d->suu / d->sn - mu * mu;
    if (!(var_u >= MIN_DUTY_SD2)) {
        return;
    }
    const float cov = d->suw / d->sn - mu * d->sw / d->sn;
    if (!(cov > 0.0f)) {
        return;
    }
    float goal = var_u / cov; /* 1/g: duty per r/min */
    const float lo = 0.5f * d->kff_cfg;
    const float hi = 2.0f * d->kff_cfg;
    goal = goal < lo ? lo : (goal > hi ? hi : goal);
    const float step = (goal - d->pid.kff) * dt_s / ADAPT_S;
    d->pid.kff += step;
    d->pid.integ -= step * target_rpm; /* bumpless: the duty does not jump with kff */
}

float td_drive_step(td_drive_t *d, float target_rpm, float meas_rpm, float dt_s) {
    if (!(dt_s > 0.0f)) {
        return 0.0f;
    }
    if (!d->pid.primed) {
        /* (re)started, the target leaving 0: the reference steps with it, so P and I push the
         * drive off breakaway as the plain PID does (a start from rest is not a step the
         * feed-forward alone makes); the model shapes only the changes that follow */
        d->ref_rpm = target_rpm;
        d->duty_lag = d->pid.kff * meas_rpm;
    }
    const float a = d->tau_s > 0.0f ? dt_s / (d->tau_s + dt_s) : 1.0f;
    d->ref_rpm += (target_rpm - d->ref_rpm) * a;
    const float duty = td_pid_step_ref(&d->pid, target_rpm, d->ref_rpm, meas_rpm, dt_s);
    d->duty_lag += (duty - d->duty_lag) * a;
    /* learn only in quasi-steady state: the model has followed the target, so the dynamics of
     * the drive (which the model only approximates) do not bias the slope */
    const float settled = MIN_SETTLED_RPM + MIN_SETTLED_SHARE * target_rpm;
    if (d->adapt && d->tau_s > 0.0f && meas_rpm > MIN_RPM && duty > DUTY_LO && duty < DUTY_HI &&
        fabsf(target_rpm - d->ref_rpm) < settled && fabsf(meas_rpm - d->ref_rpm) < 4.0f * settled) {
        learn(d, meas_rpm, target_rpm, dt_s);
    }
    return duty;
}

float td_drive_rpm_per_duty(const td_drive_t *d) {
    return d->pid.kff > 0.0f ? 1.0f / d->pid.kff : 0.0f;
}
