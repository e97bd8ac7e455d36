/* The fail-safes at their edges: a frozen GNSS receiver while the wheel stops, timeouts at the
 * clock's wrap, frames stamped after the step's time, parameter writes with data in queue G, a
 * stop while a meter is blocked, fans below their minimum while starting. */
#include "td_test.h"

static void step_drained(rig_t *r) {
    rig_step(r);
    (void)rig_drain(r, 0u);
}

/* The tractor slows from 7.44 km/h to a stop over 4 s while the receiver repeats 8.0 km/h;
 * returns once the ECU's wheel speed reads ~0. */
static void brake_to_stop_with_gnss_frozen_at_8(rig_t *r) {
    for (int i = 0; i < 400; i++) {
        r->wheel_kmh = 7.44 * (1.0 - i / 400.0);
        step_drained(r);
    }
    r->wheel_kmh = 0.0;
    for (int i = 0; rig_st(r)->v_wheel_kmh >= 0.2f; i++) {
        assert_true(i < 100);
        step_drained(r);
    }
}

static void test_frozen_gnss_while_the_wheel_stops_never_meters(void **state) {
    (void)state;
    rig_t r;
    rig_start_working(&r, NULL, 0u);
    assert_int_equal(rig_st(&r)->source, TD_SRC_GNSS);
    brake_to_stop_with_gnss_frozen_at_8(&r);
    /* standing: queue G fills with zeros (CV 0, "uniform") and GNSS says 8 km/h > 6 */
    for (int i = 0; i < 1000; i++) {
        step_drained(&r);
        assert_float_equal(r.out.meter_duty[TD_UPPER], 0.0, 0.0);
        assert_float_equal(r.out.meter_duty[TD_LOWER], 0.0, 0.0);
        assert_int_equal(rig_st(&r)->source, TD_SRC_WHEEL);
        assert_int_equal(rig_st(&r)->faults & TD_FAULT_WHEEL_ENCODER, 0);
        /* flagged once the conflict lasted longer than enc_fault_time_ms (2 s) */
        assert_int_equal(rig_st(&r)->faults & TD_FAULT_GNSS_FROZEN, i >= 200 ? TD_FAULT_GNSS_FROZEN : 0);
    }
    assert_true(rig_st(&r)->uniform);
    assert_true(rig_st(&r)->gnss_valid);
    /* the receiver recovers and reports the standstill: the flag clears, nothing latched */
    r.pc_gnss_kmh = 0.0;
    rig_run_ms(&r, 600);
    assert_int_equal(rig_st(&r)->faults, 0);
    /* driving off again meters on the wheel */
    r.pc_gnss_kmh = 4.0;
    r.wheel_kmh = 4.0;
    rig_run_ms(&r, 3000);
    assert_int_equal(rig_st(&r)->source, TD_SRC_WHEEL);
    assert_float_equal(rig_st(&r)->target_rpm[TD_UPPER], 3.6 * 200 * 4.0 / 180.0, 0.1);
}

static void test_frozen_gnss_stops_the_meters_in_gnss_only_mode(void **state) {
    (void)state;
    td_params_t p;
    td_params_default(&p);
    p.speed_mode = TD_MODE_GNSS_ONLY;
    rig_t r;
    rig_start_working(&r, &p, 0u);
    brake_to_stop_with_gnss_frozen_at_8(&r);
    /* GNSS only trusts the receiver for enc_fault_time_ms, then no longer */
    rig_run_ms(&r, 2100);
    for (int i = 0; i < 500; i++) {
        step_drained(&r);
        assert_int_equal(rig_st(&r)->faults & TD_FAULT_GNSS_FROZEN, TD_FAULT_GNSS_FROZEN);
        assert_int_equal(rig_st(&r)->source, TD_SRC_WHEEL);
        assert_float_equal(r.out.meter_duty[TD_UPPER], 0.0, 0.0);
        assert_float_equal(r.out.meter_duty[TD_LOWER], 0.0, 0.0);
    }
}

