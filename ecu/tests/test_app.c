/* The ECU application through its port: dual speed in closed loop, every fail-safe, bad frames,
 * parameter frames and their acks, the periodic frames and the transmit queue. */
#include "td_test.h"

#include "td_meter.h"

static const float k_up_target_8kmh = 3.6f * 200.0f * 8.0f / (600.0f * 0.3f); /* 32 r/min */
static const float k_lo_target_8kmh = 3.6f * 150.0f * 8.0f / (600.0f * 0.3f); /* 24 r/min */

static void test_uniform_8kmh_meters_on_gnss_across_clock_wrap(void **state) {
    (void)state;
    rig_t r;
    rig_start_working(&r, NULL, 0xFFFFFFFFu - 3000000u); /* the microsecond clock wraps 3 s in */
    const td_state_t *st = rig_st(&r);
    assert_true(st->running);
    assert_int_equal(st->faults, 0);
    assert_true(st->uniform);
    assert_true(st->cv_pct >= 0.0f && st->cv_pct < 1.0f);
    assert_int_equal(st->source, TD_SRC_GNSS);
    assert_float_equal(st->v_kmh, 8.0, 1e-4);
    assert_float_equal(st->v_wheel_kmh, 7.44, 0.05);
    assert_float_equal(st->target_rpm[TD_UPPER], k_up_target_8kmh, 1e-3);
    assert_float_equal(st->target_rpm[TD_LOWER], k_lo_target_8kmh, 1e-3);
    assert_float_equal(st->meter_rpm[TD_UPPER], k_up_target_8kmh, 0.02 * k_up_target_8kmh);
    assert_float_equal(st->meter_rpm[TD_LOWER], k_lo_target_8kmh, 0.02 * k_lo_target_8kmh);
    assert_float_equal(r.meter_rpm[TD_UPPER], k_up_target_8kmh, 0.02 * k_up_target_8kmh);
    assert_float_equal(st->fan_rpm[TD_UPPER], 3000.0, 60.0);
    assert_float_equal(st->fan_rpm[TD_LOWER], 3000.0, 60.0);
    assert_int_equal(st->wheel_updates, 11u); /* steps at 0..5.99 s: updates at 0.5..5.5 s */
    /* cumulative pulses up to the count read at 5.99 s: 7.44 km/h on 500 PPR, r = 0.0615 m */
    assert_float_equal((double)st->wheel_pulses, 7.44 / 3.6 / (2 * PI_D * 0.0615) * 500 * 5.99, 2.0);
}

static void test_below_switch_speed_meters_on_wheel(void **state) {
    (void)state;
    rig_t r;
    rig_start(&r, NULL, 0u, 4.0, 3.9);
    rig_run_ms(&r, 5000);
    const td_state_t *st = rig_st(&r);
    assert_true(st->uniform);
    assert_int_equal(st->source, TD_SRC_WHEEL);
    assert_float_equal(st->v_kmh, 3.9, 0.03);
    assert_float_equal(st->target_rpm[TD_UPPER], 3.6 * 200 * 3.9 / 180.0, 0.1);
}

static void test_acceleration_meters_on_wheel_until_uniform(void **state) {
    (void)state;
    rig_t r;
    rig_init(&r, NULL, 0u);
    r.pc_start = true;
    /* accelerate at 1 km/h per s to 8 km/h, then hold */
    bool gnss_while_accelerating = false;
    for (int i = 0; i < 1200; i++) {
        const double v = i < 800 ? i * 0.01 : 8.0;
        r.wheel_kmh = v;
        r.pc_gnss_kmh = v;
        rig_step(&r);
        (void)rig_drain(&r, 0u);
        if (i < 800 && rig_st(&r)->source == TD_SRC_GNSS) {
            gnss_while_accelerating = true;
        }
    }
    assert_false(gnss_while_accelerating);
    /* 4 s later the queue holds only steady values: uniform, above 6 km/h -> GNSS */
    rig_run_ms(&r, 2000);
    assert_int_equal(rig_st(&r)->source, TD_SRC_GNSS);
}

