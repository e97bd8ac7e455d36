/**
 * @file fw_io.c
 * @brief The machine's I/O on the timers: the wheel encoder on a TIM2 input capture (count and
 *        edge time on the microsecond clock itself), the meter encoders in TIM3/TIM4 encoder
 *        mode, the fan tachometers as TIM9/TIM12 external clocks, the four PWM outputs on TIM8.
 *        RM0090 17 (TIM8), 18 (TIM2-4), 19 (TIM9/12), 8 (GPIO).
 *
 * The PWM timer is TIM8 or TIM1 and the lower fan's counter TIM12 or TIM8, as the board header
 * says (BOARD_PWM_TIM, BOARD_FAN_LO_TIM).
 *
 * Safe state: the PWM timer's outputs are enabled (CCxE) with OSSI = 1 and idle level low, so
 * with the main output enable MOE cleared they are driven low, not left floating. MOE is cleared
 * at reset (and by fw_io_safe() on a hard fault or a lost crystal); main.c sets it only after
 * the first valid command on a clock from the crystal. BDTR is locked at level 2 (OSSI and the
 * polarities cannot be changed by a stray write until reset). A debugger halting the core stops
 * the timer (DBGMCU DBG_TIMx_STOP) and the hardware then disables the outputs as if MOE were
 * cleared: driven low (RM0090 17.3.20). The break input is not used: the boards have no fault
 * line from the motor drivers, and BKIN's pins are taken by the pin maps.
 */
#include "board.h"
#include "fw.h"
#include "stm32f4_regs.h"
#include "td_capture.h"

#if BOARD_PWM_TIM == 8u
#define PWM TIM8
#define PWM_RCC_EN RCC_APB2ENR_TIM8
#define PWM_DBG_STOP DBGMCU_APB2_FZ_TIM8
#elif BOARD_PWM_TIM == 1u
#define PWM TIM1
#define PWM_RCC_EN RCC_APB2ENR_TIM1
#define PWM_DBG_STOP DBGMCU_APB2_FZ_TIM1
#else
#error "BOARD_PWM_TIM: 8 or 1 (an advanced timer: MOE, OSSI)"
#endif
#if BOARD_FAN_LO_TIM == 12u
#define FAN_LO TIM12
#define FAN_LO_APB1_EN RCC_APB1ENR_TIM12
#define FAN_LO_APB2_EN 0u
#elif BOARD_FAN_LO_TIM == 8u && BOARD_PWM_TIM != 8u
#define FAN_LO TIM8
#define FAN_LO_APB1_EN 0u
#define FAN_LO_APB2_EN RCC_APB2ENR_TIM8
#else
#error "BOARD_FAN_LO_TIM: 12, or 8 when the PWM is on TIM1"
#endif

static gpio_t *const ports[5] = { GPIOA, GPIOB, GPIOC, GPIOD, GPIOE };

static td_wheel_capture_t wheel;
static td_ctr_t meter[2], fan[2];
static uint32_t pwm_top;

void fw_pin_af(uint32_t port, uint32_t pin, uint32_t af, uint32_t pull) {
    gpio_t *g = ports[port];
    g->MODER = (g->MODER & ~(3u << (2u * pin))) | (GPIO_MODE_AF << (2u * pin));
    g->PUPDR = (g->PUPDR & ~(3u << (2u * pin))) | (pull << (2u * pin));
    g->AFR[pin >> 3] = (g->AFR[pin >> 3] & ~(0xFu << (4u * (pin & 7u)))) | (af << (4u * (pin & 7u)));
}

void TIM2_IRQHandler(void) {
    const uint32_t sr = TIM2->SR;
    if ((sr & TIM_SR_CC1IF) != 0u) {
        const uint32_t ccr = TIM2->CCR1; /* reading CCR1 clears CC1IF */
        TIM2->SR = ~TIM_SR_CC1OF;         /* rc_w0: clear the overcapture flag only */
        td_wheel_capture_edge(&wheel, ccr, (sr & TIM_SR_CC1OF) != 0u);
    }
}