static void test_live_gnss_after_a_frozen_phase_latches_the_encoder_fault(void **state) {
    (void)state;
    rig_t r;
    rig_start_working(&r, NULL, 0u);
    r.wheel_kmh = 0.0; /* encoder cable cut at 8 km/h, GNSS repeating 8.0 for a while */
    rig_run_ms(&r, 3500);
    assert_int_equal(rig_st(&r)->faults & (TD_FAULT_GNSS_FROZEN | TD_FAULT_WHEEL_ENCODER), TD_FAULT_GNSS_FROZEN);
    assert_float_equal(r.out.meter_duty[TD_UPPER], 0.0, 0.0);
    /* the receiver's value moves: it is alive, so the encoder is what is broken */
    r.pc_gnss_jitter_kmh = 0.1;
    rig_run_ms(&r, 1100);
    assert_int_equal(rig_st(&r)->faults & (TD_FAULT_GNSS_FROZEN | TD_FAULT_WHEEL_ENCODER), TD_FAULT_WHEEL_ENCODER);
    assert_int_equal(rig_st(&r)->source, TD_SRC_GNSS);
    assert_true(r.out.meter_duty[TD_UPPER] > 0.1f);
}

static void test_command_timeout_boundary_at_the_clock_wrap(void **state) {
    (void)state;
    rig_t r;
    /* commands at t0 + 0, 0.5, ... 5.5 s; the last one 1.5 s before the clock wraps to 0 */
    rig_start_working(&r, NULL, 0u - 7000000u);
    r.pc_sending = false;
    while (r.now_us != 0u) {
        step_drained(&r);
    }
    assert_int_equal(r.last_cmd_sent_us, 0u - 1500000u);
    step_drained(&r); /* now_us == 0: exactly 1.5 s, not yet */
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_CMD_TIMEOUT, 0);
    assert_true(r.out.meter_duty[TD_UPPER] > 0.1f);
    step_drained(&r); /* 1.51 s */
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_CMD_TIMEOUT, TD_FAULT_CMD_TIMEOUT);
    assert_float_equal(r.out.meter_duty[TD_UPPER], 0.0, 0.0);
    assert_float_equal(r.out.meter_duty[TD_LOWER], 0.0, 0.0);
}

static void test_frames_stamped_after_the_step_time_are_fresh(void **state) {
    (void)state;
    rig_t r;
    rig_init(&r, NULL, 0u - 1000000u);
    r.pc_sending = false;
    r.wheel_kmh = 4.0;
    /* a receive interrupt stamps each command a few microseconds after the port read the time
     * of the step that follows */
    for (int i = 0; i < 600; i++) {
        if (i % 50 == 0) {
            const td_can_frame_t f = rig_command_frame(true, 3000.0, 200.0, 150.0, 4.0);
            assert_int_equal(td_app_rx(&r.app, &f, r.now_us + 7u), TD_OK);
        }
        step_drained(&r);
        assert_int_equal(rig_st(&r)->faults & (TD_FAULT_CMD_TIMEOUT | TD_FAULT_UPPER_FAN_LOW), 0);
        assert_true(rig_st(&r)->gnss_valid);
    }
    assert_float_equal(rig_st(&r)->meter_rpm[TD_UPPER], 3.6 * 200 * 4.0 / 180.0, 0.5);
}

/* Runs `minutes` of 50 ms steps, calling check() after each. */
static void run_minutes(rig_t *r, int minutes, void (*check)(const rig_t *)) {
    r->step_us = 50000u;
    for (int i = 0; i < minutes * 1200; i++) {
        step_drained(r);
        check(r);
    }
}

static void fan_low_set(const rig_t *r) {
    assert_int_equal(rig_st(r)->faults & TD_FAULT_UPPER_FAN_LOW, TD_FAULT_UPPER_FAN_LOW);
    assert_float_equal(r->out.meter_duty[TD_UPPER], 0.0, 0.0);
}

static void test_fan_low_stays_flagged_through_the_clock_wrap(void **state) {
    (void)state;
    rig_t r;
    rig_start(&r, NULL, 0u, 4.0, 4.0);
    r.fan_broken[TD_UPPER] = true;
    rig_run_ms(&r, 3100);
    fan_low_set(&r);
    /* 72 min of running: the microsecond clock passes the start time again after 71.6 min */
    run_minutes(&r, 72, fan_low_set);
}

