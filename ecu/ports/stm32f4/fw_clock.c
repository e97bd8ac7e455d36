/**
 * @file fw_clock.c
 * @brief Clock tree (RM0090 6.3), the microsecond clock on TIM2 (18.4) and the SysTick step.
 *
 * The set-up starts from the clock controller's reset state whatever ran before (a bootloader,
 * a debugger): HSI selected, PLL and HSE off, clock interrupts off. Every ready flag is awaited
 * with a time-out: a crystal or PLL that does not start leaves the chip on its 16 MHz internal
 * oscillator (FW_CLOCK_HSI: the ECU then stays silent on the bus with its outputs off, main.c).
 * With the PLL running the clock security system watches the crystal: its loss raises the NMI
 * (fw_sys.c). The PLL factors come from the board's crystal (board.h, checked at compile time).
 *
 * The emulator build (FW_QEMU) has no clock set-up at all: QEMU models no clock controller and
 * runs the core at its fixed 168 MHz. TIM2's input clock is not taken from the tree but measured
 * against the core clock (SysTick) at start, so the microsecond clock is right either way.
 */
#include "board.h"
#include "fw.h"
#include "stm32f4_regs.h"

#define READY_SPINS 200000u    /* > 5 ms at 16 MHz; HSE starts in ~2 ms */
#define QEMU_CORE_HZ 168000000u /* netduinoplus2's SYSCLK */

static volatile uint32_t ticks;

static void set_rates(fw_clock_t *c, uint32_t core_hz, uint32_t apb1_div, uint32_t apb2_div) {
    c->core_hz = core_hz;
    c->apb1_hz = core_hz / apb1_div;
    c->apb2_hz = core_hz / apb2_div;
    c->tim_apb2_hz = apb2_div > 1u ? 2u * c->apb2_hz : c->apb2_hz; /* 6.2: x2 behind a prescaler */
    c->tim2_hz = apb1_div > 1u ? 2u * c->apb1_hz : c->apb1_hz;
}

#if defined(FW_QEMU)

void fw_clock_init(fw_clock_t *c) {
    set_rates(c, QEMU_CORE_HZ, 4u, 2u);
    c->source = FW_CLOCK_EMULATOR;
}

#else

static bool wait_set(const REG *reg, uint32_t mask, uint32_t want) {
    for (uint32_t i = 0u; i < READY_SPINS; i++) {
        if ((*reg & mask) == want) {
            return true;
        }
    }
    return false;
}

/* The reset state of the clock tree (6.3.1-6.3.4), from any state a bootloader left. */
static void clock_reset_state(void) {
    RCC->CR |= RCC_CR_HSION;
    (void)wait_set(&RCC->CR, RCC_CR_HSIRDY, RCC_CR_HSIRDY);
    RCC->CFGR = 0u; /* SYSCLK = HSI, every prescaler 1 */
    (void)wait_set(&RCC->CFGR, RCC_CFGR_SWS_MASK, RCC_CFGR_SWS_HSI);
    RCC->CR &= ~(RCC_CR_PLLON | RCC_CR_CSSON | RCC_CR_HSEON);
    (void)wait_set(&RCC->CR, RCC_CR_PLLRDY, 0u);
    RCC->CR &= ~RCC_CR_HSEBYP; /* writable only with HSE off */
    RCC->PLLCFGR = RCC_PLLCFGR_RESET;
    RCC->CIR = RCC_CIR_CLEAR_ALL; /* interrupts off, flags cleared */
    FLASH->ACR = FLASH_ACR_PRFTEN | FLASH_ACR_ICEN | FLASH_ACR_DCEN; /* 0 WS: right for 16 MHz */
}

void fw_clock_init(fw_clock_t *c) {
    clock_reset_state();
    set_rates(c, BOARD_HSI_HZ, 1u, 1u);
    c->source = FW_CLOCK_HSI;
    RCC->CR |= RCC_CR_HSEON;
    if (!wait_set(&RCC->CR, RCC_CR_HSERDY, RCC_CR_HSERDY)) {
        RCC->CR &= ~RCC_CR_HSEON;
        return;
    }
    FLASH->ACR = BOARD_FLASH_WS | FLASH_ACR_PRFTEN | FLASH_ACR_ICEN | FLASH_ACR_DCEN;
    /* the P field is 0 for P = 2: kept in the sum so every board's divider is written the same way */
    /* cppcheck-suppress badBitmaskCheck */
    RCC->PLLCFGR = BOARD_PLL_M | (BOARD_PLL_N << RCC_PLLCFGR_N_SHIFT) |
                   ((BOARD_PLL_P / 2u - 1u) << RCC_PLLCFGR_P_SHIFT) | RCC_PLLCFGR_SRC_HSE |
                   (BOARD_PLL_Q << RCC_PLLCFGR_Q_SHIFT);
    RCC->CR |= RCC_CR_PLLON;
    if (!wait_set(&RCC->CR, RCC_CR_PLLRDY, RCC_CR_PLLRDY)) {
        RCC->CR &= ~(RCC_CR_PLLON | RCC_CR_HSEON);
        FLASH->ACR = FLASH_ACR_PRFTEN | FLASH_ACR_ICEN | FLASH_ACR_DCEN;
        return;
    }
    /* prescalers before the switch: APB1 /4, APB2 /2 (board.h checks their limits) */
    RCC->CFGR = RCC_CFGR_PPRE1_DIV4 | RCC_CFGR_PPRE2_DIV2;
    RCC->CFGR |= RCC_CFGR_SW_PLL;
    if (!wait_set(&RCC->CFGR, RCC_CFGR_SWS_MASK, RCC_CFGR_SWS_PLL)) {
        RCC->CFGR = 0u; /* back on HSI, prescalers 1 */
        RCC->CR &= ~(RCC_CR_PLLON | RCC_CR_HSEON);
        return;
    }
    RCC->CR |= RCC_CR_CSSON; /* a crystal lost from now on: NMI (fw_sys.c) */
    c->source = FW_CLOCK_PLL_HSE;
    set_rates(c, BOARD_CORE_HZ, 4u, 2u);
}

#endif /* FW_QEMU */

/* SysTick's value and TIM2's count at one moment: SysTick read before and after TIM2, retried
 * until the two lie within `close` core cycles (10 us; a few instructions on the chip). */
static void read_pair(uint32_t close, uint32_t *systick_val, uint32_t *tim2_cnt) {
    for (;;) {
        const uint32_t a = SYSTICK->VAL;
        const uint32_t t = TIM2->CNT;
        const uint32_t b = SYSTICK->VAL;
        /* a and b are two reads of a volatile counter, not one value twice */
        /* cppcheck-suppress [knownConditionTrueFalse, unsignedPositive] */
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
    /* whole MHz: 80 on the board (APB1 40 MHz x 2), 16 on the fallback */
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

/* The tick is checked with interrupts masked and WFI entered still masked: a SysTick between
 * the check and the WFI stays pending and ends the WFI at once instead of being slept through
 * (the lost wakeup that made an occasional 20 ms step). */
void fw_wait_step(void) {
    static uint32_t seen;
    irq_off();
    while (ticks == seen) {
        wait_for_interrupt();
        irq_on(); /* the pending SysTick runs here */
        irq_off();
    }
    seen = ticks;
    irq_on();
}
