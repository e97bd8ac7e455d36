#include "td_tc.h"

#include <stddef.h>
#include <string.h>

#include "td_ibname.h"

#define PD_PRIORITY 5u
#define TC_VERSION 4u
#define TC_OPTIONS 0x13u /* documentation, TC-GEO without position-based control, section control */

/* process data commands (low nibble of byte 0) */
enum {
    PD_TECH = 0, PD_DEVICE = 1, PD_REQ_VALUE = 2, PD_VALUE = 3, PD_TIME = 4, PD_DIST = 5,
    PD_MIN = 6, PD_MAX = 7, PD_CHANGE = 8, PD_SET_ACK = 10, PD_ACK = 13, PD_STATUS = 14,
    PD_TASK = 15
};

#define DDI_REQUEST_DEFAULT 0xDFFFu
#define SEC_BITS_ON 1u

static void send_pd(const td_tc_t *tc, uint8_t my, const uint8_t d[8], td_ib_txq_t *q) {
    (void)td_ib_send8(q, PD_PRIORITY, TD_IB_PGN_PROCESS_DATA, tc->tc_addr, my, d);
}

static void send_dev(const td_tc_t *tc, uint8_t my, uint8_t b0, td_ib_txq_t *q) {
    uint8_t d[8];
    memset(d, 0xFF, sizeof d);
    d[0] = b0;
    send_pd(tc, my, d, q);
}

static void pd_head(uint8_t d[8], unsigned cmd, uint16_t element, uint16_t ddi) {
    d[0] = (uint8_t)((cmd & 0x0Fu) | ((element & 0x0Fu) << 4));
    d[1] = (uint8_t)((element >> 4) & 0xFFu);
    d[2] = (uint8_t)(ddi & 0xFFu);
    d[3] = (uint8_t)(ddi >> 8);
}

static void send_value(const td_tc_t *tc, uint8_t my, const td_tc_var_t *v, td_ib_txq_t *q) {
    uint8_t d[8];
    pd_head(d, PD_VALUE, v->element, v->ddi);
    td_ib_put_u32(&d[4], (uint32_t)v->value);
    send_pd(tc, my, d, q);
}

static void send_pdack(td_tc_t *tc, uint8_t my, uint16_t element, uint16_t ddi, uint8_t errors,
                       unsigned cmd, td_ib_txq_t *q) {
    uint8_t d[8];
    pd_head(d, PD_ACK, element, ddi);
    d[4] = errors;
    d[5] = (uint8_t)(cmd & 0x0Fu);
    d[6] = 0xFFu;
    d[7] = 0xFFu;
    send_pd(tc, my, d, q);
    tc->pdacks_sent++;
}

static void add_var(td_tc_t *tc, unsigned *n, uint16_t element, uint16_t ddi, bool settable) {
    td_tc_var_t *v = &tc->vars[*n];
    memset(v, 0, sizeof *v);
    v->element = element;
    v->ddi = ddi;
    v->settable = settable;
    (*n)++;
}

int td_tc_init(td_tc_t *tc, uint64_t name, uint32_t tc_timeout_us) {
    unsigned n = 0u;
    unsigned layer;
    if (tc == NULL || tc_timeout_us == 0u) {
        return TD_IB_E_ARG;
    }
    memset(tc, 0, sizeof *tc);
    tc->tc_addr = TD_IB_ADDR_NULL;
    tc->tc_timeout_us = tc_timeout_us;
    tc->pool[0] = 0x61u;
    memcpy(&tc->pool[1], td_ddop_pool, TD_DDOP_LEN);
    td_ibname_to_bytes(name, &tc->pool[1u + TD_DDOP_NAME_OFFSET]);
    add_var(tc, &n, TD_DDOP_EL_DEVICE, 141u, false);
    add_var(tc, &n, TD_DDOP_EL_BOOM, 160u, true);
    add_var(tc, &n, TD_DDOP_EL_BOOM, 289u, true);
    add_var(tc, &n, TD_DDOP_EL_BOOM, 161u, false);
    add_var(tc, &n, TD_DDOP_EL_BOOM, 290u, true);
    add_var(tc, &n, TD_DDOP_EL_BOOM, 116u, false);
    for (layer = 0u; layer < 2u; layer++) {
        /* a one-layer machine has one bin: its variables are listed twice, harmlessly */
        const uint16_t el = (uint16_t)(layer == 0u ? TD_DDOP_EL_UPPER : TD_DDOP_EL_LOWER);
        add_var(tc, &n, el, 6u, true);
        add_var(tc, &n, el, 7u, false);
        add_var(tc, &n, el, 75u, false);
        add_var(tc, &n, el, 81u, false);
    }
    return TD_IB_OK;
}

