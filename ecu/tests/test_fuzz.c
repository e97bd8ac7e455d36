/* Deterministic randomized robustness test of the ECU application: 200,000 frames (known ids with
 * shaped and random payloads, unknown 29- and 11-bit ids, DLC 0..15, random bytes) interleaved
 * with control steps at jittered, repeated, late, backward and wild times across clock wraps,
 * encoder counters with random jumps, jammed meters and dead fans, on a fixed seed. After every
 * call the invariants of the port contract and of the fail-safes are checked. Runs under ASan
 * and UBSan too (make ctest). */
#include "td_test.h"

#include <stdio.h>

#define TD_CHECK(cond) assert_true(cond)
#include "td_invariants.h"

#define FUZZ_FRAMES 200000u
#define FUZZ_SEED 0x7D2026u
#define PHASE_FRAMES 4000u

typedef struct {
    uint64_t s;
} rng_t;

static uint32_t rnd(rng_t *g) {
    /* xorshift64*: fixed seed, same sequence on every machine */
    g->s ^= g->s >> 12;
    g->s ^= g->s << 25;
    g->s ^= g->s >> 27;
    return (uint32_t)((g->s * 0x2545F4914F6CDD1DULL) >> 32);
}

static uint32_t below(rng_t *g, uint32_t n) {
    return rnd(g) % n;
}

/* The world the ECU sees: a phase decides whether the PC wants to run and how the plant behaves. */
typedef struct {
    bool want_run;
    bool restore_defaults; /* the PC writes every parameter back to its default first */
    bool gnss_frozen;      /* the receiver repeats one speed */
    bool bus_off;          /* the port cannot send: the transmit queue is not drained */
    double v_kmh;          /* tractor speed */
    bool wheel_dead;
    bool edge_timing;      /* the port supplies wheel edge times */
    uint32_t now_us;       /* the time of the step being prepared */
    bool meter_jammed[2];
    bool fan_dead[2];
    double meter_rpm[2], fan_rpm[2];
    double wheel_pos, meter_pos[2], fan_pos[2];
    uint32_t wheel_off, meter_off[2], fan_off[2]; /* random counter jumps */
} world_t;

typedef struct {
    uint32_t frames, rejected, steps, running_steps, metering_steps, tx_frames;
    uint32_t cmd_ok, param_ok, gnss_time_ok, faults_seen, fused_steps, edge_steps;
} tally_t;

static void new_phase(rng_t *g, world_t *w) {
    w->want_run = below(g, 3u) != 0u;
    w->restore_defaults = w->want_run && below(g, 2u) == 0u;
    w->gnss_frozen = below(g, 6u) == 0u;
    w->bus_off = below(g, 8u) == 0u;
    const double speeds[] = { 0.0, 2.5, 4.0, 6.5, 8.0, 12.0, 30.0 };
    w->v_kmh = speeds[below(g, 7u)];
    w->wheel_dead = below(g, 8u) == 0u;
    w->edge_timing = below(g, 2u) == 0u;
    for (int l = 0; l < 2; l++) {
        w->meter_jammed[l] = below(g, 8u) == 0u;
        w->fan_dead[l] = below(g, 10u) == 0u;
    }
}

static void put_u16(uint8_t *d, uint32_t v) {
    d[0] = (uint8_t)v;
    d[1] = (uint8_t)(v >> 8);
}

static void shape_command(rng_t *g, const world_t *w, td_can_frame_t *f) {
    /* a stop now and then while working (each one acknowledges the latched faults) */
    const bool start = w->want_run ? below(g, 2000u) != 0u : below(g, 20u) == 0u;
    f->data[0] = below(g, 50u) == 0u ? (uint8_t)rnd(g) : (start ? TD_RUN_RUNNING : TD_RUN_STOPPED);
    put_u16(&f->data[1], below(g, 10u) == 0u ? below(g, 65536u) : 2500u + below(g, 1000u));
    put_u16(&f->data[3], below(g, 10u) == 0u ? below(g, 65536u) : below(g, 60001u));
    put_u16(&f->data[5], below(g, 10u) == 0u ? below(g, 65536u) : below(g, 60001u));
    const uint32_t gk = w->gnss_frozen ? 2u : below(g, 20u);
    const uint32_t v10 = (uint32_t)(w->v_kmh * 10.0 + 0.5);
    const uint32_t noise = w->gnss_frozen ? 0u : below(g, 2u);
    f->data[7] = gk == 0u ? 0xFFu : gk == 1u ? (uint8_t)rnd(g) : (uint8_t)(v10 >= 250u ? 250u : v10 + noise);
}

