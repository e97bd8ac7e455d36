/**
 * @file td_app.c
 * @brief The ECU application: command decoding, dual speed selection, eq. 4 targets, motor and
 *        fan control, fail-safes and the periodic frames.
 */
#include "td_app.h"

#include <math.h>
#include <stddef.h>
#include <string.h>
#include "td_meter.h"
#include "td_slip.h"
#include "td_speedsel.h"

/* Fan PI trim around the feed-forward target/fan_rpm_at_full_duty (duty per rpm, per rpm*s). */
#define TD_FAN_KP 0.0001f
#define TD_FAN_KI 0.0001f
/* Wheel slower than this counts as "reads ~0" for the encoder fault. */
#define TD_ENC_FAULT_WHEEL_KMH 0.2f
/* Blocked meter: commanded above this, duty at least this, turning below this share of target. */
#define TD_BLOCKED_MIN_TARGET_RPM 1.0f
#define TD_BLOCKED_MIN_DUTY 0.3f
#define TD_BLOCKED_SPEED_SHARE 0.1f
/* Longest dt fed to the controllers: a late step must not inject a big integral jump. */
#define TD_MAX_DT_S 0.05f
#define TD_BACKWARD_LIMIT 0x80000000u
/* Longest dt the fused estimate predicts over in one step. */
#define TD_MAX_PREDICT_S 1.0f
/* Steady motion for slip learning: the paper's uniform motion (CV of queue G below its
 * threshold), |a| below this, faster than TD_LEARN_MIN_MS, for TD_STEADY_US. */
#define TD_STEADY_A_MS2 0.3f
#define TD_LEARN_MIN_MS 0.5f
#define TD_STEADY_US 1500000u
/* An accepted GNSS speed younger than this backs the estimate against a disagreeing wheel, and
 * lets the scale learn: one period of a 1 Hz receiver and its jitter (at 1 s exactly, the
 * previous fix was always just too old when the next one came, and a 1 Hz receiver never
 * taught the scale). */
#define TD_GNSS_BACKS_US 1500000u
/* A GNSS speed older than this (age + lag) is not applied. */
#define TD_GNSS_MAX_DELAY_US 10000000u
#define TD_KMH_PER_MS 3.6f
/* A fixed GnssLag is overruled when the learned lag differs by more than this, ms, and is
 * used again once within TD_LAG_AGREE_MS. */
#define TD_LAG_CONTRADICT_MS 300.0f
#define TD_LAG_AGREE_MS 200.0f
/* The first change's early lag may be this share of itself short of a filtered receiver's. */
#define TD_LAG_EARLY_SHORT 0.5f
#define TD_LAG_NONE 0xFFFFu
/* Eq. 5 compensation: the slip is taken within 0..50 %. */
#define TD_SLIP_MAX 0.5f

static uint32_t fwd_diff(uint32_t now_count, uint32_t then_count) {
    const uint32_t d = now_count - then_count;
    return d >= TD_BACKWARD_LIMIT ? 0u : d;
}

/* Metering drives (re)configured from the parameters: the learned slope restarts. */
static void config_drives(td_app_t *app) {
    const td_params_t *p = &app->p;
    for (unsigned l = 0u; l < TD_LAYERS; l++) {
        td_drive_config(&app->meter_drive[l], p->pid_kp, p->pid_ki, p->pid_kd, p->pid_kff,
                        (float)p->meter_tau_ms * 1.0e-3f, p->drive_adapt != 0u);
        app->fan_pid[l].kff = 1.0f / p->fan_rpm_at_full_duty;
    }
}

/* (Re)build the wheel estimator and queue G from the parameters: both restart empty. */
static void init_speed_chain(td_app_t *app) {
    (void)td_wheel_init(&app->wheel, app->p.wheel_radius_m, app->p.wheel_ppr, app->p.wheel_samples,
                        app->p.wheel_update_ms);
    (void)td_edge_init(&app->edge, app->p.wheel_radius_m, app->p.wheel_ppr, app->p.wheel_stop_ms);
    (void)td_speedq_init(&app->q, app->p.queue_len);
    app->st.cv_pct = -1.0f;
    app->st.uniform = false;
}

static void set_fault(td_app_t *app, uint16_t bit, bool on) {
    if (on) {
        app->st.faults |= bit;
    } else {
        app->st.faults &= (uint16_t)~bit;
    }
}

/* The wheel reads ~0 while a valid GNSS speed says the machine moves, and no encoder fault
 * has decided yet which of the two is wrong (a cut encoder cable or a frozen receiver). */
static bool speed_conflict(const td_app_t *app) {
    const td_state_t *st = &app->st;
    return st->gnss_valid && st->v_gnss_kmh > app->p.enc_fault_gnss_kmh && st->v_wheel_kmh < TD_ENC_FAULT_WHEEL_KMH &&
           (st->faults & TD_FAULT_WHEEL_ENCODER) == 0u;
}

