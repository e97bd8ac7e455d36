"""Sending a cab's session to the office: exactly once, however often the link breaks.

Every row goes under its sequence number in the cab's file, in batches, each batch in one
transaction that also moves the session's count and checksum forward: a push cut anywhere
either committed a batch (and the next push starts after it) or did not (and the next push sends
it again). A session still being recorded is sent as far as it goes and completed later. Before
sending more, the rows the office has are checksummed again on the cab: a session changed or
damaged after it was sent is reported (`sync_problem`, exit code 4), never merged. The cab's
file is only ever read. The swaths and the summary are made by the cab's own code
(`topdress.geo.asapplied`, `topdress.log.summary`) and replaced whole when the rows grew."""

from __future__ import annotations

import hashlib
import json
import logging
import socket
import time
from collections.abc import Callable, Generator, Iterator, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Final

import numpy as np
import psycopg
import shapely

from topdress.errors import LogError, OfficeConflict, OfficeError, OfficeUnavailable
from topdress.geo.asapplied import AsAppliedStream
from topdress.log.session import SUFFIX, SessionReader, session_config
from topdress.log.summary import summarise
from topdress.office.schema import STATE_TYPES, check, ensure_season, office_errors

_log = logging.getLogger(__name__)

BATCH_ROWS: Final = 20_000  # state rows a transaction
_STATE_COLS: Final = tuple(STATE_TYPES)
LAYER: Final = "upper+lower"  # the as-applied swaths carry both layers' sum
#: a session's cover is simplified to about 5 cm: a thousandth of the area of a 3 m strip
COVER_TOLERANCE_DEG: Final = 5e-7


@dataclass
class PushResult:
    path: str
    session_id: str
    machine: str
    season: int
    state_rows: int = 0  # the office's, after the push
    state_sent: int = 0  # by this push
    events_sent: int = 0
    swaths: int = 0  # made again by this push (0: unchanged)
    closed: bool = False
    warnings: list[str] = field(default_factory=list)

    def text(self) -> str:
        what = (
            f"{self.state_sent} new state rows, {self.events_sent} new events"
            if self.state_sent or self.events_sent
            else "nothing new"
        )
        done = "closed" if self.closed else "still open"
        return (
            f"{self.path}: session {self.session_id} of {self.machine} ({self.season}): {what}; "
            f"the office has {self.state_rows} state rows, {done}"
        )


def _season(reader: SessionReader) -> int:
    """The year of the session's first GNSS time, else of the file's creation."""
    for _, utc in reader.numbered_states(("utc",)):
        if utc is not None:
            return datetime.fromtimestamp(utc, UTC).year
    try:
        return int(reader.meta.get("created_utc", "")[:4])
    except ValueError:
        return datetime.now(UTC).year


def push(
    conn: psycopg.Connection[Any],
    path: str | Path,
    machine: str = "",
    farm: str = "",
    batch_rows: int = BATCH_ROWS,
) -> PushResult:
    """Send what the office lacks of the session in `path`. Raises OfficeError (the server),
    OfficeConflict (changed since sent, another machine's, another farm's) or LogError."""
    reader = SessionReader(path)
    closing: list[Generator[Any, None, None]] = []  # readers stopped half-way, closed first
    try:
        return _push(conn, reader, machine, farm, batch_rows, closing)
    finally:
        for gen in closing:
            gen.close()
        reader.close()


