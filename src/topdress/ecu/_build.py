"""cffi (API mode) builder of `topdress.ecu._core`: the C ECU core compiled into the package.

setup.py runs from the repository root (`cffi_modules=["src/topdress/ecu/_build.py:ffibuilder"]`).
The cdef restates the public part of ecu/include/td_*.h; `...;` lets the C compiler supply
struct layouts, so a changed header is caught at build time instead of corrupting memory. The
protocol's identifiers, value tables and parameter count are declared from the header generated
from the DBC (ecu/src/gen/td_dbc.h), not restated.
"""

from __future__ import annotations

import re
from glob import glob
from pathlib import Path

from cffi import FFI

DBC_HEADER = Path("ecu/src/gen/td_dbc.h")  # setup.py runs from the repository root


def dbc_cdef(header: str) -> str:
    """The cdef of the generated header: its constants (values left to the compiler) and its
    enums as they are; the X-macro tables are for C only."""
    out = []
    for line in header.splitlines():
        if m := re.match(r"#define (TD_\w+) [^\\]+$", line):
            out.append(f"#define {m[1]} ...")
        elif line.startswith("typedef enum"):
            out.append(line)
    return "\n".join(out) + "\n"


CDEF = (
    dbc_cdef(DBC_HEADER.read_text(encoding="utf-8"))
    + r"""
/* td_common.h */
#define TD_OK ...
#define TD_E_ARG ...
#define TD_E_UNKNOWN_ID ...
#define TD_E_LENGTH ...
#define TD_E_RANGE ...
#define TD_E_BUSY ...
#define TD_E_UNKNOWN_PARAM ...
#define TD_E_INCONSISTENT ...
#define TD_E_FULL ...
#define TD_FAULT_LATCHED_MASK ...
typedef enum { TD_UPPER = 0, TD_LOWER = 1, TD_LAYERS = 2 } td_layer_t;
typedef enum { TD_SLIP_OFF = 0, TD_SLIP_LEARNED = 1, TD_SLIP_MODEL = 2 } td_slip_comp_t;
uint32_t td_elapsed_us(uint32_t now_us, uint32_t then_us);

/* td_port.h */
typedef struct { uint32_t id; uint8_t extended; uint8_t dlc; uint8_t data[8]; ...; } td_can_frame_t;
typedef struct {
    uint32_t wheel_count; uint32_t meter_count[2]; uint32_t fan_count[2];
    uint32_t wheel_edge_us; uint8_t wheel_edge_valid; ...;
} td_io_in_t;
typedef struct { float meter_duty[2]; float fan_duty[2]; ...; } td_io_out_t;

/* td_params.h */
typedef struct {
    float working_width_m;
    float kg_per_rev[2];
    float wheel_radius_m;
    uint16_t wheel_ppr;
    uint8_t queue_len;
    uint8_t cv_window;
    float cv_threshold_pct;
    float switch_speed_kmh;
    uint8_t speed_mode;
    uint8_t switch_compare;
    float pid_kp;
    float pid_ki;
    float pid_kd;
    float pid_kff;
    uint16_t cmd_timeout_ms;
    uint16_t gnss_timeout_ms;
    float min_work_speed_kmh;
    uint16_t wheel_update_ms;
    uint8_t wheel_samples;
    uint16_t meter_counts_per_rev;
    uint16_t fan_min_rpm;
    uint8_t fan_ppr;
    float enc_fault_gnss_kmh;
    uint16_t enc_fault_time_ms;
    uint16_t blocked_time_ms;
    uint16_t status_period_ms;
    uint8_t slip_comp;
    uint16_t gnss_lag_ms;
    uint16_t lead_meter_ms;
    uint16_t lead_air_ms;
    float fused_jerk_ms3;
    float fused_gnss_std_kmh;
    float fused_wheel_noise_pct;
    uint16_t wheel_stop_ms;
    uint8_t drive_adapt;
    uint16_t meter_tau_ms;
    uint16_t lead_stop_ms;
    uint8_t gnss_lag_auto;
    float fan_rpm_at_full_duty;
    uint16_t fan_spinup_ms;
    uint32_t status_id;
    uint32_t command_id;
    ...;
} td_params_t;
void td_params_default(td_params_t *p);
int td_params_validate(const td_params_t *p);
int td_params_set(td_params_t *p, uint8_t param_id, float value);
int td_params_get(const td_params_t *p, uint8_t param_id, float *value);
int td_params_encoding(uint8_t param_id, float *scale, uint32_t *raw_min, uint32_t *raw_max);

/* td_wheel.h */
#define TD_WHEEL_MAX_SAMPLES ...
float td_wheel_speed_kmh(float f_hz, float radius_m, uint16_t ppr);
typedef struct { float speed_kmh; uint8_t n_freq; ...; } td_wheel_t;
int td_wheel_init(td_wheel_t *w, float radius_m, uint16_t ppr, uint8_t samples, uint16_t update_ms);
bool td_wheel_step(td_wheel_t *w, uint32_t now_us, uint32_t count, float *speed_kmh);

/* td_edge.h */
typedef struct {
    float m_per_pulse; bool have_edge; bool started; bool moving; bool timed; float speed_ms;
    float span_s; ...;
} td_edge_t;
int td_edge_init(td_edge_t *e, float radius_m, uint16_t ppr, uint16_t stop_ms);
float td_edge_step(td_edge_t *e, uint32_t now_us, uint32_t count, uint32_t edge_us,
                   bool edge_valid);

/* td_fused.h */
typedef enum { TD_FUSED_ACCEPTED = 0, TD_FUSED_REJECTED = 1, TD_FUSED_RESTARTED = 2 }
    td_fused_result_t;
typedef struct {
    float v_ms; float a_ms2; float scale; float p[6]; float innov_ms; float run_s; int8_t run_sign;
    bool reopened; uint8_t wheel_rejects; ...;
} td_fused_t;
int td_fused_init(td_fused_t *f, float jerk_ms3, float gnss_std_kmh, float wheel_noise_pct);
void td_fused_predict(td_fused_t *f, float dt_s);
td_fused_result_t td_fused_wheel(td_fused_t *f, float z_ms, float r_extra, bool learn,
                                 bool gnss_backs);
td_fused_result_t td_fused_gnss(td_fused_t *f, float z_ms, float delay_s, bool learn);
void td_fused_standstill(td_fused_t *f);
float td_fused_lead_ms(const td_fused_t *f, float lead_s);
float td_fused_speed_std_ms(const td_fused_t *f);

/* td_speedq.h */
#define TD_SPEEDQ_MAX ...
typedef struct { uint8_t len; uint8_t count; ...; } td_speedq_t;
int td_speedq_init(td_speedq_t *q, uint8_t len);
void td_speedq_push(td_speedq_t *q, float v_kmh);
float td_speedq_cv_pct(const td_speedq_t *q, uint8_t n);
float td_cv_pct(const float *v, uint8_t n);

/* td_slip.h */
float td_slip_measured_pct(float revolutions, float radius_m, float distance_m);
float td_slip_model_pct(float v_kmh);
float td_slip_model_speed_kmh(float slip_pct);

/* td_meter.h */
float td_meter_target_rpm(float width_m, float rate_kg_ha, float v_kmh, float kg_per_rev,
                          float min_speed_kmh);
float td_meter_rate_kg_ha(float width_m, float meter_rpm, float v_kmh, float kg_per_rev,
                          float min_speed_kmh);

/* td_pid.h */
typedef struct {
    float kp, ki, kd, kff;
    float d_tau_s;
    float out_min, out_max;
    float integ;
    float d_filt;
    float prev_meas;
    bool primed;
    ...;
} td_pid_t;
void td_pid_init(td_pid_t *pid, float kp, float ki, float kd, float kff, float out_min,
                 float out_max);
void td_pid_reset(td_pid_t *pid);
float td_pid_step(td_pid_t *pid, float setpoint, float measured, float dt_s);

/* td_drive.h */
typedef struct {
    td_pid_t pid; float kff_cfg; float tau_s; bool adapt; float ref_rpm; float duty_lag;
    float sn, su, sw, suu, suw; ...;
} td_drive_t;
void td_drive_init(td_drive_t *d, float kp, float ki, float kd, float kff, float tau_s,
                   bool adapt);
void td_drive_reset(td_drive_t *d);
float td_drive_step(td_drive_t *d, float target_rpm, float meas_rpm, float dt_s);
float td_drive_rpm_per_duty(const td_drive_t *d);

/* td_speedsel.h */
td_source_t td_speedsel_rule(td_speed_mode_t mode, td_compare_t compare, float cv_pct,
                             float cv_threshold_pct, float switch_speed_kmh, float v_wheel_kmh,
                             float v_gnss_kmh, bool gnss_valid, bool wheel_valid);

/* td_proto.h */
typedef struct {
    bool start; float fan_rpm; float rate_kg_ha[2]; bool gnss_valid; float gnss_kmh; ...;
} td_command_t;
typedef struct {
    bool running; float meter_rpm[2]; float fan_rpm[2]; float wheel_kmh; ...;
} td_status_t;
typedef struct {
    uint8_t source; uint8_t mode; bool gnss_valid; bool uniform; uint8_t compare; float cv_pct;
    uint16_t faults; uint32_t wheel_pulses; ...;
} td_diag_t;
typedef struct { float wheel_kmh, gnss_kmh, selected_kmh; uint16_t rx_rejected; ...; } td_speeds_t;
typedef struct {
    float target_rpm[2]; float meter_duty_pct[2]; float fan_duty_pct[2]; ...;
} td_targets_t;
typedef struct { uint8_t param_id; uint8_t result; uint32_t raw; ...; } td_param_ack_t;
int td_proto_decode_command(const td_can_frame_t *f, td_command_t *out);
int td_proto_encode_command(const td_command_t *c, td_can_frame_t *f);
int td_proto_encode_status(const td_status_t *s, td_can_frame_t *f);
int td_proto_decode_status(const td_can_frame_t *f, td_status_t *out);
int td_proto_encode_diag(const td_diag_t *d, td_can_frame_t *f);
int td_proto_encode_speeds(const td_speeds_t *s, td_can_frame_t *f);
int td_proto_encode_targets(const td_targets_t *t, td_can_frame_t *f);
int td_proto_encode_param_ack(const td_param_ack_t *a, td_can_frame_t *f);
int td_proto_decode_param_set(const td_can_frame_t *f, uint8_t *param_id, float *value);
uint32_t td_proto_param_raw(uint8_t param_id, float value);

/* td_app.h */
#define TD_TXQ_LEN ...
typedef struct {
    bool running;
    td_source_t source;
    float cv_pct;
    bool uniform;
    float v_wheel_kmh;
    float v_gnss_kmh;
    bool gnss_valid;
    float v_kmh;
    float rate_kg_ha[2];
    float target_rpm[2];
    float meter_rpm[2];
    float fan_rpm[2];
    float fan_target_rpm;
    float meter_duty[2];
    float fan_duty[2];
    uint16_t faults;
    uint32_t wheel_updates;
    uint32_t wheel_pulses;
    float v_fused_kmh;
    float a_fused_ms2;
    float slip_pct;
    float innov_kmh;
    float speed_std_kmh;
    float v_edge_kmh;
    float v_lead_kmh;
    float drive_rpm_per_duty[2];
    uint16_t gnss_delay_ms;
    uint16_t gnss_lag_ms;
    uint16_t lag_learned_ms;
    uint8_t lag_state;
    uint8_t lag_overruled;
    float lag_evidence_s;
    float lag_fit;
    bool slip_learning;
    bool edge_timing;
    bool gnss_fused;
    uint32_t gnss_fixes;
    uint32_t gnss_rejected;
    uint32_t wheel_rejected;
    ...;
} td_state_t;
typedef struct {
    uint32_t rx_ok;
    uint32_t rx_unknown_id;
    uint32_t rx_bad_length;
    uint32_t rx_out_of_range;
    uint32_t rx_param_rejected;
    uint32_t tx_dropped;
    ...;
} td_counters_t;
/* td_cal.h */
typedef struct {
    uint8_t state; uint8_t layer; uint8_t reason; uint8_t seq;
    float target_rev; float speed_rpm; float done_rev; float meter_rpm;
    ...;
} td_cal_t;
typedef struct {
    td_params_t p; td_state_t st; td_counters_t cnt; td_drive_t meter_drive[2]; td_fused_t fused;
    td_cal_t cal;
    ...;
} td_app_t;
int td_app_init(td_app_t *app, const td_params_t *params, uint32_t now_us);
int td_app_rx(td_app_t *app, const td_can_frame_t *frame, uint32_t now_us);
int td_app_step(td_app_t *app, uint32_t now_us, const td_io_in_t *in, td_io_out_t *out);
int td_app_tx_pop(td_app_t *app, td_can_frame_t *frame);
int td_app_announce(td_app_t *app);
const td_state_t *td_app_state(const td_app_t *app);

/* fast paths of the binding (below): one C call per step, per frame in, per drain of the
   transmit queue */
int tdpy_step(td_app_t *app, uint32_t now_us, uint32_t wheel, uint32_t m0, uint32_t m1,
              uint32_t f0, uint32_t f1, uint32_t wheel_edge_us, uint8_t wheel_edge_valid,
              float out[4]);
int tdpy_rx(td_app_t *app, uint32_t id, uint8_t extended, const char *data, size_t len,
            uint32_t now_us);
int tdpy_tx_drain(td_app_t *app, uint32_t ids[], uint8_t lens[], char data[]);

/* the simulator's plant (src/topdress/sim/csrc/plant.h) */
#define TDSIM_UNIFORM_BLOCK ...
#define TDSIM_REFILL_TRACTOR ...
#define TDSIM_REFILL_WHEEL ...
#define TDSIM_FIRST_LANDING ...
#define TDSIM_BIN_DONE ...
#define TDSIM_NEW_BIN ...
#define TDSIM_TX_SHIFT ...
typedef struct {
    uint32_t n; uint32_t next; double u[...]; double kept; uint8_t has_kept; ...;
} tdsim_gauss_t;
double tdsim_gauss_draw(tdsim_gauss_t *g);
typedef struct {
    double runup_m, accel_min_ms2, accel_max_ms2, clutch_s, decel_ms2, jerk_ms3, speed_tau_s;
    double ripple_sd, ripple_tau_s, stall_at_s;
    double x_m, y_m, heading_rad, v_ms, a_ms2, odometer_m, t_s, ripple, vb_ms, accel_limit_ms2;
    double target_ms, jerk_now_ms3;
    tdsim_gauss_t gauss;
    ...;
} tdsim_tractor_t;
typedef struct {
    double circ_m, slip_a, slip_b, slip_c, bounce_sd, bounce_tau_s, encoder_dead_at_s, lifted_at_s;
    double ppr;
    double slip_offset_pct, bounce, revolutions;
    int64_t count;
    tdsim_gauss_t gauss;
    ...;
} tdsim_wheel_t;
typedef struct {
    double max_rpm, breakaway_duty, friction_duty, load_duty, flutes, load_ripple;
    double counts_per_rev, jammed_at_s, encoder_dead_at_s, decay;
    double rpm, revolutions;
    int64_t count;
    ...;
} tdsim_meter_t;
typedef struct {
    double max_rpm, ppr, failed_at_s, belt_slip, decay;
    double rpm, revolutions;
    int64_t count;
    ...;
} tdsim_fan_t;
typedef struct {
    double ndvi_mean, wave_amp, k, phase0, phase1, two_r2;
    const double *patches;
    uint32_t n_patches;
    ...;
} tdsim_field_t;
typedef struct {
    double line_length_m, air_speed_ms, nominal_fan_rpm, min_fan_rpm, drop_s, release_rev;
    uint8_t blocked;
    double rev_in, in_flight_kg, landed_kg;
    ...;
} tdsim_airline_t;
typedef struct {
    tdsim_tractor_t *tractor;
    tdsim_wheel_t *wheel;
    tdsim_meter_t *meter[2];
    tdsim_fan_t *fan[2];
    tdsim_airline_t *line[2];
    double dt_s;
    double kg_per_rev[2];
    double bin_m;
    int64_t bin;
    uint8_t wheel_edges;
    const double *patches;
    uint32_t n_patches;
    double loose_slip_pct;
    double loose_x, loose_y, loose_reach2, loose_floor;
    float duty[4];
    double rev_prev[2];
    double wheel_pos;
    uint32_t edge_us;
    uint8_t landed_any[2];
    int64_t land_bin[2], done_bin[2];
    double land_kg[2], done_kg[2];
    ...;
} tdsim_world_t;
int tdsim_tractor_step(tdsim_tractor_t *s, double dt_s, double v_target_ms, double curvature);
int64_t tdsim_wheel_step(tdsim_wheel_t *s, double t_s, double dt_s, double v_ms,
                         double slip_floor_pct);
int64_t tdsim_meter_step(tdsim_meter_t *s, double t_s, double dt_s, double duty);
int64_t tdsim_fan_step(tdsim_fan_t *s, double t_s, double dt_s, double duty);
double tdsim_field_ndvi(const tdsim_field_t *f, double x_m, double y_m);
tdsim_airline_t *tdsim_airline_new(void);
void tdsim_airline_free(tdsim_airline_t *s);
double tdsim_airline_step(tdsim_airline_t *s, double t_s, double d_rev, double kg_per_rev,
                          double fan_rpm);
uint32_t tdsim_airline_len(const tdsim_airline_t *s);
double tdsim_world_loose(tdsim_world_t *w, double x_m, double y_m);
uint32_t tdsim_world_wheel_edge(tdsim_world_t *w, uint32_t now_us, int64_t count);
int tdsim_world_step(tdsim_world_t *w, td_app_t *app, double t_s, uint32_t now_us,
                     double v_target_ms, double curvature);
"""
)

