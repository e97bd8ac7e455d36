/* libFuzzer target of the ISOBUS receive path (cmake -DTD_FUZZ=ON, clang): the input is a
 * sequence of 14-byte records (4 id, 1 flags, 1 dlc, 8 data), each fed to td_isob_rx; a flags
 * bit 7 runs a step 10 ms later first. The node starts claimed and connected to a TC at 0xF7 so
 * the fuzzer reaches the process-data path without guessing the connection first. */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "td_isob.h"

static void feed(td_isob_t *n, uint32_t pgn, uint8_t sa, uint8_t da, const uint8_t d[8],
                 uint32_t now) {
    td_can_frame_t f;
    f.id = td_ib_id_pack(5u, pgn, da, sa);
    f.extended = 1u;
    f.dlc = 8u;
    memcpy(f.data, d, 8u);
    (void)td_isob_rx(n, &f, now);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    static td_isob_t n; /* test harness only: the node itself keeps no globals */
    static const uint8_t st[8] = {0xFE, 0xFF, 0xFF, 0xFF, 0x01, 0xFF, 0x00, 0xFF};
    uint8_t act[8] = {0x91, 0x00, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF};
    uint32_t now = 1000u;
    td_can_frame_t f;
    size_t i;
    td_isob_init(&n, 0xA00A820000012345ull, 0x84u, 0x80u, 0x87u, 1000000u);
    td_isob_start(&n, now);
    now += 300000u;
    td_isob_step(&n, now, 0u);
    feed(&n, TD_IB_PGN_PROCESS_DATA, 0xF7u, 0xFFu, st, now);
    n.tc.state = TD_TC_ACTIVATE; /* skip the handshake: answer the activation directly */
    feed(&n, TD_IB_PGN_PROCESS_DATA, 0xF7u, 0x84u, act, now);
    for (i = 0u; i + 14u <= size; i += 14u) {
        const uint8_t *r = &data[i];
        f.id = ((uint32_t)r[0] | ((uint32_t)r[1] << 8) | ((uint32_t)r[2] << 16) |
                ((uint32_t)r[3] << 24)) & 0x1FFFFFFFu;
        f.extended = (uint8_t)(r[4] & 1u);
        f.dlc = (uint8_t)(r[5] & 0x0Fu);
        memcpy(f.data, &r[6], 8u);
        if ((r[4] & 0x80u) != 0u) {
            now += 10000u;
            td_isob_step(&n, now, now / 100u);
        }
        (void)td_isob_rx(&n, &f, now);
        {
            td_can_frame_t core;
            (void)td_isob_prop_rx(&n, &f, &core);
        }
        while (td_isob_tx(&n, &f)) {
        }
    }
    return 0;
}