static void test_command_timeout_at_1500ms(void **state) {
    (void)state;
    rig_t r;
    r.wheel_kmh = 8.0;
    rig_start_working(&r, NULL, 1000u);
    r.wheel_kmh = 8.0;
    r.pc_sending = false;
    /* step until exactly 1.5 s after the last command */
    while (r.now_us != r.last_cmd_sent_us + 1500000u) {
        rig_step(&r);
        (void)rig_drain(&r, 0u);
    }
    rig_step(&r);
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_CMD_TIMEOUT, 0);
    assert_true(r.out.meter_duty[TD_UPPER] > 0.1f);
    rig_step(&r); /* 1.51 s */
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_CMD_TIMEOUT, TD_FAULT_CMD_TIMEOUT);
    assert_float_equal(r.out.meter_duty[TD_UPPER], 0.0, 0.0);
    assert_float_equal(r.out.meter_duty[TD_LOWER], 0.0, 0.0);
    assert_float_equal(rig_st(&r)->target_rpm[TD_UPPER], 0.0, 0.0);
    /* the PC comes back: the fault clears and metering resumes */
    r.pc_sending = true;
    r.next_cmd_us = r.now_us;
    rig_step(&r);
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_CMD_TIMEOUT, 0);
    assert_true(r.out.meter_duty[TD_UPPER] > 0.1f);
}

static void test_gnss_not_available_and_stale(void **state) {
    (void)state;
    rig_t r;
    rig_start_working(&r, NULL, 0u);
    assert_int_equal(rig_st(&r)->source, TD_SRC_GNSS);
    /* 0xFF: wheel at once, no waiting for the stale timeout */
    r.pc_gnss_kmh = -1.0;
    r.next_cmd_us = r.now_us;
    rig_step(&r);
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_GNSS_LOST, TD_FAULT_GNSS_LOST);
    assert_false(rig_st(&r)->gnss_valid);
    assert_int_equal(rig_st(&r)->source, TD_SRC_WHEEL);
    assert_float_equal(rig_st(&r)->v_kmh, 7.44, 0.05);
    assert_true(r.out.meter_duty[TD_UPPER] > 0.1f); /* still metering, on the wheel */
    /* GNSS back: valid at once, the source follows the rule at the next wheel update */
    r.pc_gnss_kmh = 8.0;
    rig_run_ms(&r, 1000);
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_GNSS_LOST, 0);
    assert_int_equal(rig_st(&r)->source, TD_SRC_GNSS);
    /* stale: valid exactly 1.2 s after the last GNSS value, lost 10 ms later */
    r.pc_sending = false;
    while (r.now_us != r.last_cmd_sent_us + 1200000u) {
        rig_step(&r);
    }
    rig_step(&r);
    assert_true(rig_st(&r)->gnss_valid);
    assert_int_equal(rig_st(&r)->source, TD_SRC_GNSS);
    rig_step(&r);
    assert_false(rig_st(&r)->gnss_valid);
    assert_int_equal(rig_st(&r)->source, TD_SRC_WHEEL);
}

/* Run until the wheel speed reads below 0.2 km/h; returns that time. */
static uint32_t run_until_wheel_zero(rig_t *r) {
    for (int i = 0; i < 300; i++) {
        rig_step(r);
        (void)rig_drain(r, 0u);
        if (rig_st(r)->v_wheel_kmh < 0.2f) {
            return r->now_us - r->step_us;
        }
    }
    fail_msg("wheel speed never dropped");
    return 0u;
}

static void test_encoder_fault_after_2s_latched_until_stop(void **state) {
    (void)state;
    rig_t r;
    rig_start_working(&r, NULL, 0u);
    r.pc_gnss_jitter_kmh = 0.1; /* a live receiver: its speed moves by a digit now and then */
    r.wheel_kmh = 0.0;          /* encoder cable cut */
    const uint32_t t_zero = run_until_wheel_zero(&r);
    while (r.now_us != t_zero + 2000000u) {
        rig_step(&r);
        (void)rig_drain(&r, 0u);
    }
    rig_step(&r); /* exactly 2.0 s: not yet */
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_WHEEL_ENCODER, 0);
    rig_step(&r); /* 2.01 s */
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_WHEEL_ENCODER, TD_FAULT_WHEEL_ENCODER);
    assert_int_equal(rig_st(&r)->source, TD_SRC_GNSS);
    assert_float_equal(rig_st(&r)->v_kmh, 8.05, 0.05 + 1e-4);
    rig_run_ms(&r, 1000);
    assert_float_equal(rig_st(&r)->meter_rpm[TD_UPPER], k_up_target_8kmh, 0.03 * k_up_target_8kmh);
    /* the wheel turning again does not clear a latched fault */
    r.wheel_kmh = 8.0;
    rig_run_ms(&r, 3000);
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_WHEEL_ENCODER, TD_FAULT_WHEEL_ENCODER);
    assert_int_equal(rig_st(&r)->source, TD_SRC_GNSS);
    /* a stop command acknowledges it */
    r.pc_start = false;
    r.next_cmd_us = r.now_us;
    rig_step(&r);
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_WHEEL_ENCODER, 0);
    assert_false(rig_st(&r)->running);
}