static void gnss_lost(const rig_t *r) {
    assert_false(rig_st(r)->gnss_valid);
    assert_int_equal(rig_st(r)->faults & TD_FAULT_GNSS_LOST, TD_FAULT_GNSS_LOST);
}

static void test_stale_gnss_stays_lost_through_the_clock_wrap(void **state) {
    (void)state;
    rig_t r;
    rig_start_working(&r, NULL, 0u);
    r.pc_sending = false; /* the PC is gone for good */
    rig_run_ms(&r, 1300);
    gnss_lost(&r);
    run_minutes(&r, 72, gnss_lost);
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_CMD_TIMEOUT, TD_FAULT_CMD_TIMEOUT);
}

/* PcParamSet(id, raw); returns the rx code. */
static int param_set(rig_t *r, uint8_t id, uint32_t raw) {
    td_can_frame_t f;
    f.id = TD_ID_PC_PARAM_SET;
    f.extended = 1u;
    f.dlc = 8u;
    const uint8_t d[8] = { id, 0, 0, 0, (uint8_t)raw, (uint8_t)(raw >> 8), (uint8_t)(raw >> 16), (uint8_t)(raw >> 24) };
    memcpy(f.data, d, 8);
    return td_app_rx(&r->app, &f, r->now_us);
}

/* The last n values of queue G, oldest first. */
static void queue_tail(const td_speedq_t *q, uint8_t n, float *out) {
    for (uint8_t i = 0u; i < n; i++) {
        out[i] = q->v[(q->head + q->len - n + i) % q->len];
    }
}

static void test_parameter_writes_to_n_and_N_with_data_in_queue_g(void **state) {
    (void)state;
    rig_t r;
    rig_init(&r, NULL, 0u);
    /* stopped (in transport) but moving: 5 km/h, then 8 km/h; queue G holds both */
    r.pc_gnss_kmh = 8.0;
    r.wheel_kmh = 5.0;
    rig_run_ms(&r, 3000);
    r.wheel_kmh = 8.0;
    rig_run_ms(&r, 1200);
    assert_int_equal(r.app.q.count, 5);
    float tail[5];
    queue_tail(&r.app.q, 5u, tail);
    assert_float_equal(rig_st(&r)->cv_pct, td_cv_pct(tail, 5u), 1e-4);
    assert_false(rig_st(&r)->uniform); /* 5, 5, 5, 8, 8 */
    assert_int_equal(rig_st(&r)->source, TD_SRC_WHEEL);
    /* n = 2: the CV of the last two (steady) values, and the rule on it, at once */
    assert_int_equal(param_set(&r, 7u, 2u), TD_OK);
    queue_tail(&r.app.q, 2u, tail);
    assert_float_equal(rig_st(&r)->cv_pct, td_cv_pct(tail, 2u), 1e-4);
    assert_true(rig_st(&r)->cv_pct < 4.2f);
    assert_true(rig_st(&r)->uniform);
    assert_int_equal(rig_st(&r)->source, TD_SRC_GNSS);
    /* N = 3: queue G restarts empty; the CV is undefined and the source the wheel, at once */
    assert_int_equal(param_set(&r, 6u, 3u), TD_OK);
    assert_int_equal(r.app.q.len, 3);
    assert_int_equal(r.app.q.count, 0);
    assert_true(rig_st(&r)->cv_pct < 0.0f);
    assert_false(rig_st(&r)->uniform);
    assert_int_equal(rig_st(&r)->source, TD_SRC_WHEEL);
    /* two fresh updates give a CV over n = 2 again, of 8 km/h values only */
    rig_run_ms(&r, 1300);
    assert_int_equal(r.app.q.count, 2);
    assert_true(rig_st(&r)->cv_pct >= 0.0f && rig_st(&r)->cv_pct < 1.0f);
    assert_int_equal(rig_st(&r)->source, TD_SRC_GNSS);
    /* the mode acts at once too */
    assert_int_equal(param_set(&r, 10u, 1u), TD_OK);
    assert_int_equal(rig_st(&r)->source, TD_SRC_WHEEL);
    /* running: writes are refused and queue G is left alone */
    r.pc_start = true;
    r.next_cmd_us = r.now_us;
    step_drained(&r);
    const uint8_t count = r.app.q.count;
    assert_int_equal(param_set(&r, 6u, 5u), TD_E_BUSY);
    assert_int_equal(r.app.q.len, 3);
    assert_int_equal(r.app.q.count, count);
}

