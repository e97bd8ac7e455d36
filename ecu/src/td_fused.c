/**
 * @file td_fused.c
 * @brief 3-state EKF: speed, acceleration, wheel scale (td_fused.h for the model).
 */
#include "td_fused.h"

#include <math.h>
#include <stddef.h>
#include "td_common.h"
#include "td_slip.h"

enum { VV = 0, VA = 1, VS = 2, AA = 3, AS = 4, SS = 5 };

#define TD_KMH_PER_MS 3.6f
#define P0_V 1.0f         /* initial speed variance, (m/s)^2 */
#define P0_A 1.0f         /* initial acceleration variance */
#define P0_S 0.01f        /* initial scale variance: 10 % slip, 1 sigma */
#define P_S_MAX 0.01f     /* the scale's variance never grows beyond its initial value */
#define Q_SCALE 2.0e-5f   /* scale random walk, 1/s: 0.45 % per sqrt(s) */
#define Q_STEADY 0.01f    /* share of the jerk density over a GNSS delay in steady motion */
#define WHEEL_FLOOR_MS 0.02f
#define GATE_SIGMA2 25.0f /* 5 sigma */
#define GATE_MIN_MS 0.3f
#define WHEEL_RESTART 25u
#define SCALE_MIN 0.5f
#define SCALE_MAX 1.5f
#define SHAPE_MIN 0.5f
#define SHAPE_MAX_KMH 12.0f /* eq. 5's shape held constant above */
#define SCALE_MIN_MS 0.5f /* GNSS teaches the scale above this speed */
/* re-opened learning on loose ground (td_fused.h) */
#define REOPEN_SIGMA2 4.0f    /* a mean beyond 2 GNSS sigmas */
#define REOPEN_MIN_MS 0.05f   /* innovations smaller than this have no sign */
#define CLOSE_SIGMA2 1.0f     /* closed again within 1 GNSS sigma, or on a change of sign */
#define REOPEN_S 1.0f         /* one sign for this long */
#define REOPEN_A_MS2 0.3f     /* in motion this steady */
#define GNSS_AVG_S 1.0f      /* GNSS against its own mean over this long ... */
#define GNSS_MOVES_MS 0.1f   /* ... beyond this: the speed (or the receiver's filter) still moves */
#define SETTLE_S 1.0f        /* GNSS still for the delay and this long before the scale learns */
#define FLAT_A_MS2 0.1f      /* or the wheel's own acceleration below this alone */
#define P_S_REOPEN 0.0009f    /* the scale's variance at least (3 %)^2 when re-opened */
/* the wheel's history against GNSS: a bucket's bounce, share of its speed */
#define HIST_REL 0.04f
#define SCALE_PERIOD_S 0.25f /* the scale learns per fix as from a 4-5 Hz receiver */
#define WHEEL_MEAN_MAX_S 1.0f /* the wheel against a fix: its mean over the fix period, at most this */
#define WHEEL_MEAN_N 8u       /* points of that mean */
#define HIST_Z_MAX_MS 65.0f                   /* a wheel speed beyond this is no number (mm/s in 16 bits) */
#define HIST_DT_MAX_S (TD_FUSED_HIST * TD_FUSED_BUCKET_S) /* a longer step leaves no history */
#define ACCEL_BUCKETS 10u /* the wheel's own acceleration: two means of this many buckets (1 s each) */
#define BUCKET_CLOSE_S (TD_FUSED_BUCKET_S - 1.0e-4f) /* sums of 10 ms steps fall just short */
/* the jerk in flat motion (set_q_share) */
#define Q_FLAT_MIN_MS 0.5f  /* below this speed the whole jerk */
#define Q_FLAT_A_MS2 0.2f   /* the wheel's own acceleration at which the whole jerk is back */
#define Q_FLAT_SHARE 0.05f  /* the least share */
#define WHEEL_FLAT_REL 0.05f /* flat motion: the wheel within this share of the estimate is bounce */
#define WHEEL_FLAT_GAIN 1000.0f /* and weighs this much less */
#define OUTAGE_GAIN 10.0f /* in an outage with the scale learned, this much less */
#define CRUISE_SHARE 0.3f
#define CRUISE_TAU_S 0.5f  /* the acceleration's time constant in cruise */
#define FLAT_GNSS_S 0.5f    /* out of cruise a decays so only with a fix this recent (GNSS holds v) */
#define GNSS_UNSETTLED_K 10.0f /* a fix's variance while GNSS still moves and the wheel holds */
#define CRUISE_MIN_MS 1.67f /* and above the paper's 6 km/h: slower, the wheel measures well and a brake
                              * from a slow pass shows in it first (Table 2's stop at 3.5 km/h) */
#define WHEEL_DEV_K 0.03f   /* that mean: over ~0.3 s of 10 ms steps */
/* a ramp GNSS does not confirm (td_fused_gnss): the wheel's scale stepped */
#define RAMP_A_MS2 0.1f     /* the estimate's acceleration beyond this is a ramp it believes in */
#define RAMP_MARGIN_S 0.2f   /* GNSS shows a change this long after the delay, or it was none */
#define RAMP_MAX_S 5.0f      /* a change is checked this long after it began */
#define RAMP_P_S 0.0004f     /* the scale's variance after the step, (2 %)^2 */
#define RAMP_P_A 0.01f       /* and the acceleration's, (0.1 m/s^2)^2 */
#define RAMP_SIGMA2 9.0f     /* GNSS apart from the scaled wheel by 3 GNSS sigmas */
#define RAMP_W_S 0.5f        /* the wheel's mean over its last this long */   /* flat: a fix corrects v itself while the jerk's share is below this */
#define CRUISE_A_MS2 0.02f    /* an acceleration the wheel may not have shown yet, over the delay */
/* a sharp step of the wheel in cruise (step_check): a slip step or a speed change */
#define STEP_REL 0.05f      /* the wheel's newest 0.2 s beyond this share of the estimate's wheel speed */
#define STEP_SHARP_REL 0.07f /* and moved by this share since 0.2-0.5 s ago: sharper than a machine's ramp */
#define STEP_MAX_REL 0.25f  /* a wheel further off is no slip step (a cut cable, a stop): the gate's */
#define STEP_SHARP_K 3.0f   /* or by this many sigmas of the wheel's bucket-to-bucket bounce */
#define STEP_BOUNCE_K 0.02f /* that bounce's variance, a running mean over ~5 s of buckets */
#define STEP_BOUNCE0 0.0009f /* and its start, (3 %)^2 */
#define STEP_HOLD_S 0.6f    /* then the wheel waits this long before it weighs again */
#define STEP_MORE_S 0.3f    /* and this long more when it still moved at the first judgement */
#define STEP_N 3u           /* and is judged on two means of this many buckets */
#define STEP_VERIFY_S 0.5f  /* GNSS checks a scale step this long after its delay ... */
#define STEP_CONFIRM_S 1.5f /* ... and has confirmed it this long after */    /* then the wheel waits this long before it weighs again */
#define STEP_LEVEL_REL 0.035f /* the wheel level since within this share: the slip stepped */
#define STEP_GNSS_S 1.5f    /* GNSS this recent backs the hold */
/* a ramp of the wheel (wheel_trend): a brake or a launch the cruise must not wait for */
#define TREND_REL 0.06f     /* the wheel's newest 0.3 s beyond this share of the estimate's wheel speed */
#define TREND_MIN_REL 0.03f /* moved by this share in each of the last two 0.3 s, the same way */
#define TREND_K 1.5f       /* or by this many sigmas of a mean's bounce */
#define TREND_EVEN 0.2f    /* and evenly: |d1 - d2| below this share of d1 + d2 (a step straddling the middle
                            * mean moves the two by 1/3 and 2/3 of it: 1/3) */
