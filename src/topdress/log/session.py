"""The session log: one SQLite file (WAL) per session, written off the control path.

The caller (the terminal's control loop) only ever enqueues: `raw()`, `state()` and `event()` put a
tuple on a bounded queue and return at once. A writer thread drains the queue and commits a batch
at least every `commit_period_s` (0.5 s); it wakes for the batch, not for every row (a sync, a
close or a half-full queue wake it at once), so logging costs no thread switch per input. WAL
with synchronous=FULL makes every commit durable and atomic, so a SIGKILL or a power cut loses at
most the last uncommitted batch and never corrupts the file. Write failures (unwritable path, full
disk) are logged and counted in `errors`, the rows they carried in `lost`; a full queue counts its
rows in `dropped`. Nothing here raises into the caller after `create()` has returned, and
`create()` itself only reports, never raises.
"""

from __future__ import annotations

import contextlib
import fcntl
import itertools
import json
import logging
import os
import sqlite3
import threading
import time
import uuid
from collections import Counter, deque
from collections.abc import Generator, Iterator
from dataclasses import dataclass
from datetime import UTC, datetime
from enum import StrEnum
from pathlib import Path
from typing import Any, Final

from topdress import __version__
from topdress.config import TerminalConfig, loads_config
from topdress.errors import ConfigError, LogError
from topdress.log.check import (
    check_wal,
    event_detail,
    meta_ok,
    raw_ok,
    state_ok,
    text_factory,
)
from topdress.log.model import (
    CAN_KINDS,
    EVENT_KINDS,
    LINE_KINDS,
    RAW_KINDS,
    STATE_COLUMNS,
    LogEvent,
    StateRow,
    masked,
)

_log = logging.getLogger(__name__)

SCHEMA_VERSION: Final = 2  # 2: the event table
READ_VERSIONS: Final = (1, 2)  # a version-1 file reads as one without events
SUFFIX: Final = ".sqlite"

_SCHEMA: Final = f"""
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE raw (
    id INTEGER PRIMARY KEY,
    t REAL NOT NULL,
    kind TEXT NOT NULL CHECK (kind IN ({", ".join(repr(k) for k in RAW_KINDS)})),
    line TEXT,
    can_id INTEGER,
    data BLOB
);
CREATE TABLE state (
    id INTEGER PRIMARY KEY,
    t REAL NOT NULL, lat REAL, lon REAL,
    v_gnss_kmh REAL, v_wheel_kmh REAL NOT NULL, v_kmh REAL NOT NULL,
    source TEXT NOT NULL, cv_pct REAL, ndvi REAL,
    rate_kg_ha_upper REAL NOT NULL, rate_kg_ha_lower REAL NOT NULL,
    target_rpm_upper REAL NOT NULL, target_rpm_lower REAL NOT NULL,
    meter_rpm_upper REAL NOT NULL, meter_rpm_lower REAL NOT NULL,
    fan_rpm_upper REAL NOT NULL, fan_rpm_lower REAL NOT NULL,
    faults INTEGER NOT NULL,
    utc REAL, utc_source TEXT, heading_deg REAL, outlet_lat REAL, outlet_lon REAL,
    zone TEXT, prescription_kg_ha REAL
);
CREATE TABLE event (
    id INTEGER PRIMARY KEY, t REAL NOT NULL, kind TEXT NOT NULL, detail TEXT NOT NULL
);
PRAGMA user_version = {SCHEMA_VERSION};
"""

SCHEMA_SQL: Final = _SCHEMA  # the tables and the version, as a script (for a salvaged copy)

_INSERT_RAW: Final = "INSERT INTO raw (t, kind, line, can_id, data) VALUES (?, ?, ?, ?, ?)"
_INSERT_STATE: Final = (
    f"INSERT INTO state ({', '.join(STATE_COLUMNS)}) VALUES ({', '.join('?' * len(STATE_COLUMNS))})"
)

_INSERT_EVENT: Final = "INSERT INTO event (t, kind, detail) VALUES (?, ?, ?)"

_RawRec = tuple[float, str, str | None, int | None, bytes | None]
_StateRec = tuple[object, ...]
_EventRec = tuple[float, str, str]