static void test_stop_while_a_meter_is_blocked(void **state) {
    (void)state;
    rig_t r;
    rig_start_working(&r, NULL, 0u);
    r.meter_blocked[TD_UPPER] = true;
    rig_run_ms(&r, 1500);
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_UPPER_BLOCKED, TD_FAULT_UPPER_BLOCKED);
    /* stop: every output to zero, the latched fault acknowledged */
    r.pc_start = false;
    r.next_cmd_us = r.now_us;
    step_drained(&r);
    assert_false(rig_st(&r)->running);
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_LATCHED_MASK, 0);
    for (int l = 0; l < 2; l++) {
        assert_float_equal(r.out.meter_duty[l], 0.0, 0.0);
        assert_float_equal(r.out.fan_duty[l], 0.0, 0.0);
    }
    rig_run_ms(&r, 1000);
    /* start again with the meter still jammed: a fresh blocked_time_ms, not an instant latch */
    r.pc_start = true;
    r.next_cmd_us = r.now_us;
    uint32_t t_start = r.now_us;
    uint32_t t_latch = 0u;
    for (int i = 0; i < 600 && t_latch == 0u; i++) {
        step_drained(&r);
        if ((rig_st(&r)->faults & TD_FAULT_UPPER_BLOCKED) != 0u) {
            t_latch = r.now_us - r.step_us;
        }
    }
    /* fans up (~0.4 s), then 1 s commanded but still; the lower layer meters meanwhile */
    assert_true(t_latch - t_start > 1000000u && t_latch - t_start < 2500000u);
    assert_float_equal(r.out.meter_duty[TD_UPPER], 0.0, 0.0);
    assert_true(r.out.meter_duty[TD_LOWER] > 0.1f);
    /* a stop inside the suspect window: the next start times the jam from zero again */
    r.pc_start = false;
    r.next_cmd_us = r.now_us;
    step_drained(&r);
    r.pc_start = true;
    r.next_cmd_us = r.now_us;
    rig_run_ms(&r, 700); /* the fans are still up: 0.7 s of a jammed meter */
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_UPPER_BLOCKED, 0);
    assert_true(r.app.blocked_suspect[TD_UPPER]);
    r.pc_start = false;
    r.next_cmd_us = r.now_us;
    step_drained(&r);
    assert_false(r.app.blocked_suspect[TD_UPPER]);
    r.pc_start = true;
    r.next_cmd_us = r.now_us;
    rig_run_ms(&r, 700); /* 1.4 s jammed in all, but never 1 s in one go */
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_UPPER_BLOCKED, 0);
    assert_true(r.app.blocked_suspect[TD_UPPER]);
}

static void test_blocked_meter_at_a_small_target_latches_once_the_duty_is_up(void **state) {
    (void)state;
    rig_t r;
    rig_start(&r, NULL, 0u, 4.0, 4.0);
    r.pc_rate[TD_UPPER] = 30.0; /* 2.4 r/min: feed-forward duty 0.04 */
    rig_run_ms(&r, 5000);
    assert_float_equal(rig_st(&r)->target_rpm[TD_UPPER], 3.6 * 30 * 4.0 / 180.0, 0.05);
    r.meter_blocked[TD_UPPER] = true;
    uint32_t ms = 0u;
    while ((rig_st(&r)->faults & TD_FAULT_UPPER_BLOCKED) == 0u) {
        step_drained(&r);
        ms += 10u;
        assert_true(ms < 20000u);
    }
    /* the integral raises the duty to 0.3 (about 9 s), then 1 s more */
    assert_true(ms > 5000u && ms < 15000u);
    assert_float_equal(r.out.meter_duty[TD_UPPER], 0.0, 0.0);
}