static td_tc_var_t *find(td_tc_t *tc, uint16_t element, uint16_t ddi) {
    unsigned i;
    for (i = 0u; i < TD_TC_VARS; i++) {
        if (tc->vars[i].element == element && tc->vars[i].ddi == ddi) {
            return &tc->vars[i];
        }
    }
    return NULL;
}

const td_tc_var_t *td_tc_var(const td_tc_t *tc, uint16_t element, uint16_t ddi) {
    return tc == NULL ? NULL : find((td_tc_t *)(uintptr_t)tc, element, ddi);
}

static bool element_known(const td_tc_t *tc, uint16_t element) {
    unsigned i;
    for (i = 0u; i < TD_TC_VARS; i++) {
        if (tc->vars[i].element == element) {
            return true;
        }
    }
    return false;
}

static void enter(td_tc_t *tc, td_tc_state_t s, uint32_t now_us) {
    tc->state = s;
    tc->state_us = now_us;
}

/* What the state asks of the TC (sent on entering and repeated on its timeout). */
static void ask(td_tc_t *tc, uint8_t my, uint32_t now_us, td_ib_txq_t *q) {
    uint8_t d[8];
    tc->state_us = now_us;
    switch (tc->state) {
    case TD_TC_VERSION:
        memset(d, 0xFF, sizeof d);
        d[0] = 1u; /* one member: ourselves */
        (void)td_ib_send8(q, 6u, TD_IB_PGN_WORKING_SET_MASTER, TD_IB_ADDR_GLOBAL, my, d);
        send_dev(tc, my, 0x00u, q);
        break;
    case TD_TC_LANGUAGE:
        d[0] = (uint8_t)(TD_IB_PGN_LANGUAGE & 0xFFu);
        d[1] = (uint8_t)((TD_IB_PGN_LANGUAGE >> 8) & 0xFFu);
        d[2] = 0u;
        memset(&d[3], 0xFF, 5u);
        (void)td_ib_send8(q, 6u, TD_IB_PGN_REQUEST, tc->tc_addr, my, d);
        break;
    case TD_TC_STRUCTURE:
        send_dev(tc, my, 0x01u, q);
        break;
    case TD_TC_LOCALIZATION:
        send_dev(tc, my, 0x21u, q);
        break;
    case TD_TC_POOL_SIZE:
        memset(d, 0xFF, sizeof d);
        d[0] = 0x41u;
        td_ib_put_u32(&d[1], (uint32_t)TD_DDOP_LEN);
        send_pd(tc, my, d, q);
        break;
    case TD_TC_ACTIVATE:
        send_dev(tc, my, 0x81u, q); /* byte 1 0xFF: activate */
        break;
    case TD_TC_NO_ADDRESS:
    case TD_TC_WAIT_STATUS:
    case TD_TC_POOL_TRANSFER:
    case TD_TC_CONNECTED:
    case TD_TC_REFUSED:
        break;
    }
}

static void go(td_tc_t *tc, td_tc_state_t s, uint8_t my, uint32_t now_us, td_ib_txq_t *q) {
    enter(tc, s, now_us);
    ask(tc, my, now_us, q);
}

static void refuse(td_tc_t *tc, uint8_t code, uint32_t now_us) {
    tc->refuse_code = code;
    tc->alarm = true;
    enter(tc, TD_TC_REFUSED, now_us);
}

