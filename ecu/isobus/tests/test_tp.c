/* TP (BAM, CMDT) and ETP between two instances of the layer, frame by frame, plus the control
 * bytes on the wire, aborts and timeouts. */
#include "ib_test.h"

#include "td_tp.h"

#define A_ADDR 0x84u
#define B_ADDR 0x26u
#define PGN_PROCESS_DATA 0xCB00u

typedef struct {
    td_tp_t tp;
    td_ib_txq_t q;
    uint8_t addr;
    uint8_t conn[8000];
    uint8_t bam[1785];
    unsigned done;
    uint8_t got[8000];
    uint32_t got_len, got_pgn;
} node_t;

static void node_init(node_t *n, uint8_t addr) {
    memset(n, 0, sizeof *n);
    n->addr = addr;
    td_ib_txq_init(&n->q);
    assert_int_equal(td_tp_init(&n->tp, n->conn, sizeof n->conn, n->bam, sizeof n->bam), TD_IB_OK);
}

/* Moves frames both ways until quiet, stepping both at 10 ms; returns frames moved. */
static unsigned run(node_t *a, node_t *b, uint32_t *now, uint32_t until_us) {
    unsigned moved = 0u;
    td_can_frame_t f;
    while (*now < until_us) {
        node_t *nodes[2] = {a, b};
        unsigned i;
        for (i = 0u; i < 2u; i++) {
            node_t *from = nodes[i];
            node_t *to = nodes[1u - i];
            while (td_ib_txq_pop(&from->q, &f)) {
                moved++;
                if (td_tp_rx(&to->tp, &f, to->addr, *now, &to->q) == 1) {
                    to->done++;
                    memcpy(to->got, to->tp.msg.data, to->tp.msg.len);
                    to->got_len = to->tp.msg.len;
                    to->got_pgn = to->tp.msg.pgn;
                }
            }
        }
        *now += 10000u;
        td_tp_step(&a->tp, *now, &a->q);
        td_tp_step(&b->tp, *now, &b->q);
    }
    return moved;
}

static void fill(uint8_t *d, uint32_t n) {
    uint32_t i;
    for (i = 0u; i < n; i++) {
        d[i] = (uint8_t)((i * 7u + 3u) ^ (i >> 8));
    }
}

static void transfer(uint32_t len, uint8_t da, unsigned expect_frames_min) {
    static node_t a, b;
    static uint8_t msg[8000];
    uint32_t now = 1000u;
    unsigned moved;
    node_init(&a, A_ADDR);
    node_init(&b, B_ADDR);
    fill(msg, len);
    assert_int_equal(td_tp_send(&a.tp, PGN_PROCESS_DATA, A_ADDR, da, msg, len, now, &a.q), TD_IB_OK);
    assert_int_equal(a.tp.tx.state, TD_TP_TX_BUSY);
    moved = run(&a, &b, &now, 60000000u);
    assert_int_equal(a.tp.tx.state, TD_TP_TX_DONE);
    assert_int_equal(b.done, 1);
    assert_int_equal(b.got_len, len);
    assert_int_equal(b.got_pgn, PGN_PROCESS_DATA);
    assert_memory_equal(b.got, msg, len);
    assert_true(moved >= expect_frames_min);
    assert_int_equal(b.tp.rx_aborts + a.tp.rx_aborts, 0);
}

static void test_tp_cmdt_sizes(void **s) {
    (void)s;
    transfer(9u, B_ADDR, 4u);      /* RTS, CTS, 2 DT, EOMA */
    transfer(100u, B_ADDR, 18u);   /* 15 packets in one window */
    transfer(1785u, B_ADDR, 255u); /* 255 packets in 16 windows */
}

static void test_etp_sizes(void **s) {
    (void)s;
    transfer(1786u, B_ADDR, 256u);
    transfer(7777u, B_ADDR, 1111u);
}

static void test_bam(void **s) {
    (void)s;
    transfer(33u, TD_IB_ADDR_GLOBAL, 6u);
}

