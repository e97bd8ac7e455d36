/**
 * @file td_fused.h
 * @brief The fused speed estimate: a 3-state extended Kalman filter over ground speed v (m/s),
 *        acceleration a (m/s^2) and the ground wheel's scale s (wheel speed / true speed,
 *        1 - slip), fed by the wheel at every control step and by GNSS at its time of validity.
 *
 * Model (docs/speed.md): constant acceleration driven by white jerk of density q = jerk^2,
 *   v' = v + a*dt,  a' = a,  s' = s (+ a slow random walk, only felt while it is learned).
 * Flat motion: the jerk in force is q times a share, (a_w / 0.2 m/s^2)^2 within 0.05..1, where
 *   a_w is the wheel's own acceleration (td_fused_wheel_accel, set at every 100 ms bucket);
 *   below 0.5 m/s, or without 2 s of history, the whole of it. While the wheel says the speed
 *   holds, the estimate then averages the wheel's bounce over seconds instead of following it
 *   (eq. 5's slope halves what the wheel says of the speed at 10 km/h, so its bounce counts
 *   double); a launch or a brake brings the whole jerk back within ~1 s.
 * Wheel (every step):   z_w = s * g(v) * v + noise,  H = [s (g + v g'), 0, g v], with g = 1 the
 *   scale is a constant; with the slip shape on, g(v) = 1 - eq. 5 slip(v) / 100 and s learns how
 *   far this soil is from the paper's wheat stubble (the slip then follows the speed at once),
 *   R_w = (wheel_noise * z_w)^2 + floor^2 + quantization (counts-only ports); 1000 times that in
 *   flat motion (jerk share < 0.3) while GNSS backs the estimate and the wheel is within 5 % of
 *   it: the bounce wanders over seconds, no white noise, so GNSS holds the level; a wheel beyond
 *   5 % (a brake, a launch) weighs in full at once. In an outage (no accepted fix for 1.5 s)
 *   with the scale learned (its variance below (3 %)^2, which it leaves ~40 s into the outage)
 *   and in flat motion, the wheel, its ~0.3 s mean within 5 %, weighs a tenth: its slow
 *   bounce, read through eq. 5's slope ~1.5 times as large in speed, is averaged over seconds
 *   (a pass 3 % slower is followed with a time constant of ~4 s, a gentle ramp of 0.02-0.04
 *   m/s^2 up to 2.4-4.4 % behind); a ramp that brings the whole jerk back (the wheel's own
 *   acceleration ~0.1 m/s^2 and more) is followed in full.
 * Cruise (the last fix was settled and flat, below) above 6 km/h, while the wheel's innovation
 *   (its mean over ~0.3 s) stays within 5 %: a decays with a time constant of 0.5 s, so a fix's
 *   noise left in a does not ramp v until the next fix (a Gauss-Markov acceleration). Below
 *   6 km/h the wheel measures well and a brake from a slow pass shows in it first. Out of
 *   cruise too, in flat motion with the wheel within 5 %, once the scale has learned (its
 *   variance below (3 %)^2), with a fix in the last 0.5 s and no speed change awaiting GNSS's
 *   check (4. below): after a ramp, GNSS through v - a d kept the ramp's a for seconds while
 *   the receiver's filter settled, and v ran on (+9 % on the field drives at 5 Hz).
 * A ramp of the wheel above 6 km/h (td_fused_record, every 100 ms bucket, before the step
 *   check): three 0.3 s means each moving the same way by 3 % of the estimate's wheel speed (or
 *   1.5 sigmas of a mean's bounce), evenly (|d1 - d2| < 0.2 (d1 + d2): a slip step moves one, or
 *   two by 1/3 and 2/3), the newest beyond 6 % and within 40 %: a brake or a launch. a gets
 *   its whole variance back (not the three's slope: a wandering bounce passes for a ramp now
 *   and then, and its slope held the caller's steady motion off for 1.5 s), v's variance opens
 *   to its distance from the wheel's newest mean, and for 1 s after the last bucket that shows
 *   it there is no cruise and the whole jerk, unless the wheel's newest 0.3 s mean goes back
 *   against the ramp by 1.5 % of the estimate's wheel speed: a brake goes on, the bounce's
 *   ramp ends there.
 * A sharp step of the wheel in cruise above 6 km/h (td_fused_record, every 100 ms bucket), or
 *   out of cruise in flat motion (jerk share < 0.3) with the scale learned and GNSS not moving
 *   (two noisy fixes end cruise for the delay + 1 s): the estimate flat (|a| < 0.1 m/s^2), the
 *   newest bucket beyond 5 % of the estimate's wheel speed, moved by 7 % (or 3 sigmas of the
 *   wheel's own bucket-to-bucket bounce) against the buckets 0.2-0.5 s before, on the first two
 *   buckets beyond 5 % on one side (a ramp that went on is no step; a wheel that crosses to the
 *   other side departs anew; a step up is one later too, as the slow bounce may have carried
 *   the wheel out of the band just before a slip step), and within 25 % (a cut cable is the gate's). The wheel then weighs nothing for 0.6 s and is
 *   judged on two 3-bucket means: back near where it was, a bounce; level (within 3.5 %), a
 *   slip step: the scale takes it, v holds, the history before the step is rescaled to the new
 *   scale; still moving the same way, a speed change: v and a restart from the wheel; going
 *   back by 3.5 % but still beyond 5 % of where it was (a step's overshoot settling), or a step
 *   up still rising (a machine in a pass does not gain speed so sharply), judged once more
 *   0.3 s later, when a wheel still beyond 5 % is a step unless it still moves the same way.
 *   The history from the bucket that showed the step on (as old as the hold) is after it; the
 *   older is rescaled to the new scale. A scale
 *   step is undone (scale and history back, v from the wheel) by a second sharp step the same
 *   way, or by GNSS's 1 s mean moving half the step the same way (beyond 3 GNSS sigmas) within
 *   the delay + 0.5 s; confirmed after the delay + 1.5 s. A sharp step the way of a ramp that
 *   showed in the last 2 s is not held but goes on with it (v and a from the wheel): with the
 *   ramp's end, a slow brake whose ramp the bounce hid for a moment was taken for a slip step.
 * GNSS (delayed by d = age + lag) enters twice:
 *   1. the scale, against the wheel's own history at the fix's time of validity (100 ms means
 *      kept for 3.6 s in mm/s, td_fused_record): z = w(t - d) = s g(z_g) z_g, H = [0, 0, g z_g],
 *      R = (4 % of w)^2 + floor^2 + (s g)^2 gnss_std^2. Wheel and GNSS then describe the same
 *      instant, so no motion model stands between them and an acceleration cannot take up a
 *      scale error (it did when the scale was learned through v - a d);
 *   2. the speed through the model: z_g = v(t - d) = v - a*d,  H = [1, -d, 0],
 *      R_g = gnss_std^2 + q*d^3/3 (the jerk over the delay; 1 % of it in steady motion), with
 *      the scale's row of the gain zeroed; ten times that while GNSS still moves (quiet for less
 *      than the delay) and the wheel says the speed holds (jerk share < 0.3): what GNSS still
 *      shows of a change is its filter settling. Beyond the history (a delay over ~3.5 s, or no wheel)
 *      the scale is learned through this update instead.
 *   3. settled (below) and flat (jerk share < 0.3), not re-opened (cruise): the speed then was
 *      the speed now, so the fix is compared with v itself, H = [1, 0, 0], R = gnss_std^2 +
 *      (0.02 m/s^2 d)^2 (an acceleration the wheel may not show yet): through v - a d, an
 *      acceleration left by the wheel's bounce took up GNSS's difference and held v 2-5 % off
 *      for seconds.
 *   4. a speed change GNSS does not show: the estimate's acceleration went beyond 0.1 m/s^2
 *      longer than d + 0.2 s ago, its speed has moved by more than 0.1 m/s since, GNSS's 1 s mean
 *      has not (within 0.1 m/s), and GNSS stands apart from the wheel at the fix's time against
 *      the change by 3 GNSS sigmas: the wheel's scale stepped (a wet patch). The scale is set
 *      from the wheel's last 0.5 s against GNSS (its variance at least (2 %)^2), v = GNSS, a = 0.
 *      A change GNSS's mean follows by 0.1 m/s is a real one and is no longer checked.
 * The scale is learned only while the caller says (`learn`: GNSS good, motion steady) or while
 * re-opened, and kept through GNSS outages.
 * Scale random walk 2e-5/s; its variance never grows beyond the initial (10 %)^2.
 * Loose ground: GNSS against the scaled wheel history, one sign (beyond 0.05 m/s) for 1 s or
 * longer in steady motion, with a mean beyond 2 GNSS sigmas, says the wheel's scale has
 * changed (a slip step): learning re-opens (`reopened`) while the motion is steady, the scale's
 * variance raised to at least (3 %)^2, until that difference changes sign or falls within
 * 1 GNSS sigma. Steady: |a| < 0.3 m/s^2, or the wheel's own acceleration (td_fused_wheel_accel)
 * below 0.1 m/s^2 (with a short lag, ~0.6 s at 3-4 m/s, a takes up a slip step's difference
 * beyond 0.3 m/s^2; the wheel says the speed holds). Settled: the scale learns (either way) only
 * once GNSS has stayed within 0.1 m/s of its 1 s mean for the delay + 1 s (a receiver's filter
 * still settling after a brake taught a wrong slip); one fix beyond is noise, two in a row end it. A fix after a period longer than 0.25 s
 * teaches the scale as period / 0.25 s fixes (at most 4). At 2 m/s with GNSS 1.3 s late, a 15 %
 * slip step is learned to within 1.5 % in ~4 s; at 3.5 m/s with GNSS 0.6 s late, 3 % in 4 s.
 * eq. 5's shape g(v) is held at its 12 km/h value above 12 km/h: the fit's g(v) v falls again
 * above ~14.7 km/h, which gave a wheel reading a second, false speed to run off to.
 * Innovations beyond 5 sigma (and beyond 0.3 m/s) are rejected: a frozen receiver, a cut
 * encoder cable, a bounce. A wheel rejected for 25 steps in a row while no accepted GNSS backs
 * the estimate restarts the speed from the wheel.
 * Costs per step: ~120 float operations (a bucket's step check ~60 more); 228 bytes (144 of
 * state, 84 of wheel history; it was 180). No heap, no globals.
 */