static void on_device(td_tc_t *tc, const uint8_t *d, uint32_t len, uint8_t my, uint32_t now_us,
                      td_ib_txq_t *q) {
    const unsigned sub = d[0] >> 4;
    if (sub == 1u && tc->state == TD_TC_STRUCTURE && len >= 8u) {
        if (memcmp(&d[1], td_ddop_structure_label, 7u) == 0) {
            go(tc, TD_TC_LOCALIZATION, my, now_us, q);
        } else {
            go(tc, TD_TC_POOL_SIZE, my, now_us, q);
        }
    } else if (sub == 3u && tc->state == TD_TC_LOCALIZATION && len >= 8u) {
        const uint8_t *ours = &tc->pool[1u + TD_DDOP_LOCALIZATION_OFFSET];
        go(tc, memcmp(&d[1], ours, 7u) == 0 ? TD_TC_ACTIVATE : TD_TC_POOL_SIZE, my, now_us, q);
    } else if (sub == 5u && tc->state == TD_TC_POOL_SIZE) {
        if (d[1] != 0u) {
            refuse(tc, d[1], now_us);
        } else {
            enter(tc, TD_TC_POOL_TRANSFER, now_us);
            tc->state_us = now_us - TD_TC_STEP_TIMEOUT_US; /* the step starts the transfer */
        }
    } else if (sub == 7u && tc->state == TD_TC_POOL_TRANSFER) {
        if (d[1] != 0u) {
            refuse(tc, d[1], now_us);
        } else {
            go(tc, TD_TC_ACTIVATE, my, now_us, q);
        }
    } else if (sub == 9u && tc->state == TD_TC_ACTIVATE) {
        if (d[1] != 0u) {
            refuse(tc, d[1], now_us);
        } else {
            enter(tc, TD_TC_CONNECTED, now_us);
            tc->alarm = false;
            tc->connects++;
            tc->task_us = now_us - TD_TC_TASK_PERIOD_US;
        }
    }
}

static uint8_t check_value(const td_tc_var_t *v, int32_t value) {
    switch (v->ddi) {
    case 6u:
        return (value < TD_DDOP_RATE_MIN_MG_M2 || value > TD_DDOP_RATE_MAX_MG_M2)
                   ? TD_TC_PDACK_OUT_OF_RANGE : 0u;
    case 160u:
    case 289u:
        return (value < 0 || value > 3) ? TD_TC_PDACK_OUT_OF_RANGE : 0u;
    default:
        return 0u;
    }
}

static void on_value(td_tc_t *tc, unsigned cmd, uint16_t element, uint16_t ddi, int32_t value,
                     uint8_t my, td_ib_txq_t *q) {
    td_tc_var_t *v = find(tc, element, ddi);
    uint8_t err = 0u;
    if (v == NULL) {
        err = element_known(tc, element) ? TD_TC_PDACK_BAD_DDI : TD_TC_PDACK_BAD_ELEMENT;
    } else if (!v->settable) {
        err = TD_TC_PDACK_NOT_SETTABLE;
    } else {
        err = check_value(v, value);
    }
    if (err != 0u) {
        tc->values_refused++;
        send_pdack(tc, my, element, ddi, err, cmd, q);
        return;
    }
    v->value = value;
    tc->values_set++;
    if (cmd == PD_SET_ACK) {
        send_pdack(tc, my, element, ddi, 0u, cmd, q);
    }
}

static void on_measure(td_tc_t *tc, unsigned cmd, uint16_t element, uint16_t ddi, int32_t value,
                       uint8_t my, td_ib_txq_t *q) {
    td_tc_var_t *v = find(tc, element, ddi);
    if (v == NULL) {
        send_pdack(tc, my, element, ddi,
                   element_known(tc, element) ? TD_TC_PDACK_BAD_DDI : TD_TC_PDACK_BAD_ELEMENT, cmd,
                   q);
        return;
    }
    if ((cmd == PD_TIME || cmd == PD_DIST || cmd == PD_CHANGE) && value < 0) {
        send_pdack(tc, my, element, ddi, TD_TC_PDACK_BAD_INTERVAL, cmd, q);
        return;
    }
    switch (cmd) {
    case PD_TIME:
        v->time_ms = (uint32_t)value;
        break;
    case PD_DIST:
        v->dist_mm = (uint32_t)value;
        break;
    case PD_MIN:
        v->min_thr = value;
        v->min_on = true;
        break;
    case PD_MAX:
        v->max_thr = value;
        v->max_on = true;
        break;
    default:
        v->change = value;
        break;
    }
    v->sent_once = false; /* report the value now, then as triggered */
}

