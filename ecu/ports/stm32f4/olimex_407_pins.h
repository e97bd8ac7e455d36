/**
 * @file olimex_407_pins.h
 * @brief The pin map the Olimex STM32-E407 and STM32-P407 share (both STM32F407ZGT6 boards
 *        with the same Ethernet, microSD and USB pins to keep off): included by their board
 *        headers (boards/olimex_e407.h, boards/olimex_p407.h), which give the crystal and the
 *        table of what goes where.
 */
#ifndef TD_OLIMEX_407_PINS_H
#define TD_OLIMEX_407_PINS_H

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

#endif /* TD_OLIMEX_407_PINS_H */
