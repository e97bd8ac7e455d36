/**
 * @file td_lag.h
 * @brief The GNSS speed's lag behind the machine, learned from the wheel by the area between
 *        the two over a speed change (docs/speed.md).
 *
 * For any linear filter of unit DC gain between the machine's speed v and what GNSS reports z
 * (a receiver's latency D, its first-order velocity filter tau, the half fix period of a speed
 * from two positions), the area between them over a change from one steady speed v0 to
 * another v1 is the filter's first moment, its mean delay, times the change:
 *   integral (v - z) dt = lag * (v1 - v0),   lag = D + tau (+ period / 2),
 * whatever the speed did in between. The learner measures it with the wheel's ground speed u
 * for v (u = w / (s g(u)): the circumference speed w through the estimate's slip shape g,
 * td_fused.h, at the estimate's scale s when the change began):
 * - every control step the wheel is integrated (td_lag_wheel); at every GNSS fix (speed z, m/s,
 *   its age a as the PC reports it, s) the interval since the previous fix gives the wheel's
 *   integral and GNSS's by the trapezoid, and tells steady motion from a change: the wheel's
 *   own acceleration (td_fused_wheel_accel) below 0.1 m/s^2 + 3 % of its speed per second,
 *   GNSS within 0.1 m/s of its 1 s mean, both 1 s means within 0.05 m/s + 3 % of the stretch's
 *   level; a standing wheel that turns is a change at once;
 * - a steady stretch is summed into its level (means of w and z); its newest 1-2 s stay in two
 *   blocks that join the level only once later fixes confirm them steady (the tests see a
 *   change up to ~1 s late): a change starts its window from before itself;
 * - the window sums u and z until both are steady again, GNSS has caught up with the wheel and
 *   stayed still for 1.5 lags (at least 1.5 s) and a fix: a filter's tail is in. The new
 *   stretch's level ends it:
 *     lag = (k * integral (u - u0) - integral (z - z0)) / (z1 - z0) - a,  k = (z1 - z0) / (u1 - u0),
 *   so a wheel scale not learned yet does not bias it; u is moved to the scale the levels say
 *   (GNSS is the true speed: s = w1 / (z1 g(z1))) to first order, as eq. 5's shape makes u of a
 *   wrong scale bend with the speed. From where the wheel settled (steady 0.5 s, away from its
 *   old level) on, its integral is taken as its new level times the time, if its mean since
 *   then is that level: the window then carries its noise only over the change itself.
 * A change of 0.5 m/s or more gives a result, provisional (used at once) from 1 s of confirmed
 * level after it, final when the stretch ends or has 20 s. Results are averaged weighted as
 * their noise allows, (z1 - z0)^2 / window length (less while the level after is under 5 s),
 * the weight kept at most 5 (m/s)^2/s: later changes keep weighing. Before the first result,
 * while the first change goes on (from 0.4 m/s on, until the wheel settles), the lag is the
 * area so far over the change's mean of wheel and GNSS: exact for a delay on a ramp, up to a
 * third short for a filter (`area` tells it from a result). A change back to where it began
 * (within 0.15 m/s) was none: the stretch before goes on. A change that does not settle within
 * 60 s, fixes more than 1.5 s apart, a wheel fault or a bad number drop the window.
 * Measured (bench/fused_lag_bench.py, docs/speed.md): within 0.05 s of D + tau on clean
 * signals from 0.2 to 2.0 s (test_lag.c); with the bench's noise, after the first start RMS
 * 0.05 s. RAM: 136 bytes. Cost: 2 adds per step; per fix ~100 float operations, the wheel's
 * acceleration (20 bucket reads) and 1-4 ground speeds (2 slip shapes each). No heap, no
 * globals.
 */
#ifndef TD_LAG_H
#define TD_LAG_H

#include <stdbool.h>
#include <stdint.h>
#include "td_common.h"
#include "td_fused.h"

