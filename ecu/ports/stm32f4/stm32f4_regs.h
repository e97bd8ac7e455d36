/**
 * @file stm32f4_regs.h
 * @brief The STM32F405/407 registers this port uses, written for topdress from ST's reference
 *        manual RM0090 (rev 19); section numbers are given per block. This is not ST's CMSIS
 *        device header and holds nothing copied from it: only what the port touches, as
 *        register structs at the manual's addresses and the bits by the manual's names.
 *
 * SPDX-License-Identifier: MIT (the topdress licence)
 */
#ifndef STM32F4_REGS_H
#define STM32F4_REGS_H

#include <stdint.h>

#define REG volatile uint32_t

/* ---- RCC, reset and clock control (RM0090 6.3) ------------------------------------------ */
typedef struct {
    REG CR, PLLCFGR, CFGR, CIR, AHB1RSTR, AHB2RSTR, AHB3RSTR, RES0, APB1RSTR, APB2RSTR, RES1[2],
        AHB1ENR, AHB2ENR, AHB3ENR, RES2, APB1ENR, APB2ENR, RES3[2], AHB1LPENR, AHB2LPENR, AHB3LPENR,
        RES4, APB1LPENR, APB2LPENR, RES5[2], BDCR, CSR;
} rcc_t;
#define RCC ((rcc_t *)0x40023800u)
#define RCC_CR_HSION (1u << 0)
#define RCC_CR_HSIRDY (1u << 1)
#define RCC_CR_HSEON (1u << 16)
#define RCC_CR_HSERDY (1u << 17)
#define RCC_CR_HSEBYP (1u << 18)
#define RCC_CR_CSSON (1u << 19)
#define RCC_CR_PLLON (1u << 24)
#define RCC_CR_PLLRDY (1u << 25)
#define RCC_PLLCFGR_RESET 0x24003010u  /* the reset value (6.3.2) */
#define RCC_PLLCFGR_N_SHIFT 6u
#define RCC_PLLCFGR_P_SHIFT 16u
#define RCC_PLLCFGR_SRC_HSE (1u << 22)
#define RCC_PLLCFGR_Q_SHIFT 24u
#define RCC_CFGR_SW_PLL 2u
#define RCC_CFGR_SWS_MASK (3u << 2)
#define RCC_CFGR_SWS_HSI (0u << 2)
#define RCC_CFGR_SWS_PLL (2u << 2)
#define RCC_CFGR_PPRE1_DIV4 (5u << 10)
#define RCC_CFGR_PPRE2_DIV2 (4u << 13)
#define RCC_CIR_CSSF (1u << 7)
#define RCC_CIR_CLEAR_ALL 0x00BF0000u  /* LSIRDYC..PLLI2SRDYC and CSSC (6.3.4) */
#define RCC_CIR_CSSC (1u << 23)
#define RCC_CSR_LSION (1u << 0)
#define RCC_CSR_RMVF (1u << 24)
#define RCC_CSR_BORRSTF (1u << 25)
#define RCC_CSR_PINRSTF (1u << 26)
#define RCC_CSR_PORRSTF (1u << 27)
#define RCC_CSR_SFTRSTF (1u << 28)
#define RCC_CSR_IWDGRSTF (1u << 29)
#define RCC_CSR_WWDGRSTF (1u << 30)
#define RCC_AHB1ENR_GPIOA (1u << 0)
#define RCC_AHB1ENR_GPIOB (1u << 1)
#define RCC_AHB1ENR_GPIOC (1u << 2)
#define RCC_AHB1ENR_GPIOD (1u << 3)
#define RCC_AHB1ENR_GPIOE (1u << 4)
#define RCC_APB1ENR_TIM2 (1u << 0)
#define RCC_APB1ENR_TIM3 (1u << 1)
#define RCC_APB1ENR_TIM4 (1u << 2)
#define RCC_APB1ENR_TIM12 (1u << 6)
#define RCC_APB1ENR_CAN1 (1u << 25)
#define RCC_APB2ENR_TIM1 (1u << 0)
#define RCC_APB2ENR_TIM8 (1u << 1)
#define RCC_APB2ENR_USART1 (1u << 4)
#define RCC_APB2ENR_TIM9 (1u << 16)

/* ---- Flash interface (3.9) --------------------------------------------------------------- */
typedef struct {
    REG ACR, KEYR, OPTKEYR, SR, CR, OPTCR;
} flash_t;
#define FLASH ((flash_t *)0x40023C00u)
#define FLASH_ACR_LATENCY_MASK 7u
#define FLASH_ACR_PRFTEN (1u << 8)
#define FLASH_ACR_ICEN (1u << 9)
#define FLASH_ACR_DCEN (1u << 10)

