/* Ground-wheel speed: eq. 1, mean of frequency samples, counter and clock wrap, jitter. */
#include "td_test.h"

#include "td_wheel.h"

static void test_eq1_worked_value(void **state) {
    (void)state;
    /* 2*pi*431.3*0.0615*3.6/500 = 1.19996 km/h */
    assert_float_equal(td_wheel_speed_kmh(431.3f, 0.0615f, 500u), 1.19996, 5e-5);
    /* 6 km/h on the paper's wheel is 2156.5 Hz */
    assert_float_equal(td_wheel_speed_kmh(2156.5f, 0.0615f, 500u), 6.0, 1e-3);
    assert_float_equal(td_wheel_speed_kmh(0.0f, 0.0615f, 500u), 0.0, 0.0);
}

static void test_init_rejects_bad_arguments(void **state) {
    (void)state;
    td_wheel_t w;
    assert_int_equal(td_wheel_init(&w, 0.0615f, 500u, 4u, 500u), TD_OK);
    assert_int_equal(w.sample_us, 125000u);
    assert_int_equal(td_wheel_init(&w, 0.0f, 500u, 4u, 500u), TD_E_ARG);
    assert_int_equal(td_wheel_init(&w, 0.0615f, 0u, 4u, 500u), TD_E_ARG);
    assert_int_equal(td_wheel_init(&w, 0.0615f, 500u, 0u, 500u), TD_E_ARG);
    assert_int_equal(td_wheel_init(&w, 0.0615f, 500u, 17u, 500u), TD_E_ARG);
    assert_int_equal(td_wheel_init(NULL, 0.0615f, 500u, 4u, 500u), TD_E_ARG);
}

/* Drive the estimator at v_kmh with steps of (step_a, step_b) us alternately from t0/c0.
 * Returns the number of updates in `dur_us` and the last speed. */
static int drive(td_wheel_t *w, double v_kmh, uint32_t t0, uint32_t c0, uint32_t step_a, uint32_t step_b,
                 uint32_t dur_us, float *last, uint32_t *first_update_after_us) {
    const double hz = v_kmh / 3.6 / (2.0 * PI_D * 0.0615) * 500.0;
    uint32_t t = t0;
    uint64_t elapsed = 0;
    int updates = 0;
    int k = 0;
    *first_update_after_us = 0;
    while (elapsed <= dur_us) {
        const uint32_t count = c0 + (uint32_t)(hz * (double)elapsed * 1e-6);
        float v;
        if (td_wheel_step(w, t, count, &v)) {
            if (updates == 0) {
                *first_update_after_us = (uint32_t)elapsed;
            }
            updates++;
            *last = v;
        }
        const uint32_t dt = (k++ % 2 == 0) ? step_a : step_b;
        t += dt;
        elapsed += dt;
    }
    return updates;
}

static void test_constant_speed_every_500ms_across_both_wraps(void **state) {
    (void)state;
    td_wheel_t w;
    assert_int_equal(td_wheel_init(&w, 0.0615f, 500u, 4u, 500u), TD_OK);
    float v = -1.0f;
    uint32_t first;
    /* clock wraps after 0.3 s, the counter after ~1 s at 8 km/h (2875 Hz) */
    const int n = drive(&w, 8.0, 0xFFFFFFFFu - 300000u, 0xFFFFFFFFu - 3000u, 10000u, 10000u, 10000000u, &v, &first);
    assert_int_equal(first, 500000u);
    assert_int_equal(n, 20); /* 10 s / 0.5 s */
    assert_float_equal(v, 8.0, 8.0 * 0.005);
}

static void test_irregular_steps_keep_period_and_accuracy(void **state) {
    (void)state;
    td_wheel_t w;
    assert_int_equal(td_wheel_init(&w, 0.0615f, 500u, 4u, 500u), TD_OK);
    float v = -1.0f;
    uint32_t first;
    const int n = drive(&w, 5.0, 1000u, 0u, 7000u, 13000u, 10000000u, &v, &first);
    assert_true(n >= 19 && n <= 20);
    assert_float_equal(v, 5.0, 5.0 * 0.01);
}

static void test_mean_of_samples_follows_a_change(void **state) {
    (void)state;
    td_wheel_t w;
    assert_int_equal(td_wheel_init(&w, 0.0615f, 500u, 4u, 500u), TD_OK);
    float v = 0.0f;
    /* two samples at 2156.5 Hz (6 km/h) then two at 0 Hz: the mean is 3 km/h */
    uint32_t count = 0;
    assert_false(td_wheel_step(&w, 0u, count, &v));
    count += 270; /* 2156.5 Hz * 0.125 s = 269.6 */
    assert_false(td_wheel_step(&w, 125000u, count, &v));
    count += 269;
    assert_false(td_wheel_step(&w, 250000u, count, &v));
    assert_false(td_wheel_step(&w, 375000u, count, &v));
    assert_true(td_wheel_step(&w, 500000u, count, &v));
    assert_float_equal(v, td_wheel_speed_kmh((270.0f + 269.0f) / 0.5f, 0.0615f, 500u), 1e-4);
    assert_float_equal(v, 3.0, 0.01);
}

static void test_backward_count_is_ignored(void **state) {
    (void)state;
    td_wheel_t w;
    assert_int_equal(td_wheel_init(&w, 0.0615f, 500u, 1u, 100u), TD_OK);
    float v = -1.0f;
    assert_false(td_wheel_step(&w, 0u, 1000u, &v));
    assert_true(td_wheel_step(&w, 100000u, 990u, &v)); /* rolled back 10 pulses */
    assert_float_equal(v, 0.0, 0.0);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_eq1_worked_value),
        cmocka_unit_test(test_init_rejects_bad_arguments),
        cmocka_unit_test(test_constant_speed_every_500ms_across_both_wraps),
        cmocka_unit_test(test_irregular_steps_keep_period_and_accuracy),
        cmocka_unit_test(test_mean_of_samples_follows_a_change),
        cmocka_unit_test(test_backward_count_is_ignored),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
