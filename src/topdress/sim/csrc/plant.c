/* The simulator's plant in C (plant.h). Every expression keeps the Python's operand order:
 * `b > a ? b : a` is Python's max(a, b) and `b < a ? b : a` its min(a, b), down to the
 * operand returned. sin, cos and pow are called through pointers so that the compiler
 * neither fuses sin and cos into sincos nor turns pow(d, 2) into d * d: the results stay
 * glibc's, as math.sin, math.cos and ** give them in Python. */
#include "plant.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static double (*volatile sin_fn)(double) = sin;
static double (*volatile cos_fn)(double) = cos;
static double (*volatile pow_fn)(double, double) = pow;

#define TWO_PI 6.283185307179586 /* math.tau, random.TWOPI; 2 pi exactly as a double */

double tdsim_gauss_draw(tdsim_gauss_t *g) {
    double z, x2pi, g2rad;
    if (g->has_kept) {
        g->has_kept = 0;
        z = g->kept;
    } else {
        if (g->n < 2u || g->next > g->n - 2u) {
            return NAN;
        }
        x2pi = g->u[g->next++] * TWO_PI;
        g2rad = sqrt(-2.0 * log(1.0 - g->u[g->next++]));
        z = cos_fn(x2pi) * g2rad;
        g->kept = sin_fn(x2pi) * g2rad;
        g->has_kept = 1;
    }
    return 0.0 + z * 1.0; /* mu + z * sigma */
}

/* fewer than two uniforms left: the next draw may need more */
static int gauss_low(const tdsim_gauss_t *g) { return g->n < 2u || g->next > g->n - 2u; }

/* 0.0 <= at_s <= t_s: a fault knob set (>= 0) and its time reached */
static int knob_on(double at_s, double t_s) { return 0.0 <= at_s && at_s <= t_s; }

int tdsim_tractor_step(tdsim_tractor_t *s, double dt_s, double v_target_ms, double curvature) {
    const double t = s->t_s + dt_s;
    double vb, acc, limit, a_des, lo, da, step_a, v, ds, h;
    s->t_s = t;
    if (v_target_ms != s->target_ms) {
        /* the driver picks gear and throttle for the new target speed */
        double a = v_target_ms * v_target_ms / (2.0 * s->runup_m);
        double a_min = a > s->accel_min_ms2 ? a : s->accel_min_ms2;
        s->target_ms = v_target_ms;
        s->accel_limit_ms2 = a_min < s->accel_max_ms2 ? a_min : s->accel_max_ms2;
        if (s->vb_ms <= 0.0) {
            s->jerk_now_ms3 =
                s->accel_limit_ms2 / (1e-3 > s->clutch_s ? 1e-3 : s->clutch_s);
        } else {
            s->jerk_now_ms3 = s->jerk_ms3;
        }
    }
    if (knob_on(s->stall_at_s, t)) {
        v_target_ms = 0.0;
    }
    vb = s->vb_ms;
    acc = s->a_ms2;
    limit = s->accel_limit_ms2;
    a_des = (v_target_ms - vb) / s->speed_tau_s;
    lo = -s->decel_ms2;
    a_des = a_des > lo ? a_des : lo;
    a_des = a_des < limit ? a_des : limit;
    if (acc >= limit - 1e-9 || a_des < acc) {
        s->jerk_now_ms3 = s->jerk_ms3; /* the clutch is in */
    }
    da = s->jerk_now_ms3 * dt_s;
    step_a = a_des - acc;
    step_a = step_a > -da ? step_a : -da;
    acc += step_a < da ? step_a : da;
    vb += acc * dt_s;
    if (v_target_ms <= 0.0 && vb < 0.02) {
        vb = 0.0;
        acc = 0.0;
    }
    s->a_ms2 = acc;
    s->vb_ms = vb;
    if (vb > 0.0 && s->ripple_sd > 0.0) {
        const double k = dt_s / s->ripple_tau_s;
        const double c = s->ripple_sd * sqrt(2 * k);
        s->ripple += -k * s->ripple + c * tdsim_gauss_draw(&s->gauss);
    }
    v = vb * (1.0 + s->ripple);
    v = v > 0.0 ? v : 0.0;
    s->v_ms = v;
    ds = v * dt_s;
    s->odometer_m += ds;
    h = s->heading_rad + ds * curvature;
    s->heading_rad = h;
    s->x_m += ds * sin_fn(h);
    s->y_m += ds * cos_fn(h);
    return 0;
}

