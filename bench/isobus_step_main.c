/* Host bench of the control step with the ISOBUS node beside it (bench/isobus_bench.py builds
 * and runs it): per 10 ms period the port's work of the FW_ISOBUS build in one process: the
 * period's received frames to the node (and the terminal's private frames through it to the
 * core), the TC's rates as the core's command, the core's step (td_app_step) on a simple plant,
 * the core's frames on their proprietary PGNs, the node's step and its frames drained. Run
 * twice for 6000 periods: no traffic but the TC's status (idle), and 30 % bus load (250
 * kbit/s, ~555 frames/s of ~135 bits: set values with acknowledge from the TC, its status,
 * PcGnssTime on Proprietary B, other nodes' broadcasts). Prints per period: mean, sd, p99,
 * max in microseconds of the step's time; the difference of the two is what ISOBUS traffic
 * adds to the step (its jitter). */
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "td_app.h"
#include "td_can.h"
#include "isob_bench.h"
#include "td_isob.h"

#define PERIODS 6000u
#define DT_S 0.01f

static td_app_t app;
static td_isob_t node;
static double cost[PERIODS];

static void rx(const td_can_frame_t *f, uint32_t now) {
    td_can_frame_t core;
    (void)td_isob_rx(&node, f, now);
    if (td_isob_prop_rx(&node, f, &core) == 1) {
        (void)td_app_rx(&app, &core, now);
    }
}

static void command(uint32_t now) {
    const float share = (float)__builtin_popcount(td_tc_sections_on(&node.tc)) / 6.0f;
    const float upper = (float)td_tc_rate_mg_m2(&node.tc, 0u) / 100.0f * share;
    const float lower = (float)td_tc_rate_mg_m2(&node.tc, 1u) / 100.0f * share;
    const struct td_can_pc_command_t c = {
        .start_stop = upper > 0.0f ? 0x0Au : 0x00u,
        .fan_speed = td_can_pc_command_fan_speed_encode(3000.0f),
        .upper_rate = td_can_pc_command_upper_rate_encode(upper),
        .lower_rate = td_can_pc_command_lower_rate_encode(lower),
        .gnss_speed = td_can_pc_command_gnss_speed_encode(7.0f),
    };
    td_can_frame_t f = { .id = app.p.command_id, .extended = 1u, .dlc = 8u };
    (void)td_can_pc_command_pack(f.data, &c, sizeof f.data);
    (void)td_app_rx(&app, &f, now);
}

