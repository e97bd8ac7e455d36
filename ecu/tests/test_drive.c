/* Metering drive: the reference model keeps P and I out of a step the feed-forward already makes,
 * the slope is learned from a start-up ramp (bounded), and without adaptation and model it is
 * the plain PID. Plant: the simulator's drive, speed = 66 * (duty - 0.04) r/min, tau 0.15 s,
 * measured over a 100 ms window. */
#include "td_test.h"

#include "td_drive.h"

#define DT 0.01

typedef struct {
    double rpm;          /* shaft speed */
    double win[10];      /* speeds of the last 10 steps: the 100 ms count window */
    int k;
    double slope, offset; /* speed = slope * (duty - offset) */
} plant_t;

static float plant_step(plant_t *p, float duty) {
    double ss = p->slope * ((double)duty - p->offset);
    if (ss < 0.0) {
        ss = 0.0;
    }
    p->rpm = first_order(p->rpm, 1.0, ss, 0.15, DT);
    p->win[p->k++ % 10] = p->rpm;
    double sum = 0.0;
    for (int i = 0; i < 10; i++) {
        sum += p->win[i];
    }
    return (float)(sum / 10.0);
}

/* From rest: target steps of 3 r/min every 0.5 s up to 29 r/min (the paper's start on the wheel),
 * then `hold_s` at 29. Returns the last duty. */
static float ramp_up(td_drive_t *d, plant_t *p, double hold_s) {
    float meas = 0.0f;
    float duty = 0.0f;
    for (int k = 0; k < (int)((5.0 + hold_s) / DT); k++) {
        const double t = k * DT;
        const float target = t < 5.0 ? (float)(2.0 + 3.0 * floor(t / 0.5)) : 29.0f;
        duty = td_drive_step(d, target, meas, (float)DT);
        meas = plant_step(p, duty);
    }
    return duty;
}

static void test_slope_learned_on_the_start_up_ramp(void **state) {
    (void)state;
    td_drive_t d;
    td_drive_init(&d, 0.015f, 0.01f, 0.0f, 1.0f / 60.0f, 0.2f, true);
    plant_t p = { 0.0, { 0.0 }, 0, 66.0, 0.04 };
    assert_float_equal(td_drive_rpm_per_duty(&d), 60.0, 1e-3);
    (void)ramp_up(&d, &p, 10.0);
    assert_float_equal(td_drive_rpm_per_duty(&d), 66.0, 0.03 * 66.0);
    /* a step down of 7 r/min: no undershoot beyond 2 % of the jump, within 5 % in 0.6 s */
    const float r1 = 22.0f;
    float meas = (float)p.rpm;
    double low = 1e9;
    double settled_at = -1.0;
    for (int k = 0; k < 300; k++) {
        meas = plant_step(&p, td_drive_step(&d, r1, meas, (float)DT));
        low = meas < low ? meas : low;
        if (fabs(meas - r1) > 0.05 * r1) {
            settled_at = -1.0;
        } else if (settled_at < 0.0) {
            settled_at = (k + 1) * DT;
        }
    }
    assert_true(r1 - low < 0.02 * 7.0);
    assert_true(settled_at > 0.0 && settled_at <= 0.6);
    assert_float_equal(meas, r1, 0.02);
}

/* The same step without learning (feed-forward 1/60 against 66): the reference model alone
 * already halves the undershoot of the plain PID. */
static void test_reference_model_against_plain_pid(void **state) {
    (void)state;
    double under[2];
    for (int m = 0; m < 2; m++) {
        td_drive_t d;
        td_drive_init(&d, 0.015f, 0.01f, 0.0f, 1.0f / 60.0f, m == 0 ? 0.0f : 0.2f, false);
        plant_t p = { 0.0, { 0.0 }, 0, 66.0, 0.04 };
        (void)ramp_up(&d, &p, 10.0);
        float meas = (float)p.rpm;
        double low = 1e9;
        for (int k = 0; k < 300; k++) {
            meas = plant_step(&p, td_drive_step(&d, 22.0f, meas, (float)DT));
            low = meas < low ? meas : low;
        }
        under[m] = 22.0 - low;
        assert_float_equal(td_drive_rpm_per_duty(&d), 60.0, 1e-3); /* no adaptation */
    }
    assert_true(under[0] > 0.05 * 7.0);   /* plain PID: the integral winds up during the step */
    assert_true(under[1] < 0.5 * under[0]);
}

