/**
 * @file td_hil.h
 * @brief The hardware-in-the-loop link of a port: the simulated machine's counters come in as
 *        HIL frames (protocol/topdress_hil.dbc) instead of from the timers, the duties go out as
 *        HIL frames instead of to the PWM pins. The control step itself is the core's, as on
 *        the machine. No hardware here: the host tests check it.
 *
 * Per control step the simulator sends HilClock, HilWheelEdge and HilSensors (the counters at
 * the step's time); the port takes the pair when HilSensors arrives. After the step the port
 * sends the step's bus frames, then HilActuators (the duties) and HilStep (the step's time, its
 * sequence number, the steps that found no fresh input, the step's cost). The hardware's narrow
 * counters (16-bit encoder timers, 8-bit tachometers here) are extended as the timers' are
 * (td_capture.h).
 *
 * The step's tick: the first HilClock chooses it. Lockstep (HilFreeRun 0): the simulator drives
 * the step; the port makes exactly one when a HilSensors arrives (`step_due`), at the HilClock's
 * time (`clock_us`), and HilStep echoes the HilClock's number. Free-running (HilFreeRun 1): the
 * port's own 10 ms tick, its own clock, its own numbers. The control step is the same call
 * either way; only where its tick and its time come from differs.
 */
#ifndef TD_HIL_H
#define TD_HIL_H

#include <stdbool.h>
#include <stdint.h>
#include "td_capture.h"
#include "td_hilcan.h"
#include "td_port.h"

/* The HIL frames' identifiers: the codec generated from protocol/topdress_hil.dbc. */
#define TD_HIL_ID_WHEEL_EDGE TD_HILCAN_HIL_WHEEL_EDGE_FRAME_ID
#define TD_HIL_ID_SENSORS TD_HILCAN_HIL_SENSORS_FRAME_ID
#define TD_HIL_ID_CLOCK TD_HILCAN_HIL_CLOCK_FRAME_ID
#define TD_HIL_ID_ACTUATORS TD_HILCAN_HIL_ACTUATORS_FRAME_ID
#define TD_HIL_ID_STEP TD_HILCAN_HIL_STEP_FRAME_ID

/** Where the port's step tick comes from (the first HilClock says). */
typedef enum {
    TD_HIL_TICK_UNSET = 0,     /**< no HilClock yet: no step */
    TD_HIL_TICK_OWN = 1,       /**< the port's own 10 ms tick, on its own clock */
    TD_HIL_TICK_LOCKSTEP = 2   /**< one step per HilSensors, at the HilClock's time */
} td_hil_tick_t;

typedef struct {
    td_ctr_t wheel, meter[2], fan[2];
    bool have_sensors;         /**< a HilSensors arrived since start */
    bool fresh;                /**< one arrived since the last step */
    uint16_t wheel_raw;        /**< the wheel counter of the last HilSensors */
    /* HilWheelEdge waiting for its HilSensors */
    uint32_t staged_edge_us;
    uint16_t staged_edge_count;
    bool staged_edge_valid;
    /* the edge of the pair taken */
    uint32_t edge_us;
    bool edge_valid;
    uint8_t tick;              /**< td_hil_tick_t */
    bool step_due;             /**< lockstep: a HilSensors arrived, the step is to be made */
    uint32_t clock_us;         /**< lockstep: the time of the step (the last HilClock) */
    uint8_t seq;               /**< HilStep sequence number of the next step */
    uint32_t late_steps;       /**< steps without fresh HilSensors (after the first) */
    uint32_t rx_frames;        /**< HIL frames taken */
    uint32_t rx_refused;       /**< HIL frames refused (length) */
} td_hil_t;

void td_hil_init(td_hil_t *h);

/** A received frame: 1 taken (a HIL frame), 0 not a HIL frame (hand it to the core),
 *  TD_E_LENGTH a HIL frame with the wrong length (refused, counted). The first HilClock sets
 *  `tick`; in lockstep a HilSensors sets `step_due`. */
int td_hil_rx(td_hil_t *h, const td_can_frame_t *f);

/** The inputs of the step now (cumulative counters and the wheel's edge); counts a late step
 *  and clears `step_due`. */
void td_hil_inputs(td_hil_t *h, td_io_in_t *in);

/** HilActuators and HilStep for the step just made at now_us that took cost_us. */
void td_hil_outputs(td_hil_t *h, uint32_t now_us, const td_io_out_t *out, uint32_t cost_us, td_can_frame_t frames[2]);

#endif /* TD_HIL_H */
