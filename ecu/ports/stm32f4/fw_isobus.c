/**
 * @file fw_isobus.c
 * @brief The ISOBUS build (FW_ISOBUS): the node of ecu/isobus beside the control core, behind
 *        the same port. What src/topdress/sim/isobus.py does on the host, in C: every step the
 *        TC's rates times the share of the width switched on become the core's own PcCommand
 *        (the core and its control law unchanged); the rates the meters apply and the work state
 *        go back to the TC. No TC, or every section off: the command stops the meters.
 *
 * NAME: identity number from the chip's 96-bit unique ID (RM0090 39.1, 0x1FFF7A10), so two
 * ECUs on one bus never claim with the same NAME. The emulator build has no such memory and
 * takes a fixed ID.
 */
#if defined(FW_ISOBUS)
#include <stddef.h>
#include "fw.h"
#include "td_app.h"
#include "td_can.h"
#include "td_ddop_gen.h"
#include "td_ibname.h"
#include "td_isob.h"

#define UID_ADDR 0x1FFF7A10u
#define UID_LEN 12u
#define PREFERRED_ADDR 0x84u /* the node's defaults, as topdress.isobus.node */
#define RANGE_LO 0x80u
#define RANGE_HI 0x87u
#define TC_STATUS_PERIOD_US 2000000u /* a TC proves itself alive only this often (ISO 11783-10) */
#define MG_M2_PER_KG_HA 100.0f
#define KG_HA_PER_RPM_KG 600.0f /* kg/ha = rpm * kg/rev * 600 / (km/h * m) */
#define DDI_ACTUAL_RATE 7u
#define DDI_ACTUAL_WORK_STATE 141u
#ifndef FW_ISOBUS_MANUFACTURER
#define FW_ISOBUS_MANUFACTURER 0u /* reserved/unassigned: set your own for a real bus */
#endif
#ifndef FW_ISOBUS_FAN_RPM
#define FW_ISOBUS_FAN_RPM 3000.0f /* the fan speed commanded while metering */
#endif

static td_isob_t node;
static uint32_t last_us;
static float distance_mm; /* the implement's odometer from the selected speed */
static bool started;
/* the terminal's last GNSS speed (PcGnssTime from the TC's address): the command carries it,
 * as a cab PC's does; without one the core runs on its wheel */
static float gnss_kmh;
static uint32_t gnss_us;
static bool have_gnss;
static uint32_t gnss_timeout_us;

static unsigned bits_set(uint16_t v) {
    unsigned n = 0u;
    for (; v != 0u; v &= (uint16_t)(v - 1u)) {
        n++;
    }
    return n;
}

bool fw_isobus_init(const td_params_t *p, uint32_t now_us) {
    uint8_t uid[UID_LEN];
#if defined(FW_QEMU)
    /* the emulated chip has no system memory there (a read faults): a fixed ID */
    static const uint8_t emulator_uid[UID_LEN] = { 'q', 'e', 'm', 'u', '-', 't', 'o', 'p', 'd', 'r', 's', 's' };
    for (unsigned i = 0u; i < UID_LEN; i++) {
        uid[i] = emulator_uid[i];
    }
#else
    const volatile uint8_t *const src = (const volatile uint8_t *)UID_ADDR;
    for (unsigned i = 0u; i < UID_LEN; i++) {
        uid[i] = src[i];
    }
#endif
    td_ibname_t n;
    uint64_t name;
    if (td_ibname_topdress(FW_ISOBUS_MANUFACTURER, uid, sizeof uid, &n) != TD_IB_OK ||
        td_ibname_encode(&n, &name) != TD_IB_OK) {
        return false;
    }
    /* the TC is lost after the cab PC's command timeout counted from a missed status */
    const uint32_t tc_timeout_us = (uint32_t)p->cmd_timeout_ms * 1000u + TC_STATUS_PERIOD_US;
    if (td_isob_init(&node, name, PREFERRED_ADDR, RANGE_LO, RANGE_HI, tc_timeout_us) != TD_IB_OK) {
        return false;
    }
    (void)td_isob_start(&node, now_us);
    last_us = now_us;
    distance_mm = 0.0f;
    have_gnss = false;
    gnss_timeout_us = (uint32_t)p->gnss_timeout_ms * 1000u;
    started = true;
    return true;
}

