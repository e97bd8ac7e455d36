/**
 * @file fw.h
 * @brief The STM32F4 port's modules: clocks and time, I/O, bxCAN, the SLCAN serial link,
 *        watchdog and reset cause. main.c runs the port contract of td_port.h on them.
 */
#ifndef TD_FW_H
#define TD_FW_H

#include <stdbool.h>
#include <stdint.h>
#include "td_app.h"
#include "td_port.h"
#include "td_proto.h"

/* ---- fw_clock.c: clock tree, microsecond clock, step tick -------------------------------- */
typedef enum {
    FW_CLOCK_PLL_HSE = 0,      /**< BOARD_CORE_HZ from the crystal, as designed */
    FW_CLOCK_HSI = 1,          /**< the crystal or the PLL did not start: 16 MHz internal RC;
                                    the ECU stays silent on the bus, outputs off */
    FW_CLOCK_EMULATOR = 2      /**< the emulator build (FW_QEMU): QEMU's fixed 168 MHz */
} fw_clock_source_t;

typedef struct {
    uint32_t core_hz;          /**< SYSCLK = HCLK */
    uint32_t apb1_hz;          /**< APB1 (bxCAN) */
    uint32_t apb2_hz;          /**< APB2 (USART1) */
    uint32_t tim2_hz;          /**< TIM2's input clock as measured against the core clock */
    uint32_t tim_apb2_hz;      /**< APB2 timers' clock (TIM8, TIM9) */
    uint8_t source;            /**< fw_clock_source_t */
} fw_clock_t;

/** Clock tree from its reset state: HSE + PLL to BOARD_CORE_HZ, with time-outs on every ready
 *  flag, and the clock security system on. */
void fw_clock_init(fw_clock_t *c);
/** TIM2 as the free-running 32-bit microsecond clock (prescaler from its measured clock). */
void fw_time_init(fw_clock_t *c);
/** The microsecond clock now (wraps every 71.6 min, as td_port.h expects). */
uint32_t fw_micros(void);
/** SysTick every 1 / BOARD_STEP_HZ; fw_wait_step() sleeps until the next tick. */
void fw_tick_start(const fw_clock_t *c);
void fw_wait_step(void);

/* ---- fw_io.c: encoders, capture, tachometers, PWM, safe state ---------------------------- */
/** A pin (port A = 0 .. E = 4) to its alternate function `af` with `pull` (GPIO_PULL_*);
 *  PIN_AF(PIN_x, pull) takes the board header's triple. */
void fw_pin_af(uint32_t port, uint32_t pin, uint32_t af, uint32_t pull);
#define PIN_AF(p, pull) FW_PIN_AF_(p, pull)
#define FW_PIN_AF_(port, pin, af, pull) fw_pin_af(port, pin, af, pull)
/** The PWM outputs driven low with MOE off, frozen under a debugger: the first thing main does,
 *  on the reset clock, before the clock start. */
void fw_io_outputs_off(void);
/** Inputs, counters and the PWM period on the running clock. */
void fw_io_init(const fw_clock_t *c);
/** The counters and the wheel's edge as td_io_in_t (capture read with its interrupt masked). */
void fw_io_read(td_io_in_t *in);
/** Duties to the PWM compare registers; the outputs drive only while enabled. */
void fw_io_write(const td_io_out_t *out);
/** Enable or disable the PWM outputs (disabled: every output at its idle level, low). */
void fw_io_enable(bool on);
/** All PWM off now, with no stack and no state (hard fault, watchdog warning, reset). */
void fw_io_safe(void);

/* ---- fw_can.c: bxCAN CAN1 --------------------------------------------------------------- */
/** Initialise CAN1 at BOARD_CAN_BITRATE with filters for `ids` (29-bit; n == 0: every frame,
 *  as the ISOBUS build needs); silent (receive only)
 *  unless the clock is the crystal's. false: the controller never acknowledged its
 *  initialisation request, or too many ids. */
bool fw_can_init(const fw_clock_t *c, const uint32_t *ids, unsigned n);
/** CAN_BTR on the PLL's APB1 [0] and on the internal oscillator [1] (board.h). */
extern const volatile uint32_t fw_can_btr[2];
bool fw_can_read(td_can_frame_t *f);
/** Queue a frame for transmission; false when the queue is full (counted). */
bool fw_can_write(const td_can_frame_t *f);

