/* The paper's frames on an ISOBUS (td_prop.h): Proprietary B broadcasts from the claimed
 * address, Proprietary A/A2 to one address, the data bytes unchanged; the node takes the
 * terminal's frames only from its Task Controller's address and counts the rest. */
#include "ib_test.h"

#include "td_isob.h"
#include "td_prop_gen.h"

#define MY 0x84u
#define TC 0xF7u
#define OTHER 0x90u
#define NAME 0xA00A820000012345ull

/* the fixed identifiers, as generated from the DBC */
#define TD_PROP_ID(name, id, pgn, prio, ecu) ID_##name = (id),
enum { TD_PROP_TABLE(TD_PROP_ID) ID_END = 0 };
#undef TD_PROP_ID

static const uint8_t D[8] = {1u, 2u, 3u, 4u, 5u, 6u, 7u, 8u};

static td_can_frame_t core_frame(uint32_t id) {
    td_can_frame_t f;
    f.id = id;
    f.extended = 1u;
    f.dlc = 8u;
    memcpy(f.data, D, 8u);
    return f;
}

static void test_ecu_frames_to_the_bus(void **s) {
    td_can_frame_t core = core_frame(ID_EcuStatus), out;
    td_ib_id_t id;
    (void)s;
    assert_int_equal(td_prop_to_bus(&core, TD_PROP_ECU, MY, TC, &out), TD_IB_OK);
    id = td_ib_id_unpack(out.id);
    assert_int_equal(id.pgn, 0xFF5Cu); /* Proprietary B, group extension 0x5C */
    assert_int_equal(id.sa, MY);
    assert_int_equal(id.priority, 6u);
    assert_memory_equal(out.data, D, 8u);
    assert_int_equal(out.dlc, 8u);
    core = core_frame(ID_EcuParamAck); /* the answer goes to the terminal: Proprietary A */
    assert_int_equal(td_prop_to_bus(&core, TD_PROP_ECU, MY, TC, &out), TD_IB_OK);
    id = td_ib_id_unpack(out.id);
    assert_int_equal(id.pgn, TD_PROP_PGN_A);
    assert_int_equal(id.da, TC);
    assert_int_equal(id.sa, MY);
    /* no TC to answer to, no claimed address: nothing to send */
    assert_int_equal(td_prop_to_bus(&core, TD_PROP_ECU, MY, TD_IB_ADDR_NULL, &out),
                     TD_IB_E_NO_ADDRESS);
    core = core_frame(ID_EcuDiag);
    assert_int_equal(td_prop_to_bus(&core, TD_PROP_ECU, TD_IB_ADDR_NULL, TC, &out),
                     TD_IB_E_NO_ADDRESS);
    /* a terminal's frame is not the ECU's to send; an unknown identifier has no ISOBUS form */
    core = core_frame(ID_PcParamSet);
    assert_int_equal(td_prop_to_bus(&core, TD_PROP_ECU, MY, TC, &out), TD_IB_E_FRAME);
    core = core_frame(0x0A5C6465u); /* the paper's PcCommand: the TC sets rates on ISOBUS */
    assert_int_equal(td_prop_to_bus(&core, TD_PROP_TERMINAL, TC, MY, &out), TD_IB_E_FRAME);
}

static void test_terminal_frames_round_trip(void **s) {
    const uint32_t terminal[3] = {ID_PcParamSet, ID_PcCalCommand, ID_PcGnssTime};
    const uint32_t pgns[3] = {TD_PROP_PGN_A, TD_PROP_PGN_A2, 0xFF62u};
    (void)s;
    for (unsigned i = 0u; i < 3u; i++) {
        td_can_frame_t core = core_frame(terminal[i]), bus, back;
        td_ib_id_t id;
        assert_int_equal(td_prop_to_bus(&core, TD_PROP_TERMINAL, TC, MY, &bus), TD_IB_OK);
        id = td_ib_id_unpack(bus.id);
        assert_int_equal(id.pgn, pgns[i]);
        assert_int_equal(id.sa, TC);
        assert_int_equal(td_prop_from_bus(&bus, TD_PROP_TERMINAL, TC, MY, &back), 1);
        assert_int_equal(back.id, terminal[i]);
        assert_memory_equal(back.data, D, 8u);
        /* from another address: refused; to another ECU (Proprietary A): not ours at all */
        assert_int_equal(td_prop_from_bus(&bus, TD_PROP_TERMINAL, OTHER, MY, &back),
                         TD_IB_E_SOURCE);
        assert_int_equal(td_prop_from_bus(&bus, TD_PROP_TERMINAL, TD_IB_ADDR_NULL, MY, &back),
                         TD_IB_E_SOURCE);
        assert_int_equal(td_prop_from_bus(&bus, TD_PROP_TERMINAL, TC, 0x85u, &back),
                         id.da == MY ? 0 : 1);
    }
}

