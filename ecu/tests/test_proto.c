/* Protocol: PcCommand validation, frame layouts (Table 1, little-endian), PcParamSet, acks. */
#include "td_test.h"

#include "td_can.h"
#include "td_params.h"
#include "td_proto.h"

static td_can_frame_t raw_frame(uint32_t id, uint8_t dlc, const uint8_t *data) {
    td_can_frame_t f;
    memset(&f, 0, sizeof f);
    f.id = id;
    f.extended = 1u;
    f.dlc = dlc;
    memcpy(f.data, data, 8);
    return f;
}

static void test_decode_command_paper_layout(void **state) {
    (void)state;
    /* start, fan 3000 rpm (0x0BB8), upper 200.00 kg/ha (20000 = 0x4E20), lower 150.00 (15000 = 0x3A98), GNSS 8.0 */
    const uint8_t d[8] = { 0x0A, 0xB8, 0x0B, 0x20, 0x4E, 0x98, 0x3A, 80 };
    const td_can_frame_t f = raw_frame(TD_ID_PC_COMMAND, 8, d);
    td_command_t c;
    assert_int_equal(td_proto_decode_command(&f, &c), TD_OK);
    assert_true(c.start);
    assert_float_equal(c.fan_rpm, 3000.0, 0.0);
    assert_float_equal(c.rate_kg_ha[TD_UPPER], 200.0, 1e-3);
    assert_float_equal(c.rate_kg_ha[TD_LOWER], 150.0, 1e-3);
    assert_true(c.gnss_valid);
    assert_float_equal(c.gnss_kmh, 8.0, 1e-5);
    /* and the encoder writes the same bytes */
    td_can_frame_t g;
    assert_int_equal(td_proto_encode_command(&c, &g), TD_OK);
    assert_int_equal(g.id, TD_ID_PC_COMMAND);
    assert_int_equal(g.extended, 1);
    assert_int_equal(g.dlc, 8);
    assert_memory_equal(g.data, d, 8);
}

static void test_command_validation(void **state) {
    (void)state;
    td_command_t c;
    const uint8_t ok[8] = { 0x00, 0, 0, 0, 0, 0, 0, 250 };
    td_can_frame_t f = raw_frame(TD_ID_PC_COMMAND, 8, ok);
    assert_int_equal(td_proto_decode_command(&f, &c), TD_OK);
    assert_false(c.start);
    assert_float_equal(c.gnss_kmh, 25.0, 1e-5);
    f.data[7] = 0xFF; /* not available */
    assert_int_equal(td_proto_decode_command(&f, &c), TD_OK);
    assert_false(c.gnss_valid);
    for (unsigned raw = 251; raw <= 254; raw++) {
        f.data[7] = (uint8_t)raw;
        assert_int_equal(td_proto_decode_command(&f, &c), TD_E_RANGE);
    }
    f.data[7] = 0;
    f.data[0] = 0x05;
    assert_int_equal(td_proto_decode_command(&f, &c), TD_E_RANGE);
    f.data[0] = 0x01;
    assert_int_equal(td_proto_decode_command(&f, &c), TD_E_RANGE);
    f.data[0] = 0x0A;
    f.data[3] = 0x60; /* upper rate 60000 = 600.00: the limit */
    f.data[4] = 0xEA;
    assert_int_equal(td_proto_decode_command(&f, &c), TD_OK);
    assert_float_equal(c.rate_kg_ha[TD_UPPER], 600.0, 1e-3);
    f.data[3] = 0x61; /* 600.01 */
    assert_int_equal(td_proto_decode_command(&f, &c), TD_E_RANGE);
    f.data[3] = 0;
    f.data[4] = 0;
    f.data[1] = 0x71; /* fan 6001 rpm */
    f.data[2] = 0x17;
    assert_int_equal(td_proto_decode_command(&f, &c), TD_E_RANGE);
    f.data[1] = 0;
    f.data[2] = 0;
    f.dlc = 7;
    assert_int_equal(td_proto_decode_command(&f, &c), TD_E_LENGTH);
    f.dlc = 9;
    assert_int_equal(td_proto_decode_command(&f, &c), TD_E_LENGTH);
    /* the encoder refuses what the decoder would refuse */
    c.start = true;
    c.fan_rpm = 3000.0f;
    c.rate_kg_ha[0] = 600.5f;
    c.rate_kg_ha[1] = 0.0f;
    c.gnss_valid = false;
    assert_int_equal(td_proto_encode_command(&c, &f), TD_E_RANGE);
}

