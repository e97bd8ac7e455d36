/**
 * @file ecu_bench_main.c
 * @brief Host driver for the instruction count benchmark (bench/ecu_bench.py runs it under
 *        callgrind, collecting only inside td_app_step, td_app_rx and td_app_tx_pop).
 *
 * The ECU is the port's one td_app_t; a small plant closes the loop: the tractor at 5 km/h
 * (ground wheel with 5 % slip, its last pulse's time from a capture timer), two metering motors (full duty = 60 r/min, tau 0.15 s,
 * 6400 counts/rev) and two fans (full duty = 4000 rpm, tau 0.5 s, 30 pulses/rev). The PC
 * command goes in every 500 ms; all frames are drained after every step.
 * The PC also sends PcGnssTime with every command. Usage: ecu_bench [steps] [speed_mode]
 * (default 20000 steps of 10 ms, mode 0). Prints "steps N frames M meter_rpm X Y".
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include "td_app.h"

#define STEP_US 10000u
#define DT_S 0.01f

static td_app_t app;

int main(int argc, char **argv) {
    const unsigned long steps = argc > 1 ? strtoul(argv[1], NULL, 10) : 20000ul;
    td_params_t p;
    td_params_default(&p);
    p.speed_mode = argc > 2 ? (uint8_t)strtoul(argv[2], NULL, 10) : 0u;
    if (td_app_init(&app, &p, 0u) != TD_OK) {
        return 1;
    }
    const float v_kmh = 5.0f;
    const float wheel_pulses_per_s = v_kmh / 3.6f / (6.28318531f * p.wheel_radius_m) * (float)p.wheel_ppr * 0.95f;
    double wheel = 0.0, meter[2] = { 0.0, 0.0 }, fan[2] = { 0.0, 0.0 };
    float meter_rpm[2] = { 0.0f, 0.0f }, fan_rpm[2] = { 0.0f, 0.0f };
    td_io_out_t out = { { 0.0f, 0.0f }, { 0.0f, 0.0f } };
    unsigned long frames = 0ul;
    uint32_t now = 0u;
    for (unsigned long i = 0ul; i < steps; i++) {
        if (i % 50ul == 0ul) {
            const td_command_t c = { true, 3000.0f, { 200.0f, 150.0f }, true, v_kmh };
            td_can_frame_t f;
            (void)td_proto_encode_command(&c, &f);
            (void)td_app_rx(&app, &f, now);
            const td_gnss_time_t g = { true, v_kmh, 250u, (uint8_t)(i / 50ul) };
            (void)td_proto_encode_gnss_time(&g, &f);
            (void)td_app_rx(&app, &f, now);
        }
        now += STEP_US;
        wheel += (double)(wheel_pulses_per_s * DT_S);
        for (unsigned l = 0u; l < 2u; l++) {
            meter_rpm[l] += (60.0f * out.meter_duty[l] - meter_rpm[l]) * DT_S / 0.15f;
            fan_rpm[l] += (4000.0f * out.fan_duty[l] - fan_rpm[l]) * DT_S / 0.5f;
            meter[l] += (double)(meter_rpm[l] / 60.0f * DT_S * (float)p.meter_counts_per_rev);
            fan[l] += (double)(fan_rpm[l] / 60.0f * DT_S * (float)p.fan_ppr);
        }
        /* the last pulse came frac(wheel) pulses ago */
        const double back_us = (wheel - floor(wheel)) / (double)wheel_pulses_per_s * 1e6;
        const td_io_in_t in = { (uint32_t)wheel,
                                { (uint32_t)meter[0], (uint32_t)meter[1] },
                                { (uint32_t)fan[0], (uint32_t)fan[1] },
                                now - (uint32_t)back_us,
                                1u };
        (void)td_app_step(&app, now, &in, &out);
        td_can_frame_t tx;
        while (td_app_tx_pop(&app, &tx)) {
            frames++;
        }
    }
    printf("steps %lu frames %lu meter_rpm %.2f %.2f\n", steps, frames, (double)app.st.meter_rpm[0],
           (double)app.st.meter_rpm[1]);
    return 0;
}