/* ---- GPIO (8.4) -------------------------------------------------------------------------- */
typedef struct {
    REG MODER, OTYPER, OSPEEDR, PUPDR, IDR, ODR, BSRR, LCKR, AFR[2];
} gpio_t;
#define GPIOA ((gpio_t *)0x40020000u)
#define GPIOB ((gpio_t *)0x40020400u)
#define GPIOC ((gpio_t *)0x40020800u)
#define GPIOD ((gpio_t *)0x40020C00u)
#define GPIOE ((gpio_t *)0x40021000u)
#define GPIO_MODE_AF 2u
#define GPIO_PULL_UP 1u
#define GPIO_PULL_DOWN 2u

/* ---- Timers: one layout for the advanced (TIM1/8, 17.4), general (TIM2-5, 18.4) and
 *      TIM9-14 (19.4) timers; a field a timer lacks is reserved there ---------------------- */
typedef struct {
    REG CR1, CR2, SMCR, DIER, SR, EGR, CCMR1, CCMR2, CCER, CNT, PSC, ARR, RCR, CCR1, CCR2, CCR3, CCR4, BDTR;
} tim_t;
#define TIM2 ((tim_t *)0x40000000u)   /* 32-bit: the microsecond clock and the wheel capture */
#define TIM3 ((tim_t *)0x40000400u)
#define TIM4 ((tim_t *)0x40000800u)
#define TIM12 ((tim_t *)0x40001800u)
#define TIM1 ((tim_t *)0x40010000u)
#define TIM8 ((tim_t *)0x40010400u)
#define TIM9 ((tim_t *)0x40014000u)
#define TIM_CR1_CEN (1u << 0)
#define TIM_CR1_ARPE (1u << 7)
#define TIM_EGR_UG (1u << 0)
#define TIM_DIER_CC1IE (1u << 1)
#define TIM_SR_CC1IF (1u << 1)
#define TIM_SR_CC1OF (1u << 9)
#define TIM_SMCR_SMS_ENC3 3u            /* encoder mode 3: both edges of TI1 and TI2 (x4) */
#define TIM_SMCR_SMS_EXT1 7u            /* external clock mode 1 */
#define TIM_SMCR_TS_TI1FP1 (5u << 4)
#define TIM_CCMR_CC1S_TI1 1u            /* channel 1 input on TI1 */
#define TIM_CCMR_CC2S_TI2 (1u << 8)     /* channel 2 input on TI2 */
#define TIM_CCMR_IC1F(f) ((uint32_t)(f) << 4)
#define TIM_CCMR_IC2F(f) ((uint32_t)(f) << 12)
#define TIM_CCMR_OC1M_PWM1 (6u << 4)
#define TIM_CCMR_OC1PE (1u << 3)
#define TIM_CCMR_OC2M_PWM1 (6u << 12)
#define TIM_CCMR_OC2PE (1u << 11)
#define TIM_CCER_CC1E (1u << 0)
#define TIM_CCER_CC1P (1u << 1)
#define TIM_CCER_CC2E (1u << 4)
#define TIM_CCER_CC2P (1u << 5)
#define TIM_CCER_CC3E (1u << 8)
#define TIM_CCER_CC4E (1u << 12)
#define TIM_BDTR_LOCK_2 (2u << 8)       /* lock level 2 (17.4.18): also OSSI, OSSR, CCxP frozen */
#define TIM_BDTR_OSSI (1u << 10)
#define TIM_BDTR_MOE (1u << 15)

/* ---- bxCAN (32.9) ------------------------------------------------------------------------ */
typedef struct {
    REG TIR, TDTR, TDLR, TDHR;
} can_tx_mailbox_t;
typedef struct {
    REG RIR, RDTR, RDLR, RDHR;
} can_rx_mailbox_t;
typedef struct {
    REG FR1, FR2;
} can_filter_t;
typedef struct {
    REG MCR, MSR, TSR, RF0R, RF1R, IER, ESR, BTR;
    REG RES0[88];
    can_tx_mailbox_t TX[3];
    can_rx_mailbox_t RX[2];
    REG RES1[12];
    REG FMR, FM1R, RES2, FS1R, RES3, FFA1R, RES4, FA1R;
    REG RES5[8];
    can_filter_t FB[28];
} can_t;
#define CAN1 ((can_t *)0x40006400u)
#define CAN_MCR_INRQ (1u << 0)
#define CAN_BTR_SILM (1u << 31)          /* silent: receives, never drives the bus (32.5.1) */
#define CAN_MCR_SLEEP (1u << 1)
#define CAN_MCR_TXFP (1u << 2)
#define CAN_MCR_ABOM (1u << 6)
#define CAN_MSR_INAK (1u << 0)
#define CAN_MSR_ERRI (1u << 2)
#define CAN_TSR_TME_SHIFT 26u
#define CAN_TIR_TXRQ (1u << 0)
#define CAN_RF0R_FMP0_MASK 3u
#define CAN_RF0R_FOVR0 (1u << 4)
#define CAN_RF0R_RFOM0 (1u << 5)
#define CAN_IER_TMEIE (1u << 0)
#define CAN_IER_FMPIE0 (1u << 1)
#define CAN_IER_EPVIE (1u << 9)
#define CAN_IER_BOFIE (1u << 10)
#define CAN_IER_ERRIE (1u << 15)
#define CAN_ESR_EPVF (1u << 1)
#define CAN_ESR_BOFF (1u << 2)
#define CAN_ESR_TEC_SHIFT 16u
#define CAN_ESR_REC_SHIFT 24u
#define CAN_FMR_FINIT (1u << 0)