#define TREND_MAX_REL 0.4f /* a wheel further off is a cut cable (the gate's), no brake */
#define TREND_BACK_REL 0.015f /* a ramp's newest mean going back this share: the bounce's, it ends */
#define TREND_AGO_N 20u    /* a sharp step the way of a ramp this many buckets after it goes on with it */
#define TREND_KEEP 10u      /* then the whole jerk and no cruise for this many buckets (1 s) after it */
/* look-ahead acceleration: noise shrink and bound */
#define LEAD_A_SHRINK_PER_MS 0.13f /* per m/s of speed */
#define LEAD_A_MAX 3.0f

int td_fused_init(td_fused_t *f, float jerk_ms3, float gnss_std_kmh, float wheel_noise_pct) {
    if (f == NULL || !(jerk_ms3 > 0.0f) || !(gnss_std_kmh > 0.0f) || !(wheel_noise_pct > 0.0f)) {
        return TD_E_ARG;
    }
    f->v_ms = 0.0f;
    f->a_ms2 = 0.0f;
    f->scale = 1.0f;
    f->p[VV] = P0_V;
    f->p[VA] = 0.0f;
    f->p[VS] = 0.0f;
    f->p[AA] = P0_A;
    f->p[AS] = 0.0f;
    f->p[SS] = P0_S;
    f->q_share = 1.0f;
    f->innov_ms = 0.0f;
    f->since_gnss_s = 0.0f;
    f->run_s = 0.0f;
    f->run_sum = 0.0f;
    f->run_sign = 0;
    f->quiet_s = 0.0f;
    f->moves_n = 0u;
    f->gnss_avg_ms = 0.0f;
    f->ramp_s = 0.0f;
    f->reopened = false;
    f->wheel_rejects = 0u;
    f->slip_shape = false;
    f->cruise = false;
    f->hold_s = 0.0f;
    f->hold_w0_ms = 0.0f;
    f->stepped_s = 0.0f;
    f->step_scale0 = 1.0f;
    f->step_after_n = 0u;
    f->step_dv_ms = 0.0f;
    f->step_z0_ms = 0.0f;
    f->bounce_var = STEP_BOUNCE0;
    f->wheel_dev = 0.0f;
    f->departed = 0;
    f->trend_n = 0u;
    f->trend_w_ms = 0.0f;
    f->trend_ago = 0u;
    f->hist_head = 0u;
    f->hist_n = 0u;
    f->hist_sum = 0.0f;
    f->hist_s = 0.0f;
    for (unsigned i = 0u; i < TD_FUSED_HIST; i++) {
        f->hist_mms[i] = 0u;
    }
    td_fused_tune(f, jerk_ms3, gnss_std_kmh, wheel_noise_pct);
    return TD_OK;
}

void td_fused_tune(td_fused_t *f, float jerk_ms3, float gnss_std_kmh, float wheel_noise_pct) {
    const float g = gnss_std_kmh / TD_KMH_PER_MS;
    f->q_jerk = jerk_ms3 * jerk_ms3;
    f->r_gnss = g * g;
    f->wheel_rel = wheel_noise_pct * 0.01f;
}

