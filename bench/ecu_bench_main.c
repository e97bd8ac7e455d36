/**
 * @file ecu_bench_main.c
 * @brief Host driver for the instruction count benchmark (bench/ecu_bench.py runs it under
 *        callgrind, collecting only inside td_app_step, td_app_rx and td_app_tx_pop).
 *
 * The ECU is the port's one td_app_t; a small plant closes the loop: the tractor (ground wheel
 * with 5 % slip, its last pulse's time from a capture timer), two metering motors (full duty =
 * 60 r/min, tau 0.15 s, 6400 counts/rev) and two fans (full duty = 4000 rpm, tau 0.5 s, 30
 * pulses/rev). The PC command goes in every 500 ms; all frames are drained after every step.
 *
 * Usage: ecu_bench [steps] [speed_mode] [drive] (default 20000 steps of 10 ms, mode 0, drive 0).
 * - drive 0: 5 km/h throughout; PcGnssTime (250 ms old) with every command. Prints
 *   "steps N frames M meter_rpm X Y".
 * - drive 1: launches and brakes, repeated every 20 s: 2 s standing, 0 -> 8 km/h in 4 s, 6 s at
 *   8 km/h, 8 -> 0 km/h in 3 s, 5 s standing. The receiver's speed lags the truth by 0.3 s and a
 *   1.0 s first-order velocity filter (the simulated receiver of docs/speed.md, 1.3 s), and a fix
 *   goes in every 100 ms as the terminal sends it: PcGnssTime at once (age 0, its seq counting),
 *   the command every 500 ms carrying the last fix's speed. The control period that takes a fix
 *   (its PcGnssTime received, the step, the frames drained) runs in change_fix_period() while the
 *   speed changes (launch, brake) and in steady_fix_period() otherwise, so that callgrind can
 *   dump each one's cost (--dump-before/--dump-after). Prints "steps N frames M fixes_change F
 *   lag_learned_ms L lag_evidence_s E".
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include "td_app.h"

#define STEP_US 10000u
#define DT_S 0.01f
#define CYCLE_STEPS 2000ul     /* drive 1: one launch and brake, 20 s */
#define GNSS_DELAY_STEPS 30u   /* drive 1: the receiver's latency, 0.3 s */
#define GNSS_TAU_S 1.0f        /* drive 1: its velocity filter's time constant */
#define GNSS_EVERY 10ul        /* drive 1: a fix every 100 ms */
#define CMD_EVERY 50ul         /* a command every 500 ms */

static td_app_t app;

/** The plant and what the PC knows, advanced one period at a time. */
typedef struct {
    const td_params_t *p;
    uint32_t now;
    double wheel;              /* pulses, fractional */
    uint32_t edge_us;          /* the last whole pulse's time (drive 1) */
    double meter[2], fan[2];
    float meter_rpm[2], fan_rpm[2];
    td_io_out_t out;
    unsigned long frames;
    unsigned long fixes_change; /* drive 1: fixes taken while the speed changes */
} plant_t;

static void rx_command(plant_t *s, bool gnss_valid, float gnss_kmh) {
    const td_command_t c = { true, 3000.0f, { 200.0f, 150.0f }, gnss_valid, gnss_kmh };
    td_can_frame_t f;
    (void)td_proto_encode_command(&c, &f);
    (void)td_app_rx(&app, &f, s->now);
}

static void rx_gnss_time(plant_t *s, float kmh, uint16_t age_ms, uint8_t seq) {
    const td_gnss_time_t g = { true, kmh, age_ms, seq };
    td_can_frame_t f;
    (void)td_proto_encode_gnss_time(&g, &f);
    (void)td_app_rx(&app, &f, s->now);
}

/* The motors and fans over one period under the last duties. */
static void drive_motors(plant_t *s) {
    for (unsigned l = 0u; l < 2u; l++) {
        s->meter_rpm[l] += (60.0f * s->out.meter_duty[l] - s->meter_rpm[l]) * DT_S / 0.15f;
        s->fan_rpm[l] += (4000.0f * s->out.fan_duty[l] - s->fan_rpm[l]) * DT_S / 0.5f;
        s->meter[l] += (double)(s->meter_rpm[l] / 60.0f * DT_S * (float)s->p->meter_counts_per_rev);
        s->fan[l] += (double)(s->fan_rpm[l] / 60.0f * DT_S * (float)s->p->fan_ppr);
    }
}

static void step_and_drain(plant_t *s, uint32_t edge_us) {
    const td_io_in_t in = { (uint32_t)s->wheel,
                            { (uint32_t)s->meter[0], (uint32_t)s->meter[1] },
                            { (uint32_t)s->fan[0], (uint32_t)s->fan[1] },
                            edge_us,
                            1u };
    (void)td_app_step(&app, s->now, &in, &s->out);
    td_can_frame_t tx;
    while (td_app_tx_pop(&app, &tx)) {
        s->frames++;
    }
}