static void test_encoder_fault_overrides_wheel_only_mode(void **state) {
    (void)state;
    td_params_t p;
    td_params_default(&p);
    p.speed_mode = TD_MODE_WHEEL_ONLY;
    rig_t r;
    rig_init(&r, &p, 0u);
    r.pc_start = true;
    r.pc_gnss_kmh = 8.0;
    r.pc_gnss_jitter_kmh = 0.1;
    r.wheel_kmh = 7.44;
    rig_run_ms(&r, 4000);
    assert_int_equal(rig_st(&r)->source, TD_SRC_WHEEL);
    r.wheel_kmh = 0.0;
    (void)run_until_wheel_zero(&r);
    rig_run_ms(&r, 1500);
    assert_int_equal(rig_st(&r)->source, TD_SRC_WHEEL); /* wheel only: meters stopped at 0 km/h */
    assert_float_equal(r.out.meter_duty[TD_UPPER], 0.0, 0.0);
    rig_run_ms(&r, 600);
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_WHEEL_ENCODER, TD_FAULT_WHEEL_ENCODER);
    assert_int_equal(rig_st(&r)->source, TD_SRC_GNSS);
    assert_true(r.out.meter_duty[TD_UPPER] > 0.1f);
}

static void test_no_speed_when_both_sources_fail(void **state) {
    (void)state;
    rig_t r;
    rig_start_working(&r, NULL, 0u);
    r.pc_gnss_jitter_kmh = 0.1;
    r.wheel_kmh = 0.0;
    rig_run_ms(&r, 4000);
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_WHEEL_ENCODER, TD_FAULT_WHEEL_ENCODER);
    r.pc_gnss_kmh = -1.0;
    r.next_cmd_us = r.now_us;
    rig_step(&r);
    const td_state_t *st = rig_st(&r);
    assert_int_equal(st->source, TD_SRC_NONE);
    assert_int_equal(st->faults & TD_FAULT_NO_SPEED, TD_FAULT_NO_SPEED);
    assert_float_equal(st->v_kmh, 0.0, 0.0);
    assert_float_equal(r.out.meter_duty[TD_UPPER], 0.0, 0.0);
    assert_float_equal(r.out.meter_duty[TD_LOWER], 0.0, 0.0);
}

static void test_blocked_meter_stops_that_motor_only(void **state) {
    (void)state;
    rig_t r;
    rig_start_working(&r, NULL, 0u);
    r.meter_blocked[TD_UPPER] = true;
    int k = 0;
    while (!r.app.blocked_suspect[TD_UPPER]) {
        rig_step(&r);
        (void)rig_drain(&r, 0u);
        assert_true(++k < 100);
    }
    const uint32_t since = r.now_us - r.step_us;
    while (r.now_us != since + 1000000u) {
        rig_step(&r);
        (void)rig_drain(&r, 0u);
    }
    rig_step(&r); /* 1.0 s of commanded-but-still: not yet */
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_UPPER_BLOCKED, 0);
    assert_true(r.out.meter_duty[TD_UPPER] >= 0.3f);
    rig_step(&r); /* 1.01 s */
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_UPPER_BLOCKED, TD_FAULT_UPPER_BLOCKED);
    assert_float_equal(r.out.meter_duty[TD_UPPER], 0.0, 0.0);
    /* latched even when the jam clears; the lower meter keeps working */
    r.meter_blocked[TD_UPPER] = false;
    rig_run_ms(&r, 2000);
    const td_state_t *st = rig_st(&r);
    assert_int_equal(st->faults & TD_FAULT_UPPER_BLOCKED, TD_FAULT_UPPER_BLOCKED);
    assert_int_equal(st->faults & TD_FAULT_LOWER_BLOCKED, 0);
    assert_float_equal(r.out.meter_duty[TD_UPPER], 0.0, 0.0);
    assert_float_equal(st->meter_rpm[TD_LOWER], k_lo_target_8kmh, 0.03 * k_lo_target_8kmh);
    /* stop clears it, the next start meters again */
    r.pc_start = false;
    r.next_cmd_us = r.now_us;
    rig_step(&r);
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_UPPER_BLOCKED, 0);
    r.pc_start = true;
    r.next_cmd_us = r.now_us;
    rig_run_ms(&r, 3000);
    assert_float_equal(rig_st(&r)->meter_rpm[TD_UPPER], k_up_target_8kmh, 0.03 * k_up_target_8kmh);
}