#ifndef TD_FUSED_H
#define TD_FUSED_H

#include <stdbool.h>
#include <stdint.h>

/** Result of a measurement update. */
typedef enum { TD_FUSED_ACCEPTED = 0, TD_FUSED_REJECTED = 1, TD_FUSED_RESTARTED = 2 } td_fused_result_t;

/** Wheel history: TD_FUSED_HIST means of TD_FUSED_BUCKET_S each (3.6 s back: a GNSS lag of
 *  up to 3 s plus the fix's age), kept in mm/s. */
#define TD_FUSED_HIST 36u
#define TD_FUSED_BUCKET_S 0.1f
#define TD_FUSED_HIST_MM_S 0.001f /**< resolution of a bucket, m/s */

typedef struct {
    float v_ms;                /**< ground speed, m/s, >= 0 */
    float a_ms2;               /**< acceleration, m/s^2 */
    float scale;               /**< wheel scale s = wheel / true speed, 0.5..1.5 (slip = 1 - s) */
    float p[6];                /**< covariance, upper triangle: vv va vs aa as ss */
    float q_jerk;              /**< jerk density, (m/s^3)^2/Hz */
    float q_share;             /**< the share of q_jerk in force, 0.05..1: small while the wheel says the speed holds */
    float r_gnss;              /**< GNSS speed variance, (m/s)^2 */
    float wheel_rel;           /**< wheel noise, share of speed */
    float innov_ms;            /**< last GNSS innovation (z - prediction at its time of validity), m/s */
    float since_gnss_s;        /**< time since the last GNSS update, s */
    float run_s;               /**< how long GNSS against the scaled wheel history has kept one sign, s */
    float run_sum;             /**< its integral over that time, m */
    int8_t run_sign;           /**< their sign (0: none) */
    float quiet_s;             /**< how long GNSS has stayed within 0.1 m/s of its 1 s mean, s (counted at the fixes) */
    uint8_t moves_n;           /**< fixes in a row beyond 0.1 m/s of that mean, 0..2 (2 ends the quiet) */
    float gnss_avg_ms;         /**< GNSS speed, its mean over ~1 s, m/s */
    float ramp_s;              /**< time since the estimate's acceleration went beyond 0.1 m/s^2, s (0: none) */
    float ramp_v0_ms;          /**< the estimate's speed then, m/s */
    float ramp_z0_ms;          /**< and GNSS's 1 s mean, m/s */
    bool reopened;             /**< a sustained GNSS innovation re-opened the scale's learning */
    bool cruise;               /**< the last fix found the motion flat and settled: GNSS holds the level */
    float hold_s;              /**< a sharp step of the wheel in cruise held out this long, s (0: none; beyond 0.6 s: judged once, held 0.3 s more) */
    float hold_w0_ms;          /**< the wheel's speed before that step, m/s */
    float stepped_s;           /**< time since the scale took a wheel's step, s (0: none pending GNSS's check) */
    float step_scale0;         /**< the scale before it */
    uint8_t step_after_n;      /**< the history's buckets newer than this were after that step when it was taken */
    float step_dv_ms;          /**< the step, as a speed, m/s */
    float step_z0_ms;          /**< GNSS's 1 s mean then, m/s */
    float wheel_dev;           /**< the wheel's innovation, share of its speed, mean over ~0.3 s */
    float bounce_var;          /**< the wheel's bucket-to-bucket change in cruise, its mean square, share of speed ^2 */
    uint8_t trend_n;           /**< buckets left of a wheel's ramp (no cruise, the whole jerk), 0..10 */
    float trend_w_ms;          /**< the wheel's newest 0.3 s mean when the ramp last showed, m/s (negative: a ramp down) */
    uint8_t trend_ago;         /**< buckets left in which a sharp step the ramp's way goes on with it, 0..20 */
    int8_t departed;           /**< buckets of the wheel beyond 5 % of the estimate judged for a step, -2..2 (its sign: below or above) */
    uint8_t wheel_rejects;     /**< wheel updates rejected in a row */
    bool slip_shape;           /**< the wheel's slip follows eq. 5's shape in speed, scaled by s */
    uint8_t hist_head;         /**< index of the newest complete bucket */
    uint8_t hist_n;            /**< complete buckets held, 0..TD_FUSED_HIST */
    float hist_sum;            /**< the bucket being filled: integral of the wheel speed, m */
    float hist_s;              /**< and its length, s */
    uint16_t hist_mms[TD_FUSED_HIST]; /**< mean wheel speed per bucket, mm/s (newest at hist_head) */
} td_fused_t;

