/**
 * @file td_invariants.h
 * @brief What must hold after every td_app_rx() and td_app_step(), whatever came in: shared by
 *        the randomized test (tests/test_fuzz.c) and the libFuzzer target (tests/fuzz/).
 *
 * The includer defines TD_CHECK(cond) (a cmocka assertion, or abort()).
 */
#ifndef TD_INVARIANTS_H
#define TD_INVARIANTS_H

#include <math.h>
#include <stdbool.h>
#include <string.h>

#include "td_app.h"
#include "td_params.h"
#include "td_proto.h"

#ifndef TD_CHECK
#error "define TD_CHECK(cond) before including td_invariants.h"
#endif

#define TD_INV_FAULT_BITS 0x01FFu

static inline uint32_t td_inv_rejections(const td_counters_t *c) {
    return c->rx_unknown_id + c->rx_bad_length + c->rx_out_of_range + c->rx_param_rejected;
}

static inline bool td_inv_finite_nonneg(float v) {
    return isfinite(v) && v >= 0.0f;
}

/** After a step: duties in [0, 1], every figure finite, every gate respected, parameters valid. */
static inline void td_inv_check_step(const td_app_t *app, const td_io_out_t *out) {
    const td_state_t *st = &app->st;
    for (unsigned l = 0u; l < TD_LAYERS; l++) {
        /* written so that NaN fails */
        TD_CHECK(out->meter_duty[l] >= 0.0f && out->meter_duty[l] <= 1.0f);
        TD_CHECK(out->fan_duty[l] >= 0.0f && out->fan_duty[l] <= 1.0f);
        TD_CHECK(out->meter_duty[l] == st->meter_duty[l] && out->fan_duty[l] == st->fan_duty[l]);
        TD_CHECK(td_inv_finite_nonneg(st->target_rpm[l]));
        TD_CHECK(td_inv_finite_nonneg(st->meter_rpm[l]));
        TD_CHECK(td_inv_finite_nonneg(st->fan_rpm[l]));
        TD_CHECK(td_inv_finite_nonneg(st->rate_kg_ha[l]));
        /* a meter turns only when everything that gates it allows it */
        if (out->meter_duty[l] > 0.0f) {
            TD_CHECK(st->running);
            TD_CHECK((st->faults & (TD_FAULT_CMD_TIMEOUT | TD_FAULT_NO_SPEED)) == 0u);
            TD_CHECK((st->faults & (TD_FAULT_UPPER_BLOCKED << l)) == 0u);
            TD_CHECK(st->fan_rpm[l] >= (float)app->p.fan_min_rpm);
            TD_CHECK(st->v_lead_kmh >= app->p.min_work_speed_kmh);
            TD_CHECK(st->target_rpm[l] > 0.0f);
        }
        if (!st->running) {
            TD_CHECK(out->fan_duty[l] == 0.0f);
        }
    }
    TD_CHECK(td_inv_finite_nonneg(st->v_kmh));
    TD_CHECK(td_inv_finite_nonneg(st->v_wheel_kmh));
    TD_CHECK(td_inv_finite_nonneg(st->v_gnss_kmh));
    TD_CHECK(td_inv_finite_nonneg(st->fan_target_rpm));
    TD_CHECK(isfinite(st->cv_pct) && (st->cv_pct >= 0.0f || st->cv_pct == -1.0f));
    TD_CHECK(st->uniform == (st->cv_pct >= 0.0f && st->cv_pct < app->p.cv_threshold_pct));
    TD_CHECK((st->faults & ~TD_INV_FAULT_BITS) == 0u);
    TD_CHECK((unsigned)st->source <= (unsigned)TD_SRC_FUSED);
    TD_CHECK(st->source != TD_SRC_FUSED || app->p.speed_mode == TD_MODE_FUSED);
    TD_CHECK((st->source == TD_SRC_NONE) == ((st->faults & TD_FAULT_NO_SPEED) != 0u));
    TD_CHECK(st->gnss_valid == ((st->faults & TD_FAULT_GNSS_LOST) == 0u));
    if (st->source == TD_SRC_NONE) {
        TD_CHECK(st->v_kmh == 0.0f);
    } else if (app->p.speed_mode == TD_MODE_FUSED) {
        TD_CHECK(st->v_kmh == st->v_fused_kmh);
    } else if (st->source == TD_SRC_GNSS) {
        TD_CHECK(st->v_kmh == st->v_gnss_kmh);
    } else if (app->p.slip_comp == TD_SLIP_OFF) {
        TD_CHECK(st->v_kmh == st->v_wheel_kmh);
    }
    /* the fused estimate and the look-ahead: finite, speeds >= 0, the scale in its bounds */
    TD_CHECK(td_inv_finite_nonneg(st->v_fused_kmh));
    TD_CHECK(isfinite(st->a_fused_ms2) && isfinite(st->slip_pct) && isfinite(st->innov_kmh));
    TD_CHECK(st->slip_pct >= -50.0f && st->slip_pct <= 75.0f);
    TD_CHECK(td_inv_finite_nonneg(st->speed_std_kmh));
    TD_CHECK(td_inv_finite_nonneg(st->v_edge_kmh));
    TD_CHECK(td_inv_finite_nonneg(st->v_lead_kmh));
    if (app->p.lead_meter_ms == 0u && app->p.lead_air_ms == 0u && app->p.lead_stop_ms == 0u) {
        TD_CHECK(st->v_lead_kmh == st->v_kmh);
    }
    for (unsigned i = 0u; i < 6u; i++) {
        TD_CHECK(isfinite(app->fused.p[i]));
    }
    TD_CHECK(app->fused.p[0] > 0.0f && app->fused.p[3] > 0.0f && app->fused.p[5] > 0.0f);
    for (unsigned l = 0u; l < TD_LAYERS; l++) {
        TD_CHECK(isfinite(st->drive_rpm_per_duty[l]) && st->drive_rpm_per_duty[l] > 0.0f);
    }
    TD_CHECK(app->tx_count <= TD_TXQ_LEN && app->tx_head < TD_TXQ_LEN);
    TD_CHECK(td_params_validate(&app->p) == TD_OK);
}

