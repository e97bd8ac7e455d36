/**
 * @file main.c
 * @brief The topdress ECU on an STM32F405/407: the port contract of td_port.h on this chip.
 *
 * Transport, chosen at build: CAN1 on a board; in the emulator build (`VARIANT=qemu`, FW_QEMU)
 * SLCAN on USART1 with the simulated machine in the loop: its counters come in as HIL frames
 * instead of from the timers and the duties go out as HIL frames, the PWM pins staying off.
 * Everything between (td_app_rx, td_app_step, td_app_tx_pop) is the same code on the same path
 * either way. Nothing in the board image guesses whether it runs in an emulator.
 *
 * The step's tick: SysTick every 10 ms on CAN. On the HIL link the simulator's first HilClock
 * chooses: lockstep (one step per HilSensors, at the simulator's time: the emulated ECU is then
 * deterministic, however fast the host runs it; SysTick only wakes the wait to feed the
 * watchdog) or SysTick as on the board.
 *
 * Safe state: at reset the PWM timer is stopped and its pins are inputs (pull-downs on the
 * driver board); the first thing main does, before the clock start, is drive them low
 * (MOE = 0); they stay low until the first valid PcCommand, and for good on the
 * internal-oscillator fallback (the ECU is then silent on the bus). A hard fault or a lost
 * crystal turns them off and resets; the independent watchdog resets a loop that stops feeding
 * it (~100 ms), which again starts with the outputs off.
 */
#include <stddef.h>
#include "board.h"
#include "fw.h"
#include "td_app.h"
#include "td_can.h"
#include "td_hil.h"
#include "td_slcan.h"
#include "stm32f4_regs.h"

#if defined(FW_ISOBUS)
/* the ISOBUS build: the node beside the core; the core's frames on Proprietary A/B (td_prop.h) */
#define ISOBUS_BUILD true
#else
#define ISOBUS_BUILD false
#endif
/* the node's frames per step: 8 SLCAN lines (27 bytes each) leave room in the 512-byte
 * transmit buffer for the core's frames and the HIL pair; 16 on CAN, half its 32-frame ring */
#define ISOBUS_SLCAN_FRAMES_PER_STEP 8u
#define ISOBUS_CAN_FRAMES_PER_STEP 16u

#if defined(FW_QEMU)
#define HIL_BUILD true
#else
#define HIL_BUILD false
#endif

static td_app_t app; /* the one instance (td_port.h) */
static td_params_t params;
static fw_clock_t clk;
static td_hil_t hil;
static td_slcan_parser_t slcan;
static bool slcan_open;
static const bool hil_mode = HIL_BUILD;
static uint32_t slcan_tx_dropped;
static uint32_t rx_cost_us; /* lockstep: the time the step's bus frames took to take in */

static void slcan_send(const td_can_frame_t *f) {
    char line[TD_SLCAN_FRAME_MAX];
    const int n = td_slcan_encode(f, line, sizeof line);
    if (slcan_open && n > 0 && !fw_uart_write((const uint8_t *)line, (uint32_t)n)) {
        slcan_tx_dropped++;
    }
}

static td_ident_t ident;

static uint16_t sat16(uint32_t v) {
    return v > 0xFFFFu ? 0xFFFFu : (uint16_t)v;
}

static void core_can_write(const td_can_frame_t *core);

/* Once a second on CAN: the controller's health (EcuCanHealth) and, after a fault reset, one
 * register of what the fault handler kept (EcuFaultRecord), the next one each second. */
static void send_diagnostics(void) {
    static uint8_t fault_reg;
    fw_can_stats_t st;
    fw_can_stats(&st);
    const struct td_can_ecu_can_health_t h = {
        .tx_errors = st.tec,
        .rx_errors = st.rec,
        .bus_state = st.state,
        .error_passive_count = sat16(st.error_passive),
        .bus_off_count = sat16(st.bus_off),
        .rx_overruns = st.rx_overruns > 0xFFu ? 0xFFu : (uint8_t)st.rx_overruns,
    };
    td_can_frame_t f = { .id = TD_CAN_ECU_CAN_HEALTH_FRAME_ID, .extended = 1u, .dlc = 8u };
    (void)td_can_ecu_can_health_pack(f.data, &h, sizeof f.data);
    core_can_write(&f);
    fw_fault_record_t r;
    fw_fault_record(&r);
    if (r.kind == (uint8_t)FW_FAULT_NONE) {
        return;
    }
    const uint32_t regs[6] = { r.cfsr, r.hfsr, r.mmfar, r.bfar, r.pc, r.lr };
    const struct td_can_ecu_fault_record_t fr = { .register_id = fault_reg, .kind = r.kind, .value = regs[fault_reg] };
    f.id = TD_CAN_ECU_FAULT_RECORD_FRAME_ID;
    (void)td_can_ecu_fault_record_pack(f.data, &fr, sizeof f.data);
    core_can_write(&f);
    fault_reg = (uint8_t)((fault_reg + 1u) % 6u);
}

