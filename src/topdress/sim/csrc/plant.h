/* The simulator's plant in C: tractor motion, ground wheel, metering motors, fans, air lines,
 * the wheel's capture timer and one whole World step around the ECU core.
 *
 * Not part of the ECU: the simulator's side of the port, compiled into the same cffi module
 * as the ECU core (src/topdress/ecu/_build.py) so that one call advances the plant and the
 * control law by one step. Each function is the same arithmetic, operation for operation, as
 * the Python it replaced (double precision, IEEE rounding, glibc's sin/cos/pow), so that a
 * seed gives the same numbers bit for bit. The Python classes (topdress.sim.*) own the
 * parameters (fault knobs included) and the random streams: they copy a replaced parameter
 * set into the struct and hand over random() draws of their own random.Random in blocks
 * (tdsim_gauss_t), used in the order they were drawn.
 *
 * Units: seconds, metres, m/s, rpm, kg; times of the ECU's clock in microseconds (uint32).
 */
#ifndef TDSIM_PLANT_H
#define TDSIM_PLANT_H

#include <stdint.h>

#include "td_app.h"

#define TDSIM_UNIFORM_BLOCK 64

/* One N(0, 1) stream of a Python random.Random: its random() draws, handed over in blocks
 * (u[next..n-1] still to be used), turned into normal draws the way random.gauss does it
 * (a pair from two uniforms, the second one kept for the next draw). */
typedef struct {
    uint32_t n;
    uint32_t next;
    double u[TDSIM_UNIFORM_BLOCK];
    double kept; /* the second of a pair, when has_kept */
    uint8_t has_kept;
} tdsim_gauss_t;

typedef struct {
    /* TractorParams */
    double runup_m, accel_min_ms2, accel_max_ms2, clutch_s, decel_ms2, jerk_ms3, speed_tau_s;
    double ripple_sd, ripple_tau_s, stall_at_s;
    /* state */
    double x_m, y_m, heading_rad, v_ms, a_ms2, odometer_m, t_s, ripple, vb_ms, accel_limit_ms2;
    double target_ms, jerk_now_ms3;
    tdsim_gauss_t gauss;
} tdsim_tractor_t;

typedef struct {
    /* WheelParams (and 2 pi r) */
    double circ_m, slip_a, slip_b, slip_c, bounce_sd, bounce_tau_s, encoder_dead_at_s, lifted_at_s;
    double ppr;
    /* state */
    double slip_offset_pct, bounce, revolutions;
    int64_t count;
    tdsim_gauss_t gauss;
} tdsim_wheel_t;

typedef struct {
    /* MeterParams (and the lag's decay over one step) */
    double max_rpm, breakaway_duty, friction_duty, load_duty, flutes, load_ripple;
    double counts_per_rev, jammed_at_s, encoder_dead_at_s, decay;
    /* state */
    double rpm, revolutions;
    int64_t count;
} tdsim_meter_t;

typedef struct {
    /* FanParams (and the lag's decay over one step) */
    double max_rpm, ppr, failed_at_s, belt_slip, decay;
    /* state */
    double rpm, revolutions;
    int64_t count;
} tdsim_fan_t;

/* The field's NDVI pattern (FieldParams with k = 2 pi / wavelength, two_r2 = 2 r^2) */
typedef struct {
    double ndvi_mean, wave_amp, k, phase0, phase1, two_r2;
    const double *patches; /* x, y, amplitude each */
    uint32_t n_patches;
} tdsim_field_t;

/* A parcel of fertilizer in flight: it lands at t_s. */
typedef struct {
    double t_s;
    double kg;
} tdsim_parcel_t;

typedef struct {
    /* AirLineParams */
    double line_length_m, air_speed_ms, nominal_fan_rpm, min_fan_rpm, drop_s, release_rev;
    uint8_t blocked;
    /* state */
    double rev_in, in_flight_kg, landed_kg;
    /* FIFO of parcels in flight (a ring that grows: a blocked line keeps everything) */
    tdsim_parcel_t *q;
    uint32_t q_head, q_len, q_cap;
} tdsim_airline_t;

/* World.step's flags (tdsim_world_step's return value when >= 0; the ECU's transmit queue
 * length is in bits 8 and up) */
#define TDSIM_REFILL_TRACTOR 0x01 /* the tractor's stream has < 2 uniforms left: top it up */
#define TDSIM_REFILL_WHEEL 0x02
#define TDSIM_FIRST_LANDING 0x04 /* fertilizer landed for the first time (either layer) */
#define TDSIM_BIN_DONE 0x08      /* a layer's landings moved on to a new bin: see done_bin */
#define TDSIM_NEW_BIN 0x10 /* the tractor entered record bin `bin` */
#define TDSIM_TX_SHIFT 8

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
    uint8_t wheel_edges; /* the port captures the wheel's edge time */
    /* loose patches: x, y, radius (m) each; the wheel slips at least loose_slip_pct there */
    const double *patches;
    uint32_t n_patches;
    double loose_slip_pct;
    /* the last lookup: where, the squared distance within which it stands (< 0 none), floor */
    double loose_x, loose_y, loose_reach2, loose_floor;
    /* state between steps */
    float duty[4];
    double rev_prev[2];
    double wheel_pos;
    uint32_t edge_us;
    /* what landed, per layer: in the record bin the outlets are over (land_bin, kg so far:
     * land_kg) and, once they have moved on, in the bin before (done_bin, done_kg; < 0 none) */
    uint8_t landed_any[2];
    int64_t land_bin[2], done_bin[2];
    double land_kg[2], done_kg[2];
} tdsim_world_t;

/* random.gauss(0.0, 1.0) of the stream; NaN when it runs dry (the caller tops up first) */
double tdsim_gauss_draw(tdsim_gauss_t *g);
int tdsim_tractor_step(tdsim_tractor_t *s, double dt_s, double v_target_ms, double curvature);
int64_t tdsim_wheel_step(tdsim_wheel_t *s, double t_s, double dt_s, double v_ms,
                         double slip_floor_pct);
int64_t tdsim_meter_step(tdsim_meter_t *s, double t_s, double dt_s, double duty);
int64_t tdsim_fan_step(tdsim_fan_t *s, double t_s, double dt_s, double duty);
double tdsim_field_ndvi(const tdsim_field_t *f, double x_m, double y_m);
tdsim_airline_t *tdsim_airline_new(void);
void tdsim_airline_free(tdsim_airline_t *s);
/* kg landing in (t - dt, t]; < 0 when the FIFO cannot grow (out of memory) */
double tdsim_airline_step(tdsim_airline_t *s, double t_s, double d_rev, double kg_per_rev,
                          double fan_rpm);
uint32_t tdsim_airline_len(const tdsim_airline_t *s);
double tdsim_world_loose(tdsim_world_t *w, double x_m, double y_m);
uint32_t tdsim_world_wheel_edge(tdsim_world_t *w, uint32_t now_us, int64_t count);
/* One World step at t_s: plant under the last duties, then one ECU step at now_us. Returns a
 * negative code of the ECU (td_common.h) or -1000 when an air line cannot grow, else the
 * TDSIM_* flags. */
int tdsim_world_step(tdsim_world_t *w, td_app_t *app, double t_s, uint32_t now_us,
                     double v_target_ms, double curvature);

#endif