static void test_fan_low_gates_its_layer(void **state) {
    (void)state;
    rig_t r;
    rig_start(&r, NULL, 0u, 8.0, 8.0);
    r.fan_broken[TD_UPPER] = true;
    bool upper_ever_metered = false;
    for (int i = 0; i < 300; i++) { /* the 3 s spin-up grace: gated but no fault bit */
        rig_step(&r);
        (void)rig_drain(&r, 0u);
        upper_ever_metered = upper_ever_metered || r.out.meter_duty[TD_UPPER] > 0.0f;
        assert_int_equal(rig_st(&r)->faults & TD_FAULT_UPPER_FAN_LOW, 0);
    }
    rig_run_ms(&r, 100);
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_UPPER_FAN_LOW, TD_FAULT_UPPER_FAN_LOW);
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_LOWER_FAN_LOW, 0);
    rig_run_ms(&r, 2000);
    assert_false(upper_ever_metered);
    assert_float_equal(r.out.meter_duty[TD_UPPER], 0.0, 0.0);
    assert_float_equal(rig_st(&r)->target_rpm[TD_UPPER], 0.0, 0.0);
    assert_true(r.out.fan_duty[TD_UPPER] > 0.5f); /* still trying */
    assert_float_equal(rig_st(&r)->meter_rpm[TD_LOWER], k_lo_target_8kmh, 0.03 * k_lo_target_8kmh);
    /* repaired: the bit clears by itself and the layer meters */
    r.fan_broken[TD_UPPER] = false;
    rig_run_ms(&r, 3000);
    assert_int_equal(rig_st(&r)->faults & TD_FAULT_UPPER_FAN_LOW, 0);
    assert_float_equal(rig_st(&r)->meter_rpm[TD_UPPER], k_up_target_8kmh, 0.03 * k_up_target_8kmh);
}

static void test_stop_command_stops_motors_and_fans(void **state) {
    (void)state;
    rig_t r;
    rig_start_working(&r, NULL, 0u);
    assert_true(r.out.meter_duty[TD_UPPER] > 0.1f);
    r.pc_start = false;
    r.next_cmd_us = r.now_us;
    rig_step(&r);
    assert_false(rig_st(&r)->running);
    for (int l = 0; l < 2; l++) {
        assert_float_equal(r.out.meter_duty[l], 0.0, 0.0);
        assert_float_equal(r.out.fan_duty[l], 0.0, 0.0);
        /* controllers restart clean on the next start */
        assert_float_equal(r.app.meter_drive[l].pid.integ, 0.0, 0.0);
        assert_false(r.app.meter_drive[l].pid.primed);
    }
}

static void test_headland_stop_meters_reach_zero(void **state) {
    (void)state;
    rig_t r;
    rig_start(&r, NULL, 0u, 4.0, 4.0);
    rig_run_ms(&r, 4000);
    assert_true(r.out.meter_duty[TD_UPPER] > 0.1f);
    /* the tractor stops at the headland; the PC keeps the ECU running */
    r.pc_gnss_kmh = 0.0;
    r.wheel_kmh = 0.0;
    rig_run_ms(&r, 1000);
    const td_state_t *st = rig_st(&r);
    assert_true(st->running);
    assert_true(st->v_kmh < 0.5f);
    assert_float_equal(st->target_rpm[TD_UPPER], 0.0, 0.0);
    assert_float_equal(r.out.meter_duty[TD_UPPER], 0.0, 0.0);
    assert_float_equal(r.out.meter_duty[TD_LOWER], 0.0, 0.0);
}

