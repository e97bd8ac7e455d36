"""NMEA 0183 sentences to GNSS fixes: framing and checksum here, field parsing by pynmeagps.

The decoder never raises on input: every line gives a GnssFix, with `ok=False` and an `error`
reason for a line that cannot be trusted, and every reason is counted in `NmeaDecoder.counters`.
Only RMC, VTG and GGA are parsed into fields (any talker); other well-formed sentences are
accepted (`ok=True`) and carry no fix.

A checksum-valid sentence whose only faults are in fields the fix does not stand on (RMC's
date, course and magnetic variation, VTG's courses, GGA's satellites, HDOP, altitude and
differential fields) keeps the rest, as GPSD does: a real receiver wrote `2208-1` for a date
and lost a valid position and speed with it. The bad fields are left out (`dropped`) and the
line is counted as `bad_field` (besides `ok`).
"""

from __future__ import annotations

import datetime as dt
import math
import re
import sys
from collections import Counter
from dataclasses import dataclass, replace
from typing import Any, Final

from pynmeagps import NMEAReader

KNOT_KMH = 1.852

# Least number of data fields for each parsed type (NMEA 0183 v2.0 layouts).
_MIN_FIELDS = {"RMC": 11, "VTG": 8, "GGA": 14}
# Attribute of the pynmeagps message -> index of its data field, to catch bad numbers that
# pynmeagps turns into "" instead of rejecting.
_CHECKED = {
    "RMC": {"time": 0, "lat": 2, "lon": 4, "spd": 6, "cog": 7, "date": 8},
    "VTG": {"cogt": 0, "sogn": 4, "sogk": 6},
    "GGA": {"time": 0, "lat": 1, "lon": 3, "quality": 5},
}
# The numeric fields above take NMEA's form only: unsigned digits with an optional fraction.
# Python's float() also reads "2_2.4", "-4807.038", "1e308" or "inf", which no receiver writes
# and which would pass as numbers (1e308 knots overflows to an infinite km/h).
_NUMBER = re.compile(rb"^(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)$")
# Hemisphere fields: index of the field -> the letters it may hold (empty only with no value).
_HEMISPHERES = {
    "RMC": {3: b"NS", 5: b"EW"},
    "GGA": {2: b"NS", 4: b"EW"},
    "VTG": {},
}
# Physical limits of the numbers parsed: a NaN, an infinite or negative speed, latitude 99 or a
# course of 400 pass the checksum when the receiver (or a relay) wrote them, and must not travel
# on as a valid fix (a NaN speed cannot even be put in the command frame).
_LIMITS = {
    "RMC": {
        "lat": (-90.0, 90.0),
        "lon": (-180.0, 180.0),
        "spd": (0.0, math.inf),
        "cog": (0.0, 360.0),
    },
    "VTG": {"cogt": (0.0, 360.0), "sogn": (0.0, math.inf), "sogk": (0.0, math.inf)},
    "GGA": {"lat": (-90.0, 90.0), "lon": (-180.0, 180.0)},
}
# Fields a fix does not stand on: index -> name (as in GnssFix.dropped). A malformed one is
# left out of the fix, not a reason to refuse the sentence.
_OPTIONAL = {
    "RMC": {7: "course", 8: "date", 9: "magvar", 10: "magvar_ew"},
    "VTG": {0: "course", 1: "course_ref", 2: "course_mag", 3: "course_mag_ref"},
    "GGA": {
        6: "satellites",
        7: "hdop",
        8: "altitude",
        9: "altitude_unit",
        10: "separation",
        11: "separation_unit",
        12: "diff_age",
        13: "diff_station",
    },
}
_DATE = re.compile(rb"^[0-9]{6}$")
_INTEGER = re.compile(rb"^[0-9]+$")
_SIGNED = re.compile(rb"^-?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)$")  # altitude, geoid separation
# The form each optional field must have when not empty (and a check on its value).
_UNITS = {
    "course_ref": b"T",
    "course_mag_ref": b"M",
    "altitude_unit": b"M",
    "separation_unit": b"M",
}
_ADDRESS = re.compile(rb"^[A-Z][A-Z0-9]{2,9}$")
_HEX2 = re.compile(rb"^[0-9A-Fa-f]{2}$")
_PRINTABLE = re.compile(rb"[\x20-\x7e]*")  # printable ASCII only (one scan, not a step per byte)


