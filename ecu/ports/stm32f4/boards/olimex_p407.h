/**
 * @file boards/olimex_p407.h
 * @brief Olimex STM32-P407 (STM32F407ZGT6, 25 MHz crystal). The pin map keeps off the board's
 *        Ethernet PHY (RMII: PA1, PA2, PA7, PC1, PC4, PC5, PG11, PG13, PG14), its microSD slot
 *        (PC8-PC12, PD2) and its two USB ports (OTG FS PA9-PA12, OTG HS PB12-PB15), which is why
 *        the PWM moves to TIM1 (TIM8's CH3/CH4 exist only on PC8/PC9 in this package) and the
 *        lower fan's tachometer to TIM8 (TIM12 exists only on PB14/PB15), as on the E407.
 *
 * CAN1 on PB8/PB9 is the pair the P407 routes to its CAN connector (its board support in
 * other projects uses the same pair).
 *
 * | function                    | pin  | peripheral           | AF |
 * |-----------------------------|------|----------------------|----|
 * | CAN1 RX / TX                | PB8 / PB9 | CAN1_RX / TX    | 9  |
 * | ground wheel encoder, A     | PA15 | TIM2_CH1 capture     | 1  |
 * | upper meter encoder A / B   | PB4 / PB5 | TIM3_CH1/2      | 2  |
 * | lower meter encoder A / B   | PD12 / PD13 | TIM4_CH1/2    | 2  |
 * | upper fan tachometer        | PE5  | TIM9_CH1 ext. clock  | 3  |
 * | lower fan tachometer        | PC6  | TIM8_CH1 ext. clock  | 3  |
 * | meter / fan PWM             | PE9, PE11, PE13, PE14 | TIM1_CH1-4 | 1 |
 */
#ifndef TD_BOARD_OLIMEX_P407_H
#define TD_BOARD_OLIMEX_P407_H

#define BOARD_NAME "olimex_p407"
#define BOARD_HSE_HZ 25000000u

#include "../olimex_407_pins.h" /* the pin map both Olimex boards share */

#endif /* TD_BOARD_OLIMEX_P407_H */