def _push(
    conn: psycopg.Connection[Any],
    reader: SessionReader,
    machine: str,
    farm: str,
    batch_rows: int,
    closing: list[Generator[Any, None, None]],
) -> PushResult:
    cfg = session_config(reader.config_toml)
    session_farm = cfg.office.farm or farm
    check(conn, session_farm)
    machine = machine or cfg.office.machine or socket.gethostname()
    sid = reader.session_id
    season = _season(reader)
    out = PushResult(str(reader.path), sid, machine, season)
    closed = "closed_utc" in reader.meta
    where = f"{reader.path.name}"
    with office_errors(where):
        office = _claim(conn, reader, sid, machine, season)
        have_rows, have_digest, have_events, have_event_digest, swaths_of = office
        rows = reader.numbered_states(_STATE_COLS)
        closing.append(rows)
        state_hash = _verify(conn, out, rows, have_rows, have_digest, "state rows")
        sent = have_rows
        for batch in _batches(rows, batch_rows):
            for row in batch:
                state_hash.update(_row_bytes(row))
            digest = state_hash.hexdigest()
            _send_states(conn, sid, season, sent, batch, digest)
            sent += len(batch)
            out.state_sent += len(batch)
        events = reader.numbered_events()
        closing.append(events)
        event_hash = _verify(conn, out, events, have_events, have_event_digest, "events")
        rest = list(events)
        if rest:
            for ev in rest:
                event_hash.update(_row_bytes(ev))
            _send_events(conn, sid, season, have_events, rest, event_hash.hexdigest())
            out.events_sent = len(rest)
        out.state_rows = sent
        out.warnings = reader.warnings()
        if swaths_of != sent or out.events_sent or _closed_changed(conn, sid, closed):
            out.swaths = _send_swaths(conn, reader, sid, season, sent, closed)
        out.closed = closed
    return out


def _claim(
    conn: psycopg.Connection[Any], reader: SessionReader, sid: str, machine: str, season: int
) -> tuple[int, str, int, str, int]:
    """The office's session row, made on the first push; refused when another machine sent
    the same session."""
    conn.execute("INSERT INTO machine (id) VALUES (%s) ON CONFLICT DO NOTHING", (machine,))
    conn.execute(
        "INSERT INTO session (id, machine_id, season, file_name, created_utc, config_toml) "
        "VALUES (%s, %s, %s, %s, %s, %s) ON CONFLICT (id) DO NOTHING",
        (
            sid,
            machine,
            season,
            reader.path.name,
            reader.meta.get("created_utc", ""),
            reader.config_toml,
        ),
    )
    row = conn.execute(
        "SELECT machine_id, season, state_rows, state_digest, event_rows, event_digest, "
        "swaths_of_rows FROM session WHERE id = %s",
        (sid,),
    ).fetchone()
    assert row is not None
    conn.commit()
    if row[0] != machine:
        raise _problem(
            conn,
            sid,
            machine,
            reader.path.name,
            f"session {sid} was sent by machine {row[0]!r} already, not {machine!r} "
            "(two cabs with one session file: a copied file?)",
        )
    return int(row[2]), str(row[3]), int(row[4]), str(row[5]), int(row[6])


def _row_bytes(row: Sequence[Any]) -> bytes:
    return repr(tuple(row)).encode()


def _verify(
    conn: psycopg.Connection[Any],
    out: PushResult,
    rows: Iterator[tuple[Any, ...]],
    have: int,
    digest: str,
    what: str,
) -> Any:
    """The checksum of the first `have` rows (what the office has), checked against the
    office's; the hash, to carry on over the rest."""
    h = hashlib.sha256()
    n = 0
    while n < have:
        row = next(rows, None)
        if row is None:
            break
        h.update(_row_bytes(row))
        n += 1
    if n < have or (have > 0 and h.hexdigest() != digest):
        why = (
            f"it has {n} {what} where the office has {have}"
            if n < have
            else f"its first {have} {what} differ from those sent"
        )
        raise _problem(
            conn,
            out.session_id,
            out.machine,
            Path(out.path).name,
            f"session {out.session_id} changed on the cab after it was sent: {why}; nothing "
            "merged (compare the file with the office's copy)",
        )
    return h


