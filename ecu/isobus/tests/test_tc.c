/* The TC client against a scripted Task Controller at 0xF7: the connection (version, language,
 * labels, DDOP transfer by TP, activation), value commands with PDACK, measurement triggers,
 * section control, a lost TC, a refused pool and a TC that already holds the pool. */
#include "ib_test.h"

#include "td_ibname.h"
#include "td_tc.h"

#define MY 0x84u
#define TC 0xF7u
#define NAME 0xA00A820000012345ull
#define TIMEOUT_US 1000000u

typedef struct {
    td_tc_t tc;
    td_tp_t tp;        /* ours */
    td_tp_t tc_tp;     /* the TC's, receiving the pool */
    td_ib_txq_t q, tc_q;
    uint8_t buf[64], tc_buf[2048];
    uint32_t now;
    uint32_t dist_mm;
    td_can_frame_t out[64];
    unsigned n_out;
} rig_t;

static rig_t R;

static void rig_init(void) {
    memset(&R, 0, sizeof R);
    assert_int_equal(td_tc_init(&R.tc, NAME, TIMEOUT_US), TD_IB_OK);
    td_tp_init(&R.tp, R.buf, sizeof R.buf, NULL, 0u);
    td_tp_init(&R.tc_tp, R.tc_buf, sizeof R.tc_buf, NULL, 0u);
    td_ib_txq_init(&R.q);
    td_ib_txq_init(&R.tc_q);
    R.now = 5000u;
}

/* The TC sends process data (8 bytes) to us, or to all when da is global. */
static void tc_send(uint8_t da, const uint8_t d[8]) {
    assert_true(td_tc_rx(&R.tc, TD_IB_PGN_PROCESS_DATA, TC, da, d, 8u, MY, R.now, &R.q) >= 0);
}

static void tc_status(void) {
    const uint8_t d[8] = {0xFE, 0xFF, 0xFF, 0xFF, 0x00, 0xFF, 0x00, 0xFF};
    tc_send(0xFFu, d);
}

/* One 10 ms step of ours; our frames are collected (and TP frames handed to the TC's TP). */
static void step(void) {
    td_can_frame_t f;
    R.now += 10000u;
    td_tc_step(&R.tc, MY, R.now, R.dist_mm, &R.tp, &R.q);
    td_tp_step(&R.tp, R.now, &R.q);
    while (td_ib_txq_pop(&R.q, &f)) {
        td_ib_id_t id = td_ib_id_unpack(f.id);
        if (id.pgn == TD_IB_PGN_TP_CM || id.pgn == TD_IB_PGN_TP_DT || id.pgn == TD_IB_PGN_ETP_CM ||
            id.pgn == TD_IB_PGN_ETP_DT) {
            (void)td_tp_rx(&R.tc_tp, &f, TC, R.now, &R.tc_q);
        } else if (R.n_out < 64u) {
            R.out[R.n_out++] = f;
        }
    }
    while (td_ib_txq_pop(&R.tc_q, &f)) {
        (void)td_tp_rx(&R.tp, &f, MY, R.now, &R.q);
    }
}

static const td_can_frame_t *last_out(void) {
    assert_true(R.n_out > 0u);
    return &R.out[R.n_out - 1u];
}

static void expect_pd(uint8_t b0, uint8_t b1) {
    const td_can_frame_t *f = last_out();
    assert_int_equal(f->id, td_ib_id_pack(5u, TD_IB_PGN_PROCESS_DATA, TC, MY));
    assert_int_equal(f->data[0], b0);
    assert_int_equal(f->data[1], b1);
}