static void on_connected_pd(td_tc_t *tc, const uint8_t *d, uint8_t da, uint8_t my,
                            td_ib_txq_t *q) {
    const unsigned cmd = d[0] & 0x0Fu;
    const uint16_t element = (uint16_t)((d[0] >> 4) | ((unsigned)d[1] << 4));
    const uint16_t ddi = (uint16_t)(d[2] | ((unsigned)d[3] << 8));
    const int32_t value = (int32_t)td_ib_get_u32(&d[4]);
    switch (cmd) {
    case PD_REQ_VALUE:
        if (ddi == DDI_REQUEST_DEFAULT) {
            for (unsigned i = 0u; i < TD_TC_VARS; i++) {
                tc->vars[i].sent_once = false; /* the step sends them as the queue allows */
            }
        } else {
            const td_tc_var_t *v = find(tc, element, ddi);
            if (v == NULL) {
                send_pdack(tc, my, element, ddi,
                           element_known(tc, element) ? TD_TC_PDACK_BAD_DDI
                                                      : TD_TC_PDACK_BAD_ELEMENT,
                           cmd, q);
            } else {
                send_value(tc, my, v, q);
            }
        }
        break;
    case PD_VALUE:
    case PD_SET_ACK:
        on_value(tc, cmd, element, ddi, value, my, q);
        break;
    case PD_TIME:
    case PD_DIST:
    case PD_MIN:
    case PD_MAX:
    case PD_CHANGE:
        on_measure(tc, cmd, element, ddi, value, my, q);
        break;
    default:
        if (da == my && cmd != PD_ACK && cmd != PD_TASK && cmd != PD_STATUS) {
            send_pdack(tc, my, element, ddi, TD_TC_PDACK_CMD_UNSUPPORTED, cmd, q);
        }
        break;
    }
}

int td_tc_rx(td_tc_t *tc, uint32_t pgn, uint8_t sa, uint8_t da, const uint8_t *d, uint32_t len,
             uint8_t my_addr, uint32_t now_us, td_ib_txq_t *q) {
    unsigned cmd;
    if (tc == NULL || d == NULL || q == NULL) {
        return TD_IB_E_ARG;
    }
    if (my_addr == TD_IB_ADDR_NULL || sa == my_addr) {
        return 0;
    }
    if (tc->state == TD_TC_NO_ADDRESS) {
        enter(tc, TD_TC_WAIT_STATUS, now_us); /* claimed since the last step */
    }
    if (pgn == TD_IB_PGN_LANGUAGE) {
        if (len < 2u) {
            return TD_IB_E_FRAME;
        }
        tc->language[0] = (char)d[0];
        tc->language[1] = (char)d[1];
        if (tc->state == TD_TC_LANGUAGE && sa == tc->tc_addr) {
            go(tc, TD_TC_STRUCTURE, my_addr, now_us, q);
        }
        return 1;
    }
    if (pgn != TD_IB_PGN_PROCESS_DATA) {
        return 0;
    }
    if (len < 8u) {
        return TD_IB_E_FRAME;
    }
    if (da != my_addr && da != TD_IB_ADDR_GLOBAL) {
        return 0;
    }
    cmd = d[0] & 0x0Fu;
    if (cmd == PD_STATUS) {
        if (tc->state == TD_TC_WAIT_STATUS) {
            tc->tc_addr = sa;
            tc->my_addr = my_addr;
            tc->last_status_us = now_us;
            tc->task_active = (d[4] & 1u) != 0u;
            go(tc, TD_TC_VERSION, my_addr, now_us, q);
        } else if (sa == tc->tc_addr) {
            tc->last_status_us = now_us;
            tc->task_active = (d[4] & 1u) != 0u;
        }
        return 1;
    }
    if (sa != tc->tc_addr || da != my_addr) {
        return 0;
    }
    if (cmd == PD_TECH) {
        if ((d[0] >> 4) == 0u) {
            const uint8_t v[8] = {0x10u, TC_VERSION, 0xFFu, TC_OPTIONS, 0u, 1u,
                                  (uint8_t)TD_DDOP_SECTIONS, (uint8_t)TD_DDOP_LAYERS};
            send_pd(tc, my_addr, v, q);
        } else if ((d[0] >> 4) == 1u && tc->state == TD_TC_VERSION) {
            tc->tc_version = d[1];
            tc->tc_options = d[3];
            go(tc, TD_TC_LANGUAGE, my_addr, now_us, q);
        }
        return 1;
    }
    if (cmd == PD_DEVICE) {
        on_device(tc, d, len, my_addr, now_us, q);
        return 1;
    }
    if (tc->state == TD_TC_CONNECTED) {
        on_connected_pd(tc, d, da, my_addr, q);
    }
    return 1;
}