static void decide_source(td_app_t *app) {
    td_state_t *st = &app->st;
    const td_speed_mode_t mode = (td_speed_mode_t)app->p.speed_mode;
    const bool gnss_usable = st->gnss_valid && (st->faults & TD_FAULT_GNSS_FROZEN) == 0u;
    st->source = td_speedsel_rule(mode, (td_compare_t)app->p.switch_compare, st->cv_pct, app->p.cv_threshold_pct,
                                  app->p.switch_speed_kmh, st->v_wheel_kmh, st->v_gnss_kmh, gnss_usable,
                                  (st->faults & TD_FAULT_WHEEL_ENCODER) == 0u);
    /* A standing wheel is "uniform" (CV 0): the dual rule alone would meter at a frozen GNSS
     * speed while the machine stands. Until the encoder check settles the conflict, the wheel. */
    if (st->source == TD_SRC_GNSS && mode == TD_MODE_DUAL && speed_conflict(app)) {
        st->source = TD_SRC_WHEEL;
    }
}

/* After the queue or the rule's parameters changed: CV and source from what queue G holds now. */
static void refresh_cv_and_source(td_app_t *app) {
    td_state_t *st = &app->st;
    st->cv_pct = td_speedq_cv_pct(&app->q, app->p.cv_window);
    st->uniform = st->cv_pct >= 0.0f && st->cv_pct < app->p.cv_threshold_pct;
    decide_source(app);
}

/* The GNSS lag in use: learned (GnssLagAuto 1, once learned), GnssLag (before, or fixed), or the
 * learned one again where the data contradict a fixed GnssLag (counted: lag_overruled). */
static void choose_lag(td_app_t *app) {
    td_state_t *st = &app->st;
    const td_lag_t *l = &app->lag;
    const float learned_ms = l->lag_s * 1000.0f;
    /* the lag is never negative, so adding a half rounds it */
    /* NOLINTNEXTLINE(bugprone-incorrect-roundings) */
    st->lag_learned_ms = l->learned ? (uint16_t)(learned_ms + 0.5f) : (uint16_t)TD_LAG_NONE;
    st->lag_evidence_s = l->evidence_s;
    st->lag_fit = l->fit;
    td_lag_state_t state;
    if (app->p.gnss_lag_auto != 0u) {
        state = l->learned ? TD_LAG_LEARNED : TD_LAG_START;
    } else if (!l->learned) {
        state = TD_LAG_FIXED;
    } else {
        /* the first change's early lag (before its area is in) comes out up to a third short
         * of a filtered receiver's: a fixed lag up to half as long again is not contradicted */
        const float off = learned_ms - (float)app->p.gnss_lag_ms;
        const float margin = st->lag_state == (uint8_t)TD_LAG_OVERRULED ? TD_LAG_AGREE_MS : TD_LAG_CONTRADICT_MS;
        const bool over = off > margin || -off > margin + (l->area ? 0.0f : TD_LAG_EARLY_SHORT * learned_ms);
        state = over ? TD_LAG_OVERRULED : TD_LAG_FIXED;
        if (over && st->lag_state != (uint8_t)TD_LAG_OVERRULED) {
            st->lag_overruled++;
        }
    }
    st->lag_state = (uint8_t)state;
    st->gnss_lag_ms = state == TD_LAG_LEARNED || state == TD_LAG_OVERRULED ? st->lag_learned_ms : app->p.gnss_lag_ms;
}

int td_app_init(td_app_t *app, const td_params_t *params, uint32_t now_us) {
    if (app == NULL || params == NULL) {
        return TD_E_ARG;
    }
    const int rc = td_params_validate(params);
    if (rc != TD_OK) {
        return rc;
    }
    memset(app, 0, sizeof *app);
    app->p = *params;
    for (unsigned l = 0u; l < TD_LAYERS; l++) {
        td_drive_init(&app->meter_drive[l], 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, false);
        td_pid_init(&app->fan_pid[l], TD_FAN_KP, TD_FAN_KI, 0.0f, 0.0f, 0.0f, 1.0f);
    }
    config_drives(app);
    init_speed_chain(app);
    (void)td_fused_init(&app->fused, app->p.fused_jerk_ms3, app->p.fused_gnss_std_kmh, app->p.fused_wheel_noise_pct);
    app->fused.slip_shape = app->p.slip_comp != (uint8_t)TD_SLIP_LEARNED;
    td_lag_init(&app->lag);
    choose_lag(app);
    app->st.drive_rpm_per_duty[TD_UPPER] = td_drive_rpm_per_duty(&app->meter_drive[TD_UPPER]);
    app->st.drive_rpm_per_duty[TD_LOWER] = td_drive_rpm_per_duty(&app->meter_drive[TD_LOWER]);
    app->last_step_us = now_us;
    app->last_cmd_us = now_us;
    app->last_gnss_us = now_us;
    app->last_status_us = now_us;
    app->start_us = now_us;
    app->st.source = TD_SRC_WHEEL;
    app->st.faults = TD_FAULT_GNSS_LOST;
    td_cal_init(&app->cal);
    app->ident.target = (uint8_t)TD_TARGET_HOST;
    app->ident.transport = (uint8_t)TD_TRANSPORT_IN_PROCESS;
    app->ident.reset_cause = (uint8_t)TD_RESET_UNKNOWN;
    app->ident_due = true;
    return TD_OK;
}