int64_t tdsim_wheel_step(tdsim_wheel_t *s, double t_s, double dt_s, double v_ms,
                         double slip_floor_pct) {
    double v_kmh, slip;
    if (v_ms <= 0.0 || knob_on(s->lifted_at_s, t_s)) {
        return s->count;
    }
    if (s->bounce_sd > 0.0) {
        const double k = dt_s / s->bounce_tau_s;
        const double c = s->bounce_sd * sqrt(2 * k);
        s->bounce += -k * s->bounce + c * tdsim_gauss_draw(&s->gauss);
    }
    /* eq. 5 plus the run's offset, >= 0, and at least the ground's floor */
    v_kmh = v_ms * 3.6;
    slip = s->slip_a * v_kmh * v_kmh + s->slip_b * v_kmh + s->slip_c + s->slip_offset_pct;
    slip = slip > 0.0 ? slip : 0.0;
    slip = (slip_floor_pct > slip ? slip_floor_pct : slip) * 0.01;
    s->revolutions += v_ms * dt_s * (1.0 - slip) * (1.0 + s->bounce) / s->circ_m;
    if (!knob_on(s->encoder_dead_at_s, t_s)) {
        s->count = (int64_t)(s->revolutions * s->ppr);
    }
    return s->count;
}

static double clamp_duty(double duty) { return duty < 0.0 ? 0.0 : (duty > 1.0 ? 1.0 : duty); }

int64_t tdsim_meter_step(tdsim_meter_t *s, double t_s, double dt_s, double duty) {
    double rpm, load, w_ss, w, revolutions;
    duty = clamp_duty(duty); /* PWM saturates */
    if (knob_on(s->jammed_at_s, t_s)) {
        s->rpm = 0.0;
        return s->count;
    }
    rpm = s->rpm;
    if (rpm <= 0.0 && duty <= s->breakaway_duty + s->load_duty) {
        return s->count;
    }
    load = s->load_duty;
    if (s->load_ripple != 0.0) {
        load *= 1.0 + s->load_ripple * sin_fn(TWO_PI * s->flutes * s->revolutions);
    }
    w_ss = s->max_rpm * (duty - s->friction_duty - load);
    w = w_ss + (rpm - w_ss) * s->decay;
    if (w <= 0.0) {
        w = 0.0; /* friction holds the shaft; it does not turn backwards */
    }
    revolutions = s->revolutions + 0.5 * (rpm + w) * dt_s / 60.0;
    s->revolutions = revolutions;
    s->rpm = w;
    if (!knob_on(s->encoder_dead_at_s, t_s)) {
        s->count = (int64_t)(revolutions * s->counts_per_rev);
    }
    return s->count;
}

int64_t tdsim_fan_step(tdsim_fan_t *s, double t_s, double dt_s, double duty) {
    double w_ss, rpm;
    duty = clamp_duty(duty);
    if (knob_on(s->failed_at_s, t_s)) {
        duty = 0.0;
    }
    w_ss = s->max_rpm * duty * (1.0 - s->belt_slip);
    rpm = w_ss + (s->rpm - w_ss) * s->decay;
    s->rpm = rpm;
    s->revolutions = s->revolutions + rpm * dt_s / 60.0;
    s->count = (int64_t)(s->revolutions * s->ppr);
    return s->count;
}

double tdsim_field_ndvi(const tdsim_field_t *f, double x_m, double y_m) {
    double v = f->ndvi_mean + f->wave_amp * 0.5 * (sin_fn(f->k * x_m + f->phase0) +
                                                   sin_fn(0.7 * f->k * y_m + f->phase1));
    uint32_t i;
    for (i = 0; i < f->n_patches; i++) {
        const double *pa = f->patches + 3 * i;
        const double d2 = pow_fn(x_m - pa[0], 2) + pow_fn(y_m - pa[1], 2);
        v += pa[2] * exp(-d2 / f->two_r2);
    }
    v = v > 0.15 ? v : 0.15;
    return v < 0.92 ? v : 0.92;
}

tdsim_airline_t *tdsim_airline_new(void) { return calloc(1, sizeof(tdsim_airline_t)); }

