/**
 * @file td_hil.c
 * @brief The HIL link (td_hil.h) on the codec generated from protocol/topdress_hil.dbc.
 */
#include "td_hil.h"

#include <stddef.h>
#include <string.h>
#include "td_common.h"
#include "td_hilcan.h"

#define DUTY_RAW_MAX 10000u

void td_hil_init(td_hil_t *h) {
    memset(h, 0, sizeof *h);
    td_ctr_init(&h->wheel, 16u, 0u);
    for (unsigned l = 0u; l < 2u; l++) {
        td_ctr_init(&h->meter[l], 16u, 0u);
        td_ctr_init(&h->fan[l], 8u, 0u);
    }
}

static void take_sensors(td_hil_t *h, const struct td_hilcan_hil_sensors_t *m) {
    if (!h->have_sensors) { /* the first pair sets the counters' origin */
        td_ctr_init(&h->wheel, 16u, m->hil_wheel_count);
        td_ctr_init(&h->meter[0], 16u, m->hil_upper_meter_count);
        td_ctr_init(&h->meter[1], 16u, m->hil_lower_meter_count);
        td_ctr_init(&h->fan[0], 8u, m->hil_upper_fan_count);
        td_ctr_init(&h->fan[1], 8u, m->hil_lower_fan_count);
        h->have_sensors = true;
    }
    /* the wheel and the tachometers only count up; the meters' quadrature counters both ways */
    (void)td_ctr_update_up(&h->wheel, m->hil_wheel_count);
    (void)td_ctr_update_signed(&h->meter[0], m->hil_upper_meter_count);
    (void)td_ctr_update_signed(&h->meter[1], m->hil_lower_meter_count);
    (void)td_ctr_update_up(&h->fan[0], m->hil_upper_fan_count);
    (void)td_ctr_update_up(&h->fan[1], m->hil_lower_fan_count);
    h->wheel_raw = m->hil_wheel_count;
    /* an edge time belongs to the count it made */
    h->edge_valid = h->staged_edge_valid && h->staged_edge_count == m->hil_wheel_count;
    h->edge_us = h->staged_edge_us;
    h->staged_edge_valid = false;
    h->fresh = true;
    h->step_due = h->tick == (uint8_t)TD_HIL_TICK_LOCKSTEP;
}

static void take_clock(td_hil_t *h, const struct td_hilcan_hil_clock_t *c) {
    if (h->tick == (uint8_t)TD_HIL_TICK_UNSET) {
        h->tick = (uint8_t)(c->hil_free_run != 0u ? TD_HIL_TICK_OWN : TD_HIL_TICK_LOCKSTEP);
    }
    if (h->tick == (uint8_t)TD_HIL_TICK_LOCKSTEP) {
        h->clock_us = c->hil_clock_time;
        h->seq = c->hil_seq;
    }
}

int td_hil_rx(td_hil_t *h, const td_can_frame_t *f) {
    if (f->extended == 0u ||
        (f->id != TD_HIL_ID_WHEEL_EDGE && f->id != TD_HIL_ID_SENSORS && f->id != TD_HIL_ID_CLOCK)) {
        return 0;
    }
    if (f->dlc != 8u) {
        h->rx_refused++;
        return TD_E_LENGTH;
    }
    h->rx_frames++;
    if (f->id == TD_HIL_ID_WHEEL_EDGE) {
        struct td_hilcan_hil_wheel_edge_t e;
        (void)td_hilcan_hil_wheel_edge_unpack(&e, f->data, 8u);
        h->staged_edge_us = e.hil_edge_time;
        h->staged_edge_count = e.hil_edge_count;
        h->staged_edge_valid = e.hil_edge_valid != 0u;
    } else if (f->id == TD_HIL_ID_CLOCK) {
        struct td_hilcan_hil_clock_t c;
        (void)td_hilcan_hil_clock_unpack(&c, f->data, 8u);
        take_clock(h, &c);
    } else {
        struct td_hilcan_hil_sensors_t s;
        (void)td_hilcan_hil_sensors_unpack(&s, f->data, 8u);
        take_sensors(h, &s);
    }
    return 1;
}

void td_hil_inputs(td_hil_t *h, td_io_in_t *in) {
    if (h->have_sensors && !h->fresh) {
        h->late_steps++;
    }
    h->fresh = false;
    h->step_due = false;
    in->wheel_count = h->wheel.total;
    in->meter_count[0] = h->meter[0].total;
    in->meter_count[1] = h->meter[1].total;
    in->fan_count[0] = h->fan[0].total;
    in->fan_count[1] = h->fan[1].total;
    in->wheel_edge_us = h->edge_valid ? h->edge_us : 0u;
    in->wheel_edge_valid = h->edge_valid ? 1u : 0u;
}

static uint16_t duty_raw(float d) {
    const float r = d * (float)DUTY_RAW_MAX + 0.5f;
    if (!(r >= 1.0f)) {
        return 0u;
    }
    return r >= (float)DUTY_RAW_MAX ? (uint16_t)DUTY_RAW_MAX : (uint16_t)r;
}

void td_hil_outputs(td_hil_t *h, uint32_t now_us, const td_io_out_t *out, uint32_t cost_us, td_can_frame_t frames[2]) {
    struct td_hilcan_hil_actuators_t a;
    a.hil_upper_meter_duty = duty_raw(out->meter_duty[0]);
    a.hil_lower_meter_duty = duty_raw(out->meter_duty[1]);
    a.hil_upper_fan_duty = duty_raw(out->fan_duty[0]);
    a.hil_lower_fan_duty = duty_raw(out->fan_duty[1]);
    a.hil_seq = h->seq;
    frames[0].id = TD_HIL_ID_ACTUATORS;
    frames[0].extended = 1u;
    frames[0].dlc = 8u;
    (void)td_hilcan_hil_actuators_pack(frames[0].data, &a, 8u);
    struct td_hilcan_hil_step_t s;
    s.hil_step_time = now_us;
    s.hil_seq = h->seq;
    s.hil_late_inputs = (uint8_t)h->late_steps;
    s.hil_step_cost = cost_us > 0xFFFFu ? (uint16_t)0xFFFFu : (uint16_t)cost_us;
    frames[1].id = TD_HIL_ID_STEP;
    frames[1].extended = 1u;
    frames[1].dlc = 8u;
    (void)td_hilcan_hil_step_pack(frames[1].data, &s, 8u);
    h->seq++;
}
