/* NAME packing and J1939-81 address claim: contests won and lost by NAME, re-claim in the
 * fallback range, Cannot Claim, Requests answered. */
#include "ib_test.h"

#include "td_claim.h"
#include "td_ibname.h"

static const uint8_t UID[12] = {0x31, 0x00, 0x2A, 0x00, 0x0D, 0x51, 0x33, 0x38,
                                0x37, 0x39, 0x35, 0x30};

static void test_name_fields_round_trip(void **s) {
    td_ibname_t n, back;
    uint64_t v = 0u;
    (void)s;
    assert_int_equal(td_ibname_topdress(1407u, UID, sizeof UID, &n), TD_IB_OK);
    assert_int_equal(td_ibname_encode(&n, &v), TD_IB_OK);
    /* self-configurable, industry group 2, device class 5, function 128, manufacturer 1407 */
    assert_true((v >> 63) == 1u);
    assert_int_equal((v >> 60) & 7u, 2);
    assert_int_equal((v >> 49) & 127u, 5);
    assert_int_equal((v >> 40) & 0xFFu, 128);
    assert_int_equal((v >> 21) & 0x7FFu, 1407);
    assert_int_equal(v & 0x1FFFFFu, n.identity_number);
    td_ibname_decode(v, &back);
    assert_memory_equal(&n, &back, sizeof n);
}

static void test_name_known_value_and_bytes(void **s) {
    /* All fields at their maximum give all ones except the reserved bit 48. */
    td_ibname_t n = {0x1FFFFFu, 0x7FFu, 7u, 31u, 255u, 127u, 15u, 7u, 1u};
    uint64_t v = 0u;
    uint8_t b[8];
    (void)s;
    assert_int_equal(td_ibname_encode(&n, &v), TD_IB_OK);
    assert_true(v == 0xFFFEFFFFFFFFFFFFull);
    td_ibname_to_bytes(v, b);
    assert_int_equal(b[0], 0xFF);
    assert_int_equal(b[6], 0xFE);
    assert_true(td_ibname_from_bytes(b) == v);
}

static void test_name_rejects_out_of_range(void **s) {
    td_ibname_t n = {0x200000u, 1u, 0u, 0u, 0u, 0u, 0u, 2u, 1u};
    uint64_t v = 0u;
    (void)s;
    assert_int_equal(td_ibname_encode(&n, &v), TD_IB_E_ARG);
    n.identity_number = 1u;
    n.manufacturer_code = 2048u;
    assert_int_equal(td_ibname_encode(&n, &v), TD_IB_E_ARG);
    n.manufacturer_code = 1u;
    n.industry_group = 8u;
    assert_int_equal(td_ibname_encode(&n, &v), TD_IB_E_ARG);
    assert_int_equal(td_ibname_topdress(2048u, UID, sizeof UID, &n), TD_IB_E_ARG);
}

static void test_identity_differs_between_boards(void **s) {
    uint8_t other[12];
    (void)s;
    memcpy(other, UID, sizeof other);
    other[11] ^= 1u;
    assert_true(td_ibname_identity_from_uid(UID, 12u) != td_ibname_identity_from_uid(other, 12u));
    assert_true(td_ibname_identity_from_uid(UID, 12u) <= 0x1FFFFFu);
}

#define OUR_NAME 0xA00A0A0000012345ull /* self-configurable */
#define FIXED_NAME 0x200A0A0000012345ull /* same but not self-configurable */

static td_can_frame_t claim_frame(uint64_t name, uint8_t sa) {
    uint8_t d[8];
    td_ibname_to_bytes(name, d);
    return ib_frame(6u, TD_IB_PGN_ADDRESS_CLAIM, 0xFFu, sa, d);
}

static void test_claim_preferred_after_250ms(void **s) {
    td_claim_t c;
    td_ib_txq_t q;
    td_can_frame_t out[4];
    (void)s;
    td_ib_txq_init(&q);
    assert_int_equal(td_claim_init(&c, OUR_NAME, 0x84u, 0x80u, 0x87u), TD_IB_OK);
    assert_int_equal(td_claim_start(&c, 1000u, &q), TD_IB_OK);
    assert_int_equal(ib_drain(&q, out, 4u), 1);
    assert_int_equal(out[0].id, 0x18EEFF84u);
    assert_true(td_ibname_from_bytes(out[0].data) == OUR_NAME);
    td_claim_step(&c, 1000u + 249999u);
    assert_int_equal(td_claim_address(&c), TD_IB_ADDR_NULL);
    td_claim_step(&c, 1000u + 250000u);
    assert_int_equal(td_claim_address(&c), 0x84);
}

