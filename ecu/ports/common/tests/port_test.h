/* cmocka includes for the port's host tests. */
#ifndef PORT_TEST_H
#define PORT_TEST_H
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>
#include <cmocka.h>
#include "td_port.h"

/* Two frames alike in every field (a struct compare would read its padding). */
static inline void assert_frame_equal(const td_can_frame_t *a, const td_can_frame_t *b) {
    assert_int_equal(a->id, b->id);
    assert_int_equal(a->extended, b->extended);
    assert_int_equal(a->dlc, b->dlc);
    assert_memory_equal(a->data, b->data, 8u);
}
#endif
