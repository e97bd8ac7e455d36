"""The session's CAN traffic as a trace file that python-can and can-utils read: candump
`.log` (`python -m can.player`, `canplayer`, `cantools decode`) or Vector `.asc`.

Frames are logged on the terminal's monotonic clock; the trace gives them UTC time stamps
(the state rows' UTC, carried over by their offset from the monotonic clock), so a trace lines
up with the as-applied map and with other loggers on the bus.
"""

from __future__ import annotations

import itertools
import statistics
from collections.abc import Iterator
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Final, TextIO

import can

from topdress.errors import MapError
from topdress.log.session import SessionReader


class _UtcAscWriter(can.ASCWriter):
    """Vector ASC with its header in the session's UTC: python-can's writer dates the file
    with the export's local time and the trigger block with the first frame's local time."""

    def __init__(self, file: str | Path | TextIO, start_utc: float, **kw: Any) -> None:
        self._start = datetime.fromtimestamp(start_utc, UTC)
        super().__init__(file, **kw)

    def _format_header_datetime(self, dt: datetime) -> str:
        # Both header dates are the session's first frame (the start of the measurement).
        return super()._format_header_datetime(self._start.replace(tzinfo=None))


FORMATS: Final = (".log", ".asc")


def check_trace_path(path: Path) -> None:
    """MapError unless `path` names a trace format (checked before anything is written)."""
    if path.suffix.lower() not in FORMATS:
        given = path.suffix or "no extension"
        raise MapError(f"{path}: a CAN trace is .log (candump) or .asc (Vector), not {given}")


def utc_offset(reader: SessionReader) -> float:
    """UTC minus the monotonic clock: from the state rows' UTC, else the creation time."""
    diffs = [r.utc - r.t for r in reader.states() if r.utc is not None and r.utc_source == "gnss"]
    if not diffs:
        diffs = [r.utc - r.t for r in reader.states() if r.utc is not None]
    if diffs:
        return statistics.median(diffs)
    created = reader.meta.get("created_utc")
    first = next(reader.raw(), None)
    if created and first is not None:
        try:
            return datetime.fromisoformat(created).timestamp() - first.t
        except ValueError:
            pass
    return 0.0


def write_trace(
    reader: SessionReader, path: Path, channel: str = "can0", shown: Path | None = None
) -> int:
    """Every logged CAN frame (both directions) to `path` (.log or .asc); returns the count.
    `shown`: the path errors name (the user's, when `path` is a temporary file)."""
    name = shown if shown is not None else path
    check_trace_path(name)
    offset = utc_offset(reader)
    frames = _frames(reader, offset, channel)
    first = next(frames, None)
    writer: can.io.generic.MessageWriter
    try:
        if path.suffix.lower() == ".asc":
            # no frame: the session's UTC at its clock's zero
            start = first.timestamp if first is not None else offset
            writer = _UtcAscWriter(path, start, channel=channel)
        else:
            writer = can.CanutilsLogWriter(path, channel=channel)
    except OSError as exc:
        raise MapError(f"cannot write {name}: {exc}") from exc
    n = 0
    with writer:
        for msg in itertools.chain([first] if first is not None else [], frames):
            writer.on_message_received(msg)
            n += 1
    return n


def _frames(reader: SessionReader, offset: float, channel: str) -> Iterator[can.Message]:
    for rec in reader.raw():
        if rec.can_id is None or rec.data is None:
            continue
        yield can.Message(
            timestamp=rec.t + offset,
            arbitration_id=rec.can_id,
            is_extended_id=True,
            data=rec.data,
            is_rx=rec.kind == "can_rx",
            channel=channel,
        )
