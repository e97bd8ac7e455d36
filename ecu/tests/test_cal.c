/* The metering catch test through the ECU's port: it runs standing, counts the revolutions that
 * fell into the bag, and every abort condition stops the meter. */
#include "td_test.h"

#include "td_can.h"

static td_can_frame_t cal_frame(uint8_t action, uint8_t layer, double rev, double rpm, uint8_t seq) {
    struct td_can_pc_cal_command_t m;
    (void)td_can_pc_cal_command_init(&m);
    m.cal_action = action;
    m.cal_layer = layer;
    m.cal_revolutions = (uint16_t)(rev * 10.0 + 0.5);
    m.cal_meter_speed = (uint16_t)(rpm * 100.0 + 0.5);
    m.cal_seq = seq;
    td_can_frame_t f;
    memset(&f, 0, sizeof f);
    f.id = TD_ID_PC_CAL_COMMAND;
    f.extended = 1u;
    f.dlc = 8u;
    assert_int_equal(td_can_pc_cal_command_pack(f.data, &m, sizeof f.data), 8);
    return f;
}

typedef struct {
    int frames;
    struct td_can_ecu_cal_status_t last;
} cal_seen_t;

/* Step for `ms`, collecting the EcuCalStatus frames. */
static void run_collect(rig_t *r, uint32_t ms, cal_seen_t *seen) {
    const uint32_t steps = ms * 1000u / r->step_us;
    for (uint32_t i = 0; i < steps; i++) {
        rig_step(r);
        td_can_frame_t f;
        while (td_app_tx_pop(&r->app, &f)) {
            if (f.id == TD_ID_ECU_CAL_STATUS) {
                assert_int_equal(f.dlc, 8);
                assert_int_equal(td_can_ecu_cal_status_unpack(&seen->last, f.data, f.dlc), 0);
                seen->frames++;
            }
        }
    }
}

static double status_rev(const cal_seen_t *s) {
    return s->last.cal_revolutions * 0.001;
}

static void rig_standing(rig_t *r) {
    rig_init(r, NULL, 1000u);
    r->pc_start = false; /* the terminal sends stop commands while the test runs */
    r->wheel_kmh = 0.0;
}

static void test_catch_test_runs_the_revolutions_standing_and_counts_the_coast(void **state) {
    (void)state;
    rig_t r;
    rig_standing(&r);
    const td_can_frame_t f = cal_frame(1, TD_LOWER, 10.0, 20.0, 7);
    assert_int_equal(td_app_rx(&r.app, &f, r.now_us), TD_OK);
    cal_seen_t s = { 0 };
    run_collect(&r, 10000, &s); /* nominal 30 s at 20 r/min; look at 10 s in */
    assert_int_equal(s.last.cal_state, TD_CAL_RUNNING);
    assert_int_equal(s.last.cal_layer, TD_LOWER);
    assert_int_equal(s.last.cal_seq, 7);
    assert_float_equal(s.last.cal_meter_speed * 0.01, 20.0, 1.0);
    assert_float_equal(r.meter_rpm[TD_LOWER], 20.0, 1.0);
    assert_float_equal(r.meter_rpm[TD_UPPER], 0.0, 1e-9); /* the other layer stays still */
    assert_false(rig_st(&r)->running);
    assert_int_equal(s.frames, 100); /* every status period (100 ms) + the start */
    run_collect(&r, 25000, &s);
    assert_int_equal(s.last.cal_state, TD_CAL_DONE);
    assert_int_equal(s.last.cal_reason, TD_CAL_R_NONE);
    assert_float_equal(r.meter_rpm[TD_LOWER], 0.0, 1e-3); /* stopped */
    /* what turned, as the plant saw it (coast after the stop included), is what is reported */
    const double plant_rev = r.meter_pos[TD_LOWER] / r.p.meter_counts_per_rev;
    assert_true(plant_rev >= 10.0 && plant_rev < 10.3);
    assert_float_equal(status_rev(&s), plant_rev, 0.002);
    assert_true(r.meter_pos[TD_UPPER] < 1.0);
    /* a reset after the test: one idle frame, then silence */
    const td_can_frame_t reset = cal_frame(0, 0, 0.0, 0.0, 8);
    assert_int_equal(td_app_rx(&r.app, &reset, r.now_us), TD_OK);
    cal_seen_t after = { 0 };
    run_collect(&r, 1000, &after);
    assert_int_equal(after.frames, 1);
    assert_int_equal(after.last.cal_state, TD_CAL_IDLE);
    assert_int_equal(after.last.cal_seq, 8);
}

static void test_refused_while_running(void **state) {
    (void)state;
    rig_t r;
    rig_start_working(&r, NULL, 0u);
    const float before = rig_st(&r)->meter_rpm[TD_UPPER];
    const td_can_frame_t f = cal_frame(1, TD_UPPER, 10.0, 20.0, 1);
    assert_int_equal(td_app_rx(&r.app, &f, r.now_us), TD_OK);
    cal_seen_t s = { 0 };
    run_collect(&r, 500, &s);
    assert_int_equal(s.last.cal_state, TD_CAL_ABORTED);
    assert_int_equal(s.last.cal_reason, TD_CAL_R_RUNNING);
    assert_float_equal(rig_st(&r)->meter_rpm[TD_UPPER], before, 0.05 * before); /* work goes on */
}