static bool crossed(int32_t thr, int32_t before, int32_t now, bool below) {
    return below ? (now < thr && before >= thr) : (now > thr && before <= thr);
}

static void measure(td_tc_t *tc, uint8_t my, uint32_t now_us, uint32_t dist_mm, td_ib_txq_t *q) {
    unsigned i;
    for (i = 0u; i < TD_TC_VARS && q->count + 2u < TD_IB_TXQ_LEN; i++) {
        td_tc_var_t *v = &tc->vars[i];
        bool due = !v->sent_once;
        const int64_t delta = (int64_t)v->value - v->last_sent; /* any two int32 values */
        if (find(tc, v->element, v->ddi) != v) {
            continue; /* the second copy of a one-layer machine's bin */
        }
        if (v->time_ms != 0u && td_ib_elapsed_us(now_us, v->last_us) >= v->time_ms * 1000u) {
            due = true;
        }
        if (v->dist_mm != 0u && dist_mm - v->last_mm >= v->dist_mm) {
            due = true;
        }
        if (v->change != 0 && (delta >= v->change || -delta >= v->change)) { /* both widen */
            due = true;
        }
        if ((v->min_on && crossed(v->min_thr, v->last_sent, v->value, true)) ||
            (v->max_on && crossed(v->max_thr, v->last_sent, v->value, false))) {
            due = true;
        }
        if (due) {
            send_value(tc, my, v, q);
            v->last_sent = v->value;
            v->last_us = now_us;
            v->last_mm = dist_mm;
            v->sent_once = true;
        }
    }
}

