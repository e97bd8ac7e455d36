/**
 * @file td_edge.h
 * @brief Ground-wheel speed from pulse timing, at every control step.
 *
 * With a capture timer the port passes the time of the last encoder edge with the count
 * (td_io_in_t.wheel_edge_us). The speed is then the distance of the pulses counted since the
 * previous captured edge over the time between the two edges: exact to the timer's
 * resolution, at every step, whatever the pulse rate. Without edge times (counts-only port)
 * the step time stands in for the edge time: the same formula over the steps in which pulses
 * arrived, with one pulse of quantization.
 *
 * Motion from standstill: the first pulse marks motion (moving = true); from the second pulse
 * (1.5 mm with the paper's wheel: 2 x 2*pi*0.0615/500) there is a period and a speed. Within a
 * step with several pulses the speed is at least (n - 1) pulses over the time since the
 * previous step.
 * Slowing down and standstill: while no pulse comes, the speed cannot be above one pulse over
 * the time since the last edge, so it is bounded by that and falls as 1/t; after stop_ms
 * without a pulse the wheel stands (speed 0, moving = false).
 */
#ifndef TD_EDGE_H
#define TD_EDGE_H

#include <stdbool.h>
#include <stdint.h>

typedef struct {
    float m_per_pulse;         /**< 2*pi*r / K, m */
    uint32_t stop_us;          /**< no pulse for this long = standstill */
    uint32_t last_count;       /**< counter at the last step */
    uint32_t last_step_us;     /**< time of the last step */
    uint32_t edge_us;          /**< time of the last edge (or of the step that saw it) */
    bool have_edge;            /**< edge_us is the time of a pulse since the wheel last stood */
    bool started;              /**< a first step has set last_count */
    bool moving;               /**< a pulse came within stop_us */
    bool timed;                /**< the last pulses were timed by a captured edge */
    float speed_ms;            /**< wheel circumference speed, m/s (no slip correction), >= 0 */
    float span_s;              /**< time base of the last measured period, s (0: bound or standstill) */
} td_edge_t;

/** Initialise. TD_E_ARG on radius <= 0, ppr 0 or stop_ms 0. */
int td_edge_init(td_edge_t *e, float radius_m, uint16_t ppr, uint16_t stop_ms);

/**
 * Feed the cumulative count read at now_us, with the captured time of its last edge when
 * edge_valid. An edge time after now_us, or before the previous edge while pulses came, is
 * not trusted (the step time is used). Returns the speed in m/s (also in e->speed_ms).
 */
float td_edge_step(td_edge_t *e, uint32_t now_us, uint32_t count, uint32_t edge_us, bool edge_valid);

#endif /* TD_EDGE_H */