void td_fused_predict(td_fused_t *f, float dt_s) {
    if (!(dt_s > 0.0f)) {
        return;
    }
    float *p = f->p;
    const float q = f->q_jerk * f->q_share;
    const float dt2 = dt_s * dt_s;
    p[VV] += dt_s * (2.0f * p[VA] + dt_s * p[AA]) + q * dt2 * dt_s / 3.0f;
    p[VA] += dt_s * p[AA] + q * dt2 * 0.5f;
    p[VS] += dt_s * p[AS];
    p[AA] += q * dt_s;
    p[SS] += Q_SCALE * dt_s;
    if (p[SS] > P_S_MAX) {
        p[SS] = P_S_MAX;
    }
    f->v_ms += f->a_ms2 * dt_s;
    if (f->v_ms < 0.0f) {
        f->v_ms = 0.0f;
    }
    /* out of cruise too once the scale has learned, with a recent fix and no change awaiting
     * GNSS's check (td_fused_gnss): after a ramp, GNSS through v - a d kept its a while the
     * receiver's filter settled, and v ran on */
    const bool flat = f->cruise || (f->p[SS] < P_S_REOPEN && !(f->ramp_s > 0.0f) && f->since_gnss_s < FLAT_GNSS_S);
    if (flat && f->q_share < CRUISE_SHARE && fabsf(f->wheel_dev) < WHEEL_FLAT_REL && f->v_ms > CRUISE_MIN_MS) {
        /* in flat motion the acceleration is a short-lived correction (a Gauss-Markov one of time
         * constant CRUISE_TAU_S): a GNSS fix's noise left in a would ramp v until the next */
        const float k = dt_s < CRUISE_TAU_S ? 1.0f - dt_s / CRUISE_TAU_S : 0.0f;
        f->a_ms2 *= k;
        p[VA] *= k;
        p[AS] *= k;
        p[AA] = p[AA] * k * k > 1.0e-8f ? p[AA] * k * k : 1.0e-8f;
    }
    if (f->since_gnss_s < 60.0f) {
        f->since_gnss_s += dt_s;
    }
    if (f->stepped_s > 0.0f && f->stepped_s < 60.0f) {
        f->stepped_s += dt_s;
    }
    /* a speed change the estimate believes in: from where a went beyond RAMP_A_MS2, for at most
     * RAMP_MAX_S (td_fused_gnss checks it against GNSS) */
    if (f->ramp_s > 0.0f) {
        f->ramp_s = f->ramp_s + dt_s < RAMP_MAX_S ? f->ramp_s + dt_s : 0.0f;
    } else if (fabsf(f->a_ms2) > RAMP_A_MS2) {
        f->ramp_s = dt_s;
        f->ramp_v0_ms = f->v_ms;
        f->ramp_z0_ms = f->gnss_avg_ms;
    }
}

/* Scalar measurement with H = h, innovation y, variance r. The scale's gain is zeroed unless
 * learning; the Joseph form P - K u' - u K' + S K K' keeps P right for that gain. */
static bool update(td_fused_t *f, const float h[3], float y, float r, bool learn) {
    float *p = f->p;
    const float u[3] = { p[VV] * h[0] + p[VA] * h[1] + p[VS] * h[2], p[VA] * h[0] + p[AA] * h[1] + p[AS] * h[2],
                         p[VS] * h[0] + p[AS] * h[1] + p[SS] * h[2] };
    const float s = h[0] * u[0] + h[1] * u[1] + h[2] * u[2] + r;
    if (!(s > 0.0f) || (y * y > GATE_SIGMA2 * s && fabsf(y) > GATE_MIN_MS)) {
        return false;
    }
    const float k[3] = { u[0] / s, u[1] / s, learn ? u[2] / s : 0.0f };
    f->v_ms += k[0] * y;
    f->a_ms2 += k[1] * y;
    f->scale += k[2] * y;
    static const uint8_t ij[6][2] = { { 0, 0 }, { 0, 1 }, { 0, 2 }, { 1, 1 }, { 1, 2 }, { 2, 2 } };
    for (unsigned n = 0u; n < 6u; n++) {
        const unsigned i = ij[n][0];
        const unsigned j = ij[n][1];
        p[n] += -k[i] * u[j] - u[i] * k[j] + s * k[i] * k[j];
    }
    /* keep the variances positive whatever the rounding */
    if (p[VV] < 1.0e-8f) {
        p[VV] = 1.0e-8f;
    }
    if (p[AA] < 1.0e-8f) {
        p[AA] = 1.0e-8f;
    }
    if (p[SS] < 1.0e-10f) {
        p[SS] = 1.0e-10f;
    }
    if (f->v_ms < 0.0f) {
        f->v_ms = 0.0f;
    }
    if (f->scale < SCALE_MIN) {
        f->scale = SCALE_MIN;
    } else if (f->scale > SCALE_MAX) {
        f->scale = SCALE_MAX;
    }
    return true;
}

float td_fused_shape(const td_fused_t *f, float v_ms, float *slope) {
    if (slope != NULL) {
        *slope = 0.0f;
    }
    if (!f->slip_shape) {
        return 1.0f;
    }
    /* eq. 5: slip(%) = A v^2 + B v + C, v in km/h; g = 1 - slip/100, dg/dv per m/s. Held at
     * its value at SHAPE_MAX_KMH beyond: the fit's wheel speed g(v) v would fall again above
     * ~14.7 km/h and give the wheel a second, false solution the estimate could run off to */
    const float vk = v_ms * 3.6f;
    const bool held = vk > SHAPE_MAX_KMH;
    const float g = 1.0f - td_slip_model_pct(held ? SHAPE_MAX_KMH : vk) * 0.01f;
    if (g < SHAPE_MIN || g > 1.0f) {
        return g < SHAPE_MIN ? SHAPE_MIN : 1.0f;
    }
    if (slope != NULL && !held) {
        *slope = -(td_slip_model_pct(vk + 0.5f) - td_slip_model_pct(vk - 0.5f)) * 0.01f * 3.6f;
    }
    return g;
}

