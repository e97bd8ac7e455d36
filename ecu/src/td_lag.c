/**
 * @file td_lag.c
 * @brief The GNSS lag learned from the area between the wheel and GNSS over a speed change
 *        (td_lag.h).
 */
#include "td_lag.h"

#include <math.h>
#include <string.h>

#define LAG_FLAT_A_MS2 0.1f      /* the wheel is steady: its own acceleration below this */
#define LAG_FLAT_A_PER_S 0.03f   /* and this share of its speed per second (its bounce) */
#define LAG_QUIET_MS 0.1f        /* GNSS is steady: within this of its mean ... */
#define LAG_AVG_S 1.0f           /* ... over this long */
#define LAG_BAND_MS 0.05f        /* a speed has left its level: further than this ... */
#define LAG_BAND_SHARE 0.03f     /* ... and this share of it */
#define LAG_BLOCK_S 1.0f         /* a steady stretch's newest blocks, each this long */
#define LAG_LEVEL_MIN_S 0.5f     /* a level before a change: at least this long */
#define LAG_END_MIN_S 1.0f       /* the level after it: at least this long for a result */
#define LAG_END_FULL_S 5.0f      /* a result weighs less while the level after it is shorter */
#define LAG_END_MAX_S 20.0f      /* the result is final once the level after it is this long */
#define LAG_SETTLE_MIN_S 1.5f    /* after a change GNSS is still at least this long ... */
#define LAG_SETTLE_LAGS 1.5f     /* ... and this many lags: a filter's tail has died out */
#define LAG_GUESS_S 1.0f         /* the lag the settling time assumes before one is known */
#define LAG_CAUGHT_MS 0.1f       /* GNSS has caught up with the wheel: their changes differ by less */
#define LAG_CAUGHT_SHARE 0.25f   /* than this and this share of the change (a slip shape off) */
#define LAG_WHEEL_SETTLED_S 0.5f /* the wheel has settled after a change: steady this long */
#define LAG_DV_MIN_MS 0.5f       /* a change this large or larger gives a result */
#define LAG_EARLY_MS 0.4f        /* the first change gives a lag while it goes on from this on */
#define LAG_BLIP_MS 0.15f        /* a change back within this of where it began was none */
#define LAG_CHANGE_MAX_S 60.0f   /* a change that has not settled by then gives none */
#define LAG_GAP_S 1.5f           /* fixes further apart than this break the integrals */
#define LAG_WEIGHT_MAX 5.0f     /* (m/s)^2/s: later changes keep weighing */
#define LAG_K_MIN 0.5f           /* GNSS against the wheel (and the wheel's scale): plausible */
#define LAG_K_MAX 2.0f

enum { PHASE_NONE = 0u, PHASE_STEADY = 1u, PHASE_CHANGE = 2u };

static void add(td_lag_sum_t *to, const td_lag_sum_t *s) {
    to->u_m += s->u_m;
    to->z_m += s->z_m;
    to->t_s += s->t_s;
}

static float mean_of(float sum, float t_s) {
    return t_s > 0.0f ? sum / t_s : 0.0f;
}

static float clamp_lag(float lag_s) {
    return lag_s < 0.0f ? 0.0f : (lag_s > TD_LAG_MAX_S ? TD_LAG_MAX_S : lag_s);
}

/* A speed (m/s) has left a level when it is further from it than this. */
static float band_ms(float level_ms) {
    return LAG_BAND_MS + LAG_BAND_SHARE * level_ms;
}

void td_lag_init(td_lag_t *l) {
    memset(l, 0, sizeof *l); /* PHASE_NONE, nothing pending or learned */
    l->scale = 1.0f;
    l->fit = 1.0f;
}

void td_lag_wheel(td_lag_t *l, float w_ms, float dt_s) {
    if (w_ms >= 0.0f && dt_s >= 0.0f) {
        l->wheel_m += w_ms * dt_s;
        l->wheel_s += dt_s;
    } else {
        l->phase = PHASE_NONE; /* no wheel: the integrals would miss it */
        l->pending = false;
        l->have_prev = false;
    }
}

/* The ground speed u of a wheel circumference speed w (m/s) through the slip shape at the scale
 * s: s g(u) u = w, two Newton steps from w / s (eq. 5 bends the wheel's speed by up to 20 %).
 * `scale_slope`, if not NULL: -d(ln u) / d(ln s) = g / (g + u g'). */