typedef struct {
    uint32_t rx_frames, rx_overruns, rx_ring_dropped, tx_frames, tx_dropped;
    uint32_t error_passive;    /**< entries into error-passive (SCE interrupt) */
    uint32_t bus_off;          /**< entries into bus-off */
    uint8_t tec, rec;          /**< transmit / receive error counters now (CAN_ESR) */
    uint8_t state;             /**< 0 error-active, 1 error-passive, 2 bus-off */
} fw_can_stats_t;
void fw_can_stats(fw_can_stats_t *s);

/* ---- fw_uart.c: the SLCAN serial link on USART1 ------------------------------------------ */
void fw_uart_init(const fw_clock_t *c, uint32_t baud);
bool fw_uart_getc(uint8_t *b);
/** Sleep until a byte has arrived (at once when one is waiting). */
void fw_uart_wait(void);
/** Queue bytes for sending, all or none (false: no room, counted). */
bool fw_uart_write(const uint8_t *b, uint32_t n);
/** Move queued bytes to the transmitter while it takes them (the interrupt does the rest). */
void fw_uart_pump(void);

/* ---- fw_isobus.c: the ISOBUS node beside the core (FW_ISOBUS builds only) ---------------- */
#if defined(FW_ISOBUS)
/** The node with its NAME from the chip's unique ID; starts the address claim. false: no NAME. */
bool fw_isobus_init(const td_params_t *p, uint32_t now_us);
/** A received frame (29-bit ones only) to the node; the terminal's private frames from the TC's
 *  address (Proprietary A/B, td_prop.h) to the core with their fixed identifiers. */
void fw_isobus_rx(td_app_t *app, const td_can_frame_t *f, uint32_t now_us);
/** A frame of the core as it goes on the ISOBUS (from the claimed address); false: not sent
 *  (no address yet, no TC for an answer, or no ISOBUS form). */
bool fw_isobus_to_bus(const td_can_frame_t *core, td_can_frame_t *out);
/** The core's PcCommand from the TC's rates and sections (stop without a TC), with the
 *  terminal's last GNSS speed (PcGnssTime) while fresh, else "not available". */
void fw_isobus_command(const td_app_t *app, td_can_frame_t *cmd, uint32_t now_us);
/** After the core's step: actual rates and work state to the TC, the node's period. */
void fw_isobus_step(const td_app_t *app, uint32_t now_us);
/** The node's next frame to send; false when none. */
bool fw_isobus_tx(td_can_frame_t *f);
/** The claimed address (0xFE: none). */
uint8_t fw_isobus_address(void);
/** True while the node is connected to its TC (its pool active). */
bool fw_isobus_connected(void);
#endif

/* ---- fw_sys.c: watchdog, reset cause ------------------------------------------------------ */
typedef enum {
    FW_FAULT_NONE = 0,
    FW_FAULT_HARD = 1,         /**< a hard fault (or any unexpected exception) */
    FW_FAULT_CRYSTAL = 2       /**< the crystal stopped while running (the clock security
                                    system) or did not start at an earlier start */
} fw_fault_kind_t;

/** What the fault handler kept across its reset (zero when the last reset was not a fault). */
typedef struct {
    uint32_t cfsr, hfsr, mmfar, bfar; /**< SCB fault status and address registers */
    uint32_t pc, lr;                  /**< stacked by the faulting code (0: the frame was not in RAM) */
    uint8_t kind;                     /**< fw_fault_kind_t */
} fw_fault_record_t;

/** The cause of the last reset (RCC_CSR, and the fault record), flags cleared; call once, first. */
td_reset_cause_t fw_reset_cause(void);
/** Independent watchdog, ~100 ms (LSI 32 kHz / 32, reload 100; 68..188 ms over LSI's spread). */
void fw_watchdog_start(void);
void fw_watchdog_feed(void);
/** The record the last reset left (from fw_reset_cause()). */
void fw_fault_record(fw_fault_record_t *r);
/** On the internal-oscillator fallback, where nothing can be sent: keep the record (or, with
 *  none, a crystal failure) across the next reset for a start on the crystal to send. */
void fw_fault_keep_for_next_start(void);

#endif /* TD_FW_H */
