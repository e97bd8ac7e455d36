"""What a row read from a session file may hold: the type and range of every value.

SQLite checks its pages, not the values in them: a flipped type byte, a bit flip in a value or
another program writing to the file gives a row SQLite reads without complaint (a text where a
number belongs, an integer of two billion where 8 data bytes belong, a time of 1e300). The
reader (`SessionReader`) passes every row through these checks; a row that fails is skipped and
counted, never handed to a command. The ranges are wide (what any machine can produce), not
plausibility limits: they keep every later step finite and bounded.

Also here: the check of a session's write-ahead log (the `-wal` file) before it is opened, so
that frames SQLite would skip in silence (a torn or damaged frame and every frame after it) are
reported.
"""

from __future__ import annotations

import json
import math
import struct
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from topdress.log.model import (
    CAN_KINDS,
    EVENT_KINDS,
    LINE_KINDS,
    RAW_KINDS,
    STATE_COLUMNS,
    UTC_SOURCES,
    ZONES,
)
from topdress.protocol.model import Source

T_LIMIT_S: Final = 1e10  # the monotonic clock of a terminal: |t| below ~300 years
MAX_LINE: Final = 4096  # an NMEA sentence is at most 82 characters, a crop line ~60
MAX_DETAIL: Final = 65536  # an event's detail JSON
MAX_CAN_ID: Final = 0x1FFFFFFF
UTC_MIN_S: Final = 946684800.0  # 2000-01-01
UTC_MAX_S: Final = 4102444800.0  # 2100-01-01
SPEED_MAX_KMH: Final = 1000.0
RPM_MAX: Final = 1e6
RATE_MAX_KG_HA: Final = 1e5

_Check = Callable[[Any], bool]


def _real(lo: float, hi: float, nullable: bool) -> _Check:
    def check(v: Any) -> bool:
        if v is None:
            return nullable
        return type(v) in (float, int) and lo <= v <= hi  # NaN fails both comparisons

    return check


def _text(allowed: tuple[str, ...], nullable: bool) -> _Check:
    choices = frozenset(allowed)

    def check(v: Any) -> bool:
        return nullable if v is None else type(v) is str and v in choices

    return check


def _faults(v: Any) -> bool:
    return type(v) is int and 0 <= v <= 0xFFFFFFFF


_SOURCES: Final = tuple(s.value for s in Source)

#: The check of each state column (a column missing from an older file is not checked).
STATE_CHECKS: Final[dict[str, _Check]] = {
    "t": _real(-T_LIMIT_S, T_LIMIT_S, False),
    "lat": _real(-90.0, 90.0, True),
    "lon": _real(-180.0, 180.0, True),
    "v_gnss_kmh": _real(0.0, SPEED_MAX_KMH, True),
    "v_wheel_kmh": _real(0.0, SPEED_MAX_KMH, False),
    "v_kmh": _real(0.0, SPEED_MAX_KMH, False),
    "source": _text(_SOURCES, False),
    "cv_pct": _real(0.0, 1e4, True),
    "ndvi": _real(-1.0, 1.0, True),
    "rate_kg_ha_upper": _real(0.0, RATE_MAX_KG_HA, False),
    "rate_kg_ha_lower": _real(0.0, RATE_MAX_KG_HA, False),
    "target_rpm_upper": _real(0.0, RPM_MAX, False),
    "target_rpm_lower": _real(0.0, RPM_MAX, False),
    "meter_rpm_upper": _real(0.0, RPM_MAX, False),
    "meter_rpm_lower": _real(0.0, RPM_MAX, False),
    "fan_rpm_upper": _real(0.0, RPM_MAX, False),
    "fan_rpm_lower": _real(0.0, RPM_MAX, False),
    "faults": _faults,
    "utc": _real(UTC_MIN_S, UTC_MAX_S, True),
    "utc_source": _text(UTC_SOURCES, True),
    "heading_deg": _real(-360.0, 360.0, True),
    "outlet_lat": _real(-90.0, 90.0, True),
    "outlet_lon": _real(-180.0, 180.0, True),
    "zone": _text(ZONES, True),
    "prescription_kg_ha": _real(0.0, RATE_MAX_KG_HA, True),
}
assert tuple(STATE_CHECKS) == STATE_COLUMNS


def state_ok(columns: tuple[str, ...], values: tuple[Any, ...]) -> bool:
    """Every value of a state row (the given columns) of its type and in its range."""
    checks = STATE_CHECKS
    return all(checks[c](v) for c, v in zip(columns, values, strict=True))


def _t_ok(t: Any) -> bool:
    return type(t) in (float, int) and -T_LIMIT_S <= t <= T_LIMIT_S


def raw_ok(t: Any, kind: Any, line: Any, can_id: Any, data: Any) -> bool:
    """A raw input row: a line for nmea/crop, an identifier of 29 bits and 0-8 data bytes for
    CAN, and nothing else."""
    if not _t_ok(t):
        return False
    if kind in LINE_KINDS:
        return type(line) is str and len(line) <= MAX_LINE and can_id is None and data is None
    if kind in CAN_KINDS:
        return (
            line is None
            and type(can_id) is int
            and 0 <= can_id <= MAX_CAN_ID
            and type(data) is bytes
            and len(data) <= 8
        )
    return False