def _problem(
    conn: psycopg.Connection[Any], sid: str, machine: str, name: str, message: str
) -> OfficeConflict:
    """Record the problem in the office (best effort: the error reaches the user anyway)."""
    try:
        conn.rollback()
        conn.execute(
            "INSERT INTO sync_problem (session_id, machine_id, file_name, problem) "
            "VALUES (%s, %s, %s, %s)",
            (sid, machine, name, message),
        )
        conn.commit()
    except psycopg.Error as exc:
        _log.warning("the problem could not be recorded in the office: %s", exc)
    return OfficeConflict(message)


def _batches(rows: Iterator[tuple[Any, ...]], size: int) -> Iterator[list[tuple[Any, ...]]]:
    batch: list[tuple[Any, ...]] = []
    for row in rows:
        batch.append(row)
        if len(batch) >= size:
            yield batch
            batch = []
    if batch:
        yield batch


def _lock(conn: psycopg.Connection[Any], sid: str, column: str, expect: int) -> None:
    """Lock the session's row and check nobody moved it on since we read it."""
    row = conn.execute(f"SELECT {column} FROM session WHERE id = %s FOR UPDATE", (sid,)).fetchone()
    if row is None or int(row[0]) != expect:
        conn.rollback()
        raise OfficeUnavailable(
            f"session {sid} is being sent by another push at the same time: try again"
        )


def _send_states(
    conn: psycopg.Connection[Any],
    sid: str,
    season: int,
    have: int,
    batch: list[tuple[Any, ...]],
    digest: str,
) -> None:
    ensure_season(conn, season)
    _lock(conn, sid, "state_rows", have)
    cols = ", ".join(("season", "session_id", "seq", *_STATE_COLS))
    with conn.cursor().copy(f"COPY state ({cols}) FROM STDIN") as copy:
        for row in batch:
            copy.write_row((season, sid, *row))
    conn.execute(
        "UPDATE session SET state_rows = %s, state_digest = %s, last_push = now() WHERE id = %s",
        (have + len(batch), digest, sid),
    )
    conn.commit()


def _send_events(
    conn: psycopg.Connection[Any],
    sid: str,
    season: int,
    have: int,
    rows: list[tuple[int, float, str, str]],
    digest: str,
) -> None:
    ensure_season(conn, season)
    _lock(conn, sid, "event_rows", have)
    with conn.cursor().copy(
        "COPY event (season, session_id, seq, t, kind, detail) FROM STDIN"
    ) as copy:
        for seq, t, kind, detail in rows:
            copy.write_row((season, sid, seq, t, kind, detail))
    conn.execute(
        "UPDATE session SET event_rows = %s, event_digest = %s, last_push = now() WHERE id = %s",
        (have + len(rows), digest, sid),
    )
    conn.commit()


def _closed_changed(conn: psycopg.Connection[Any], sid: str, closed: bool) -> bool:
    row = conn.execute("SELECT closed FROM session WHERE id = %s", (sid,)).fetchone()
    conn.rollback()
    return row is None or bool(row[0]) != closed