static td_can_frame_t frame8(uint32_t id, const uint8_t *d) {
    td_can_frame_t f;
    f.id = id;
    f.extended = 1u;
    f.dlc = 8u;
    memcpy(f.data, d, 8);
    return f;
}

static void test_malformed_frames_counted_never_acted_on(void **state) {
    (void)state;
    rig_t r;
    rig_init(&r, NULL, 0u);
    const uint8_t start8[8] = { 0x0A, 0xB8, 0x0B, 0x20, 0x4E, 0x98, 0x3A, 80 };
    td_can_frame_t f = frame8(0x123u, start8);
    assert_int_equal(td_app_rx(&r.app, &f, 0u), TD_E_UNKNOWN_ID);
    f = frame8(TD_ID_PC_COMMAND, start8);
    f.extended = 0u; /* an 11-bit frame is another identifier */
    assert_int_equal(td_app_rx(&r.app, &f, 0u), TD_E_UNKNOWN_ID);
    f = frame8(TD_ID_ECU_STATUS, start8); /* our own frame echoed back */
    assert_int_equal(td_app_rx(&r.app, &f, 0u), TD_E_UNKNOWN_ID);
    f = frame8(TD_ID_PC_COMMAND, start8);
    f.dlc = 6u;
    assert_int_equal(td_app_rx(&r.app, &f, 0u), TD_E_LENGTH);
    f = frame8(TD_ID_PC_COMMAND, start8);
    f.data[0] = 0x05;
    assert_int_equal(td_app_rx(&r.app, &f, 0u), TD_E_RANGE);
    f = frame8(TD_ID_PC_COMMAND, start8);
    f.data[7] = 0xFC;
    assert_int_equal(td_app_rx(&r.app, &f, 0u), TD_E_RANGE);
    f = frame8(TD_ID_PC_COMMAND, start8);
    f.data[3] = 0x61; /* 600.01 kg/ha */
    f.data[4] = 0xEA;
    assert_int_equal(td_app_rx(&r.app, &f, 0u), TD_E_RANGE);
    assert_int_equal(r.app.cnt.rx_unknown_id, 3u);
    assert_int_equal(r.app.cnt.rx_bad_length, 1u);
    assert_int_equal(r.app.cnt.rx_out_of_range, 3u);
    assert_int_equal(r.app.cnt.rx_ok, 0u);
    const td_state_t *st = rig_st(&r);
    assert_false(st->running);
    assert_float_equal(st->rate_kg_ha[TD_UPPER], 0.0, 0.0);
    assert_float_equal(st->fan_target_rpm, 0.0, 0.0);
    assert_false(r.app.have_cmd);
    assert_false(r.app.have_gnss);
    /* the rejections are reported in EcuSpeeds.RxRejected */
    r.pc_sending = false;
    for (int i = 0; i <= 10; i++) {
        rig_step(&r);
    }
    td_can_frame_t out;
    int seen = 0;
    while (td_app_tx_pop(&r.app, &out)) {
        if (out.id == TD_ID_ECU_SPEEDS) {
            assert_int_equal(out.data[6], 7);
            assert_int_equal(out.data[7], 0);
            assert_int_equal(out.data[2], 0xFF); /* GNSS not valid */
            assert_int_equal(out.data[3], 0xFF);
            seen++;
        }
    }
    assert_int_equal(seen, 1);
    /* the good frame is then taken */
    f = frame8(TD_ID_PC_COMMAND, start8);
    assert_int_equal(td_app_rx(&r.app, &f, r.now_us), TD_OK);
    assert_true(rig_st(&r)->running);
    assert_float_equal(rig_st(&r)->rate_kg_ha[TD_UPPER], 200.0, 1e-3);
}