td_fused_result_t td_fused_wheel(td_fused_t *f, float z_ms, float r_extra, bool learn, bool gnss_backs) {
    if (f->hold_s > 0.0f) {
        /* a sharp step of the wheel is being judged (step_check): it weighs nothing meanwhile */
        return TD_FUSED_ACCEPTED;
    }
    float dg = 0.0f;
    const float g = td_fused_shape(f, f->v_ms, &dg);
    /* z = s * g(v) * v: dz/dv = s * (g + v * g'), dz/ds = g * v */
    const float h[3] = { f->scale * (g + f->v_ms * dg), 0.0f, g * f->v_ms };
    const float sd = f->wheel_rel * z_ms;
    const float y = z_ms - f->scale * g * f->v_ms;
    if (z_ms > SCALE_MIN_MS) {
        f->wheel_dev += WHEEL_DEV_K * (y / z_ms - f->wheel_dev);
    }
    float r = sd * sd + WHEEL_FLOOR_MS * WHEEL_FLOOR_MS + r_extra;
    if (gnss_backs && f->q_share < CRUISE_SHARE && fabsf(y) < WHEEL_FLAT_REL * z_ms) {
        /* flat motion, the wheel within its bounce: the bounce wanders over seconds and is no
         * white noise, so GNSS holds the level; a wheel beyond it weighs in full at once */
        r *= WHEEL_FLAT_GAIN;
    } else if (!gnss_backs && f->p[SS] < P_S_REOPEN && f->q_share < CRUISE_SHARE &&
               fabsf(f->wheel_dev) < WHEEL_FLAT_REL) {
        /* an outage with the scale learned (its variance, growing without GNSS, leaves that
         * after ~40 s): the wheel is all there is, but its slow bounce, read through eq. 5's
         * slope, is ~1.5 times as large in speed; in flat motion the estimate averages it over
         * seconds while the wheel's ~0.3 s mean stays within the band (its fast bounce alone
         * leaves it often), and follows in full a wheel beyond it or a ramp */
        r *= OUTAGE_GAIN;
    }
    /* a wheel already refused while GNSS backs the estimate comes back only when it agrees
     * again, not because the estimate grew uncertain without it */
    const bool held = f->wheel_rejects > 0u && gnss_backs && fabsf(y) > GATE_MIN_MS + 3.0f * sqrtf(r);
    if (!held && update(f, h, y, r, learn)) {
        f->wheel_rejects = 0u;
        return TD_FUSED_ACCEPTED;
    }
    if (f->wheel_rejects < WHEEL_RESTART) {
        f->wheel_rejects++;
        return TD_FUSED_REJECTED;
    }
    if (gnss_backs) {
        return TD_FUSED_REJECTED;
    }
    /* the wheel has disagreed for long and nothing says it is wrong: start again from it */
    f->v_ms = z_ms / (f->scale * td_fused_shape(f, z_ms / f->scale, NULL));
    f->a_ms2 = 0.0f;
    f->p[VV] = r;
    f->p[VA] = 0.0f;
    f->p[VS] = 0.0f;
    f->p[AA] = P0_A;
    f->p[AS] = 0.0f;
    f->wheel_rejects = 0u;
    return TD_FUSED_RESTARTED;
}

/* The jerk the model allows: the whole of it while the wheel's own acceleration says the speed
 * changes, a small share while it holds (then the estimate averages the wheel's bounce over
 * seconds instead of following it, and GNSS pins the mean); a launch from rest keeps it all. */
static void set_q_share(td_fused_t *f) {
    float aw = 0.0f;
    if (f->v_ms < Q_FLAT_MIN_MS || !td_fused_wheel_accel(f, &aw)) {
        f->q_share = 1.0f;
        return;
    }
    const float x = aw / Q_FLAT_A_MS2;
    const float share = x * x;
    f->q_share = share < Q_FLAT_SHARE ? Q_FLAT_SHARE : (share > 1.0f ? 1.0f : share);
}

/* Mean of the history's buckets i0..i1 (0 = newest), m/s. */
static float hist_mean(const td_fused_t *f, unsigned i0, unsigned i1) {
    uint32_t sum = 0u;
    for (unsigned i = i0; i <= i1; i++) {
        sum += f->hist_mms[(f->hist_head + TD_FUSED_HIST - i) % TD_FUSED_HIST];
    }
    return (float)sum * TD_FUSED_HIST_MM_S / (float)(i1 - i0 + 1u);
}

/* Rescales the wheel's history older than bucket i0 by ratio (clamped to 16 bits). */
static void rescale_history(td_fused_t *f, unsigned i0, float ratio) {
    for (unsigned i = i0; i < f->hist_n; i++) {
        uint16_t *b = &f->hist_mms[(f->hist_head + TD_FUSED_HIST - i) % TD_FUSED_HIST];
        const float x = (float)*b * ratio + 0.5f;
        *b = (uint16_t)(x < 65535.0f ? x : 65535.0f);
    }
}

/* The wheel ramps away from the estimate: three means of STEP_N buckets each moving the same way
 * by TREND_MIN_REL, the newest beyond TREND_REL (and within TREND_MAX_REL: a cut cable is the
 * gate's), and evenly. A slip step moves one of them only, or two unevenly. */
static bool wheel_trend(const td_fused_t *f, float pred) {
    if (f->hist_n < 3u * STEP_N) {
        return false;
    }
    const float m0 = hist_mean(f, 0u, STEP_N - 1u);
    const float m1 = hist_mean(f, STEP_N, 2u * STEP_N - 1u);
    const float d1 = m0 - m1;
    const float d2 = m1 - hist_mean(f, 2u * STEP_N, 3u * STEP_N - 1u);
    /* each move beyond the bounce of a mean too (a wheel that bounces harder needs a steeper ramp) */
    const float k = TREND_K * sqrtf(f->bounce_var / (float)STEP_N);
    const float min = (k > TREND_MIN_REL ? k : TREND_MIN_REL) * pred;
    return d1 * d2 > 0.0f && (m0 - pred) * d1 > 0.0f && fabsf(m0 - pred) > TREND_REL * pred &&
           fabsf(m0 - pred) < TREND_MAX_REL * pred && fabsf(d1) > min && fabsf(d2) > min &&
           fabsf(d1 - d2) < TREND_EVEN * fabsf(d1 + d2);
}

/* The speed changed after all: the estimate restarts from the wheel at scale s, with the
 * acceleration it saw from w0 to w over span_s. */
static void snap_to_wheel(td_fused_t *f, float w, float w0, float span_s) {
    const float sg = f->scale * td_fused_shape(f, f->v_ms, NULL);
    f->cruise = false;
    f->v_ms = w / sg;
    f->a_ms2 = (w - w0) / (sg * span_s);
    f->p[VV] = f->p[VV] > f->r_gnss ? f->p[VV] : f->r_gnss;
    f->p[VA] = 0.0f;
    f->p[AA] = P0_A;
    f->q_share = 1.0f;
}

