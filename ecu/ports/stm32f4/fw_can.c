/**
 * @file fw_can.c
 * @brief bxCAN CAN1 (RM0090 32): identifier-list filters for the ECU's frames into FIFO 0,
 *        reception by interrupt into a lock-free ring, transmission in queue order
 *        (TXFP: mailboxes by request order) from a ring the transmit interrupt refills the
 *        mailboxes from. Automatic bus-off recovery (ABOM) and retransmission.
 *
 * Bit timing: fixed at compile time from the board's APB1 clock (board.h: 16 quanta, sample
 * point 87.5 %), kept in fw_can_btr[] (the image's tests read it). On the internal-oscillator
 * fallback the controller runs silent (BTR.SILM): it receives but never drives the bus, not
 * even an acknowledge, since the oscillator's error is beyond what the bus tolerates.
 *
 * Health: the status-change/error interrupt (SCE) counts the entries into error-passive and
 * bus-off; fw_can_stats() reads the transmit and receive error counters (CAN_ESR, 32.9.1).
 */
#include "board.h"
#include "fw.h"
#include "stm32f4_regs.h"
#include "td_bxcan.h"
#include "td_ring.h"

#define INIT_SPINS 100000u

static td_frame_ring_t rx_ring; /* producer: CAN1_RX0 interrupt; consumer: main loop */
static td_frame_ring_t tx_ring; /* producer: main loop; consumer: CAN1_TX interrupt (or the
                                   main loop with that interrupt masked) */
static fw_can_stats_t stats;
static uint32_t esr_seen; /* the ESR flags the SCE interrupt saw last */

/* [0] on the PLL's APB1, [1] on the internal oscillator; volatile: read from the image */
const volatile uint32_t fw_can_btr[2] = { BOARD_CAN_BTR_FOR(BOARD_APB1_HZ), BOARD_CAN_BTR_FOR(BOARD_HSI_HZ) };

static bool wait_msr(uint32_t mask, uint32_t want) {
    for (uint32_t i = 0u; i < INIT_SPINS; i++) {
        if ((CAN1->MSR & mask) == want) {
            return true;
        }
    }
    return false;
}

bool fw_can_init(const fw_clock_t *c, const uint32_t *ids, unsigned n) {
    td_bxcan_bank_t banks[TD_BXCAN_BANKS];
    const int nb = n == 0u ? 1 : td_bxcan_filters_ext(ids, n, banks, TD_BXCAN_BANKS);
    if (nb < 0) {
        return false;
    }
    td_frame_ring_init(&rx_ring);
    td_frame_ring_init(&tx_ring);
    RCC->APB1ENR |= RCC_APB1ENR_CAN1;
    (void)RCC->APB1ENR;
    /* leave sleep, request initialisation (32.4.1): an absent controller never acknowledges */
    CAN1->MCR = CAN_MCR_INRQ;
    if (!wait_msr(CAN_MSR_INAK, CAN_MSR_INAK)) {
        RCC->APB1ENR &= ~RCC_APB1ENR_CAN1;
        return false;
    }
    /* pins only once the controller is known to be there (GPIO clocks: fw_io_outputs_off) */
    PIN_AF(PIN_CAN_RX, GPIO_PULL_UP); /* RX idles recessive */
    PIN_AF(PIN_CAN_TX, 0u);
    CAN1->MCR = CAN_MCR_INRQ | CAN_MCR_ABOM | CAN_MCR_TXFP;
    CAN1->BTR = c->source == (uint8_t)FW_CLOCK_PLL_HSE ? fw_can_btr[0] : (fw_can_btr[1] | CAN_BTR_SILM);
    /* filters (32.7.4): banks 0..nb-1 in 32-bit identifier-list mode, FIFO 0 */
    CAN1->FMR |= CAN_FMR_FINIT;
    CAN1->FA1R = 0u;
    if (n == 0u) { /* bank 0 in mask mode with a zero mask: every frame */
        banks[0].fr1 = 0u;
        banks[0].fr2 = 0u;
    }
    for (int i = 0; i < nb; i++) {
        CAN1->FB[i].FR1 = banks[i].fr1;
        CAN1->FB[i].FR2 = banks[i].fr2;
    }
    const uint32_t used = (1u << (uint32_t)nb) - 1u;
    CAN1->FM1R = n == 0u ? 0u : used;
    CAN1->FS1R = used;
    CAN1->FFA1R = 0u;
    CAN1->FA1R = used;
    CAN1->FMR &= ~CAN_FMR_FINIT;
    /* normal mode once 11 recessive bits were seen; a bus held dominant keeps it waiting,
     * the controller joins by itself when the bus frees */
    CAN1->MCR &= ~CAN_MCR_INRQ;
    (void)wait_msr(CAN_MSR_INAK, 0u);
    CAN1->IER = CAN_IER_FMPIE0 | CAN_IER_TMEIE | CAN_IER_EPVIE | CAN_IER_BOFIE | CAN_IER_ERRIE;
    nvic_enable(IRQ_CAN1_RX0, 2u);
    nvic_enable(IRQ_CAN1_TX, 2u);
    nvic_enable(IRQ_CAN1_SCE, 2u);
    return true;
}

