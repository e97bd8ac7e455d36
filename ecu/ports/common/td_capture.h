/**
 * @file td_capture.h
 * @brief Counter arithmetic of a port: narrow hardware counters extended to the core's
 *        cumulative uint32_t counters, and the wheel encoder's input capture (count and the
 *        time of its last edge, td_port.h). No registers here: the host tests check it.
 */
#ifndef TD_CAPTURE_H
#define TD_CAPTURE_H

#include <stdbool.h>
#include <stdint.h>

/** A hardware counter of `bits` (1..16) bits extended to a cumulative 32-bit count. */
typedef struct {
    uint32_t total;            /**< cumulative count, wraps modulo 2^32 as the core expects */
    uint16_t last;             /**< the raw value at the last update */
    uint8_t bits;              /**< width of the hardware counter */
} td_ctr_t;

/** Start from the counter's value now (the cumulative count starts at 0). */
void td_ctr_init(td_ctr_t *c, uint8_t bits, uint16_t raw);

/**
 * Quadrature counter (timer encoder mode, counts up and down): the difference is taken signed,
 * so backward motion lowers the total (the core takes a backward count as no motion). Read it at
 * least once per half wrap (2^(bits-1) counts) or motion is lost.
 */
uint32_t td_ctr_update_signed(td_ctr_t *c, uint16_t raw);

/** Up-only counter (a tachometer on a timer's external clock): the difference modulo 2^bits.
 *  Read it at least once per wrap. */
uint32_t td_ctr_update_up(td_ctr_t *c, uint16_t raw);

/** The wheel encoder on an input-capture channel of the microsecond timer. */
typedef struct {
    uint32_t count;            /**< pulses counted (cumulative, wraps) */
    uint32_t edge_us;          /**< capture of the pulse that made `count` what it is */
    uint32_t overcaptures;     /**< interrupts that found a capture overwritten (an edge's time lost) */
    bool have_edge;            /**< at least one edge since start */
} td_wheel_capture_t;

void td_wheel_capture_init(td_wheel_capture_t *w);

/**
 * One capture interrupt. `ccr_us` is the latched time (CCRx); `overcapture` says another edge
 * came before this one was read (CCxOF, RM0090 18.4.5): the register then holds the later edge,
 * so both edges are counted and the latched time is that of the last one, which keeps the
 * count and the time together as td_port.h wants. Call with the capture interrupt masked
 * against the reader.
 */
void td_wheel_capture_edge(td_wheel_capture_t *w, uint32_t ccr_us, bool overcapture);

#endif /* TD_CAPTURE_H */
