/**
 * @file td_slcan.c
 * @brief SLCAN encode and decode (td_slcan.h).
 */
#include "td_slcan.h"

#include <stddef.h>
#include <string.h>
#include "td_common.h"

#define CR '\r'
#define BEL '\a'

static const char HEX[] = "0123456789ABCDEF";

void td_slcan_init(td_slcan_parser_t *p) {
    memset(p, 0, sizeof *p);
}

static int hexval(char c) {
    if (c >= '0' && c <= '9') {
        return c - '0';
    }
    if (c >= 'A' && c <= 'F') {
        return c - 'A' + 10;
    }
    if (c >= 'a' && c <= 'f') {
        return c - 'a' + 10;
    }
    return -1;
}

/* n hex digits at s; false on a non-hex character */
static bool hexn(const char *s, unsigned n, uint32_t *out) {
    uint32_t v = 0u;
    for (unsigned i = 0u; i < n; i++) {
        const int d = hexval(s[i]);
        if (d < 0) {
            return false;
        }
        v = (v << 4) | (uint32_t)d;
    }
    *out = v;
    return true;
}

static td_slcan_event_t parse_frame(const char *s, unsigned len, td_can_frame_t *f) {
    const bool ext = s[0] == 'T';
    const unsigned id_len = ext ? 8u : 3u;
    uint32_t id;
    uint32_t dlc;
    if (len < 1u + id_len + 1u || !hexn(s + 1, id_len, &id) || !hexn(s + 1 + id_len, 1u, &dlc) || dlc > 8u) {
        return TD_SLCAN_ERROR;
    }
    if (id > (ext ? 0x1FFFFFFFu : 0x7FFu)) {
        return TD_SLCAN_ERROR;
    }
    const unsigned data_at = 2u + id_len;
    const unsigned rest = len - data_at;
    /* the data, optionally followed by a 4-digit time stamp */
    if (rest != 2u * dlc && rest != 2u * dlc + 4u) {
        return TD_SLCAN_ERROR;
    }
    memset(f->data, 0, sizeof f->data);
    for (unsigned i = 0u; i < dlc; i++) {
        uint32_t b;
        if (!hexn(s + data_at + (size_t)2u * i, 2u, &b)) {
            return TD_SLCAN_ERROR;
        }
        f->data[i] = (uint8_t)b;
    }
    uint32_t stamp;
    if (rest == 2u * dlc + 4u && !hexn(s + data_at + (size_t)2u * dlc, 4u, &stamp)) {
        return TD_SLCAN_ERROR;
    }
    f->id = id;
    f->extended = ext ? 1u : 0u;
    f->dlc = (uint8_t)dlc;
    return TD_SLCAN_FRAME;
}

static td_slcan_event_t parse_line(const char *s, unsigned len, td_can_frame_t *f, uint8_t *arg) {
    if (len == 0u) {
        return TD_SLCAN_NONE;
    }
    switch (s[0]) {
    case 't':
    case 'T':
        return parse_frame(s, len, f);
    case 'O':
    case 'L':
        return len == 1u ? TD_SLCAN_OPEN : TD_SLCAN_ERROR;
    case 'C':
        return len == 1u ? TD_SLCAN_CLOSE : TD_SLCAN_ERROR;
    case 'S':
        if (len == 2u && s[1] >= '0' && s[1] <= '8') {
            *arg = (uint8_t)(s[1] - '0');
            return TD_SLCAN_BITRATE;
        }
        return TD_SLCAN_ERROR;
    case 'V':
        return len == 1u ? TD_SLCAN_VERSION : TD_SLCAN_ERROR;
    case 'N':
        return len == 1u ? TD_SLCAN_SERIAL : TD_SLCAN_ERROR;
    case 'F':
        return len == 1u ? TD_SLCAN_STATUS : TD_SLCAN_ERROR;
    default:
        return TD_SLCAN_ERROR;
    }
}

td_slcan_event_t td_slcan_feed(td_slcan_parser_t *p, uint8_t byte, td_can_frame_t *frame, uint8_t *arg) {
    if (byte == (uint8_t)CR) {
        td_slcan_event_t ev = TD_SLCAN_ERROR;
        if (!p->overflow) {
            uint8_t dummy = 0u;
            td_can_frame_t scratch;
            ev = parse_line(p->line, p->len, frame != NULL ? frame : &scratch, arg != NULL ? arg : &dummy);
        }
        p->len = 0u;
        p->overflow = false;
        if (ev == TD_SLCAN_ERROR) {
            p->errors++;
        }
        return ev;
    }
    if (byte == (uint8_t)'\n' && p->len == 0u) {
        return TD_SLCAN_NONE; /* a terminal's CR LF */
    }
    if (p->len >= TD_SLCAN_LINE_MAX - 1u) {
        p->overflow = true;
        return TD_SLCAN_NONE;
    }
    p->line[p->len++] = (char)byte;
    return TD_SLCAN_NONE;
}

int td_slcan_encode(const td_can_frame_t *f, char *buf, unsigned size) {
    if (f == NULL || buf == NULL || f->dlc > 8u || f->id > (f->extended != 0u ? 0x1FFFFFFFu : 0x7FFu)) {
        return TD_E_ARG;
    }
    const unsigned id_len = f->extended != 0u ? 8u : 3u;
    const unsigned len = 1u + id_len + 1u + 2u * f->dlc + 1u;
    if (size < len) {
        return TD_E_ARG;
    }
    unsigned n = 0u;
    buf[n++] = f->extended != 0u ? 'T' : 't';
    for (unsigned i = 0u; i < id_len; i++) {
        buf[n++] = HEX[(f->id >> (4u * (id_len - 1u - i))) & 0xFu];
    }
    buf[n++] = HEX[f->dlc];
    for (unsigned i = 0u; i < f->dlc; i++) {
        buf[n++] = HEX[f->data[i] >> 4];
        buf[n++] = HEX[f->data[i] & 0xFu];
    }
    buf[n++] = CR;
    return (int)n;
}

unsigned td_slcan_reply(td_slcan_event_t ev, char *buf, unsigned size) {
    static const char version[] = "V0100\r";
    static const char serial[] = "NTD01\r";
    static const char status[] = "F00\r";
    const char *s;
    switch (ev) {
    case TD_SLCAN_OPEN:
    case TD_SLCAN_CLOSE:
    case TD_SLCAN_BITRATE:
        s = "\r";
        break;
    case TD_SLCAN_VERSION:
        s = version;
        break;
    case TD_SLCAN_SERIAL:
        s = serial;
        break;
    case TD_SLCAN_STATUS:
        s = status;
        break;
    case TD_SLCAN_ERROR:
        s = "\a";
        break;
    case TD_SLCAN_NONE:
    case TD_SLCAN_FRAME:
    default:
        return 0u; /* a frame or nothing: no reply */
    }
    const unsigned n = (unsigned)strlen(s);
    if (buf == NULL || size < n) {
        return 0u;
    }
    /* an SLCAN reply is bytes on a line, not a C string: no terminator is sent */
    memcpy(buf, s, n); /* NOLINT(bugprone-not-null-terminated-result) */
    return n;
}
