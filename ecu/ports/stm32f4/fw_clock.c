/**
 * @file fw_clock.c
 * @brief Clock tree (RM0090 6.3), the microsecond clock on TIM2 (18.4) and the SysTick step.
 *
 * Every ready flag is awaited with a time-out: a crystal that does not start leaves the chip on
 * its 16 MHz internal oscillator (reported in EcuIdent.ClockFallback); a clock controller that
 * never answers at all (HSIRDY reads 0, impossible on silicon: HSI runs from reset) is an
 * emulator's, whose core runs at the machine's fixed 168 MHz. TIM2's input clock is then not
 * taken from the tree but measured against the core clock (SysTick) at start, so the
 * microsecond clock is right on the board, on the fallback and in the emulator alike.
 */
#include "board.h"
#include "fw.h"
#include "stm32f4_regs.h"

#define READY_SPINS 200000u    /* > 5 ms at 16 MHz; HSE starts in ~2 ms */

static volatile uint32_t ticks;

static bool wait_set(REG *reg, uint32_t mask, uint32_t want) {
    for (uint32_t i = 0u; i < READY_SPINS; i++) {
        if ((*reg & mask) == want) {
            return true;
        }
    }
    return false;
}

void fw_clock_init(fw_clock_t *c) {
    c->core_hz = BOARD_HSI_HZ;
    c->apb1_hz = BOARD_HSI_HZ;
    c->apb2_hz = BOARD_HSI_HZ;
    c->tim_apb2_hz = BOARD_HSI_HZ;
    c->tim2_hz = BOARD_HSI_HZ;
    c->source = FW_CLOCK_HSI;
    if ((RCC->CR & RCC_CR_HSIRDY) == 0u) {
        c->source = FW_CLOCK_UNMODELLED;
        c->core_hz = BOARD_CORE_HZ;
        c->apb1_hz = BOARD_CORE_HZ / 4u;
        c->apb2_hz = BOARD_CORE_HZ / 2u;
        c->tim_apb2_hz = BOARD_CORE_HZ;
        return;
    }
    RCC->CR |= RCC_CR_HSEON;
    if (!wait_set(&RCC->CR, RCC_CR_HSERDY, RCC_CR_HSERDY)) {
        RCC->CR &= ~RCC_CR_HSEON;
        return;
    }
    /* 5 wait states at 168 MHz and 2.7-3.6 V (3.5.1, table 10), caches and prefetch on */
    FLASH->ACR = FLASH_ACR_LATENCY_5WS | FLASH_ACR_PRFTEN | FLASH_ACR_ICEN | FLASH_ACR_DCEN;
    RCC->PLLCFGR = BOARD_PLL_M | (BOARD_PLL_N << 6) | (0u << 16) /* P = 2 */ | RCC_PLLCFGR_SRC_HSE |
                   (BOARD_PLL_Q << 24);
    RCC->CR |= RCC_CR_PLLON;
    if (!wait_set(&RCC->CR, RCC_CR_PLLRDY, RCC_CR_PLLRDY)) {
        RCC->CR &= ~(RCC_CR_PLLON | RCC_CR_HSEON);
        FLASH->ACR = FLASH_ACR_PRFTEN | FLASH_ACR_ICEN | FLASH_ACR_DCEN;
        return;
    }
    /* AHB 168, APB1 42 (max 42), APB2 84 (max 84): prescalers before the switch */
    RCC->CFGR = RCC_CFGR_PPRE1_DIV4 | RCC_CFGR_PPRE2_DIV2;
    RCC->CFGR |= RCC_CFGR_SW_PLL;
    if (!wait_set(&RCC->CFGR, RCC_CFGR_SWS_MASK, RCC_CFGR_SWS_PLL)) {
        RCC->CFGR = 0u; /* back on HSI, prescalers 1 */
        RCC->CR &= ~(RCC_CR_PLLON | RCC_CR_HSEON);
        return;
    }
    c->source = FW_CLOCK_PLL_HSE;
    c->core_hz = BOARD_CORE_HZ;
    c->apb1_hz = BOARD_CORE_HZ / 4u;
    c->apb2_hz = BOARD_CORE_HZ / 2u;
    c->tim_apb2_hz = BOARD_CORE_HZ; /* an APB prescaler > 1 doubles the timers' clock (6.2) */
}