static void connect(bool tc_has_pool) {
    uint8_t d[8];
    const uint8_t version[8] = {0x10, 4, 0xFF, 0x13, 0, 1, 16, 2};
    tc_status();
    assert_int_equal(R.tc.state, TD_TC_VERSION);
    assert_int_equal(R.n_out, 0u); /* sent into the queue: collected at the next step */
    step();
    assert_int_equal(R.n_out, 2u);
    assert_int_equal(R.out[0].id, 0x18FE0D84u); /* Working Set Master, one member */
    assert_int_equal(R.out[0].data[0], 1);
    expect_pd(0x00, 0xFF); /* request version */
    tc_send(MY, version);
    step();
    assert_int_equal(last_out()->id, 0x18EAF784u); /* Request for the language command */
    assert_int_equal(td_ib_get_u24(last_out()->data), TD_IB_PGN_LANGUAGE);
    {
        const uint8_t lang[8] = {'d', 'e', 0x50, 0x00, 0x00, 0x00, 0xFF, 0xFF};
        assert_int_equal(td_tc_rx(&R.tc, TD_IB_PGN_LANGUAGE, TC, 0xFF, lang, 8u, MY, R.now, &R.q), 1);
    }
    step();
    assert_int_equal(R.tc.language[0], 'd');
    expect_pd(0x01, 0xFF); /* request structure label */
    memset(d, 0xFF, sizeof d);
    d[0] = 0x11;
    if (tc_has_pool) {
        memcpy(&d[1], td_ddop_structure_label, 7u);
    }
    tc_send(MY, d);
    step();
    if (tc_has_pool) {
        const uint8_t loc[8] = {0x31, 'e', 'n', 0x50, 0x00, 0x00, 0x00, 0xFF};
        expect_pd(0x21, 0xFF);
        tc_send(MY, loc);
        step();
    } else {
        const uint8_t ok[8] = {0x51, 0x00, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF};
        unsigned i;
        expect_pd(0x41, (uint8_t)((TD_DDOP_LEN) & 0xFFu)); /* pool size */
        assert_int_equal(td_ib_get_u32(&last_out()->data[1]), TD_DDOP_LEN);
        tc_send(MY, ok);
        for (i = 0u; i < 100u && R.tc_tp.rx_done == 0u; i++) {
            step();
        }
        assert_int_equal(R.tc_tp.rx_done, 1);
        assert_int_equal(R.tc_tp.msg.len, 1u + TD_DDOP_LEN);
        assert_int_equal(R.tc_tp.msg.data[0], 0x61);
        assert_memory_equal(&R.tc_tp.msg.data[7], "topdress", 8u); /* DVC designator */
        assert_true(td_ibname_from_bytes(&R.tc_tp.msg.data[1u + TD_DDOP_NAME_OFFSET]) == NAME);
        step();
        memset(d, 0xFF, sizeof d);
        d[0] = 0x71;
        d[1] = 0;
        tc_send(MY, d);
        step();
    }
    expect_pd(0x81, 0xFF); /* activate */
    memset(d, 0xFF, sizeof d);
    d[0] = 0x91;
    d[1] = 0;
    tc_send(MY, d);
    assert_int_equal(R.tc.state, TD_TC_CONNECTED);
    R.n_out = 0u;
}

static void pd(uint8_t d[8], unsigned cmd, uint16_t el, uint16_t ddi, int32_t v) {
    d[0] = (uint8_t)(cmd | ((el & 0xFu) << 4));
    d[1] = (uint8_t)(el >> 4);
    d[2] = (uint8_t)(ddi & 0xFFu);
    d[3] = (uint8_t)(ddi >> 8);
    td_ib_put_u32(&d[4], (uint32_t)v);
}

static void set_ack(uint16_t el, uint16_t ddi, int32_t v) {
    uint8_t d[8];
    pd(d, 10u, el, ddi, v);
    tc_send(MY, d);
}

static uint8_t pdack_errors(uint16_t ddi) {
    unsigned i;
    for (i = R.n_out; i-- > 0u;) {
        const uint8_t *d = R.out[i].data;
        if ((d[0] & 0x0Fu) == 13u && (unsigned)(d[2] | (d[3] << 8)) == ddi) {
            return d[4];
        }
    }
    fail_msg("no PDACK for DDI %u", ddi);
    return 0xFFu;
}

