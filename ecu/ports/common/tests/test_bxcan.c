/* bxCAN bit timing, filters and mailbox words, against RM0090's formulas. */
#include "port_test.h"
#include "td_bxcan.h"
#include "td_common.h"

/* The bit rate and sample point a BTR value gives (32.7.7), recomputed from the register. */
static void btr_check(uint32_t pclk, uint32_t btr, uint32_t want_rate, unsigned sp_lo, unsigned sp_hi) {
    const uint32_t brp = (btr & 0x3FFu) + 1u;
    const uint32_t ts1 = ((btr >> 16) & 0xFu) + 1u;
    const uint32_t ts2 = ((btr >> 20) & 0x7u) + 1u;
    const uint32_t sjw = ((btr >> 24) & 0x3u) + 1u;
    const uint32_t tq = 1u + ts1 + ts2;
    assert_int_equal(pclk % (brp * tq), 0u);
    assert_int_equal(pclk / (brp * tq), want_rate);
    const unsigned sp = 1000u * (1u + ts1) / tq;
    assert_in_range(sp, sp_lo, sp_hi);
    assert_true(sjw <= ts2 && ts2 >= 2u);
    assert_int_equal(btr & 0xC0000000u, 0u); /* normal mode: no loop-back, not silent */
}

static void test_250k_at_42mhz_is_the_classic_setting(void **state) {
    (void)state;
    td_bxcan_timing_t t;
    assert_int_equal(td_bxcan_timing(42000000u, 250000u, 875u, &t), TD_OK);
    /* 168 quanta per bit at 42 MHz: 12 x 14, sample at 12/14 = 85.7 % (8 x 21 cannot reach it) */
    assert_int_equal(t.brp, 12);
    assert_int_equal(t.ts1, 11);
    assert_int_equal(t.ts2, 2);
    assert_int_equal(t.sjw, 2);
    assert_int_equal(t.sample_permille, 857);
    assert_int_equal(t.btr, 0x011A000Bu);
    btr_check(42000000u, t.btr, 250000u, 857u, 857u);
}

static void test_every_common_rate(void **state) {
    (void)state;
    const uint32_t rates[] = { 125000u, 250000u, 500000u, 1000000u };
    const uint32_t clocks[] = { 42000000u, 16000000u, 36000000u, 45000000u };
    for (unsigned c = 0u; c < 4u; c++) {
        for (unsigned i = 0u; i < 4u; i++) {
            td_bxcan_timing_t t;
            const int rc = td_bxcan_timing(clocks[c], rates[i], 875u, &t);
            if (clocks[c] == 45000000u && rates[i] == 1000000u) {
                assert_int_equal(rc, TD_OK); /* 45 = 3 x 15 */
            }
            if (rc == TD_OK) {
                btr_check(clocks[c], t.btr, rates[i], 750u, 900u);
            }
        }
    }
    td_bxcan_timing_t t;
    /* HSI fallback: 16 MHz APB1 still makes 250 kbit/s (4 x 16 quanta) */
    assert_int_equal(td_bxcan_timing(16000000u, 250000u, 875u, &t), TD_OK);
    assert_int_equal(t.brp * (1u + t.ts1 + t.ts2), 64u);
    assert_int_equal(t.sample_permille, 875u);
}

static void test_impossible_rates_are_refused(void **state) {
    (void)state;
    td_bxcan_timing_t t;
    assert_int_equal(td_bxcan_timing(42000000u, 333333u, 875u, &t), TD_E_RANGE);
    assert_int_equal(td_bxcan_timing(42000000u, 10000000u, 875u, &t), TD_E_RANGE);
    assert_int_equal(td_bxcan_timing(42000000u, 1000u, 875u, &t), TD_E_RANGE); /* prescaler > 1024 */
    assert_int_equal(td_bxcan_timing(0u, 250000u, 875u, &t), TD_E_ARG);
    assert_int_equal(td_bxcan_timing(42000000u, 250000u, 400u, &t), TD_E_ARG);
    assert_int_equal(td_bxcan_timing(42000000u, 250000u, 875u, NULL), TD_E_ARG);
}

static void test_filters_pass_exactly_the_ecus_frames(void **state) {
    (void)state;
    const uint32_t ids[] = { 0x0A5C6465u, 0x0A606465u, 0x0A646465u, 0x0A626465u, 0x0A706465u };
    td_bxcan_bank_t banks[TD_BXCAN_BANKS];
    assert_int_equal(td_bxcan_filters_ext(ids, 5u, banks, TD_BXCAN_BANKS), 3);
    assert_int_equal(banks[0].fr1, (0x0A5C6465u << 3) | 4u);
    assert_int_equal(banks[2].fr1, banks[2].fr2);
    for (unsigned i = 0u; i < 5u; i++) {
        assert_true(td_bxcan_accepts(banks, 3u, ids[i], true, false));
        assert_false(td_bxcan_accepts(banks, 3u, ids[i], true, true));      /* remote */
        assert_false(td_bxcan_accepts(banks, 3u, ids[i] & 0x7FFu, false, false)); /* 11-bit */
        assert_false(td_bxcan_accepts(banks, 3u, ids[i] ^ 1u, true, false));
        assert_false(td_bxcan_accepts(banks, 3u, ids[i] ^ 0x10000000u, true, false));
    }
    assert_false(td_bxcan_accepts(banks, 3u, 0x185C6465u, true, false)); /* the ECU's own status */
    const uint32_t bad[] = { 0x20000000u };
    assert_int_equal(td_bxcan_filters_ext(bad, 1u, banks, 1u), TD_E_ARG);
    assert_int_equal(td_bxcan_filters_ext(ids, 5u, banks, 2u), TD_E_FULL);
    assert_int_equal(td_bxcan_filters_ext(ids, 0u, banks, 2u), 0);
}

static void test_mailbox_words_round_trip(void **state) {
    (void)state;
    td_can_frame_t f = { 0x185C6465u, 1u, 8u, { 0x0A, 0x60, 0x09, 0x10, 0x00, 0x96, 0x95, 0x41 } };
    uint32_t tir, tdtr, tdlr, tdhr;
    td_bxcan_tx_words(&f, &tir, &tdtr, &tdlr, &tdhr);
    assert_int_equal(tir, (0x185C6465u << 3) | 4u);
    assert_int_equal(tdtr, 8u);
    assert_int_equal(tdlr, 0x1009600Au);
    assert_int_equal(tdhr, 0x41959600u);
    td_can_frame_t g;
    assert_true(td_bxcan_rx_frame(tir, tdtr | 0xAB00u, tdlr, tdhr, &g)); /* FMI bits ignored */
    assert_frame_equal(&f, &g);
    assert_false(td_bxcan_rx_frame(tir | TD_BXCAN_RTR, tdtr, tdlr, tdhr, &g));
    assert_true(td_bxcan_rx_frame(0x123u << 21, 12u, 0u, 0u, &g)); /* DLC 12 = 8 bytes */
    assert_int_equal(g.id, 0x123u);
    assert_int_equal(g.extended, 0u);
    assert_int_equal(g.dlc, 8u);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_250k_at_42mhz_is_the_classic_setting),
        cmocka_unit_test(test_every_common_rate),
        cmocka_unit_test(test_impossible_rates_are_refused),
        cmocka_unit_test(test_filters_pass_exactly_the_ecus_frames),
        cmocka_unit_test(test_mailbox_words_round_trip),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
