/* Counter extension and the wheel capture: wraps, backward motion, overcapture. */
#include "port_test.h"
#include "td_capture.h"

static void test_encoder_counter_across_its_wrap_both_ways(void **state) {
    (void)state;
    td_ctr_t c;
    td_ctr_init(&c, 16u, 65000u);
    assert_int_equal(td_ctr_update_signed(&c, 65500u), 500u);
    assert_int_equal(td_ctr_update_signed(&c, 300u), 836u);    /* forward over the wrap: +336 */
    assert_int_equal(td_ctr_update_signed(&c, 65400u), 400u);  /* backward over it: -436 */
    assert_int_equal(td_ctr_update_signed(&c, 65400u), 400u);
    /* the largest forward step read as such: 32767; one more is read as backward */
    assert_int_equal(td_ctr_update_signed(&c, (uint16_t)(65400u + 32767u)), 400u + 32767u);
    assert_int_equal(td_ctr_update_signed(&c, (uint16_t)(65400u + 32767u + 32768u)), 400u + 32767u - 32768u);
    /* backward from 0: the 32-bit total wraps below zero, as the core's counters may */
    td_ctr_init(&c, 16u, 10u);
    assert_int_equal(td_ctr_update_signed(&c, 5u), 0xFFFFFFFBu);
    assert_int_equal(td_ctr_update_signed(&c, 15u), 5u);
}

static void test_tachometer_counts_up_only(void **state) {
    (void)state;
    td_ctr_t c;
    td_ctr_init(&c, 8u, 250u);
    assert_int_equal(td_ctr_update_up(&c, 4u), 10u);     /* 250 -> 256 -> 4 */
    assert_int_equal(td_ctr_update_up(&c, 3u), 265u);    /* a full wrap less one: never backwards */
    assert_int_equal(td_ctr_update_up(&c, 0x1FFu), 517u); /* bits above the width ignored: 0xFF */
    td_ctr_t w;
    td_ctr_init(&w, 16u, 0xFFFFu);
    uint32_t total = 0u;
    for (uint32_t k = 1u; k <= 70000u; k++) { /* 4.6 wraps of 16 bits, 7 pulses a read */
        total = td_ctr_update_up(&w, (uint16_t)(0xFFFFu + 7u * k));
    }
    assert_int_equal(total, 490000u);
}

static void test_32_bit_total_wraps_like_the_cores_counters(void **state) {
    (void)state;
    td_ctr_t c;
    td_ctr_init(&c, 16u, 0u);
    c.total = 0xFFFFFF00u;
    assert_int_equal(td_ctr_update_up(&c, 0x200u), 0x100u);
}

static void test_wheel_capture_keeps_count_and_time_together(void **state) {
    (void)state;
    td_wheel_capture_t w;
    td_wheel_capture_init(&w);
    assert_false(w.have_edge);
    td_wheel_capture_edge(&w, 0xFFFFFF00u, false);
    td_wheel_capture_edge(&w, 0x00000100u, false); /* the microsecond clock wraps between edges */
    assert_int_equal(w.count, 2u);
    assert_int_equal(w.edge_us, 0x100u);
    assert_int_equal(w.edge_us - 0xFFFFFF00u, 0x200u); /* the period as the core takes it */
    /* an edge overwritten before the interrupt ran: counted, the later time stands */
    td_wheel_capture_edge(&w, 0x00000500u, true);
    assert_int_equal(w.count, 4u);
    assert_int_equal(w.edge_us, 0x500u);
    assert_int_equal(w.overcaptures, 1u);
    assert_true(w.have_edge);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_encoder_counter_across_its_wrap_both_ways),
        cmocka_unit_test(test_tachometer_counts_up_only),
        cmocka_unit_test(test_32_bit_total_wraps_like_the_cores_counters),
        cmocka_unit_test(test_wheel_capture_keeps_count_and_time_together),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