static void test_bam_paced_50ms(void **s) {
    node_t a;
    uint8_t msg[20];
    td_can_frame_t f;
    (void)s;
    node_init(&a, A_ADDR);
    fill(msg, sizeof msg);
    td_tp_send(&a.tp, 0xFECAu, A_ADDR, 0xFFu, msg, sizeof msg, 0u, &a.q);
    assert_true(td_ib_txq_pop(&a.q, &f));
    assert_int_equal(f.id, 0x1CECFF84u);
    assert_int_equal(f.data[0], 32);
    assert_int_equal(f.data[1], 20);
    assert_int_equal(f.data[3], 3);
    assert_int_equal(td_ib_get_u24(&f.data[5]), 0xFECAu);
    td_tp_step(&a.tp, 49999u, &a.q);
    assert_int_equal(a.q.count, 0);
    td_tp_step(&a.tp, 50000u, &a.q);
    assert_int_equal(a.q.count, 1);
    td_tp_step(&a.tp, 60000u, &a.q);
    assert_int_equal(a.q.count, 1);
}

static td_can_frame_t cm(uint8_t sa, uint8_t da, uint8_t b0, uint8_t b1, uint8_t b2, uint8_t b3,
                         uint8_t b4, uint32_t pgn) {
    uint8_t d[8] = {b0, b1, b2, b3, b4, 0u, 0u, 0u};
    td_ib_put_u24(&d[5], pgn);
    return ib_frame(7u, TD_IB_PGN_TP_CM, da, sa, d);
}

static td_can_frame_t dt(uint8_t sa, uint8_t da, uint8_t seq) {
    uint8_t d[8] = {seq, 1u, 2u, 3u, 4u, 5u, 6u, 7u};
    return ib_frame(7u, TD_IB_PGN_TP_DT, da, sa, d);
}

static void test_rx_wire_format_and_window_limit(void **s) {
    node_t b;
    td_can_frame_t f = cm(A_ADDR, B_ADDR, 16u, 40u, 0u, 6u, 4u, PGN_PROCESS_DATA);
    td_can_frame_t out[4];
    unsigned i;
    (void)s;
    node_init(&b, B_ADDR);
    assert_int_equal(td_tp_rx(&b.tp, &f, B_ADDR, 0u, &b.q), 0);
    assert_int_equal(ib_drain(&b.q, out, 4u), 1);
    assert_int_equal(out[0].id, 0x1CEC8426u);          /* TP.CM from us to the sender */
    assert_int_equal(out[0].data[0], 17);              /* CTS */
    assert_int_equal(out[0].data[1], 4);               /* the sender's limit of 4 */
    assert_int_equal(out[0].data[2], 1);
    assert_int_equal(td_ib_get_u24(&out[0].data[5]), PGN_PROCESS_DATA);
    for (i = 1u; i <= 4u; i++) {
        f = dt(A_ADDR, B_ADDR, (uint8_t)i);
        assert_int_equal(td_tp_rx(&b.tp, &f, B_ADDR, i * 1000u, &b.q), 0);
    }
    assert_int_equal(ib_drain(&b.q, out, 4u), 1);
    assert_int_equal(out[0].data[0], 17);
    assert_int_equal(out[0].data[1], 2); /* the last 2 packets */
    assert_int_equal(out[0].data[2], 5);
    f = dt(A_ADDR, B_ADDR, 5u);
    td_tp_rx(&b.tp, &f, B_ADDR, 6000u, &b.q);
    f = dt(A_ADDR, B_ADDR, 6u);
    assert_int_equal(td_tp_rx(&b.tp, &f, B_ADDR, 7000u, &b.q), 1);
    assert_int_equal(b.tp.msg.len, 40);
    assert_int_equal(b.tp.msg.data[39], 5); /* byte 5 of packet 6 */
    assert_int_equal(ib_drain(&b.q, out, 4u), 1);
    assert_int_equal(out[0].data[0], 19); /* EOMA */
    assert_int_equal(out[0].data[1], 40);
    assert_int_equal(out[0].data[3], 6);
}