static void shape_param_set(rng_t *g, td_can_frame_t *f) {
    const uint8_t id = (uint8_t)below(g, TD_PARAM_COUNT + 4u);
    float scale;
    uint32_t lo = 0u;
    uint32_t hi = 0u;
    uint32_t raw = rnd(g);
    if (td_params_encoding(id, &scale, &lo, &hi) == TD_OK && below(g, 4u) != 0u) {
        raw = lo + below(g, hi - lo + 1u);
    }
    f->data[0] = id;
    if (below(g, 4u) != 0u) {
        f->data[1] = f->data[2] = f->data[3] = 0u;
    }
    f->data[4] = (uint8_t)raw;
    f->data[5] = (uint8_t)(raw >> 8);
    f->data[6] = (uint8_t)(raw >> 16);
    f->data[7] = (uint8_t)(raw >> 24);
}

static void shape_gnss_time(rng_t *g, const world_t *w, td_can_frame_t *f) {
    const uint32_t k = below(g, 20u);
    const uint32_t v100 = (uint32_t)(w->v_kmh * 100.0 + 0.5);
    const uint32_t fine = k == 0u ? 0xFFFFu : k == 1u ? below(g, 65536u) : (v100 >= 2500u ? 2500u : v100 + below(g, 20u));
    put_u16(&f->data[0], fine);
    put_u16(&f->data[2], below(g, 10u) == 0u ? below(g, 65536u) : below(g, 1500u));
    f->data[4] = (uint8_t)(w->gnss_frozen ? 7u : below(g, 256u));
}

static void random_frame(rng_t *g, const world_t *w, const td_app_t *app, td_can_frame_t *f) {
    static const uint32_t ecu_ids[] = { TD_ID_ECU_STATUS,    TD_ID_ECU_DIAG,  TD_ID_ECU_SPEEDS,   TD_ID_ECU_TARGETS,
                                        TD_ID_ECU_PARAM_ACK, TD_ID_ECU_FUSED, TD_ID_ECU_FUSED_AUX };
    for (int i = 0; i < 8; i++) {
        f->data[i] = (uint8_t)rnd(g);
    }
    const uint32_t k = below(g, 100u);
    f->extended = 1u;
    if (k < 40u) {
        f->id = app->p.command_id;
        if (below(g, 8u) != 0u) {
            shape_command(g, w, f);
        }
    } else if (k < 65u) {
        f->id = TD_ID_PC_PARAM_SET;
        if (below(g, 8u) != 0u) {
            shape_param_set(g, f);
        }
    } else if (k < 70u) {
        f->id = TD_ID_PC_GNSS_TIME;
        if (below(g, 8u) != 0u) {
            shape_gnss_time(g, w, f);
        }
    } else if (k < 75u) {
        f->id = ecu_ids[below(g, 7u)];
    } else if (k < 88u) {
        f->id = rnd(g) & 0x1FFFFFFFu;
    } else {
        f->id = below(g, 2u) == 0u ? (app->p.command_id & 0x7FFu) : (rnd(g) & 0x7FFu);
        f->extended = 0u;
    }
    if (k < 75u && below(g, 30u) == 0u) {
        f->extended = 0u; /* a known number as an 11-bit frame is another identifier */
    }
    f->dlc = below(g, 5u) == 0u ? (uint8_t)below(g, 16u) : 8u;
}

/* Counts what happened, to show the run reached the interesting states. */
static void tally_rx(const td_app_t *app, const td_can_frame_t *f, int rc, tally_t *t) {
    t->frames++;
    if (rc != TD_OK) {
        t->rejected++;
    } else if (f->id == app->p.command_id) {
        t->cmd_ok++;
    } else if (f->id == TD_ID_PC_GNSS_TIME) {
        t->gnss_time_ok++;
    } else {
        t->param_ok++;
    }
}