static void test_connect_transfers_pool_and_sets_rate(void **s) {
    (void)s;
    rig_init();
    assert_int_equal(td_tc_rate_mg_m2(&R.tc, 0u), 0);
    connect(false);
    assert_false(R.tc.alarm);
    set_ack(TD_DDOP_EL_UPPER, 6u, 15000); /* 150 kg/ha */
    set_ack(TD_DDOP_EL_LOWER, 6u, 10000);
    step();
    assert_int_equal(pdack_errors(6u), 0u);
    assert_int_equal(td_tc_rate_mg_m2(&R.tc, 0u), 15000);
    assert_int_equal(td_tc_rate_mg_m2(&R.tc, 1u), 10000);
    /* out of range (700 kg/ha), unknown element and DDI, not settable: refused, rate kept */
    set_ack(TD_DDOP_EL_UPPER, 6u, 70000);
    step();
    assert_int_equal(pdack_errors(6u), TD_TC_PDACK_OUT_OF_RANGE);
    assert_int_equal(td_tc_rate_mg_m2(&R.tc, 0u), 15000);
    set_ack(99u, 6u, 1);
    step();
    assert_int_equal(pdack_errors(6u), TD_TC_PDACK_BAD_ELEMENT);
    set_ack(TD_DDOP_EL_UPPER, 999u, 1);
    step();
    assert_int_equal(pdack_errors(999u), TD_TC_PDACK_BAD_DDI);
    set_ack(TD_DDOP_EL_UPPER, 7u, 1);
    step();
    assert_int_equal(pdack_errors(7u), TD_TC_PDACK_NOT_SETTABLE);
    assert_int_equal(R.tc.values_refused, 4u);
}

static void test_sections_by_condensed_work_state(void **s) {
    (void)s;
    rig_init();
    connect(false);
    assert_int_equal(td_tc_sections_on(&R.tc), 0u);
    set_ack(TD_DDOP_EL_BOOM, 289u, 1); /* master on */
    set_ack(TD_DDOP_EL_BOOM, 160u, 1); /* automatic section control */
    /* sections 1-3 on, 4-6 off, 7-16 not installed */
    set_ack(TD_DDOP_EL_BOOM, 290u, (int32_t)0xFFFFF015u);
    assert_int_equal(td_tc_sections_on(&R.tc), 0x07u);
    set_ack(TD_DDOP_EL_BOOM, 160u, 0); /* manual: every section follows the master */
    assert_int_equal(td_tc_sections_on(&R.tc), 0x3Fu);
    set_ack(TD_DDOP_EL_BOOM, 289u, 0);
    assert_int_equal(td_tc_sections_on(&R.tc), 0u);
}

static unsigned values_of(uint16_t ddi) {
    unsigned i, n = 0u;
    for (i = 0u; i < R.n_out; i++) {
        const uint8_t *d = R.out[i].data;
        if ((d[0] & 0x0Fu) == 3u && (unsigned)(d[2] | (d[3] << 8)) == ddi) {
            n++;
        }
    }
    return n;
}

static void test_measurements_by_time_distance_change(void **s) {
    uint8_t d[8];
    unsigned i;
    (void)s;
    rig_init();
    connect(false);
    tc_status();
    for (i = 0u; i < 20u; i++) { /* the default set goes out once at connection */
        step();
    }
    R.n_out = 0u;
    pd(d, 4u, TD_DDOP_EL_UPPER, 7u, 1000); /* actual rate every 1000 ms */
    tc_send(MY, d);
    pd(d, 5u, TD_DDOP_EL_BOOM, 116u, 10000); /* area every 10 m */
    tc_send(MY, d);
    pd(d, 8u, TD_DDOP_EL_LOWER, 75u, 500); /* content on 500 g change */
    tc_send(MY, d);
    for (i = 0u; i < 300u; i++) { /* 3 s at 2 m/s */
        R.dist_mm += 20u;
        td_tc_set_actual(&R.tc, TD_DDOP_EL_LOWER, 75u, 100000 - (int32_t)i * 10);
        if (i % 50u == 0u) {
            tc_status();
        }
        step();
    }
    assert_int_equal(values_of(7u), 1u + 2u); /* at once, then 1 s and 2 s later */
    assert_int_equal(values_of(116u), 1u);     /* 6 m so far: only the first */
    assert_int_equal(values_of(75u), 1u + 5u); /* 2990 g less: every 500 g */
    assert_int_equal(td_tc_set_actual(&R.tc, TD_DDOP_EL_UPPER, 6u, 1), TD_IB_E_ARG);
    /* the client task message every 2 s */
    for (i = 0u; i < R.n_out; i++) {
        if (R.out[i].id == 0x18CBF784u && R.out[i].data[0] == 0xFF) {
            break;
        }
    }
    assert_true(i < R.n_out);
}

