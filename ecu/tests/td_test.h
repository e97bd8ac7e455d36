/**
 * @file td_test.h
 * @brief Shared helpers of the C tests: cmocka includes and a small plant (ground wheel,
 *        first-order metering motors and fans) that drives td_app through virtual time.
 */
#ifndef TD_TEST_H
#define TD_TEST_H

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>
#include <cmocka.h>

#include "td_app.h"

#define PI_D 3.14159265358979323846

/* Reference metering motor: duty 1.0 -> 60 r/min at the shaft, time constant 0.15 s. */
#define MOTOR_RPM_FULL 60.0
#define MOTOR_TAU_S 0.15
#define FAN_RPM_FULL 4000.0
#define FAN_TAU_S 0.4

/** Exact first-order response over dt towards gain*u. */
static inline double first_order(double y, double u, double gain, double tau_s, double dt_s) {
    const double target = gain * u;
    return target + (y - target) * exp(-dt_s / tau_s);
}

typedef struct {
    td_app_t app;
    td_params_t p;
    uint32_t now_us;
    uint32_t step_us;
    /* plant */
    double wheel_kmh;          /* what the ground wheel turns at */
    double wheel_pos;          /* pulses, fractional */
    uint32_t wheel_base;       /* counter offset (to cross the wrap) */
    bool edge_timing;          /* the port has a capture timer: it passes the last pulse's time */
    double meter_rpm[2], meter_pos[2];
    double fan_rpm[2], fan_pos[2];
    bool meter_blocked[2], fan_broken[2];
    /* the PC */
    bool pc_start;
    double pc_gnss_kmh;        /* < 0: send 0xFF */
    double pc_gnss_jitter_kmh; /* added to every other GNSS speed: a live receiver's noise */
    uint32_t cmds_sent;
    double pc_rate[2];
    double pc_fan_rpm;
    bool pc_sending;
    uint32_t next_cmd_us;
    uint32_t last_cmd_sent_us;
    td_io_out_t out;
} rig_t;

static inline void rig_init(rig_t *r, const td_params_t *p, uint32_t t0_us) {
    memset(r, 0, sizeof *r);
    if (p != NULL) {
        r->p = *p;
    } else {
        td_params_default(&r->p);
    }
    r->now_us = t0_us;
    r->step_us = 10000u;
    r->pc_gnss_kmh = -1.0;
    r->pc_fan_rpm = 3000.0;
    r->pc_rate[0] = 200.0;
    r->pc_rate[1] = 150.0;
    r->pc_sending = true;
    r->next_cmd_us = t0_us;
    assert_int_equal(td_app_init(&r->app, &r->p, t0_us), TD_OK);
}

/* The PC has sent start and forwards gnss_kmh; the ground moves under the wheel at wheel_kmh. */
static inline void rig_start(rig_t *r, const td_params_t *p, uint32_t t0_us, double gnss_kmh,
                             double wheel_kmh) {
    rig_init(r, p, t0_us);
    r->pc_start = true;
    r->pc_gnss_kmh = gnss_kmh;
    r->wheel_kmh = wheel_kmh;
}

static inline td_can_frame_t rig_command_frame(bool start, double fan, double up, double lo, double gnss) {
    td_command_t c;
    c.start = start;
    c.fan_rpm = (float)fan;
    c.rate_kg_ha[0] = (float)up;
    c.rate_kg_ha[1] = (float)lo;
    c.gnss_valid = gnss >= 0.0;
    c.gnss_kmh = c.gnss_valid ? (float)gnss : 0.0f;
    td_can_frame_t f;
    assert_int_equal(td_proto_encode_command(&c, &f), TD_OK);
    return f;
}

static inline void rig_send_command(rig_t *r) {
    const double jitter = (r->cmds_sent++ % 2u == 1u && r->pc_gnss_kmh >= 0.0) ? r->pc_gnss_jitter_kmh : 0.0;
    const td_can_frame_t f =
        rig_command_frame(r->pc_start, r->pc_fan_rpm, r->pc_rate[0], r->pc_rate[1], r->pc_gnss_kmh + jitter);
    assert_int_equal(td_app_rx(&r->app, &f, r->now_us), TD_OK);
}

