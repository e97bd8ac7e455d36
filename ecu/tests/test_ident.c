/* EcuIdent: who the ECU is, when it says so, and refused identities. */
#include "td_test.h"
#include "td_can.h"
#include "td_version.h"

/* Steps until the queue holds an EcuIdent (at most `steps`); returns how many there were. */
static int idents_in(rig_t *r, int steps, td_can_frame_t *last) {
    int n = 0;
    for (int i = 0; i < steps; i++) {
        rig_step(r);
        td_can_frame_t f;
        while (td_app_tx_pop(&r->app, &f)) {
            if (f.id == TD_ID_ECU_IDENT) {
                n++;
                *last = f;
            }
        }
    }
    return n;
}

static void test_host_identity_at_the_first_step(void **state) {
    (void)state;
    rig_t r;
    rig_init(&r, NULL, 0u);
    r.pc_sending = false;
    td_can_frame_t f;
    assert_int_equal(idents_in(&r, 1, &f), 1);
    assert_int_equal(f.extended, 1);
    assert_int_equal(f.dlc, 8);
    struct td_can_ecu_ident_t m;
    assert_int_equal(td_can_ecu_ident_unpack(&m, f.data, 8u), 0);
    assert_int_equal(m.target, TD_TARGET_HOST);
    assert_int_equal(m.transport, TD_TRANSPORT_IN_PROCESS);
    assert_int_equal(m.reset_cause, TD_RESET_UNKNOWN);
    assert_int_equal(m.firmware_major, TD_FW_VERSION_MAJOR);
    assert_int_equal(m.firmware_minor, TD_FW_VERSION_MINOR);
    assert_int_equal(m.firmware_patch, TD_FW_VERSION_PATCH);
    assert_int_equal(m.protocol_major, TD_PROTO_VERSION_MAJOR);
    assert_int_equal(m.protocol_minor, TD_PROTO_VERSION_MINOR);
    assert_int_equal(m.clock_fallback, 0);
    /* nothing more while nobody commands */
    assert_int_equal(idents_in(&r, 300, &f), 0);
}

static void test_port_identity_and_the_pc_coming_back(void **state) {
    (void)state;
    rig_t r;
    rig_init(&r, NULL, 0u);
    const td_ident_t id = { TD_TARGET_STM32F4, TD_TRANSPORT_SLCAN_HIL, TD_RESET_WATCHDOG, true };
    assert_int_equal(td_app_set_ident(&r.app, &id), TD_OK);
    td_can_frame_t f;
    /* the first command comes with the first step: one EcuIdent, not two */
    assert_int_equal(idents_in(&r, 100, &f), 1);
    /* bytes: target, firmware x3, protocol x2, transport | reset << 4, clock fallback |
     * on defaults << 1 (no parameter taken since power-up) */
    assert_int_equal(f.data[0], 1);
    assert_int_equal(f.data[6], 2u | (3u << 4));
    assert_int_equal(f.data[7], 1u | (1u << 1));
    /* commands every 500 ms: no repetition */
    assert_int_equal(idents_in(&r, 500, &f), 0);
    /* the PC goes quiet past the timeout (1.5 s), then commands again: one EcuIdent */
    r.pc_sending = false;
    assert_int_equal(idents_in(&r, 200, &f), 0);
    assert_true((rig_st(&r)->faults & TD_FAULT_CMD_TIMEOUT) != 0u);
    r.pc_sending = true;
    r.next_cmd_us = r.now_us;
    assert_int_equal(idents_in(&r, 100, &f), 1);
    assert_int_equal(f.data[0], 1);
}

/* One PcParamSet of the working width (raw mm), as the terminal sends it; its ack drained. */
static int set_width(rig_t *r, uint32_t raw_mm) {
    td_can_frame_t f;
    f.id = TD_ID_PC_PARAM_SET;
    f.extended = 1u;
    f.dlc = 8u;
    const uint8_t d[8] = { 1u, 0, 0, 0, (uint8_t)raw_mm, (uint8_t)(raw_mm >> 8), 0, 0 };
    memcpy(f.data, d, sizeof d);
    const int rc = td_app_rx(&r->app, &f, r->now_us);
    (void)rig_drain(r, 0u);
    return rc;
}

