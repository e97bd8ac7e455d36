/**
 * @file startup.c
 * @brief Reset handler and vector table of the STM32F405/407 (RM0090 12.2, table 61), written for
 *        topdress. Reset: outputs are in their reset state (timers off, pins inputs); copy .data,
 *        zero .bss, enable the FPU (the core uses single-precision floats), run main().
 */
#include <stdint.h>
#include "stm32f4_regs.h"

extern uint32_t _sidata, _sdata, _edata, _sbss, _ebss, _estack;
int main(void);
void Reset_Handler(void);
void Default_Handler(void);

void HardFault_Handler(void);
void SysTick_Handler(void);
void TIM2_IRQHandler(void);
void USART1_IRQHandler(void);
void CAN1_TX_IRQHandler(void);
void CAN1_RX0_IRQHandler(void);
void CAN1_SCE_IRQHandler(void);
void NMI_Handler(void);

void Reset_Handler(void) {
    SCB_CPACR |= 0xFu << 20; /* CP10, CP11: full access to the FPU */
    __asm__ volatile("dsb\n isb" ::: "memory");
    for (uint32_t *s = &_sidata, *d = &_sdata; d < &_edata;) {
        *d++ = *s++;
    }
    /* the linker's bounds of one section, not two objects */
    /* cppcheck-suppress comparePointers */
    for (uint32_t *d = &_sbss; d < &_ebss;) {
        *d++ = 0u;
    }
    (void)main();
    for (;;) {
    }
}

/* Anything unexpected: the hard-fault path (outputs off, recorded, reset); a branch, not a
 * call, so the hard-fault handler sees this exception's own EXC_RETURN and frame. */
__attribute__((naked)) void Default_Handler(void) {
    __asm__ volatile("b HardFault_Handler\n");
}

typedef void (*vector_t)(void);

#define IRQ(n) [16u + (n)]

__attribute__((section(".isr_vector"), used)) static const vector_t vectors[16u + IRQ_COUNT] = {
    [0] = (vector_t)(uintptr_t)&_estack,
    [1] = Reset_Handler,
    [2] = NMI_Handler,         /* the clock security system: the crystal lost (fw_sys.c) */
    [3] = HardFault_Handler,
    [4] = Default_Handler,     /* MemManage */
    [5] = Default_Handler,     /* BusFault */
    [6] = Default_Handler,     /* UsageFault */
    [11] = Default_Handler,    /* SVCall */
    [12] = Default_Handler,    /* DebugMonitor */
    [14] = Default_Handler,    /* PendSV */
    [15] = SysTick_Handler,
    IRQ(IRQ_TIM2) = TIM2_IRQHandler,
#if defined(FW_QEMU) /* the emulator build's transport: SLCAN on USART1 */
    IRQ(IRQ_USART1) = USART1_IRQHandler,
#else
    IRQ(IRQ_CAN1_TX) = CAN1_TX_IRQHandler,
    IRQ(IRQ_CAN1_RX0) = CAN1_RX0_IRQHandler,
    IRQ(IRQ_CAN1_SCE) = CAN1_SCE_IRQHandler,
#endif
};