@dataclass(frozen=True)
class GnssFix:
    """What one NMEA line says. `utc` is ISO 8601: date and time when the sentence carries a
    date (RMC), else the time of day only; `speed_kmh`/`course_deg` from RMC or VTG."""

    talker: str | None
    type: str | None
    ok: bool
    error: str | None = None
    fix_valid: bool = False
    speed_kmh: float | None = None
    course_deg: float | None = None
    lat: float | None = None
    lon: float | None = None
    utc: str | None = None
    dropped: tuple[str, ...] = ()  # malformed optional fields left out (see the module's doc)


def nmea_checksum(body: bytes) -> int:
    """XOR of the bytes between '$' and '*'."""
    value = 0
    for b in body:
        value ^= b
    return value


def make_sentence(body: str) -> bytes:
    """A complete sentence for `body` (without '$'): '$' + body + '*' + checksum + CRLF."""
    raw = body.encode("ascii")
    return b"$" + raw + b"*" + f"{nmea_checksum(raw):02X}".encode() + b"\r\n"


class NmeaDecoder:
    """Decodes NMEA lines. `counters` counts 'ok' and each error reason:
    empty, binary, no_start, no_checksum, truncated, bad_checksum, malformed, out_of_range;
    'resync' for a sentence found after garbage on its line (decoded normally) and 'bad_field'
    for a sentence decoded without a malformed optional field (also counted 'ok')."""

    def __init__(self) -> None:
        self.counters: Counter[str] = Counter()

    def decode(self, line: bytes | str) -> GnssFix:
        raw = line.encode("latin-1", "replace") if isinstance(line, str) else bytes(line)
        fix = self._decode(raw.strip(b"\r\n\x00 "))
        self.counters["ok" if fix.ok else _reason(fix.error)] += 1
        if fix.dropped:
            self.counters["bad_field"] += 1
        return fix

    def _decode(self, raw: bytes) -> GnssFix:
        if not raw:
            return _bad("empty", "empty line")
        start = raw.rfind(b"$")
        if start < 0:
            if _printable(raw):
                return _bad("no_start", "no '$' sentence start")
            return _bad("binary", "binary data, no NMEA sentence")
        if start > 0:
            self.counters["resync"] += 1
            raw = raw[start:]
        if not _printable(raw):
            return _bad("binary", "binary data inside the sentence")
        star = raw.rfind(b"*")
        if star < 0:
            return _bad("no_checksum", "no '*hh' checksum (missing, or the line was cut)")
        body, given = raw[1:star], raw[star + 1 :]
        if len(given) < 2:
            return _bad("truncated", "line ends inside the checksum")
        if not _HEX2.match(given):
            return _bad("malformed", f"checksum field {given.decode()!r} is not two hex digits")
        if b"*" in body:
            # '*' only ever opens the checksum: a second one means two sentences ran together
            # or a corrupt one; the field parser would split it elsewhere than this framing.
            return _bad("malformed", "'*' inside the sentence body (only one '*hh' is allowed)")
        address = body.split(b",", 1)[0]
        if not _ADDRESS.match(address):
            return _bad("malformed", f"bad address field {address.decode()!r}")
        talker, kind = _split_address(address.decode())
        expected = nmea_checksum(body)
        if int(given, 16) != expected:
            msg = f"checksum {given.decode().upper()} != computed {expected:02X}"
            return _bad("bad_checksum", msg, talker, kind)
        if kind not in _MIN_FIELDS:
            return GnssFix(talker=talker, type=kind, ok=True)
        return _parse(raw[: star + 3], body, talker, kind)