assert frozenset(RAW_KINDS) == LINE_KINDS | CAN_KINDS


def _plain(v: Any) -> bool:
    if v is None or type(v) in (bool, int, str):
        return True
    if type(v) is float:
        return math.isfinite(v)
    return type(v) is list and all(_plain(x) for x in v)


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} in JSON")


def event_detail(t: Any, kind: Any, detail: Any) -> dict[str, Any] | None:
    """An event row's detail as a dict, or None when the row is damaged: a known kind, a time,
    a JSON object of plain values (numbers, strings, booleans, lists of them)."""
    if not _t_ok(t) or kind not in EVENT_KINDS:
        return None
    if type(detail) is not str or len(detail) > MAX_DETAIL:
        return None
    try:
        value = json.loads(detail, parse_constant=_no_constant)
    except (ValueError, RecursionError):
        return None
    if type(value) is not dict or not all(_plain(v) for v in value.values()):
        return None
    return value


class Undecodable:
    """A text value that is not UTF-8 (a flipped bit in a line): not a str, so it fails the
    checks and its row is skipped, where sqlite3 would stop the whole query."""

    def __repr__(self) -> str:
        return "<not UTF-8>"


UNDECODABLE: Final = Undecodable()


def text_factory(raw: bytes) -> str | Undecodable:
    """The reading connections' text factory (sqlite3 `Connection.text_factory`)."""
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return UNDECODABLE


def meta_ok(key: Any, value: Any) -> bool:
    return type(key) is str and type(value) is str


# ---- the write-ahead log ----

_WAL_MAGIC: Final = (0x377F0682, 0x377F0683)
_WAL_HEADER: Final = 32
_FRAME_HEADER: Final = 24


@dataclass(frozen=True)
class WalCheck:
    """What SQLite will read of a `-wal` file, and what it will skip."""

    frames: int  # frames SQLite applies (up to the last sound commit)
    skipped: int  # frames of this WAL written after them, which it skips
    skipped_commits: int  # transactions among the skipped frames
    damaged_at: int | None  # the frame (from 0) whose checksum failed, None: none

    def message(self, wal: Path) -> str | None:
        """None when nothing is skipped; else what is lost and why."""
        if self.damaged_at is None or not self.skipped:
            return None
        if self.skipped_commits <= 1:
            return (
                f"{wal}: the last write was cut off (frame {self.damaged_at}, a power cut "
                f"while writing): its {self.skipped} frames are not read"
            )
        return (
            f"{wal}: damaged at frame {self.damaged_at}: {self.skipped} frames "
            f"({self.skipped_commits} commits, each up to half a second of rows) from the last "
            "sound commit on cannot be read"
        )


def _checksum(data: bytes, big: bool, s1: int, s2: int) -> tuple[int, int]:
    words = struct.unpack(f"{'>' if big else '<'}{len(data) // 4}I", data)
    mask = 0xFFFFFFFF
    for i in range(0, len(words), 2):
        s1 = (s1 + words[i] + s2) & mask
        s2 = (s2 + words[i + 1] + s1) & mask
    return s1, s2


def check_wal(wal: Path) -> WalCheck | None:
    """Walk a `-wal` file as SQLite does (salts and cumulative checksums); None when there is
    no WAL or it holds no frames. Frames of an older WAL generation (other salts) after the
    current ones are normal (a WAL is reused from its start) and not counted."""
    try:
        with wal.open("rb") as f:
            blob = f.read()
    except OSError:
        return None
    if len(blob) < _WAL_HEADER:
        return None
    magic, _, page_size, _, salt1, salt2, c1, c2 = struct.unpack(">8I", blob[:_WAL_HEADER])
    if magic not in _WAL_MAGIC or page_size < 512 or page_size & (page_size - 1):
        return None
    big = magic & 1 == 1
    s1, s2 = _checksum(blob[:24], big, 0, 0)
    if (s1, s2) != (c1, c2):
        return WalCheck(0, 0, 0, None)  # a header SQLite ignores: it starts a new WAL
    size = _FRAME_HEADER + page_size
    n = (len(blob) - _WAL_HEADER) // size
    applied = current = 0
    damaged: int | None = None
    skipped_commits = 0
    for i in range(n):
        off = _WAL_HEADER + i * size
        head = blob[off : off + _FRAME_HEADER]
        _, commit, fs1, fs2, fc1, fc2 = struct.unpack(">6I", head)
        if (fs1, fs2) != (salt1, salt2):
            break  # an older generation: SQLite stops here, and so do we
        current += 1
        if damaged is None:
            s1, s2 = _checksum(head[:8], big, s1, s2)
            s1, s2 = _checksum(blob[off + _FRAME_HEADER : off + size], big, s1, s2)
            if (s1, s2) != (fc1, fc2):
                damaged = i
            elif commit:
                applied = i + 1
        if damaged is not None:
            skipped_commits += commit != 0
    if damaged is None and current == n and (len(blob) - _WAL_HEADER) % size:
        damaged = n  # a frame cut short at the end of the file
        current += 1
    if damaged is None:
        return WalCheck(applied, current - applied, 0, None)
    return WalCheck(applied, current - applied, skipped_commits, damaged)