int td_app_set_ident(td_app_t *app, const td_ident_t *ident) {
    td_can_frame_t probe;
    if (app == NULL || td_proto_encode_ident(ident, false, &probe) != TD_OK) {
        return TD_E_ARG;
    }
    app->ident = *ident;
    app->ident_due = true;
    return TD_OK;
}

int td_app_announce(td_app_t *app) {
    if (app == NULL) {
        return TD_E_ARG;
    }
    app->ident_due = true;
    return TD_OK;
}

static void txq_push(td_app_t *app, const td_can_frame_t *f) {
    if (app->tx_count >= TD_TXQ_LEN) {
        app->cnt.tx_dropped++;
        return;
    }
    app->txq[(app->tx_head + app->tx_count) % TD_TXQ_LEN] = *f;
    app->tx_count++;
}

int td_app_tx_pop(td_app_t *app, td_can_frame_t *frame) {
    if (app == NULL || frame == NULL || app->tx_count == 0u) {
        return 0;
    }
    *frame = app->txq[app->tx_head];
    app->tx_head = (uint8_t)((app->tx_head + 1u) % TD_TXQ_LEN);
    app->tx_count--;
    return 1;
}

const td_state_t *td_app_state(const td_app_t *app) {
    return app == NULL ? NULL : &app->st;
}

/* Stop command: motors stop, controllers and fault timers restart, latched faults clear. */
static void stop(td_app_t *app) {
    app->st.running = false;
    app->st.faults &= (uint16_t)~TD_FAULT_LATCHED_MASK;
    app->enc_suspect = false;
    for (unsigned l = 0u; l < TD_LAYERS; l++) {
        app->blocked_suspect[l] = false;
        td_drive_reset(&app->meter_drive[l]);
        td_pid_reset(&app->fan_pid[l]);
    }
}

/* A received frame's decode result, counted in the rx counters; returns `rc`. */
static int count_rx(td_app_t *app, int rc) {
    if (rc == TD_OK) {
        app->cnt.rx_ok++;
    } else if (rc == TD_E_LENGTH) {
        app->cnt.rx_bad_length++;
    } else {
        app->cnt.rx_out_of_range++;
    }
    return rc;
}

static int apply_command(td_app_t *app, const td_can_frame_t *frame, uint32_t now_us) {
    td_command_t c;
    const int rc = count_rx(app, td_proto_decode_command(frame, &c));
    if (rc != TD_OK) {
        return rc;
    }
    /* a PC starts commanding (power-up, or back after a timeout): tell it who we are */
    if (!app->have_cmd || (app->st.faults & TD_FAULT_CMD_TIMEOUT) != 0u) {
        app->ident_due = true;
    }
    app->have_cmd = true;
    app->last_cmd_us = now_us;
    set_fault(app, TD_FAULT_CMD_TIMEOUT, false);
    td_state_t *st = &app->st;
    st->rate_kg_ha[TD_UPPER] = c.rate_kg_ha[TD_UPPER];
    st->rate_kg_ha[TD_LOWER] = c.rate_kg_ha[TD_LOWER];
    st->fan_target_rpm = c.fan_rpm;
    if (c.gnss_valid) {
        if (c.gnss_kmh != st->v_gnss_kmh) {
            app->gnss_moved = true;
        }
        st->v_gnss_kmh = c.gnss_kmh;
        app->have_gnss = true;
        app->last_gnss_us = now_us;
        /* a PC without PcGnssTime: the command's speed goes to the estimate as if fresh. One
         * that speaks it gives its fixes there only: when its fixes stop (an outage) it still
         * repeats the last speed in its commands until that is stale, and those are no fixes */
        if (!app->have_gnss_time) {
            app->gnss_pend = true;
            app->gnss_pend_ms = c.gnss_kmh / TD_KMH_PER_MS;
            app->gnss_pend_us = now_us;
        }
    } else {
        /* 0xFF: the PC says it has no GNSS speed; do not wait for the stale timeout */
        app->have_gnss = false;
    }
    if (c.start && !st->running) {
        st->running = true;
        app->start_us = now_us;
        app->spun_up = false;
    } else if (!c.start) {
        const bool had_latched = (st->faults & TD_FAULT_LATCHED_MASK) != 0u;
        stop(app);
        if (had_latched) {
            decide_source(app);
        }
    }
    return TD_OK;
}

