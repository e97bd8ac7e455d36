/**
 * @file board.h
 * @brief The board's numbers: the board header (boards/<name>.h, chosen with `make firmware
 *        BOARD=<name>`) gives the crystal and the pin map; this file derives the clock tree from
 *        the crystal and checks every PLL and bus limit at compile time (RM0090 6.3.2 RCC_PLLCFGR,
 *        6.3.3 RCC_CFGR; datasheet DS8626 table 17). Every default is guarded (#ifndef), so
 *        `make firmware FW_CFLAGS=-DBOARD_CAN_BITRATE=500000` overrides it.
 *
 * Clock tree: SYSCLK 160 MHz (not the chip's 168): APB1 = 160 / 4 = 40 MHz gives the CAN bit
 * timing 16 quanta per bit with the sample point at 14/16 = 87.5 % (ISO 11783-2, SAE J1939-11)
 * at 250 and 500 kbit/s; 42 MHz reaches 85.7 % at best. APB2 = 80 MHz, its timers 160 MHz.
 */
#ifndef TD_BOARD_H
#define TD_BOARD_H

#include <stdint.h>

#ifndef BOARD_HEADER
#define BOARD_HEADER "boards/generic8.h"
#endif
#include BOARD_HEADER

#ifndef BOARD_HSE_HZ
#error "the board header names its crystal (BOARD_HSE_HZ)"
#endif
#ifndef BOARD_CORE_HZ
#define BOARD_CORE_HZ 160000000u
#endif
#define BOARD_HSI_HZ 16000000u
/* PLL input 2 MHz when the crystal divides to it (less jitter, RM0090 6.3.2), else 1 MHz */
#define BOARD_PLL_IN_HZ (BOARD_HSE_HZ % 2000000u == 0u ? 2000000u : 1000000u)
#define BOARD_PLL_M (BOARD_HSE_HZ / BOARD_PLL_IN_HZ)
#define BOARD_PLL_P 2u
#define BOARD_PLL_N (BOARD_CORE_HZ * BOARD_PLL_P / BOARD_PLL_IN_HZ)
#define BOARD_VCO_HZ (BOARD_PLL_IN_HZ * BOARD_PLL_N)
/* the 48 MHz domain (USB, SDIO, RNG; none used): Q keeps it at or below 48 MHz */
#define BOARD_PLL_Q ((BOARD_VCO_HZ + 47999999u) / 48000000u)
#define BOARD_AHB_HZ BOARD_CORE_HZ
#define BOARD_APB1_HZ (BOARD_AHB_HZ / 4u) /* RCC_CFGR.PPRE1 = /4 */
#define BOARD_APB2_HZ (BOARD_AHB_HZ / 2u) /* RCC_CFGR.PPRE2 = /2 */
/* flash wait states at 2.7-3.6 V (RM0090 3.5.1, table 10): one per started 30 MHz */
#define BOARD_FLASH_WS ((BOARD_CORE_HZ - 1u) / 30000000u)

/* C11's _Static_assert; __extension__ keeps -std=c99 -pedantic quiet about it */
#define BOARD_ASSERT(cond, msg) __extension__ _Static_assert(cond, msg)

BOARD_ASSERT(BOARD_HSE_HZ >= 4000000u && BOARD_HSE_HZ <= 26000000u, "HSE crystal 4-26 MHz");
BOARD_ASSERT(BOARD_HSE_HZ % BOARD_PLL_IN_HZ == 0u, "the crystal divides to the PLL input");
BOARD_ASSERT(BOARD_PLL_M >= 2u && BOARD_PLL_M <= 63u, "PLLM 2..63");
BOARD_ASSERT(BOARD_PLL_IN_HZ >= 1000000u && BOARD_PLL_IN_HZ <= 2000000u, "VCO input 1-2 MHz");
BOARD_ASSERT(BOARD_PLL_N >= 50u && BOARD_PLL_N <= 432u, "PLLN 50..432");
BOARD_ASSERT(BOARD_VCO_HZ >= 100000000u && BOARD_VCO_HZ <= 432000000u, "VCO 100-432 MHz");
BOARD_ASSERT(BOARD_VCO_HZ / BOARD_PLL_P == BOARD_CORE_HZ, "SYSCLK is exactly VCO / P");
BOARD_ASSERT(BOARD_CORE_HZ <= 168000000u, "SYSCLK at most 168 MHz");
BOARD_ASSERT(BOARD_PLL_Q >= 2u && BOARD_PLL_Q <= 15u, "PLLQ 2..15");
BOARD_ASSERT(BOARD_VCO_HZ / BOARD_PLL_Q <= 48000000u, "48 MHz domain at most 48 MHz");
BOARD_ASSERT(BOARD_APB1_HZ <= 42000000u, "APB1 at most 42 MHz");
BOARD_ASSERT(BOARD_APB2_HZ <= 84000000u, "APB2 at most 84 MHz");
BOARD_ASSERT(BOARD_FLASH_WS <= 7u, "flash latency 0..7 wait states");