class _Sync:
    """A marker put on the queue; the writer sets `done` once everything before it is committed."""

    def __init__(self) -> None:
        self.done = threading.Event()


_STOP: Final = object()

#: Free space kept for closing (the last commit, the counters, the checkpoint): a file beside
#: the session, allocated at start and given back when the disk is full (half, to record the
#: failure in the file) and at close (the rest).
RESERVE_BYTES: Final = 256 * 1024
#: Below this much free space on the log's disk the log reports LOW_SPACE (it keeps writing).
MIN_FREE_BYTES: Final = 50 * 1024 * 1024


class LogHealth(StrEnum):
    """The session log's state, for the control loop to show (an alarm unless OK)."""

    OK = "ok"
    LOW_SPACE = "low_space"  # writing, but the disk's free space is below the margin
    DISK_FULL = "disk_full"  # the last commit failed: no space (or the max_bytes cap)
    WRITE_FAILING = "write_failing"  # the last commit (or the creation) failed otherwise


def _connect(path: Path) -> sqlite3.Connection:
    # isolation_level=None: transactions are explicit (BEGIN/COMMIT in the writer).
    conn = sqlite3.connect(path, isolation_level=None, check_same_thread=False)
    conn.execute("PRAGMA journal_mode = WAL")
    conn.execute("PRAGMA synchronous = FULL")
    return conn


def _claim_path(directory: Path, name: str | None) -> Path:
    """A fresh file name, created empty here with O_EXCL: checking first and creating after let
    a second terminal on the same directory take the name in between (and both wrote one
    file). SQLite takes an empty file as a new database."""
    stem = name or datetime.now(UTC).strftime("session-%Y%m%dT%H%M%SZ")
    n = 0
    while True:
        path = directory / (f"{stem}{SUFFIX}" if n == 0 else f"{stem}-{n}{SUFFIX}")
        if any(path.with_name(path.name + c).exists() for c in ("-wal", "-shm")):
            n += 1  # a left-over WAL would be applied to the new file as if it were its own
            continue
        try:
            os.close(os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644))
        except FileExistsError:
            n += 1
            continue
        return path


def _reserve_path(path: Path) -> Path:
    return path.with_name(f".{path.name}.reserve")


def _make_reserve(path: Path, size: int) -> int | None:
    """The reserve file, allocated (not sparse) and locked while the session is open; None
    when the disk has no room for it (the log works without)."""
    if size <= 0:
        return None
    try:
        fd = os.open(path, os.O_CREAT | os.O_RDWR | os.O_CLOEXEC, 0o644)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        os.posix_fallocate(fd, 0, size)
    except OSError:
        os.close(fd)
        with contextlib.suppress(OSError):
            path.unlink()
        return None
    return fd


def _remove_stale_reserves(directory: Path) -> None:
    """Reserve files of sessions that ended without closing (a kill, a power cut): nobody
    holds their lock. A running session's (another terminal's) stays."""
    for path in directory.glob(f".*{SUFFIX}.reserve"):
        try:
            fd = os.open(path, os.O_RDWR | os.O_CLOEXEC)
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            path.unlink()
        except OSError:
            pass
        finally:
            os.close(fd)


def _remove_unfinished(path: Path) -> None:
    """A file whose schema could not be written (disk full at start) holds nothing: remove it
    with its WAL and shared-memory files, rather than leave a 0-byte session behind."""
    for p in (path, path.with_name(path.name + "-wal"), path.with_name(path.name + "-shm")):
        with contextlib.suppress(OSError):
            p.unlink()


