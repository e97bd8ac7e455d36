/**
 * @file fw_sys.c
 * @brief Reset cause (RCC_CSR, RM0090 6.3.21), the independent watchdog (21), the hard-fault
 *        handler and the clock security system's NMI: outputs off first, then a record in RAM
 *        that survives the reset (.noinit), then the reset.
 *
 * The record holds the fault status registers (CFSR, HFSR, MMFAR, BFAR; ARMv7-M B3.2.15-19) and
 * the stacked PC and LR of the faulting code, so the fault can be found in the map file after
 * the reboot; main.c sends it in EcuFaultRecord.
 */
#include "board.h"
#include "fw.h"
#include "stm32f4_regs.h"

#define FAULT_MARK 0x48415244u /* "HARD" */
#define KEPT_MARK 0x4B455054u  /* "KEPT": a record to send, not a hard fault at this reset */

/* Not zeroed at start (.noinit): a mark and its complement, so power-up garbage is not a mark. */
typedef struct {
    uint32_t mark, mark_inv;
    fw_fault_record_t rec;
} kept_t;
__attribute__((section(".noinit"))) static volatile kept_t kept;
static fw_fault_record_t last; /* the record of the last reset, taken at start */

static bool kept_valid(uint32_t mark) {
    return kept.mark == mark && kept.mark_inv == ~mark;
}

void fw_fault_record(fw_fault_record_t *r) {
    *r = last;
}

td_reset_cause_t fw_reset_cause(void) {
    const uint32_t csr = RCC->CSR;
    const bool faulted = kept_valid(FAULT_MARK);
    if (faulted || kept_valid(KEPT_MARK)) {
        last.cfsr = kept.rec.cfsr;
        last.hfsr = kept.rec.hfsr;
        last.mmfar = kept.rec.mmfar;
        last.bfar = kept.rec.bfar;
        last.pc = kept.rec.pc;
        last.lr = kept.rec.lr;
        last.kind = kept.rec.kind;
    }
    kept.mark = 0u;
    kept.mark_inv = 0u;
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

/* The stack may be what failed: the handler takes the stacked frame's address (MSP or PSP by
 * EXC_RETURN bit 2), starts on a fresh stack at the top of RAM, turns the outputs off with
 * plain stores, keeps the record and resets. */
extern uint32_t _estack, _sdata;
void hard_fault_c(const uint32_t *frame);

__attribute__((naked)) void HardFault_Handler(void) {
    __asm__ volatile("tst lr, #4\n"
                     "ite eq\n"
                     "mrseq r0, msp\n"
                     "mrsne r0, psp\n"
                     "ldr r1, =_estack\n"
                     "msr msp, r1\n"
                     "b hard_fault_c\n");
}

static __attribute__((noreturn)) void keep_and_reset(uint32_t mark) {
    __asm__ volatile("dsb" ::: "memory");
    kept.mark = mark;
    kept.mark_inv = ~mark;
    __asm__ volatile("dsb" ::: "memory");
    SCB_AIRCR = SCB_AIRCR_RESET;
    for (;;) {
    }
}

__attribute__((used, noreturn)) void hard_fault_c(const uint32_t *frame) {
    fw_io_safe();
    kept.rec.cfsr = SCB_CFSR;
    kept.rec.hfsr = SCB_HFSR;
    kept.rec.mmfar = SCB_MMFAR;
    kept.rec.bfar = SCB_BFAR;
    /* the frame (R0-R3, R12, LR, PC, xPSR) only when it lies in RAM: a broken stack pointer
     * must not fault again here */
    const uintptr_t at = (uintptr_t)frame;
    const bool in_ram = at >= (uintptr_t)&_sdata && at + 8u * 4u <= (uintptr_t)&_estack;
    kept.rec.lr = in_ram ? frame[5] : 0u;
    kept.rec.pc = in_ram ? frame[6] : 0u;
    kept.rec.kind = (uint8_t)FW_FAULT_HARD;
    keep_and_reset(FAULT_MARK);
}

/* The clock security system (RM0090 6.2.7): the crystal failed while the PLL ran from it. The
 * hardware has already switched to the internal oscillator; the outputs go off and the chip
 * restarts, to come up on the fallback (silent, outputs off) with the cause kept. */
void NMI_Handler(void) {
    fw_io_safe();
    if ((RCC->CIR & RCC_CIR_CSSF) != 0u) {
        RCC->CIR = RCC_CIR_CSSC;
    }
    kept.rec.cfsr = 0u;
    kept.rec.hfsr = 0u;
    kept.rec.mmfar = 0u;
    kept.rec.bfar = 0u;
    kept.rec.pc = 0u;
    kept.rec.lr = 0u;
    kept.rec.kind = (uint8_t)FW_FAULT_CRYSTAL;
    keep_and_reset(KEPT_MARK);
}

void fw_fault_keep_for_next_start(void) {
    const bool hard = last.kind == (uint8_t)FW_FAULT_HARD;
    kept.rec.cfsr = last.cfsr;
    kept.rec.hfsr = last.hfsr;
    kept.rec.mmfar = last.mmfar;
    kept.rec.bfar = last.bfar;
    kept.rec.pc = last.pc;
    kept.rec.lr = last.lr;
    kept.rec.kind = hard ? (uint8_t)FW_FAULT_HARD : (uint8_t)FW_FAULT_CRYSTAL;
    __asm__ volatile("dsb" ::: "memory");
    kept.mark = KEPT_MARK; /* the next reset's cause stays its own */
    kept.mark_inv = ~KEPT_MARK;
}
