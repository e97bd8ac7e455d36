/* PID step response on the reference first-order metering motor, anti-windup, derivative. */
#include "td_test.h"

#include "td_params.h"
#include "td_pid.h"

typedef struct {
    double overshoot_pct;
    double settle_s;     /* last time outside +-5 % of the jump */
    double final_rpm;
} response_t;

/* Motor at steady state `from`, setpoint jumps to `to` at t = 0; 10 ms period, the duty
 * computed from the speed measured at the start of each period is held for the period. */
static response_t step_response(td_pid_t *pid, double from, double to, double gain, double dur_s) {
    const double dt = 0.01;
    double w = from;
    /* settle the controller at `from` first */
    for (int i = 0; i < 500; i++) {
        const float u = td_pid_step(pid, (float)from, (float)w, (float)dt);
        w = first_order(w, u, MOTOR_RPM_FULL * gain, MOTOR_TAU_S, dt);
    }
    response_t r = { 0.0, 0.0, 0.0 };
    const double jump = to - from;
    double peak = w;
    for (int i = 1; i <= (int)(dur_s / dt + 0.5); i++) {
        const float u = td_pid_step(pid, (float)to, (float)w, (float)dt);
        w = first_order(w, u, MOTOR_RPM_FULL * gain, MOTOR_TAU_S, dt);
        if ((jump > 0 && w > peak) || (jump < 0 && w < peak)) {
            peak = w;
        }
        if (fabs(w - to) > 0.05 * fabs(jump)) {
            r.settle_s = i * dt;
        }
    }
    r.overshoot_pct = (peak - to) / jump * 100.0;
    r.final_rpm = w;
    return r;
}

static void init_default(td_pid_t *pid) {
    td_params_t p;
    td_params_default(&p);
    td_pid_init(pid, p.pid_kp, p.pid_ki, p.pid_kd, p.pid_kff, 0.0f, 1.0f);
}

static void test_step_response_beats_the_paper(void **state) {
    (void)state;
    td_pid_t pid;
    /* the paper's deceleration jumps were ~7 r/min (8.7 % overshoot, 1.3 s); ours: */
    const double jumps[][2] = { { 27.0, 20.0 }, { 20.0, 27.0 }, { 0.0, 24.0 }, { 32.0, 24.6 }, { 10.0, 45.0 } };
    for (size_t k = 0; k < sizeof jumps / sizeof jumps[0]; k++) {
        init_default(&pid);
        const response_t r = step_response(&pid, jumps[k][0], jumps[k][1], 1.0, 10.0);
        print_message("step %.1f -> %.1f r/min: overshoot %.2f %%, settled in %.2f s\n", jumps[k][0], jumps[k][1],
                      r.overshoot_pct, r.settle_s);
        assert_true(r.overshoot_pct < 5.0);
        assert_true(r.settle_s < 0.8);
        assert_float_equal(r.final_rpm, jumps[k][1], 0.05);
    }
}

static void test_integral_removes_a_gain_error(void **state) {
    (void)state;
    td_pid_t pid;
    init_default(&pid);
    /* the motor gives 20 % less than the feed-forward assumes: still reaches the target */
    const response_t r = step_response(&pid, 20.0, 27.0, 0.8, 15.0);
    assert_float_equal(r.final_rpm, 27.0, 0.1);
}

static void test_anti_windup(void **state) {
    (void)state;
    td_pid_t pid;
    init_default(&pid);
    double w = 0.0;
    /* ask for 90 r/min from a motor that can do 60: output pinned at 1.0 for 5 s */
    for (int i = 0; i < 500; i++) {
        const float u = td_pid_step(&pid, 90.0f, (float)w, 0.01f);
        assert_true(u <= 1.0f && u >= 0.0f);
        w = first_order(w, u, MOTOR_RPM_FULL, MOTOR_TAU_S, 0.01);
    }
    assert_float_equal(w, 60.0, 0.01);
    assert_true(pid.integ < 0.01f); /* did not wind up */
    /* back to a reachable 30 r/min: no saturated hangover, settled as fast as from rest */
    double settle_s = 0.0;
    for (int i = 1; i <= 300; i++) {
        const float u = td_pid_step(&pid, 30.0f, (float)w, 0.01f);
        w = first_order(w, u, MOTOR_RPM_FULL, MOTOR_TAU_S, 0.01);
        if (fabs(w - 30.0) > 1.5) {
            settle_s = i * 0.01;
        }
    }
    assert_true(settle_s < 0.8);
    td_pid_reset(&pid);
    assert_float_equal(pid.integ, 0.0, 0.0);
    assert_false(pid.primed);
}

static void test_derivative_on_measurement_no_kick(void **state) {
    (void)state;
    td_pid_t pid;
    td_pid_init(&pid, 0.01f, 0.0f, 0.1f, 0.0f, -10.0f, 10.0f);
    assert_float_equal(td_pid_step(&pid, 0.0f, 0.0f, 0.01f), 0.0, 1e-7);
    /* setpoint step, measurement unchanged: P only */
    assert_float_equal(td_pid_step(&pid, 10.0f, 0.0f, 0.01f), 0.1, 1e-6);
    /* measurement jumps by 1: raw D = -0.1*1/0.01 = -10, filtered by dt/(tau+dt) = 1/6 */
    assert_float_equal(td_pid_step(&pid, 10.0f, 1.0f, 0.01f), 0.09 - 10.0 / 6.0, 1e-5);
    /* bad dt gives the minimum output */
    assert_float_equal(td_pid_step(&pid, 10.0f, 1.0f, 0.0f), -10.0, 0.0);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_step_response_beats_the_paper),
        cmocka_unit_test(test_integral_removes_a_gain_error),
        cmocka_unit_test(test_anti_windup),
        cmocka_unit_test(test_derivative_on_measurement_no_kick),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
