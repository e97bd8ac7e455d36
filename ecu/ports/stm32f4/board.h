/**
 * @file board.h
 * @brief The pin map and the board's numbers: the one place to change for another STM32F405/407
 *        board. docs/firmware.md has the same as a wiring table (keep both in step).
 *
 * | function                    | pin  | peripheral        | AF | electrical                         |
 * |-----------------------------|------|-------------------|----|------------------------------------|
 * | CAN1 RX                     | PB8  | CAN1_RX           | 9  | to the transceiver's RXD           |
 * | CAN1 TX                     | PB9  | CAN1_TX           | 9  | to the transceiver's TXD           |
 * | ground wheel encoder, A     | PA15 | TIM2_CH1 capture  | 1  | NPN open collector, pull-up        |
 * | upper meter encoder A / B   | PA6 / PA7 | TIM3_CH1/2 encoder | 2 | push-pull or open collector, pull-up |
 * | lower meter encoder A / B   | PB6 / PB7 | TIM4_CH1/2 encoder | 2 | same                          |
 * | upper fan tachometer        | PA2  | TIM9_CH1 ext. clock | 3 | open collector, pull-up          |
 * | lower fan tachometer        | PB14 | TIM12_CH1 ext. clock | 9 | same                            |
 * | upper meter motor PWM       | PC6  | TIM8_CH1          | 3  | to the driver's PWM input; pull-down on the board |
 * | lower meter motor PWM       | PC7  | TIM8_CH2          | 3  | same                               |
 * | upper fan PWM               | PC8  | TIM8_CH3          | 3  | same                               |
 * | lower fan PWM               | PC9  | TIM8_CH4          | 3  | same                               |
 * | SLCAN serial (emulator/HIL) | PA9 / PA10 | USART1 TX / RX | 7 | 3.3 V UART, 921600 8N1          |
 * | debug                       | PA13 / PA14 | SWDIO / SWCLK | 0 | ST-LINK                         |
 */
#ifndef TD_BOARD_H
#define TD_BOARD_H

#include <stdint.h>

#define BOARD_HSE_HZ 8000000u          /* crystal (most F405/F407 boards); PLL: /8 x336 /2 = 168 MHz */
#define BOARD_PLL_M 8u
#define BOARD_PLL_N 336u
#define BOARD_PLL_Q 7u                 /* 48 MHz for USB (unused) */
#define BOARD_CORE_HZ 168000000u
#define BOARD_HSI_HZ 16000000u
#define BOARD_CAN_BITRATE 250000u      /* ISO 11783 / J1939; configurable at build: -DBOARD_CAN_BITRATE=500000 */
#define BOARD_CAN_SAMPLE_PERMILLE 875u
#define BOARD_SLCAN_BAUD 921600u
#define BOARD_PWM_HZ 20000u            /* above hearing; the motor drivers take up to 20-25 kHz */
#define BOARD_STEP_HZ 100u             /* the 10 ms control step */
/* Encoder direction: 1 inverts a meter encoder's count direction (CCxP of TI1), for a shaft
 * whose encoder counts down when the meter turns forward (bring-up checklist). */
#define BOARD_METER_UPPER_INVERT 0u
#define BOARD_METER_LOWER_INVERT 0u
/* Input filters (RM0090 18.4.7 ICxF): 0xF = f_DTS/32, 8 samples: ~3 us at 84 MHz, well under
 * the 110 us period of the wheel at 25 km/h and the meters' ~50 us at full speed. */
#define BOARD_INPUT_FILTER 0xFu

/* Pins: port letter index (A = 0), pin number, alternate function. */
#define PIN_CAN_RX 1u, 8u, 9u
#define PIN_CAN_TX 1u, 9u, 9u
#define PIN_WHEEL 0u, 15u, 1u
#define PIN_METER_UP_A 0u, 6u, 2u
#define PIN_METER_UP_B 0u, 7u, 2u
#define PIN_METER_LO_A 1u, 6u, 2u
#define PIN_METER_LO_B 1u, 7u, 2u
#define PIN_FAN_UP_TACH 0u, 2u, 3u
#define PIN_FAN_LO_TACH 1u, 14u, 9u
#define PIN_PWM_METER_UP 2u, 6u, 3u
#define PIN_PWM_METER_LO 2u, 7u, 3u
#define PIN_PWM_FAN_UP 2u, 8u, 3u
#define PIN_PWM_FAN_LO 2u, 9u, 3u
#define PIN_SLCAN_TX 0u, 9u, 7u
#define PIN_SLCAN_RX 0u, 10u, 7u

#endif /* TD_BOARD_H */
