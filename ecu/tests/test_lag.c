/* The GNSS lag learned from the area between the wheel and GNSS over a speed change (td_lag.h):
 * launches from rest seen through a receiver's latency and first-order velocity filter, a
 * change between two speeds, a wheel scale not learned, noise, a change that never settles,
 * steady motion, bad input. The receiver: fixes every 0.2 s, each the filtered speed of its
 * epoch, arriving latency_s later, 0.05 s of which the PC reports as the fix's age. */
#include "td_test.h"

#include "td_fused.h"
#include "td_lag.h"

#define DT 0.01
#define AGE_S 0.05

typedef struct {
    double v0, v1;       /* m/s: from, to */
    double t0, ramp_s;   /* the change: a smoothstep from t0 over ramp_s */
} change_t;

static double smooth_v(const change_t *c, double t) {
    if (t <= c->t0) {
        return c->v0;
    }
    if (t >= c->t0 + c->ramp_s) {
        return c->v1;
    }
    const double x = (t - c->t0) / c->ramp_s;
    return c->v0 + (c->v1 - c->v0) * x * x * (3.0 - 2.0 * x);
}

/* A small deterministic noise source: uniform in -1..1. */
static double noise(uint32_t *seed) {
    *seed = *seed * 1664525u + 1013904223u;
    return (double)(*seed >> 8) / 8388608.0 - 1.0;
}

typedef struct {
    double latency_s, tau_s; /* the receiver */
    double rate_hz;          /* its fixes per second */
    double wheel_scale;      /* wheel speed / true speed */
    double gnss_noise_ms;    /* uniform noise per fix, m/s (0: none) */
    double bounce;           /* the wheel's bounce, share (uniform per 0.1 s) */
    bool slip_shape;         /* the estimate's slip shape (eq. 5) on, the wheel slipping as eq. 5 */
} rx_t;

typedef struct {
    td_fused_t f;
    td_lag_t l;
    double t;
    double y;              /* the receiver's filter */
    double pend_z[64];     /* fixes on their way: speed, arrival time */
    double pend_t[64];
    unsigned head, n;
    uint32_t seed;
    double bounce_now;
} sim_t;

static void sim_init(sim_t *s, double v_start) {
    memset(s, 0, sizeof *s);
    assert_int_equal(td_fused_init(&s->f, 0.3f, 0.2f, 15.0f), TD_OK);
    td_lag_init(&s->l);
    s->y = v_start;
    s->seed = 12345u;
}

static double wheel_of(const rx_t *rx, double v) {
    const double kmh = v * 3.6;
    const double slip = rx->slip_shape ? (0.167 * kmh * kmh - 0.296 * kmh + 0.773) / 100.0 : 0.0;
    return v > 0.0 ? rx->wheel_scale * v * (1.0 - slip) : 0.0;
}

/* Runs the drive `c` until t_end; returns how often the lag changed. */
static int sim_run(sim_t *s, const rx_t *rx, const change_t *c, double t_end) {
    const int fix_every = (int)(1.0 / (rx->rate_hz * DT) + 0.5);
    const double period = fix_every * DT;
    const double k = period / (rx->tau_s + period);
    int changes = 0;
    s->f.slip_shape = rx->slip_shape;
    while (s->t < t_end - 0.5 * DT) {
        const long step = lround(s->t / DT) + 1;
        s->t = (double)step * DT;
        if (step % 10 == 0) {
            s->bounce_now = rx->bounce * noise(&s->seed);
        }
        const double w = wheel_of(rx, smooth_v(c, s->t - 0.5 * DT)) * (1.0 + s->bounce_now);
        td_fused_record(&s->f, (float)w, (float)DT);
        td_lag_wheel(&s->l, (float)w, (float)DT);
        if (step % fix_every == 0) {
            /* the epoch's filtered speed, on its way for latency_s */
            s->y += k * (smooth_v(c, s->t) + rx->gnss_noise_ms * noise(&s->seed) - s->y);
            const unsigned i = (s->head + s->n) % 64u;
            s->pend_z[i] = s->y > 0.0 ? s->y : 0.0;
            s->pend_t[i] = s->t + rx->latency_s + AGE_S;
            s->n++;
        }
        while (s->n > 0u && s->pend_t[s->head] <= s->t + 1e-9) {
            if (td_lag_fix(&s->l, &s->f, (float)s->pend_z[s->head], (float)AGE_S)) {
                changes++;
            }
            s->head = (s->head + 1u) % 64u;
            s->n--;
        }
    }
    return changes;
}

static const rx_t CLEAN = { 0.3, 1.0, 5.0, 1.0, 0.0, 0.0, false };

/* A start from rest to 3 m/s over 5 s, then 20 s of cruise: D + tau within 0.05 s for
 * receivers of 0.2-2.0 s, a first estimate already during the launch. */
static void test_launch_through_delay_and_filter(void **state) {
    (void)state;
    const double rx_d[5][2] = { { 0.1, 0.1 }, { 0.2, 0.3 }, { 0.3, 1.0 }, { 0.3, 1.5 }, { 0.5, 1.5 } };
    const change_t c = { 0.0, 3.0, 3.0, 5.0 };
    for (int i = 0; i < 5; i++) {
        rx_t rx = CLEAN;
        rx.latency_s = rx_d[i][0];
        rx.tau_s = rx_d[i][1];
        sim_t s;
        sim_init(&s, 0.0);
        (void)sim_run(&s, &rx, &c, 7.0);
        assert_true(s.l.learned); /* while the launch goes on */
        (void)sim_run(&s, &rx, &c, 28.0);
        assert_true(s.l.learned);
        assert_float_equal(s.l.lag_s, rx.latency_s + rx.tau_s, 0.05);
    }
}