#define TD_LAG_MAX_S 3.0f /**< learned lags are 0..3 s */

/* td_lag_state_t, where the GNSS lag in use comes from (EcuGnssLag.LagState): td_dbc.h.
 * START learning (GnssLagAuto 1), not learned yet: GnssLag is used; LEARNED learned (GnssLagAuto
 * 1): the learned lag is used; FIXED GnssLagAuto 0: GnssLag is used, the data do not contradict
 * it; OVERRULED GnssLagAuto 0, but the learned lag differs by more than 0.3 s: it is used. */

/** Integrals over a stretch of time: of u (m), of z (m), and its length (s). */
typedef struct {
    float u_m;
    float z_m;
    float t_s;
} td_lag_sum_t;

typedef struct {
    td_lag_sum_t level;    /**< the steady stretch, confirmed */
    td_lag_sum_t block[2]; /**< its newest 1-2 s, not yet confirmed ([1] the newest) */
    td_lag_sum_t change;   /**< the window: from before the change to the steady stretch after it */
    float change_du_m;     /**< the window's d(integral of u) / d(ln s), negated, m */
    float snap_u_m;        /**< the window's integral of u where the wheel had settled, m */
    float snap_du_m;       /**< and of change_du_m, m */
    float snap_t_s;        /**< and its length, s (0: not settled) */
    float wheel_steady_s;  /**< how long the wheel has been steady in the window, s */
    float w0_ms;           /**< the level before the change: wheel circumference speed, m/s */
    float u0_ms;           /**< and as ground speed at the window's scale, m/s */
    float z0_ms;           /**< and GNSS, m/s */
    float scale;           /**< the estimate's wheel scale when the window began: its ground speeds' */
    float wheel_m;         /**< the wheel's circumference speed integrated since the last fix, m */
    float wheel_s;         /**< over this long, s */
    float z_prev_ms;       /**< the previous fix, m/s */
    float z_avg_ms;        /**< GNSS, its mean over ~1 s, m/s */
    float w_avg_ms;        /**< the wheel's circumference speed, its mean over ~1 s, m/s */
    float quiet_s;         /**< how long GNSS has stayed within 0.1 m/s of that mean, s */
    float avg_s;           /**< the final results' weighted mean, s */
    float weight_ms;       /**< their weight: (z1 - z0)^2 / window, summed, (m/s)^2/s (at most 5) */
    float lag_s;           /**< the lag: avg_s with the provisional result, 0..TD_LAG_MAX_S s */
    float evidence_s;      /**< the seconds of the windows behind the final results */
    float fit;             /**< the last result's distance from the mean before it, share of the lag, 0..1 */
    uint8_t phase;         /**< 0: nothing to stand on, 1: steady, 2: changing */
    bool pending;          /**< a window with its level before the change, waiting for its end level */
    bool have_prev;        /**< z_prev_ms and the wheel's integral belong to this interval */
    bool learned;          /**< a lag known: the first change's early one, or a result */
    bool area;             /**< lag_s is (or holds) a result of a settled change, not only the early one */
} td_lag_t;

/** Start empty: nothing learned. */
void td_lag_init(td_lag_t *l);
/**
 * Every control step: the wheel's circumference speed w_ms (m/s, 0 at rest; < 0 or no number:
 * no wheel, the window is dropped) over the last dt_s (s).
 */
void td_lag_wheel(td_lag_t *l, float w_ms, float dt_s);
/**
 * Take one GNSS fix: speed z_ms (m/s), its age_s (s, from the fix to now, without the lag).
 * Needs the wheel's history of `f` (its acceleration) and its scale and slip shape. Returns
 * true when the lag (lag_s, learned) changed. A fix with a bad number (NaN, negative) is ignored.
 */
bool td_lag_fix(td_lag_t *l, const td_fused_t *f, float z_ms, float age_s);

#endif /* TD_LAG_H */