/* PcGnssTime: the GNSS speed with its age; a new GnssSeq is applied at the next step. */
static int apply_gnss_time(td_app_t *app, const td_can_frame_t *frame, uint32_t now_us) {
    td_gnss_time_t g;
    const int rc = count_rx(app, td_proto_decode_gnss_time(frame, &g));
    if (rc != TD_OK) {
        return rc;
    }
    app->have_gnss_time = true;
    if (g.valid && !(app->have_seq && g.seq == app->gnss_seq)) {
        app->gnss_pend = true;
        app->gnss_pend_ms = g.speed_kmh / TD_KMH_PER_MS;
        app->gnss_pend_us = now_us - (uint32_t)g.age_ms * 1000u;
    }
    app->gnss_seq = g.seq;
    app->have_seq = true;
    return TD_OK;
}

static int apply_param_set(td_app_t *app, const td_can_frame_t *frame) {
    td_param_ack_t ack = { 0u, 0u, 0u };
    uint8_t id = 0u;
    float value = 0.0f;
    int rc = td_proto_decode_param_set(frame, &id, &value);
    if (rc == TD_E_LENGTH) {
        ack.param_id = frame->dlc > 0u ? frame->data[0] : 0u;
        ack.result = (uint8_t)TD_ACK_BAD_FRAME;
        app->cnt.rx_bad_length++;
    } else {
        ack.param_id = frame->data[0];
        if (rc == TD_OK) {
            id = frame->data[0];
            rc = app->st.running ? TD_E_BUSY : td_params_set(&app->p, id, value);
        }
        switch (rc) {
        case TD_OK:
            ack.result = (uint8_t)TD_ACK_OK;
            app->params_taken = true; /* EcuIdent says so from now on (OnDefaults 0) */
            break;
        case TD_E_UNKNOWN_PARAM:
            ack.result = (uint8_t)TD_ACK_UNKNOWN_PARAM;
            break;
        case TD_E_RANGE:
            ack.result = (uint8_t)TD_ACK_OUT_OF_RANGE;
            break;
        case TD_E_BUSY:
            ack.result = (uint8_t)TD_ACK_BUSY;
            break;
        default:
            ack.result = (uint8_t)TD_ACK_INCONSISTENT;
            break;
        }
        float in_force = 0.0f;
        if (td_params_get(&app->p, ack.param_id, &in_force) == TD_OK) {
            ack.raw = td_proto_param_raw(ack.param_id, in_force);
        }
        if (rc == TD_OK) {
            app->cnt.rx_ok++;
            /* PID gains, drive adaptation, drive model: the drives restart their learning */
            if ((id >= 12u && id <= 15u) || id == 36u || id == 37u) {
                config_drives(app);
            }
            /* radius, ppr, N, update period, samples, stop time: the estimators and queue G restart */
            if (id == 4u || id == 5u || id == 6u || id == 19u || id == 20u || id == 35u) {
                init_speed_chain(app);
            }
            td_fused_tune(&app->fused, app->p.fused_jerk_ms3, app->p.fused_gnss_std_kmh, app->p.fused_wheel_noise_pct);
            app->fused.slip_shape = app->p.slip_comp != (uint8_t)TD_SLIP_LEARNED;
            choose_lag(app); /* GnssLag, GnssLagAuto: the learned lag is kept */
            /* n, threshold, switch speed, mode, compare act at once, not at the next wheel update */
            refresh_cv_and_source(app);
        } else {
            app->cnt.rx_param_rejected++;
        }
    }
    td_can_frame_t out;
    (void)td_proto_encode_param_ack(&ack, &out);
    txq_push(app, &out);
    return rc;
}

int td_app_rx(td_app_t *app, const td_can_frame_t *frame, uint32_t now_us) {
    if (app == NULL || frame == NULL) {
        return TD_E_ARG;
    }
    if (frame->extended != 0u) {
        if (frame->id == TD_ID_PC_CAL_COMMAND) {
            return count_rx(app, td_cal_rx(&app->cal, frame, app->st.running, now_us));
        }
        if (frame->id == app->p.command_id) {
            return apply_command(app, frame, now_us);
        }
        if (frame->id == TD_ID_PC_PARAM_SET) {
            return apply_param_set(app, frame);
        }
        if (frame->id == TD_ID_PC_GNSS_TIME) {
            return apply_gnss_time(app, frame, now_us);
        }
    }
    app->cnt.rx_unknown_id++;
    return TD_E_UNKNOWN_ID;
}

/* Metering and fan speeds over the last TD_RATE_WINDOW steps of counts. */
static void measure_rates(td_app_t *app, uint32_t now_us, const td_io_in_t *in) {
    const uint8_t oldest = app->hist_count < TD_RATE_WINDOW ? 0u : app->hist_head;
    if (app->hist_count > 0u) {
        const uint32_t span_us = td_elapsed_us(now_us, app->time_hist[oldest]);
        if (span_us > 0u) {
            const float per_min = 60.0e6f / (float)span_us;
            for (unsigned l = 0u; l < TD_LAYERS; l++) {
                app->st.meter_rpm[l] = (float)fwd_diff(in->meter_count[l], app->meter_hist[oldest][l]) * per_min /
                                       (float)app->p.meter_counts_per_rev;
                app->st.fan_rpm[l] =
                    (float)fwd_diff(in->fan_count[l], app->fan_hist[oldest][l]) * per_min / (float)app->p.fan_ppr;
            }
        }
    }
    for (unsigned l = 0u; l < TD_LAYERS; l++) {
        app->meter_hist[app->hist_head][l] = in->meter_count[l];
        app->fan_hist[app->hist_head][l] = in->fan_count[l];
    }
    app->time_hist[app->hist_head] = now_us;
    app->hist_head = (uint8_t)((app->hist_head + 1u) % TD_RATE_WINDOW);
    if (app->hist_count < TD_RATE_WINDOW) {
        app->hist_count++;
    }
}

