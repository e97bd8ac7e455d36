/* SLCAN lines: what python-can's slcan interface sends and expects, and what is refused. */
#include "port_test.h"
#include "td_common.h"
#include "td_slcan.h"

static td_slcan_event_t feed_line(td_slcan_parser_t *p, const char *s, td_can_frame_t *f, uint8_t *arg) {
    td_slcan_event_t ev = TD_SLCAN_NONE;
    for (const char *c = s; *c != '\0'; c++) {
        const td_slcan_event_t e = td_slcan_feed(p, (uint8_t)*c, f, arg);
        if (e != TD_SLCAN_NONE) {
            ev = e;
        }
    }
    return ev;
}

static void test_python_can_opening_and_frames(void **state) {
    (void)state;
    td_slcan_parser_t p;
    td_slcan_init(&p);
    td_can_frame_t f;
    uint8_t arg = 0u;
    assert_int_equal(feed_line(&p, "C\r", &f, &arg), TD_SLCAN_CLOSE);
    assert_int_equal(feed_line(&p, "S5\r", &f, &arg), TD_SLCAN_BITRATE);
    assert_int_equal(arg, 5u);
    assert_int_equal(feed_line(&p, "O\r", &f, &arg), TD_SLCAN_OPEN);
    /* python-can: 'T%08X%d%s' with upper-case hex */
    assert_int_equal(feed_line(&p, "T0A5C64658" "0AB80B204ECA3A41\r", &f, &arg), TD_SLCAN_FRAME);
    assert_int_equal(f.id, 0x0A5C6465u);
    assert_int_equal(f.extended, 1u);
    assert_int_equal(f.dlc, 8u);
    assert_int_equal(f.data[0], 0x0A);
    assert_int_equal(f.data[7], 0x41);
    /* lower case, a time stamp, an 11-bit frame, an empty frame */
    assert_int_equal(feed_line(&p, "t1232beef1234\r", &f, &arg), TD_SLCAN_FRAME);
    assert_int_equal(f.id, 0x123u);
    assert_int_equal(f.extended, 0u);
    assert_int_equal(f.dlc, 2u);
    assert_int_equal(f.data[0], 0xBE);
    assert_int_equal(feed_line(&p, "T1FFFFFFF0\r", &f, &arg), TD_SLCAN_FRAME);
    assert_int_equal(f.dlc, 0u);
    assert_int_equal(feed_line(&p, "\r", &f, &arg), TD_SLCAN_NONE);
    assert_int_equal(feed_line(&p, "\n", &f, &arg), TD_SLCAN_NONE);
    assert_int_equal(p.errors, 0u);
}

static void test_bad_lines_are_refused_and_counted(void **state) {
    (void)state;
    td_slcan_parser_t p;
    td_slcan_init(&p);
    td_can_frame_t f;
    uint8_t arg;
    const char *bad[] = {
        "T20000000" "0\r",                      /* identifier above 29 bits */
        "t8000\r",                              /* above 11 bits */
        "T0A5C64659" "000000000000000000\r",    /* DLC 9 */
        "T0A5C64658" "00112233445566\r",        /* 7 bytes for DLC 8 */
        "T0A5C6465" "2" "00G1\r",               /* not hex */
        "R0A5C64658\r",                         /* remote frame */
        "S9\r", "Ox\r", "X\r",
        "T0A5C64658" "0011223344556677" "0011223344556677\r", /* longer than a line */
    };
    for (unsigned i = 0u; i < sizeof bad / sizeof bad[0]; i++) {
        assert_int_equal(feed_line(&p, bad[i], &f, &arg), TD_SLCAN_ERROR);
    }
    assert_int_equal(p.errors, sizeof bad / sizeof bad[0]);
    /* the line after a refused one is taken */
    assert_int_equal(feed_line(&p, "O\r", &f, &arg), TD_SLCAN_OPEN);
}

static void test_encode_round_trip(void **state) {
    (void)state;
    td_slcan_parser_t p;
    td_slcan_init(&p);
    char buf[TD_SLCAN_FRAME_MAX + 1u];
    for (uint32_t n = 0u; n < 2000u; n++) {
        td_can_frame_t f;
        memset(&f, 0, sizeof f);
        f.extended = (uint8_t)(n % 3u != 0u);
        f.id = (n * 2654435761u) & (f.extended != 0u ? 0x1FFFFFFFu : 0x7FFu);
        f.dlc = (uint8_t)(n % 9u);
        for (unsigned i = 0u; i < f.dlc; i++) {
            f.data[i] = (uint8_t)(n * 31u + i);
        }
        const int len = td_slcan_encode(&f, buf, sizeof buf);
        assert_int_equal(len, (f.extended != 0u ? 10 : 5) + 2 * f.dlc + 1);
        buf[len] = '\0';
        td_can_frame_t g;
        assert_int_equal(feed_line(&p, buf, &g, NULL), TD_SLCAN_FRAME);
        assert_frame_equal(&f, &g);
    }
    td_can_frame_t f = { 0x185C6465u, 1u, 8u, { 0x0A, 0, 0, 0, 0, 0, 0, 0xFF } };
    assert_int_equal(td_slcan_encode(&f, buf, sizeof buf), 27);
    assert_memory_equal(buf, "T185C646580A000000000000FF\r", 27);
    assert_int_equal(td_slcan_encode(&f, buf, 26u), TD_E_ARG);
    f.dlc = 9u;
    assert_int_equal(td_slcan_encode(&f, buf, sizeof buf), TD_E_ARG);
    f.dlc = 8u;
    f.extended = 0u;
    assert_int_equal(td_slcan_encode(&f, buf, sizeof buf), TD_E_ARG);
}

static void test_replies(void **state) {
    (void)state;
    char buf[8];
    assert_int_equal(td_slcan_reply(TD_SLCAN_OPEN, buf, sizeof buf), 1u);
    assert_int_equal(buf[0], '\r');
    assert_int_equal(td_slcan_reply(TD_SLCAN_ERROR, buf, sizeof buf), 1u);
    assert_int_equal(buf[0], '\a');
    assert_int_equal(td_slcan_reply(TD_SLCAN_VERSION, buf, sizeof buf), 6u);
    assert_memory_equal(buf, "V0100\r", 6);
    assert_int_equal(td_slcan_reply(TD_SLCAN_FRAME, buf, sizeof buf), 0u);
    assert_int_equal(td_slcan_reply(TD_SLCAN_VERSION, buf, 3u), 0u);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_python_can_opening_and_frames),
        cmocka_unit_test(test_bad_lines_are_refused_and_counted),
        cmocka_unit_test(test_encode_round_trip),
        cmocka_unit_test(test_replies),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