/* The node (re)started: at power-up and when lockstep moves the time base. */
static void isobus_start(uint32_t now_us) {
#if defined(FW_ISOBUS)
    (void)fw_isobus_init(&params, now_us);
#else
    (void)now_us;
#endif
}

/* A received bus frame: to the core on the paper's bus; in the ISOBUS build to the node,
 * which hands the core the terminal's private frames from the TC's address. */
static void bus_rx(const td_can_frame_t *f, uint32_t now_us) {
#if defined(FW_ISOBUS)
    fw_isobus_rx(&app, f, now_us);
#else
    (void)td_app_rx(&app, f, now_us);
#endif
}

/* A frame of the core for the bus: as it is on the paper's bus; in the ISOBUS build on its
 * Proprietary A/B PGN from the claimed address, or not at all (no address yet). */
static bool bus_form(const td_can_frame_t *core, td_can_frame_t *out) {
#if defined(FW_ISOBUS)
    return fw_isobus_to_bus(core, out);
#else
    *out = *core;
    return true;
#endif
}

static void core_can_write(const td_can_frame_t *core) {
    td_can_frame_t f;
    if (bus_form(core, &f)) {
        (void)fw_can_write(&f);
    }
}

/* Before the core's step: the TC's command as the core's own PcCommand. */
static void isobus_before_step(uint32_t now_us) {
#if defined(FW_ISOBUS)
    td_can_frame_t cmd;
    fw_isobus_command(&app, &cmd, now_us);
    (void)td_app_rx(&app, &cmd, now_us);
#else
    (void)now_us;
#endif
}

/* After it: the actual values to the TC, the node's period; at most `max` of its frames to
 * `send` (the rest wait in the node's queue, whose TP sender refills it as it drains: a
 * step's frames must fit the link's transmit buffer, 512 serial bytes on SLCAN). */
static void isobus_after_step(uint32_t now_us, void (*send)(const td_can_frame_t *f), unsigned max) {
#if defined(FW_ISOBUS)
    static bool tc_connected;
    fw_isobus_step(&app, now_us);
    const bool connected = fw_isobus_connected();
    if (connected && !tc_connected) {
        (void)td_app_announce(&app); /* EcuIdent from the claimed address, now the TC hears it */
    }
    tc_connected = connected;
    td_can_frame_t f;
    for (unsigned i = 0u; i < max && fw_isobus_tx(&f); i++) {
        send(&f);
    }
#else
    (void)now_us;
    (void)send;
    (void)max;
#endif
}

static void can_send(const td_can_frame_t *f) {
    (void)fw_can_write(f);
}

/* The first HilClock chose the step's tick. Lockstep: the core starts again on the simulator's
 * clock (nothing has stepped yet; its time base moves from the chip's TIM2 to the simulator's). */
static void hil_tick_chosen(void) {
    if (hil.tick == (uint8_t)TD_HIL_TICK_OWN) {
        return; /* SysTick runs already */
    }
    (void)td_app_init(&app, &params, hil.clock_us);
    (void)td_app_set_ident(&app, &ident);
    isobus_start(hil.clock_us);
}

/* Serial bytes to SLCAN lines: commands answered, HIL frames to the link, the rest to the core.
 * Lockstep stops after the HilSensors that makes a step: what follows belongs to the next. */
static void slcan_receive(uint32_t now_us) {
    uint8_t b;
    while (!hil.step_due && fw_uart_getc(&b)) {
        td_can_frame_t f;
        uint8_t arg;
        const td_slcan_event_t ev = td_slcan_feed(&slcan, b, &f, &arg);
        if (ev == TD_SLCAN_NONE) {
            continue;
        }
        if (ev == TD_SLCAN_FRAME) {
            const uint8_t tick = hil.tick;
            if (td_hil_rx(&hil, &f) == 0) {
                const uint32_t t_us = tick == (uint8_t)TD_HIL_TICK_LOCKSTEP ? hil.clock_us : now_us;
                const uint32_t t0 = fw_micros();
                bus_rx(&f, t_us);
                rx_cost_us += fw_micros() - t0;
            } else if (hil.tick != tick) {
                hil_tick_chosen();
            }
            continue;
        }
        if (ev == TD_SLCAN_OPEN) {
            slcan_open = true;
            (void)td_app_set_ident(&app, &ident); /* a new listener: EcuIdent at the next step */
        } else if (ev == TD_SLCAN_CLOSE) {
            slcan_open = false;
        }
        char reply[8];
        const unsigned n = td_slcan_reply(ev, reply, sizeof reply);
        if (n > 0u) {
            (void)fw_uart_write((const uint8_t *)reply, n);
            fw_uart_pump(); /* answered now: in lockstep no step may come to send it */
        }
    }
}