void CAN1_RX0_IRQHandler(void) {
    while ((CAN1->RF0R & CAN_RF0R_FMP0_MASK) != 0u) {
        const can_rx_mailbox_t *m = &CAN1->RX[0];
        td_can_frame_t f;
        if (td_bxcan_rx_frame(m->RIR, m->RDTR, m->RDLR, m->RDHR, &f)) {
            stats.rx_frames++;
            (void)td_frame_ring_push(&rx_ring, &f); /* a full ring counts the frame as dropped */
        }
        CAN1->RF0R = CAN_RF0R_RFOM0;
    }
    if ((CAN1->RF0R & CAN_RF0R_FOVR0) != 0u) {
        stats.rx_overruns++;
        CAN1->RF0R = CAN_RF0R_FOVR0;
    }
}

/* Fill the free mailboxes from the ring, oldest first. */
static void fill_mailboxes(void) {
    for (;;) {
        const uint32_t tsr = CAN1->TSR;
        unsigned box = 3u;
        for (unsigned i = 0u; i < 3u; i++) {
            if ((tsr & (1u << (CAN_TSR_TME_SHIFT + i))) != 0u) {
                box = i;
                break;
            }
        }
        td_can_frame_t f;
        if (box == 3u || !td_frame_ring_pop(&tx_ring, &f)) {
            return;
        }
        uint32_t tir, tdtr, tdlr, tdhr;
        td_bxcan_tx_words(&f, &tir, &tdtr, &tdlr, &tdhr);
        can_tx_mailbox_t *m = &CAN1->TX[box];
        m->TDTR = tdtr;
        m->TDLR = tdlr;
        m->TDHR = tdhr;
        m->TIR = tir | CAN_TIR_TXRQ;
        stats.tx_frames++;
    }
}

void CAN1_TX_IRQHandler(void) {
    CAN1->TSR = 0x00010101u; /* RQCP0..2: acknowledge the completed requests */
    fill_mailboxes();
}

/* Status change and error (32.8): count each entry into error-passive and bus-off. */
void CAN1_SCE_IRQHandler(void) {
    const uint32_t esr = CAN1->ESR;
    const uint32_t entered = esr & ~esr_seen;
    if ((entered & CAN_ESR_EPVF) != 0u) {
        stats.error_passive++;
    }
    if ((entered & CAN_ESR_BOFF) != 0u) {
        stats.bus_off++;
    }
    esr_seen = esr & (CAN_ESR_EPVF | CAN_ESR_BOFF);
    CAN1->MSR = CAN_MSR_ERRI; /* rc_w1 */
}

bool fw_can_read(td_can_frame_t *f) {
    return td_frame_ring_pop(&rx_ring, f);
}

bool fw_can_write(const td_can_frame_t *f) {
    const bool ok = td_frame_ring_push(&tx_ring, f);
    nvic_disable(IRQ_CAN1_TX); /* the ring's one consumer for a moment */
    fill_mailboxes();
    nvic_enable(IRQ_CAN1_TX, 2u);
    return ok;
}

void fw_can_stats(fw_can_stats_t *s) {
    *s = stats;
    s->rx_ring_dropped = rx_ring.dropped;
    s->tx_dropped = tx_ring.dropped;
    const uint32_t esr = CAN1->ESR;
    s->tec = (uint8_t)(esr >> CAN_ESR_TEC_SHIFT);
    s->rec = (uint8_t)(esr >> CAN_ESR_REC_SHIFT);
    s->state = (esr & CAN_ESR_BOFF) != 0u ? 2u : (esr & CAN_ESR_EPVF) != 0u ? 1u : 0u;
}