static void test_status_layout(void **state) {
    (void)state;
    const td_status_t s = { true, { 24.0f, 18.37f }, { 3000.0f, 2990.0f }, 1.2f };
    td_can_frame_t f;
    assert_int_equal(td_proto_encode_status(&s, &f), TD_OK);
    /* 2400 = 0x0960, 1837 = 0x072D, 3000/20 = 150, 2990/20 = 149.5 -> 150, 1.2/0.1 = 12 */
    const uint8_t want[8] = { 0x0A, 0x60, 0x09, 0x2D, 0x07, 150, 150, 12 };
    assert_int_equal(f.id, TD_ID_ECU_STATUS);
    assert_memory_equal(f.data, want, 8);
    td_status_t back;
    assert_int_equal(td_proto_decode_status(&f, &back), TD_OK);
    assert_float_equal(back.meter_rpm[TD_LOWER], 18.37, 1e-4);
    assert_float_equal(back.wheel_kmh, 1.2, 1e-5);
    /* saturation instead of wrap-around */
    const td_status_t big = { false, { 700.0f, -3.0f }, { 9000.0f, 0.0f }, 40.0f };
    assert_int_equal(td_proto_encode_status(&big, &f), TD_OK);
    const uint8_t sat[8] = { 0x00, 0xFF, 0xFF, 0x00, 0x00, 0xFF, 0x00, 0xFF };
    assert_memory_equal(f.data, sat, 8);
}

static void test_diag_speeds_targets_layout(void **state) {
    (void)state;
    td_can_frame_t f;
    td_diag_t d = { TD_SRC_GNSS, TD_MODE_DUAL, true, true, TD_CMP_GNSS, 3.27f, 0x0082u, 0x01020304u };
    assert_int_equal(td_proto_encode_diag(&d, &f), TD_OK);
    /* byte0: source 1 | mode 0<<2 | gnss 1<<4 | uniform 1<<5 | compare 0<<6 = 0x31; cv 327 = 0x0147 */
    const uint8_t want[8] = { 0x31, 0x47, 0x01, 0x82, 0x00, 0x04, 0x03, 0x02 };
    assert_int_equal(f.id, TD_ID_ECU_DIAG);
    assert_memory_equal(f.data, want, 8);
    d.cv_pct = -1.0f; /* undefined */
    assert_int_equal(td_proto_encode_diag(&d, &f), TD_OK);
    assert_int_equal(f.data[1], 0xFF);
    assert_int_equal(f.data[2], 0xFF);
    d.source = TD_SRC_FUSED;
    d.mode = TD_MODE_FUSED;
    assert_int_equal(td_proto_encode_diag(&d, &f), TD_OK);
    assert_int_equal(f.data[0] & 0x0F, 0x0F); /* source 3 | mode 3 << 2 */
    d.source = 4;
    assert_int_equal(td_proto_encode_diag(&d, &f), TD_E_ARG);

    const td_speeds_t s = { 7.31f, -1.0f, 7.31f, 3u };
    assert_int_equal(td_proto_encode_speeds(&s, &f), TD_OK);
    const uint8_t ws[8] = { 0xDB, 0x02, 0xFF, 0xFF, 0xDB, 0x02, 0x03, 0x00 }; /* 731 = 0x02DB */
    assert_memory_equal(f.data, ws, 8);

    const td_targets_t t = { { 24.0f, 0.0f }, { 40.25f, 0.0f }, { 75.0f, 100.0f } };
    assert_int_equal(td_proto_encode_targets(&t, &f), TD_OK);
    const uint8_t wt[8] = { 0x60, 0x09, 0x00, 0x00, 81, 0, 150, 200 }; /* 40.25 % / 0.5 = 80.5 -> 81 */
    assert_memory_equal(f.data, wt, 8);
}

