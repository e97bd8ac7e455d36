/**
 * @file td_pid.c
 * @brief PID with feed-forward, clamped output, conditional-integration anti-windup and a
 *        low-pass filtered derivative on the measurement (no kick on setpoint steps).
 */
#include "td_pid.h"

#include <stddef.h>

#define TD_PID_D_TAU_S 0.05f

void td_pid_init(td_pid_t *pid, float kp, float ki, float kd, float kff, float out_min, float out_max) {
    if (pid == NULL) {
        return;
    }
    pid->kp = kp;
    pid->ki = ki;
    pid->kd = kd;
    pid->kff = kff;
    pid->d_tau_s = TD_PID_D_TAU_S;
    pid->out_min = out_min;
    pid->out_max = out_max;
    td_pid_reset(pid);
}

void td_pid_reset(td_pid_t *pid) {
    if (pid == NULL) {
        return;
    }
    pid->integ = 0.0f;
    pid->d_filt = 0.0f;
    pid->prev_meas = 0.0f;
    pid->primed = false;
}

float td_pid_step(td_pid_t *pid, float setpoint, float measured, float dt_s) {
    return td_pid_step_ref(pid, setpoint, setpoint, measured, dt_s);
}

float td_pid_step_ref(td_pid_t *pid, float setpoint, float reference, float measured, float dt_s) {
    if (!(dt_s > 0.0f)) {
        return pid->out_min;
    }
    const float e = reference - measured;
    if (!pid->primed) {
        pid->prev_meas = measured;
        pid->primed = true;
    }
    const float d_raw = -pid->kd * (measured - pid->prev_meas) / dt_s;
    pid->prev_meas = measured;
    pid->d_filt += (d_raw - pid->d_filt) * dt_s / (pid->d_tau_s + dt_s);

    const float base = pid->kff * setpoint + pid->kp * e + pid->d_filt;
    const float integ_next = pid->integ + pid->ki * e * dt_s;
    const float u_next = base + integ_next;
    /* integrate unless that pushes an already saturated output further out */
    if (!((u_next > pid->out_max && e > 0.0f) || (u_next < pid->out_min && e < 0.0f))) {
        pid->integ = integ_next;
    }
    /* the integral alone never needs more than the full output span */
    const float span = pid->out_max - pid->out_min;
    if (pid->integ > span) {
        pid->integ = span;
    } else if (pid->integ < -span) {
        pid->integ = -span;
    }
    float u = base + pid->integ;
    if (u > pid->out_max) {
        u = pid->out_max;
    } else if (u < pid->out_min) {
        u = pid->out_min;
    }
    return u;
}
