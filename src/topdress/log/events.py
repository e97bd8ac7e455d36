"""Raw-input events: the NDJSON format of `topdress log export` and `topdress replay`.

One JSON object per line: "t" (seconds, monotonic) and exactly one of "nmea" (a sentence as
received), "wheel_count" (cumulative ground-wheel encoder pulses), "crop" (a raw sensor line)
or "can" ({"id": int, "data": "hex"}, optional "dir": "rx" ECU->terminal or "tx"
terminal->ECU). Unknown keys are ignored; a malformed line is reported with its number and
skipped, never fatal. See docs/log.md.
"""

from __future__ import annotations

import json
import logging
import math
import re
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final, TextIO

from topdress.errors import LogError

_log = logging.getLogger(__name__)

PAYLOAD_KEYS: Final = ("nmea", "wheel_count", "crop", "can")
CAN_DIRS: Final = ("rx", "tx")
_MAX_CAN_ID: Final = 0x1FFFFFFF


@dataclass(frozen=True, slots=True)
class NmeaEvent:
    t: float
    nmea: str


@dataclass(frozen=True, slots=True)
class WheelEvent:
    t: float
    wheel_count: int


@dataclass(frozen=True, slots=True)
class CropEvent:
    t: float
    crop: str


@dataclass(frozen=True, slots=True)
class CanEvent:
    t: float
    can_id: int
    data: bytes
    dir: str | None = None  # "rx": ECU -> terminal, "tx": terminal -> ECU, None: not known


Event = NmeaEvent | WheelEvent | CropEvent | CanEvent


class EventLineError(ValueError):
    """One malformed event line (the reader reports it and goes on)."""


_string: Final = json.encoder.encode_basestring  # what json.dumps(ensure_ascii=False) uses


def to_json(event: Event) -> str:
    """One NDJSON line (without the newline). Floats keep full precision (repr). Built from
    parts, byte for byte what json.dumps gives: a 12 h day is ~8 million lines."""
    t = event.t
    if type(t) is not float or not math.isfinite(t):
        return _to_json_slow(event)
    head = '{"t":' + float.__repr__(t)
    if isinstance(event, NmeaEvent):
        return head + ',"nmea":' + _string(event.nmea) + "}"
    if isinstance(event, CropEvent):
        return head + ',"crop":' + _string(event.crop) + "}"
    if isinstance(event, WheelEvent):
        return head + ',"wheel_count":' + int.__repr__(event.wheel_count) + "}"
    direction = "" if event.dir is None else ',"dir":' + _string(event.dir)
    return (
        f'{head},"can":{{"id":{int.__repr__(event.can_id)},"data":"{event.data.hex()}"'
        f"{direction}}}}}"
    )


def _to_json_slow(event: Event) -> str:
    obj: dict[str, Any] = {"t": event.t}
    if isinstance(event, NmeaEvent):
        obj["nmea"] = event.nmea
    elif isinstance(event, WheelEvent):
        obj["wheel_count"] = event.wheel_count
    elif isinstance(event, CropEvent):
        obj["crop"] = event.crop
    else:
        can: dict[str, Any] = {"id": event.can_id, "data": event.data.hex()}
        if event.dir is not None:
            can["dir"] = event.dir
        obj["can"] = can
    return json.dumps(obj, separators=(",", ":"), ensure_ascii=False)


# The exact forms `to_json` writes (a number as Python or JSON writes it, strings with no
# escapes but the line ends \r \n, lower-case hex of at most 8 bytes): read without json.loads,
# which is most of the time a long day's replay spends reading. Anything else, valid or not,
# takes the full parser.
_NUM: Final = r"-?(?:0|[1-9][0-9]*)(?:\.[0-9]+)?(?:[eE][-+]?[0-9]+)?"
_TEXT: Final = r'"([^"\\\x00-\x1f]*(?:\\[rn][^"\\\x00-\x1f]*)*)"'
_FAST: Final = re.compile(
    r'\{"t":(' + _NUM + r"),(?:"
    r'"(nmea|crop)":' + _TEXT + r'|"wheel_count":(0|[1-9][0-9]{0,30})'
    r'|"can":\{"id":(0|[1-9][0-9]{0,15}),"data":"((?:[0-9a-f]{2}){0,8})"(?:,"dir":"(rx|tx)")?\}'
    r")\}\n?\Z"
)


def parse(line: str) -> Event:
    """Parse one line; EventLineError says what is wrong."""
    m = _FAST.match(line)
    if m is not None:
        event = _fast(m)
        if event is not None:
            return event
    return _parse_json(line)


def _fast(m: re.Match[str]) -> Event | None:
    """The event of a line in `to_json`'s form; None when the full parser must judge it (a
    time that is not finite, an identifier out of range)."""
    t, key, text, wheel, can_id, data, direction = m.groups()
    tf = float(t)
    if not math.isfinite(tf):
        return None
    if key is not None and "\\" in text:
        text = text.replace("\\r", "\r").replace("\\n", "\n")
    if key == "nmea":
        return NmeaEvent(tf, text)
    if key == "crop":
        return CropEvent(tf, text)
    if wheel is not None:
        return WheelEvent(tf, int(wheel))
    ident = int(can_id)
    if ident > _MAX_CAN_ID:
        return None
    return CanEvent(tf, ident, bytes.fromhex(data), direction)