static void test_param_set_decode_matches_generated_unpack(void **state) {
    (void)state;
    for (uint8_t id = 1; id <= TD_PARAM_COUNT; id++) {
        float scale;
        uint32_t lo, hi;
        assert_int_equal(td_params_encoding(id, &scale, &lo, &hi), TD_OK);
        const uint32_t raw = lo + (hi - lo) / 3u;
        const uint8_t d[8] = { id, 0, 0, 0, (uint8_t)raw, (uint8_t)(raw >> 8), (uint8_t)(raw >> 16), (uint8_t)(raw >> 24) };
        const td_can_frame_t f = raw_frame(TD_ID_PC_PARAM_SET, 8, d);
        uint8_t got_id = 0;
        float value = -1.0f;
        assert_int_equal(td_proto_decode_param_set(&f, &got_id, &value), TD_OK);
        assert_int_equal(got_id, id);
        assert_float_equal(value, (float)raw * scale, 1e-6);
        assert_int_equal(td_proto_param_raw(id, value), raw);
        /* the generated unpack finds the same raw value in the multiplexed signal */
        struct td_can_pc_param_set_t m;
        assert_int_equal(td_can_pc_param_set_unpack(&m, f.data, 8), 0);
        assert_int_equal(m.param_id, id);
        uint8_t packed[8];
        assert_true(td_can_pc_param_set_pack(packed, &m, 8) >= 0);
        assert_memory_equal(packed, d, 8);
        /* out of range on both sides */
        uint8_t e[8];
        memcpy(e, d, 8);
        const uint32_t over = hi + 1u;
        e[4] = (uint8_t)over;
        e[5] = (uint8_t)(over >> 8);
        e[6] = (uint8_t)(over >> 16);
        e[7] = (uint8_t)(over >> 24);
        const td_can_frame_t g = raw_frame(TD_ID_PC_PARAM_SET, 8, e);
        assert_int_equal(td_proto_decode_param_set(&g, &got_id, &value), TD_E_RANGE);
    }
    const uint8_t unknown[8] = { TD_PARAM_COUNT + 1, 0, 0, 0, 1, 0, 0, 0 };
    td_can_frame_t f = raw_frame(TD_ID_PC_PARAM_SET, 8, unknown);
    uint8_t id;
    float v;
    assert_int_equal(td_proto_decode_param_set(&f, &id, &v), TD_E_UNKNOWN_PARAM);
    f.data[0] = 0;
    assert_int_equal(td_proto_decode_param_set(&f, &id, &v), TD_E_UNKNOWN_PARAM);
    f.data[0] = 1;
    f.dlc = 5;
    assert_int_equal(td_proto_decode_param_set(&f, &id, &v), TD_E_LENGTH);
}

static void test_param_ack_layout(void **state) {
    (void)state;
    const td_param_ack_t a = { 1u, 2u, 3600u };
    td_can_frame_t f;
    assert_int_equal(td_proto_encode_param_ack(&a, &f), TD_OK);
    const uint8_t want[8] = { 1, 2, 0, 0, 0x10, 0x0E, 0, 0 }; /* 3600 = 0x0E10 */
    assert_int_equal(f.id, TD_ID_ECU_PARAM_ACK);
    assert_memory_equal(f.data, want, 8);
    /* physical -> raw rounds to nearest: 1/60 duty per r/min -> 1667 * 1e-5 */
    assert_int_equal(td_proto_param_raw(15, 1.0f / 60.0f), 1667u);
    assert_int_equal(td_proto_param_raw(99, 1.0f), 0u);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_decode_command_paper_layout),
        cmocka_unit_test(test_command_validation),
        cmocka_unit_test(test_status_layout),
        cmocka_unit_test(test_diag_speeds_targets_layout),
        cmocka_unit_test(test_param_set_decode_matches_generated_unpack),
        cmocka_unit_test(test_param_ack_layout),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
