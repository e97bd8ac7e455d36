/**
 * @file td_tc.h
 * @brief ISO 11783-10 Task Controller client of the topdress implement (TC-BAS documentation,
 *        TC-SC section control, TC-GEO rates without position-based control; version 4).
 *
 * Connection (after the address claim): wait for the TC's status message (its source address
 * becomes the TC), announce the working set (Working Set Master), exchange versions, request
 * the language, ask for the stored structure and localization labels, transfer the DDOP
 * (td_ddop_gen.h, with our NAME patched in) unless the TC already holds it, activate it. Then
 * process data: value commands (with and without acknowledge), measurement commands by time,
 * distance, minimum/maximum threshold and on change, requests of values and of the default set,
 * PDACK for every refused command. The client task message goes out every 2 s.
 *
 * Fail-safe: no TC status for `tc_timeout_us` (the cab PC's command timeout), or a refused
 * pool, sets `alarm`; rates go to 0 and sections off until a TC connects again.
 * Rates are mg/m^2 (DDI 6: 1 kg/ha = 100 mg/m^2), lengths mm, areas m^2, masses g or kg as
 * each DDI says.
 */
#ifndef TD_TC_H
#define TD_TC_H

#include <stdbool.h>
#include <stdint.h>

#include "td_ddop_gen.h"
#include "td_ib.h"
#include "td_tp.h"

#define TD_IB_PGN_PROCESS_DATA 0x00CB00u
#define TD_IB_PGN_WORKING_SET_MASTER 0x00FE0Du
#define TD_IB_PGN_LANGUAGE 0x00FE0Fu

#define TD_TC_STEP_TIMEOUT_US 2000000u /**< an answer of the TC not seen within: ask again */
#define TD_TC_TASK_PERIOD_US 2000000u  /**< client task message period */
#define TD_TC_VARS 14u                 /**< process variables of the pool */

typedef enum {
    TD_TC_NO_ADDRESS = 0,   /**< waiting for our address claim */
    TD_TC_WAIT_STATUS,      /**< waiting for a TC's status message */
    TD_TC_VERSION,          /**< Working Set Master sent, version requested */
    TD_TC_LANGUAGE,         /**< language requested */
    TD_TC_STRUCTURE,        /**< structure label requested */
    TD_TC_LOCALIZATION,     /**< localization label requested */
    TD_TC_POOL_SIZE,        /**< Request Object-pool Transfer sent */
    TD_TC_POOL_TRANSFER,    /**< pool on its way (TP/ETP) and its response awaited */
    TD_TC_ACTIVATE,         /**< activation requested */
    TD_TC_CONNECTED,        /**< pool active: process data runs */
    TD_TC_REFUSED           /**< the TC refused the pool: alarm, no retry until the TC restarts */
} td_tc_state_t;

/** PDACK error bits (ISO 11783-10). */
#define TD_TC_PDACK_CMD_UNSUPPORTED 0x01u
#define TD_TC_PDACK_BAD_ELEMENT 0x02u
#define TD_TC_PDACK_BAD_DDI 0x04u
#define TD_TC_PDACK_TRIGGER_UNSUPPORTED 0x08u
#define TD_TC_PDACK_NOT_SETTABLE 0x10u
#define TD_TC_PDACK_BAD_INTERVAL 0x20u
#define TD_TC_PDACK_OUT_OF_RANGE 0x80u

/** One process variable of the pool and the TC's measurement commands for it. */
typedef struct {
    uint16_t element;
    uint16_t ddi;
    bool settable;
    int32_t value;
    uint32_t time_ms, dist_mm; /**< 0 = trigger off */
    int32_t change;            /**< 0 = off */
    int32_t min_thr, max_thr;
    bool min_on, max_on;
    int32_t last_sent;
    uint32_t last_us, last_mm;
    bool sent_once;
} td_tc_var_t;

typedef struct {
    td_tc_state_t state;
    uint8_t tc_addr;
    uint8_t my_addr; /**< our address when the connection began: a move starts it again */
    uint8_t tc_version;
    uint8_t tc_options;
    char language[2];
    uint32_t tc_timeout_us;
    uint32_t last_status_us;
    uint32_t state_us;       /**< time the current state began (or its request went out) */
    uint32_t task_us;        /**< last client task message */
    bool task_active;        /**< TC status: a task runs (totals active) */
    bool alarm;              /**< TC lost or pool refused: the operator must be told */
    uint8_t refuse_code;     /**< activation or transfer error code of a refusal */
    uint32_t pdacks_sent, values_set, values_refused, connects;
    td_tc_var_t vars[TD_TC_VARS];
    uint8_t pool[1u + TD_DDOP_LEN]; /**< Object-pool Transfer message: 0x61 and the pool */
} td_tc_t;

/** `name`: our NAME (written into the pool's DVC); `tc_timeout_us`: loss of the TC after. */
int td_tc_init(td_tc_t *tc, uint64_t name, uint32_t tc_timeout_us);
/** A process-data (PGN 0xCB00) or language message, single frame or reassembled by TP. */
int td_tc_rx(td_tc_t *tc, uint32_t pgn, uint8_t sa, uint8_t da, const uint8_t *d, uint32_t len,
             uint8_t my_addr, uint32_t now_us, td_ib_txq_t *q);
/** Runs the connection, timeouts, client task message and measurements. `distance_mm`: the
 *  implement's odometer (wraps modulo 2^32). */
void td_tc_step(td_tc_t *tc, uint8_t my_addr, uint32_t now_us, uint32_t distance_mm,
                td_tp_t *tp, td_ib_txq_t *q);
/** The application's actual values (DDI 7, 75, 81, 116, 141, 161); TD_IB_E_ARG if unknown. */
int td_tc_set_actual(td_tc_t *tc, uint16_t element, uint16_t ddi, int32_t value);
/** The rate the TC sets for a layer (0 upper, 1 lower), mg/m^2; 0 unless connected. */
int32_t td_tc_rate_mg_m2(const td_tc_t *tc, unsigned layer);
/** Sections to apply (bit i = section i+1); 0 unless connected and the TC turned them on. */
uint16_t td_tc_sections_on(const td_tc_t *tc);
/** A variable by element and DDI, NULL if the pool has none. */
const td_tc_var_t *td_tc_var(const td_tc_t *tc, uint16_t element, uint16_t ddi);

#endif