void fw_isobus_rx(td_app_t *app, const td_can_frame_t *f, uint32_t now_us) {
    td_can_frame_t core;
    if (started && f->extended != 0u) {
        (void)td_isob_rx(&node, f, now_us); /* malformed frames are counted by the node */
        /* the terminal's private frames reach the core only from the TC's address (the rest
         * counted by the node); a fixed paper identifier on an ISOBUS is another node's PGN */
        if (td_isob_prop_rx(&node, f, &core) == 1) {
            (void)td_app_rx(app, &core, now_us);
            struct td_can_pc_gnss_time_t g;
            if (core.id == TD_CAN_PC_GNSS_TIME_FRAME_ID &&
                td_can_pc_gnss_time_unpack(&g, core.data, core.dlc) == 0) {
                gnss_kmh = td_can_pc_gnss_time_gnss_speed_precise_decode(g.gnss_speed_precise);
                have_gnss = g.gnss_speed_precise != 0xFFFFu && gnss_kmh <= 25.0f;
                gnss_us = now_us;
            }
        }
    }
}

bool fw_isobus_to_bus(const td_can_frame_t *core, td_can_frame_t *out) {
    return started && td_isob_prop_tx(&node, core, out) == TD_IB_OK;
}

void fw_isobus_command(const td_app_t *app, td_can_frame_t *cmd, uint32_t now_us) {
    const bool gnss = have_gnss && now_us - gnss_us <= gnss_timeout_us;
    const float share = (float)bits_set(td_tc_sections_on(&node.tc)) / (float)TD_DDOP_SECTIONS;
    const float upper = (float)td_tc_rate_mg_m2(&node.tc, 0u) / MG_M2_PER_KG_HA * share;
    const float lower = (float)td_tc_rate_mg_m2(&node.tc, 1u) / MG_M2_PER_KG_HA * share;
    const bool run = upper > 0.0f || lower > 0.0f;
    const struct td_can_pc_command_t c = {
        .start_stop = run ? TD_CAN_PC_COMMAND_START_STOP_START_CHOICE : TD_CAN_PC_COMMAND_START_STOP_STOP_CHOICE,
        .fan_speed = td_can_pc_command_fan_speed_encode(FW_ISOBUS_FAN_RPM),
        .upper_rate = td_can_pc_command_upper_rate_encode(upper),
        .lower_rate = td_can_pc_command_lower_rate_encode(lower),
        .gnss_speed = gnss ? td_can_pc_command_gnss_speed_encode(gnss_kmh) : 0xFFu,
    };
    cmd->id = app->p.command_id;
    cmd->extended = 1u;
    cmd->dlc = 8u;
    (void)td_can_pc_command_pack(cmd->data, &c, sizeof cmd->data);
}

void fw_isobus_step(const td_app_t *app, uint32_t now_us) {
    const td_state_t *st = &app->st;
    distance_mm += st->v_kmh * (float)(now_us - last_us) / 3600.0f; /* km/h * us -> mm */
    last_us = now_us;
    static const uint16_t elements[2] = { TD_DDOP_EL_UPPER, TD_DDOP_EL_LOWER };
    const float width_m = (float)TD_DDOP_WIDTH_MM / 1000.0f;
    for (unsigned layer = 0u; layer < 2u; layer++) {
        float rate = 0.0f;
        if (st->v_kmh > 0.5f) {
            rate = st->meter_rpm[layer] * app->p.kg_per_rev[layer] * KG_HA_PER_RPM_KG / (st->v_kmh * width_m);
        }
        (void)td_tc_set_actual(&node.tc, elements[layer], DDI_ACTUAL_RATE, (int32_t)(rate * MG_M2_PER_KG_HA + 0.5f));
    }
    (void)td_tc_set_actual(&node.tc, TD_DDOP_EL_DEVICE, DDI_ACTUAL_WORK_STATE, st->running ? 1 : 0);
    td_isob_step(&node, now_us, (uint32_t)distance_mm);
}

bool fw_isobus_tx(td_can_frame_t *f) {
    return td_isob_tx(&node, f);
}

uint8_t fw_isobus_address(void) {
    return td_claim_address(&node.claim);
}

bool fw_isobus_connected(void) {
    return started && node.tc.state == TD_TC_CONNECTED;
}
#else
/* ISO C wants a translation unit to declare something */
typedef int fw_isobus_unused_t;
#endif
