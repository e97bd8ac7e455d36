/* Eq. 4: target metering speed, on the paper's machine. */
#include "td_test.h"

#include "td_meter.h"

static void test_eq4_target(void **state) {
    (void)state;
    assert_float_equal(td_meter_target_rpm(3.6f, 200.0f, 6.0f, 0.3f, 0.5f), 24.0, 1e-4);
    /* linear in speed: 8 km/h -> 32 r/min */
    assert_float_equal(td_meter_target_rpm(3.6f, 200.0f, 8.0f, 0.3f, 0.5f), 32.0, 1e-4);
    assert_float_equal(td_meter_target_rpm(3.6f, 200.0f, 0.49f, 0.3f, 0.5f), 0.0, 0.0);
    assert_float_equal(td_meter_target_rpm(3.6f, 200.0f, 0.5f, 0.3f, 0.5f), 2.0, 1e-5);
    assert_float_equal(td_meter_target_rpm(3.6f, 0.0f, 6.0f, 0.3f, 0.5f), 0.0, 0.0);
    assert_float_equal(td_meter_target_rpm(3.6f, 200.0f, NAN, 0.3f, 0.5f), 0.0, 0.0);
    assert_float_equal(td_meter_target_rpm(3.6f, 200.0f, 6.0f, 0.0f, 0.5f), -1.0, 0.0);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_eq4_target),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