def _reason(error: str | None) -> str:
    return (error or "malformed").split(":", 1)[0]


def _bad(reason: str, message: str, talker: str | None = None, kind: str | None = None) -> GnssFix:
    return GnssFix(talker=talker, type=kind, ok=False, error=f"{reason}: {message}")


def _printable(raw: bytes) -> bool:
    return _PRINTABLE.fullmatch(raw) is not None


def _split_address(address: str) -> tuple[str, str]:
    if address.startswith("P"):  # proprietary: P + manufacturer + type
        return "P", address[1:]
    return address[:2], address[2:]


def _parse(sentence: bytes, body: bytes, talker: str, kind: str) -> GnssFix:
    fields = body.split(b",")[1:]
    if len(fields) < _MIN_FIELDS[kind]:
        msg = f"{kind} has {len(fields)} fields, needs {_MIN_FIELDS[kind]}"
        return _bad("truncated", msg, talker, kind)
    fast = _FAST[kind](fields, talker)
    if fast is not None:
        return fast
    dropped = _drop_optional(fields, kind)
    if dropped:
        # parsed without them: the field parser would refuse the sentence for any one
        body = b",".join([body.split(b",", 1)[0], *fields])
        sentence = make_sentence(body.decode("ascii")).rstrip(b"\r\n")
    try:
        msg = NMEAReader.parse(sentence, validate=0)
    except Exception as exc:  # pynmeagps raises many types on odd fields
        return _bad("malformed", f"{type(exc).__name__}: {exc}", talker, kind)
    for attr, index in _CHECKED[kind].items():
        text = fields[index]
        if text and (not _NUMBER.match(text) or getattr(msg, attr, "") == ""):
            return _bad("malformed", f"{kind} field {attr}={text.decode()!r}", talker, kind)
    for index, letters in _HEMISPHERES[kind].items():
        hemi, value = fields[index], fields[index - 1]
        if (hemi or value) and (len(hemi) != 1 or hemi not in letters):
            msg_text = f"{kind} hemisphere {hemi.decode()!r} is not one of {letters.decode()}"
            return _bad("malformed", msg_text, talker, kind)
    for attr, (lo, hi) in _LIMITS[kind].items():
        number = getattr(msg, attr, "")
        if isinstance(number, int | float) and not (math.isfinite(number) and lo <= number <= hi):
            msg_text = f"{kind} field {attr}={number!r} outside {lo:g}..{hi:g}"
            return _bad("out_of_range", msg_text, talker, kind)
    fix = _FIELD_PARSERS[kind](msg, talker)
    # Checked again after converting: a finite knots value can still give an infinite km/h.
    for name in ("speed_kmh", "course_deg", "lat", "lon"):
        value = getattr(fix, name)
        if value is not None and not math.isfinite(value):
            return _bad("out_of_range", f"{kind} {name} is not finite", talker, kind)
    return replace(fix, dropped=tuple(dropped)) if dropped else fix


def _drop_optional(fields: list[bytes], kind: str) -> list[str]:
    """Blanks each malformed optional field of `fields` in place; their names."""
    out = []
    for index, name in _OPTIONAL[kind].items():
        text = fields[index]
        if text and not _optional_ok(name, text):
            fields[index] = b""
            out.append(name)
    return out


def _optional_ok(name: str, text: bytes) -> bool:
    if name == "date":
        if not _DATE.match(text):
            return False
        try:
            dt.datetime.strptime(text.decode(), "%d%m%y")
        except ValueError:
            return False
        return True
    if name in _UNITS:
        return text == _UNITS[name]
    if name == "magvar_ew":
        return text in (b"E", b"W")
    if name in ("satellites", "diff_station"):
        return _INTEGER.match(text) is not None
    if name in ("altitude", "separation"):
        return _SIGNED.match(text) is not None and math.isfinite(float(text))
    if not _NUMBER.match(text):
        return False
    limit = 180.0 if name == "magvar" else 360.0 if name.startswith("course") else math.inf
    return float(text) <= limit


