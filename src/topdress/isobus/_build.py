"""cffi (API mode) builder of `topdress.isobus._isobus`: the ECU's ISOBUS layer (ecu/isobus)
compiled into the package, so the terminal and the tests use the very C codecs the ECU runs.

setup.py runs from the repository root. The cdef restates the public part of
ecu/isobus/include/td_*.h; `...;` lets the C compiler supply struct layouts.
"""

from __future__ import annotations

from glob import glob

from cffi import FFI

CDEF = r"""
typedef struct { uint32_t id; uint8_t extended; uint8_t dlc; uint8_t data[8]; ...; } td_can_frame_t;

/* td_ib.h */
#define TD_IB_OK ...
#define TD_IB_E_ARG ...
#define TD_IB_E_FRAME ...
#define TD_IB_E_BUSY ...
#define TD_IB_E_FULL ...
#define TD_IB_E_TOO_LONG ...
#define TD_IB_ADDR_GLOBAL ...
#define TD_IB_ADDR_NULL ...
#define TD_IB_TXQ_LEN ...
typedef struct { uint8_t count; uint32_t dropped; ...; } td_ib_txq_t;
typedef struct { uint8_t priority; uint32_t pgn; uint8_t sa; uint8_t da; } td_ib_id_t;
void td_ib_txq_init(td_ib_txq_t *q);
bool td_ib_txq_pop(td_ib_txq_t *q, td_can_frame_t *out);
uint32_t td_ib_id_pack(uint8_t priority, uint32_t pgn, uint8_t da, uint8_t sa);
td_ib_id_t td_ib_id_unpack(uint32_t id);

/* td_ibname.h */
typedef struct {
    uint32_t identity_number; uint16_t manufacturer_code; uint8_t ecu_instance;
    uint8_t function_instance; uint8_t function; uint8_t device_class;
    uint8_t device_class_instance; uint8_t industry_group; uint8_t self_configurable;
} td_ibname_t;
int td_ibname_encode(const td_ibname_t *n, uint64_t *out);
void td_ibname_decode(uint64_t name, td_ibname_t *out);
int td_ibname_topdress(uint16_t manufacturer_code, const uint8_t *uid, size_t uid_len,
                       td_ibname_t *out);

/* td_claim.h */
typedef enum { TD_CLAIM_IDLE = 0, TD_CLAIM_CLAIMING = 1, TD_CLAIM_CLAIMED = 2,
               TD_CLAIM_FAILED = 3 } td_claim_state_t;
typedef struct { uint64_t name; uint8_t address; td_claim_state_t state;
                 uint32_t contests_won; uint32_t contests_lost; ...; } td_claim_t;
int td_claim_init(td_claim_t *c, uint64_t name, uint8_t preferred, uint8_t range_lo,
                  uint8_t range_hi);
int td_claim_start(td_claim_t *c, uint32_t now_us, td_ib_txq_t *q);
int td_claim_rx(td_claim_t *c, const td_can_frame_t *f, uint32_t now_us, td_ib_txq_t *q);
void td_claim_step(td_claim_t *c, uint32_t now_us);
uint8_t td_claim_address(const td_claim_t *c);

/* td_tp.h */
typedef enum { TD_TP_TX_IDLE = 0, TD_TP_TX_BUSY, TD_TP_TX_DONE, TD_TP_TX_ABORTED,
               TD_TP_TX_TIMEOUT } td_tp_tx_state_t;
typedef struct { td_tp_tx_state_t state; uint8_t abort_reason; ...; } td_tp_tx_t;
typedef struct { uint32_t pgn; uint8_t sa; uint8_t da; const uint8_t *data; uint32_t len; }
    td_tp_msg_t;
typedef struct { td_tp_tx_t tx; td_tp_msg_t msg;
                 uint32_t rx_done, rx_aborts, rx_timeouts, rx_ignored; ...; } td_tp_t;
int td_tp_init(td_tp_t *tp, uint8_t *conn_buf, uint32_t conn_cap, uint8_t *bam_buf,
               uint32_t bam_cap);
int td_tp_send(td_tp_t *tp, uint32_t pgn, uint8_t sa, uint8_t da, const uint8_t *data,
               uint32_t len, uint32_t now_us, td_ib_txq_t *q);
int td_tp_rx(td_tp_t *tp, const td_can_frame_t *f, uint8_t my_addr, uint32_t now_us,
             td_ib_txq_t *q);
void td_tp_step(td_tp_t *tp, uint32_t now_us, td_ib_txq_t *q);
void td_tp_cancel(td_tp_t *tp, td_ib_txq_t *q);

/* td_tc.h */
typedef enum { TD_TC_NO_ADDRESS = 0, TD_TC_WAIT_STATUS, TD_TC_VERSION, TD_TC_LANGUAGE,
               TD_TC_STRUCTURE, TD_TC_LOCALIZATION, TD_TC_POOL_SIZE, TD_TC_POOL_TRANSFER,
               TD_TC_ACTIVATE, TD_TC_CONNECTED, TD_TC_REFUSED } td_tc_state_t;
typedef struct { td_tc_state_t state; uint8_t tc_addr; uint8_t tc_version; uint8_t tc_options;
                 char language[2]; bool task_active; bool alarm; uint8_t refuse_code;
                 uint32_t pdacks_sent, values_set, values_refused, connects; ...; } td_tc_t;
int td_tc_set_actual(td_tc_t *tc, uint16_t element, uint16_t ddi, int32_t value);
int32_t td_tc_rate_mg_m2(const td_tc_t *tc, unsigned layer);
uint16_t td_tc_sections_on(const td_tc_t *tc);

/* td_ddop_gen.h */
#define TD_DDOP_LEN ...
#define TD_DDOP_SECTIONS ...
#define TD_DDOP_EL_BOOM ...
#define TD_DDOP_EL_UPPER ...
#define TD_DDOP_EL_LOWER ...
#define TD_DDOP_EL_DEVICE ...

/* td_prop.h */
#define TD_IB_E_SOURCE ...
#define TD_IB_E_NO_ADDRESS ...
typedef enum { TD_PROP_TERMINAL = 0, TD_PROP_ECU = 1 } td_prop_side_t;
int td_prop_to_bus(const td_can_frame_t *core, td_prop_side_t side, uint8_t sa, uint8_t da,
                   td_can_frame_t *out);
int td_prop_from_bus(const td_can_frame_t *bus, td_prop_side_t side, uint8_t peer,
                     uint8_t my_addr, td_can_frame_t *core);

/* td_isob.h */
typedef struct { td_claim_t claim; td_tp_t tp; td_tc_t tc; td_ib_txq_t q;
                 uint32_t rx_frames; uint32_t rx_errors; uint32_t prop_rx;
                 uint32_t prop_wrong_source; ...; } td_isob_t;
int td_isob_init(td_isob_t *n, uint64_t name, uint8_t preferred, uint8_t range_lo,
                 uint8_t range_hi, uint32_t tc_timeout_us);
int td_isob_start(td_isob_t *n, uint32_t now_us);
int td_isob_rx(td_isob_t *n, const td_can_frame_t *f, uint32_t now_us);
void td_isob_step(td_isob_t *n, uint32_t now_us, uint32_t distance_mm);
bool td_isob_tx(td_isob_t *n, td_can_frame_t *out);
int td_isob_prop_rx(td_isob_t *n, const td_can_frame_t *f, td_can_frame_t *core);
int td_isob_prop_tx(const td_isob_t *n, const td_can_frame_t *core, td_can_frame_t *out);
"""

ffibuilder = FFI()
ffibuilder.cdef(CDEF)
ffibuilder.set_source(
    "topdress.isobus._isobus",
    '#include "td_isob.h"\n#include "td_ibname.h"\n',
    sources=[*sorted(glob("ecu/isobus/src/*.c")), "ecu/isobus/src/gen/td_ddop_gen.c"],
    include_dirs=["ecu/isobus/include", "ecu/isobus/src/gen", "ecu/include"],
    extra_compile_args=["-std=c99", "-O2"],
)

if __name__ == "__main__":
    ffibuilder.compile(verbose=True)