/* A scale step taken from the wheel proved a speed change: the scale and the history back. */
static void undo_step(td_fused_t *f) {
    const unsigned since_n = (unsigned)(f->stepped_s / TD_FUSED_BUCKET_S);
    rescale_history(f, f->step_after_n + since_n, f->step_scale0 / f->scale);
    f->scale = f->step_scale0;
    f->stepped_s = 0.0f;
}

/* In cruise (or as flat out of it) above 6 km/h a wheel that steps away from the estimate within
 * a few tenths of a second is held out for STEP_HOLD_S: a machine does not change its speed that sharply, a wet
 * patch changes the wheel's slip so. Level since: the scale takes the step and the speed holds
 * (GNSS would show the truth only a lag later, and td_fused_gnss checks it then). Still moving
 * the same way: a speed change after all, and the estimate restarts from the wheel. Back where
 * it was: a bounce. Going back but not there yet: judged again STEP_MORE_S later. A second step
 * the same way soon after a scale step undoes it: a brake. */
static void step_check(td_fused_t *f) {
    if (f->hist_n < 2u * STEP_N) {
        f->hold_s = 0.0f;
        return;
    }
    if (f->trend_ago > 0u) {
        f->trend_ago--;
    }
    const float g = td_fused_shape(f, f->v_ms, NULL);
    const float pred = f->scale * g * f->v_ms;
    if (f->hold_s > 0.0f) {
        f->hold_s += TD_FUSED_BUCKET_S;
        /* past the first judgement: judged again STEP_MORE_S after it */
        const bool more = f->hold_s > STEP_HOLD_S + 0.5f * TD_FUSED_BUCKET_S;
        if (f->hold_s < STEP_HOLD_S + (more ? STEP_MORE_S : 0.0f) - 0.5f * TD_FUSED_BUCKET_S) {
            return;
        }
        const float held_s = f->hold_s;
        f->hold_s = 0.0f;
        const float w_new = hist_mean(f, 0u, STEP_N - 1u);
        const float since = w_new - hist_mean(f, STEP_N, 2u * STEP_N - 2u);
        const float step = w_new - f->hold_w0_ms;
        const bool moved = fabsf(since) >= STEP_LEVEL_REL * pred;
        if (!(fabsf(step) > STEP_REL * pred)) {
            return; /* the wheel came back: a bounce, nothing changed */
        }
        if (moved && (since * step < 0.0f || step > 0.0f) && !more) {
            /* going back but still beyond the step's share: a bounce on its way back, or a
             * step's overshoot settling at its level (a wet patch's end on the bounce); or a
             * step up still rising (a machine in a pass does not gain speed so sharply: the
             * bounce rising with a wet patch's end). Judged once more STEP_MORE_S on, when a
             * wheel still beyond the share is a step unless it still moves the same way. (A
             * step down going on is not judged again: a brake would wait for it) */
            f->hold_s = held_s;
            return;
        }
        if (moved && since * step > 0.0f) {
            snap_to_wheel(f, w_new, f->hold_w0_ms, held_s + 2.0f * TD_FUSED_BUCKET_S);
            return;
        }
        float s_new = w_new / (g * f->v_ms);
        s_new = s_new < SCALE_MIN ? SCALE_MIN : (s_new > SCALE_MAX ? SCALE_MAX : s_new);
        /* the wheel's history before the step as the new scale would have read it: GNSS
         * against it, and the wheel's own acceleration, then see no step. The buckets from
         * the one that showed the step (as old as the hold) on are after it */
        f->step_after_n = (uint8_t)(held_s / TD_FUSED_BUCKET_S + 0.5f);
        rescale_history(f, f->step_after_n, s_new / f->scale);
        f->step_scale0 = f->scale;
        f->step_dv_ms = step / (f->scale * g);
        f->step_z0_ms = f->gnss_avg_ms;
        f->stepped_s = TD_FUSED_BUCKET_S;
        f->scale = s_new;
        set_q_share(f);
        f->p[VS] = 0.0f;
        f->p[AS] = 0.0f;
        f->p[SS] = f->p[SS] > RAMP_P_S ? f->p[SS] : RAMP_P_S;
        return;
    }
    if (f->v_ms > CRUISE_MIN_MS && wheel_trend(f, pred)) {
        /* a brake or a launch: the wheel leads, the estimate follows it with the whole jerk (a
         * keeps its value: the bounce's ramps come now and then, and a slope set as a held the
         * caller's steady motion off for 1.5 s after them) */
        const float m0 = hist_mean(f, 0u, STEP_N - 1u);
        if (f->trend_n == 0u) {
            const float y = m0 / (f->scale * td_fused_shape(f, f->v_ms, NULL)) - f->v_ms;
            f->p[VV] = f->p[VV] > y * y ? f->p[VV] : y * y;
            f->p[VA] = 0.0f;
            f->p[AA] = P0_A;
        }
        f->trend_w_ms = m0 > pred ? m0 : -m0;
        f->trend_n = TREND_KEEP;
        f->trend_ago = TREND_AGO_N;
        f->cruise = false;
        f->q_share = 1.0f;
        return;
    }
    if (f->trend_n > 0u) {
        /* the wheel went back against the ramp: it was the bounce's (a brake goes on) */
        const float back = hist_mean(f, 0u, STEP_N - 1u) - fabsf(f->trend_w_ms);
        if ((f->trend_w_ms > 0.0f ? back : -back) < -TREND_BACK_REL * pred) {
            f->trend_n = 0u;
            return;
        }
        f->trend_n--;
        f->q_share = 1.0f;
        return;
    }
    /* in cruise, or as flat as cruise with the scale learned and GNSS not moving now: two noisy
     * fixes end cruise for the delay + 1 s, and a slip step then went in as a speed change until
     * GNSS's check (a slow brake's onset, which GNSS already shows, is no step to hold) */
    const bool flat = f->q_share < CRUISE_SHARE && f->p[SS] < P_S_REOPEN && f->moves_n < 2u;
    if (!(f->cruise || flat) || !(f->since_gnss_s < STEP_GNSS_S) || !(f->v_ms > CRUISE_MIN_MS) ||
        !(fabsf(f->a_ms2) < RAMP_A_MS2)) {
        return;
    }
    const float b0 = hist_mean(f, 0u, 0u);
    /* the wheel's bounce from one bucket to the next (share of the speed): a step stands out
     * of it by STEP_SHARP_K of its sigmas (a wheel that bounces harder needs a larger one) */
    const float d01 = (b0 - hist_mean(f, 1u, 1u)) / pred;
    f->bounce_var += STEP_BOUNCE_K * (d01 * d01 - f->bounce_var);
    if (!(fabsf(b0 - pred) > STEP_REL * pred)) {
        f->departed = 0;
        return;
    }
    /* judged on the first two buckets beyond: a ramp that went on is no step; a wheel that
     * crossed to the other side beyond the band (a slip step out of a bounce) departs anew */
    const int8_t side = b0 > pred ? 1 : -1;
    if (f->departed * side < 0) {
        f->departed = 0;
    }
    const float w_old = hist_mean(f, 2u, 4u);
    const float sharp = STEP_SHARP_K * sqrtf(f->bounce_var);
    const bool stepped = fabsf(b0 - w_old) > (sharp > STEP_SHARP_REL ? sharp : STEP_SHARP_REL) * pred;
    /* beyond that, a sharp step up still is one: the slow bounce may carry the wheel out of the
     * band just before a slip step (a wet patch's end on a rising bounce), and a machine in a
     * pass does not gain speed that sharply (a brake may, and goes on as a ramp) */
    if (f->departed * side >= 2 && !(stepped && side > 0 && b0 > w_old)) {
        return;
    }
    if (f->departed * side < 2) {
        f->departed = (int8_t)(f->departed + side);
    }
    if (!stepped || !(fabsf(b0 - pred) < STEP_MAX_REL * pred)) {
        return;
    }
    if (f->stepped_s > 0.0f && (b0 - w_old) * f->step_dv_ms > 0.0f) {
        /* the wheel went on the same way: the first step was a brake (or a launch) too */
        undo_step(f);
        snap_to_wheel(f, b0, w_old, 3.0f * TD_FUSED_BUCKET_S);
        return;
    }
    if (f->trend_ago > 0u && (b0 - w_old) * f->trend_w_ms > 0.0f) {
        /* a ramp the same way ended lately: a slow brake whose ramp the bounce hid for a moment */
        snap_to_wheel(f, b0, w_old, 3.0f * TD_FUSED_BUCKET_S);
        return;
    }
    f->hold_s = TD_FUSED_BUCKET_S;
    f->hold_w0_ms = w_old;
}