def _opt(value: Any) -> float | None:
    return None if value == "" or value is None else float(value)


def _utc(time: Any, date: Any = "") -> str | None:
    if not isinstance(time, dt.time):
        return None
    clock = time.isoformat(timespec="milliseconds")
    return f"{date.isoformat()}T{clock}Z" if isinstance(date, dt.date) else clock


def _rmc(msg: Any, talker: str) -> GnssFix:
    mode = getattr(msg, "posMode", "")
    valid = msg.status == "A" and mode != "N"
    knots = _opt(msg.spd)
    return GnssFix(
        talker=talker,
        type="RMC",
        ok=True,
        fix_valid=valid and knots is not None,
        speed_kmh=None if knots is None else knots * KNOT_KMH,
        course_deg=_opt(msg.cog),
        lat=_opt(msg.lat),
        lon=_opt(msg.lon),
        utc=_utc(msg.time, msg.date),
    )


def _vtg(msg: Any, talker: str) -> GnssFix:
    kmh = _opt(msg.sogk)
    if kmh is None and (knots := _opt(msg.sogn)) is not None:
        kmh = knots * KNOT_KMH
    mode = getattr(msg, "posMode", "")
    return GnssFix(
        talker=talker,
        type="VTG",
        ok=True,
        fix_valid=kmh is not None and mode != "N",
        speed_kmh=kmh,
        course_deg=_opt(msg.cogt),
    )


def _gga(msg: Any, talker: str) -> GnssFix:
    quality = msg.quality if isinstance(msg.quality, int) else 0
    return GnssFix(
        talker=talker,
        type="GGA",
        ok=True,
        fix_valid=quality > 0,
        lat=_opt(msg.lat),
        lon=_opt(msg.lon),
        utc=_utc(msg.time),
    )


_FIELD_PARSERS = {"RMC": _rmc, "VTG": _vtg, "GGA": _gga}


# ---- the fast path: clean RMC, VTG and GGA without the field parser -----------------------
#
# A replay decodes every sentence of a day (54,000 an hour); through pynmeagps that was most of
# its time. A sentence whose every field the fix reads or checks has the plain form a receiver
# writes is decoded here with pynmeagps's own conversions (dmm2ddd's rounding, strptime's
# ranges, the hemisphere's sign); anything else (an empty or odd field, a value out of range,
# a field to drop) returns None and takes the full path, which says what is wrong.
# tests/test_gnss_fast.py holds the two equal on every sentence of the recorded logs and on
# mutants of them.

_F_TIME = re.compile(rb"^([01][0-9]|2[0-3])([0-5][0-9])([0-5][0-9])(?:\.([0-9]{1,6}))?$")
_F_DMM = re.compile(rb"^[0-9]{4,}\.[0-9]*$")


def _f_time(text: bytes) -> dt.time | None:
    m = _F_TIME.match(text)
    if m is None:
        return None
    frac = m.group(4) or b"0"
    us = int(frac.decode().ljust(6, "0"))
    return dt.time(int(m.group(1)), int(m.group(2)), int(m.group(3)), us)


def _f_date(text: bytes) -> dt.date | None:
    if len(text) != 6 or not text.isdigit():
        return None
    yy = int(text[4:6])
    try:  # strptime's %y: 69-99 are 19yy
        return dt.date((1900 if yy >= 69 else 2000) + yy, int(text[2:4]), int(text[0:2]))
    except ValueError:
        return None


def _f_pos(value: bytes, hemi: bytes, letters: bytes, limit: float) -> float | bool | None:
    """Signed degrees; None for an empty field; False when the full path must judge it."""
    if not value and not hemi:
        return None
    if len(hemi) != 1 or hemi not in letters or _F_DMM.match(value) is None:
        return False
    text = value.decode()
    dp = text.find(".")
    deg = round(abs(float(text[0 : dp - 2])) + float(text[dp - 2 :]) / 60, 10)
    if not deg <= limit:
        return False
    return -deg if hemi in b"SW" else deg