/* SysTick's value and TIM2's count at one moment: SysTick read before and after TIM2, retried
 * until the two lie within `close` core cycles (10 us; a few instructions on the chip). */
static void read_pair(uint32_t close, uint32_t *systick_val, uint32_t *tim2_cnt) {
    for (;;) {
        const uint32_t a = SYSTICK->VAL;
        const uint32_t t = TIM2->CNT;
        const uint32_t b = SYSTICK->VAL;
        if (b <= a && a - b <= close) { /* SysTick counts down */
            *systick_val = a - (a - b) / 2u;
            *tim2_cnt = t;
            return;
        }
    }
}

void fw_time_init(fw_clock_t *c) {
    RCC->APB1ENR |= RCC_APB1ENR_TIM2;
    (void)RCC->APB1ENR;
    TIM2->CR1 = 0u;
    TIM2->PSC = 0u;
    TIM2->ARR = 0xFFFFFFFFu;
    TIM2->EGR = TIM_EGR_UG;
    TIM2->CR1 = TIM_CR1_CEN;
    /* TIM2 ticks over 10 ms of core clock. SysTick's current value, not its wrap flag (which
     * an emulator may raise late), read together with TIM2 (read_pair): an emulator descheduled
     * between the two counters would skew the ratio. */
    SYSTICK->CTRL = 0u;
    SYSTICK->LOAD = 0x00FFFFFFu;
    SYSTICK->VAL = 0u;
    SYSTICK->CTRL = SYSTICK_CTRL_CLKSOURCE | SYSTICK_CTRL_ENABLE;
    while (SYSTICK->VAL == 0u) { /* the reload to 0xFFFFFF */
    }
    const uint32_t window = c->core_hz / 100u; /* 10 ms, < 2^24 cycles up to 1.6 GHz */
    uint32_t v0;
    uint32_t t0;
    uint32_t v1;
    uint32_t t1;
    const uint32_t close = c->core_hz / 100000u;
    read_pair(close, &v0, &t0);
    do {
        read_pair(close, &v1, &t1);
    } while (v1 <= v0 && v0 - v1 < window);
    SYSTICK->CTRL = 0u;
    const uint32_t cycles = v1 <= v0 ? v0 - v1 : window;
    const uint64_t hz = (uint64_t)(t1 - t0) * c->core_hz / (cycles > 0u ? cycles : 1u);
    /* whole MHz: 84 on the board (APB1 42 MHz x 2), 16 on the fallback */
    uint32_t mhz = (uint32_t)((hz + 500000u) / 1000000u);
    if (mhz == 0u) {
        mhz = 1u;
    }
    c->tim2_hz = mhz * 1000000u;
    TIM2->CR1 = 0u;
    TIM2->PSC = mhz - 1u;
    TIM2->EGR = TIM_EGR_UG; /* the prescaler takes effect at an update; CNT restarts at 0 */
    TIM2->SR = 0u;
    TIM2->CR1 = TIM_CR1_CEN;
}

uint32_t fw_micros(void) {
    return TIM2->CNT;
}

void SysTick_Handler(void) {
    ticks++;
}

void fw_tick_start(const fw_clock_t *c) {
    SCB_SHPR3 = (SCB_SHPR3 & 0x00FFFFFFu) | (0x40u << 24); /* SysTick priority 4: below CAN and serial */
    SYSTICK->LOAD = c->core_hz / BOARD_STEP_HZ - 1u;
    SYSTICK->VAL = 0u;
    SYSTICK->CTRL = SYSTICK_CTRL_CLKSOURCE | SYSTICK_CTRL_TICKINT | SYSTICK_CTRL_ENABLE;
}

void fw_wait_step(void) {
    static uint32_t seen;
    while (ticks == seen) {
        wait_for_interrupt();
    }
    seen = ticks;
}