void tdsim_airline_free(tdsim_airline_t *s) {
    if (s != NULL) {
        free(s->q);
        free(s);
    }
}

uint32_t tdsim_airline_len(const tdsim_airline_t *s) { return s->q_len; }

static int airline_push(tdsim_airline_t *s, double t_s, double kg) {
    if (s->q_len == s->q_cap) {
        /* grow, unwrapping the ring to the front of the new block */
        const uint32_t cap = s->q_cap ? 2u * s->q_cap : 64u;
        tdsim_parcel_t *q = malloc((size_t)cap * sizeof *q);
        uint32_t i;
        if (q == NULL || cap < s->q_cap) {
            free(q);
            return -1;
        }
        for (i = 0; i < s->q_len; i++) {
            q[i] = s->q[(s->q_head + i) % s->q_cap];
        }
        free(s->q);
        s->q = q;
        s->q_head = 0;
        s->q_cap = cap;
    }
    s->q[(s->q_head + s->q_len) % s->q_cap].t_s = t_s;
    s->q[(s->q_head + s->q_len) % s->q_cap].kg = kg;
    s->q_len++;
    return 0;
}

double tdsim_airline_step(tdsim_airline_t *s, double t_s, double d_rev, double kg_per_rev,
                          double fan_rpm) {
    double landed;
    if (d_rev > 0.0) {
        const double before = s->rev_in;
        const double rev_in = before + d_rev;
        const double released = rev_in - (s->release_rev > before ? s->release_rev : before);
        s->rev_in = rev_in;
        if (released > 0.0) {
            const double m = released * kg_per_rev;
            double arrive_s;
            s->in_flight_kg += m;
            if (fan_rpm < s->min_fan_rpm) {
                arrive_s = t_s + INFINITY; /* the air cannot carry it */
            } else {
                const double air_ms = s->air_speed_ms * fan_rpm / s->nominal_fan_rpm;
                arrive_s = t_s + (s->drop_s + s->line_length_m / air_ms);
            }
            if (airline_push(s, arrive_s, m) < 0) {
                return -1.0;
            }
        }
    }
    if (s->q_len == 0 || s->q[s->q_head].t_s > t_s || s->blocked) {
        return 0.0;
    }
    landed = 0.0;
    while (s->q_len > 0 && s->q[s->q_head].t_s <= t_s) {
        landed += s->q[s->q_head].kg;
        s->q_head = (s->q_head + 1u) % s->q_cap;
        s->q_len--;
    }
    s->in_flight_kg -= landed;
    s->landed_kg += landed;
    return landed;
}

double tdsim_world_loose(tdsim_world_t *w, double x_m, double y_m) {
    double floor_pct = 0.0, edge = INFINITY, reach;
    uint32_t i;
    if (pow_fn(x_m - w->loose_x, 2) + pow_fn(y_m - w->loose_y, 2) < w->loose_reach2) {
        return w->loose_floor;
    }
    for (i = 0; i < w->n_patches; i++) {
        const double px = w->patches[3 * i], py = w->patches[3 * i + 1];
        const double r = w->patches[3 * i + 2];
        const double d2 = pow_fn(x_m - px, 2) + pow_fn(y_m - py, 2);
        const double d_edge = fabs(sqrt(d2) - r);
        if (d2 <= r * r) {
            floor_pct = w->loose_slip_pct;
        }
        edge = d_edge < edge ? d_edge : edge;
    }
    /* half of it, less a margin for rounding: near an edge the patches are looked at again
       every step */
    reach = edge * 0.5 - 1e-6;
    w->loose_x = x_m;
    w->loose_y = y_m;
    w->loose_reach2 = reach > 0.0 ? reach * reach : -1.0;
    w->loose_floor = floor_pct;
    return floor_pct;
}

uint32_t tdsim_world_wheel_edge(tdsim_world_t *w, uint32_t now_us, int64_t count) {
    const double pos = w->wheel->revolutions * w->wheel->ppr;
    const double prev = w->wheel_pos;
    w->wheel_pos = pos;
    if (pos > prev) {
        const double whole = floor(pos);
        if (whole > floor(prev) && count == (int64_t)pos) {
            const double back_us = (pos - whole) / (pos - prev) * w->dt_s * 1e6;
            w->edge_us = (uint32_t)((int64_t)now_us - (int64_t)back_us);
        }
    }
    return w->edge_us;
}

