/* The dual speed rule: truth table with its boundaries, both modes, both comparisons, fail-safes. */
#include "td_test.h"

#include "td_speedsel.h"

#define W TD_SRC_WHEEL
#define G TD_SRC_GNSS
#define N TD_SRC_NONE

typedef struct {
    td_speed_mode_t mode;
    td_compare_t cmp;
    float cv, vw, vg;
    bool gnss_ok, wheel_ok;
    td_source_t want;
} row_t;

static const row_t k_rows[] = {
    /* dual, GNSS compared (default): CV boundary at v = 8 */
    { TD_MODE_DUAL, TD_CMP_GNSS, 4.19f, 7.5f, 8.0f, true, true, G },
    { TD_MODE_DUAL, TD_CMP_GNSS, 4.20f, 7.5f, 8.0f, true, true, W },
    { TD_MODE_DUAL, TD_CMP_GNSS, 4.21f, 7.5f, 8.0f, true, true, W },
    { TD_MODE_DUAL, TD_CMP_GNSS, 0.0f, 7.5f, 8.0f, true, true, G },
    { TD_MODE_DUAL, TD_CMP_GNSS, -1.0f, 7.5f, 8.0f, true, true, W }, /* CV undefined */
    /* speed boundary at CV 2 */
    { TD_MODE_DUAL, TD_CMP_GNSS, 2.0f, 9.0f, 5.99f, true, true, W },
    { TD_MODE_DUAL, TD_CMP_GNSS, 2.0f, 9.0f, 6.00f, true, true, W },
    { TD_MODE_DUAL, TD_CMP_GNSS, 2.0f, 5.0f, 6.01f, true, true, G },
    /* wheel compared instead: the same speeds give the opposite answers */
    { TD_MODE_DUAL, TD_CMP_WHEEL, 2.0f, 5.99f, 9.0f, true, true, W },
    { TD_MODE_DUAL, TD_CMP_WHEEL, 2.0f, 6.00f, 9.0f, true, true, W },
    { TD_MODE_DUAL, TD_CMP_WHEEL, 2.0f, 6.01f, 5.0f, true, true, G },
    { TD_MODE_DUAL, TD_CMP_WHEEL, 4.21f, 6.01f, 9.0f, true, true, W },
    /* modes */
    { TD_MODE_WHEEL_ONLY, TD_CMP_GNSS, 0.0f, 9.0f, 9.0f, true, true, W },
    { TD_MODE_GNSS_ONLY, TD_CMP_GNSS, 30.0f, 1.0f, 1.0f, true, true, G },
    /* fail-safes in every mode */
    { TD_MODE_DUAL, TD_CMP_GNSS, 0.0f, 7.5f, 8.0f, false, true, W },
    { TD_MODE_GNSS_ONLY, TD_CMP_GNSS, 0.0f, 7.5f, 8.0f, false, true, W },
    { TD_MODE_DUAL, TD_CMP_GNSS, 30.0f, 0.0f, 3.0f, true, false, G },
    { TD_MODE_WHEEL_ONLY, TD_CMP_GNSS, 0.0f, 0.0f, 3.0f, true, false, G },
    { TD_MODE_DUAL, TD_CMP_GNSS, 0.0f, 0.0f, 3.0f, false, false, N },
    { TD_MODE_WHEEL_ONLY, TD_CMP_GNSS, 0.0f, 0.0f, 3.0f, false, false, N },
};

static void test_truth_table(void **state) {
    (void)state;
    for (size_t i = 0; i < sizeof k_rows / sizeof k_rows[0]; i++) {
        const row_t *r = &k_rows[i];
        const td_source_t got =
            td_speedsel_rule(r->mode, r->cmp, r->cv, 4.2f, 6.0f, r->vw, r->vg, r->gnss_ok, r->wheel_ok);
        if (got != r->want) {
            fail_msg("row %zu: got %d, want %d", i, (int)got, (int)r->want);
        }
    }
}

static void test_thresholds_are_parameters(void **state) {
    (void)state;
    /* with N = 3's noisier CV one might raise the threshold to 6 %: 5 % is then uniform */
    assert_int_equal(td_speedsel_rule(TD_MODE_DUAL, TD_CMP_GNSS, 5.0f, 6.0f, 6.0f, 7.0f, 7.0f, true, true), G);
    assert_int_equal(td_speedsel_rule(TD_MODE_DUAL, TD_CMP_GNSS, 5.0f, 4.2f, 6.0f, 7.0f, 7.0f, true, true), W);
    assert_int_equal(td_speedsel_rule(TD_MODE_DUAL, TD_CMP_GNSS, 1.0f, 4.2f, 8.0f, 7.0f, 7.0f, true, true), W);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_truth_table),
        cmocka_unit_test(test_thresholds_are_parameters),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