static float ground_ms(const td_fused_t *f, float w_ms, float s, float *scale_slope) {
    const float v = w_ms / s;
    float u = v;
    float slope = 1.0f;
    for (unsigned i = 0u; i < 2u; i++) {
        float dg = 0.0f;
        const float g = td_fused_shape(f, u, &dg);
        const float d = g + u * dg;
        if (d > 0.1f) {
            u -= (u * g - v) / d;
            slope = g / d;
        }
    }
    if (scale_slope != NULL) {
        *scale_slope = slope;
    }
    return u;
}

/* An interval (or steady blocks) of the wheel's circumference speed into the window, as ground
 * speed at the window's scale, with what a change of that scale would change in it. */
static float add_ground(td_lag_t *l, const td_fused_t *f, const td_lag_sum_t *s) {
    float slope = 1.0f;
    const float u = ground_ms(f, mean_of(s->u_m, s->t_s), l->scale, &slope);
    l->change.u_m += u * s->t_s;
    l->change.z_m += s->z_m;
    l->change.t_s += s->t_s;
    l->change_du_m += u * slope * s->t_s;
    return u;
}

/* The window's lag against the level `end` after it (s), and its weight (m/s). */
static bool area_lag(const td_lag_t *l, const td_fused_t *f, const td_lag_sum_t *end, float age_s, float *lag_s,
                     float *w_ms) {
    const float w1 = mean_of(end->u_m, end->t_s);
    const float z1 = mean_of(end->z_m, end->t_s);
    const float dz = z1 - l->z0_ms;
    if (!(end->t_s >= LAG_END_MIN_S && fabsf(dz) >= LAG_DV_MIN_MS)) {
        return false;
    }
    /* the wheel's scale from the faster level (GNSS is its true speed); the window's ground
     * speeds, taken at the scale of its start, are moved to it to first order */
    const bool up = dz > 0.0f;
    const float zs = up ? z1 : l->z0_ms;
    const float s = (up ? w1 : l->w0_ms) / (zs * td_fused_shape(f, zs, NULL));
    const float u0 = ground_ms(f, l->w0_ms, s, NULL);
    const float u1 = ground_ms(f, w1, s, NULL);
    const float k = dz / (u1 - u0);
    if (!(s > LAG_K_MIN && s < LAG_K_MAX && k > LAG_K_MIN && k < LAG_K_MAX)) {
        return false;
    }
    const td_lag_sum_t *c = &l->change;
    const float ds = s / l->scale - 1.0f;
    float u_m = c->u_m - ds * l->change_du_m;
    /* from where the wheel settled on, its level after the change: its noise since then is in
     * the level's mean, not in the window, if it did stay there (a slow change may fool the
     * settling) */
    const float after_s = c->t_s - l->snap_t_s;
    const float snap_m = l->snap_u_m - ds * l->snap_du_m;
    if (l->snap_t_s > 0.0f && after_s > 0.0f && fabsf((u_m - snap_m) / after_s - u1) < band_ms(u1)) {
        u_m = snap_m + after_s * u1;
    }
    const float lag = (k * (u_m - u0 * c->t_s) - (c->z_m - l->z0_ms * c->t_s)) / dz - age_s;
    if (!(lag > -0.2f && lag < TD_LAG_MAX_S + 0.5f)) {
        return false; /* not a lag: something else moved in the window */
    }
    *lag_s = clamp_lag(lag);
    /* weighed as its noise allows: GNSS's and the wheel's over the window, against the change;
     * less while the level after it is short (its noise is in k) */
    *w_ms = dz * dz / c->t_s * (end->t_s < LAG_END_FULL_S ? end->t_s / LAG_END_FULL_S : 1.0f);
    return true;
}

/* A result joins the mean: provisionally (lag_s only) or for good. */
static void take(td_lag_t *l, float lag_s, float w_ms, bool final) {
    const float mean = (l->avg_s * l->weight_ms + lag_s * w_ms) / (l->weight_ms + w_ms);
    const float ref = l->weight_ms > 0.0f ? l->avg_s : lag_s;
    const float off = fabsf(lag_s - ref) / (ref > 0.1f ? ref : 0.1f);
    l->fit = off < 1.0f ? off : 1.0f;
    l->lag_s = mean;
    l->learned = true;
    l->area = true;
    if (final) {
        l->avg_s = mean;
        l->weight_ms = l->weight_ms + w_ms < LAG_WEIGHT_MAX ? l->weight_ms + w_ms : LAG_WEIGHT_MAX;
        l->evidence_s += l->change.t_s;
        l->pending = false;
    }
}

