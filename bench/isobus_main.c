/* Host bench of the ISOBUS node (bench/isobus_bench.py builds and runs it): a connected node
 * under 30 % bus load (250 kbit/s, 29-bit 8-byte frames of ~135 bits: ~555 frames/s, 5-6 per
 * 10 ms period: process data from the TC to us and to all, other nodes' frames) for 60 s of
 * virtual time; prints the time the ISOBUS work (receive of the period's frames + step + drain)
 * takes per 10 ms period: mean, p99, max in microseconds, and the state size. */
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "isob_bench.h"
#include "td_isob.h"

#define PERIODS 6000u

int main(void) {
    static td_isob_t n;
    static double cost[PERIODS];
    td_can_frame_t f;
    const uint8_t st[8] = {0xFE, 0xFF, 0xFF, 0xFF, 1, 0xFF, 0, 0xFF};
    uint8_t act[8] = {0x91, 0, 0xFF, 0xFF, 0xFF, 0xFF, 0, 0xFF};
    uint32_t now = 1000u, k, acc = 0u;
    double sum = 0.0;
    td_isob_init(&n, 0xA00A820000012345ull, 0x84u, 0x80u, 0x87u, 3500000u);
    td_isob_start(&n, now);
    now += 300000u;
    td_isob_step(&n, now, 0u);
    f = fr(3u, 0xCB00u, 0xFFu, 0xF7u, st);
    td_isob_rx(&n, &f, now);
    n.tc.state = TD_TC_ACTIVATE; /* the handshake is not what is measured */
    f = fr(5u, 0xCB00u, 0x84u, 0xF7u, act);
    td_isob_rx(&n, &f, now);
    while (td_isob_tx(&n, &f)) {
    }
    for (k = 0u; k < PERIODS; k++) {
        const unsigned frames = 5u + ((acc += 555u) % 1000u < 555u ? 1u : 0u);
        unsigned i;
        double t0, t1;
        now += 10000u;
        t0 = now_s();
        for (i = 0u; i < frames; i++) {
            uint8_t d[8] = {0x0A | (3u << 4), 0, 6, 0, 0, 0, 0, 0};
            td_ib_put_u32(&d[4], 10000u + (k % 5000u));
            if (i % 3u == 0u) {
                f = fr(5u, 0xCB00u, 0x84u, 0xF7u, d); /* set value and acknowledge: a rate */
            } else if (i % 3u == 1u) {
                f = fr(3u, 0xCB00u, 0xFFu, 0xF7u, st);
            } else {
                f = fr(6u, 0xFEF1u, 0xFFu, 0x20u, d); /* another node's broadcast */
            }
            td_isob_rx(&n, &f, now);
        }
        td_tc_set_actual(&n.tc, 3u, 7u, (int32_t)(10000u + k % 300u));
        td_isob_step(&n, now, k * 19u);
        while (td_isob_tx(&n, &f)) {
        }
        t1 = now_s();
        cost[k] = (t1 - t0) * 1e6;
        sum += cost[k];
    }
    qsort(cost, PERIODS, sizeof cost[0], cmp);
    printf("isobus_host_state_bytes: %zu\n", sizeof n);
    printf("isobus_host_period_mean_us: %.2f\n", sum / PERIODS);
    printf("isobus_host_period_p99_us: %.2f\n", cost[PERIODS * 99u / 100u]);
    printf("isobus_host_period_max_us: %.2f\n", cost[PERIODS - 1u]);
    printf("isobus_host_connected: %d\n", n.tc.state == TD_TC_CONNECTED);
    printf("isobus_host_values_set: %u\n", (unsigned)n.tc.values_set);
    return 0;
}
