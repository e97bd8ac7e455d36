/* The SPSC rings: order, full and empty, wrap of the free-running indices, and two threads. */
#include "port_test.h"
#include <pthread.h>
#include "td_ring.h"

static td_can_frame_t frame_n(uint32_t n) {
    td_can_frame_t f;
    memset(&f, 0, sizeof f);
    f.id = n & 0x1FFFFFFFu;
    f.extended = 1u;
    f.dlc = 8u;
    for (unsigned i = 0u; i < 8u; i++) {
        f.data[i] = (uint8_t)(n >> (i % 4u * 8u));
    }
    return f;
}

static void test_frames_in_order_full_and_empty(void **state) {
    (void)state;
    static td_frame_ring_t r;
    td_frame_ring_init(&r);
    td_can_frame_t f;
    assert_false(td_frame_ring_pop(&r, &f));
    for (uint32_t i = 0u; i < TD_FRAME_RING_LEN; i++) {
        const td_can_frame_t in = frame_n(i);
        assert_true(td_frame_ring_push(&r, &in));
    }
    const td_can_frame_t extra = frame_n(999u);
    assert_false(td_frame_ring_push(&r, &extra));
    assert_int_equal(r.dropped, 1u);
    assert_int_equal(td_frame_ring_count(&r), TD_FRAME_RING_LEN);
    for (uint32_t i = 0u; i < TD_FRAME_RING_LEN; i++) {
        assert_true(td_frame_ring_pop(&r, &f));
        assert_int_equal(f.id, i);
        assert_int_equal(f.data[1], (uint8_t)(i >> 8));
    }
    assert_false(td_frame_ring_pop(&r, &f));
    assert_int_equal(td_frame_ring_count(&r), 0u);
}

static void test_indices_wrap_at_2_pow_32(void **state) {
    (void)state;
    static td_frame_ring_t r;
    td_frame_ring_init(&r);
    r.head = r.tail = 0xFFFFFFF0u; /* 16 pushes before the wrap of the counters */
    td_can_frame_t f;
    for (uint32_t i = 0u; i < 100u; i++) {
        const td_can_frame_t in = frame_n(i);
        assert_true(td_frame_ring_push(&r, &in));
        assert_true(td_frame_ring_push(&r, &in));
        assert_int_equal(td_frame_ring_count(&r), 2u);
        assert_true(td_frame_ring_pop(&r, &f));
        assert_true(td_frame_ring_pop(&r, &f));
        assert_int_equal(f.id, i);
    }
    assert_true(r.head < 0x100u);
}

static void test_bytes_whole_lines_or_nothing(void **state) {
    (void)state;
    static td_byte_ring_t r;
    td_byte_ring_init(&r);
    uint8_t line[200];
    for (unsigned i = 0u; i < sizeof line; i++) {
        line[i] = (uint8_t)i;
    }
    assert_true(td_byte_ring_write(&r, line, 200u));
    assert_true(td_byte_ring_write(&r, line, 200u));
    assert_false(td_byte_ring_write(&r, line, 200u)); /* 112 free: none of it goes in */
    assert_int_equal(r.dropped, 200u);
    assert_int_equal(td_byte_ring_count(&r), 400u);
    assert_true(td_byte_ring_write(&r, line, 112u));
    assert_false(td_byte_ring_push(&r, 7u));
    uint8_t b;
    for (unsigned i = 0u; i < 512u; i++) {
        assert_true(td_byte_ring_pop(&r, &b));
        assert_int_equal(b, (uint8_t)(i % 200u));
    }
    assert_false(td_byte_ring_pop(&r, &b));
}

/* A producer thread (the interrupt) and the consumer (the main loop): every frame arrives once,
 * in order, intact, or is counted as dropped. */
#define STRESS_N 200000u
static td_frame_ring_t shared;

static void *producer(void *arg) {
    (void)arg;
    for (uint32_t i = 0u; i < STRESS_N; i++) {
        const td_can_frame_t f = frame_n(i);
        while (!td_frame_ring_push(&shared, &f)) {
            shared.dropped--; /* retry: this test wants every frame through */
        }
    }
    return NULL;
}

static void test_two_threads(void **state) {
    (void)state;
    td_frame_ring_init(&shared);
    pthread_t t;
    assert_int_equal(pthread_create(&t, NULL, producer, NULL), 0);
    uint32_t next = 0u;
    while (next < STRESS_N) {
        td_can_frame_t f;
        if (td_frame_ring_pop(&shared, &f)) {
            const td_can_frame_t want = frame_n(next);
            assert_frame_equal(&f, &want);
            next++;
        }
    }
    assert_int_equal(pthread_join(t, NULL), 0);
    assert_int_equal(shared.dropped, 0u);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_frames_in_order_full_and_empty),
        cmocka_unit_test(test_indices_wrap_at_2_pow_32),
        cmocka_unit_test(test_bytes_whole_lines_or_nothing),
        cmocka_unit_test(test_two_threads),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