/* The pending window against the confirmed level after it: provisional, or final. */
static bool result(td_lag_t *l, const td_fused_t *f, float age_s, bool final) {
    float lag = 0.0f;
    float w = 0.0f;
    if (l->pending && area_lag(l, f, &l->level, age_s, &lag, &w)) {
        take(l, lag, w, final || l->level.t_s >= LAG_END_MAX_S);
        return true;
    }
    return false;
}

/* A steady stretch begins with this interval. */
static void start_stretch(td_lag_t *l, const td_lag_sum_t *in) {
    memset(&l->level, 0, sizeof l->level);
    memset(&l->block[0], 0, sizeof l->block[0]);
    l->block[1] = *in;
    l->phase = PHASE_STEADY;
}

/* A steady interval: into the newest block; a full block confirms the one before it (the
 * tests see a change up to ~1 s late: a change then starts its window from before itself). */
static void steady(td_lag_t *l, const td_lag_sum_t *in) {
    add(&l->block[1], in);
    if (l->block[1].t_s > LAG_BLOCK_S + 0.01f) { /* (at 1 Hz two fixes) */
        add(&l->level, &l->block[0]);
        l->block[0] = l->block[1];
        memset(&l->block[1], 0, sizeof l->block[1]);
        if (l->level.t_s > 2.0f * LAG_END_MAX_S) { /* a long stretch: its mean, in fewer digits */
            l->level.u_m *= 0.5f;
            l->level.z_m *= 0.5f;
            l->level.t_s *= 0.5f;
        }
    }
}

/* The steady stretch ends in a change: the pending window's result is final, and the stretch's
 * confirmed level starts the window of this change, its unconfirmed blocks in it. */
static bool change_begins(td_lag_t *l, const td_fused_t *f, const td_lag_sum_t *in, float age_s) {
    if (l->level.u_m + l->block[0].u_m + l->block[1].u_m == 0.0f) {
        /* standing: the change is seen at once, all of the stretch is its level */
        add(&l->level, &l->block[0]);
        add(&l->level, &l->block[1]);
        memset(l->block, 0, sizeof l->block);
    }
    const bool changed = result(l, f, age_s, true);
    l->scale = f->scale;
    l->pending = l->level.t_s >= LAG_LEVEL_MIN_S;
    l->w0_ms = mean_of(l->level.u_m, l->level.t_s);
    l->z0_ms = mean_of(l->level.z_m, l->level.t_s);
    l->u0_ms = ground_ms(f, l->w0_ms, l->scale, NULL);
    memset(&l->change, 0, sizeof l->change);
    l->change_du_m = 0.0f;
    l->snap_t_s = 0.0f;
    l->wheel_steady_s = 0.0f;
    l->quiet_s = 0.0f; /* the settling counts from the change on */
    (void)add_ground(l, f, &l->block[0]);
    (void)add_ground(l, f, &l->block[1]);
    (void)add_ground(l, f, in);
    l->phase = PHASE_CHANGE;
    return changed;
}

/* A change goes on: into the window; where the wheel has settled; the first change's lag. */
static bool change_goes_on(td_lag_t *l, const td_fused_t *f, const td_lag_sum_t *in, bool wheel_steady, float z_ms,
                           float age_s) {
    const float du = add_ground(l, f, in) - l->u0_ms;
    const bool settled = l->wheel_steady_s >= LAG_WHEEL_SETTLED_S;
    /* (once it has left its level: at a smooth start its acceleration still looks steady) */
    l->wheel_steady_s = wheel_steady && fabsf(du) > band_ms(l->u0_ms) ? l->wheel_steady_s + in->t_s : 0.0f;
    if (!settled && l->wheel_steady_s >= LAG_WHEEL_SETTLED_S) {
        l->snap_u_m = l->change.u_m;
        l->snap_du_m = l->change_du_m;
        l->snap_t_s = l->change.t_s;
    }
    if (l->change.t_s > LAG_CHANGE_MAX_S) {
        l->pending = false; /* it never settled */
    }
    /* Before the first result, the lag while the first change goes on (and the wheel still
     * changes: after, its unlearned scale would move it): the area so far over the change's
     * mean of wheel and GNSS; exact for a delay on a ramp, up to a third short for a filter */
    const float dz = z_ms - l->z0_ms;
    const float mid = 0.5f * (du + dz);
    if (!(l->pending && l->weight_ms == 0.0f && !settled && fabsf(mid) >= LAG_EARLY_MS && du * dz > 0.0f)) {
        return false;
    }
    const td_lag_sum_t *c = &l->change;
    l->lag_s = clamp_lag(((c->u_m - l->u0_ms * c->t_s) - (c->z_m - l->z0_ms * c->t_s)) / mid - age_s);
    l->fit = 1.0f;
    l->learned = true;
    return true;
}

