/**
 * @file td_cal.c
 * @brief Metering catch test (see td_cal.h).
 */
#include "td_cal.h"

#include <stddef.h>
#include "td_can.h"
#include "td_common.h"

/* A meter turning below this share of its speed, with the duty at least this, is not turning. */
#define TD_CAL_SLOW_SHARE 0.1f
#define TD_CAL_SLOW_MIN_DUTY 0.3f

void td_cal_init(td_cal_t *cal) {
    if (cal == NULL) {
        return;
    }
    cal->state = TD_CAL_IDLE;
    cal->layer = 0u;
    cal->reason = TD_CAL_R_NONE;
    cal->seq = 0u;
    cal->target_rev = 0.0f;
    cal->speed_rpm = 0.0f;
    cal->done_rev = 0.0f;
    cal->meter_rpm = 0.0f;
    cal->start_count = 0u;
    cal->start_us = 0u;
    cal->last_status_us = 0u;
    cal->slow_since_us = 0u;
    cal->counting = false;
    cal->slow = false;
    cal->announce = false;
    cal->with_fans = false;
    td_pid_init(&cal->pid, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 1.0f);
}

bool td_cal_active(const td_cal_t *cal) {
    return cal != NULL && cal->state == TD_CAL_RUNNING;
}

static void finish(td_cal_t *cal, uint8_t state, uint8_t reason) {
    cal->state = state;
    cal->reason = reason;
    cal->announce = true;
    td_pid_reset(&cal->pid);
}

int td_cal_rx(td_cal_t *cal, const td_can_frame_t *frame, bool running, uint32_t now_us) {
    if (cal == NULL || frame == NULL) {
        return TD_E_ARG;
    }
    if (frame->dlc != TD_CAN_PC_CAL_COMMAND_LENGTH) {
        return TD_E_LENGTH;
    }
    struct td_can_pc_cal_command_t m;
    (void)td_can_pc_cal_command_unpack(&m, frame->data, frame->dlc);
    if (!td_can_pc_cal_command_cal_action_is_in_range(m.cal_action) ||
        !td_can_pc_cal_command_cal_layer_is_in_range(m.cal_layer)) {
        return TD_E_RANGE;
    }
    cal->seq = m.cal_seq;
    if (m.cal_action == TD_CAN_PC_CAL_COMMAND_CAL_ACTION_RESET_CHOICE) {
        if (cal->state == TD_CAL_RUNNING) {
            finish(cal, TD_CAL_ABORTED, TD_CAL_R_RESET);
        } else {
            cal->state = TD_CAL_IDLE;
            cal->reason = TD_CAL_R_NONE;
            cal->announce = true; /* one frame saying idle, then silence */
        }
        return TD_OK;
    }
    const float rev = td_can_pc_cal_command_cal_revolutions_decode(m.cal_revolutions);
    const float rpm = td_can_pc_cal_command_cal_meter_speed_decode(m.cal_meter_speed);
    cal->layer = m.cal_layer;
    cal->target_rev = rev;
    cal->speed_rpm = rpm;
    cal->done_rev = 0.0f;
    cal->counting = false;
    cal->slow = false;
    cal->start_us = now_us;
    cal->with_fans = m.cal_action == TD_CAN_PC_CAL_COMMAND_CAL_ACTION_LEAD_TEST_CHOICE;
    if (running && !cal->with_fans) {
        finish(cal, TD_CAL_ABORTED, TD_CAL_R_RUNNING);
    } else if (!running && cal->with_fans) {
        finish(cal, TD_CAL_ABORTED, TD_CAL_R_FANS_OFF);
    } else if (rev <= 0.0f || rev > TD_CAL_MAX_REV || rpm < TD_CAL_MIN_RPM || rpm > TD_CAL_MAX_RPM) {
        finish(cal, TD_CAL_ABORTED, TD_CAL_R_BAD_VALUE);
    } else {
        cal->state = TD_CAL_RUNNING;
        cal->reason = TD_CAL_R_NONE;
        cal->announce = true;
        td_pid_reset(&cal->pid);
    }
    return TD_OK;
}