static void encoder_init(tim_t *t, bool invert) {
    t->CR1 = 0u;
    t->SMCR = TIM_SMCR_SMS_ENC3;
    t->CCMR1 = TIM_CCMR_CC1S_TI1 | TIM_CCMR_CC2S_TI2 | TIM_CCMR_IC1F(BOARD_INPUT_FILTER) |
               TIM_CCMR_IC2F(BOARD_INPUT_FILTER);
    t->CCER = invert ? TIM_CCER_CC1P : 0u; /* TI1 inverted: the count runs the other way */
    t->ARR = 0xFFFFu;
    t->CNT = 0u;
    t->CR1 = TIM_CR1_CEN;
}

static void tach_init(tim_t *t) {
    t->CR1 = 0u;
    t->CCMR1 = TIM_CCMR_CC1S_TI1 | TIM_CCMR_IC1F(BOARD_INPUT_FILTER);
    t->CCER = 0u; /* rising edges */
    t->SMCR = TIM_SMCR_TS_TI1FP1 | TIM_SMCR_SMS_EXT1;
    t->ARR = 0xFFFFu;
    t->CNT = 0u;
    t->CR1 = TIM_CR1_CEN;
}

void fw_io_outputs_off(void) {
    RCC->AHB1ENR |= RCC_AHB1ENR_GPIOA | RCC_AHB1ENR_GPIOB | RCC_AHB1ENR_GPIOC | RCC_AHB1ENR_GPIOD |
                    RCC_AHB1ENR_GPIOE;
    RCC->APB2ENR |= PWM_RCC_EN;
    (void)RCC->APB2ENR;
    DBGMCU_APB2_FZ |= PWM_DBG_STOP; /* halted by a debugger: counter stopped, outputs low */
    PWM->CR1 = 0u;
    PWM->CCR1 = PWM->CCR2 = PWM->CCR3 = PWM->CCR4 = 0u;
    PWM->CCMR1 = TIM_CCMR_OC1M_PWM1 | TIM_CCMR_OC1PE | TIM_CCMR_OC2M_PWM1 | TIM_CCMR_OC2PE;
    PWM->CCMR2 = TIM_CCMR_OC1M_PWM1 | TIM_CCMR_OC1PE | TIM_CCMR_OC2M_PWM1 | TIM_CCMR_OC2PE;
    PWM->CCER = TIM_CCER_CC1E | TIM_CCER_CC2E | TIM_CCER_CC3E | TIM_CCER_CC4E; /* active high */
    /* MOE = 0: outputs at their idle level (low); OSSI and the polarities locked until reset */
    PWM->BDTR = TIM_BDTR_OSSI | TIM_BDTR_LOCK_2;
    /* the outputs are low before their pins leave the reset state */
    PIN_AF(PIN_PWM_METER_UP, GPIO_PULL_DOWN);
    PIN_AF(PIN_PWM_METER_LO, GPIO_PULL_DOWN);
    PIN_AF(PIN_PWM_FAN_UP, GPIO_PULL_DOWN);
    PIN_AF(PIN_PWM_FAN_LO, GPIO_PULL_DOWN);
}

static void pwm_init(const fw_clock_t *c) {
    PWM->CR1 = 0u;
    pwm_top = c->tim_apb2_hz / BOARD_PWM_HZ;
    PWM->PSC = 0u;
    PWM->ARR = pwm_top - 1u;
    PWM->EGR = TIM_EGR_UG;
    PWM->CR1 = TIM_CR1_ARPE | TIM_CR1_CEN;
}

