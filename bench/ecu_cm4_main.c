/**
 * @file ecu_cm4_main.c
 * @brief Minimal Cortex-M4 image for the size benchmark: the one static td_app_t a port owns
 *        and a main loop that calls every entry point, so --gc-sections keeps all of the core
 *        a real port links. The volatile "registers" stand for the hardware.
 */
#include "td_app.h"

static td_app_t app;

volatile uint32_t hw_now_us;
volatile uint32_t hw_counter[5];
volatile uint32_t hw_wheel_capture_us;
volatile float hw_pwm[4];
volatile uint8_t hw_rx_ready;
volatile uint32_t hw_tx_count;

int main(void) {
    td_params_t p;
    td_params_default(&p);
    if (td_app_init(&app, &p, hw_now_us) != TD_OK) {
        return 1;
    }
    for (;;) {
        const uint32_t now = hw_now_us;
        if (hw_rx_ready != 0u) {
            td_can_frame_t rx = { TD_ID_PC_COMMAND, 1u, 8u, { 0x0A, 0, 0, 0, 0, 0, 0, 0 } };
            (void)td_app_rx(&app, &rx, now);
        }
        const td_io_in_t in = { hw_counter[0],
                                { hw_counter[1], hw_counter[2] },
                                { hw_counter[3], hw_counter[4] },
                                hw_wheel_capture_us,
                                1u };
        td_io_out_t out;
        (void)td_app_step(&app, now, &in, &out);
        hw_pwm[0] = out.meter_duty[0];
        hw_pwm[1] = out.meter_duty[1];
        hw_pwm[2] = out.fan_duty[0];
        hw_pwm[3] = out.fan_duty[1];
        td_can_frame_t tx;
        while (td_app_tx_pop(&app, &tx)) {
            hw_tx_count++;
        }
    }
}
