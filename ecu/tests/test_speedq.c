/* Queue G and eq. 2 (CV = sample SD / mean). */
#include "td_test.h"

#include "td_speedq.h"

static void test_cv_of_known_vectors(void **state) {
    (void)state;
    const float steady[5] = { 6.0f, 6.0f, 6.0f, 6.0f, 6.0f };
    assert_float_equal(td_cv_pct(steady, 5), 0.0, 1e-6);
    const float three[3] = { 5.0f, 6.0f, 7.0f }; /* SD 1, mean 6 */
    assert_float_equal(td_cv_pct(three, 3), 100.0 / 6.0, 1e-4);
    const float ramp[5] = { 4.0f, 4.1f, 4.2f, 4.3f, 4.4f }; /* SD sqrt(0.1/4) = 0.158114 */
    assert_float_equal(td_cv_pct(ramp, 5), 0.158114 / 4.2 * 100.0, 1e-3);
    const float accel[5] = { 1.0f, 2.0f, 3.0f, 4.0f, 5.0f }; /* SD 1.5811, mean 3 */
    assert_float_equal(td_cv_pct(accel, 5), 52.7046, 1e-3);
}

static void test_cv_undefined_cases(void **state) {
    (void)state;
    const float zeros[4] = { 0.0f, 0.0f, 0.0f, 0.0f };
    assert_float_equal(td_cv_pct(zeros, 4), 0.0, 0.0); /* standing still is uniform */
    const float creep[5] = { 0.0f, 0.0f, 0.0f, 0.0f, 0.2f }; /* mean 0.04 */
    assert_true(td_cv_pct(creep, 5) < 0.0f);
    assert_true(td_cv_pct(zeros, 1) < 0.0f);
    assert_true(td_cv_pct(NULL, 3) < 0.0f);
}

static void test_queue_keeps_last_n(void **state) {
    (void)state;
    td_speedq_t q;
    assert_int_equal(td_speedq_init(&q, 5), TD_OK);
    assert_int_equal(td_speedq_init(&q, 1), TD_E_ARG);
    assert_int_equal(td_speedq_init(&q, 17), TD_E_ARG);
    assert_int_equal(td_speedq_init(&q, 5), TD_OK);
    td_speedq_push(&q, 1.0f);
    td_speedq_push(&q, 2.0f);
    assert_true(td_speedq_cv_pct(&q, 3) < 0.0f); /* fewer than n values */
    for (int i = 3; i <= 7; i++) {
        td_speedq_push(&q, (float)i);
    }
    /* holds 3..7; the last 3 are 5, 6, 7 */
    assert_int_equal(q.count, 5);
    assert_float_equal(td_speedq_cv_pct(&q, 3), 100.0 / 6.0, 1e-4);
    /* all five: mean 5, SD 1.5811 */
    assert_float_equal(td_speedq_cv_pct(&q, 5), 1.58114 / 5.0 * 100.0, 1e-3);
    assert_true(td_speedq_cv_pct(&q, 6) < 0.0f); /* n > N */
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_cv_of_known_vectors),
        cmocka_unit_test(test_cv_undefined_cases),
        cmocka_unit_test(test_queue_keeps_last_n),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
