/* What the ISOBUS benches' host programs (isobus_main.c, isobus_step_main.c) share: the
 * monotonic clock, a frame of a PGN between two addresses, the order of a sort. */
#ifndef ISOB_BENCH_H
#define ISOB_BENCH_H

#include <string.h>
#include <time.h>

#include "td_isob.h"

static double now_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static td_can_frame_t fr(uint8_t prio, uint32_t pgn, uint8_t da, uint8_t sa, const uint8_t d[8]) {
    td_can_frame_t f;
    f.id = td_ib_id_pack(prio, pgn, da, sa);
    f.extended = 1u;
    f.dlc = 8u;
    memcpy(f.data, d, 8u);
    return f;
}

static int cmp(const void *a, const void *b) {
    const double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

#endif