/* ---- USART (30.6) ------------------------------------------------------------------------ */
typedef struct {
    REG SR, DR, BRR, CR1, CR2, CR3, GTPR;
} usart_t;
#define USART1 ((usart_t *)0x40011000u)
#define USART_SR_ORE (1u << 3)
#define USART_SR_RXNE (1u << 5)
#define USART_SR_TXE (1u << 7)
#define USART_CR1_RE (1u << 2)
#define USART_CR1_TE (1u << 3)
#define USART_CR1_RXNEIE (1u << 5)
#define USART_CR1_TXEIE (1u << 7)
#define USART_CR1_UE (1u << 13)

/* ---- Independent watchdog (21.4) ---------------------------------------------------------- */
typedef struct {
    REG KR, PR, RLR, SR;
} iwdg_t;
#define IWDG ((iwdg_t *)0x40003000u)
#define IWDG_KEY_START 0xCCCCu
#define IWDG_KEY_RELOAD 0xAAAAu
#define IWDG_KEY_ACCESS 0x5555u

/* ---- Debug support (38.16.4): stop the watchdog and the timers while halted --------------- */
#define DBGMCU_APB1_FZ (*(REG *)0xE0042008u)
#define DBGMCU_APB1_FZ_IWDG (1u << 12)
#define DBGMCU_APB2_FZ (*(REG *)0xE004200Cu)
#define DBGMCU_APB2_FZ_TIM1 (1u << 0)
#define DBGMCU_APB2_FZ_TIM8 (1u << 1)

/* ---- Cortex-M4 core peripherals (ARM v7-M ARM B3; PM0214 4.3-4.5) ------------------------- */
typedef struct {
    REG CTRL, LOAD, VAL, CALIB;
} systick_t;
#define SYSTICK ((systick_t *)0xE000E010u)
#define SYSTICK_CTRL_ENABLE (1u << 0)
#define SYSTICK_CTRL_TICKINT (1u << 1)
#define SYSTICK_CTRL_CLKSOURCE (1u << 2)
#define SYSTICK_CTRL_COUNTFLAG (1u << 16)
#define NVIC_ISER ((REG *)0xE000E100u)
#define NVIC_ICER ((REG *)0xE000E180u)
#define NVIC_IPR ((volatile uint8_t *)0xE000E400u)
#define SCB_VTOR (*(REG *)0xE000ED08u)
#define SCB_AIRCR (*(REG *)0xE000ED0Cu)
#define SCB_AIRCR_RESET (0x05FA0000u | (1u << 2))
#define SCB_SHPR3 (*(REG *)0xE000ED20u)
#define SCB_CFSR (*(REG *)0xE000ED28u)
#define SCB_HFSR (*(REG *)0xE000ED2Cu)
#define SCB_MMFAR (*(REG *)0xE000ED34u)
#define SCB_BFAR (*(REG *)0xE000ED38u)
#define SCB_CPACR (*(REG *)0xE000ED88u)

/* Interrupt numbers (RM0090 12.2, table 61) */
#define IRQ_CAN1_TX 19u
#define IRQ_CAN1_RX0 20u
#define IRQ_CAN1_SCE 22u
#define IRQ_TIM2 28u
#define IRQ_USART1 37u
#define IRQ_COUNT 82u

static inline void nvic_enable(uint32_t irq, uint8_t prio) {
    NVIC_IPR[irq] = (uint8_t)(prio << 4); /* 4 priority bits on the STM32F4 */
    NVIC_ISER[irq >> 5] = 1u << (irq & 31u);
}
static inline void nvic_disable(uint32_t irq) {
    NVIC_ICER[irq >> 5] = 1u << (irq & 31u);
    __asm__ volatile("dsb\n isb" ::: "memory");
}
static inline void irq_off(void) {
    __asm__ volatile("cpsid i" ::: "memory");
}
static inline void irq_on(void) {
    __asm__ volatile("cpsie i" ::: "memory");
}
/* PRIMASK set: WFI still wakes on a pending interrupt, which runs once PRIMASK is cleared */
static inline void wait_for_interrupt(void) {
    __asm__ volatile("wfi" ::: "memory");
}

#endif /* STM32F4_REGS_H */
