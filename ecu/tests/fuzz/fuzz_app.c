/* libFuzzer target of the ECU application: the input is a script of frames, steps and drains,
 * checked after every call against the invariants of td_invariants.h (abort on a violation).
 * Built only on request (see ecu/tests/fuzz/run.sh). */
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

#define TD_CHECK(cond)   \
    do {                 \
        if (!(cond)) {   \
            abort();     \
        }                \
    } while (0)
#include "td_invariants.h"

typedef struct {
    const uint8_t *p;
    size_t n;
} script_t;

static uint8_t take8(script_t *s) {
    if (s->n == 0u) {
        return 0u;
    }
    s->n--;
    return *s->p++;
}

static uint32_t take32(script_t *s) {
    uint32_t v = 0u;
    for (int i = 0; i < 4; i++) {
        v = (v << 8) | take8(s);
    }
    return v;
}

static void rx(td_app_t *app, script_t *s, uint32_t now) {
    static const uint32_t ids[] = { TD_ID_PC_COMMAND,  TD_ID_PC_PARAM_SET, TD_ID_ECU_STATUS,   TD_ID_ECU_DIAG,
                                    TD_ID_ECU_SPEEDS,  TD_ID_ECU_TARGETS,  TD_ID_ECU_PARAM_ACK, TD_ID_PC_GNSS_TIME,
                                    TD_ID_ECU_FUSED,   TD_ID_ECU_FUSED_AUX };
    const uint8_t sel = take8(s);
    td_can_frame_t f;
    f.id = (sel & 15u) < 10u ? ids[sel & 15u] : take32(s) & 0x1FFFFFFFu;
    f.extended = (sel & 0x80u) != 0u ? 0u : 1u;
    const uint8_t dlc = take8(s);
    f.dlc = (dlc & 0x10u) != 0u ? (uint8_t)(dlc & 0x0Fu) : 8u; /* 0..15, as the binding passes */
    for (int i = 0; i < 8; i++) {
        f.data[i] = take8(s);
    }
    static td_app_t before;
    memcpy(&before, app, sizeof before);
    const int rc = td_app_rx(app, &f, now + (uint32_t)take8(s) * 40u);
    td_inv_check_rx(&before, app, &f, rc);
}

static uint32_t step(td_app_t *app, script_t *s, uint32_t now, td_io_in_t *in) {
    const uint8_t k = take8(s);
    uint32_t dt_us = 10000u;
    if (k >= 240u) {
        dt_us = take32(s); /* anywhere: late, backwards, half the clock away */
    } else if (k >= 200u) {
        dt_us = (uint32_t)(k - 200u) * 250u; /* repeated and short */
    }
    now += dt_us;
    in->wheel_count += take8(s);
    const uint8_t e = take8(s); /* a capture timer or not, its edge somewhere in the step or wild */
    in->wheel_edge_valid = (uint8_t)(e & 1u);
    in->wheel_edge_us = (e & 2u) != 0u ? take32(s) : now - (uint32_t)(e >> 2) * 40u;
    for (int l = 0; l < 2; l++) {
        in->meter_count[l] += (uint32_t)take8(s) * 8u;
        in->fan_count[l] += (uint32_t)take8(s) * 4u;
    }
    td_io_out_t out;
    TD_CHECK(td_app_step(app, now, in, &out) == TD_OK);
    td_inv_check_step(app, &out);
    return now;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    static td_app_t app;
    script_t s = { data, size };
    td_params_t p;
    td_params_default(&p);
    uint32_t now = take32(&s);
    TD_CHECK(td_app_init(&app, &p, now) == TD_OK);
    td_io_in_t in;
    memset(&in, 0, sizeof in);
    while (s.n > 0u) {
        const uint8_t op = take8(&s) % 4u;
        if (op < 2u) {
            rx(&app, &s, now);
        } else if (op == 2u) {
            now = step(&app, &s, now, &in);
        } else {
            td_can_frame_t f;
            int n = 0;
            while (td_app_tx_pop(&app, &f)) {
                TD_CHECK(++n <= (int)TD_TXQ_LEN && f.dlc == 8u && f.extended == 1u);
            }
        }
    }
    return 0;
}