static int drive_constant(const td_params_t *p, unsigned long steps) {
    plant_t s = { p, 0u, 0.0, 0u, { 0.0, 0.0 }, { 0.0, 0.0 }, { 0.0f, 0.0f }, { 0.0f, 0.0f },
                  { { 0.0f, 0.0f }, { 0.0f, 0.0f } }, 0ul, 0ul };
    const float v_kmh = 5.0f;
    const float wheel_pulses_per_s = v_kmh / 3.6f / (6.28318531f * p->wheel_radius_m) * (float)p->wheel_ppr * 0.95f;
    for (unsigned long i = 0ul; i < steps; i++) {
        if (i % CMD_EVERY == 0ul) {
            rx_command(&s, true, v_kmh);
            rx_gnss_time(&s, v_kmh, 250u, (uint8_t)(i / CMD_EVERY));
        }
        s.now += STEP_US;
        s.wheel += (double)(wheel_pulses_per_s * DT_S);
        drive_motors(&s);
        /* the last pulse came frac(wheel) pulses ago */
        const double back_us = (s.wheel - floor(s.wheel)) / (double)wheel_pulses_per_s * 1e6;
        step_and_drain(&s, s.now - (uint32_t)back_us);
    }
    printf("steps %lu frames %lu meter_rpm %.2f %.2f\n", steps, s.frames, (double)app.st.meter_rpm[0],
           (double)app.st.meter_rpm[1]);
    return 0;
}

/* Drive 1's true ground speed (km/h) at step k, and whether it is changing there. */
static float launch_brake_kmh(unsigned long k, bool *changing) {
    const float t = (float)(k % CYCLE_STEPS) * DT_S;
    *changing = (t >= 2.0f && t < 6.0f) || (t >= 12.0f && t < 15.0f);
    if (t < 2.0f || t >= 15.0f) {
        return 0.0f;
    }
    if (t < 6.0f) {
        return 8.0f * (t - 2.0f) / 4.0f;
    }
    return t < 12.0f ? 8.0f : 8.0f * (15.0f - t) / 3.0f;
}

/* One control period of drive 1: the PC's frames, the plant, the step, the frames drained. */
static void period(plant_t *s, unsigned long i, float v_kmh, float gnss_kmh, uint8_t seq, bool fix) {
    if (i % CMD_EVERY == 0ul) {
        rx_command(s, true, gnss_kmh);
    }
    if (fix) {
        rx_gnss_time(s, gnss_kmh, 0u, seq);
    }
    s->now += STEP_US;
    const double before = s->wheel;
    const float pulses_per_s = v_kmh / 3.6f / (6.28318531f * s->p->wheel_radius_m) * (float)s->p->wheel_ppr * 0.95f;
    s->wheel += (double)(pulses_per_s * DT_S);
    if (floor(s->wheel) > floor(before)) { /* a pulse in this period: when, at the rate in it */
        const double frac = (floor(s->wheel) - before) / (s->wheel - before);
        s->edge_us = s->now - STEP_US + (uint32_t)(frac * (double)STEP_US);
    }
    drive_motors(s);
    step_and_drain(s, s->edge_us);
}

/* The periods that take a fix, apart so that callgrind dumps each one's cost (bodies that differ:
 * gcc would fold identical ones into one symbol). */
__attribute__((noinline)) static void change_fix_period(plant_t *s, unsigned long i, float v, float g, uint8_t seq) {
    s->fixes_change++;
    period(s, i, v, g, seq, true);
}

__attribute__((noinline)) static void steady_fix_period(plant_t *s, unsigned long i, float v, float g, uint8_t seq) {
    period(s, i, v, g, seq, true);
}

static int drive_launch_brake(const td_params_t *p, unsigned long steps) {
    plant_t s = { p, 0u, 0.0, 0u, { 0.0, 0.0 }, { 0.0, 0.0 }, { 0.0f, 0.0f }, { 0.0f, 0.0f },
                  { { 0.0f, 0.0f }, { 0.0f, 0.0f } }, 0ul, 0ul };
    float past[GNSS_DELAY_STEPS] = { 0.0f };  /* the true speed over the receiver's latency */
    float gnss_kmh = 0.0f;                    /* its filtered speed */
    uint8_t seq = 0u;
    for (unsigned long i = 0ul; i < steps; i++) {
        bool changing = false;
        const float v_kmh = launch_brake_kmh(i, &changing);
        const float delayed = past[i % GNSS_DELAY_STEPS];
        past[i % GNSS_DELAY_STEPS] = v_kmh;
        gnss_kmh += (delayed - gnss_kmh) * DT_S / GNSS_TAU_S;
        if (i % GNSS_EVERY != 0ul) {
            period(&s, i, v_kmh, gnss_kmh, seq, false);
        } else if (changing) {
            change_fix_period(&s, i, v_kmh, gnss_kmh, ++seq);
        } else {
            steady_fix_period(&s, i, v_kmh, gnss_kmh, ++seq);
        }
    }
    printf("steps %lu frames %lu fixes_change %lu lag_learned_ms %u lag_evidence_s %.1f\n", steps, s.frames,
           s.fixes_change, (unsigned)app.st.lag_learned_ms, (double)app.st.lag_evidence_s);
    return 0;
}

int main(int argc, char **argv) {
    const unsigned long steps = argc > 1 ? strtoul(argv[1], NULL, 10) : 20000ul;
    const unsigned long drive = argc > 3 ? strtoul(argv[3], NULL, 10) : 0ul;
    td_params_t p;
    td_params_default(&p);
    p.speed_mode = argc > 2 ? (uint8_t)strtoul(argv[2], NULL, 10) : 0u;
    if (td_app_init(&app, &p, 0u) != TD_OK) {
        return 1;
    }
    return drive == 1ul ? drive_launch_brake(&p, steps) : drive_constant(&p, steps);
}
