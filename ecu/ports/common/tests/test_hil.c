/* The HIL link: counters in as the hardware's, duties and step time out, late steps counted. */
#include "port_test.h"
#include "td_common.h"
#include "td_hil.h"
#include "td_hilcan.h"

static td_can_frame_t sensors(uint16_t wheel, uint16_t m0, uint16_t m1, uint8_t f0, uint8_t f1) {
    struct td_hilcan_hil_sensors_t s = { wheel, m0, m1, f0, f1 };
    td_can_frame_t f = { TD_HIL_ID_SENSORS, 1u, 8u, { 0 } };
    (void)td_hilcan_hil_sensors_pack(f.data, &s, 8u);
    return f;
}

static td_can_frame_t edge(uint32_t t_us, uint16_t count, uint8_t seq, bool valid) {
    struct td_hilcan_hil_wheel_edge_t e = { t_us, count, seq, valid ? 1u : 0u };
    td_can_frame_t f = { TD_HIL_ID_WHEEL_EDGE, 1u, 8u, { 0 } };
    (void)td_hilcan_hil_wheel_edge_pack(f.data, &e, 8u);
    return f;
}

static td_can_frame_t clock(uint32_t t_us, uint8_t seq, bool free_run) {
    struct td_hilcan_hil_clock_t c = { t_us, seq, free_run ? 1u : 0u };
    td_can_frame_t f = { TD_HIL_ID_CLOCK, 1u, 8u, { 0 } };
    (void)td_hilcan_hil_clock_pack(f.data, &c, 8u);
    return f;
}

static void test_lockstep_steps_once_per_sensors_at_the_clocks_time(void **state) {
    (void)state;
    td_hil_t h;
    td_hil_init(&h);
    assert_int_equal(h.tick, TD_HIL_TICK_UNSET);
    td_can_frame_t f = clock(0u, 0u, false);
    assert_int_equal(td_hil_rx(&h, &f), 1);
    assert_int_equal(h.tick, TD_HIL_TICK_LOCKSTEP);
    assert_false(h.step_due); /* a clock alone makes no step */
    f = clock(10000u, 1u, false);
    assert_int_equal(td_hil_rx(&h, &f), 1);
    f = edge(9500u, 3u, 1u, true);
    assert_int_equal(td_hil_rx(&h, &f), 1);
    assert_false(h.step_due);
    f = sensors(3u, 0u, 0u, 0u, 0u);
    assert_int_equal(td_hil_rx(&h, &f), 1);
    assert_true(h.step_due);
    assert_int_equal(h.clock_us, 10000u);
    td_io_in_t in;
    td_hil_inputs(&h, &in);
    assert_false(h.step_due);
    assert_int_equal(in.wheel_edge_us, 9500u);
    const td_io_out_t out = { { 0.5f, 0.0f }, { 0.0f, 0.0f } };
    td_can_frame_t fr[2];
    td_hil_outputs(&h, h.clock_us, &out, 3u, fr);
    struct td_hilcan_hil_step_t s;
    (void)td_hilcan_hil_step_unpack(&s, fr[1].data, 8u);
    assert_int_equal(s.hil_seq, 1u); /* the clock's number echoed */
    assert_int_equal(s.hil_step_time, 10000u);
    /* the next clock (wrapping) with a free-running flag: the tick stays, its number is taken */
    f = clock(0xFFFFFFF0u, 200u, true);
    assert_int_equal(td_hil_rx(&h, &f), 1);
    assert_int_equal(h.tick, TD_HIL_TICK_LOCKSTEP);
    assert_int_equal(h.clock_us, 0xFFFFFFF0u);
    f = sensors(4u, 0u, 0u, 0u, 0u);
    assert_int_equal(td_hil_rx(&h, &f), 1);
    assert_true(h.step_due);
    td_hil_inputs(&h, &in);
    td_hil_outputs(&h, h.clock_us, &out, 3u, fr);
    (void)td_hilcan_hil_step_unpack(&s, fr[1].data, 8u);
    assert_int_equal(s.hil_seq, 200u);
    assert_int_equal(h.late_steps, 0u);
    f = clock(0u, 0u, false);
    f.dlc = 6u;
    assert_int_equal(td_hil_rx(&h, &f), TD_E_LENGTH);
}

static void test_free_running_keeps_its_own_tick(void **state) {
    (void)state;
    td_hil_t h;
    td_hil_init(&h);
    td_can_frame_t f = clock(5000u, 9u, true);
    assert_int_equal(td_hil_rx(&h, &f), 1);
    assert_int_equal(h.tick, TD_HIL_TICK_OWN);
    f = clock(7000u, 10u, false); /* chosen once: a later lockstep clock changes nothing */
    assert_int_equal(td_hil_rx(&h, &f), 1);
    assert_int_equal(h.tick, TD_HIL_TICK_OWN);
    f = sensors(1u, 0u, 0u, 0u, 0u);
    assert_int_equal(td_hil_rx(&h, &f), 1);
    assert_false(h.step_due); /* the port's own tick makes the step */
    td_io_in_t in;
    td_hil_inputs(&h, &in);
    const td_io_out_t out = { { 0.0f, 0.0f }, { 0.0f, 0.0f } };
    td_can_frame_t fr[2];
    td_hil_outputs(&h, 123u, &out, 1u, fr);
    td_hil_outputs(&h, 10123u, &out, 1u, fr);
    struct td_hilcan_hil_step_t s;
    (void)td_hilcan_hil_step_unpack(&s, fr[1].data, 8u);
    assert_int_equal(s.hil_seq, 1u); /* its own numbers */
    assert_int_equal(s.hil_step_time, 10123u);
}