/* The look-ahead test: only with a start command in force, so the fans run; the machine stands,
 * so the meters' own control holds them at 0 and only the layer under test turns. */
static void test_lead_test_runs_with_the_fans_and_a_stop_aborts_it(void **state) {
    (void)state;
    rig_t r;
    rig_standing(&r);
    const td_can_frame_t early = cal_frame(2, TD_UPPER, 2.0, 20.0, 3);
    assert_int_equal(td_app_rx(&r.app, &early, r.now_us), TD_OK);
    cal_seen_t s = { 0 };
    run_collect(&r, 300, &s);
    assert_int_equal(s.last.cal_state, TD_CAL_ABORTED); /* stopped: no fans, no air line */
    assert_int_equal(s.last.cal_reason, TD_CAL_R_FANS_OFF);
    r.pc_start = true;
    run_collect(&r, 5000, &s); /* the fans spin up; standing, nothing is metered */
    assert_true(r.fan_rpm[TD_UPPER] > 0.9 * r.pc_fan_rpm);
    assert_float_equal(r.meter_rpm[TD_UPPER], 0.0, 1e-9);
    const td_can_frame_t f = cal_frame(2, TD_UPPER, 2.0, 20.0, 4);
    assert_int_equal(td_app_rx(&r.app, &f, r.now_us), TD_OK);
    run_collect(&r, 3000, &s);
    assert_int_equal(s.last.cal_state, TD_CAL_RUNNING);
    assert_int_equal(s.last.cal_seq, 4);
    assert_float_equal(r.meter_rpm[TD_UPPER], 20.0, 1.0);
    assert_float_equal(r.meter_rpm[TD_LOWER], 0.0, 1e-9);
    assert_true(r.fan_rpm[TD_UPPER] > 0.9 * r.pc_fan_rpm); /* the fans keep running */
    r.pc_start = false; /* stop: the fans go off, the test ends */
    run_collect(&r, 1000, &s);
    assert_int_equal(s.last.cal_state, TD_CAL_ABORTED);
    assert_int_equal(s.last.cal_reason, TD_CAL_R_FANS_OFF);
    assert_float_equal(r.out.meter_duty[TD_UPPER], 0.0, 1e-9);
}

static void test_start_command_aborts_the_test(void **state) {
    (void)state;
    rig_t r;
    rig_standing(&r);
    const td_can_frame_t f = cal_frame(1, TD_UPPER, 10.0, 20.0, 1);
    assert_int_equal(td_app_rx(&r.app, &f, r.now_us), TD_OK);
    cal_seen_t s = { 0 };
    run_collect(&r, 3000, &s);
    assert_int_equal(s.last.cal_state, TD_CAL_RUNNING);
    r.pc_start = true; /* standing: with start the meters stay at zero (no speed) */
    run_collect(&r, 1000, &s);
    assert_int_equal(s.last.cal_state, TD_CAL_ABORTED);
    assert_int_equal(s.last.cal_reason, TD_CAL_R_RUNNING);
    assert_float_equal(r.out.meter_duty[TD_UPPER], 0.0, 1e-9);
    assert_float_equal(r.meter_rpm[TD_UPPER], 0.0, 0.05); /* coasting out, first order */
}

static void test_moving_machine_aborts_the_test(void **state) {
    (void)state;
    rig_t r;
    rig_standing(&r);
    const td_can_frame_t f = cal_frame(1, TD_UPPER, 50.0, 20.0, 1);
    assert_int_equal(td_app_rx(&r.app, &f, r.now_us), TD_OK);
    cal_seen_t s = { 0 };
    run_collect(&r, 2000, &s);
    assert_int_equal(s.last.cal_state, TD_CAL_RUNNING);
    r.wheel_kmh = 2.0;
    run_collect(&r, 1500, &s); /* the wheel speed is updated every 500 ms */
    assert_int_equal(s.last.cal_state, TD_CAL_ABORTED);
    assert_int_equal(s.last.cal_reason, TD_CAL_R_MOVING);
    assert_float_equal(r.meter_rpm[TD_UPPER], 0.0, 0.5);
}

static void test_blocked_meter_aborts_after_blocked_time(void **state) {
    (void)state;
    rig_t r;
    rig_standing(&r);
    r.meter_blocked[TD_UPPER] = true;
    const td_can_frame_t f = cal_frame(1, TD_UPPER, 10.0, 20.0, 1);
    assert_int_equal(td_app_rx(&r.app, &f, r.now_us), TD_OK);
    cal_seen_t s = { 0 };
    /* the duty ramps past 0.3 within a few tenths; then blocked_time_ms (default 1000) */
    run_collect(&r, 900, &s);
    assert_int_equal(s.last.cal_state, TD_CAL_RUNNING);
    run_collect(&r, 1000, &s);
    assert_int_equal(s.last.cal_state, TD_CAL_ABORTED);
    assert_int_equal(s.last.cal_reason, TD_CAL_R_BLOCKED);
    assert_float_equal(r.out.meter_duty[TD_UPPER], 0.0, 1e-9);
}

