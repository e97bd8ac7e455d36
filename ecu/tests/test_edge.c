/* Wheel speed from pulse timing: first motion within 2 pulses, exact periods with a capture timer,
 * counts-only ports, the 1/t bound while slowing, standstill after the stop time, bad edge times. */
#include "td_test.h"

#include "td_edge.h"

#define M_PER_PULSE (2.0 * PI_D * 0.0615 / 500.0) /* 0.7728 mm */

static void test_init_rejects_bad_arguments(void **state) {
    (void)state;
    td_edge_t e;
    assert_int_equal(td_edge_init(&e, 0.0615f, 500u, 300u), TD_OK);
    assert_float_equal(e.m_per_pulse, M_PER_PULSE, 1e-9);
    assert_int_equal(td_edge_init(&e, 0.0f, 500u, 300u), TD_E_ARG);
    assert_int_equal(td_edge_init(&e, 0.0615f, 0u, 300u), TD_E_ARG);
    assert_int_equal(td_edge_init(&e, 0.0615f, 500u, 0u), TD_E_ARG);
    assert_int_equal(td_edge_init(NULL, 0.0615f, 500u, 300u), TD_E_ARG);
}

/* From standstill: the first pulse is motion, the second gives the speed of its period. */
static void test_first_motion_within_two_pulses(void **state) {
    (void)state;
    td_edge_t e;
    assert_int_equal(td_edge_init(&e, 0.0615f, 500u, 300u), TD_OK);
    uint32_t t = 1000000u;
    assert_float_equal(td_edge_step(&e, t, 100u, 0u, true), 0.0, 0.0);
    for (int i = 0; i < 50; i++) { /* standing */
        t += 10000u;
        assert_float_equal(td_edge_step(&e, t, 100u, 0u, true), 0.0, 0.0);
    }
    assert_false(e.moving);
    t += 10000u; /* pulse 1, 3 ms before the step */
    assert_float_equal(td_edge_step(&e, t, 101u, t - 3000u, true), 0.0, 0.0);
    assert_true(e.moving);
    t += 10000u; /* no second pulse yet: moving, no period to measure */
    assert_float_equal(td_edge_step(&e, t, 101u, 0u, true), 0.0, 0.0);
    assert_true(e.moving);
    t += 10000u; /* pulse 2, 21 ms after pulse 1: 1.5 mm travelled, the speed of that period */
    const float v = td_edge_step(&e, t, 102u, t - 2000u, true);
    assert_float_equal(v, M_PER_PULSE / 0.021, 1e-5);
    assert_true(e.timed);
}

/* A capture timer gives the exact speed at every step, whatever the step phase. */
static void test_constant_speed_exact_at_every_step(void **state) {
    (void)state;
    td_edge_t e;
    assert_int_equal(td_edge_init(&e, 0.0615f, 500u, 300u), TD_OK);
    const double v_ms = 5.0 / 3.6;
    const double period_us = M_PER_PULSE / v_ms * 1e6; /* 556.5 us */
    uint32_t t = 0xFFFF0000u;                          /* across the clock's wrap */
    for (int k = 0; k < 300; k++) {
        const double elapsed = (double)k * 10000.0 + (k % 3) * 1700.0; /* jitter */
        const double pulses = elapsed / period_us;
        const uint32_t count = 0xFFFFFF00u + (uint32_t)pulses; /* and the counter's */
        const uint32_t edge = t + (uint32_t)(floor(pulses) * period_us + 0.5);
        const float v = td_edge_step(&e, t + (uint32_t)elapsed, count, edge, true);
        if (k > 1) {
            assert_float_equal(v, v_ms, 2e-3 * v_ms);
        }
    }
}

/* Counts only: the step clock times the pulses; one pulse of quantization, right on average. */
static void test_counts_only_port(void **state) {
    (void)state;
    td_edge_t e;
    assert_int_equal(td_edge_init(&e, 0.0615f, 500u, 300u), TD_OK);
    const double v_ms = 5.0 / 3.6;
    double sum = 0.0;
    int n = 0;
    for (int k = 0; k < 500; k++) {
        const uint32_t count = (uint32_t)(v_ms * k * 0.01 / M_PER_PULSE);
        const float v = td_edge_step(&e, (uint32_t)k * 10000u, count, 12345u, false);
        assert_false(e.timed && k > 0);
        if (k > 2) {
            assert_float_equal(v, v_ms, 0.3 * v_ms); /* 3 or 4 pulses per 10 ms */
            sum += v;
            n++;
        }
    }
    assert_float_equal(sum / (float)n, v_ms, 0.01 * v_ms);
}

/* Slowing to a stop: bounded by one pulse over the time since the last, then 0 after stop_ms. */
static void test_standstill_within_stop_time(void **state) {
    (void)state;
    td_edge_t e;
    assert_int_equal(td_edge_init(&e, 0.0615f, 500u, 300u), TD_OK);
    uint32_t t = 0u;
    uint32_t c = 0u;
    (void)td_edge_step(&e, t, c, 0u, true);
    for (int k = 0; k < 20; k++) { /* 1 m/s */
        t += 10000u;
        c += 13u;
        (void)td_edge_step(&e, t, c, t - 100u, true);
    }
    const uint32_t last_edge = t - 100u;
    float prev = e.speed_ms;
    for (uint32_t k = 1u; k <= 29u; k++) { /* the wheel stops dead */
        t += 10000u;
        const float v = td_edge_step(&e, t, c, 0u, true);
        assert_true(v <= prev);
        assert_true(v <= (float)(M_PER_PULSE / ((t - last_edge) * 1e-6)) + 1e-6f);
        assert_true(e.moving);
        prev = v;
    }
    t += 10000u; /* 300.1 ms after the last pulse */
    assert_float_equal(td_edge_step(&e, t, c, 0u, true), 0.0, 0.0);
    assert_false(e.moving);
}

/* An edge time after the step, or before the previous edge, is not trusted; a counter that runs
 * backwards is no motion. */
static void test_bad_edge_times_and_backward_counts(void **state) {
    (void)state;
    td_edge_t e;
    assert_int_equal(td_edge_init(&e, 0.0615f, 500u, 300u), TD_OK);
    (void)td_edge_step(&e, 0u, 0u, 0u, true);
    (void)td_edge_step(&e, 10000u, 10u, 9000u, true);
    float v = td_edge_step(&e, 20000u, 20u, 25000u, true); /* in the future: the step time */
    assert_false(e.timed);
    assert_float_equal(v, 10.0 * M_PER_PULSE / 0.011, 1e-4);
    v = td_edge_step(&e, 30000u, 30u, 15000u, true); /* before the previous edge (20000) */
    assert_false(e.timed);
    assert_float_equal(v, 10.0 * M_PER_PULSE / 0.010, 1e-4);
    v = td_edge_step(&e, 40000u, 25u, 39000u, true); /* backwards */
    assert_true(v <= (float)(M_PER_PULSE / 0.010) + 1e-6f);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_init_rejects_bad_arguments),
        cmocka_unit_test(test_first_motion_within_two_pulses),
        cmocka_unit_test(test_constant_speed_exact_at_every_step),
        cmocka_unit_test(test_counts_only_port),
        cmocka_unit_test(test_standstill_within_stop_time),
        cmocka_unit_test(test_bad_edge_times_and_backward_counts),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