/* A step: plant and counters advance by dt, then the ECU steps at now. */
static void plant_step(rng_t *g, world_t *w, const td_io_out_t *out, double dt_s, td_io_in_t *in) {
    const double step_s = dt_s > 0.05 ? 0.05 : dt_s;
    if (!w->wheel_dead) {
        w->wheel_pos += w->v_kmh / 3.6 / (2.0 * PI_D * 0.0615) * 500.0 * dt_s;
    }
    for (int l = 0; l < 2; l++) {
        const double m = w->meter_jammed[l] ? 0.0 : MOTOR_RPM_FULL * out->meter_duty[l];
        w->meter_rpm[l] = first_order(w->meter_rpm[l], 1.0, m, MOTOR_TAU_S, step_s);
        w->meter_pos[l] += w->meter_rpm[l] / 60.0 * 6400.0 * dt_s;
        const double fr = w->fan_dead[l] ? 0.0 : FAN_RPM_FULL * out->fan_duty[l];
        w->fan_rpm[l] = first_order(w->fan_rpm[l], 1.0, fr, FAN_TAU_S, step_s);
        w->fan_pos[l] += w->fan_rpm[l] / 60.0 * 30.0 * dt_s;
    }
    if (below(g, 400u) == 0u) { /* a counter jumps: glitch, reset, or runs backwards */
        const uint32_t j = rnd(g);
        switch (below(g, 5u)) {
        case 0u: w->wheel_off += j; break;
        case 1u: w->meter_off[0] += j; break;
        case 2u: w->meter_off[1] += j; break;
        case 3u: w->fan_off[0] += j; break;
        default: w->fan_off[1] += j; break;
        }
    }
    in->wheel_count = (uint32_t)(uint64_t)fmod(w->wheel_pos, 4294967296.0) + w->wheel_off;
    /* a capture timer in some phases: the edge at a random point of the step, or garbage */
    in->wheel_edge_valid = w->edge_timing ? 1u : 0u;
    in->wheel_edge_us = w->now_us - (below(g, 20u) == 0u ? rnd(g) : below(g, 10000u));
    for (int l = 0; l < 2; l++) {
        in->meter_count[l] = (uint32_t)(uint64_t)fmod(w->meter_pos[l], 4294967296.0) + w->meter_off[l];
        in->fan_count[l] = (uint32_t)(uint64_t)fmod(w->fan_pos[l], 4294967296.0) + w->fan_off[l];
    }
}

/* The next step time: mostly the 10 ms period, sometimes repeated, short, late, backwards, wild. */
static uint32_t next_dt_us(rng_t *g) {
    const uint32_t k = below(g, 1000u);
    if (k < 900u) {
        return 10000u - 50u + below(g, 101u);
    }
    if (k < 930u) {
        return 0u;
    }
    if (k < 960u) {
        return 1u + below(g, 1000u);
    }
    if (k < 985u) {
        return 10000u + below(g, 2000000u);
    }
    if (k < 995u) {
        return 0u - (1u + below(g, 5000u)); /* backwards */
    }
    return rnd(g); /* anywhere, also half the clock away */
}

static void drain(td_app_t *app, tally_t *t) {
    td_can_frame_t f;
    uint32_t n = 0u;
    while (td_app_tx_pop(app, &f)) {
        n++;
        assert_true(n <= TD_TXQ_LEN);
        assert_int_equal(f.extended, 1);
        assert_int_equal(f.dlc, 8);
        assert_true(f.id == app->p.status_id || f.id == TD_ID_ECU_DIAG || f.id == TD_ID_ECU_SPEEDS ||
                    f.id == TD_ID_ECU_TARGETS || f.id == TD_ID_ECU_PARAM_ACK || f.id == TD_ID_ECU_FUSED ||
                    f.id == TD_ID_ECU_FUSED_AUX || f.id == TD_ID_ECU_GNSS_LAG ||
                    f.id == TD_ID_ECU_IDENT);
    }
    assert_int_equal(app->tx_count, 0);
    t->tx_frames += n;
}

/* One frame through td_app_rx with the checks of every frame. */
static void drain(td_app_t *app, tally_t *t);

static void send(td_app_t *app, td_app_t *before, const td_can_frame_t *f, uint32_t stamp, tally_t *t) {
    memcpy(before, app, sizeof *before);
    const int rc = td_app_rx(app, f, stamp);
    td_inv_check_rx(before, app, f, rc);
    tally_rx(app, f, rc, t);
}

static void write_param(td_app_t *app, td_app_t *before, uint8_t id, float v, uint32_t now, tally_t *t) {
    const uint32_t raw = td_proto_param_raw(id, v);
    const uint8_t data[8] = { id, 0, 0, 0, (uint8_t)raw, (uint8_t)(raw >> 8), (uint8_t)(raw >> 16), (uint8_t)(raw >> 24) };
    td_can_frame_t f;
    f.id = TD_ID_PC_PARAM_SET;
    f.extended = 1u;
    f.dlc = 8u;
    memcpy(f.data, data, 8);
    send(app, before, &f, now, t);
    drain(app, t);
}

/* The PC stops the ECU and writes every parameter back to its default; then, in half the
 * phases, the fused mode, and in some of them a look-ahead or slip compensation. */