static void test_contest_won_by_lower_name(void **s) {
    td_claim_t c;
    td_ib_txq_t q;
    td_can_frame_t out[4];
    td_can_frame_t f = claim_frame(OUR_NAME + 1u, 0x84u);
    (void)s;
    td_ib_txq_init(&q);
    td_claim_init(&c, OUR_NAME, 0x84u, 0x80u, 0x87u);
    td_claim_start(&c, 0u, &q);
    td_claim_step(&c, 300000u);
    (void)ib_drain(&q, out, 4u);
    assert_int_equal(td_claim_rx(&c, &f, 400000u, &q), 1);
    assert_int_equal(ib_drain(&q, out, 4u), 1); /* our claim repeated: we keep 0x84 */
    assert_int_equal(out[0].id, 0x18EEFF84u);
    assert_int_equal(td_claim_address(&c), 0x84);
    assert_int_equal(c.contests_won, 1);
}

static void test_contest_lost_moves_to_free_fallback(void **s) {
    td_claim_t c;
    td_ib_txq_t q;
    td_can_frame_t out[4];
    td_can_frame_t other85 = claim_frame(0x1ull, 0x85u);
    td_can_frame_t winner = claim_frame(OUR_NAME - 1u, 0x84u);
    (void)s;
    td_ib_txq_init(&q);
    td_claim_init(&c, OUR_NAME, 0x84u, 0x80u, 0x87u);
    td_claim_start(&c, 0u, &q);
    assert_int_equal(td_claim_rx(&c, &other85, 10000u, &q), 1);
    td_claim_step(&c, 300000u);
    (void)ib_drain(&q, out, 4u);
    assert_int_equal(td_claim_rx(&c, &winner, 400000u, &q), 1);
    assert_int_equal(ib_drain(&q, out, 4u), 1);
    /* 0x85 is held by another NAME: the next free address after 0x84 is 0x86 */
    assert_int_equal(out[0].id, 0x18EEFF86u);
    assert_int_equal(td_claim_address(&c), TD_IB_ADDR_NULL);
    td_claim_step(&c, 650000u);
    assert_int_equal(td_claim_address(&c), 0x86);
    assert_int_equal(c.contests_lost, 1);
}

static void test_range_exhausted_cannot_claim(void **s) {
    td_claim_t c;
    td_ib_txq_t q;
    td_can_frame_t out[4];
    td_can_frame_t held = claim_frame(0x2ull, 0x81u);
    td_can_frame_t winner = claim_frame(0x1ull, 0x80u);
    td_can_frame_t req;
    const uint8_t rd[8] = {0x00, 0xEE, 0x00, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF};
    (void)s;
    td_ib_txq_init(&q);
    td_claim_init(&c, OUR_NAME, 0x80u, 0x80u, 0x81u);
    td_claim_start(&c, 0u, &q);
    td_claim_rx(&c, &held, 1000u, &q);
    td_claim_rx(&c, &winner, 2000u, &q);
    assert_int_equal(ib_drain(&q, out, 4u), 2);
    assert_int_equal(out[1].id, 0x18EEFFFEu); /* Cannot Claim: source 254 */
    assert_int_equal(c.state, TD_CLAIM_FAILED);
    td_claim_step(&c, 900000u);
    assert_int_equal(td_claim_address(&c), TD_IB_ADDR_NULL);
    /* a global Request for Address Claimed is answered with Cannot Claim again */
    req = ib_frame(6u, TD_IB_PGN_REQUEST, 0xFFu, 0x26u, rd);
    req.dlc = 3u;
    assert_int_equal(td_claim_rx(&c, &req, 1000000u, &q), 1);
    assert_int_equal(ib_drain(&q, out, 4u), 1);
    assert_int_equal(out[0].id, 0x18EEFFFEu);
}

static void test_not_self_configurable_gives_up_at_once(void **s) {
    td_claim_t c;
    td_ib_txq_t q;
    td_can_frame_t out[4];
    td_can_frame_t winner = claim_frame(0x1ull, 0x84u);
    (void)s;
    td_ib_txq_init(&q);
    td_claim_init(&c, FIXED_NAME, 0x84u, 0x80u, 0x87u);
    td_claim_start(&c, 0u, &q);
    td_claim_rx(&c, &winner, 1000u, &q);
    assert_int_equal(ib_drain(&q, out, 4u), 2);
    assert_int_equal(out[1].id, 0x18EEFFFEu);
}