/** Initialise at rest, scale 1, with the tuning (units of td_params.h). TD_E_ARG on a bad argument. */
int td_fused_init(td_fused_t *f, float jerk_ms3, float gnss_std_kmh, float wheel_noise_pct);
/** Change the tuning, keeping the state. */
void td_fused_tune(td_fused_t *f, float jerk_ms3, float gnss_std_kmh, float wheel_noise_pct);
/** Advance the state by dt_s (0..0.05 s). */
void td_fused_predict(td_fused_t *f, float dt_s);
/**
 * Wheel update with the wheel circumference speed z_ms (m/s, no slip correction); r_extra is
 * added variance (quantization). `gnss_backs` = an accepted GNSS speed is recent (then a
 * persistently rejected wheel stays rejected).
 */
td_fused_result_t td_fused_wheel(td_fused_t *f, float z_ms, float r_extra, bool learn, bool gnss_backs);
/** Record the wheel circumference speed z_ms (m/s, 0 at rest) over the last dt_s (every step; any
 *  period: a step's overshoot beyond a bucket starts the next). z_ms < 0 (no wheel: encoder
 *  fault), a step longer than the history, or no number clears the history and ends a re-opening. */
void td_fused_record(td_fused_t *f, float z_ms, float dt_s);
/** The recorded wheel speed delay_s ago (m/s, interpolated between buckets); false beyond the history. */
bool td_fused_wheel_at(const td_fused_t *f, float delay_s, float *z_ms);
/**
 * The wheel's own acceleration from its history, m/s^2 of wheel speed: the mean of the newest
 * second of buckets less that of the second before, over 1 s. False with less than 2 s held.
 * It does not depend on the scale or on GNSS, so it tells steady motion from a speed change
 * when the estimate's acceleration has taken up a wrong scale or lag.
 */