static void test_rx_bad_sequence_aborts(void **s) {
    node_t b;
    td_can_frame_t f = cm(A_ADDR, B_ADDR, 16u, 40u, 0u, 6u, 0xFFu, PGN_PROCESS_DATA);
    td_can_frame_t out[4];
    (void)s;
    node_init(&b, B_ADDR);
    td_tp_rx(&b.tp, &f, B_ADDR, 0u, &b.q);
    f = dt(A_ADDR, B_ADDR, 2u);
    td_tp_rx(&b.tp, &f, B_ADDR, 1000u, &b.q);
    assert_int_equal(ib_drain(&b.q, out, 4u), 2);
    assert_int_equal(out[1].data[0], 255);
    assert_int_equal(out[1].data[1], TD_TP_ABORT_BAD_SEQUENCE);
    assert_int_equal(b.tp.rx_aborts, 1);
    assert_int_equal(b.tp.conn.kind, TD_TP_KIND_NONE);
}

static void test_rx_busy_too_long_and_malformed(void **s) {
    node_t b;
    td_can_frame_t out[4];
    td_can_frame_t first = cm(A_ADDR, B_ADDR, 16u, 40u, 0u, 6u, 0xFFu, PGN_PROCESS_DATA);
    td_can_frame_t second = cm(0x30u, B_ADDR, 16u, 40u, 0u, 6u, 0xFFu, PGN_PROCESS_DATA);
    td_can_frame_t wrong_count = cm(0x30u, B_ADDR, 16u, 40u, 0u, 7u, 0xFFu, PGN_PROCESS_DATA);
    (void)s;
    node_init(&b, B_ADDR);
    td_tp_rx(&b.tp, &first, B_ADDR, 0u, &b.q);
    td_tp_rx(&b.tp, &second, B_ADDR, 0u, &b.q);
    assert_int_equal(ib_drain(&b.q, out, 4u), 2);
    assert_int_equal(out[1].id, 0x1CEC3026u);
    assert_int_equal(out[1].data[1], TD_TP_ABORT_BUSY);
    assert_int_equal(b.tp.conn.sa, A_ADDR); /* the first session goes on */
    /* a receive buffer of 30 bytes cannot take 40 */
    assert_int_equal(td_tp_init(&b.tp, b.conn, 30u, b.bam, 0u), TD_IB_OK);
    td_tp_rx(&b.tp, &first, B_ADDR, 0u, &b.q);
    assert_int_equal(ib_drain(&b.q, out, 4u), 1);
    assert_int_equal(out[0].data[1], TD_TP_ABORT_RESOURCES);
    assert_int_equal(td_tp_rx(&b.tp, &wrong_count, B_ADDR, 0u, &b.q), TD_IB_E_FRAME);
    wrong_count.dlc = 5u;
    assert_int_equal(td_tp_rx(&b.tp, &wrong_count, B_ADDR, 0u, &b.q), TD_IB_E_FRAME);
    assert_int_equal(b.tp.rx_ignored, 2);
}

static void test_rx_timeout_sends_abort(void **s) {
    node_t b;
    td_can_frame_t f = cm(A_ADDR, B_ADDR, 16u, 40u, 0u, 6u, 0xFFu, PGN_PROCESS_DATA);
    td_can_frame_t out[4];
    (void)s;
    node_init(&b, B_ADDR);
    td_tp_rx(&b.tp, &f, B_ADDR, 0u, &b.q);
    f = dt(A_ADDR, B_ADDR, 1u);
    td_tp_rx(&b.tp, &f, B_ADDR, 100000u, &b.q);
    (void)ib_drain(&b.q, out, 4u);
    td_tp_step(&b.tp, 100000u + TD_TP_T1_US, &b.q);
    assert_int_equal(b.q.count, 0); /* T1 not yet over */
    td_tp_step(&b.tp, 100001u + TD_TP_T1_US, &b.q);
    assert_int_equal(ib_drain(&b.q, out, 4u), 1);
    assert_int_equal(out[0].data[0], 255);
    assert_int_equal(out[0].data[1], TD_TP_ABORT_TIMEOUT);
    assert_int_equal(b.tp.rx_timeouts, 1);
}

