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

/* Eq. 4 inverted gives back the rate eq. 4 was given. */
static void test_eq4_inverted(void **state) {
    (void)state;
    assert_float_equal(td_meter_rate_kg_ha(3.6f, 24.0f, 6.0f, 0.3f, 0.5f), 200.0, 1e-3);
    assert_float_equal(td_meter_rate_kg_ha(3.6f, 32.0f, 8.0f, 0.3f, 0.5f), 200.0, 1e-3);
    const float r = td_meter_target_rpm(3.6f, 137.5f, 7.3f, 0.25f, 0.5f);
    assert_float_equal(td_meter_rate_kg_ha(3.6f, r, 7.3f, 0.25f, 0.5f), 137.5, 1e-3);
    /* at a standstill (or below the working speed) the rate per area is not defined: 0 */
    assert_float_equal(td_meter_rate_kg_ha(3.6f, 24.0f, 0.49f, 0.3f, 0.5f), 0.0, 0.0);
    assert_float_equal(td_meter_rate_kg_ha(3.6f, 24.0f, 0.0f, 0.3f, 0.0f), 0.0, 0.0);
    assert_float_equal(td_meter_rate_kg_ha(3.6f, 0.0f, 6.0f, 0.3f, 0.5f), 0.0, 0.0);
    assert_float_equal(td_meter_rate_kg_ha(3.6f, NAN, 6.0f, 0.3f, 0.5f), 0.0, 0.0);
    assert_float_equal(td_meter_rate_kg_ha(3.6f, 24.0f, NAN, 0.3f, 0.5f), 0.0, 0.0);
    assert_float_equal(td_meter_rate_kg_ha(3.6f, 24.0f, 6.0f, 0.0f, 0.5f), -1.0, 0.0);
    assert_float_equal(td_meter_rate_kg_ha(0.0f, 24.0f, 6.0f, 0.3f, 0.5f), -1.0, 0.0);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_eq4_target),
        cmocka_unit_test(test_eq4_inverted),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