/* Without the model and adaptation it is td_pid_step with the same gains, bit for bit. */
static void test_plain_pid_without_model(void **state) {
    (void)state;
    td_drive_t d;
    td_drive_init(&d, 0.015f, 0.01f, 0.0f, 1.0f / 60.0f, 0.0f, false);
    td_pid_t pid;
    td_pid_init(&pid, 0.015f, 0.01f, 0.0f, 1.0f / 60.0f, 0.0f, 1.0f);
    plant_t p = { 0.0, { 0.0 }, 0, 60.0, 0.0 };
    float meas = 0.0f;
    for (int k = 0; k < 500; k++) {
        const float target = k < 250 ? 24.0f : 12.0f;
        const float a = td_drive_step(&d, target, meas, (float)DT);
        const float b = td_pid_step(&pid, target, meas, (float)DT);
        assert_true(a == b);
        meas = plant_step(&p, a);
    }
}

/* A drive far from the configured one: the learned feed-forward stays within 0.5..2 x. */
static void test_learned_slope_bounded(void **state) {
    (void)state;
    td_drive_t d;
    td_drive_init(&d, 0.015f, 0.01f, 0.0f, 1.0f / 60.0f, 0.2f, true);
    plant_t p = { 0.0, { 0.0 }, 0, 200.0, 0.0 };
    const float duty = ramp_up(&d, &p, 30.0);
    assert_true(duty >= 0.0f && duty <= 1.0f);
    const float learned = td_drive_rpm_per_duty(&d);
    assert_true(learned > 100.0f && learned <= 120.0f + 1e-3f);
    /* a reset keeps what was learned; a new configuration restarts it */
    td_drive_reset(&d);
    assert_float_equal(td_drive_rpm_per_duty(&d), learned, 0.0);
    td_drive_config(&d, 0.015f, 0.01f, 0.0f, 1.0f / 60.0f, 0.2f, true);
    assert_float_equal(td_drive_rpm_per_duty(&d), 60.0, 1e-3);
}

/* A start from rest (the target leaves 0): no model lag. While the target holds, the drive
 * with the model gives the plain PID's duties bit for bit, the first one kff*T + kp*T + ki*T*dt
 * (P and I push the drive off its breakaway at once); a later change is shaped by the model. */
static void test_start_from_rest_without_model_lag(void **state) {
    (void)state;
    td_drive_t d;
    td_drive_init(&d, 0.015f, 0.01f, 0.0f, 1.0f / 60.0f, 0.2f, false);
    td_pid_t pid;
    td_pid_init(&pid, 0.015f, 0.01f, 0.0f, 1.0f / 60.0f, 0.0f, 1.0f);
    plant_t p = { 0.0, { 0.0 }, 0, 66.0, 0.04 };
    const float t0 = 3.0f;
    const float first = td_drive_step(&d, t0, 0.0f, (float)DT);
    assert_float_equal(first, t0 / 60.0f + 0.015f * t0 + 0.01f * t0 * (float)DT, 1e-6);
    assert_float_equal(d.ref_rpm, t0, 0.0);
    assert_true(first == td_pid_step(&pid, t0, 0.0f, (float)DT));
    float meas = plant_step(&p, first);
    for (int k = 1; k < 100; k++) {
        const float a = td_drive_step(&d, t0, meas, (float)DT);
        assert_true(a == td_pid_step(&pid, t0, meas, (float)DT));
        meas = plant_step(&p, a);
    }
    /* an in-run step: the reference follows with tau 0.2 s (one step: a = dt / (tau + dt)) */
    (void)td_drive_step(&d, 10.0f, meas, (float)DT);
    assert_float_equal(d.ref_rpm, t0 + (10.0f - t0) * (float)(DT / (0.2 + DT)), 1e-4);
    /* a stop and a new start: again no lag */
    td_drive_reset(&d);
    (void)td_drive_step(&d, 5.0f, meas, (float)DT);
    assert_float_equal(d.ref_rpm, 5.0, 0.0);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_slope_learned_on_the_start_up_ramp),
        cmocka_unit_test(test_reference_model_against_plain_pid),
        cmocka_unit_test(test_plain_pid_without_model),
        cmocka_unit_test(test_learned_slope_bounded),
        cmocka_unit_test(test_start_from_rest_without_model_lag),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