static void restore_defaults(rng_t *g, td_app_t *app, td_app_t *before, uint32_t now, tally_t *t) {
    td_params_t d;
    td_params_default(&d);
    td_can_frame_t f;
    const td_command_t stop = { false, 0.0f, { 0.0f, 0.0f }, false, 0.0f };
    assert_int_equal(td_proto_encode_command(&stop, &f), TD_OK);
    send(app, before, &f, now, t);
    for (uint8_t id = 1u; id <= TD_PARAM_COUNT; id++) {
        /* n before N: a write that would make n > N on its own is refused */
        const uint8_t which = id == 6u ? 7u : id == 7u ? 6u : id;
        float v;
        assert_int_equal(td_params_get(&d, which, &v), TD_OK);
        const uint32_t raw = td_proto_param_raw(which, v);
        const uint8_t data[8] = { which, 0, 0, 0, (uint8_t)raw, (uint8_t)(raw >> 8), (uint8_t)(raw >> 16),
                                  (uint8_t)(raw >> 24) };
        f.id = TD_ID_PC_PARAM_SET;
        f.extended = 1u;
        f.dlc = 8u;
        memcpy(f.data, data, 8);
        send(app, before, &f, now, t);
        drain(app, t);
    }
    if (below(g, 2u) == 0u) {
        write_param(app, before, 10u, (float)TD_MODE_FUSED, now, t);
    }
    if (below(g, 3u) == 0u) {
        write_param(app, before, 31u, 800.0f, now, t); /* air line */
    }
    if (below(g, 3u) == 0u) {
        write_param(app, before, 28u, (float)(1u + below(g, 2u)), now, t); /* slip learned or eq. 5 */
    }
}

static void test_random_frames_steps_and_counters_keep_every_invariant(void **state) {
    (void)state;
    rng_t g = { FUZZ_SEED };
    world_t w;
    memset(&w, 0, sizeof w);
    tally_t t;
    memset(&t, 0, sizeof t);
    static td_app_t app;
    static td_app_t before;
    td_params_t p;
    td_params_default(&p);
    uint32_t now = 0u - 300000000u; /* the clock wraps 5 min in, and again at every wild jump */
    assert_int_equal(td_app_init(&app, &p, now), TD_OK);
    td_io_out_t out = { { 0.0f, 0.0f }, { 0.0f, 0.0f } };
    for (uint32_t i = 0u; i < FUZZ_FRAMES; i++) {
        if (i % PHASE_FRAMES == 0u) {
            new_phase(&g, &w);
            if (w.restore_defaults) {
                restore_defaults(&g, &app, &before, now, &t);
            }
        }
        td_can_frame_t f;
        random_frame(&g, &w, &app, &f);
        /* stamped at the last step's time, or a little after it (a receive interrupt) */
        send(&app, &before, &f, below(&g, 4u) == 0u ? now + below(&g, 10000u) : now, &t);
        if (below(&g, 2u) == 0u) {
            const uint32_t dt_us = next_dt_us(&g);
            now += dt_us;
            td_io_in_t in;
            w.now_us = now;
            plant_step(&g, &w, &out, dt_us < 0x80000000u ? dt_us * 1e-6 : 0.0, &in);
            assert_int_equal(td_app_step(&app, now, &in, &out), TD_OK);
            td_inv_check_step(&app, &out);
            t.steps++;
            t.running_steps += app.st.running;
            t.metering_steps += out.meter_duty[0] > 0.0f || out.meter_duty[1] > 0.0f;
            t.faults_seen |= app.st.faults;
            t.fused_steps += app.st.source == TD_SRC_FUSED && (out.meter_duty[0] > 0.0f || out.meter_duty[1] > 0.0f);
            t.edge_steps += app.st.edge_timing;
        }
        if (!w.bus_off && below(&g, 3u) != 0u) {
            drain(&app, &t);
        }
    }
    drain(&app, &t);
    printf("fuzz: %u frames (%u acted on: %u commands, %u GNSS times, %u parameters; %u refused), %u steps "
           "(%u running, %u metering, %u metering on the fused speed, %u with edge times), %u frames out, "
           "%u dropped, fault bits seen 0x%03X\n",
           t.frames, t.cmd_ok + t.gnss_time_ok + t.param_ok, t.cmd_ok, t.gnss_time_ok, t.param_ok, t.rejected, t.steps,
           t.running_steps, t.metering_steps, t.fused_steps, t.edge_steps, t.tx_frames, app.cnt.tx_dropped,
           t.faults_seen);
    /* every counter adds up, and the run did reach the interesting states */
    assert_true(t.frames >= FUZZ_FRAMES);
    assert_int_equal(app.cnt.rx_ok, t.cmd_ok + t.gnss_time_ok + t.param_ok);
    assert_true(t.gnss_time_ok > 5000u && t.fused_steps > 1000u && t.edge_steps > 10000u);
    assert_int_equal(td_inv_rejections(&app.cnt), t.rejected);
    assert_true(app.cnt.rx_unknown_id > 10000u && app.cnt.rx_bad_length > 10000u);
    assert_true(app.cnt.rx_out_of_range > 5000u && app.cnt.rx_param_rejected > 5000u);
    assert_true(t.cmd_ok > 20000u && t.param_ok > 1000u);
    assert_true(t.metering_steps > 5000u);
    assert_true(app.cnt.tx_dropped > 1000u);
    assert_int_equal(t.faults_seen, TD_INV_FAULT_BITS);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_random_frames_steps_and_counters_keep_every_invariant),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