/** Drain the transmit queue; returns how many frames had id `id` (0: count all). */
static inline int rig_drain(rig_t *r, uint32_t id) {
    td_can_frame_t f;
    int n = 0;
    while (td_app_tx_pop(&r->app, &f)) {
        if (id == 0u || f.id == id) {
            n++;
        }
    }
    return n;
}

/** One control period: the PC command when due (every 500 ms), the ECU step, then the plant. */
static inline void rig_step(rig_t *r) {
    if (r->pc_sending && (int32_t)(r->now_us - r->next_cmd_us) >= 0) {
        rig_send_command(r);
        r->last_cmd_sent_us = r->now_us;
        r->next_cmd_us = r->now_us + 500000u;
    }
    td_io_in_t in;
    in.wheel_count = r->wheel_base + (uint32_t)(uint64_t)r->wheel_pos;
    /* the last pulse came frac(pos) pulses ago, at the wheel's current pulse rate */
    const double rate_per_us = r->wheel_kmh / 3.6 / (2.0 * PI_D * r->p.wheel_radius_m) * r->p.wheel_ppr * 1e-6;
    const double back_us = rate_per_us > 0.0 ? (r->wheel_pos - floor(r->wheel_pos)) / rate_per_us : 0.0;
    in.wheel_edge_valid = r->edge_timing ? 1u : 0u;
    in.wheel_edge_us = r->now_us - (uint32_t)(back_us < 4.0e9 ? back_us : 0.0);
    for (int l = 0; l < 2; l++) {
        in.meter_count[l] = (uint32_t)(uint64_t)r->meter_pos[l];
        in.fan_count[l] = (uint32_t)(uint64_t)r->fan_pos[l];
    }
    assert_int_equal(td_app_step(&r->app, r->now_us, &in, &r->out), TD_OK);
    const double dt = r->step_us * 1e-6;
    for (int l = 0; l < 2; l++) {
        assert_true(r->out.meter_duty[l] >= 0.0f && r->out.meter_duty[l] <= 1.0f);
        assert_true(r->out.fan_duty[l] >= 0.0f && r->out.fan_duty[l] <= 1.0f);
        const double m = r->meter_blocked[l] ? 0.0 : first_order(r->meter_rpm[l], r->out.meter_duty[l], MOTOR_RPM_FULL, MOTOR_TAU_S, dt);
        r->meter_pos[l] += 0.5 * (r->meter_rpm[l] + m) / 60.0 * r->p.meter_counts_per_rev * dt;
        r->meter_rpm[l] = m;
        const double fr = r->fan_broken[l] ? 0.0 : first_order(r->fan_rpm[l], r->out.fan_duty[l], FAN_RPM_FULL, FAN_TAU_S, dt);
        r->fan_pos[l] += 0.5 * (r->fan_rpm[l] + fr) / 60.0 * r->p.fan_ppr * dt;
        r->fan_rpm[l] = fr;
    }
    r->wheel_pos += r->wheel_kmh / 3.6 / (2.0 * PI_D * r->p.wheel_radius_m) * r->p.wheel_ppr * dt;
    r->now_us += r->step_us;
}

static inline void rig_run_ms(rig_t *r, uint32_t ms) {
    const uint32_t steps = ms * 1000u / r->step_us;
    for (uint32_t i = 0; i < steps; i++) {
        rig_step(r);
        (void)rig_drain(r, 0u);
    }
}

static inline const td_state_t *rig_st(const rig_t *r) {
    return td_app_state(&r->app);
}

/* A machine working at 8 km/h on GNSS for 6 s: GNSS 8.0, the wheel 7 % under by slip. */
static inline void rig_start_working(rig_t *r, const td_params_t *p, uint32_t t0_us) {
    rig_start(r, p, t0_us, 8.0, 8.0 * 0.93);
    rig_run_ms(r, 6000);
}

#endif /* TD_TEST_H */