void td_fused_record(td_fused_t *f, float z_ms, float dt_s) {
    if (!(z_ms >= 0.0f && z_ms < HIST_Z_MAX_MS) || !(dt_s <= HIST_DT_MAX_S)) {
        /* no wheel (encoder fault), or no number: the history says nothing any more, and a
         * re-opening that rested on it is over */
        f->hist_n = 0u;
        f->hist_sum = 0.0f;
        f->hist_s = 0.0f;
        f->reopened = false;
        f->q_share = 1.0f;
        f->hold_s = 0.0f;
        return;
    }
    f->hist_sum += z_ms * dt_s;
    f->hist_s += dt_s;
    /* buckets stay TD_FUSED_BUCKET_S long whatever the step: the overshoot starts the next one,
     * and a long step fills several */
    while (f->hist_s >= BUCKET_CLOSE_S) {
        f->hist_head = (uint8_t)((f->hist_head + 1u) % TD_FUSED_HIST);
        f->hist_mms[f->hist_head] = (uint16_t)(f->hist_sum / (f->hist_s * TD_FUSED_HIST_MM_S) + 0.5f);
        if (f->hist_n < TD_FUSED_HIST) {
            f->hist_n++;
        }
        f->hist_s -= TD_FUSED_BUCKET_S;
        f->hist_sum = z_ms * f->hist_s;
        set_q_share(f);
        step_check(f);
    }
}

bool td_fused_wheel_at(const td_fused_t *f, float delay_s, float *z_ms) {
    /* bucket i (0 = newest complete) is centred hist_s + (i + 0.5) buckets back */
    float x = (delay_s - f->hist_s) / TD_FUSED_BUCKET_S - 0.5f;
    x = x > 0.0f ? x : 0.0f;
    if (!(x <= (float)f->hist_n - 1.0f)) {
        return false;
    }
    const unsigned i = (unsigned)x;
    const unsigned k = f->hist_head + TD_FUSED_HIST - i;
    const float w0 = (float)f->hist_mms[k % TD_FUSED_HIST] * TD_FUSED_HIST_MM_S;
    /* the older neighbour: at the oldest bucket x is whole and it weighs 0 (every entry is a
     * finite speed: init zeroes the ring, record writes only checked speeds) */
    const float w1 = (float)f->hist_mms[(k - 1u) % TD_FUSED_HIST] * TD_FUSED_HIST_MM_S;
    *z_ms = w0 + (x - (float)i) * (w1 - w0);
    return true;
}

bool td_fused_wheel_accel(const td_fused_t *f, float *a_ms2) {
    if (f->hist_n < 2u * ACCEL_BUCKETS) {
        return false;
    }
    int32_t diff = 0; /* newest second less the second before, mm/s summed over its buckets */
    for (unsigned i = 0u; i < ACCEL_BUCKETS; i++) {
        diff += (int32_t)f->hist_mms[(f->hist_head + TD_FUSED_HIST - i) % TD_FUSED_HIST];
        diff -= (int32_t)f->hist_mms[(f->hist_head + TD_FUSED_HIST - i - ACCEL_BUCKETS) % TD_FUSED_HIST];
    }
    *a_ms2 = (float)diff * TD_FUSED_HIST_MM_S / ((float)ACCEL_BUCKETS * (float)ACCEL_BUCKETS * TD_FUSED_BUCKET_S);
    return true;
}