/* Send PcParamSet(id, raw) with dlc; return the rx code and check the ack frame. */
static int param_set(rig_t *r, uint8_t id, uint32_t raw, uint8_t dlc, uint8_t want_result, uint32_t want_raw) {
    const uint8_t d[8] = { id, 0, 0, 0, (uint8_t)raw, (uint8_t)(raw >> 8), (uint8_t)(raw >> 16), (uint8_t)(raw >> 24) };
    td_can_frame_t f = frame8(TD_ID_PC_PARAM_SET, d);
    f.dlc = dlc;
    const int rc = td_app_rx(&r->app, &f, r->now_us);
    td_can_frame_t ack;
    assert_int_equal(td_app_tx_pop(&r->app, &ack), 1);
    assert_int_equal(ack.id, TD_ID_ECU_PARAM_ACK);
    assert_int_equal(ack.extended, 1);
    assert_int_equal(ack.dlc, 8);
    assert_int_equal(ack.data[0], id);
    assert_int_equal(ack.data[1], want_result);
    const uint32_t got_raw = (uint32_t)ack.data[4] | ((uint32_t)ack.data[5] << 8) | ((uint32_t)ack.data[6] << 16) |
                             ((uint32_t)ack.data[7] << 24);
    assert_int_equal(got_raw, want_raw);
    assert_int_equal(td_app_tx_pop(&r->app, &ack), 0);
    return rc;
}

static void test_parameter_frames_and_acks(void **state) {
    (void)state;
    rig_t r;
    rig_init(&r, NULL, 0u);
    assert_int_equal(param_set(&r, 1, 4000u, 8, 0, 4000u), TD_OK); /* width 4.000 m */
    assert_float_equal(r.app.p.working_width_m, 4.0, 1e-5);
    assert_int_equal(param_set(&r, 1, 400u, 8, 2, 4000u), TD_E_RANGE); /* 0.4 m: out of range */
    assert_int_equal(param_set(&r, 1, 30001u, 8, 2, 4000u), TD_E_RANGE);
    assert_int_equal(param_set(&r, 40, 1u, 8, 1, 0u), TD_E_UNKNOWN_PARAM);
    assert_int_equal(param_set(&r, 39, 2u, 8, 2, 1u), TD_E_RANGE); /* GnssLagAuto: 0 or 1 */
    assert_int_equal(param_set(&r, 7, 6u, 8, 4, 5u), TD_E_INCONSISTENT); /* n = 6 > N = 5 */
    assert_int_equal(param_set(&r, 1, 4000u, 5, 5, 0u), TD_E_LENGTH);
    assert_int_equal(param_set(&r, 9, 900u, 8, 0, 900u), TD_OK); /* switch speed 9.00 km/h */
    assert_int_equal(r.app.cnt.rx_param_rejected, 5u);
    assert_int_equal(r.app.cnt.rx_bad_length, 1u);
    assert_int_equal(r.app.cnt.rx_ok, 2u);
    /* N = 3 (after n = 3): queue G is rebuilt with the new length */
    assert_int_equal(param_set(&r, 7, 3u, 8, 0, 3u), TD_OK);
    assert_int_equal(param_set(&r, 6, 3u, 8, 0, 3u), TD_OK);
    assert_int_equal(r.app.q.len, 3);
    /* running: busy, the value in force is reported */
    r.pc_start = true;
    r.pc_gnss_kmh = 8.0;
    r.wheel_kmh = 8.0;
    rig_step(&r);
    (void)rig_drain(&r, 0u);
    assert_int_equal(param_set(&r, 1, 5000u, 8, 3, 4000u), TD_E_BUSY);
    assert_float_equal(r.app.p.working_width_m, 4.0, 1e-5);
    /* the new switch speed acts: uniform 8 km/h is below 9 -> wheel */
    rig_run_ms(&r, 4000);
    assert_true(rig_st(&r)->uniform);
    assert_int_equal(rig_st(&r)->source, TD_SRC_WHEEL);
    assert_float_equal(rig_st(&r)->target_rpm[TD_UPPER], 4.0 * 200 * 8.0 / 180.0, 0.05);
}

