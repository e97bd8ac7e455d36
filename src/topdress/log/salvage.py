"""`topdress log salvage`: copy what can still be read of a damaged session into a new file.

Built on Python's sqlite3 alone (the sqlite3 command-line program is not on every tractor PC):
the tables are read row by row in id order; where a damaged page stops the reading, the copy
jumps ahead (1, 2, 4, ... ids) until it reads again, so one bad page costs the rows on it and
not the rest of the table (`sqlite3 .recover` gave up on a file cut short; `.dump` stops at the
first bad page of each table). Each row read goes through the reader's checks
(`topdress.log.check`): a damaged row is not copied. The source is opened read-only (with its
`-wal`, whose sound frames are read) and never changed.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

from topdress.errors import LogError
from topdress.log.check import event_detail, meta_ok, raw_ok, state_ok, text_factory
from topdress.log.model import STATE_COLUMNS
from topdress.log.session import SCHEMA_SQL

_TABLES: Final = {
    "raw": ("t", "kind", "line", "can_id", "data"),
    "state": STATE_COLUMNS,
    "event": ("t", "kind", "detail"),
}
_MAX_JUMP: Final = 1 << 40
_BATCH: Final = 5000


@dataclass
class TableSalvage:
    copied: int = 0
    damaged: int = 0  # read, but failed the checks
    last_id: int = 0  # the highest id seen (rows are numbered from 1 as written)
    unreadable_ranges: int = 0  # places where damaged pages stopped the reading

    @property
    def unreadable(self) -> int:
        """Rows that were written (ids up to the last seen) but could not be read."""
        return max(self.last_id - self.copied - self.damaged, 0)


@dataclass
class SalvageReport:
    source: str
    out: str
    meta: int = 0
    tables: dict[str, TableSalvage] = field(default_factory=dict)

    def text(self) -> str:
        copied = sum(t.copied for t in self.tables.values())
        written = sum(t.last_id for t in self.tables.values())
        pct = f" ({100.0 * copied / written:.1f} %)" if written else ""
        parts = [
            f"{name} {t.copied} of {t.last_id}" + (f" ({t.damaged} damaged)" if t.damaged else "")
            for name, t in self.tables.items()
        ]
        return (
            f"{self.out}: {copied} of {written} rows recovered{pct}: {', '.join(parts)}; "
            f"{self.meta} meta entries"
        )


def salvage(source: Path, out: Path) -> SalvageReport:
    """Copy the readable, sound rows of `source` into a new session file `out` (which must not
    exist: write it under a temporary name and rename)."""
    report = SalvageReport(str(source), str(out))
    has_wal = source.with_name(source.name + "-wal").exists()
    uri = source.resolve().as_uri() + ("?mode=ro" if has_wal else "?immutable=1")
    try:
        src = sqlite3.connect(uri, uri=True)
    except sqlite3.Error as exc:
        raise LogError(f"{source}: cannot open: {exc}") from exc
    src.text_factory = text_factory
    try:
        # As the sqlite3 shell's .dump: a file shorter than its header says is read as far
        # as it goes instead of refused (a connection setting; nothing is written).
        src.execute("PRAGMA writable_schema = ON")
        present = _tables(src, source)
        dst = sqlite3.connect(out, isolation_level=None)
        try:
            dst.executescript(f"BEGIN; {SCHEMA_SQL} COMMIT;")
            dst.execute("BEGIN")
            for key, value in _readable(src, "SELECT key, value FROM meta"):
                if meta_ok(key, value):
                    dst.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)", (key, value))
                    report.meta += 1
            dst.execute(
                "INSERT OR REPLACE INTO meta VALUES ('salvaged_from', ?)", (str(source.name),)
            )
            for table, columns in _TABLES.items():
                if table in present:
                    cols = tuple(c for c in columns if c in present[table])
                    report.tables[table] = _copy(src, dst, table, cols)
            dst.execute("COMMIT")
        finally:
            dst.close()
    finally:
        src.close()
    return report


def _tables(src: sqlite3.Connection, source: Path) -> dict[str, set[str]]:
    try:
        names = [r[0] for r in src.execute("SELECT name FROM sqlite_master WHERE type='table'")]
        return {
            name: {str(r[1]) for r in src.execute(f"PRAGMA table_info({name})")}
            for name in names
            if name in _TABLES
        }
    except sqlite3.Error as exc:
        raise LogError(
            f"{source}: nothing can be salvaged: its schema page is unreadable ({exc})"
        ) from exc


def _readable(src: sqlite3.Connection, sql: str) -> Iterator[tuple[Any, ...]]:
    try:
        yield from src.execute(sql)
    except sqlite3.Error:
        return


def _copy(
    src: sqlite3.Connection, dst: sqlite3.Connection, table: str, cols: tuple[str, ...]
) -> TableSalvage:
    got = TableSalvage()
    insert = f"INSERT INTO {table} ({', '.join(cols)}) VALUES ({', '.join('?' * len(cols))})"
    select = f"SELECT id, {', '.join(cols)} FROM {table} WHERE id > ? ORDER BY id"
    after = 0  # the last id read (or jumped to)
    jump = 1
    in_gap = False
    while after < _MAX_JUMP:
        batch: list[tuple[Any, ...]] = []
        try:
            for row in src.execute(select, (after,)):
                in_gap = False
                rid = row[0]
                after = got.last_id = max(got.last_id, rid)
                if _sound(table, cols, row[1:]):
                    batch.append(row[1:])
                else:
                    got.damaged += 1
                if len(batch) >= _BATCH:
                    _flush(dst, insert, batch, got)
            _flush(dst, insert, batch, got)
            break  # read to the end of the table
        except sqlite3.Error:
            _flush(dst, insert, batch, got)
            if not in_gap:  # a new damaged place
                got.unreadable_ranges += 1
                in_gap, jump = True, 1
            after += jump  # past the page that stopped the reading, further each time
            jump *= 2
    return got


def _flush(
    dst: sqlite3.Connection, insert: str, batch: list[tuple[Any, ...]], got: TableSalvage
) -> None:
    dst.executemany(insert, batch)
    got.copied += len(batch)
    batch.clear()


def _sound(table: str, cols: tuple[str, ...], values: tuple[Any, ...]) -> bool:
    if table == "raw":
        return raw_ok(*values)
    if table == "state":
        return state_ok(cols, values)
    return event_detail(*values) is not None