void td_tc_step(td_tc_t *tc, uint8_t my_addr, uint32_t now_us, uint32_t distance_mm,
                td_tp_t *tp, td_ib_txq_t *q) {
    if (tc == NULL || tp == NULL || q == NULL) {
        return;
    }
    if (my_addr == TD_IB_ADDR_NULL) {
        if (tc->state != TD_TC_NO_ADDRESS && tc->state != TD_TC_WAIT_STATUS) {
            tc->alarm = true;
        }
        enter(tc, TD_TC_NO_ADDRESS, now_us);
        return;
    }
    if (tc->state == TD_TC_NO_ADDRESS) {
        enter(tc, TD_TC_WAIT_STATUS, now_us);
    }
    if (tc->state != TD_TC_WAIT_STATUS && tc->state != TD_TC_REFUSED && my_addr != tc->my_addr) {
        /* a higher-priority NAME took our address and we moved: the TC knows the client by
         * its address, so connect again from the new one; no rates meanwhile */
        tc->alarm = true;
        enter(tc, TD_TC_WAIT_STATUS, now_us);
    }
    if (tc->state != TD_TC_WAIT_STATUS &&
        td_ib_elapsed_us(now_us, tc->last_status_us) > tc->tc_timeout_us) {
        tc->alarm = true; /* TC lost: setpoints fall back to zero, connect again from scratch */
        tc->tc_addr = TD_IB_ADDR_NULL;
        enter(tc, TD_TC_WAIT_STATUS, now_us);
        return;
    }
    switch (tc->state) {
    case TD_TC_VERSION:
    case TD_TC_STRUCTURE:
    case TD_TC_LOCALIZATION:
    case TD_TC_POOL_SIZE:
    case TD_TC_ACTIVATE:
        if (td_ib_elapsed_us(now_us, tc->state_us) > TD_TC_STEP_TIMEOUT_US) {
            ask(tc, my_addr, now_us, q);
        }
        break;
    case TD_TC_LANGUAGE:
        if (td_ib_elapsed_us(now_us, tc->state_us) > TD_TC_STEP_TIMEOUT_US) {
            go(tc, TD_TC_STRUCTURE, my_addr, now_us, q); /* the language is optional */
        }
        break;
    case TD_TC_POOL_TRANSFER:
        if (tp->tx.state == TD_TP_TX_BUSY) {
            tc->state_us = now_us;
        } else if (td_ib_elapsed_us(now_us, tc->state_us) >= TD_TC_STEP_TIMEOUT_US) {
            if (td_tp_send(tp, TD_IB_PGN_PROCESS_DATA, my_addr, tc->tc_addr, tc->pool,
                           (uint32_t)sizeof tc->pool, now_us, q) == TD_IB_OK) {
                tc->state_us = now_us;
            }
        }
        break;
    case TD_TC_CONNECTED:
        if (td_ib_elapsed_us(now_us, tc->task_us) >= TD_TC_TASK_PERIOD_US) {
            const uint8_t d[8] = {0xFFu, 0xFFu, 0xFFu, 0xFFu, 0u, 0u, 0u, 0u};
            (void)td_ib_send8(q, 6u, TD_IB_PGN_PROCESS_DATA, tc->tc_addr, my_addr, d);
            tc->task_us = now_us;
        }
        measure(tc, my_addr, now_us, distance_mm, q);
        break;
    case TD_TC_NO_ADDRESS:
    case TD_TC_WAIT_STATUS:
    case TD_TC_REFUSED:
        break;
    }
}

int td_tc_set_actual(td_tc_t *tc, uint16_t element, uint16_t ddi, int32_t value) {
    td_tc_var_t *v;
    if (tc == NULL) {
        return TD_IB_E_ARG;
    }
    v = find(tc, element, ddi);
    if (v == NULL || v->settable) {
        return TD_IB_E_ARG;
    }
    v->value = value;
    return TD_IB_OK;
}

int32_t td_tc_rate_mg_m2(const td_tc_t *tc, unsigned layer) {
    const td_tc_var_t *v;
    if (tc == NULL || tc->state != TD_TC_CONNECTED || layer > 1u) {
        return 0;
    }
    v = td_tc_var(tc, (uint16_t)(layer == 0u ? TD_DDOP_EL_UPPER : TD_DDOP_EL_LOWER), 6u);
    return v == NULL ? 0 : v->value;
}

uint16_t td_tc_sections_on(const td_tc_t *tc) {
    const td_tc_var_t *master, *auto_sc, *cond;
    uint16_t mask = 0u;
    unsigned i;
    if (tc == NULL || tc->state != TD_TC_CONNECTED) {
        return 0u;
    }
    master = td_tc_var(tc, TD_DDOP_EL_BOOM, 289u);
    auto_sc = td_tc_var(tc, TD_DDOP_EL_BOOM, 160u);
    cond = td_tc_var(tc, TD_DDOP_EL_BOOM, 290u);
    if (master == NULL || auto_sc == NULL || cond == NULL || master->value != 1) {
        return 0u;
    }
    for (i = 0u; i < TD_DDOP_SECTIONS; i++) {
        const uint32_t bits = ((uint32_t)cond->value >> (2u * i)) & 3u;
        if (auto_sc->value != 1 || bits == SEC_BITS_ON) {
            mask = (uint16_t)(mask | (1u << i));
        }
    }
    return mask;
}