/** Refused: nothing but the counters and (for PcParamSet, its ack) the transmit queue changed. */
static inline void td_inv_check_untouched(const td_app_t *before, const td_app_t *app) {
    td_app_t after;
    memcpy(&after, app, sizeof after);
    after.cnt = before->cnt;
    memcpy(after.txq, before->txq, sizeof after.txq);
    after.tx_head = before->tx_head;
    after.tx_count = before->tx_count;
    TD_CHECK(memcmp(&after, before, sizeof after) == 0);
}

/**
 * After td_app_rx(app, f) returned rc, `before` being a copy of the app from just before: the
 * frame was either acted on (counted once in rx_ok, its values in force) or refused (counted in
 * exactly one rejection counter, nothing else changed); a PcParamSet was answered once.
 */
static inline void td_inv_check_rx(const td_app_t *before, const td_app_t *app, const td_can_frame_t *f, int rc) {
    const td_counters_t *b = &before->cnt;
    const td_counters_t *c = &app->cnt;
    const bool param = f->extended != 0u && f->id == TD_ID_PC_PARAM_SET;
    const bool command = f->extended != 0u && f->id == app->p.command_id;
    const bool gnss_time = f->extended != 0u && f->id == TD_ID_PC_GNSS_TIME;
    if (rc == TD_OK) {
        TD_CHECK(c->rx_ok == b->rx_ok + 1u);
        TD_CHECK(td_inv_rejections(c) == td_inv_rejections(b));
        TD_CHECK(param || command || gnss_time);
        TD_CHECK(!param || !before->st.running); /* parameters change only while stopped */
        if (gnss_time) {
            td_gnss_time_t gt;
            TD_CHECK(td_proto_decode_gnss_time(f, &gt) == TD_OK);
            TD_CHECK(app->have_seq && app->gnss_seq == gt.seq);
        } else if (command) {
            td_command_t cmd;
            TD_CHECK(td_proto_decode_command(f, &cmd) == TD_OK);
            TD_CHECK(app->st.rate_kg_ha[0] == cmd.rate_kg_ha[0] && app->st.rate_kg_ha[1] == cmd.rate_kg_ha[1]);
            TD_CHECK(app->st.fan_target_rpm == cmd.fan_rpm);
            TD_CHECK(app->st.running == cmd.start);
        } else {
            uint8_t id = 0u;
            float value = 0.0f;
            float in_force = -1.0f;
            TD_CHECK(td_proto_decode_param_set(f, &id, &value) == TD_OK);
            TD_CHECK(td_params_get(&app->p, id, &in_force) == TD_OK);
            TD_CHECK(fabsf(in_force - value) <= 0.5f + 1e-6f * fabsf(value)); /* integers round */
        }
    } else {
        TD_CHECK(rc < 0);
        TD_CHECK(c->rx_ok == b->rx_ok);
        TD_CHECK(td_inv_rejections(c) == td_inv_rejections(b) + 1u);
        td_inv_check_untouched(before, app);
    }
    TD_CHECK(app->tx_count <= TD_TXQ_LEN);
    TD_CHECK(c->tx_dropped + app->tx_count == b->tx_dropped + before->tx_count + (param ? 1u : 0u));
    TD_CHECK(td_params_validate(&app->p) == TD_OK);
}

#endif /* TD_INVARIANTS_H */
