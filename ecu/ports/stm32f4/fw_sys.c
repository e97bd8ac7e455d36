/**
 * @file fw_sys.c
 * @brief Reset cause (RCC_CSR, RM0090 6.3.21), the independent watchdog (21), and the hard-fault
 *        handler: outputs off first, then a mark in RAM that survives the reset, then the reset.
 */
#include "board.h"
#include "fw.h"
#include "stm32f4_regs.h"

#define FAULT_MARK 0x48415244u /* "HARD" */

/* Not zeroed at start (.noinit): a mark and its complement, so power-up garbage is not a mark. */
__attribute__((section(".noinit"))) static volatile uint32_t fault_mark[2];

td_reset_cause_t fw_reset_cause(void) {
    const uint32_t csr = RCC->CSR;
    const bool faulted = fault_mark[0] == FAULT_MARK && fault_mark[1] == ~FAULT_MARK;
    fault_mark[0] = 0u;
    fault_mark[1] = 0u;
    RCC->CSR = csr | RCC_CSR_RMVF;
    if (faulted) {
        return TD_RESET_HARD_FAULT; /* a software reset the fault handler asked for */
    }
    if ((csr & (RCC_CSR_IWDGRSTF | RCC_CSR_WWDGRSTF)) != 0u) {
        return TD_RESET_WATCHDOG;
    }
    if ((csr & RCC_CSR_SFTRSTF) != 0u) {
        return TD_RESET_SOFTWARE;
    }
    if ((csr & RCC_CSR_PORRSTF) != 0u) {
        return TD_RESET_POWER_ON; /* power-on also sets BORRSTF and PINRSTF */
    }
    if ((csr & RCC_CSR_BORRSTF) != 0u) {
        return TD_RESET_BROWN_OUT;
    }
    if ((csr & RCC_CSR_PINRSTF) != 0u) {
        return TD_RESET_PIN; /* every internal reset also pulls NRST: checked last */
    }
    return TD_RESET_UNKNOWN; /* an emulator's clock controller reads 0 */
}

void fw_watchdog_start(void) {
    DBGMCU_APB1_FZ |= DBGMCU_APB1_FZ_IWDG; /* halted by a debugger: no reset */
    IWDG->KR = IWDG_KEY_START;             /* also starts LSI */
    IWDG->KR = IWDG_KEY_ACCESS;
    IWDG->PR = 3u;    /* /32: 1 kHz at LSI's nominal 32 kHz */
    IWDG->RLR = 100u; /* 100 ms nominal, 68..188 ms over LSI's 17..47 kHz: 7 missed steps at least */
    IWDG->KR = IWDG_KEY_RELOAD;
}

void fw_watchdog_feed(void) {
    IWDG->KR = IWDG_KEY_RELOAD;
}

/* The stack may be what failed: the handler starts on a fresh one at the top of RAM, turns the
 * outputs off with plain stores, marks the cause and resets. */
extern uint32_t _estack;
void hard_fault_c(void);

__attribute__((naked)) void HardFault_Handler(void) {
    __asm__ volatile("ldr r0, =_estack\n"
                     "msr msp, r0\n"
                     "b hard_fault_c\n");
}

__attribute__((used, noreturn)) void hard_fault_c(void) {
    fw_io_safe();
    fault_mark[0] = FAULT_MARK;
    fault_mark[1] = ~FAULT_MARK;
    __asm__ volatile("dsb" ::: "memory");
    SCB_AIRCR = SCB_AIRCR_RESET;
    for (;;) {
    }
}
