/**
 * @file fw_uart.c
 * @brief USART1 (RM0090 30) as the SLCAN serial link: bytes in by the receive interrupt into a
 *        lock-free ring, bytes out from a ring by the transmit-empty interrupt.
 */
#include "board.h"
#include "fw.h"
#include "stm32f4_regs.h"
#include "td_ring.h"

static td_byte_ring_t rx_ring; /* producer: USART1 interrupt; consumer: main loop */
static td_byte_ring_t tx_ring; /* producer: main loop; consumer: USART1 interrupt or the pump */

void fw_uart_init(const fw_clock_t *c, uint32_t baud) {
    td_byte_ring_init(&rx_ring);
    td_byte_ring_init(&tx_ring);
    RCC->AHB1ENR |= RCC_AHB1ENR_GPIOA;
    RCC->APB2ENR |= RCC_APB2ENR_USART1;
    (void)RCC->APB2ENR;
    gpio_t *const a = GPIOA;
    a->MODER = (a->MODER & ~(0xFu << 18)) | (GPIO_MODE_AF << 18) | (GPIO_MODE_AF << 20);
    a->PUPDR = (a->PUPDR & ~(3u << 20)) | (GPIO_PULL_UP << 20); /* RX idles high */
    a->AFR[1] = (a->AFR[1] & ~0xFF0u) | 0x770u;                 /* PA9, PA10: AF7 */
    /* 16x oversampling: BRR = f / baud with 4 fraction bits (30.3.4) */
    USART1->BRR = (c->apb2_hz + baud / 2u) / baud;
    USART1->CR1 = USART_CR1_UE | USART_CR1_TE | USART_CR1_RE | USART_CR1_RXNEIE;
    nvic_enable(IRQ_USART1, 2u);
}

void USART1_IRQHandler(void) {
    const uint32_t sr = USART1->SR;
    if ((sr & (USART_SR_RXNE | USART_SR_ORE)) != 0u) {
        (void)td_byte_ring_push(&rx_ring, (uint8_t)USART1->DR); /* reading DR clears both */
    }
    if ((sr & USART_SR_TXE) != 0u && (USART1->CR1 & USART_CR1_TXEIE) != 0u) {
        uint8_t b;
        if (td_byte_ring_pop(&tx_ring, &b)) {
            USART1->DR = b;
        } else {
            USART1->CR1 &= ~USART_CR1_TXEIE;
        }
    }
}

bool fw_uart_getc(uint8_t *b) {
    return td_byte_ring_pop(&rx_ring, b);
}

void fw_uart_wait(void) {
    /* masked: a byte arriving between the look and the sleep still wakes it (pending) */
    irq_off();
    if (td_byte_ring_count(&rx_ring) == 0u) {
        wait_for_interrupt();
    }
    irq_on();
}

bool fw_uart_write(const uint8_t *b, uint32_t n) {
    return td_byte_ring_write(&tx_ring, b, n);
}

void fw_uart_pump(void) {
    nvic_disable(IRQ_USART1);
    uint8_t b;
    /* what the transmitter takes now; an emulator's takes everything at once */
    while ((USART1->SR & USART_SR_TXE) != 0u && td_byte_ring_pop(&tx_ring, &b)) {
        USART1->DR = b;
    }
    if (td_byte_ring_count(&tx_ring) > 0u) {
        USART1->CR1 |= USART_CR1_TXEIE;
    }
    nvic_enable(IRQ_USART1, 2u);
}
