/* The GNSS lag learned against the wheel's history (td_lag.h): a pure delay, a receiver with a
 * latency and a first-order velocity filter, a wheel whose scale is not learned, steady motion
 * (nothing to learn), a history too short; and in the application a fixed GnssLag the data
 * contradict, overruled and reported. */
#include "td_test.h"

#include "td_fused.h"
#include "td_lag.h"

#define DT 0.01

/* rest 2 s, 0.5 m/s^2 to 2 m/s, hold, then 0.4 m/s^2 down to 0.4 m/s, hold */
static double v_drive(double t) {
    if (t < 2.0) {
        return 0.0;
    }
    if (t < 6.0) {
        return 0.5 * (t - 2.0);
    }
    if (t < 12.0) {
        return 2.0;
    }
    if (t < 16.0) {
        return 2.0 - 0.4 * (t - 12.0);
    }
    return 0.4;
}

/* The receiver: latency D, first-order filter tau, fixes every 0.2 s; the wheel reads scale * v. */
static td_lag_t learn(double latency_s, double tau_s, double scale, double dur_s) {
    td_fused_t f;
    assert_int_equal(td_fused_init(&f, 0.3f, 0.2f, 15.0f), TD_OK);
    td_lag_t l;
    td_lag_init(&l);
    double t = 0.0;
    double y = 0.0;
    const int n = (int)(dur_s / DT + 0.5);
    for (int k = 1; k <= n; k++) {
        t = k * DT;
        td_fused_record(&f, (float)(scale * v_drive(t - 0.5 * DT)), (float)DT);
        const double lag_t = t - latency_s;
        y += (tau_s > 0.0 ? DT / tau_s : 1.0) * (v_drive(lag_t) - y);
        if (k % 20 == 0) {
            (void)td_lag_fix(&l, &f, (float)(tau_s > 0.0 ? y : v_drive(lag_t)), 0.05f, 0.2f);
        }
    }
    return l;
}

static void test_pure_delay_is_learned(void **state) {
    (void)state;
    const double delays[3] = { 0.3, 1.0, 2.0 };
    for (int i = 0; i < 3; i++) {
        const td_lag_t l = learn(delays[i] + 0.05, 0.0, 1.0, 20.0);
        assert_true(l.learned);
        assert_float_equal(l.lag_s, delays[i], 0.05);
    }
}

/* The first start from rest teaches it: learned before the ramp is over. */
static void test_learned_at_the_first_start(void **state) {
    (void)state;
    const td_lag_t l = learn(1.05, 0.0, 1.0, 6.0);
    assert_true(l.learned);
    assert_float_equal(l.lag_s, 1.0, 0.1);
}

/* A wheel reading 8 % low (a scale not learned yet) does not move the lag: c_k is free. */
static void test_an_unlearned_scale_does_not_bias_it(void **state) {
    (void)state;
    const td_lag_t l = learn(0.85, 0.0, 0.92, 20.0);
    assert_float_equal(l.lag_s, 0.8, 0.05);
}

/* latency 0.3 s + filter 0.5 s: the best pure delay, near latency + tau (measured 0.76 s) */
static void test_a_filtered_receiver(void **state) {
    (void)state;
    const td_lag_t l = learn(0.35, 0.5, 1.0, 20.0);
    assert_true(l.learned);
    assert_float_equal(l.lag_s, 0.8, 0.1);
}

/* Steady motion and standstill teach nothing; a history shorter than age + 3 s takes no fix. */
static void test_steady_motion_and_a_short_history(void **state) {
    (void)state;
    td_fused_t f;
    assert_int_equal(td_fused_init(&f, 0.3f, 0.2f, 15.0f), TD_OK);
    td_lag_t l;
    td_lag_init(&l);
    for (int k = 0; k < 200; k++) { /* 2 s: shorter than the 3 s of candidates */
        td_fused_record(&f, 0.1f * (float)k * (float)DT, (float)DT);
    }
    assert_false(td_lag_fix(&l, &f, 0.5f, 0.0f, 0.2f));
    for (int k = 0; k < 400; k++) {
        td_fused_record(&f, 2.0f, (float)DT);
    }
    assert_false(td_lag_fix(&l, &f, 2.0f, 0.0f, 0.2f)); /* steady */
    assert_false(td_lag_fix(&l, &f, NAN, 0.0f, 0.2f));
    assert_false(l.learned);
    assert_float_equal(l.evidence_s, 0.0, 0.0);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_pure_delay_is_learned),
        cmocka_unit_test(test_learned_at_the_first_start),
        cmocka_unit_test(test_an_unlearned_scale_does_not_bias_it),
        cmocka_unit_test(test_a_filtered_receiver),
        cmocka_unit_test(test_steady_motion_and_a_short_history),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