static void test_tx_abort_hold_and_timeout(void **s) {
    node_t a;
    uint8_t msg[50];
    td_can_frame_t out[16];
    td_can_frame_t f;
    (void)s;
    node_init(&a, A_ADDR);
    fill(msg, sizeof msg);
    /* the receiver aborts: the send ends with its reason */
    td_tp_send(&a.tp, PGN_PROCESS_DATA, A_ADDR, B_ADDR, msg, sizeof msg, 0u, &a.q);
    assert_int_equal(td_tp_send(&a.tp, PGN_PROCESS_DATA, A_ADDR, B_ADDR, msg, sizeof msg, 0u, &a.q),
                     TD_IB_E_BUSY);
    f = cm(B_ADDR, A_ADDR, 255u, 2u, 0xFFu, 0xFFu, 0xFFu, PGN_PROCESS_DATA);
    td_tp_rx(&a.tp, &f, A_ADDR, 1000u, &a.q);
    assert_int_equal(a.tp.tx.state, TD_TP_TX_ABORTED);
    assert_int_equal(a.tp.tx.abort_reason, 2);
    (void)ib_drain(&a.q, out, 16u);
    /* CTS with 0 packets holds for T4, then the send times out with Abort reason 3 */
    td_tp_send(&a.tp, PGN_PROCESS_DATA, A_ADDR, B_ADDR, msg, sizeof msg, 0u, &a.q);
    f = cm(B_ADDR, A_ADDR, 17u, 0u, 1u, 0xFFu, 0xFFu, PGN_PROCESS_DATA);
    td_tp_rx(&a.tp, &f, A_ADDR, 100000u, &a.q);
    td_tp_step(&a.tp, 100000u + TD_TP_T4_US, &a.q);
    assert_int_equal(a.tp.tx.state, TD_TP_TX_BUSY);
    td_tp_step(&a.tp, 100001u + TD_TP_T4_US, &a.q);
    assert_int_equal(a.tp.tx.state, TD_TP_TX_TIMEOUT);
    assert_int_equal(ib_drain(&a.q, out, 16u), 2);
    assert_int_equal(out[1].data[0], 255);
    assert_int_equal(out[1].data[1], TD_TP_ABORT_TIMEOUT);
    /* a CTS for packet 9 of 8 is answered with an abort */
    td_tp_send(&a.tp, PGN_PROCESS_DATA, A_ADDR, B_ADDR, msg, sizeof msg, 0u, &a.q);
    f = cm(B_ADDR, A_ADDR, 17u, 1u, 9u, 0xFFu, 0xFFu, PGN_PROCESS_DATA);
    td_tp_rx(&a.tp, &f, A_ADDR, 1000u, &a.q);
    assert_int_equal(a.tp.tx.state, TD_TP_TX_ABORTED);
    /* bad arguments */
    assert_int_equal(td_tp_send(&a.tp, PGN_PROCESS_DATA, A_ADDR, B_ADDR, msg, 8u, 0u, &a.q),
                     TD_IB_E_ARG);
    assert_int_equal(td_tp_send(&a.tp, PGN_PROCESS_DATA, A_ADDR, 0xFFu, msg, 1786u, 0u, &a.q),
                     TD_IB_E_TOO_LONG);
}

static void test_tx_cancel(void **s) {
    node_t a;
    uint8_t msg[50];
    td_can_frame_t out[4];
    (void)s;
    node_init(&a, A_ADDR);
    fill(msg, sizeof msg);
    td_tp_send(&a.tp, PGN_PROCESS_DATA, A_ADDR, B_ADDR, msg, sizeof msg, 0u, &a.q);
    td_tp_cancel(&a.tp, &a.q);
    assert_int_equal(ib_drain(&a.q, out, 4u), 2);
    assert_int_equal(out[1].data[0], 255);
    assert_int_equal(a.tp.tx.state, TD_TP_TX_ABORTED);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_tp_cmdt_sizes),
        cmocka_unit_test(test_etp_sizes),
        cmocka_unit_test(test_bam),
        cmocka_unit_test(test_bam_paced_50ms),
        cmocka_unit_test(test_rx_wire_format_and_window_limit),
        cmocka_unit_test(test_rx_bad_sequence_aborts),
        cmocka_unit_test(test_rx_busy_too_long_and_malformed),
        cmocka_unit_test(test_rx_timeout_sends_abort),
        cmocka_unit_test(test_tx_abort_hold_and_timeout),
        cmocka_unit_test(test_tx_cancel),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
