/* Parameters: paper defaults, DBC ranges (checked against the generated codec), cross-constraints. */
#include "td_test.h"

#include "td_can.h"
#include "td_params.h"

static void test_defaults_are_the_papers(void **state) {
    (void)state;
    td_params_t p;
    td_params_default(&p);
    assert_int_equal(td_params_validate(&p), TD_OK);
    assert_float_equal(p.working_width_m, 3.6, 1e-6);
    assert_float_equal(p.wheel_radius_m, 0.0615, 1e-7);
    assert_int_equal(p.wheel_ppr, 500);
    assert_int_equal(p.queue_len, 5);
    assert_float_equal(p.cv_threshold_pct, 4.2, 1e-6);
    assert_float_equal(p.switch_speed_kmh, 6.0, 1e-6);
    assert_int_equal(p.wheel_update_ms, 500);
    assert_int_equal(p.wheel_samples, 4);
    assert_int_equal(p.cmd_timeout_ms, 1500);
    assert_int_equal(p.status_period_ms, 100);
    assert_float_equal(p.pid_kff, 1.0 / 60.0, 1e-7);
    assert_int_equal(p.status_id, 0x185C6465u);
    assert_int_equal(p.command_id, 0x0A5C6465u);
}

static void test_set_get_round_trip_every_id(void **state) {
    (void)state;
    td_params_t p;
    td_params_default(&p);
    for (uint8_t id = 1; id <= TD_PARAM_COUNT; id++) {
        float v = -1.0f;
        assert_int_equal(td_params_get(&p, id, &v), TD_OK);
        assert_int_equal(td_params_set(&p, id, v), TD_OK);
        float w = -2.0f;
        assert_int_equal(td_params_get(&p, id, &w), TD_OK);
        assert_float_equal(v, w, 1e-6);
    }
    assert_int_equal(td_params_set(&p, 1, 4.5f), TD_OK);
    assert_float_equal(p.working_width_m, 4.5, 1e-6);
    assert_int_equal(td_params_set(&p, 5, 1000.0f), TD_OK);
    assert_int_equal(p.wheel_ppr, 1000);
}

static void test_range_boundaries(void **state) {
    (void)state;
    td_params_t p;
    td_params_default(&p);
    assert_int_equal(td_params_set(&p, 1, 0.5f), TD_OK);
    assert_int_equal(td_params_set(&p, 1, 30.0f), TD_OK);
    assert_int_equal(td_params_set(&p, 1, 0.49f), TD_E_RANGE);
    assert_int_equal(td_params_set(&p, 1, 30.01f), TD_E_RANGE);
    assert_int_equal(td_params_set(&p, 1, NAN), TD_E_RANGE);
    assert_float_equal(p.working_width_m, 30.0, 1e-5); /* unchanged by the refusals */
    assert_int_equal(td_params_set(&p, 8, 0.1f), TD_OK);
    assert_int_equal(td_params_set(&p, 8, 0.09f), TD_E_RANGE);
    assert_int_equal(td_params_set(&p, 10, 2.0f), TD_OK);
    assert_int_equal(td_params_set(&p, 10, 3.0f), TD_OK); /* fused */
    assert_int_equal(td_params_set(&p, 10, 4.0f), TD_E_RANGE);
    assert_int_equal(td_params_set(&p, 16, 99.0f), TD_E_RANGE);
    assert_int_equal(td_params_set(&p, 27, 1001.0f), TD_E_RANGE);
    assert_int_equal(td_params_set(&p, 12, -0.001f), TD_E_RANGE);
    assert_int_equal(td_params_set(&p, 0, 1.0f), TD_E_UNKNOWN_PARAM);
    assert_int_equal(td_params_set(&p, 38, 5000.0f), TD_OK); /* LeadStop */
    assert_int_equal(td_params_set(&p, 38, 5001.0f), TD_E_RANGE);
    assert_int_equal(td_params_set(&p, 39, 0.0f), TD_OK); /* GnssLagAuto */
    assert_int_equal(td_params_set(&p, 39, 2.0f), TD_E_RANGE);
    assert_int_equal(td_params_set(&p, 40, 1.0f), TD_E_UNKNOWN_PARAM);
    float v;
    assert_int_equal(td_params_get(&p, 40, &v), TD_E_UNKNOWN_PARAM);
    assert_int_equal(td_params_set(&p, 28, 2.0f), TD_OK); /* slip compensation by eq. 5 */
    assert_int_equal(td_params_set(&p, 28, 3.0f), TD_E_RANGE);
    assert_int_equal(td_params_set(&p, 32, 0.0f), TD_E_RANGE); /* the filter needs process noise */
    assert_int_equal(td_params_set(&p, 35, 19.0f), TD_E_RANGE);
    assert_int_equal(td_params_validate(NULL), TD_E_ARG);
}