static void update_wheel(td_app_t *app, uint32_t now_us, uint32_t wheel_count) {
    td_state_t *st = &app->st;
    if (app->stepped) {
        st->wheel_pulses += fwd_diff(wheel_count, app->wheel_last_count);
    }
    app->wheel_last_count = wheel_count;
    float v;
    if (td_wheel_step(&app->wheel, now_us, wheel_count, &v)) {
        st->v_wheel_kmh = v;
        td_speedq_push(&app->q, v);
        st->cv_pct = td_speedq_cv_pct(&app->q, app->p.cv_window);
        st->uniform = st->cv_pct >= 0.0f && st->cv_pct < app->p.cv_threshold_pct;
        st->wheel_updates++;
        decide_source(app);
    }
}

/* The wheel speed corrected for slip as parameter SlipComp says (modes dual, wheel, GNSS). */
static float wheel_compensated_kmh(const td_app_t *app, float v_kmh) {
    if (app->p.slip_comp == (uint8_t)TD_SLIP_LEARNED) {
        return v_kmh / app->fused.scale;
    }
    if (app->p.slip_comp == (uint8_t)TD_SLIP_MODEL) {
        /* eq. 5 is slip against true speed: two fixed-point passes from the wheel speed */
        float v = v_kmh;
        for (unsigned i = 0u; i < 2u; i++) {
            float slip = td_slip_model_pct(v) * 0.01f;
            slip = slip < 0.0f ? 0.0f : (slip > TD_SLIP_MAX ? TD_SLIP_MAX : slip);
            v = v_kmh / (1.0f - slip);
        }
        return v;
    }
    return v_kmh;
}

/* The fused estimate: edge-timed wheel at every step, GNSS at its time of validity, the
 * scale learned while GNSS is good and the motion steady. Runs in every mode. */
static void update_fused(td_app_t *app, uint32_t now_us, const td_io_in_t *in, uint32_t dt_us) {
    td_state_t *st = &app->st;
    td_fused_t *f = &app->fused;
    td_edge_t *e = &app->edge;
    const float v_edge = td_edge_step(e, now_us, in->wheel_count, in->wheel_edge_us, in->wheel_edge_valid != 0u);
    st->edge_timing = in->wheel_edge_valid != 0u;
    st->v_edge_kmh = v_edge * TD_KMH_PER_MS;
    const float dt_raw_s = (float)dt_us * 1.0e-6f;
    const float dt_s = dt_raw_s > TD_MAX_PREDICT_S ? TD_MAX_PREDICT_S : dt_raw_s;
    td_fused_predict(f, dt_s);

    const bool wheel_ok = (st->faults & TD_FAULT_WHEEL_ENCODER) == 0u;
    const float v_hist = wheel_ok && e->started ? v_edge : -1.0f; /* < 0: no wheel */
    td_fused_record(f, v_hist, dt_s);
    td_lag_wheel(&app->lag, v_hist, dt_s);
    const bool gnss_ok = st->gnss_valid && (st->faults & TD_FAULT_GNSS_FROZEN) == 0u;
    const bool backs = gnss_ok && app->have_fused && td_age_us(now_us, app->gnss_fused_us) < TD_GNSS_BACKS_US;
    /* the paper's own test of uniform motion (the wheel's CV): the estimate's acceleration alone
     * would not do, as an unlearned scale shows up in it */
    if (st->uniform && fabsf(f->a_ms2) < TD_STEADY_A_MS2 && f->v_ms > TD_LEARN_MIN_MS) {
        if (!app->steady) {
            app->steady = true;
            app->steady_since_us = now_us;
        }
    } else {
        app->steady = false;
    }
    st->slip_learning =
        wheel_ok && backs && app->steady && td_elapsed_us(now_us, app->steady_since_us) >= TD_STEADY_US;

    if (wheel_ok && e->started) {
        if (!e->moving) {
            if (f->wheel_rejects == 0u) {
                td_fused_standstill(f);
            }
        } else {
            float r_extra = 0.0f;
            if (e->span_s <= 0.0f) {
                r_extra = 0.25f * v_edge * v_edge; /* a bound while slowing, not a period */
            } else if (!e->timed) {
                const float q = e->m_per_pulse / e->span_s; /* one pulse of quantization */
                r_extra = q * q / 6.0f;
            }
            if (td_fused_wheel(f, v_edge, r_extra, false, backs) != TD_FUSED_ACCEPTED) {
                st->wheel_rejected++;
            }
        }
    }
    if (app->gnss_pend) {
        app->gnss_pend = false;
        const uint32_t age_us = td_age_us(now_us, app->gnss_pend_us);
        /* the lag is learned from this fix first and used for it at once */
        if (gnss_ok && td_lag_fix(&app->lag, f, app->gnss_pend_ms, (float)age_us * 1.0e-6f)) {
            choose_lag(app);
        }
        const uint32_t delay_us = age_us + (uint32_t)st->gnss_lag_ms * 1000u;
        if (gnss_ok && delay_us <= TD_GNSS_MAX_DELAY_US) {
            st->gnss_delay_ms = (uint16_t)(delay_us / 1000u);
            if (td_fused_gnss(f, app->gnss_pend_ms, (float)delay_us * 1.0e-6f, st->slip_learning) ==
                TD_FUSED_ACCEPTED) {
                app->gnss_fused_us = now_us;
                app->have_fused = true;
                st->gnss_fixes++;
            } else {
                st->gnss_rejected++;
            }
            st->innov_kmh = f->innov_ms * TD_KMH_PER_MS;
        }
    }
    st->gnss_fused = app->have_fused && gnss_ok &&
                     td_age_us(now_us, app->gnss_fused_us) <= (uint32_t)app->p.gnss_timeout_ms * 1000u;
    st->v_fused_kmh = f->v_ms * TD_KMH_PER_MS;
    st->a_fused_ms2 = f->a_ms2;
    st->slip_pct = (1.0f - f->scale * td_fused_shape(f, f->v_ms, NULL)) * 100.0f;
    st->speed_std_kmh = td_fused_speed_std_ms(f) * TD_KMH_PER_MS;
}