def _f_num(text: bytes, hi: float) -> float | bool | None:
    """A plain number within 0..hi (None: empty; False: for the full path)."""
    if not text:
        return None
    if _NUMBER.match(text) is None:
        return False
    value = float(text)
    return value if value <= hi else False


def _f_mode(fields: list[bytes], index: int) -> str:
    return fields[index].decode() if len(fields) > index else ""


def _fast_rmc(f: list[bytes], talker: str) -> GnssFix | None:
    time = _f_time(f[0]) if f[0] else ""
    lat = _f_pos(f[2], f[3], b"NS", 90.0)
    lon = _f_pos(f[4], f[5], b"EW", 180.0)
    knots = _f_num(f[6], _MAX_FINITE_KNOTS)
    course = _f_num(f[7], 360.0)
    date = _f_date(f[8]) if f[8] else ""
    magvar = _f_num(f[9], 180.0)
    if (
        time is None
        or date is None
        or lat is False
        or lon is False
        or knots is False
        or course is False
        or magvar is False
        or f[10] not in (b"", b"E", b"W")
    ):
        return None
    valid = f[1] == b"A" and _f_mode(f, 11) != "N"
    return GnssFix(
        talker=talker,
        type="RMC",
        ok=True,
        fix_valid=valid and knots is not None,
        speed_kmh=None if knots is None else knots * KNOT_KMH,
        course_deg=course,
        lat=lat,
        lon=lon,
        utc=_utc(time, date),
    )


def _fast_vtg(f: list[bytes], talker: str) -> GnssFix | None:
    course = _f_num(f[0], 360.0)
    knots = _f_num(f[4], _MAX_FINITE_KNOTS)
    kmh = _f_num(f[6], _MAX_FINITE_KMH)
    if (
        course is False
        or knots is False
        or kmh is False
        or f[1] not in (b"", b"T")
        or _f_num(f[2], 360.0) is False
        or f[3] not in (b"", b"M")
    ):
        return None
    if kmh is None and knots is not None:
        kmh = knots * KNOT_KMH
    return GnssFix(
        talker=talker,
        type="VTG",
        ok=True,
        fix_valid=kmh is not None and _f_mode(f, 8) != "N",
        speed_kmh=kmh,
        course_deg=course,
    )


def _f_signed(text: bytes) -> bool:
    return not text or (_SIGNED.match(text) is not None and math.isfinite(float(text)))


def _fast_gga(f: list[bytes], talker: str) -> GnssFix | None:
    time = _f_time(f[0]) if f[0] else ""
    lat = _f_pos(f[1], f[2], b"NS", 90.0)
    lon = _f_pos(f[3], f[4], b"EW", 180.0)
    if (
        time is None
        or lat is False
        or lon is False
        or not (f[5] == b"" or f[5].isdigit())
        or not (f[6] == b"" or f[6].isdigit())
        or _f_num(f[7], math.inf) is False
        or not _f_signed(f[8])
        or f[9] not in (b"", b"M")
        or not _f_signed(f[10])
        or f[11] not in (b"", b"M")
        or _f_num(f[12], math.inf) is False
        or not (f[13] == b"" or f[13].isdigit())
    ):
        return None
    quality = int(f[5]) if f[5] else 0
    return GnssFix(
        talker=talker,
        type="GGA",
        ok=True,
        fix_valid=quality > 0,
        lat=lat,
        lon=lon,
        utc=_utc(time),
    )


# Beyond these a speed is not finite once converted: left to the full path, which refuses it.
_MAX_FINITE_KNOTS: Final = sys.float_info.max / KNOT_KMH
_MAX_FINITE_KMH: Final = sys.float_info.max
_FAST = {"RMC": _fast_rmc, "VTG": _fast_vtg, "GGA": _fast_gga}
