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

#define BOARD_PWM_TIM 1u
#define BOARD_FAN_LO_TIM 8u

#define PIN_CAN_RX 1u, 8u, 9u
#define PIN_CAN_TX 1u, 9u, 9u
#define PIN_WHEEL 0u, 15u, 1u
#define PIN_METER_UP_A 1u, 4u, 2u
#define PIN_METER_UP_B 1u, 5u, 2u
#define PIN_METER_LO_A 3u, 12u, 2u
#define PIN_METER_LO_B 3u, 13u, 2u
#define PIN_FAN_UP_TACH 4u, 5u, 3u
#define PIN_FAN_LO_TACH 2u, 6u, 3u
#define PIN_PWM_METER_UP 4u, 9u, 1u
#define PIN_PWM_METER_LO 4u, 11u, 1u
#define PIN_PWM_FAN_UP 4u, 13u, 1u
#define PIN_PWM_FAN_LO 4u, 14u, 1u
/* USART3 on PB10/PB11: the ROM bootloader's second serial port, for the field update
 * (USART1's PA9/PA10 are USB here) */
#define PIN_SERIAL_TX 1u, 10u, 7u
#define PIN_SERIAL_RX 1u, 11u, 7u
#define BOARD_RESERVED_PINS                                                                 \
    "PA13 PA14 PH0 PH1 PA1 PA2 PA7 PC1 PC4 PC5 PG11 PG13 PG14 PC8 PC9 PC10 PC11 PC12 PD2 " \
    "PA9 PA10 PA11 PA12 PB12 PB13 PB14 PB15"

#endif /* TD_BOARD_OLIMEX_P407_H */