# Small C shims so that one Python call does one whole step, without filling structs field
# by field from Python (the simulator calls step 360,000 times per simulated hour).
SHIMS = r"""
#include <string.h>
#include "td_app.h"
#include "td_drive.h"
#include "td_edge.h"
#include "td_fused.h"
#include "td_meter.h"
#include "td_slip.h"
#include "td_speedsel.h"
#include "plant.h"

static int tdpy_step(td_app_t *app, uint32_t now_us, uint32_t wheel, uint32_t m0, uint32_t m1,
                     uint32_t f0, uint32_t f1, uint32_t wheel_edge_us, uint8_t wheel_edge_valid,
                     float out[4]) {
    td_io_in_t in;
    td_io_out_t o;
    int rc;
    in.wheel_count = wheel;
    in.meter_count[0] = m0;
    in.meter_count[1] = m1;
    in.fan_count[0] = f0;
    in.fan_count[1] = f1;
    in.wheel_edge_us = wheel_edge_us;
    in.wheel_edge_valid = wheel_edge_valid;
    rc = td_app_step(app, now_us, &in, &o);
    out[0] = o.meter_duty[0];
    out[1] = o.meter_duty[1];
    out[2] = o.fan_duty[0];
    out[3] = o.fan_duty[1];
    return rc;
}

/* A frame longer than 8 bytes (CAN FD) keeps its length in dlc so the core rejects it as
   TD_E_LENGTH and counts it; only the first 8 bytes are copied. */
static int tdpy_rx(td_app_t *app, uint32_t id, uint8_t extended, const char *data, size_t len,
                   uint32_t now_us) {
    td_can_frame_t f;
    memset(&f, 0, sizeof f);
    f.id = id;
    f.extended = extended;
    f.dlc = (uint8_t)(len > 255u ? 255u : len);
    memcpy(f.data, data, len > 8u ? 8u : len);
    return td_app_rx(app, &f, now_us);
}

/* Pops every frame of the transmit queue (at most TD_TXQ_LEN): ids, lengths, and payloads 8
   bytes apart in data. Returns how many. */
static int tdpy_tx_drain(td_app_t *app, uint32_t ids[], uint8_t lens[], char data[]) {
    td_can_frame_t f;
    int n = 0;
    while (n < (int)TD_TXQ_LEN && td_app_tx_pop(app, &f)) {
        ids[n] = f.id;
        lens[n] = f.dlc;
        memcpy(data + 8 * n, f.data, 8);
        n++;
    }
    return n;
}
"""

ffibuilder = FFI()
ffibuilder.cdef(CDEF)
ffibuilder.set_source(
    "topdress.ecu._core",
    SHIMS,
    sources=[*sorted(glob("ecu/src/*.c")), "ecu/src/gen/td_can.c", "src/topdress/sim/csrc/plant.c"],
    include_dirs=["ecu/include", "ecu/src/gen", "src/topdress/sim/csrc"],
    extra_compile_args=["-std=c99", "-O2"],
)

if __name__ == "__main__":
    ffibuilder.compile(verbose=True)