static void test_tx_queue_overflow_counted(void **state) {
    (void)state;
    rig_t r;
    rig_init(&r, NULL, 0u);
    r.pc_sending = false;
    for (int k = 0; k <= 50; k++) { /* EcuIdent, then status at 100..500 ms: 1 + 5 x 7 frames into 16 places */
        rig_step(&r);
    }
    assert_int_equal(r.app.cnt.tx_dropped, 20u);
    const uint32_t order[7] = { TD_ID_ECU_STATUS, TD_ID_ECU_DIAG,      TD_ID_ECU_SPEEDS,  TD_ID_ECU_TARGETS,
                                TD_ID_ECU_FUSED,  TD_ID_ECU_FUSED_AUX, TD_ID_ECU_GNSS_LAG };
    td_can_frame_t f;
    assert_int_equal(td_app_tx_pop(&r.app, &f), 1);
    assert_int_equal(f.id, TD_ID_ECU_IDENT);
    for (int i = 0; i < 15; i++) {
        assert_int_equal(td_app_tx_pop(&r.app, &f), 1);
        assert_int_equal(f.id, order[i % 7]);
    }
    assert_int_equal(td_app_tx_pop(&r.app, &f), 0);
    /* a parameter ack into a full queue is dropped and counted too */
    for (int k = 0; k < 40; k++) {
        rig_step(&r);
    }
    const uint8_t d[8] = { 1, 0, 0, 0, 0xA0, 0x0F, 0, 0 };
    const td_can_frame_t ps = frame8(TD_ID_PC_PARAM_SET, d);
    const uint32_t before = r.app.cnt.tx_dropped;
    assert_int_equal(td_app_rx(&r.app, &ps, r.now_us), TD_OK);
    assert_int_equal(r.app.cnt.tx_dropped, before + 1u);
}

static void test_status_frames_every_100ms_with_state(void **state) {
    (void)state;
    rig_t r;
    rig_start_working(&r, NULL, 0u);
    int n[4] = { 0, 0, 0, 0 };
    td_can_frame_t last_status;
    memset(&last_status, 0, sizeof last_status);
    for (int i = 0; i < 100; i++) { /* 1 s */
        rig_step(&r);
        td_can_frame_t f;
        while (td_app_tx_pop(&r.app, &f)) {
            n[0] += f.id == TD_ID_ECU_STATUS;
            n[1] += f.id == TD_ID_ECU_DIAG;
            n[2] += f.id == TD_ID_ECU_SPEEDS;
            n[3] += f.id == TD_ID_ECU_TARGETS;
            if (f.id == TD_ID_ECU_STATUS) {
                last_status = f;
            }
        }
    }
    for (int i = 0; i < 4; i++) {
        assert_int_equal(n[i], 10);
    }
    td_status_t s;
    assert_int_equal(td_proto_decode_status(&last_status, &s), TD_OK);
    assert_true(s.running);
    assert_float_equal(s.meter_rpm[TD_UPPER], rig_st(&r)->meter_rpm[TD_UPPER], 0.6);
    assert_float_equal(s.wheel_kmh, 7.4, 0.051);
}

static void test_init_rejects_bad_parameters(void **state) {
    (void)state;
    td_app_t app;
    td_params_t p;
    td_params_default(&p);
    p.queue_len = 1;
    assert_int_equal(td_app_init(&app, &p, 0u), TD_E_RANGE);
    td_params_default(&p);
    p.cv_window = 9;
    assert_int_equal(td_app_init(&app, &p, 0u), TD_E_INCONSISTENT);
    assert_int_equal(td_app_init(NULL, &p, 0u), TD_E_ARG);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_uniform_8kmh_meters_on_gnss_across_clock_wrap),
        cmocka_unit_test(test_below_switch_speed_meters_on_wheel),
        cmocka_unit_test(test_acceleration_meters_on_wheel_until_uniform),
        cmocka_unit_test(test_command_timeout_at_1500ms),
        cmocka_unit_test(test_gnss_not_available_and_stale),
        cmocka_unit_test(test_encoder_fault_after_2s_latched_until_stop),
        cmocka_unit_test(test_encoder_fault_overrides_wheel_only_mode),
        cmocka_unit_test(test_no_speed_when_both_sources_fail),
        cmocka_unit_test(test_blocked_meter_stops_that_motor_only),
        cmocka_unit_test(test_fan_low_gates_its_layer),
        cmocka_unit_test(test_stop_command_stops_motors_and_fans),
        cmocka_unit_test(test_headland_stop_meters_reach_zero),
        cmocka_unit_test(test_malformed_frames_counted_never_acted_on),
        cmocka_unit_test(test_parameter_frames_and_acks),
        cmocka_unit_test(test_tx_queue_overflow_counted),
        cmocka_unit_test(test_status_frames_every_100ms_with_state),
        cmocka_unit_test(test_init_rejects_bad_parameters),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