def _parse_json(line: str) -> Event:
    try:
        obj = json.loads(line)
    except json.JSONDecodeError as exc:
        raise EventLineError(f"not JSON: {exc.msg}") from None
    if not isinstance(obj, dict):
        raise EventLineError("not a JSON object")
    t = obj.get("t")
    if isinstance(t, bool) or not isinstance(t, int | float) or not math.isfinite(t):
        raise EventLineError(f'"t" must be a number of seconds, not {t!r}')
    keys = [k for k in PAYLOAD_KEYS if k in obj]
    if len(keys) != 1:
        raise EventLineError(
            f"needs exactly one of {', '.join(PAYLOAD_KEYS)}; has {', '.join(keys) or 'none'}"
        )
    key = keys[0]
    value = obj[key]
    if key in ("nmea", "crop"):
        if not isinstance(value, str):
            raise EventLineError(f'"{key}" must be a string')
        return NmeaEvent(float(t), value) if key == "nmea" else CropEvent(float(t), value)
    if key == "wheel_count":
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise EventLineError(f'"wheel_count" must be an integer >= 0, not {value!r}')
        return WheelEvent(float(t), value)
    return _parse_can(float(t), value)


def _parse_can(t: float, value: Any) -> CanEvent:
    if not isinstance(value, dict):
        raise EventLineError('"can" must be an object {"id": int, "data": "hex"}')
    can_id = value.get("id")
    if isinstance(can_id, bool) or not isinstance(can_id, int) or not 0 <= can_id <= _MAX_CAN_ID:
        raise EventLineError(f'"can.id" must be an integer 0..0x1FFFFFFF, not {can_id!r}')
    hexdata = value.get("data")
    if not isinstance(hexdata, str):
        raise EventLineError('"can.data" must be a hex string')
    try:
        data = bytes.fromhex(hexdata)
    except ValueError:
        raise EventLineError(f'"can.data" is not hex: {hexdata!r}') from None
    if len(data) > 8:
        raise EventLineError(f'"can.data" has {len(data)} bytes, a CAN frame at most 8')
    direction = value.get("dir")
    if direction is not None and direction not in CAN_DIRS:
        raise EventLineError(f'"can.dir" must be "rx" or "tx", not {direction!r}')
    return CanEvent(t, can_id, data, direction)


@dataclass
class ReadResult:
    """Events in file order, and the malformed lines as (line number, reason)."""

    events: list[Event] = field(default_factory=list)
    bad: list[tuple[int, str]] = field(default_factory=list)
    parsed: int = 0  # well-formed lines (kept or not)


@dataclass(frozen=True)
class Drop:
    """Events a reader drops, told from a line in `to_json`'s form before an event is built:
    crop lines (`crop`), CAN frames from the ECU (`can_rx`) but for the identifiers in
    `rx_kept`. Lines in any other form are judged by `keep` once parsed."""

    crop: bool = False
    can_rx: bool = False
    rx_kept: frozenset[int] = frozenset()

    def drops(self, m: re.Match[str]) -> bool:
        if not math.isfinite(float(m[1])):
            return False  # the full parser says what is wrong with it
        if m[2] == "crop":
            return self.crop
        if m[7] == "rx" and self.can_rx:
            ident = int(m[5])
            return ident <= _MAX_CAN_ID and ident not in self.rx_kept
        return False


def iter_lines(
    lines: Iterable[str],
    result: ReadResult,
    keep: Callable[[Event], bool] | None = None,
    drop: Drop | None = None,
) -> Iterator[Event]:
    """The events of NDJSON lines one at a time, as `read_lines` keeps them; the well-formed
    and malformed lines are counted in `result` (its `events` stay empty), so a reader that
    goes through a long day need not hold it."""
    match = _FAST.match
    for number, line in enumerate(lines, start=1):
        m = match(line)
        if m is not None:
            if drop is not None and drop.drops(m):
                result.parsed += 1
                continue
            event = _fast(m)
            if event is not None:
                result.parsed += 1
                if keep is None or keep(event):
                    yield event
                continue
        if not line.strip():
            continue
        try:
            event = _parse_json(line)
        except EventLineError as exc:
            result.bad.append((number, str(exc)))
            _log.debug("events line %d skipped: %s", number, exc)
            continue
        result.parsed += 1
        if keep is None or keep(event):
            yield event


def read_lines(
    lines: Iterable[str], keep: Callable[[Event], bool] | None = None, drop: Drop | None = None
) -> ReadResult:
    """Parse NDJSON lines; blank lines are skipped. `keep`: only the events it accepts are
    kept (every line is still checked), so a reader that needs few holds only those; `drop`:
    the same told from the line, before an event is built (it must drop only what `keep`
    drops)."""
    result = ReadResult()
    result.events.extend(iter_lines(lines, result, keep, drop))
    return result


def iter_file(
    path: str | Path,
    result: ReadResult,
    keep: Callable[[Event], bool] | None = None,
    drop: Drop | None = None,
) -> Iterator[Event]:
    """`iter_lines` of a file: its events one at a time, the lines counted in `result`."""
    try:
        # utf-8-sig: a file saved by an editor that puts a byte order mark first
        with open(path, encoding="utf-8-sig", errors="replace") as f:
            yield from iter_lines(f, result, keep, drop)
    except OSError as exc:
        raise LogError(f"cannot read events {path}: {exc}") from exc


def read_file(
    path: str | Path, keep: Callable[[Event], bool] | None = None, drop: Drop | None = None
) -> ReadResult:
    try:
        # utf-8-sig: a file saved by an editor that puts a byte order mark first
        with open(path, encoding="utf-8-sig", errors="replace") as f:
            return read_lines(f, keep, drop)
    except OSError as exc:
        raise LogError(f"cannot read events {path}: {exc}") from exc


def write(events: Iterable[Event], out: TextIO) -> int:
    """Write events as NDJSON; returns how many."""
    n = 0
    for event in events:
        out.write(to_json(event))
        out.write("\n")
        n += 1
    return n
