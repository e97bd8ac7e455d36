/**
 * @file td_slcan.h
 * @brief The SLCAN (Lawicel) line protocol: CAN frames as ASCII lines over a serial link, as
 *        python-can's `slcan` interface and USB-CAN dongles speak it. No hardware here.
 *
 * Host -> ECU lines (each ends with CR): `O` open, `L` open listen-only (taken as open), `C` close,
 * `Sn` bit rate 0..8 (10k..1M; the emulator link has none, it is acknowledged and kept),
 * `V` version, `N` serial number, `F` status flags, `tIIILDD..` 11-bit and
 * `TIIIIIIIILDD..` 29-bit data frames (hex digits, either case). The answer to a command is
 * CR (done) or BEL (refused); a frame is not answered (no `z`/`Z`, as most dongles do).
 * ECU -> host: frames as `TIIIIIIIILDD..` CR (upper-case hex, no time stamp).
 * Remote frames (`r`, `R`), malformed and over-long lines are refused with BEL and counted.
 */
#ifndef TD_SLCAN_H
#define TD_SLCAN_H

#include <stdbool.h>
#include <stdint.h>
#include "td_port.h"

#define TD_SLCAN_LINE_MAX 32u   /**< longest line taken: `T` + 8 + 1 + 16 + a 4-digit time stamp + CR */
#define TD_SLCAN_FRAME_MAX 27u  /**< longest line sent: `T` + 8 + 1 + 16 + CR */

typedef enum {
    TD_SLCAN_NONE = 0,         /**< mid-line, or an empty line: nothing to do */
    TD_SLCAN_FRAME,            /**< a data frame: *frame holds it */
    TD_SLCAN_OPEN,
    TD_SLCAN_CLOSE,
    TD_SLCAN_BITRATE,          /**< `Sn`: *arg = n */
    TD_SLCAN_VERSION,
    TD_SLCAN_SERIAL,
    TD_SLCAN_STATUS,
    TD_SLCAN_ERROR             /**< refused line (counted in `errors`) */
} td_slcan_event_t;

typedef struct {
    char line[TD_SLCAN_LINE_MAX];
    uint8_t len;
    bool overflow;             /**< the current line outgrew the buffer: refused at its CR */
    uint32_t errors;           /**< lines refused */
} td_slcan_parser_t;

void td_slcan_init(td_slcan_parser_t *p);

/** Feed one received byte; at CR the line's event (a frame into *frame, `Sn` into *arg). */
td_slcan_event_t td_slcan_feed(td_slcan_parser_t *p, uint8_t byte, td_can_frame_t *frame, uint8_t *arg);

/** The line for a frame into buf (at least TD_SLCAN_FRAME_MAX bytes): its length, or TD_E_ARG
 *  (NULL, dlc > 8, an identifier too wide for its format, buffer too small). */
int td_slcan_encode(const td_can_frame_t *f, char *buf, unsigned size);

/** The answer to an event into buf (at least 8 bytes): its length (0: no answer). */
unsigned td_slcan_reply(td_slcan_event_t ev, char *buf, unsigned size);

#endif /* TD_SLCAN_H */