static void test_request_answered_and_others_ignored(void **s) {
    td_claim_t c;
    td_ib_txq_t q;
    td_can_frame_t out[4];
    const uint8_t rd[8] = {0x00, 0xEE, 0x00, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF};
    const uint8_t other_pgn[8] = {0x00, 0xFE, 0x00, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF};
    td_can_frame_t to_us = ib_frame(6u, TD_IB_PGN_REQUEST, 0x84u, 0x26u, rd);
    td_can_frame_t to_other = ib_frame(6u, TD_IB_PGN_REQUEST, 0x90u, 0x26u, rd);
    td_can_frame_t wrong_pgn = ib_frame(6u, TD_IB_PGN_REQUEST, 0xFFu, 0x26u, other_pgn);
    td_can_frame_t echo = claim_frame(OUR_NAME, 0x84u);
    td_can_frame_t shortf = claim_frame(1u, 0x84u);
    td_can_frame_t std = to_us;
    (void)s;
    td_ib_txq_init(&q);
    td_claim_init(&c, OUR_NAME, 0x84u, 0x80u, 0x87u);
    /* before start: a Request is not answered */
    assert_int_equal(td_claim_rx(&c, &to_us, 0u, &q), 1);
    assert_int_equal(q.count, 0);
    td_claim_start(&c, 0u, &q);
    td_claim_step(&c, 250000u);
    (void)ib_drain(&q, out, 4u);
    assert_int_equal(td_claim_rx(&c, &to_us, 300000u, &q), 1);
    assert_int_equal(td_claim_rx(&c, &to_other, 300000u, &q), 1);
    assert_int_equal(td_claim_rx(&c, &wrong_pgn, 300000u, &q), 0);
    assert_int_equal(td_claim_rx(&c, &echo, 300000u, &q), 1);
    assert_int_equal(ib_drain(&q, out, 4u), 1);
    assert_int_equal(out[0].id, 0x18EEFF84u);
    shortf.dlc = 7u;
    assert_int_equal(td_claim_rx(&c, &shortf, 300000u, &q), TD_IB_E_FRAME);
    std.extended = 0u;
    assert_int_equal(td_claim_rx(&c, &std, 300000u, &q), 0);
    assert_int_equal(td_claim_address(&c), 0x84);
    assert_int_equal(td_claim_init(&c, OUR_NAME, 254u, 0x80u, 0x87u), TD_IB_E_ARG);
    assert_int_equal(td_claim_init(&c, OUR_NAME, 0x84u, 0x88u, 0x87u), TD_IB_E_ARG);
}

static void test_txq_full_counts_drops(void **s) {
    td_ib_txq_t q;
    const uint8_t d[8] = {0};
    unsigned i;
    (void)s;
    td_ib_txq_init(&q);
    for (i = 0u; i < TD_IB_TXQ_LEN; i++) {
        assert_int_equal(td_ib_send8(&q, 6u, 0xEF00u, 0x26u, 0x84u, d), TD_IB_OK);
    }
    assert_int_equal(td_ib_send8(&q, 6u, 0xEF00u, 0x26u, 0x84u, d), TD_IB_E_FULL);
    assert_int_equal(q.dropped, 1);
    {
        td_ib_id_t id = td_ib_id_unpack(q.f[0].id);
        assert_int_equal(id.pgn, 0xEF00u);
        assert_int_equal(id.da, 0x26u);
        assert_int_equal(id.sa, 0x84u);
        assert_int_equal(id.priority, 6u);
    }
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_name_fields_round_trip),
        cmocka_unit_test(test_name_known_value_and_bytes),
        cmocka_unit_test(test_name_rejects_out_of_range),
        cmocka_unit_test(test_identity_differs_between_boards),
        cmocka_unit_test(test_claim_preferred_after_250ms),
        cmocka_unit_test(test_contest_won_by_lower_name),
        cmocka_unit_test(test_contest_lost_moves_to_free_fallback),
        cmocka_unit_test(test_range_exhausted_cannot_claim),
        cmocka_unit_test(test_not_self_configurable_gives_up_at_once),
        cmocka_unit_test(test_request_answered_and_others_ignored),
        cmocka_unit_test(test_txq_full_counts_drops),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