static void test_counters_extend_across_wraps(void **state) {
    (void)state;
    td_hil_t h;
    td_hil_init(&h);
    td_io_in_t in;
    td_can_frame_t f = sensors(65000u, 100u, 65530u, 250u, 10u);
    assert_int_equal(td_hil_rx(&h, &f), 1);
    td_hil_inputs(&h, &in);
    assert_int_equal(in.wheel_count, 0u); /* the first pair is the origin */
    f = sensors(700u, 50u, 20u, 4u, 20u);   /* wheel +1236, meter 0 back 50, meter 1 +26, fans +10 +10 */
    assert_int_equal(td_hil_rx(&h, &f), 1);
    td_hil_inputs(&h, &in);
    assert_int_equal(in.wheel_count, 1236u);
    assert_int_equal(in.meter_count[0], 0xFFFFFFCEu);
    assert_int_equal(in.meter_count[1], 26u);
    assert_int_equal(in.fan_count[0], 10u);
    assert_int_equal(in.fan_count[1], 10u);
    assert_int_equal(in.wheel_edge_valid, 0u);
    assert_int_equal(h.late_steps, 0u);
    td_hil_inputs(&h, &in); /* no fresh pair: the same counts, one late step */
    assert_int_equal(in.wheel_count, 1236u);
    assert_int_equal(h.late_steps, 1u);
}

static void test_edge_belongs_to_its_count(void **state) {
    (void)state;
    td_hil_t h;
    td_hil_init(&h);
    td_io_in_t in;
    td_can_frame_t f = edge(0xFFFFFFF0u, 10u, 0u, true);
    assert_int_equal(td_hil_rx(&h, &f), 1);
    f = sensors(10u, 0u, 0u, 0u, 0u);
    assert_int_equal(td_hil_rx(&h, &f), 1);
    td_hil_inputs(&h, &in);
    assert_int_equal(in.wheel_edge_valid, 1u);
    assert_int_equal(in.wheel_edge_us, 0xFFFFFFF0u);
    /* an edge of another count, or none before the sensors: not valid */
    f = edge(100u, 11u, 1u, true);
    assert_int_equal(td_hil_rx(&h, &f), 1);
    f = sensors(12u, 0u, 0u, 0u, 0u);
    assert_int_equal(td_hil_rx(&h, &f), 1);
    td_hil_inputs(&h, &in);
    assert_int_equal(in.wheel_edge_valid, 0u);
    assert_int_equal(in.wheel_count, 2u);
    f = sensors(12u, 0u, 0u, 0u, 0u);
    assert_int_equal(td_hil_rx(&h, &f), 1);
    td_hil_inputs(&h, &in);
    assert_int_equal(in.wheel_edge_valid, 0u);
}

static void test_outputs_and_refusals(void **state) {
    (void)state;
    td_hil_t h;
    td_hil_init(&h);
    const td_io_out_t out = { { 0.40001f, 1.5f }, { -0.2f, 0.12345f } };
    td_can_frame_t fr[2];
    td_hil_outputs(&h, 123456789u, &out, 70000u, fr);
    struct td_hilcan_hil_actuators_t a;
    assert_int_equal(fr[0].id, TD_HIL_ID_ACTUATORS);
    (void)td_hilcan_hil_actuators_unpack(&a, fr[0].data, 8u);
    assert_int_equal(a.hil_upper_meter_duty, 4000u);
    assert_int_equal(a.hil_lower_meter_duty, 10000u);
    assert_int_equal(a.hil_upper_fan_duty, 0u);
    assert_int_equal(a.hil_lower_fan_duty, 1235u);
    assert_int_equal(a.hil_seq, 0u);
    struct td_hilcan_hil_step_t s;
    assert_int_equal(fr[1].id, TD_HIL_ID_STEP);
    (void)td_hilcan_hil_step_unpack(&s, fr[1].data, 8u);
    assert_int_equal(s.hil_step_time, 123456789u);
    assert_int_equal(s.hil_step_cost, 65535u);
    td_hil_outputs(&h, 0u, &out, 5u, fr);
    (void)td_hilcan_hil_step_unpack(&s, fr[1].data, 8u);
    assert_int_equal(s.hil_seq, 1u);
    /* a short HIL frame is refused; a bus frame is not the link's */
    td_can_frame_t f = sensors(1u, 0u, 0u, 0u, 0u);
    f.dlc = 7u;
    assert_int_equal(td_hil_rx(&h, &f), TD_E_LENGTH);
    assert_int_equal(h.rx_refused, 1u);
    f.id = 0x0A5C6465u;
    f.dlc = 8u;
    assert_int_equal(td_hil_rx(&h, &f), 0);
    f.id = TD_HIL_ID_SENSORS;
    f.extended = 0u;
    assert_int_equal(td_hil_rx(&h, &f), 0);
    assert_false(h.have_sensors);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_counters_extend_across_wraps),
        cmocka_unit_test(test_edge_belongs_to_its_count),
        cmocka_unit_test(test_outputs_and_refusals),
        cmocka_unit_test(test_lockstep_steps_once_per_sensors_at_the_clocks_time),
        cmocka_unit_test(test_free_running_keeps_its_own_tick),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