bool td_lag_fix(td_lag_t *l, const td_fused_t *f, float z_ms, float age_s) {
    if (!(z_ms >= 0.0f && age_s >= 0.0f && z_ms < 100.0f && age_s < 10.0f)) {
        return false; /* ignored: the next fix's interval covers this one's */
    }
    const float dt = l->wheel_s;
    const float w = mean_of(l->wheel_m, dt);
    const td_lag_sum_t in = { l->wheel_m, 0.5f * (l->z_prev_ms + z_ms) * dt, dt }; /* GNSS: trapezoid */
    const bool have_prev = l->have_prev;
    l->wheel_m = 0.0f;
    l->wheel_s = 0.0f;
    l->z_prev_ms = z_ms;
    l->have_prev = true;
    if (!(have_prev && dt > 0.0f && dt <= LAG_GAP_S)) {
        l->phase = PHASE_NONE;
        l->pending = false;
        l->z_avg_ms = z_ms;
        l->w_avg_ms = w;
        return false;
    }
    float a = 0.0f;
    const bool wheel_steady =
        td_fused_wheel_accel(f, &a) ? fabsf(a) < LAG_FLAT_A_MS2 + LAG_FLAT_A_PER_S * w : w == 0.0f;
    const bool quiet = fabsf(z_ms - l->z_avg_ms) <= LAG_QUIET_MS;
    const float k_avg = dt < LAG_AVG_S ? dt / LAG_AVG_S : 1.0f;
    l->z_avg_ms += k_avg * (z_ms - l->z_avg_ms);
    l->w_avg_ms += k_avg * (w - l->w_avg_ms);
    l->quiet_s = quiet ? l->quiet_s + dt : 0.0f;

    if (l->phase == PHASE_STEADY) {
        /* a change: the tests, a standing level that moves, or the 1 s means left the
         * stretch's level (a slow change, its acceleration still small) */
        td_lag_sum_t st = l->level;
        add(&st, &l->block[0]);
        add(&st, &l->block[1]);
        const float w_st = mean_of(st.u_m, st.t_s);
        const float z_st = mean_of(st.z_m, st.t_s);
        const bool left = st.t_s >= LAG_BLOCK_S &&
                          (fabsf(l->w_avg_ms - w_st) > band_ms(w_st) || fabsf(l->z_avg_ms - z_st) > band_ms(z_st));
        if (!wheel_steady || !quiet || (st.u_m == 0.0f && w > 0.0f) || left) {
            return change_begins(l, f, &in, age_s);
        }
        steady(l, &in);
        return result(l, f, age_s, false);
    }
    if (l->phase == PHASE_CHANGE) {
        /* over once GNSS has caught up with the wheel (a change of both alike, the slip aside),
         * has stayed still since for the settling time (and a fix: at 1 Hz the quiet test sees
         * two fixes a second apart), and the wheel is steady */
        const float du = l->pending ? ground_ms(f, l->w_avg_ms, l->scale, NULL) - l->u0_ms : 0.0f;
        const float dz = l->pending ? l->z_avg_ms - l->z0_ms : 0.0f;
        const float guess = l->learned ? l->lag_s : LAG_GUESS_S;
        const float settle = LAG_SETTLE_LAGS * guess > LAG_SETTLE_MIN_S ? LAG_SETTLE_LAGS * guess : LAG_SETTLE_MIN_S;
        if (!(wheel_steady && l->quiet_s >= settle + dt && fabsf(dz - du) < LAG_CAUGHT_MS + LAG_CAUGHT_SHARE * fabsf(du))) {
            return change_goes_on(l, f, &in, wheel_steady, z_ms, age_s);
        }
        if (l->pending && fabsf(du) < LAG_BLIP_MS && fabsf(dz) < LAG_BLIP_MS) {
            /* back where it was (a bounce, a noisy fix): the stretch before goes on */
            memset(&l->block[0], 0, sizeof l->block[0]);
            l->block[1] = in;
            l->pending = false;
            l->phase = PHASE_STEADY;
            return false;
        }
    } else if (!(wheel_steady && quiet)) {
        return false;
    }
    start_stretch(l, &in);
    return false;
}