static void run(int load, const char *name) {
    const uint8_t st[8] = {0xFE, 0xFF, 0xFF, 0xFF, 1, 0xFF, 0, 0xFF};
    uint8_t act[8] = {0x91, 0, 0xFF, 0xFF, 0xFF, 0xFF, 0, 0xFF};
    td_params_t p;
    td_io_out_t out = {{0.0f, 0.0f}, {0.0f, 0.0f}};
    double wheel = 0.0, meter[2] = {0.0, 0.0}, fan[2] = {0.0, 0.0};
    float meter_rpm[2] = {0.0f, 0.0f}, fan_rpm[2] = {0.0f, 0.0f};
    uint32_t now = 1000u, k, acc = 0u;
    double sum = 0.0, sq = 0.0;
    td_can_frame_t f;
    td_params_default(&p);
    (void)td_app_init(&app, &p, now);
    td_isob_init(&node, 0xA00A820000012345ull, 0x84u, 0x80u, 0x87u, 3500000u);
    td_isob_start(&node, now);
    now += 300000u;
    td_isob_step(&node, now, 0u);
    f = fr(3u, 0xCB00u, 0xFFu, 0xF7u, st);
    rx(&f, now);
    node.tc.state = TD_TC_ACTIVATE; /* the handshake is not what is measured */
    f = fr(5u, 0xCB00u, 0x84u, 0xF7u, act);
    rx(&f, now);
    {   /* the TC sets 150 kg/ha on the upper bin and the boom's work state on (manual
         * section control: every section follows it) */
        uint8_t d[8] = {0x0Au | (3u << 4), 0, 6, 0, 0, 0, 0, 0};
        const uint8_t w[8] = {0x0Au | (2u << 4), 0, 0x21, 0x01, 1, 0, 0, 0};
        td_ib_put_u32(&d[4], 15000u);
        f = fr(5u, 0xCB00u, 0x84u, 0xF7u, d);
        rx(&f, now);
        f = fr(5u, 0xCB00u, 0x84u, 0xF7u, w);
        rx(&f, now);
    }
    while (td_isob_tx(&node, &f)) {
    }
    for (k = 0u; k < PERIODS; k++) {
        const unsigned frames = load ? 5u + ((acc += 555u) % 1000u < 555u ? 1u : 0u) : 0u;
        unsigned i;
        double t0, t1;
        now += 10000u;
        /* the plant over the period under the last duties: 7 km/h, a simple motor */
        wheel += 7.0 / 3.6 * DT_S / (2.0 * 3.14159265 * (double)p.wheel_radius_m) * p.wheel_ppr;
        for (i = 0u; i < 2u; i++) {
            meter_rpm[i] += (60.0f * out.meter_duty[i] - meter_rpm[i]) * DT_S / 0.15f;
            fan_rpm[i] += (4000.0f * out.fan_duty[i] - fan_rpm[i]) * DT_S / 0.5f;
            meter[i] += (double)(meter_rpm[i] / 60.0f * DT_S * (float)p.meter_counts_per_rev);
            fan[i] += (double)(fan_rpm[i] / 60.0f * DT_S * (float)p.fan_ppr);
        }
        const td_io_in_t in = {(uint32_t)wheel, {(uint32_t)meter[0], (uint32_t)meter[1]},
                               {(uint32_t)fan[0], (uint32_t)fan[1]}, now, 1u};
        t0 = now_s();
        if (k % 200u == 0u) {
            f = fr(3u, 0xCB00u, 0xFFu, 0xF7u, st); /* the TC's status every 2 s */
            rx(&f, now);
        }
        for (i = 0u; i < frames; i++) {
            uint8_t d[8] = {0x0Au | (3u << 4), 0, 6, 0, 0, 0, 0, 0};
            td_ib_put_u32(&d[4], 15000u + (k % 50u));
            if (i % 4u == 0u) {
                f = fr(5u, 0xCB00u, 0x84u, 0xF7u, d); /* set value and acknowledge: a rate */
            } else if (i % 4u == 1u) {
                f = fr(3u, 0xCB00u, 0xFFu, 0xF7u, st);
            } else if (i % 4u == 2u) {
                const uint8_t g[8] = {0xBC, 0x02, 0, 0, (uint8_t)k, 0xFF, 0xFF, 0xFF};
                f = fr(2u, 0xFF62u, 0xFFu, 0xF7u, g); /* PcGnssTime, Proprietary B */
            } else {
                f = fr(6u, 0xFEF1u, 0xFFu, 0x20u, d); /* another node's broadcast */
            }
            rx(&f, now);
        }
        command(now);
        (void)td_app_step(&app, now, &in, &out);
        while (td_app_tx_pop(&app, &f)) {
            td_can_frame_t b;
            (void)td_isob_prop_tx(&node, &f, &b);
        }
        td_tc_set_actual(&node.tc, 3u, 7u, (int32_t)(15000u + k % 300u));
        td_isob_step(&node, now, k * 19u);
        while (td_isob_tx(&node, &f)) {
        }
        t1 = now_s();
        cost[k] = (t1 - t0) * 1e6;
        sum += cost[k];
        sq += cost[k] * cost[k];
    }
    {
        const double mean = sum / PERIODS;
        qsort(cost, PERIODS, sizeof cost[0], cmp);
        printf("isobus_step_host_%s_mean_us: %.2f\n", name, mean);
        printf("isobus_step_host_%s_sd_us: %.2f\n", name, sqrt(sq / PERIODS - mean * mean));
        printf("isobus_step_host_%s_p99_us: %.2f\n", name, cost[PERIODS * 99u / 100u]);
        printf("isobus_step_host_%s_max_us: %.2f\n", name, cost[PERIODS - 1u]);
        fprintf(stderr, "isobus_step %s: running %d, meter %.1f rpm, TC values set %u, "
                        "private frames taken %u\n", name, (int)app.st.running,
                (double)app.st.meter_rpm[0], (unsigned)node.tc.values_set, (unsigned)node.prop_rx);
    }
}

int main(void) {
    run(0, "idle");
    run(1, "load30");
    return 0;
}
