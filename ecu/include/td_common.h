/**
 * @file td_common.h
 * @brief Error codes, fault bits and small shared types of the topdress ECU core.
 *
 * Conventions (whole core): no heap, no globals, no clock reads. Every function
 * that depends on time takes `now_us`, a free-running microsecond counter of the
 * port (uint32_t, wraps every 71.6 min; all differences are taken modulo 2^32,
 * so any interval below 35 min is measured correctly across the wrap).
 * Errors are negative return codes; faults are latched in one fault word.
 */
#ifndef TD_COMMON_H
#define TD_COMMON_H

#include <stdbool.h>
#include <stdint.h>
#include "td_dbc.h" /* the protocol's ids, value tables and parameter table (from the DBC) */

/* ---- error codes (negative) ---- */
#define TD_OK 0
#define TD_E_ARG (-1)          /**< NULL pointer or argument outside its domain */
#define TD_E_UNKNOWN_ID (-2)   /**< CAN frame with an identifier the ECU does not take */
#define TD_E_LENGTH (-3)       /**< CAN frame with the wrong DLC */
#define TD_E_RANGE (-4)        /**< a value outside its documented range */
#define TD_E_BUSY (-5)         /**< parameter write while running */
#define TD_E_UNKNOWN_PARAM (-6) /**< parameter id not defined */
#define TD_E_INCONSISTENT (-7) /**< parameter set inconsistent (e.g. CV window > queue length) */
#define TD_E_FULL (-8)         /**< transmit queue full, frame dropped */

/* ---- fault word bits (td_app_t.faults): TD_FAULT_* of td_dbc.h, named in the DBC ----
 * CMD_TIMEOUT   no valid PcCommand for > cmd_timeout_ms: meters stopped; clears on the next
 *               valid command
 * GNSS_LOST     GNSS speed missing (0xFF) or stale (> gnss_timeout_ms): wheel speed used;
 *               clears when GNSS returns
 * WHEEL_ENCODER wheel reads ~0 while GNSS > enc_fault_gnss_kmh for > enc_fault_time_ms: GNSS
 *               used; latched until a stop command
 * UPPER_BLOCKED upper meter commanded but not turning for > blocked_time_ms: upper motor
 *               stopped; latched until a stop command
 * LOWER_BLOCKED same, lower meter
 * UPPER_FAN_LOW upper fan below fan_min_rpm after the spin-up grace: upper meter held at zero;
 *               clears when the fan is up
 * LOWER_FAN_LOW same, lower fan
 * NO_SPEED      neither speed source usable: meters held at zero
 * GNSS_FROZEN   running, wheel reads ~0 while GNSS > enc_fault_gnss_kmh for > enc_fault_time_ms
 *               and the GNSS value never changed meanwhile (frozen receiver): GNSS not used;
 *               clears when the wheel turns or GNSS drops below enc_fault_gnss_kmh (a GNSS value
 *               that changes while the wheel still reads ~0 latches WHEEL_ENCODER instead) */

/** Latched faults: cleared only by a stop command (operator acknowledgement). */
#define TD_FAULT_LATCHED_MASK (TD_FAULT_WHEEL_ENCODER | TD_FAULT_UPPER_BLOCKED | TD_FAULT_LOWER_BLOCKED)

/** Layers / metering motors and fans. */
typedef enum { TD_UPPER = 0, TD_LOWER = 1, TD_LAYERS = 2 } td_layer_t;

/* td_dbc.h (generated from the DBC's value tables):
 * td_source_t, the speed source in use (EcuDiag.SpeedSource). TD_SRC_FUSED: the fused estimate
 *  fed by both the wheel and GNSS (in TD_MODE_FUSED, WHEEL and GNSS name the one sensor still
 *  feeding it).
 * td_speed_mode_t, the speed mode (parameter SpeedMode). TD_MODE_FUSED: the Kalman estimate of
 *  td_fused.h.
 * td_compare_t, which speed the dual rule compares with switch_speed_kmh (SwitchCompare). */

/** Slip compensation of the wheel speed (parameter SlipComp). Modes dual, wheel and GNSS: none,
 *  the scale the fused estimate learned, eq. 5. The fused mode always compensates: eq. 5's shape
 *  in speed times a learned factor, except with TD_SLIP_LEARNED (one learned constant scale). */
typedef enum { TD_SLIP_OFF = 0, TD_SLIP_LEARNED = 1, TD_SLIP_MODEL = 2 } td_slip_comp_t;

/** Elapsed microseconds from `then_us` to `now_us`, correct across the 2^32 wrap. */
static inline uint32_t td_elapsed_us(uint32_t now_us, uint32_t then_us) {
    return (uint32_t)(now_us - then_us);
}

/**
 * Age in microseconds at `now_us` of an event stamped `then_us`, for stamps that come from
 * td_app_rx(): a frame may be stamped after the port read the time of the step that follows
 * (a receive interrupt between the two), so a stamp up to 35 min ahead of now is age 0, not
 * 71 minutes old.
 */
static inline uint32_t td_age_us(uint32_t now_us, uint32_t then_us) {
    const uint32_t d = (uint32_t)(now_us - then_us);
    return d >= 0x80000000u ? 0u : d;
}

#endif /* TD_COMMON_H */