/* The speed that drives eq. 4 now (v_kmh) and at landing (v_lead_kmh). */
static void select_speed(td_app_t *app) {
    td_state_t *st = &app->st;
    if (st->source == TD_SRC_NONE) {
        st->v_kmh = 0.0f;
    } else if (app->p.speed_mode == (uint8_t)TD_MODE_FUSED) {
        st->v_kmh = st->v_fused_kmh;
    } else if (st->source == TD_SRC_GNSS) {
        st->v_kmh = st->v_gnss_kmh;
    } else {
        st->v_kmh = wheel_compensated_kmh(app, st->v_wheel_kmh);
    }
    /* the estimate's acceleration without its bounce noise; a falling speed (slowing, the
     * stop) looks ahead by LeadStop, as the meters' run-down and the stop take longer to
     * land than a start (docs/speed.md) */
    const float a = td_fused_lead_accel_ms2(&app->fused);
    const uint32_t rise_ms = (uint32_t)app->p.lead_meter_ms + app->p.lead_air_ms;
    const uint32_t lead_ms = a < 0.0f && app->p.lead_stop_ms > 0u ? app->p.lead_stop_ms : rise_ms;
    if (lead_ms > 0u && st->v_kmh > 0.0f) {
        const float v = st->v_kmh + a * (float)lead_ms * 1.0e-3f * TD_KMH_PER_MS;
        st->v_lead_kmh = v > 0.0f ? v : 0.0f;
    } else {
        st->v_lead_kmh = st->v_kmh;
    }
}

/* The wheel reads ~0 while GNSS says we move, for longer than enc_fault_time_ms. If the GNSS
 * value changed meanwhile, the receiver is alive and the encoder is broken: WHEEL_ENCODER,
 * latched until a stop. If it never changed, the receiver is as likely frozen while the
 * machine stands: GNSS_FROZEN, GNSS not used, the meters stay stopped on the wheel. */
static void check_encoder(td_app_t *app, uint32_t now_us) {
    td_state_t *st = &app->st;
    const uint16_t before = st->faults;
    if (!(st->running && speed_conflict(app))) {
        app->enc_suspect = false;
        set_fault(app, TD_FAULT_GNSS_FROZEN, false);
    } else if (!app->enc_suspect) {
        app->enc_suspect = true;
        app->enc_fault_since_us = now_us;
        app->gnss_moved = false;
    } else if (td_elapsed_us(now_us, app->enc_fault_since_us) > (uint32_t)app->p.enc_fault_time_ms * 1000u) {
        if (app->gnss_moved) {
            st->faults |= TD_FAULT_WHEEL_ENCODER;
            set_fault(app, TD_FAULT_GNSS_FROZEN, false);
        } else {
            st->faults |= TD_FAULT_GNSS_FROZEN;
        }
    }
    if (st->faults != before) {
        decide_source(app);
    }
}

