/**
 * @file td_lag.h
 * @brief The GNSS speed's lag behind the machine, learned from the wheel: the delay at which
 *        the two agree best while the speed changes (docs/speed.md).
 *
 * At every GNSS fix (speed z, m/s, its age a as the PC reports it, s) the learner reads the
 * wheel's history (td_fused.h, 100 ms means over 3.6 s) at a + L_k for the candidate lags
 * L_k = k * TD_LAG_STEP_S, k = 0..TD_LAG_N-1 (0..3 s), as ground speed u_k = w / (s g(w/s))
 * with the estimate's scale s and slip shape g. While the speed changes in that window (the
 * candidates' speeds span more than 0.3 m/s), the fix enters a least-squares fit z = c_k u_k
 * per candidate, with c_k free so that a scale not learned yet does not bias the lag:
 *   S_zz += w z^2,  S_zu[k] += w z u_k,  S_uu[k] += w u_k^2,
 * w = the time since the previous fix (at most 1 s), every sum first decayed by (1 - w / 20 s):
 * the fit remembers the last ~20 s of speed changes. The misfit of candidate k is
 *   r_k = 1 - S_zu[k]^2 / (S_zz S_uu[k])   (1 - the squared correlation through the origin),
 * the lag the smallest r_k, refined by a parabola through its neighbours. A receiver's
 * first-order velocity filter (time constant tau) behind a latency D delays a ramp by D + tau:
 * that is the lag found. The lag counts as learned after 1.5 s of speed change whose fit has a
 * clear minimum (r_min below TD_LAG_CLEAR of the largest r_k); it is refined at every fix that
 * changes speed, and used at once by the application (td_app.c).
 * A history shorter than a + 3 s (a fix older than 0.55 s, a wheel fault that cleared it) takes
 * no fix. RAM: 144 bytes. Cost: TD_LAG_N interpolations per fix while the speed changes.
 * No heap, no globals.
 */
#ifndef TD_LAG_H
#define TD_LAG_H

#include <stdbool.h>
#include <stdint.h>
#include "td_fused.h"

#define TD_LAG_N 16u        /**< candidate lags */
#define TD_LAG_STEP_S 0.2f  /**< between candidates: 0, 0.2, ..., 3.0 s */
#define TD_LAG_MAX_S ((float)(TD_LAG_N - 1u) * TD_LAG_STEP_S)
#define TD_LAG_CLEAR 0.25f  /**< learned when r_min < this share of the largest r_k */

/** Where the GNSS lag in use comes from (EcuGnssLag.LagState). */
typedef enum {
    TD_LAG_START = 0,     /**< learning (GnssLagAuto 1), not learned yet: GnssLag is used */
    TD_LAG_LEARNED = 1,   /**< learned (GnssLagAuto 1): the learned lag is used */
    TD_LAG_FIXED = 2,     /**< GnssLagAuto 0: GnssLag is used, the data do not contradict it */
    TD_LAG_OVERRULED = 3  /**< GnssLagAuto 0, but the learned lag differs by more than 0.3 s: it is used */
} td_lag_state_t;

typedef struct {
    float s_zz;              /**< decayed sum of z^2, (m/s)^2 s */
    float s_zu[TD_LAG_N];    /**< decayed sums of z u_k */
    float s_uu[TD_LAG_N];    /**< decayed sums of u_k^2 */
    float evidence_s;        /**< decayed seconds of speed change in the fit */
    float lag_s;             /**< the best lag, s, 0..TD_LAG_MAX_S (meaningful once learned) */
    float fit;               /**< r_min / r_max, 0..1: small = a clear minimum */
    bool learned;            /**< enough speed change with a clear minimum seen */
} td_lag_t;

/** Start empty: nothing learned. */
void td_lag_init(td_lag_t *l);
/**
 * Take one GNSS fix: speed z_ms (m/s), its age_s (s, from the fix to now, without the lag),
 * weight_s the time since the previous fix (s; capped at 1 s). Returns true when the fix
 * entered the fit (the speed changes and the history reaches back far enough).
 */
bool td_lag_fix(td_lag_t *l, const td_fused_t *f, float z_ms, float age_s, float weight_s);

#endif /* TD_LAG_H */
