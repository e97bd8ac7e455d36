/**
 * @file td_prop.h
 * @brief The frames of the paper's bus on an ISOBUS: the project's private frames on
 *        Proprietary A/B PGNs (J1939-21), sent from and to the claimed addresses.
 *
 * The paper's bus gives every frame a fixed identifier (fixed source and destination bytes);
 * on an ISOBUS the source is whatever address the sender claimed, so each frame moves to the
 * PGN of its IsobusPgn attribute in protocol/topdress.dbc (generated: td_prop_gen.h):
 * Proprietary B (0xFF00 + group extension) for broadcasts from their sender, Proprietary A
 * (0xEF00) and A2 (0x1EF00) for frames to one address. The frame's 8 data bytes stay as they
 * are. A frame whose attribute is 0 (the PcCommand: on an ISOBUS the Task Controller sets the
 * rates) has no ISOBUS form. Both sides use this module: the ECU (sender TD_PROP_ECU) and the
 * terminal or a test (TD_PROP_TERMINAL).
 */
#ifndef TD_PROP_H
#define TD_PROP_H

#include <stdint.h>

#include "td_ib.h"

#define TD_IB_E_SOURCE (-26) /**< a private frame from an address that is not the peer's */

#define TD_PROP_PGN_A 0x00EF00u  /**< Proprietary A, destination-specific */
#define TD_PROP_PGN_A2 0x01EF00u /**< Proprietary A2 (data page 1) */

/** Who sends a frame (the DBC's sender). */
typedef enum { TD_PROP_TERMINAL = 0, TD_PROP_ECU = 1 } td_prop_side_t;

/**
 * The paper's-bus frame `core`, sent by `side`, as the ISOBUS frame from `sa` (to `da` for
 * Proprietary A). TD_IB_OK; TD_IB_E_FRAME when `core` has no ISOBUS form or is not `side`'s;
 * TD_IB_E_NO_ADDRESS when `sa` is not a claimed address (null or global) or a Proprietary A
 * frame has no destination.
 */
int td_prop_to_bus(const td_can_frame_t *core, td_prop_side_t side, uint8_t sa, uint8_t da,
                   td_can_frame_t *out);

/**
 * An ISOBUS frame heard by the other side of `side`: 1 when it is one of `side`'s private
 * frames from `peer` (to `my_addr` for Proprietary A), `core` then holds it with its fixed
 * identifier; 0 when it is none of them (other traffic); TD_IB_E_SOURCE when it is one of
 * them from another address, or `peer` is unknown (TD_IB_ADDR_NULL): to be ignored and
 * counted. A Proprietary A frame to another address is other traffic.
 */
int td_prop_from_bus(const td_can_frame_t *bus, td_prop_side_t side, uint8_t peer,
                     uint8_t my_addr, td_can_frame_t *core);

#endif