void fw_io_init(const fw_clock_t *c) {
    RCC->APB1ENR |= RCC_APB1ENR_TIM3 | RCC_APB1ENR_TIM4 | FAN_LO_APB1_EN;
    RCC->APB2ENR |= RCC_APB2ENR_TIM9 | FAN_LO_APB2_EN;
    (void)RCC->APB2ENR;
    pwm_init(c);
    PIN_AF(PIN_WHEEL, GPIO_PULL_UP); /* the paper's encoder is NPN open collector */
    PIN_AF(PIN_METER_UP_A, GPIO_PULL_UP);
    PIN_AF(PIN_METER_UP_B, GPIO_PULL_UP);
    PIN_AF(PIN_METER_LO_A, GPIO_PULL_UP);
    PIN_AF(PIN_METER_LO_B, GPIO_PULL_UP);
    PIN_AF(PIN_FAN_UP_TACH, GPIO_PULL_UP);
    PIN_AF(PIN_FAN_LO_TACH, GPIO_PULL_UP);
    encoder_init(TIM3, BOARD_METER_UPPER_INVERT != 0u);
    encoder_init(TIM4, BOARD_METER_LOWER_INVERT != 0u);
    tach_init(TIM9);
    tach_init(FAN_LO);
    td_ctr_init(&meter[0], 16u, (uint16_t)TIM3->CNT);
    td_ctr_init(&meter[1], 16u, (uint16_t)TIM4->CNT);
    td_ctr_init(&fan[0], 16u, (uint16_t)TIM9->CNT);
    td_ctr_init(&fan[1], 16u, (uint16_t)FAN_LO->CNT);
    /* the wheel: TIM2 channel 1 captures the microsecond clock on each rising edge */
    td_wheel_capture_init(&wheel);
    TIM2->CCMR1 = TIM_CCMR_CC1S_TI1 | TIM_CCMR_IC1F(BOARD_INPUT_FILTER);
    TIM2->CCER = TIM_CCER_CC1E;
    TIM2->SR = 0u;
    TIM2->DIER = TIM_DIER_CC1IE;
    nvic_enable(IRQ_TIM2, 1u);
}

void fw_io_read(td_io_in_t *in) {
    nvic_disable(IRQ_TIM2); /* count and edge time together (td_port.h) */
    in->wheel_count = wheel.count;
    in->wheel_edge_us = wheel.edge_us;
    in->wheel_edge_valid = wheel.have_edge ? 1u : 0u;
    nvic_enable(IRQ_TIM2, 1u);
    in->meter_count[0] = td_ctr_update_signed(&meter[0], (uint16_t)TIM3->CNT);
    in->meter_count[1] = td_ctr_update_signed(&meter[1], (uint16_t)TIM4->CNT);
    in->fan_count[0] = td_ctr_update_up(&fan[0], (uint16_t)TIM9->CNT);
    in->fan_count[1] = td_ctr_update_up(&fan[1], (uint16_t)FAN_LO->CNT);
}

static uint32_t compare(float duty) {
    const float v = duty * (float)pwm_top + 0.5f;
    if (!(v >= 1.0f)) {
        return 0u; /* also NaN */
    }
    return v >= (float)pwm_top ? pwm_top : (uint32_t)v; /* CCR = ARR + 1: 100 % */
}

void fw_io_write(const td_io_out_t *out) {
    PWM->CCR1 = compare(out->meter_duty[0]);
    PWM->CCR2 = compare(out->meter_duty[1]);
    PWM->CCR3 = compare(out->fan_duty[0]);
    PWM->CCR4 = compare(out->fan_duty[1]);
}

void fw_io_enable(bool on) {
    if (on) {
        PWM->BDTR |= TIM_BDTR_MOE;
    } else {
        PWM->BDTR &= ~TIM_BDTR_MOE;
    }
}

void fw_io_safe(void) {
    PWM->BDTR = TIM_BDTR_OSSI | TIM_BDTR_LOCK_2; /* MOE = 0 (the lock leaves MOE writable) */
    PWM->CCR1 = 0u;
    PWM->CCR2 = 0u;
    PWM->CCR3 = 0u;
    PWM->CCR4 = 0u;
}