static void encode_status(const td_cal_t *cal, td_can_frame_t *f) {
    struct td_can_ecu_cal_status_t m;
    (void)td_can_ecu_cal_status_init(&m);
    m.cal_state = cal->state;
    m.cal_layer = cal->layer;
    m.cal_reason = cal->reason;
    const float rev = cal->done_rev < 0.0f ? 0.0f : (cal->done_rev > 16777.0f ? 16777.0f : cal->done_rev);
    m.cal_revolutions = (uint32_t)(rev * 1000.0f + 0.5f);
    const float rpm = cal->meter_rpm < 0.0f ? 0.0f : (cal->meter_rpm > 655.0f ? 655.0f : cal->meter_rpm);
    m.cal_meter_speed = (uint16_t)(rpm * 100.0f + 0.5f);
    m.cal_seq = cal->seq;
    f->id = TD_ID_ECU_CAL_STATUS;
    f->extended = 1u;
    f->dlc = TD_CAN_ECU_CAL_STATUS_LENGTH;
    (void)td_can_ecu_cal_status_pack(f->data, &m, sizeof f->data);
}

/* The abort conditions of a running test; the first that holds ends it. */
static void check_running(td_cal_t *cal, uint32_t now_us, const td_params_t *p, const td_cal_io_t *io, float duty) {
    const float budget_s = 2.0f * 60.0f * cal->target_rev / cal->speed_rpm + TD_CAL_SLACK_S;
    const bool slow = duty >= TD_CAL_SLOW_MIN_DUTY && cal->meter_rpm < TD_CAL_SLOW_SHARE * cal->speed_rpm;
    if (!slow) {
        cal->slow = false;
    } else if (!cal->slow) {
        cal->slow = true;
        cal->slow_since_us = now_us;
    }
    if (io->running && !cal->with_fans) {
        finish(cal, TD_CAL_ABORTED, TD_CAL_R_RUNNING);
    } else if (!io->running && cal->with_fans) {
        finish(cal, TD_CAL_ABORTED, TD_CAL_R_FANS_OFF);
    } else if (io->v_wheel_kmh > TD_CAL_MAX_WHEEL_KMH) {
        finish(cal, TD_CAL_ABORTED, TD_CAL_R_MOVING);
    } else if (cal->slow && td_elapsed_us(now_us, cal->slow_since_us) > (uint32_t)p->blocked_time_ms * 1000u) {
        finish(cal, TD_CAL_ABORTED, TD_CAL_R_BLOCKED);
    } else if ((float)td_elapsed_us(now_us, cal->start_us) * 1.0e-6f > budget_s) {
        finish(cal, TD_CAL_ABORTED, TD_CAL_R_TIMEOUT);
    } else if (cal->done_rev >= cal->target_rev) {
        finish(cal, TD_CAL_DONE, TD_CAL_R_NONE);
    }
}

int td_cal_step(td_cal_t *cal, uint32_t now_us, float dt_s, const td_params_t *p, const td_cal_io_t *io,
                td_io_out_t *out, td_can_frame_t *status) {
    if (cal == NULL || p == NULL || io == NULL || out == NULL || status == NULL || cal->state == TD_CAL_IDLE) {
        if (cal != NULL && status != NULL && cal->announce) {
            cal->announce = false;
            encode_status(cal, status);
            return 1;
        }
        return 0;
    }
    const unsigned l = cal->layer;
    const uint32_t count = io->meter_count[l];
    if (!cal->counting) {
        cal->counting = true;
        cal->start_count = count;
    }
    /* Counted on after the end too: the shaft coasts, and what it turns falls into the bag. */
    const uint32_t d = count - cal->start_count;
    if (d < 0x80000000u) {
        cal->done_rev = (float)d / (float)p->meter_counts_per_rev;
    }
    cal->meter_rpm = io->meter_rpm[l];
    if (cal->state == TD_CAL_RUNNING) {
        cal->pid.kp = p->pid_kp;
        cal->pid.ki = p->pid_ki;
        cal->pid.kd = p->pid_kd;
        cal->pid.kff = p->pid_kff;
        float duty = 0.0f;
        if (dt_s > 0.0f) {
            duty = td_pid_step(&cal->pid, cal->speed_rpm, cal->meter_rpm, dt_s);
        }
        check_running(cal, now_us, p, io, duty);
        out->meter_duty[l] = cal->state == TD_CAL_RUNNING ? duty : 0.0f;
    }
    const uint32_t period_us = (uint32_t)p->status_period_ms * 1000u;
    if (cal->announce || td_elapsed_us(now_us, cal->last_status_us) >= period_us) {
        cal->announce = false;
        cal->last_status_us = now_us;
        encode_status(cal, status);
        return 1;
    }
    return 0;
}
