/* Deterministic randomized robustness test of the ISOBUS receive path: 300,000 frames (address
 * claims, requests, TP/ETP control and data, process data of every command, language, random
 * ids, DLC 0..15) from a scripted TC and random peers, interleaved with steps at jittered times,
 * on a fixed seed. After every call: the node never sets a rate above the pool's maximum, never
 * reports sections it does not have, never queues more than its queue holds, and a node
 * without an address sends nothing but claims. Runs under ASan and UBSan too. */
#include "ib_test.h"

#include "td_isob.h"

#define FRAMES 300000u
#define SEED 0x150B05u

typedef struct {
    uint64_t s;
} rng_t;

static uint32_t rnd(rng_t *g) {
    g->s ^= g->s >> 12;
    g->s ^= g->s << 25;
    g->s ^= g->s >> 27;
    return (uint32_t)((g->s * 0x2545F4914F6CDD1DULL) >> 32);
}

static const uint32_t PGNS[] = {TD_IB_PGN_ADDRESS_CLAIM, TD_IB_PGN_REQUEST, TD_IB_PGN_TP_CM,
                                TD_IB_PGN_TP_DT, TD_IB_PGN_ETP_CM, TD_IB_PGN_ETP_DT,
                                TD_IB_PGN_PROCESS_DATA, TD_IB_PGN_LANGUAGE, 0xFECAu, 0xEF00u,
                                0x1EF00u, 0xFF62u};

static td_can_frame_t random_frame(rng_t *g, uint8_t my) {
    td_can_frame_t f;
    uint32_t pick = rnd(g) % 16u;
    unsigned i;
    const uint8_t sa = (rnd(g) % 4u == 0u) ? (uint8_t)rnd(g) : 0xF7u;
    const uint8_t da = (rnd(g) % 3u == 0u) ? 0xFFu : my;
    memset(&f, 0, sizeof f);
    f.extended = (uint8_t)(rnd(g) % 20u != 0u);
    f.dlc = (uint8_t)(rnd(g) % 10u == 0u ? rnd(g) % 16u : 8u);
    for (i = 0u; i < 8u; i++) {
        f.data[i] = (uint8_t)rnd(g);
    }
    if (pick == 0u && rnd(g) % 50u != 0u) {
        pick = 6u; /* address claims rare: a lost contest silences the node for good */
    }
    if (pick < 10u) {
        f.id = td_ib_id_pack((uint8_t)(rnd(g) % 8u), PGNS[pick], da, sa);
        if (PGNS[pick] == TD_IB_PGN_PROCESS_DATA && rnd(g) % 2u == 0u) {
            static const uint16_t ddis[] = {6u, 7u, 160u, 289u, 290u, 116u, 0xDFFFu};
            const uint16_t ddi = ddis[rnd(g) % 7u];
            f.data[0] = (uint8_t)(((rnd(g) % 12u) << 4) | (rnd(g) % 16u));
            f.data[1] = 0u;
            f.data[2] = (uint8_t)(ddi & 0xFFu);
            f.data[3] = (uint8_t)(ddi >> 8);
        }
        if (PGNS[pick] == TD_IB_PGN_TP_CM || PGNS[pick] == TD_IB_PGN_ETP_CM) {
            const uint8_t ctl[] = {16, 17, 19, 32, 20, 21, 22, 23, 255};
            f.data[0] = ctl[rnd(g) % sizeof ctl];
            td_ib_put_u24(&f.data[5], rnd(g) % 2u ? TD_IB_PGN_PROCESS_DATA : rnd(g) & 0x3FFFFu);
        }
        if (PGNS[pick] == TD_IB_PGN_TP_DT || PGNS[pick] == TD_IB_PGN_ETP_DT) {
            f.data[0] = (uint8_t)(1u + rnd(g) % 20u);
        }
    } else {
        f.id = rnd(g) & (f.extended ? 0x1FFFFFFFu : 0x7FFu);
    }
    return f;
}

/* A TC that answers the node's requests correctly (it holds the pool already), so the random
 * traffic also reaches a connected node. Returns true and the answer in *a. */
static bool tc_answer(const td_can_frame_t *f, td_can_frame_t *a) {
    const td_ib_id_t id = td_ib_id_unpack(f->id);
    uint8_t d[8];
    memset(d, 0xFF, sizeof d);
    if (id.pgn == TD_IB_PGN_REQUEST && td_ib_get_u24(f->data) == TD_IB_PGN_LANGUAGE) {
        d[0] = 'e';
        d[1] = 'n';
        *a = ib_frame(6u, TD_IB_PGN_LANGUAGE, 0xFFu, 0xF7u, d);
        return true;
    }
    if (id.pgn != TD_IB_PGN_PROCESS_DATA) {
        return false;
    }
    switch (f->data[0]) {
    case 0x00:
        d[0] = 0x10;
        d[1] = 4;
        break;
    case 0x01:
        d[0] = 0x11;
        memcpy(&d[1], td_ddop_structure_label, 7u);
        break;
    case 0x21: {
        const uint8_t loc[7] = {'e', 'n', 0x50, 0x00, 0x00, 0x00, 0xFF};
        d[0] = 0x31;
        memcpy(&d[1], loc, 7u);
        break;
    }
    case 0x81:
        d[0] = 0x91;
        d[1] = 0;
        break;
    default:
        return false;
    }
    *a = ib_frame(5u, TD_IB_PGN_PROCESS_DATA, id.sa, 0xF7u, d);
    return true;
}