static bool on_defaults(const td_can_frame_t *f) {
    struct td_can_ecu_ident_t m;
    assert_int_equal(td_can_ecu_ident_unpack(&m, f->data, 8u), 0);
    return m.on_defaults != 0u;
}

static void test_a_power_up_is_told_from_a_command_timeout(void **state) {
    (void)state;
    rig_t r;
    rig_init(&r, NULL, 0u);
    r.pc_sending = false;
    td_can_frame_t f;
    /* powered up: on the firmware's defaults until a parameter is taken */
    assert_int_equal(idents_in(&r, 1, &f), 1);
    assert_true(on_defaults(&f));
    /* a refused parameter is not one taken */
    assert_int_equal(set_width(&r, 400u), TD_E_RANGE);
    assert_int_equal(set_width(&r, 4000u), TD_OK);
    assert_float_equal(r.app.p.working_width_m, 4.0, 1e-6);
    /* the PC commands, goes quiet past the timeout, commands again: its parameters are kept */
    r.pc_sending = true;
    assert_int_equal(idents_in(&r, 100, &f), 1);
    assert_false(on_defaults(&f));
    r.pc_sending = false;
    assert_int_equal(idents_in(&r, 200, &f), 0);
    assert_true((rig_st(&r)->faults & TD_FAULT_CMD_TIMEOUT) != 0u);
    r.pc_sending = true;
    r.next_cmd_us = r.now_us;
    assert_int_equal(idents_in(&r, 100, &f), 1);
    assert_false(on_defaults(&f));
    assert_float_equal(r.app.p.working_width_m, 4.0, 1e-6);
    /* a reset within the timeout (the PC never stops commanding): on defaults again, at once */
    td_params_t defaults;
    td_params_default(&defaults);
    assert_int_equal(td_app_init(&r.app, &defaults, r.now_us), TD_OK);
    assert_int_equal(idents_in(&r, 1, &f), 1);
    assert_true(on_defaults(&f));
    assert_float_equal(r.app.p.working_width_m, 3.6, 1e-6);
}

static void test_bad_identities_are_refused(void **state) {
    (void)state;
    rig_t r;
    rig_init(&r, NULL, 0u);
    const td_ident_t bad[3] = { { 2u, TD_TRANSPORT_CAN, TD_RESET_PIN, false },
                                { TD_TARGET_STM32F4, 3u, TD_RESET_PIN, false },
                                { TD_TARGET_STM32F4, TD_TRANSPORT_CAN, 7u, false } };
    for (int i = 0; i < 3; i++) {
        assert_int_equal(td_app_set_ident(&r.app, &bad[i]), TD_E_ARG);
    }
    assert_int_equal(td_app_set_ident(NULL, &bad[0]), TD_E_ARG);
    assert_int_equal(td_app_set_ident(&r.app, NULL), TD_E_ARG);
    assert_int_equal(r.app.ident.target, TD_TARGET_HOST);
}

static void test_announce_says_it_again_with_the_identity_set(void **state) {
    (void)state;
    rig_t r;
    rig_init(&r, NULL, 0u);
    const td_ident_t id = { TD_TARGET_STM32F4, TD_TRANSPORT_CAN, TD_RESET_PIN, false };
    assert_int_equal(td_app_set_ident(&r.app, &id), TD_OK);
    td_can_frame_t f;
    assert_int_equal(idents_in(&r, 100, &f), 1);
    assert_int_equal(idents_in(&r, 300, &f), 0); /* commanded all along: said once */
    /* the port's link came up (an ISOBUS node connected to its TC): once more, same identity */
    assert_int_equal(td_app_announce(&r.app), TD_OK);
    assert_int_equal(idents_in(&r, 1, &f), 1);
    assert_int_equal(f.data[0], TD_TARGET_STM32F4);
    assert_int_equal(f.data[6], TD_TRANSPORT_CAN | (TD_RESET_PIN << 4));
    assert_int_equal(idents_in(&r, 300, &f), 0);
    assert_int_equal(td_app_announce(NULL), TD_E_ARG);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_host_identity_at_the_first_step),
        cmocka_unit_test(test_port_identity_and_the_pc_coming_back),
        cmocka_unit_test(test_a_power_up_is_told_from_a_command_timeout),
        cmocka_unit_test(test_bad_identities_are_refused),
        cmocka_unit_test(test_announce_says_it_again_with_the_identity_set),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