static void control_fans(td_app_t *app, uint32_t now_us, float dt_s, td_io_out_t *out) {
    td_state_t *st = &app->st;
    /* latched: after 71.6 min of running the wrapped clock must not reopen the grace */
    if (st->running && td_age_us(now_us, app->start_us) > (uint32_t)app->p.fan_spinup_ms * 1000u) {
        app->spun_up = true;
    }
    const bool spun_up = app->spun_up;
    const float target = st->running ? st->fan_target_rpm : 0.0f;
    for (unsigned l = 0u; l < TD_LAYERS; l++) {
        if (target > 0.0f) {
            if (dt_s > 0.0f) { /* a repeated timestamp holds the duty: nothing to integrate */
                st->fan_duty[l] = td_pid_step(&app->fan_pid[l], target, st->fan_rpm[l], dt_s);
            }
        } else {
            td_pid_reset(&app->fan_pid[l]);
            st->fan_duty[l] = 0.0f;
        }
        const bool low = st->fan_rpm[l] < (float)app->p.fan_min_rpm;
        set_fault(app, (uint16_t)(TD_FAULT_UPPER_FAN_LOW << l), st->running && spun_up && low);
        out->fan_duty[l] = st->fan_duty[l];
    }
}

static void check_blocked(td_app_t *app, unsigned l, uint32_t now_us) {
    td_state_t *st = &app->st;
    const bool suspect = st->target_rpm[l] > TD_BLOCKED_MIN_TARGET_RPM && st->meter_duty[l] >= TD_BLOCKED_MIN_DUTY &&
                         st->meter_rpm[l] < TD_BLOCKED_SPEED_SHARE * st->target_rpm[l];
    if (!suspect) {
        app->blocked_suspect[l] = false;
        return;
    }
    if (!app->blocked_suspect[l]) {
        app->blocked_suspect[l] = true;
        app->blocked_since_us[l] = now_us;
    } else if (td_elapsed_us(now_us, app->blocked_since_us[l]) > (uint32_t)app->p.blocked_time_ms * 1000u) {
        st->faults |= (uint16_t)(TD_FAULT_UPPER_BLOCKED << l);
        app->blocked_suspect[l] = false;
        td_drive_reset(&app->meter_drive[l]);
        st->meter_duty[l] = 0.0f;
        st->target_rpm[l] = 0.0f;
    }
}

static void control_meters(td_app_t *app, uint32_t now_us, float dt_s, td_io_out_t *out) {
    td_state_t *st = &app->st;
    /* with look-ahead the meters stop once the speed predicted at landing reaches a stop */
    const bool may_meter = st->running && (st->faults & (TD_FAULT_CMD_TIMEOUT | TD_FAULT_NO_SPEED)) == 0u &&
                           st->v_lead_kmh >= app->p.min_work_speed_kmh;
    for (unsigned l = 0u; l < TD_LAYERS; l++) {
        const bool allowed = may_meter && st->fan_rpm[l] >= (float)app->p.fan_min_rpm &&
                             (st->faults & (uint16_t)(TD_FAULT_UPPER_BLOCKED << l)) == 0u;
        st->target_rpm[l] = allowed ? td_meter_target_rpm(app->p.working_width_m, st->rate_kg_ha[l], st->v_lead_kmh,
                                                          app->p.kg_per_rev[l], app->p.min_work_speed_kmh)
                                    : 0.0f;
        if (st->target_rpm[l] > 0.0f) {
            if (dt_s > 0.0f) { /* a repeated timestamp holds the duty: nothing to integrate */
                st->meter_duty[l] = td_drive_step(&app->meter_drive[l], st->target_rpm[l], st->meter_rpm[l], dt_s);
                st->drive_rpm_per_duty[l] = td_drive_rpm_per_duty(&app->meter_drive[l]);
            }
            check_blocked(app, l, now_us);
        } else {
            td_drive_reset(&app->meter_drive[l]);
            st->meter_duty[l] = 0.0f;
            app->blocked_suspect[l] = false;
        }
        out->meter_duty[l] = st->meter_duty[l];
    }
}

static uint16_t sat16(uint32_t v) {
    return v > 0xFFFFu ? (uint16_t)0xFFFFu : (uint16_t)v;
}