class SessionLog:
    """Append-only log of one working session. Build with `SessionLog.create()`."""

    def __init__(
        self,
        path: Path,
        conn: sqlite3.Connection | None,
        queue_size: int,
        commit_period_s: float,
        open_error: str | None,
        *,
        reserve: int | None = None,
        max_pages: int | None = None,
        min_free_bytes: int = MIN_FREE_BYTES,
    ) -> None:
        self.path = path
        self.dropped = 0  # rows refused because the queue was full or the log closed/failed
        self.lost = 0  # rows in batches that failed to commit
        self.errors = 0  # write failures (open, commit)
        self.last_error: str | None = None
        self._first_utc: float | None = None
        self._last_utc: float | None = None
        self._commit_failing = False
        self._health = LogHealth.OK if open_error is None else LogHealth.WRITE_FAILING
        self.free_bytes: int | None = None  # room on the disk (and under the cap), at each commit
        self.min_free_bytes = min_free_bytes
        self._reserve = reserve  # the reserve file's descriptor (locked), None: none
        self._max_pages = max_pages  # the max_bytes cap in pages
        self._failure_recorded = False
        self._count_lock = threading.Lock()
        self.commit_period_s = commit_period_s
        self._conn = conn
        # A deque under a plain lock, not a queue.Queue: a row is put ~200 times a second and
        # nobody waits on the queue itself (the writer waits on `_wake`).
        self._queue: deque[object] = deque()
        self._queue_size = queue_size
        self._queue_lock = threading.Lock()
        self._wake = threading.Event()  # the writer drains now, not at the end of the period
        self._wake_depth = max(1, queue_size // 2)
        self._closed = False
        self._thread: threading.Thread | None = None
        if open_error is not None:
            self._fail(open_error)
        else:
            self._check_space()
        if conn is not None:
            self._thread = threading.Thread(target=self._run, name="session-log", daemon=True)
            self._thread.start()

    @classmethod
    def create(
        cls,
        directory: str | Path,
        config_toml: str,
        *,
        name: str | None = None,
        queue_size: int = 20000,
        commit_period_s: float = 0.5,
        max_bytes: int | None = None,
        min_free_bytes: int = MIN_FREE_BYTES,
        reserve_bytes: int = RESERVE_BYTES,
    ) -> SessionLog:
        """Create a new session file in `directory` (made if missing) holding `config_toml`.

        Never raises on I/O: if the file cannot be made, the returned log has `ok` False,
        `errors` 1 and `last_error` set, and counts every row given to it as dropped.
        `max_bytes` caps the file size (SQLite reports "disk full" beyond it);
        `min_free_bytes`: the free-space margin below which `health` is LOW_SPACE;
        `reserve_bytes`: the space set aside for closing (see RESERVE_BYTES).
        """
        directory = Path(directory)
        path = directory / f"{name or 'session'}{SUFFIX}"
        claimed = False
        conn: sqlite3.Connection | None = None
        try:
            directory.mkdir(parents=True, exist_ok=True)
            path = _claim_path(directory, name)
            claimed = True
            conn = _connect(path)
            max_pages = None
            if max_bytes is not None:
                page_size = int(conn.execute("PRAGMA page_size").fetchone()[0])
                max_pages = max(1, max_bytes // page_size)
                conn.execute(f"PRAGMA max_page_count = {max_pages}")
            _init_schema(conn, config_toml)
        except (OSError, sqlite3.Error) as exc:
            if conn is not None:
                conn.close()
            if claimed:
                _remove_unfinished(path)
            return cls(path, None, queue_size, commit_period_s, f"cannot create the file: {exc}")
        _remove_stale_reserves(directory)
        reserve = _make_reserve(_reserve_path(path), reserve_bytes)
        return cls(
            path,
            conn,
            queue_size,
            commit_period_s,
            None,
            reserve=reserve,
            max_pages=max_pages,
            min_free_bytes=min_free_bytes,
        )

    @property
    def health(self) -> LogHealth:
        """OK, LOW_SPACE, DISK_FULL or WRITE_FAILING (read from any thread: one attribute)."""
        return self._health

    @property
    def ok(self) -> bool:
        """True while the log is open and writing: its last write succeeded and its disk (or
        cap) is not full."""
        full = self._health in (LogHealth.DISK_FULL, LogHealth.WRITE_FAILING)
        return self._thread is not None and not self._closed and not full

    def raw(self, kind: str, t: float, payload: str | tuple[int, bytes] | Any) -> None:
        """Enqueue one raw input: a line (kind nmea/crop) or a CAN frame (can_rx/can_tx) as
        `(arbitration_id, data)` or a can.Message."""
        rec = _raw_record(kind, t, payload)
        if rec is None:
            self._drop()
            self._fail(f"raw input of kind {kind!r} with a {type(payload).__name__} payload")
            return
        self._put(("raw", rec))

    def state(self, row: StateRow) -> None:
        """Enqueue one decoded state row."""
        if row.utc is not None and row.utc_source == "gnss":
            # The session's start and end in the receiver's UTC, for the meta at close.
            if self._first_utc is None:
                self._first_utc = row.utc
            self._last_utc = row.utc
        self._put(("state", row.as_tuple()))

    def event(self, ev: LogEvent) -> None:
        """Enqueue one event; it is committed with the batch it falls in (at the latest with
        the next state rows). A secret setting's values are masked here, whoever built it."""
        rec = _event_record(masked(ev))
        if rec is None:
            self._drop()
            self._fail(f"event {ev.kind!r} that is not a known kind with plain JSON values")
            return
        self._put(("event", rec))

    def sync(self, timeout_s: float = 5.0) -> bool:
        """Block until everything enqueued so far is committed (for shutdown and tests)."""
        if self._thread is None or self._closed:
            return False
        marker = _Sync()
        self._queue.append(marker)  # a marker is not a row: never refused
        self._wake.set()
        return marker.done.wait(timeout_s)

    def close(self) -> None:
        """Commit what is queued, record the loss counters in the file, and stop the writer."""
        if self._closed:
            return
        self._closed = True
        if self._thread is not None:
            self._queue.append(_STOP)
            self._wake.set()
            self._thread.join()

    def __enter__(self) -> SessionLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _put(self, item: tuple[str, object]) -> None:
        if self._closed or self._thread is None:
            self._drop()
            return
        with self._queue_lock:
            depth = len(self._queue)
            if depth < self._queue_size:
                self._queue.append(item)
        if depth >= self._queue_size:
            self._drop()
        elif depth + 1 >= self._wake_depth:
            self._wake.set()

    def _drop(self) -> None:
        # Several input threads may log at once.
        with self._count_lock:
            self.dropped += 1

    def _fail(self, message: str) -> None:
        with self._count_lock:
            self.errors += 1
            errors = self.errors
        # The first failure, then sparingly: a full disk fails every half second.
        if self.last_error is None or errors in (10, 100) or errors % 1000 == 0:
            _log.error("session log %s: %s (%d errors)", self.path, message, errors)
        self.last_error = message

    # ---- writer thread ----

    def _run(self) -> None:
        raws: list[_RawRec] = []
        states: list[_StateRec] = []
        events: list[_EventRec] = []
        syncs: list[_Sync] = []
        deadline = time.monotonic() + self.commit_period_s
        stop = False
        while not stop:
            self._wake.wait(max(0.0, deadline - time.monotonic()))
            self._wake.clear()
            while not stop:  # everything queued so far, in order, up to a stop
                try:
                    item = self._queue.popleft()
                except IndexError:
                    break
                if item is _STOP:
                    stop = True
                elif isinstance(item, _Sync):
                    syncs.append(item)
                elif isinstance(item, tuple):
                    if item[0] == "raw":
                        raws.append(item[1])
                    elif item[0] == "state":
                        states.append(item[1])
                    else:
                        events.append(item[1])
            if stop or syncs or time.monotonic() >= deadline:
                self._commit(raws, states, events)
                raws, states, events = [], [], []
                for s in syncs:
                    s.done.set()
                syncs = []
                deadline = time.monotonic() + self.commit_period_s
        self._finish()

    def _commit(
        self, raws: list[_RawRec], states: list[_StateRec], events: list[_EventRec]
    ) -> None:
        n = len(raws) + len(states) + len(events)
        if not n:
            return
        assert self._conn is not None
        try:
            self._conn.execute("BEGIN")
            self._conn.executemany(_INSERT_RAW, raws)
            self._conn.executemany(_INSERT_STATE, states)
            self._conn.executemany(_INSERT_EVENT, events)
            self._conn.execute("COMMIT")
        except sqlite3.Error as exc:
            self.lost += n
            self._commit_failing = True
            full = getattr(exc, "sqlite_errorcode", None) == sqlite3.SQLITE_FULL
            self._health = LogHealth.DISK_FULL if full else LogHealth.WRITE_FAILING
            self._fail(f"commit of {n} rows failed: {exc}")
            if self._conn.in_transaction:
                self._conn.execute("ROLLBACK")
            self._record_failure(str(exc), full)
        else:
            if self._commit_failing:
                _log.warning("session log %s: writing again", self.path)
            self._commit_failing = False
            self.last_error = None
            self._check_space()

    def _check_space(self) -> None:
        """Measure the room left (a statvfs and, under a max_bytes cap, the cap's free pages)
        and set the health from it. A full disk stays DISK_FULL until the room is back above
        the margin: a small batch that squeezes into the last pages does not end the alarm."""
        try:
            st = os.statvfs(self.path.parent)
        except OSError:
            return
        room = st.f_bavail * st.f_frsize
        if self._max_pages is not None and self._conn is not None:
            pages, free, size = (
                int(self._conn.execute(f"PRAGMA {p}").fetchone()[0])
                for p in ("page_count", "freelist_count", "page_size")
            )
            room = min(room, (self._max_pages - pages + free) * size)
        self.free_bytes = room
        if room >= self.min_free_bytes:
            self._health = LogHealth.OK
        elif self._health != LogHealth.DISK_FULL:
            self._health = LogHealth.LOW_SPACE

    def _record_failure(self, error: str, full: bool) -> None:
        """The first failure of a session goes into the file itself, so that `log summary`
        tells a full disk from a power cut: half the reserve is given back to make room."""
        if self._failure_recorded or self._conn is None:
            return
        self._failure_recorded = True
        self._release_reserve(half=True)
        record = {
            "kind": "disk_full" if full else "write_failed",
            "error": error,
            "utc": _iso(self._last_utc),
            "rows_lost_so_far": self.lost,
        }
        try:
            self._with_room(
                lambda conn: conn.execute(
                    "INSERT OR REPLACE INTO meta VALUES ('write_failed', ?)",
                    (json.dumps(record, separators=(",", ":")),),
                )
            )
        except sqlite3.Error as exc:
            _log.error("session log %s: the failure could not be recorded: %s", self.path, exc)

    def _with_room(self, write: Any) -> None:
        """Run `write(conn)` (autocommit) with the max_bytes cap lifted a little."""
        assert self._conn is not None
        if self._max_pages is not None:
            self._conn.execute(f"PRAGMA max_page_count = {self._max_pages + 64}")
        try:
            write(self._conn)
        finally:
            if self._max_pages is not None:
                self._conn.execute(f"PRAGMA max_page_count = {self._max_pages}")

    def _release_reserve(self, half: bool = False) -> None:
        fd = self._reserve
        if fd is None:
            return
        with contextlib.suppress(OSError):
            if half:
                os.ftruncate(fd, os.fstat(fd).st_size // 2)
                return
            _reserve_path(self.path).unlink()
        with contextlib.suppress(OSError):
            os.close(fd)
        self._reserve = None

    def _finish(self) -> None:
        assert self._conn is not None
        counters = {
            # From the state rows' GNSS time, never the PC's clock (empty: no fix all session)
            "start_utc": _iso(self._first_utc),
            "closed_utc": _iso(self._last_utc),
            "dropped": str(self.dropped),
            "lost": str(self.lost),
            "errors": str(self.errors),
        }
        # The reserve is given back first: closing must not need the space the disk lacks.
        self._release_reserve()
        try:
            self._with_room(
                lambda conn: conn.executemany(
                    "INSERT OR REPLACE INTO meta VALUES (?, ?)", counters.items()
                )
            )
        except sqlite3.Error as exc:
            self._fail(f"closing failed: {exc}")
        try:
            self._conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        except sqlite3.Error as exc:  # the -wal stays, with the counters in it: still closed
            _log.warning("session log %s: checkpoint at close failed: %s", self.path, exc)
        finally:
            self._conn.close()


def _iso(utc: float | None) -> str:
    if utc is None:
        return ""
    return datetime.fromtimestamp(utc, UTC).isoformat(timespec="milliseconds")


def _raw_record(kind: str, t: float, payload: Any) -> _RawRec | None:
    """The row for one raw input, or None when the payload does not fit the kind."""
    if kind in LINE_KINDS:
        return (float(t), kind, payload, None, None) if isinstance(payload, str) else None
    if kind not in CAN_KINDS:
        return None
    if hasattr(payload, "arbitration_id"):  # a can.Message
        payload = (payload.arbitration_id, payload.data)
    try:
        can_id, data = payload
        return (float(t), kind, None, int(can_id), bytes(data))
    except (TypeError, ValueError):
        return None


def _event_record(ev: LogEvent) -> _EventRec | None:
    """The row for one event, or None for an unknown kind or a detail JSON cannot hold."""
    if ev.kind not in EVENT_KINDS:
        return None
    try:
        detail = json.dumps(dict(ev.detail), allow_nan=False, separators=(",", ":"))
    except (TypeError, ValueError):
        return None
    return (float(ev.t), ev.kind, detail)


def _init_schema(conn: sqlite3.Connection, config_toml: str) -> None:
    meta = {
        # the session's stable id, made at its start: the office keys its copy by it
        "session_id": str(uuid.uuid4()),
        "config_toml": config_toml,
        "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "software": f"topdress {__version__}",
    }
    conn.executescript(f"BEGIN; {_SCHEMA} COMMIT;")
    conn.execute("BEGIN")
    conn.executemany("INSERT INTO meta VALUES (?, ?)", meta.items())
    conn.execute("COMMIT")


# ---- reading ----


@dataclass(frozen=True, slots=True)
class RawRecord:
    """One raw input as logged: `line` for nmea/crop, `can_id`/`data` for CAN."""

    t: float
    kind: str
    line: str | None
    can_id: int | None
    data: bytes | None


class SessionReader:
    """Read access to a session file (also one left behind by a killed writer).

    It never changes the file: it opens it read-only (a `-wal` beside it is read, not merged
    and removed, so a damaged one stays for `topdress log salvage`), or as immutable when
    there is no `-wal`. Every row is checked (`topdress.log.check`) before it is handed on; a
    damaged row is skipped and counted in `damaged`, and `warnings()` says what was skipped."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise LogError(f"{self.path}: no such session file")
        if not self.path.is_file():
            raise LogError(f"{self.path}: not a file (give the .sqlite file of a session)")
        self.notes: list[str] = []  # what is wrong with the file as a whole
        self._bad: dict[str, set[int]] = {t: set() for t in ("meta", "raw", "state", "event")}
        wal = self.path.with_name(self.path.name + "-wal")
        has_wal = wal.exists()
        if has_wal:
            walcheck = check_wal(wal)
            message = walcheck.message(wal) if walcheck is not None else None
            if message is not None:
                self.notes.append(message)
        wal_mode = _wal_mode(self.path)
        uri = self.path.resolve().as_uri() + ("?mode=ro" if has_wal else "?immutable=1")
        try:
            self._conn = sqlite3.connect(uri, uri=True)
        except sqlite3.Error as exc:
            raise LogError(f"{self.path}: cannot open: {exc}") from exc
        self._conn.text_factory = text_factory
        try:
            version = int(self._conn.execute("PRAGMA user_version").fetchone()[0])
            if version == 0 and wal_mode and not has_wal:
                raise LogError(
                    f"{self.path}: a live session copied without its -wal file (its rows are "
                    f"in {wal.name}, which is not beside it): copy {wal.name} too, or close "
                    "the session before copying"
                )
            if version == 0:  # an empty file, or another program's database
                raise LogError(f"{self.path}: not a topdress session log (no session schema)")
            if version not in READ_VERSIONS:
                raise LogError(
                    f"{self.path}: session schema {version}, this software reads "
                    f"{READ_VERSIONS[0]} to {READ_VERSIONS[-1]}"
                )
            self.version = version
            self.meta: dict[str, str] = {}
            for rowid, key, value in self._conn.execute("SELECT rowid, key, value FROM meta"):
                if meta_ok(key, value):
                    self.meta[key] = value
                else:
                    self._bad["meta"].add(int(rowid))
        except LogError as exc:
            self._conn.close()
            if self.notes:  # a damaged -wal may be why the file reads as no session
                raise LogError("; ".join([str(exc), *self.notes])) from exc
            raise
        except sqlite3.Error as exc:
            self._conn.close()
            raise LogError(
                f"{self.path}: not a readable session log: {exc}"
                + (f"; {_SALVAGE.format(path=self.path)}" if "malformed" in str(exc) else "")
            ) from exc
        #: Not closed, and no -wal beside it: the tail may be in a -wal left behind elsewhere.
        self.wal_missing = wal_mode and not has_wal and "closed_utc" not in self.meta

    @property
    def config_toml(self) -> str:
        return self.meta.get("config_toml", "")

    @property
    def session_id(self) -> str:
        """The id made at the session's start; for a file written before sessions had one, an
        id made from what the file recorded at its start (the same for every copy of it)."""
        sid = self.meta.get("session_id")
        if sid:
            return sid
        start = "\n".join(self.meta.get(k, "") for k in ("created_utc", "software", "config_toml"))
        return str(uuid.uuid5(_OLD_SESSIONS, start))

    @property
    def damaged(self) -> dict[str, int]:
        """Damaged rows skipped so far, by table (each row counted once)."""
        return {table: len(ids) for table, ids in self._bad.items() if ids}

    def warnings(self) -> list[str]:
        """What the commands tell the user: damage to the file as a whole, rows skipped."""
        out = list(self.notes)
        damaged = self.damaged
        if damaged:
            n = sum(damaged.values())
            where = ", ".join(f"{table} {k}" for table, k in damaged.items())
            out.append(
                f"{self.path}: {n} damaged row{'s' if n != 1 else ''} skipped ({where}): "
                "values of the wrong type or out of range"
            )
        return out

    def raw(self) -> Iterator[RawRecord]:
        """Raw inputs in time order. Inputs logged from several threads may reach the log a
        little out of order; equal times keep their logged order."""
        bad = self._bad["raw"]
        for rid, t, kind, line, can_id, data in self._select(
            "SELECT id, t, kind, line, can_id, data FROM raw ORDER BY t, id"
        ):
            if raw_ok(t, kind, line, can_id, data):
                yield RawRecord(float(t), kind, line, can_id, data)
            else:
                bad.add(rid)

    def can_frames(self, kind: str, can_id: int) -> Iterator[RawRecord]:
        """The raw CAN rows of `kind` (can_rx, can_tx) with identifier `can_id`, in time
        order: one frame looked for without reading every raw input."""
        bad = self._bad["raw"]
        for rid, t, k, line, cid, data in self._select(
            "SELECT id, t, kind, line, can_id, data FROM raw WHERE kind = ? AND can_id = ? "
            "ORDER BY t, id",
            (kind, can_id),
        ):
            if raw_ok(t, k, line, cid, data):
                yield RawRecord(float(t), k, line, cid, data)
            else:
                bad.add(rid)

    def states(self) -> Iterator[StateRow]:
        """State rows in the order they were logged. Columns added since a file was written
        (utc, outlet position, ...) read as None."""
        present = self.state_columns()
        cols = tuple(c for c in STATE_COLUMNS if c in present)
        for values in self._state_rows(cols):
            yield StateRow(**dict(zip(cols, values, strict=True)))

    def _state_rows(self, cols: tuple[str, ...]) -> Iterator[tuple[Any, ...]]:
        for row in self.numbered_states(cols):
            yield row[1:]

    def numbered_states(self, cols: tuple[str, ...]) -> Generator[tuple[Any, ...], None, None]:
        """The sound state rows as (id, *cols), in logged order: the id is the row's sequence
        number in the session, which never changes once written."""
        bad = self._bad["state"]
        for row in self._select(f"SELECT id, {', '.join(cols)} FROM state ORDER BY id"):
            if state_ok(cols, row[1:]):
                yield row
            else:
                bad.add(row[0])

    def numbered_events(self) -> Generator[tuple[int, float, str, str], None, None]:
        """The sound events as (id, t, kind, detail as JSON text), in logged order."""
        if self.version < 2:
            return
        bad = self._bad["event"]
        for rid, t, kind, text in self._select("SELECT id, t, kind, detail FROM event ORDER BY id"):
            if event_detail(t, kind, text) is None:
                bad.add(rid)
            else:
                yield int(rid), float(t), str(kind), str(text)

    def events(self) -> Iterator[LogEvent]:
        """The events in time order (none in a version-1 file)."""
        if self.version < 2:
            return
        bad = self._bad["event"]
        for rid, t, kind, text in self._select(
            "SELECT id, t, kind, detail FROM event ORDER BY t, id"
        ):
            detail = event_detail(t, kind, text)
            if detail is None:
                bad.add(rid)
            else:
                yield LogEvent(float(t), kind, detail)

    def event_counts(self) -> dict[str, int]:
        """Number of events of each kind."""
        counts = Counter(ev.kind for ev in self.events())
        return dict(sorted(counts.items()))

    def state_values(self, columns: tuple[str, ...]) -> dict[str, list[Any]]:
        """The given state columns in logged order, as lists (bulk reading for exports);
        a column this file lacks reads as None."""
        present = self.state_columns()
        cols = tuple(c for c in columns if c in present)
        rows = list(self._state_rows(cols)) if cols else []
        n = len(rows) if cols else self.count("state")
        got = dict(zip(cols, (list(c) for c in zip(*rows, strict=True)), strict=True)) if n else {}
        return {c: got.get(c, [None] * n) if c in present else [None] * n for c in columns}

    def state_chunks(self, columns: tuple[str, ...], rows: int) -> Iterator[dict[str, list[Any]]]:
        """`state_values` `rows` rows at a time: a long session read in bounded memory."""
        present = self.state_columns()
        cols = tuple(c for c in columns if c in present)
        values = self._state_rows(cols)
        while block := list(itertools.islice(values, rows)):
            got = dict(zip(cols, (list(c) for c in zip(*block, strict=True)), strict=True))
            yield {c: got[c] if c in present else [None] * len(block) for c in columns}

    def state_columns(self) -> frozenset[str]:
        """The state table's columns in this file (older files lack the added ones)."""
        return frozenset(str(r[1]) for r in self._select("PRAGMA table_info(state)"))

    def raw_counts(self) -> dict[str, int]:
        """Number of raw inputs of each kind (rows of no known kind are counted as damaged)."""
        rows = self._select("SELECT kind, count(*) FROM raw GROUP BY kind")
        counts = {kind: int(n) for kind, n in rows if kind in RAW_KINDS}
        if sum(counts.values()) < self.count("raw"):
            known = ", ".join(f"'{k}'" for k in RAW_KINDS)
            ids = self._select(f"SELECT id FROM raw WHERE kind IS NULL OR kind NOT IN ({known})")
            self._bad["raw"].update(int(r[0]) for r in ids)
        return counts

    def count(self, table: str) -> int:
        if table not in ("raw", "state", "event"):
            raise ValueError(table)
        if table == "event" and self.version < 2:
            return 0
        return int(next(self._select(f"SELECT count(*) FROM {table}"))[0])

    def _select(self, sql: str, args: tuple[Any, ...] = ()) -> Iterator[tuple[Any, ...]]:
        # A damaged page (a worn SD card, a stick pulled while writing) shows only when read.
        try:
            yield from self._conn.execute(sql, args)
        except sqlite3.Error as exc:
            raise LogError(
                f"{self.path}: damaged session log ({exc}); {_SALVAGE.format(path=self.path)}"
            ) from exc

    def close(self) -> None:
        self._conn.close()

    def __enter__(self) -> SessionReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


_OLD_SESSIONS: Final = uuid.UUID("5f1c2a52-8e0b-4f55-9a43-7d1c3b6e2a10")
_SALVAGE: Final = "`topdress log salvage {path} --out NEW.sqlite` saves what is left"


def _wal_mode(path: Path) -> bool:
    """The file's header says WAL (bytes 18 and 19 are 2): its last writes may be in a -wal."""
    try:
        with path.open("rb") as f:
            head = f.read(20)
    except OSError:
        return False
    return len(head) == 20 and head[18] == 2 and head[19] == 2


def session_config(config_toml: str) -> TerminalConfig:
    """The configuration a session was recorded with (`SessionReader.config_toml`); the
    defaults where it cannot be read, said in the program log (a file from another version)."""
    try:
        return loads_config(config_toml)
    except ConfigError as exc:
        _log.warning("session configuration unreadable (%s): defaults used", exc)
        return TerminalConfig()