/* A change between two speeds in motion, up and then down, at 1 Hz and at 10 Hz. */
static void test_change_between_two_speeds(void **state) {
    (void)state;
    const double rates[2] = { 1.0, 10.0 };
    for (int i = 0; i < 2; i++) {
        rx_t rx = CLEAN;
        rx.rate_hz = rates[i];
        sim_t s;
        sim_init(&s, 2.0);
        const change_t up = { 2.0, 3.5, 10.0, 3.0 };
        (void)sim_run(&s, &rx, &up, 35.0);
        assert_true(s.l.learned);
        assert_float_equal(s.l.lag_s, 1.3, 0.05);
        const change_t down = { 3.5, 1.5, 40.0, 4.0 };
        (void)sim_run(&s, &rx, &down, 45.0);
        const float one = s.l.weight_ms; /* the first change's, final once the second began */
        assert_true(one > 0.0f);
        (void)sim_run(&s, &rx, &down, 75.0);
        assert_float_equal(s.l.lag_s, 1.3, 0.05);
        assert_true(s.l.weight_ms > one); /* and the second's */
    }
}

/* A wheel reading 3 % low (a scale the estimate has not learned), with eq. 5's slip on top:
 * the lag is the same. */
static void test_an_unlearned_scale_does_not_bias_it(void **state) {
    (void)state;
    const change_t c = { 0.0, 3.0, 3.0, 5.0 };
    double lag[2];
    for (int i = 0; i < 2; i++) {
        rx_t rx = CLEAN;
        rx.slip_shape = true;
        rx.wheel_scale = i == 0 ? 1.0 : 0.97;
        sim_t s;
        sim_init(&s, 0.0);
        (void)sim_run(&s, &rx, &c, 28.0);
        lag[i] = s.l.lag_s;
    }
    assert_float_equal(lag[0], 1.3, 0.05);
    assert_float_equal(lag[1], lag[0], 0.02);
}

/* GNSS noise (0.05 m/s per fix, uniform +-0.087) and a bouncing wheel (3 %): within 0.1 s. */
static void test_noise(void **state) {
    (void)state;
    const change_t c = { 0.0, 3.0, 3.0, 5.0 };
    rx_t rx = CLEAN;
    rx.gnss_noise_ms = 0.087;
    rx.bounce = 0.05;
    for (uint32_t seed = 1u; seed <= 5u; seed++) {
        sim_t s;
        sim_init(&s, 0.0);
        s.seed = seed;
        (void)sim_run(&s, &rx, &c, 28.0);
        assert_float_equal(s.l.lag_s, 1.3, 0.1);
    }
}

/* Steady motion teaches nothing; a change that never settles (a speed swinging +-0.4 m/s
 * around 2 m/s every 6 s for 2 minutes) gives no result. */
static void test_steady_and_never_settling_teach_nothing(void **state) {
    (void)state;
    rx_t rx = CLEAN;
    sim_t s;
    sim_init(&s, 2.0);
    const change_t steady = { 2.0, 2.0, 0.0, 1.0 };
    assert_int_equal(sim_run(&s, &rx, &steady, 30.0), 0);
    assert_false(s.l.learned);
    for (int k = 0; k < 40; k++) {
        const double from = k % 2 == 0 ? 2.0 : 2.8;
        const change_t swing = { from, k % 2 == 0 ? 2.8 : 2.0, s.t, 3.0 };
        (void)sim_run(&s, &rx, &swing, s.t + 3.0);
        assert_false(s.l.area); /* (the first swing's early lag aside) */
    }
    assert_float_equal(s.l.weight_ms, 0.0, 0.0);
    assert_int_equal(s.l.phase, 2u);
    assert_false(s.l.pending); /* dropped after 60 s */
}

/* Bad numbers are ignored (NaN, negative speed or age); a missing wheel drops the window;
 * learning goes on afterwards. */
static void test_bad_input(void **state) {
    (void)state;
    rx_t rx = CLEAN;
    sim_t s;
    sim_init(&s, 0.0);
    const change_t rest = { 0.0, 0.0, 0.0, 1.0 };
    (void)sim_run(&s, &rx, &rest, 3.0);
    const td_lag_t before = s.l;
    assert_false(td_lag_fix(&s.l, &s.f, NAN, (float)AGE_S));
    assert_false(td_lag_fix(&s.l, &s.f, -1.0f, (float)AGE_S));
    assert_false(td_lag_fix(&s.l, &s.f, 1.0f, -0.1f));
    assert_false(td_lag_fix(&s.l, &s.f, 1.0f, NAN));
    assert_memory_equal(&before, &s.l, sizeof before);
    /* a wheel fault in the launch: that window is dropped, nothing learned from it */
    const change_t c = { 0.0, 3.0, 3.0, 5.0 };
    (void)sim_run(&s, &rx, &c, 5.0);
    td_lag_wheel(&s.l, -1.0f, (float)DT);
    td_lag_wheel(&s.l, NAN, (float)DT);
    (void)sim_run(&s, &rx, &c, 28.0);
    assert_float_equal(s.l.weight_ms, 0.0, 0.0);
    /* the next change teaches it */
    const change_t down = { 3.0, 1.0, 30.0, 4.0 };
    (void)sim_run(&s, &rx, &down, 55.0);
    assert_true(s.l.learned);
    assert_float_equal(s.l.lag_s, 1.3, 0.05);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_launch_through_delay_and_filter),
        cmocka_unit_test(test_change_between_two_speeds),
        cmocka_unit_test(test_an_unlearned_scale_does_not_bias_it),
        cmocka_unit_test(test_noise),
        cmocka_unit_test(test_steady_and_never_settling_teach_nothing),
        cmocka_unit_test(test_bad_input),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