def _send_swaths(
    conn: psycopg.Connection[Any],
    reader: SessionReader,
    sid: str,
    season: int,
    rows: int,
    closed: bool,
) -> int:
    """The session's swaths and summary, made again from the whole file and replaced whole."""
    summary = summarise(reader)
    stream = AsAppliedStream(reader)
    batches = list(stream.swath_batches())
    product = session_config(reader.config_toml).office.product
    ensure_season(conn, season)
    _lock(conn, sid, "state_rows", rows)
    conn.execute("DELETE FROM swath WHERE season = %s AND session_id = %s", (season, sid))
    n = 0
    with conn.cursor().copy(
        "COPY swath (season, session_id, seq, utc, product, layer, applied_kg_ha, target_kg_ha, "
        "prescribed_kg_ha, applied_kg, target_kg, area_ha, zone, overlap_pct, geom) FROM STDIN"
    ) as copy:
        for cols, geoms in batches:
            wkb = shapely.to_wkb(shapely.set_srid(geoms, 4326), hex=True, include_srid=True)
            for i in range(geoms.size):
                copy.write_row(
                    (
                        season,
                        sid,
                        n,
                        str(cols["IsoTime"][i]),
                        product,
                        LAYER,
                        _num(cols["AppliedRate"][i]),
                        _num(cols["TargetRate"][i]),
                        _num(cols["PrescRate"][i]),
                        float(cols["AppliedKg"][i]),
                        float(cols["TargetKg"][i]),
                        float(cols["AREA"][i]),
                        str(cols["Zone"][i]) or None,
                        _num(cols["Overlap"][i]),
                        str(wkb[i]),
                    )
                )
                n += 1
    conn.execute(
        "UPDATE session SET cover = (SELECT ST_SimplifyPreserveTopology("
        "ST_UnaryUnion(ST_Collect(geom)), %s) FROM swath WHERE season = %s AND session_id = %s) "
        "WHERE id = %s",
        (COVER_TOLERANCE_DEG, season, sid, sid),
    )
    applied = sum(layer.applied_kg for layer in summary.layers.values())
    conn.execute(
        "UPDATE session SET swaths_of_rows = %s, closed = %s, applied_kg = %s, area_ha = %s, "
        "summary = %s, start_utc = to_timestamp(%s), end_utc = to_timestamp(%s), "
        "last_push = now() WHERE id = %s",
        (
            rows,
            closed,
            applied,
            summary.area_ha,
            json.dumps(summary.as_dict(), default=str),
            summary.start_utc,
            summary.end_utc,
            sid,
        ),
    )
    conn.commit()
    return n


def _num(value: Any) -> float | None:
    v = float(value)
    return None if np.isnan(v) else v


def session_files(directory: str | Path) -> list[Path]:
    """The session files in a cab's session directory, oldest first."""
    root = Path(directory)
    if not root.is_dir():
        raise OfficeError(f"{root}: no such directory of sessions")
    return sorted(p for p in root.glob(f"*{SUFFIX}") if p.is_file())


@dataclass
class SyncOutcome:
    pushed: list[PushResult] = field(default_factory=list)
    failed: list[tuple[Path, OfficeError | LogError]] = field(default_factory=list)

    @property
    def exit_code(self) -> int:
        """0 all sent; else the most serious failure's code (4 conflict over 3 down over 2)."""
        codes = [getattr(e, "exit_code", 2) for _, e in self.failed]
        return max(codes, default=0)


def sync(
    connect: Callable[[], psycopg.Connection[Any]],
    paths: Sequence[Path],
    machine: str = "",
    farm: str = "",
    retries: int = 3,
    backoff_s: float = 1.0,
    sleep: Callable[[float], None] = time.sleep,
    batch_rows: int = BATCH_ROWS,
) -> SyncOutcome:
    """Push every file; a file whose push failed with the office unreachable is tried again
    (a new connection, after backoff_s, doubling up to a minute), the others are reported and
    the rest go on: one bad file does not stop the sync."""
    out = SyncOutcome()
    conn: psycopg.Connection[Any] | None = None
    try:
        for path in paths:
            delay = backoff_s
            for attempt in range(retries + 1):
                try:
                    if conn is None or conn.closed:
                        conn = connect()
                    out.pushed.append(push(conn, path, machine, farm, batch_rows))
                    break
                except OfficeUnavailable as exc:
                    if conn is not None:
                        conn.close()
                    conn = None
                    if attempt == retries:
                        out.failed.append((path, exc))
                        break
                    _log.warning("%s; again in %.0f s", exc, delay)
                    sleep(delay)
                    delay = min(delay * 2, 60.0)
                except (OfficeError, LogError) as exc:
                    out.failed.append((path, exc))
                    if conn is not None and not conn.closed:
                        conn.rollback()
                    break
    finally:
        if conn is not None:
            conn.close()
    return out
