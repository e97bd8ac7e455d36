/**
 * @file td_port.h
 * @brief The port contract: everything that crosses between the ECU core and the hardware.
 *
 * The core never touches hardware and never reads a clock. A port (a microcontroller
 * main loop, the simulator, a test) does four things, and only these:
 *
 *  1. Every control period (default 10 ms, any period 1..50 ms works) it reads the five
 *     free-running encoder counters into a td_io_in_t and calls
 *     td_app_step(app, now_us, &in, &out).
 *  2. It applies td_io_out_t: the four PWM duties, 0..1 (0 = off, 1 = full on).
 *  3. For every CAN frame received it calls td_app_rx(app, &frame, now_us).
 *  4. After each step it drains the transmit queue with td_app_tx_pop() and hands the
 *     frames to the CAN controller.
 *
 * Counters are cumulative and may wrap (uint32_t): the core uses differences only.
 * Wheel edge time: with a capture timer the port also passes the time of the last wheel pulse
 * (wheel_edge_us, wheel_edge_valid = 1); the core then measures the wheel speed from pulse
 * periods at every step (td_edge.h). Without one it times the pulses by the step clock.
 * Count direction: forward counts up; the core ignores backward motion.
 *
 * Sketch of a main loop on a microcontroller:
 * @code
 *   static td_app_t app;                 // the one instance, owned by the port
 *   td_app_init(&app, &params, hal_micros());
 *   for (;;) {
 *       wait_for_tick_10ms();
 *       uint32_t now = hal_micros();
 *       td_can_frame_t rx;
 *       while (hal_can_read(&rx)) td_app_rx(&app, &rx, now);
 *       td_io_in_t in = { hal_counter(WHEEL), { hal_counter(M_UP), hal_counter(M_LO) },
 *                         { hal_counter(F_UP), hal_counter(F_LO) },
 *                         hal_capture(WHEEL), 1 };   // 0, 0 without a capture timer
 *       td_io_out_t out;
 *       td_app_step(&app, now, &in, &out);
 *       hal_pwm(M_UP, out.meter_duty[0]); hal_pwm(M_LO, out.meter_duty[1]);
 *       hal_pwm(F_UP, out.fan_duty[0]);   hal_pwm(F_LO, out.fan_duty[1]);
 *       td_can_frame_t tx;
 *       while (td_app_tx_pop(&app, &tx)) hal_can_write(&tx);
 *   }
 * @endcode
 */
#ifndef TD_PORT_H
#define TD_PORT_H

#include <stdint.h>

/** A classic CAN frame. `id` is the 29-bit identifier when `extended` is 1. */
typedef struct {
    uint32_t id;       /**< identifier, without any flag bits */
    uint8_t extended;  /**< 1 = 29-bit identifier, 0 = 11-bit */
    uint8_t dlc;       /**< data length, 0..8 */
    uint8_t data[8];   /**< payload; bytes past dlc are ignored */
} td_can_frame_t;

/** Inputs read by the port each control period: cumulative encoder counters and, if the port
 *  has an input-capture timer on the wheel encoder, the time of its last edge. A port that
 *  only counts sets the last two fields to zero. */
typedef struct {
    uint32_t wheel_count;      /**< ground wheel encoder pulses (A phase), wheel_ppr per wheel revolution */
    uint32_t meter_count[2];   /**< metering shaft encoder counts [TD_UPPER, TD_LOWER], meter_counts_per_rev per shaft revolution */
    uint32_t fan_count[2];     /**< fan tachometer pulses [TD_UPPER, TD_LOWER], fan_ppr per fan revolution */
    uint32_t wheel_edge_us;    /**< time of the wheel pulse that made wheel_count what it is, on the clock of now_us
                                    (capture timer); read with wheel_count, atomically; only when wheel_edge_valid */
    uint8_t wheel_edge_valid;  /**< 1: wheel_edge_us is a captured edge time; 0: counts only (pulses are timed by the step) */
} td_io_in_t;

/** Outputs the port applies after each control step. Duties in [0, 1]. */
typedef struct {
    float meter_duty[2];       /**< metering motor PWM duty [TD_UPPER, TD_LOWER] */
    float fan_duty[2];         /**< fan PWM duty [TD_UPPER, TD_LOWER] */
} td_io_out_t;

#endif /* TD_PORT_H */