static void test_lost_tc_is_fail_safe_and_reconnects_without_transfer(void **s) {
    unsigned i;
    (void)s;
    rig_init();
    connect(false);
    set_ack(TD_DDOP_EL_UPPER, 6u, 15000);
    set_ack(TD_DDOP_EL_BOOM, 289u, 1);
    tc_status(); /* the TC's last word */
    for (i = 0u; i < 100u; i++) { /* 1 s: still within the timeout */
        step();
    }
    assert_int_equal(td_tc_rate_mg_m2(&R.tc, 0u), 15000);
    step();
    assert_int_equal(td_tc_rate_mg_m2(&R.tc, 0u), 0);
    assert_int_equal(td_tc_sections_on(&R.tc), 0u);
    assert_true(R.tc.alarm);
    assert_int_equal(R.tc.state, TD_TC_WAIT_STATUS);
    R.n_out = 0u;
    connect(true); /* labels match: activated without a transfer */
    assert_false(R.tc.alarm);
    assert_int_equal(R.tc.connects, 2u);
    assert_int_equal(td_tc_rate_mg_m2(&R.tc, 0u), 15000); /* the TC sets it again; kept meanwhile */
}

/* A higher-priority NAME took our address and the claim moved us: the TC knows its client by
 * the address, so the connection starts again from the new one, with no rate meanwhile. */
static void test_moved_address_connects_again(void **s) {
    (void)s;
    rig_init();
    connect(false);
    set_ack(TD_DDOP_EL_UPPER, 6u, 15000);
    set_ack(TD_DDOP_EL_BOOM, 289u, 1);
    assert_int_equal(td_tc_rate_mg_m2(&R.tc, 0u), 15000);
    R.now += 10000u;
    td_tc_step(&R.tc, 0x85u, R.now, 0u, &R.tp, &R.q);
    assert_true(R.tc.alarm);
    assert_int_equal(R.tc.state, TD_TC_WAIT_STATUS);
    assert_int_equal(td_tc_rate_mg_m2(&R.tc, 0u), 0);
    assert_int_equal(td_tc_sections_on(&R.tc), 0u);
    tc_status(); /* the next status: the connection begins again */
    assert_int_equal(R.tc.state, TD_TC_VERSION);
}

static void test_refused_pool_raises_alarm(void **s) {
    uint8_t d[8];
    const uint8_t version[8] = {0x10, 4, 0xFF, 0x13, 0, 1, 16, 2};
    unsigned i;
    (void)s;
    rig_init();
    tc_status();
    tc_send(MY, version);
    for (i = 0u; i < 210u; i++) { /* no language answer: on after 2 s */
        step();
        if (i % 100u == 0u) {
            tc_status();
        }
    }
    assert_int_equal(R.tc.state, TD_TC_STRUCTURE);
    memset(d, 0xFF, sizeof d);
    d[0] = 0x11;
    tc_send(MY, d);
    memset(d, 0xFF, sizeof d);
    d[0] = 0x51;
    d[1] = 1; /* not enough memory */
    tc_send(MY, d);
    assert_int_equal(R.tc.state, TD_TC_REFUSED);
    assert_true(R.tc.alarm);
    assert_int_equal(R.tc.refuse_code, 1);
    assert_int_equal(td_tc_rate_mg_m2(&R.tc, 0u), 0);
    /* bad arguments and frames */
    assert_int_equal(td_tc_init(&R.tc, NAME, 0u), TD_IB_E_ARG);
    assert_int_equal(td_tc_rx(&R.tc, TD_IB_PGN_PROCESS_DATA, TC, MY, d, 7u, MY, 0u, &R.q),
                     TD_IB_E_FRAME);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_connect_transfers_pool_and_sets_rate),
        cmocka_unit_test(test_sections_by_condensed_work_state),
        cmocka_unit_test(test_measurements_by_time_distance_change),
        cmocka_unit_test(test_lost_tc_is_fail_safe_and_reconnects_without_transfer),
        cmocka_unit_test(test_moved_address_connects_again),
        cmocka_unit_test(test_refused_pool_raises_alarm),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