static void test_cv_window_not_above_queue_length(void **state) {
    (void)state;
    td_params_t p;
    td_params_default(&p);
    assert_int_equal(td_params_set(&p, 7, 6.0f), TD_E_INCONSISTENT);
    assert_int_equal(p.cv_window, 5);
    assert_int_equal(td_params_set(&p, 6, 3.0f), TD_E_INCONSISTENT);
    assert_int_equal(p.queue_len, 5);
    /* shrink n first, then N */
    assert_int_equal(td_params_set(&p, 7, 3.0f), TD_OK);
    assert_int_equal(td_params_set(&p, 6, 3.0f), TD_OK);
    assert_int_equal(p.queue_len, 3);
    p.cv_window = 4;
    assert_int_equal(td_params_validate(&p), TD_E_INCONSISTENT);
    td_params_default(&p);
    p.command_id = p.status_id;
    assert_int_equal(td_params_validate(&p), TD_E_INCONSISTENT);
    /* a PcParamSet would be taken for a command; a status would look like a diagnostic frame */
    td_params_default(&p);
    p.command_id = TD_ID_PC_PARAM_SET;
    assert_int_equal(td_params_validate(&p), TD_E_INCONSISTENT);
    td_params_default(&p);
    p.status_id = TD_ID_ECU_DIAG;
    assert_int_equal(td_params_validate(&p), TD_E_INCONSISTENT);
    td_params_default(&p);
    p.command_id = 0x20000000u;
    assert_int_equal(td_params_validate(&p), TD_E_RANGE);
    td_params_default(&p);
    p.fan_rpm_at_full_duty = 0.0f;
    assert_int_equal(td_params_validate(&p), TD_E_RANGE);
    p.fan_rpm_at_full_duty = INFINITY;
    assert_int_equal(td_params_validate(&p), TD_E_RANGE);
    p.fan_rpm_at_full_duty = 60000.0f;
    assert_int_equal(td_params_validate(&p), TD_OK);
}

typedef bool (*in_range_fn)(uint32_t);
typedef float (*decode_fn)(uint32_t);

#define GEN(name) { td_can_pc_param_set_##name##_is_in_range, td_can_pc_param_set_##name##_decode }
static const struct {
    in_range_fn in_range;
    decode_fn decode;
} k_gen[TD_PARAM_COUNT] = {
    GEN(working_width), GEN(upper_kg_per_rev), GEN(lower_kg_per_rev), GEN(wheel_radius),
    GEN(wheel_pulses_per_rev), GEN(queue_length), GEN(cv_window), GEN(cv_threshold),
    GEN(switch_speed), GEN(speed_mode), GEN(switch_compare), GEN(pid_kp), GEN(pid_ki),
    GEN(pid_kd), GEN(pid_kff), GEN(cmd_timeout), GEN(gnss_timeout), GEN(min_work_speed),
    GEN(wheel_update_period), GEN(wheel_samples), GEN(meter_counts_per_rev), GEN(fan_min_speed),
    GEN(fan_pulses_per_rev), GEN(enc_fault_gnss_speed), GEN(enc_fault_time), GEN(blocked_time),
    GEN(status_period), GEN(slip_comp), GEN(gnss_lag), GEN(lead_meter), GEN(lead_air_line),
    GEN(fused_jerk), GEN(fused_gnss_std), GEN(fused_wheel_noise), GEN(wheel_stop_time),
    GEN(drive_adapt), GEN(meter_tau), GEN(lead_stop), GEN(gnss_lag_auto),
};

/* The range table of td_params.c is the DBC's: same scale and raw limits as the generated codec. */
static void test_table_matches_generated_codec(void **state) {
    (void)state;
    for (uint8_t id = 1; id <= TD_PARAM_COUNT; id++) {
        float scale;
        uint32_t lo, hi;
        assert_int_equal(td_params_encoding(id, &scale, &lo, &hi), TD_OK);
        const in_range_fn in_range = k_gen[id - 1].in_range;
        assert_true(in_range(lo));
        assert_true(in_range(hi));
        assert_false(in_range(hi + 1u));
        if (lo > 0u) {
            assert_false(in_range(lo - 1u));
        }
        assert_float_equal(k_gen[id - 1].decode(1000u), 1000.0f * scale, 1e-6);
        /* and td_params_set accepts exactly that range */
        td_params_t p;
        td_params_default(&p);
        p.queue_len = 16; /* let the CV window take its whole range */
        assert_int_equal(td_params_set(&p, id, (float)hi * scale), TD_OK);
        td_params_default(&p);
        p.queue_len = 16;
        assert_int_equal(td_params_set(&p, id, (float)(hi + 1u) * scale), TD_E_RANGE);
        if (id != 6u) { /* N at its minimum needs n lowered first */
            assert_int_equal(td_params_set(&p, id, (float)lo * scale), TD_OK);
        }
    }
    assert_int_equal(td_params_encoding(0, NULL, NULL, NULL), TD_E_UNKNOWN_PARAM);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_defaults_are_the_papers),
        cmocka_unit_test(test_set_get_round_trip_every_id),
        cmocka_unit_test(test_range_boundaries),
        cmocka_unit_test(test_cv_window_not_above_queue_length),
        cmocka_unit_test(test_table_matches_generated_codec),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