#ifndef BOARD_CAN_BITRATE
#define BOARD_CAN_BITRATE 250000u /* ISO 11783 / J1939 */
#endif
/* Bit timing (RM0090 32.7.7): 16 quanta, TS1 = 13, TS2 = 2, SJW = 2: sample point 87.5 %.
 * The prescaler is the only variable: the bit rate must divide APB1 / 16 exactly, on the PLL
 * and on the internal oscillator (the silent fallback). td_bxcan_timing() finds the same. */
#define BOARD_CAN_TQ 16u
#define BOARD_CAN_TS1 13u
#define BOARD_CAN_TS2 2u
#define BOARD_CAN_SJW 2u
#define BOARD_CAN_BTR_FOR(pclk_hz)                                                           \
    (((BOARD_CAN_SJW - 1u) << 24) | ((BOARD_CAN_TS2 - 1u) << 20) | ((BOARD_CAN_TS1 - 1u) << 16) | \
     ((pclk_hz) / (BOARD_CAN_BITRATE * BOARD_CAN_TQ) - 1u))
BOARD_ASSERT(1u + BOARD_CAN_TS1 + BOARD_CAN_TS2 == BOARD_CAN_TQ, "16 quanta per bit");
BOARD_ASSERT(BOARD_APB1_HZ % (BOARD_CAN_BITRATE * BOARD_CAN_TQ) == 0u,
               "BOARD_CAN_BITRATE must divide APB1 / 16 (40 MHz: 500, 250, 125, 100, 50 kbit/s)");
BOARD_ASSERT(BOARD_APB1_HZ / (BOARD_CAN_BITRATE * BOARD_CAN_TQ) <= 1024u, "BRP 1..1024");
BOARD_ASSERT(BOARD_HSI_HZ % (BOARD_CAN_BITRATE * BOARD_CAN_TQ) == 0u,
               "BOARD_CAN_BITRATE must divide the 16 MHz internal oscillator / 16 too");

#ifndef BOARD_SLCAN_BAUD
#define BOARD_SLCAN_BAUD 921600u
#endif
#ifndef BOARD_PWM_HZ
#define BOARD_PWM_HZ 20000u /* above hearing; the motor drivers take up to 20-25 kHz */
#endif
#ifndef BOARD_STEP_HZ
#define BOARD_STEP_HZ 100u /* the 10 ms control step */
#endif
/* Encoder direction: 1 inverts a meter encoder's count direction (CCxP of TI1), for a shaft
 * whose encoder counts down when the meter turns forward (bring-up checklist). */
#ifndef BOARD_METER_UPPER_INVERT
#define BOARD_METER_UPPER_INVERT 0u
#endif
#ifndef BOARD_METER_LOWER_INVERT
#define BOARD_METER_LOWER_INVERT 0u
#endif
/* Input filters (RM0090 18.4.7 ICxF): 0xF = f_DTS/32, 8 samples: ~3 us at 80 MHz, well under
 * the 110 us period of the wheel at 25 km/h and the meters' ~50 us at full speed. */
#ifndef BOARD_INPUT_FILTER
#define BOARD_INPUT_FILTER 0xFu
#endif

#endif /* TD_BOARD_H */
