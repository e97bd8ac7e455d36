"""Export a session: raw inputs as events (NDJSON), the decoded state as CSV, the logged events
(what happened) as NDJSON."""

from __future__ import annotations

import csv
import json
import logging
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Final, TextIO

from topdress import protocol
from topdress.config import loads_config
from topdress.errors import ConfigError, ProtocolError
from topdress.log.events import CanEvent, CropEvent, Event, NmeaEvent, WheelEvent
from topdress.log.model import STATE_COLUMNS
from topdress.log.session import RawRecord, SessionReader

_log = logging.getLogger(__name__)

WHEEL_PULSES_MOD: Final = 1 << 24  # EcuDiag.WheelPulses is the ECU's counter mod 2^24


def session_frame_ids(config_toml: str) -> protocol.FrameIds:
    """The CAN identifiers the session ran with (its stored configuration), else the defaults."""
    try:
        ids = loads_config(config_toml).can.ids
    except ConfigError as exc:
        _log.warning("session configuration unreadable (%s): default CAN identifiers used", exc)
        return protocol.DEFAULT_IDS
    return protocol.FrameIds(**ids)


class WheelUnwrap:
    """Cumulative pulses from the 24-bit counter: counts forward across every wrap."""

    def __init__(self) -> None:
        self.total: int | None = None
        self._last = 0

    def update(self, pulses_mod: int) -> int:
        if self.total is None:
            self.total = pulses_mod
        else:
            self.total += (pulses_mod - self._last) % WHEEL_PULSES_MOD
        self._last = pulses_mod
        return self.total


@dataclass
class ExportStats:
    events: int = 0
    wheel_counts: int = 0
    bad_diag: int = 0  # EcuDiag frames that did not decode (no wheel_count from them)


def session_events(reader: SessionReader, stats: ExportStats | None = None) -> Iterator[Event]:
    """The session's raw inputs as events, in logged order. Each EcuDiag frame received also
    gives a wheel_count event (right after its can event, same t)."""
    stats = stats if stats is not None else ExportStats()
    ids = session_frame_ids(reader.config_toml)
    wheel = WheelUnwrap()
    for rec in reader.raw():
        event = _event(rec)
        stats.events += 1
        yield event
        if rec.kind == "can_rx" and rec.can_id == ids.diag and rec.data is not None:
            try:
                diag = protocol.decode((rec.can_id, rec.data), ids)
            except ProtocolError as exc:
                stats.bad_diag += 1
                _log.warning("EcuDiag at t=%r not decoded: %s", rec.t, exc)
                continue
            assert isinstance(diag, protocol.EcuDiag)
            stats.events += 1
            stats.wheel_counts += 1
            yield WheelEvent(rec.t, wheel.update(diag.wheel_pulses))


def _event(rec: RawRecord) -> Event:
    if rec.kind == "nmea":
        return NmeaEvent(rec.t, rec.line or "")
    if rec.kind == "crop":
        return CropEvent(rec.t, rec.line or "")
    direction = "rx" if rec.kind == "can_rx" else "tx"
    return CanEvent(rec.t, rec.can_id or 0, rec.data or b"", direction)


def write_state_csv(reader: SessionReader, out: TextIO) -> int:
    """The decoded state rows as CSV (header = StateRow fields; empty = not available)."""
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(STATE_COLUMNS)
    n = 0
    for row in reader.states():
        writer.writerow("" if v is None else v for v in row.as_tuple())
        n += 1
    return n


def write_log_events(reader: SessionReader, out: TextIO) -> int:
    """The session's events (the event table), one JSON object per line in time order:
    {"t": ..., "kind": ..., "detail": {...}}. A version-1 file has none."""
    n = 0
    for ev in reader.events():
        line = {"t": ev.t, "kind": ev.kind, "detail": dict(ev.detail)}
        out.write(json.dumps(line, separators=(",", ":")) + "\n")
        n += 1
    return n