/* The wheel's mean over the fix period centred delay_s back (at most 1 s, in WHEEL_MEAN_N
 * points): a fix from a receiver's filter stands for its period, and the mean takes the wheel's
 * bounce out of the comparison as much as the period allows (at 1 Hz one 100 ms bucket gave
 * the scale 2.7 % of bounce per fix). False where the span leaves the history. */
static bool wheel_over(const td_fused_t *f, float delay_s, float period_s, float *z_ms) {
    const float span = period_s < WHEEL_MEAN_MAX_S ? period_s : WHEEL_MEAN_MAX_S;
    const float step = span / (float)WHEEL_MEAN_N;
    float sum = 0.0f;
    for (unsigned i = 0u; i < WHEEL_MEAN_N; i++) {
        float w = 0.0f;
        if (!td_fused_wheel_at(f, delay_s + ((float)i + 0.5f) * step - 0.5f * span, &w)) {
            return false;
        }
        sum += w;
    }
    *z_ms = sum / (float)WHEEL_MEAN_N;
    return true;
}

/* The scale from the wheel's history against GNSS at the same instant: no motion model between
 * them, so an acceleration cannot take up a scale error. Innovation in wheel m/s. */
static void learn_scale(td_fused_t *f, float z_ms, float w_then, float g, float period_s) {
    const float h[3] = { 0.0f, 0.0f, g * z_ms };
    const float sg = f->scale * g;
    const float sd = HIST_REL * w_then;
    /* a fix that comes after a longer period stands for that many at 4 Hz (a receiver's fixes
     * are correlated through its filter), so a 1 Hz receiver teaches the scale as fast */
    const float n = period_s > SCALE_PERIOD_S ? period_s / SCALE_PERIOD_S : 1.0f;
    const float r = (sd * sd + WHEEL_FLOOR_MS * WHEEL_FLOOR_MS + sg * sg * f->r_gnss) / (n < 4.0f ? n : 4.0f);
    (void)update(f, h, w_then - sg * z_ms, r, true);
}