static void emit_status(td_app_t *app) {
    const td_state_t *st = &app->st;
    td_can_frame_t f;
    const td_status_t s = { st->running,
                            { st->meter_rpm[TD_UPPER], st->meter_rpm[TD_LOWER] },
                            { st->fan_rpm[TD_UPPER], st->fan_rpm[TD_LOWER] },
                            st->v_wheel_kmh };
    (void)td_proto_encode_status(&s, &f);
    f.id = app->p.status_id;
    txq_push(app, &f);
    const td_diag_t d = { (uint8_t)st->source, app->p.speed_mode, st->gnss_valid, st->uniform,
                          app->p.switch_compare, st->cv_pct, st->faults, st->wheel_pulses };
    (void)td_proto_encode_diag(&d, &f);
    txq_push(app, &f);
    const uint32_t rejected =
        app->cnt.rx_unknown_id + app->cnt.rx_bad_length + app->cnt.rx_out_of_range + app->cnt.rx_param_rejected;
    const td_speeds_t sp = { st->v_wheel_kmh, st->gnss_valid ? st->v_gnss_kmh : -1.0f, st->v_kmh, sat16(rejected) };
    (void)td_proto_encode_speeds(&sp, &f);
    txq_push(app, &f);
    const td_targets_t t = { { st->target_rpm[TD_UPPER], st->target_rpm[TD_LOWER] },
                             { st->meter_duty[TD_UPPER] * 100.0f, st->meter_duty[TD_LOWER] * 100.0f },
                             { st->fan_duty[TD_UPPER] * 100.0f, st->fan_duty[TD_LOWER] * 100.0f } };
    (void)td_proto_encode_targets(&t, &f);
    txq_push(app, &f);
    const td_fused_diag_t fd = { st->v_fused_kmh, st->a_fused_ms2,  st->slip_pct,    st->innov_kmh,
                                 st->slip_learning, st->edge_timing, st->gnss_fused, st->speed_std_kmh };
    (void)td_proto_encode_fused(&fd, &f);
    txq_push(app, &f);
    const td_fused_aux_t fa = { st->v_edge_kmh,
                                st->v_lead_kmh,
                                { st->drive_rpm_per_duty[TD_UPPER], st->drive_rpm_per_duty[TD_LOWER] },
                                st->gnss_delay_ms };
    (void)td_proto_encode_fused_aux(&fa, &f);
    txq_push(app, &f);
    const td_gnss_lag_t gl = { st->gnss_lag_ms, st->lag_learned_ms, st->lag_evidence_s,
                               st->lag_fit,     st->lag_state,      app->p.gnss_lag_auto != 0u };
    (void)td_proto_encode_gnss_lag(&gl, &f);
    txq_push(app, &f);
}

int td_app_step(td_app_t *app, uint32_t now_us, const td_io_in_t *in, td_io_out_t *out) {
    if (app == NULL || in == NULL || out == NULL) {
        return TD_E_ARG;
    }
    td_state_t *st = &app->st;
    const uint32_t dt_us = td_elapsed_us(now_us, app->last_step_us);
    float dt_s = (float)dt_us * 1.0e-6f;
    if (dt_s > TD_MAX_DT_S) {
        dt_s = TD_MAX_DT_S;
    }
    app->last_step_us = now_us;

    update_wheel(app, now_us, in->wheel_count);
    measure_rates(app, now_us, in);
    app->stepped = true;

    /* command timeout: strictly longer than cmd_timeout_ms without a valid PcCommand */
    if (td_age_us(now_us, app->last_cmd_us) > (uint32_t)app->p.cmd_timeout_ms * 1000u) {
        st->faults |= TD_FAULT_CMD_TIMEOUT;
        app->have_gnss_time = false; /* the PC is gone: the next may not speak PcGnssTime */
    }
    /* GNSS: missing (0xFF) or stale; a stale value is dropped for good, so that the clock
     * wrapping 71.6 min later cannot make it fresh again; re-decide at once when it comes or goes */
    if (app->have_gnss && td_age_us(now_us, app->last_gnss_us) > (uint32_t)app->p.gnss_timeout_ms * 1000u) {
        app->have_gnss = false;
    }
    const bool gnss_valid = app->have_gnss;
    set_fault(app, TD_FAULT_GNSS_LOST, !gnss_valid);
    if (gnss_valid != st->gnss_valid) {
        st->gnss_valid = gnss_valid;
        decide_source(app);
    }
    check_encoder(app, now_us);

    set_fault(app, TD_FAULT_NO_SPEED, st->source == TD_SRC_NONE);
    update_fused(app, now_us, in, dt_us);
    select_speed(app);

    /* also on a repeated timestamp: a stop or a fault between two steps of the same time
     * must still zero the outputs it gates */
    control_fans(app, now_us, dt_s, out);
    control_meters(app, now_us, dt_s, out);
    const td_cal_io_t cal_io = { st->running, st->v_wheel_kmh, { in->meter_count[TD_UPPER], in->meter_count[TD_LOWER] },
                                 { st->meter_rpm[TD_UPPER], st->meter_rpm[TD_LOWER] } };
    td_can_frame_t cal_status;
    if (td_cal_step(&app->cal, now_us, dt_s, &app->p, &cal_io, out, &cal_status) > 0) {
        txq_push(app, &cal_status);
    }

    const uint32_t period_us = (uint32_t)app->p.status_period_ms * 1000u;
    if (td_elapsed_us(now_us, app->last_status_us) >= period_us) {
        emit_status(app);
        /* keep the period on its grid; after a long gap restart it from now */
        app->last_status_us += period_us;
        if (td_elapsed_us(now_us, app->last_status_us) >= period_us) {
            app->last_status_us = now_us;
        }
    }
    if (app->ident_due) {
        td_can_frame_t f;
        (void)td_proto_encode_ident(&app->ident, !app->params_taken, &f);
        txq_push(app, &f);
        app->ident_due = false;
    }
    return TD_OK;
}