/* The meter's revolutions since the last call into its air line; what lands goes to the record
 * bin under the outlets (summed in landing order, as the bins' dict of World had it). */
static int transport(tdsim_world_t *w, int i, double t_s) {
    const double rev = w->meter[i]->revolutions;
    const double d_rev = rev - w->rev_prev[i];
    double landed;
    int flags = 0;
    w->rev_prev[i] = rev;
    landed = tdsim_airline_step(w->line[i], t_s, d_rev, w->kg_per_rev[i], w->fan[i]->rpm);
    if (landed < 0.0) {
        return -1;
    }
    if (landed > 0.0) {
        if (!w->landed_any[i]) {
            w->landed_any[i] = 1;
            flags |= TDSIM_FIRST_LANDING;
        }
        if (w->bin != w->land_bin[i]) {
            if (w->land_bin[i] >= 0) {
                w->done_bin[i] = w->land_bin[i];
                w->done_kg[i] = w->land_kg[i];
                flags |= TDSIM_BIN_DONE;
            }
            w->land_bin[i] = w->bin;
            w->land_kg[i] = 0.0;
        }
        w->land_kg[i] += landed;
    }
    return flags;
}

int tdsim_world_step(tdsim_world_t *w, td_app_t *app, double t_s, uint32_t now_us,
                     double v_target_ms, double curvature) {
    tdsim_tractor_t *tr = w->tractor;
    const double dt = w->dt_s;
    int64_t wc;
    int64_t b;
    int flags = 0;
    int i, rc;
    td_io_in_t in;
    td_io_out_t out;
    int64_t counts[4];

    tdsim_tractor_step(tr, dt, v_target_ms, curvature);
    if (tr->v_ms > 0.0) { /* a standing wheel does not turn */
        const double floor_pct =
            w->n_patches ? tdsim_world_loose(w, tr->x_m, tr->y_m) : 0.0;
        wc = tdsim_wheel_step(w->wheel, t_s, dt, tr->v_ms, floor_pct);
    } else {
        wc = w->wheel->count;
    }
    b = (int64_t)(tr->odometer_m / w->bin_m);
    if (b != w->bin) {
        w->bin = b;
        flags |= TDSIM_NEW_BIN;
    }
    counts[0] = tdsim_meter_step(w->meter[0], t_s, dt, w->duty[0]);
    counts[1] = tdsim_meter_step(w->meter[1], t_s, dt, w->duty[1]);
    counts[2] = tdsim_fan_step(w->fan[0], t_s, dt, w->duty[2]);
    counts[3] = tdsim_fan_step(w->fan[1], t_s, dt, w->duty[3]);
    /* an air line with nothing metered into it and nothing in flight has nothing to do */
    for (i = 0; i < 2; i++) {
        if (w->meter[i]->revolutions > w->rev_prev[i] || w->line[i]->in_flight_kg > 0.0) {
            const int f = transport(w, i, t_s);
            if (f < 0) {
                return -1000;
            }
            flags |= f;
        } else {
            w->rev_prev[i] = w->meter[i]->revolutions;
        }
    }
    in.wheel_count = (uint32_t)wc;
    in.meter_count[0] = (uint32_t)counts[0];
    in.meter_count[1] = (uint32_t)counts[1];
    in.fan_count[0] = (uint32_t)counts[2];
    in.fan_count[1] = (uint32_t)counts[3];
    in.wheel_edge_valid = w->wheel_edges;
    in.wheel_edge_us = w->wheel_edges ? tdsim_world_wheel_edge(w, now_us, wc) : 0u;
    rc = td_app_step(app, now_us, &in, &out);
    if (rc < 0) {
        return rc;
    }
    w->duty[0] = out.meter_duty[0];
    w->duty[1] = out.meter_duty[1];
    w->duty[2] = out.fan_duty[0];
    w->duty[3] = out.fan_duty[1];
    if (gauss_low(&tr->gauss)) {
        flags |= TDSIM_REFILL_TRACTOR;
    }
    if (gauss_low(&w->wheel->gauss)) {
        flags |= TDSIM_REFILL_WHEEL;
    }
    return flags | ((int)app->tx_count << TDSIM_TX_SHIFT);
}