td_fused_result_t td_fused_gnss(td_fused_t *f, float z_ms, float delay_s, bool learn) {
    const float d = delay_s > 0.0f ? delay_s : 0.0f;
    float h[3] = { 1.0f, -d, 0.0f };
    const float y = z_ms - (f->v_ms - f->a_ms2 * d);
    f->innov_ms = y;
    float w_then = 0.0f;
    const bool have_w = wheel_over(f, d, f->since_gnss_s, &w_then);
    const float g = td_fused_shape(f, z_ms, NULL);
    /* GNSS against the wheel at the fix's time, in speed: what a scale error leaves */
    const float ys = have_w ? z_ms - w_then / (f->scale * g) : y;
    /* steady: the estimate's a and the wheel's own acceleration over its last 2 s both small,
     * or the wheel's alone very small: a wrong scale or lag can hold the estimate's a away from
     * 0 while the wheel says the speed does not change (v - a d takes up the difference; the
     * wheel's change over the delay alone let a bouncing wheel re-open on noise) */
    float aw = 0.0f;
    const bool steady = fabsf(f->a_ms2) < REOPEN_A_MS2 || (td_fused_wheel_accel(f, &aw) && fabsf(aw) < FLAT_A_MS2);
    /* a changed wheel scale: innovations of one sign for REOPEN_S whose mean is beyond
     * REOPEN_SIGMA GNSS sigmas */
    /* and settled: a receiver's velocity filter reaches the new speed only some of its time
     * constants after a change, so GNSS and the wheel are compared for the scale only once
     * GNSS has stopped moving (against its own 1 s mean) for the delay and a second more
     * (twice the delay held the field's loose patches back too long: docs/speed.md). A slip step moves the wheel, not GNSS: it is not held back */
    /* against the mean before this fix: at 1 Hz the mean is the previous fix */
    const bool gnss_moves = fabsf(z_ms - f->gnss_avg_ms) > GNSS_MOVES_MS;
    const float k_avg = f->since_gnss_s < GNSS_AVG_S ? f->since_gnss_s / GNSS_AVG_S : 1.0f;
    f->gnss_avg_ms += k_avg * (z_ms - f->gnss_avg_ms);
    /* one fix off its mean is noise (at 5 Hz one in ~60 is 2.5 sigmas out); two in a row, a
     * moving speed */
    f->moves_n = gnss_moves ? (uint8_t)(f->moves_n < 2u ? f->moves_n + 1u : 2u) : 0u;
    f->quiet_s = f->moves_n >= 2u ? 0.0f : f->quiet_s + f->since_gnss_s;
    /* a scale step taken from the wheel (step_check), checked once GNSS shows its time: GNSS's
     * mean moved half the step the same way, it was a speed change */
    if (f->stepped_s > d + STEP_VERIFY_S) {
        const float moved = f->gnss_avg_ms - f->step_z0_ms;
        float w_now = 0.0f;
        if (moved * f->step_dv_ms > 0.0f && fabsf(moved) > 0.5f * fabsf(f->step_dv_ms) &&
            moved * moved > RAMP_SIGMA2 * f->r_gnss &&
            wheel_over(f, RAMP_W_S, RAMP_W_S, &w_now)) {
            undo_step(f);
            f->v_ms = w_now / (f->scale * td_fused_shape(f, f->v_ms, NULL));
            f->a_ms2 = 0.0f;
            f->p[VV] = f->p[VV] > f->r_gnss ? f->p[VV] : f->r_gnss;
            f->p[VA] = 0.0f;
            f->p[AA] = P0_A;
            f->q_share = 1.0f;
            f->cruise = false;
        } else if (f->stepped_s > d + STEP_CONFIRM_S) {
            f->stepped_s = 0.0f;
        }
    }
    /* a speed change GNSS should show by now (it began longer than the delay ago): GNSS moved,
     * it was one; GNSS held still and stands apart from the wheel at the fix's time against it,
     * the wheel's scale stepped (a wet patch) and the speed did not. The scale then takes the
     * step at once from the wheel's last half second against GNSS, and the change is undone */
    const float dv = f->v_ms - f->ramp_v0_ms;
    float w_now = 0.0f;
    if (f->ramp_s > 0.0f && fabsf(f->gnss_avg_ms - f->ramp_z0_ms) > GNSS_MOVES_MS) {
        f->ramp_s = 0.0f;
    } else if (have_w && f->ramp_s > d + RAMP_MARGIN_S && fabsf(dv) > GNSS_MOVES_MS && z_ms > SCALE_MIN_MS &&
               ys * dv < 0.0f && ys * ys > RAMP_SIGMA2 * f->r_gnss && wheel_over(f, RAMP_W_S, RAMP_W_S, &w_now)) {
        const float s_new = w_now / (g * z_ms);
        f->scale = s_new < SCALE_MIN ? SCALE_MIN : (s_new > SCALE_MAX ? SCALE_MAX : s_new);
        f->v_ms = z_ms;
        f->a_ms2 = 0.0f;
        f->p[VV] = f->r_gnss;
        f->p[VA] = 0.0f;
        f->p[VS] = 0.0f;
        f->p[AA] = RAMP_P_A;
        f->p[AS] = 0.0f;
        f->p[SS] = f->p[SS] > RAMP_P_S ? f->p[SS] : RAMP_P_S;
        f->ramp_s = 0.0f;
        f->since_gnss_s = 0.0f;
        return TD_FUSED_ACCEPTED;
    }
    const bool settled = steady && f->quiet_s >= d + SETTLE_S;
    const int8_t sign = (int8_t)(ys > REOPEN_MIN_MS ? 1 : (ys < -REOPEN_MIN_MS ? -1 : 0));
    if (sign != 0 && sign == f->run_sign && settled) {
        f->run_s += f->since_gnss_s;
        f->run_sum += ys * f->since_gnss_s;
    } else {
        f->reopened = false; /* the run is over */
        f->run_s = 0.0f;
        f->run_sum = 0.0f;
        f->run_sign = sign;
    }
    if (!f->reopened && f->run_s >= REOPEN_S) {
        const float mean = f->run_sum / f->run_s;
        if (mean * mean > REOPEN_SIGMA2 * f->r_gnss) {
            f->reopened = true;
            if (f->p[SS] < P_S_REOPEN) {
                f->p[SS] = P_S_REOPEN;
            }
        }
    } else if (f->reopened && ys * ys < CLOSE_SIGMA2 * f->r_gnss) {
        f->reopened = false;
    }
    const float period_s = f->since_gnss_s;
    f->since_gnss_s = 0.0f;
    /* the jerk over the delay; in steady motion a small share of it */
    float r = f->r_gnss + (learn ? Q_STEADY : 1.0f) * f->q_jerk * d * d * d / 3.0f;
    const bool learning = settled && (learn || f->reopened);
    /* flat and settled: the speed then was the speed now, so the fix corrects v itself; through
     * v - a d an acceleration could take up GNSS's difference and hold v off for seconds */
    const bool cruise = learning && !f->reopened && f->q_share < CRUISE_SHARE;
    f->cruise = cruise || f->hold_s > 0.0f;
    if (cruise) {
        h[1] = 0.0f;
        r = f->r_gnss + CRUISE_A_MS2 * CRUISE_A_MS2 * d * d;
        f->innov_ms = z_ms - f->v_ms;
    } else if (f->q_share < CRUISE_SHARE && f->quiet_s < d) {
        /* GNSS still moves while the wheel says the speed holds: its filter still settles */
        r *= GNSS_UNSETTLED_K;
    }
    if (!update(f, h, f->innov_ms, r, learning && !have_w && !cruise)) {
        return TD_FUSED_REJECTED; /* a refused GNSS speed teaches the scale nothing either */
    }
    if (learning && have_w && z_ms > SCALE_MIN_MS) {
        learn_scale(f, z_ms, w_then, g, period_s);
    }
    return TD_FUSED_ACCEPTED;
}

void td_fused_standstill(td_fused_t *f) {
    f->v_ms = 0.0f;
    f->a_ms2 = 0.0f;
    f->p[VV] = 1.0e-4f;
    f->p[VA] = 0.0f;
    f->p[VS] = 0.0f;
    f->p[AA] = 1.0e-2f;
    f->p[AS] = 0.0f;
    f->wheel_rejects = 0u;
    f->run_s = 0.0f;
    f->run_sum = 0.0f;
    f->run_sign = 0;
    f->ramp_s = 0.0f;
    f->cruise = false;
    f->hold_s = 0.0f;
}

float td_fused_lead_ms(const td_fused_t *f, float lead_s) {
    const float v = f->v_ms + f->a_ms2 * lead_s;
    return v > 0.0f ? v : 0.0f;
}

float td_fused_lead_accel_ms2(const td_fused_t *f) {
    const float a = f->a_ms2;
    const float a2 = a * a;
    /* the bounce's share of a grows with the speed (the bounce is relative); a launch from
     * rest keeps its acceleration */
    const float k = LEAD_A_SHRINK_PER_MS * f->v_ms;
    const float s = a2 > 0.0f ? a * a2 / (a2 + k * k) : 0.0f;
    return s > LEAD_A_MAX ? LEAD_A_MAX : (s < -LEAD_A_MAX ? -LEAD_A_MAX : s);
}

float td_fused_speed_std_ms(const td_fused_t *f) {
    return sqrtf(f->p[VV]);
}
