/**
 * @file boards/generic8.h
 * @brief A generic STM32F405/407 board with an 8 MHz crystal (F4 Discovery with a CAN
 *        transceiver board, most custom boards): the pin map of docs/firmware.md.
 *
 * | function                    | pin  | peripheral           | AF |
 * |-----------------------------|------|----------------------|----|
 * | CAN1 RX / TX                | PB8 / PB9 | CAN1_RX / TX    | 9  |
 * | ground wheel encoder, A     | PA15 | TIM2_CH1 capture     | 1  |
 * | upper meter encoder A / B   | PA6 / PA7 | TIM3_CH1/2      | 2  |
 * | lower meter encoder A / B   | PB6 / PB7 | TIM4_CH1/2      | 2  |
 * | upper fan tachometer        | PA2  | TIM9_CH1 ext. clock  | 3  |
 * | lower fan tachometer        | PB14 | TIM12_CH1 ext. clock | 9  |
 * | meter / fan PWM             | PC6, PC7, PC8, PC9 | TIM8_CH1-4 | 3 |
 */
#ifndef TD_BOARD_GENERIC8_H
#define TD_BOARD_GENERIC8_H

#define BOARD_NAME "generic8"
#define BOARD_HSE_HZ 8000000u

#define BOARD_PWM_TIM 8u       /* TIM8 CH1-4: the four PWM outputs */
#define BOARD_FAN_LO_TIM 12u   /* TIM12 CH1: the lower fan's tachometer */

/* Pins: port letter index (A = 0), pin number, alternate function (RM0090 8.3.2; the
 * datasheet's table 9). tests/test_fw_board.py checks each against docs/stm32f4_registers.tsv
 * and against the others and BOARD_RESERVED_PINS. */
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
/* USART1: the emulator build's SLCAN link and the ROM bootloader's serial port (field update) */
#define PIN_SERIAL_TX 0u, 9u, 7u
#define PIN_SERIAL_RX 0u, 10u, 7u
/* pins the board uses for something else: SWD, the crystal */
#define BOARD_RESERVED_PINS "PA13 PA14 PH0 PH1"

#endif /* TD_BOARD_GENERIC8_H */
