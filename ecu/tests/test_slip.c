/* Eq. 3 (measured slip) and the eq. 5 model on the paper's numbers. */
#include "td_test.h"

#include "td_slip.h"

static void test_eq5_model(void **state) {
    (void)state;
    /* 0.167*36 - 0.296*6 + 0.773 = 5.009 */
    assert_float_equal(td_slip_model_pct(6.0f), 5.009, 1e-4);
    assert_float_equal(td_slip_model_pct(0.0f), 0.773, 1e-6);
    const float v5 = td_slip_model_speed_kmh(5.0f);
    assert_true(v5 >= 5.95f && v5 <= 6.05f);
    assert_float_equal(v5, 5.99474, 1e-4);
    assert_float_equal(td_slip_model_pct(v5), 5.0, 1e-4);
    /* the parabola's minimum is 0.642 %: lower slips are never reached */
    assert_float_equal(td_slip_model_speed_kmh(0.5f), -1.0, 0.0);
}

static void test_eq3_measured(void **state) {
    (void)state;
    /* 100 revolutions of r = 0.0615 m over the paper's 40 m run: 38.6416 m rolled, 3.396 % */
    assert_float_equal(td_slip_measured_pct(100.0f, 0.0615f, 40.0f), 3.3960, 1e-3);
    /* rolling further than the real distance counts the same way (|.|) */
    assert_float_equal(td_slip_measured_pct(110.0f, 0.0615f, 40.0f), 6.2644, 1e-3);
    assert_float_equal(td_slip_measured_pct(100.0f, 0.0615f, 0.0f), -1.0, 0.0);
    assert_float_equal(td_slip_measured_pct(100.0f, 0.0615f, -40.0f), -1.0, 0.0);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_eq5_model),
        cmocka_unit_test(test_eq3_measured),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