static void test_reset_aborts_a_running_test(void **state) {
    (void)state;
    rig_t r;
    rig_standing(&r);
    const td_can_frame_t f = cal_frame(1, TD_UPPER, 10.0, 20.0, 1);
    assert_int_equal(td_app_rx(&r.app, &f, r.now_us), TD_OK);
    cal_seen_t s = { 0 };
    run_collect(&r, 3000, &s);
    const td_can_frame_t reset = cal_frame(0, 0, 0.0, 0.0, 2);
    assert_int_equal(td_app_rx(&r.app, &reset, r.now_us), TD_OK);
    run_collect(&r, 1000, &s);
    assert_int_equal(s.last.cal_state, TD_CAL_ABORTED);
    assert_int_equal(s.last.cal_reason, TD_CAL_R_RESET);
    assert_int_equal(s.last.cal_seq, 2);
    assert_float_equal(r.out.meter_duty[TD_UPPER], 0.0, 1e-9);
    assert_float_equal(r.meter_rpm[TD_UPPER], 0.0, 0.05);
    const double rev = status_rev(&s);
    assert_true(rev > 0.5 && rev < 1.2); /* about 3 s at 20 r/min, with the ramp */
}

static void test_bad_values_and_bad_frames(void **state) {
    (void)state;
    rig_t r;
    rig_standing(&r);
    cal_seen_t s = { 0 };
    td_can_frame_t f = cal_frame(1, TD_UPPER, 0.0, 20.0, 1); /* no revolutions */
    assert_int_equal(td_app_rx(&r.app, &f, r.now_us), TD_OK);
    run_collect(&r, 200, &s);
    assert_int_equal(s.last.cal_state, TD_CAL_ABORTED);
    assert_int_equal(s.last.cal_reason, TD_CAL_R_BAD_VALUE);
    f = cal_frame(1, TD_UPPER, 10.0, 200.0, 1); /* faster than TD_CAL_MAX_RPM */
    assert_int_equal(td_app_rx(&r.app, &f, r.now_us), TD_OK);
    run_collect(&r, 200, &s);
    assert_int_equal(s.last.cal_reason, TD_CAL_R_BAD_VALUE);
    assert_float_equal(r.meter_rpm[TD_UPPER], 0.0, 1e-9);
    const uint32_t ok_before = r.app.cnt.rx_ok;
    f = cal_frame(1, TD_UPPER, 10.0, 20.0, 1);
    f.dlc = 7u;
    assert_int_equal(td_app_rx(&r.app, &f, r.now_us), TD_E_LENGTH);
    assert_int_equal(r.app.cnt.rx_bad_length, 1u);
    f = cal_frame(1, TD_UPPER, 10.0, 20.0, 1);
    f.data[0] = 3u; /* undefined action */
    assert_int_equal(td_app_rx(&r.app, &f, r.now_us), TD_E_RANGE);
    f = cal_frame(1, TD_UPPER, 10.0, 20.0, 1);
    f.data[1] = 2u; /* no third layer */
    assert_int_equal(td_app_rx(&r.app, &f, r.now_us), TD_E_RANGE);
    assert_int_equal(r.app.cnt.rx_out_of_range, 2u);
    assert_true(r.app.cnt.rx_ok > ok_before - 1u); /* stop commands went on being taken */
    run_collect(&r, 1000, &s);
    assert_float_equal(r.meter_rpm[TD_UPPER], 0.0, 1e-9); /* nothing started */
}

static void test_calibration_ids_cannot_be_configured_for_other_frames(void **state) {
    (void)state;
    td_params_t p;
    td_params_default(&p);
    p.command_id = TD_ID_PC_CAL_COMMAND; /* a catch test would be taken for a command */
    assert_int_equal(td_params_validate(&p), TD_E_INCONSISTENT);
    td_params_default(&p);
    p.status_id = TD_ID_ECU_CAL_STATUS;
    assert_int_equal(td_params_validate(&p), TD_E_INCONSISTENT);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_catch_test_runs_the_revolutions_standing_and_counts_the_coast),
        cmocka_unit_test(test_refused_while_running),
        cmocka_unit_test(test_start_command_aborts_the_test),
        cmocka_unit_test(test_lead_test_runs_with_the_fans_and_a_stop_aborts_it),
        cmocka_unit_test(test_moving_machine_aborts_the_test),
        cmocka_unit_test(test_blocked_meter_aborts_after_blocked_time),
        cmocka_unit_test(test_reset_aborts_a_running_test),
        cmocka_unit_test(test_bad_values_and_bad_frames),
        cmocka_unit_test(test_calibration_ids_cannot_be_configured_for_other_frames),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