static void test_other_traffic_is_not_ours(void **s) {
    td_can_frame_t back;
    /* another maker's Proprietary B with a group extension we do not use, and a TC status */
    td_can_frame_t f = ib_frame(6u, 0xFF10u, TD_IB_ADDR_GLOBAL, TC, D);
    (void)s;
    assert_int_equal(td_prop_from_bus(&f, TD_PROP_TERMINAL, TC, MY, &back), 0);
    f = ib_frame(3u, 0xCB00u, TD_IB_ADDR_GLOBAL, TC, D);
    assert_int_equal(td_prop_from_bus(&f, TD_PROP_TERMINAL, TC, MY, &back), 0);
    /* the ECU's own broadcast heard by the terminal side */
    f = ib_frame(6u, 0xFF5Cu, TD_IB_ADDR_GLOBAL, MY, D);
    assert_int_equal(td_prop_from_bus(&f, TD_PROP_TERMINAL, TC, MY, &back), 0);
    assert_int_equal(td_prop_from_bus(&f, TD_PROP_ECU, MY, TC, &back), 1);
    assert_int_equal(back.id, ID_EcuStatus);
    f.extended = 0u;
    assert_int_equal(td_prop_from_bus(&f, TD_PROP_ECU, MY, TC, &back), 0);
}

/* The node: claimed, then a TC status from 0xF7; the terminal's frames from it are taken, the
 * same frames from another address dropped and counted. */
static void test_node_takes_only_its_tcs_frames(void **s) {
    static td_isob_t n;
    const uint8_t status[8] = {0xFE, 0xFF, 0xFF, 0xFF, 0x00, 0xFF, 0x00, 0xFF};
    td_can_frame_t core = core_frame(ID_PcParamSet), bus, back, f;
    uint32_t now = 1000u;
    (void)s;
    assert_int_equal(td_isob_init(&n, NAME, MY, 0x80u, 0x87u, 1000000u), TD_IB_OK);
    assert_int_equal(td_isob_start(&n, now), TD_IB_OK);
    assert_int_equal(td_prop_to_bus(&core, TD_PROP_TERMINAL, TC, MY, &bus), TD_IB_OK);
    /* before our claim it is not to us */
    assert_int_equal(td_isob_prop_rx(&n, &bus, &back), 0);
    for (unsigned i = 0u; i < 30u; i++) {
        now += 10000u;
        td_isob_step(&n, now, 0u);
        while (td_isob_tx(&n, &f)) {
        }
    }
    assert_int_equal(td_claim_address(&n.claim), MY);
    /* before any TC is known: counted, not taken */
    assert_int_equal(td_isob_prop_rx(&n, &bus, &back), TD_IB_E_SOURCE);
    /* our broadcasts once claimed; the acknowledgement only to a TC */
    core = core_frame(ID_EcuIdent);
    assert_int_equal(td_isob_prop_tx(&n, &core, &f), TD_IB_OK);
    assert_int_equal(td_ib_id_unpack(f.id).sa, MY);
    core = core_frame(ID_EcuParamAck);
    assert_int_equal(td_isob_prop_tx(&n, &core, &f), TD_IB_E_NO_ADDRESS);
    f = ib_frame(3u, 0xCB00u, TD_IB_ADDR_GLOBAL, TC, status);
    assert_int_equal(td_isob_rx(&n, &f, now), 0);
    assert_int_equal(n.tc.tc_addr, TC);
    assert_int_equal(td_isob_prop_tx(&n, &core, &f), TD_IB_OK);
    assert_int_equal(td_ib_id_unpack(f.id).da, TC);
    assert_int_equal(td_isob_prop_rx(&n, &bus, &back), 1);
    assert_int_equal(back.id, ID_PcParamSet);
    core = core_frame(ID_PcParamSet);
    assert_int_equal(td_prop_to_bus(&core, TD_PROP_TERMINAL, OTHER, MY, &bus), TD_IB_OK);
    assert_int_equal(td_isob_prop_rx(&n, &bus, &back), TD_IB_E_SOURCE);
    assert_int_equal(n.prop_rx, 1u);
    assert_int_equal(n.prop_wrong_source, 2u);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ecu_frames_to_the_bus),
        cmocka_unit_test(test_terminal_frames_round_trip),
        cmocka_unit_test(test_other_traffic_is_not_ours),
        cmocka_unit_test(test_node_takes_only_its_tcs_frames),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