/* The next step on the HIL link: its time, its inputs taken from the link. */
static uint32_t hil_wait_step(void) {
    for (;;) {
        if (hil.tick == (uint8_t)TD_HIL_TICK_OWN) {
            fw_wait_step();
            const uint32_t now = fw_micros();
            slcan_receive(now);
            return now;
        }
        slcan_receive(fw_micros());
        if (hil.step_due) {
            return hil.clock_us;
        }
        if (hil.tick != (uint8_t)TD_HIL_TICK_OWN) {
            /* until more bytes (the simulator drives) or SysTick: waiting for the simulator is
             * not a loop that hangs, and the outputs are off on this link */
            fw_watchdog_feed();
            fw_uart_wait();
        }
    }
}

int main(void) {
    fw_io_outputs_off(); /* first: on the reset clock, before anything can take time */
    const td_reset_cause_t cause = fw_reset_cause();
    fw_clock_init(&clk);
    fw_time_init(&clk);
    fw_io_init(&clk);
    td_params_t *const p = &params;
    td_params_default(p); /* the terminal pushes its parameters over CAN at every connection */
    const uint32_t ids[] = { p->command_id, TD_ID_PC_PARAM_SET, TD_ID_PC_CAL_COMMAND, TD_ID_PC_GNSS_TIME };
    if (hil_mode) {
        td_hil_init(&hil);
        td_slcan_init(&slcan);
        fw_uart_init(&clk, BOARD_SLCAN_BAUD);
    } else if (!fw_can_init(&clk, ids, ISOBUS_BUILD ? 0u : sizeof ids / sizeof ids[0])) {
        for (;;) { /* a CAN controller that never answers: a broken chip; outputs off, no watchdog */
            wait_for_interrupt();
        }
    }
    /* only a clock from the crystal drives the outputs (and the bus: fw_can_init) */
    const bool on_crystal = clk.source == (uint8_t)FW_CLOCK_PLL_HSE;
    if (!hil_mode && !on_crystal) {
        fw_fault_keep_for_next_start(); /* said at the next start that can send it */
    }
    if (td_app_init(&app, p, fw_micros()) != TD_OK) {
        for (;;) { /* defaults that do not validate: no control, the watchdog is not started */
        }
    }
    ident.target = (uint8_t)TD_TARGET_STM32F4;
    ident.transport = (uint8_t)(hil_mode ? TD_TRANSPORT_SLCAN_HIL : TD_TRANSPORT_CAN);
    ident.reset_cause = (uint8_t)cause;
    ident.clock_fallback = clk.source == (uint8_t)FW_CLOCK_HSI;
    (void)td_app_set_ident(&app, &ident);
    isobus_start(fw_micros());
    fw_watchdog_start();
    fw_tick_start(&clk); /* on the HIL link in lockstep it only wakes the wait for the watchdog */
    uint32_t steps = 0u;
    for (;;) {
        uint32_t now;
        td_can_frame_t f;
        td_io_in_t in;
        if (hil_mode) {
            now = hil_wait_step();
            td_hil_inputs(&hil, &in);
        } else {
            fw_wait_step();
            now = fw_micros();
            while (fw_can_read(&f)) {
                bus_rx(&f, now);
            }
            fw_io_read(&in);
        }
        /* the step's cost: receive and core on the board; in lockstep the core and the time
         * its frames took to take in (not the wait for the simulator's bytes between them) */
        const uint32_t t_start = hil_mode && hil.tick == (uint8_t)TD_HIL_TICK_LOCKSTEP ? fw_micros() : now;
        td_io_out_t out;
        isobus_before_step(now);
        (void)td_app_step(&app, now, &in, &out);
        if (hil_mode) {
            /* the step's bus frames, then its duties and HilStep: the simulator's end of it */
            while (td_app_tx_pop(&app, &f)) {
                td_can_frame_t b;
                if (bus_form(&f, &b)) {
                    slcan_send(&b);
                }
            }
            isobus_after_step(now, slcan_send, ISOBUS_SLCAN_FRAMES_PER_STEP);
            const uint32_t cost_us = fw_micros() - t_start + (t_start == now ? 0u : rx_cost_us);
            rx_cost_us = 0u;
            td_can_frame_t step_frames[2];
            td_hil_outputs(&hil, now, &out, cost_us, step_frames);
            slcan_send(&step_frames[0]);
            slcan_send(&step_frames[1]);
            fw_uart_pump();
        } else {
            fw_io_write(&out);
            fw_io_enable(app.have_cmd && on_crystal); /* low until the first valid command */
            while (td_app_tx_pop(&app, &f)) {
                if (on_crystal) { /* silent on the fallback: nothing queued for the bus */
                    core_can_write(&f);
                }
            }
            if (on_crystal) {
                isobus_after_step(now, can_send, ISOBUS_CAN_FRAMES_PER_STEP);
            }
            if (on_crystal && ++steps % BOARD_STEP_HZ == 0u) {
                send_diagnostics();
            }
        }
        fw_watchdog_feed();
    }
}