static void check(const td_isob_t *n) {
    assert_true(n->q.count <= TD_IB_TXQ_LEN);
    assert_true(td_tc_rate_mg_m2(&n->tc, 0u) <= TD_DDOP_RATE_MAX_MG_M2);
    assert_true(td_tc_rate_mg_m2(&n->tc, 1u) >= TD_DDOP_RATE_MIN_MG_M2);
    assert_true((td_tc_sections_on(&n->tc) >> TD_DDOP_SECTIONS) == 0u);
    if (n->tc.state != TD_TC_CONNECTED) {
        assert_int_equal(td_tc_rate_mg_m2(&n->tc, 0u), 0);
        assert_int_equal(td_tc_sections_on(&n->tc), 0u);
    }
}

static void test_receive_path_survives_random_traffic(void **s) {
    static td_isob_t n;
    rng_t g = {SEED};
    uint32_t now = 0xFFF00000u; /* wraps during the run */
    uint32_t dist = 0u;
    unsigned i, sent = 0u, claims_only = 0u, answers = 0u, restarts = 0u;
    td_can_frame_t f, answer[TD_IB_TXQ_LEN];
    (void)s;
    assert_int_equal(td_isob_init(&n, 0xA00A820000012345ull, 0x84u, 0x80u, 0x87u, 1000000u),
                     TD_IB_OK);
    td_isob_start(&n, now);
    for (i = 0u; i < FRAMES; i++) {
        const uint8_t my = n.claim.address;
        f = random_frame(&g, my == TD_IB_ADDR_NULL ? 0x84u : my);
        (void)td_isob_rx(&n, &f, now);
        {
            td_can_frame_t core;
            const int rc = td_isob_prop_rx(&n, &f, &core);
            assert_true(rc == 0 || rc == 1 || rc == TD_IB_E_SOURCE);
            assert_true(rc != 1 || (core.dlc == f.dlc && core.extended == 1u));
        }
        check(&n);
        if (rnd(&g) % 50u == 0u) {
            const uint8_t st[8] = {0xFE, 0xFF, 0xFF, 0xFF, 0x01, 0xFF, 0x00, 0xFF};
            f = ib_frame(3u, TD_IB_PGN_PROCESS_DATA, 0xFFu, 0xF7u, st); /* the TC's status */
            (void)td_isob_rx(&n, &f, now);
        }
        if (n.claim.state == TD_CLAIM_FAILED && rnd(&g) % 1000u == 0u) {
            td_isob_start(&n, now); /* the operator power-cycles the implement */
            restarts++;
        }
        if (rnd(&g) % 8u == 0u) {
            unsigned k = 0u, j;
            now += 10000u + (rnd(&g) % 3000u) - 1500u;
            dist += rnd(&g) % 40u;
            td_isob_step(&n, now, dist);
            check(&n);
            while (td_isob_tx(&n, &f)) {
                const td_ib_id_t id = td_ib_id_unpack(f.id);
                sent++;
                if (td_claim_address(&n.claim) == TD_IB_ADDR_NULL) {
                    /* unclaimed: only claims, and TP answers of a session begun before */
                    claims_only += id.pgn == TD_IB_PGN_ADDRESS_CLAIM ? 1u : 0u;
                }
                assert_true(f.extended == 1u && f.dlc == 8u);
                if (k < TD_IB_TXQ_LEN && tc_answer(&f, &answer[k])) {
                    k++;
                }
            }
            for (j = 0u; j < k; j++) {
                (void)td_isob_rx(&n, &answer[j], now);
                check(&n);
                answers++;
            }
        }
    }
    print_message("frames %u, sent %u, rx errors %u, TP done %u aborts %u, TC state %d, "
                  "connects %u, pdacks %u, set %u, claims %u lost %u, answers %u, restarts %u\n",
                  FRAMES, sent, n.rx_errors, n.tp.rx_done, n.tp.rx_aborts, (int)n.tc.state,
                  n.tc.connects, n.tc.pdacks_sent, n.tc.values_set, claims_only,
                  n.claim.contests_lost, answers, restarts);
    assert_true(sent > 1000u);
    /* the connected path was reached: values set and refused */
    assert_true(n.tc.connects > 0u && n.tc.values_set > 0u && n.tc.values_refused > 0u);
    assert_true(n.rx_errors > 0u); /* the malformed frames were seen and counted */
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_receive_path_survives_random_traffic),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