bool td_fused_wheel_accel(const td_fused_t *f, float *a_ms2);
/** GNSS update with speed z_ms valid delay_s (0..10 s) ago. */
td_fused_result_t td_fused_gnss(td_fused_t *f, float z_ms, float delay_s, bool learn);
/** The wheel stands (no pulse for the stop time): speed and acceleration are zero. */
void td_fused_standstill(td_fused_t *f);
/** The slip shape g(v) (1 without the shape) and, if slope != NULL, dg/dv per m/s. */
float td_fused_shape(const td_fused_t *f, float v_ms, float *slope);
/** Speed predicted lead_s ahead, m/s, >= 0 (0 once the prediction reaches a stop). */
float td_fused_lead_ms(const td_fused_t *f, float lead_s);
/**
 * The acceleration the look-ahead uses, m/s^2: the estimate's, with its wheel-bounce noise
 * shrunk away, a^3 / (a^2 + k^2) with k = 0.13 /s * v (the bounce is a share of the speed: at
 * 8 km/h k = 0.29 m/s^2; a launch from rest keeps its acceleration), bounded to +-3 m/s^2.
 */
float td_fused_lead_accel_ms2(const td_fused_t *f);
/** 1-sigma uncertainty of the speed, m/s. */
float td_fused_speed_std_ms(const td_fused_t *f);

#endif /* TD_FUSED_H */
