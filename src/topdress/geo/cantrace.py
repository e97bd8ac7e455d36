"""The session's CAN traffic as a trace file that python-can and can-utils read: candump
`.log` (`python -m can.player`, `canplayer`, `cantools decode`) or Vector `.asc`.

Frames are logged on the terminal's monotonic clock; the trace gives them UTC time stamps
(the state rows' UTC, carried over by their offset from the monotonic clock), so a trace lines
up with the as-applied map and with other loggers on the bus.
"""

from __future__ import annotations

import statistics
from datetime import datetime
from pathlib import Path
from typing import Final

import can

from topdress.errors import MapError
from topdress.log.session import SessionReader

FORMATS: Final = {".log": can.CanutilsLogWriter, ".asc": can.ASCWriter}


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


def write_trace(reader: SessionReader, path: Path, channel: str = "can0") -> int:
    """Every logged CAN frame (both directions) to `path` (.log or .asc); returns the count."""
    writer_cls = FORMATS.get(path.suffix.lower())
    if writer_cls is None:
        raise MapError(f"{path}: a CAN trace is .log (candump) or .asc (Vector)")
    offset = utc_offset(reader)
    n = 0
    try:
        writer = writer_cls(path, channel=channel)
    except OSError as exc:
        raise MapError(f"cannot write {path}: {exc}") from exc
    with writer:
        for rec in reader.raw():
            if rec.can_id is None or rec.data is None:
                continue
            writer.on_message_received(
                can.Message(
                    timestamp=rec.t + offset,
                    arbitration_id=rec.can_id,
                    is_extended_id=True,
                    data=rec.data,
                    is_rx=rec.kind == "can_rx",
                    channel=channel,
                )
            )
            n += 1
    return n