static void test_fans_below_minimum_while_starting(void **state) {
    (void)state;
    rig_t r;
    rig_start(&r, NULL, 0u, 4.0, 4.0);
    r.fan_broken[TD_LOWER] = true;
    /* no meter turns before its fan is measured at fan_min_rpm; no fault during the grace */
    bool upper_metered = false;
    for (int i = 0; i < 301; i++) { /* steps at 0 .. 3.00 s after the start */
        step_drained(&r);
        for (int l = 0; l < 2; l++) {
            if (rig_st(&r)->fan_rpm[l] < 2000.0f) {
                assert_float_equal(r.out.meter_duty[l], 0.0, 0.0);
            }
        }
        upper_metered = upper_metered || r.out.meter_duty[TD_UPPER] > 0.0f;
        assert_int_equal(rig_st(&r)->faults & (TD_FAULT_UPPER_FAN_LOW | TD_FAULT_LOWER_FAN_LOW), 0);
    }
    assert_true(upper_metered);
    step_drained(&r); /* 3.01 s: the lower fan is late */
    assert_int_equal(rig_st(&r)->faults & (TD_FAULT_UPPER_FAN_LOW | TD_FAULT_LOWER_FAN_LOW), TD_FAULT_LOWER_FAN_LOW);
    assert_float_equal(r.out.meter_duty[TD_LOWER], 0.0, 0.0);
    /* a stop and a new start give the fans their grace again */
    r.pc_start = false;
    r.next_cmd_us = r.now_us;
    step_drained(&r);
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_LOWER_FAN_LOW, 0);
    r.pc_start = true;
    r.next_cmd_us = r.now_us;
    for (int i = 0; i < 300; i++) {
        step_drained(&r);
        assert_int_equal(rig_st(&r)->faults & TD_FAULT_LOWER_FAN_LOW, 0);
    }
    rig_run_ms(&r, 20);
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_LOWER_FAN_LOW, TD_FAULT_LOWER_FAN_LOW);
    /* a commanded fan speed below the minimum can never let a meter run, and says so */
    r.fan_broken[TD_LOWER] = false;
    r.pc_fan_rpm = 1500.0;
    rig_run_ms(&r, 4000);
    assert_int_equal(rig_st(&r)->faults & (TD_FAULT_UPPER_FAN_LOW | TD_FAULT_LOWER_FAN_LOW),
                     TD_FAULT_UPPER_FAN_LOW | TD_FAULT_LOWER_FAN_LOW);
    assert_true(rig_st(&r)->fan_rpm[TD_UPPER] > 1300.0f && rig_st(&r)->fan_rpm[TD_UPPER] < 1600.0f);
    assert_float_equal(r.out.meter_duty[TD_UPPER], 0.0, 0.0);
    assert_float_equal(r.out.meter_duty[TD_LOWER], 0.0, 0.0);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_frozen_gnss_while_the_wheel_stops_never_meters),
        cmocka_unit_test(test_frozen_gnss_stops_the_meters_in_gnss_only_mode),
        cmocka_unit_test(test_live_gnss_after_a_frozen_phase_latches_the_encoder_fault),
        cmocka_unit_test(test_command_timeout_boundary_at_the_clock_wrap),
        cmocka_unit_test(test_frames_stamped_after_the_step_time_are_fresh),
        cmocka_unit_test(test_fan_low_stays_flagged_through_the_clock_wrap),
        cmocka_unit_test(test_stale_gnss_stays_lost_through_the_clock_wrap),
        cmocka_unit_test(test_parameter_writes_to_n_and_N_with_data_in_queue_g),
        cmocka_unit_test(test_stop_while_a_meter_is_blocked),
        cmocka_unit_test(test_blocked_meter_at_a_small_target_latches_once_the_duty_is_up),
        cmocka_unit_test(test_fans_below_minimum_while_starting),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
