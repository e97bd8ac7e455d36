"""Mutated copies of a session (values of another type, flipped bits, pages of noise, a file cut
short, damaged -wal frames) through every log command: exit 0 or 2, never a traceback, and
no output larger than a bound set by the session's size. Seeded: the same mutants each run."""

from __future__ import annotations

import contextlib
import random
import shutil
import sqlite3
from collections.abc import Callable
from pathlib import Path

import pytest

from session_rig import closed_session, live_copy
from topdress.cli.main import main

SEED = 22
PAGE = 4096


def _values(path: Path, rng: random.Random) -> None:
    """A foreign writer: one value of another type or far out of range in each table."""
    bad: list[object] = ["x", b"\x00\xff", 2**62, -(2**62), 1e300, -1.0, None, "", 5_000_000]
    conn = sqlite3.connect(path)
    with conn:
        for table, cols in (
            ("raw", ("t", "kind", "line", "can_id", "data")),
            ("state", ("t", "lat", "v_kmh", "source", "faults", "utc", "meter_rpm_upper")),
            ("event", ("t", "kind", "detail")),
            ("meta", ("value",)),
        ):
            col = rng.choice(cols)
            n = conn.execute(f"SELECT max(rowid) FROM {table}").fetchone()[0]
            rowid = rng.randint(1, n)
            sql = f"UPDATE {table} SET {col} = ? WHERE rowid = ?"
            with contextlib.suppress(sqlite3.IntegrityError):  # NOT NULL or CHECK refused it
                conn.execute(sql, (rng.choice(bad), rowid))
    conn.close()


def _bits(path: Path, rng: random.Random) -> None:
    data = bytearray(path.read_bytes())
    for _ in range(rng.randint(1, 8)):
        i = rng.randrange(100, len(data))  # past the file header
        data[i] ^= 1 << rng.randrange(8)
    path.write_bytes(bytes(data))


def _types(path: Path, rng: random.Random) -> None:
    """Type bytes of record headers: the byte after a cell's header length, changed."""
    data = bytearray(path.read_bytes())
    for _ in range(rng.randint(1, 6)):
        page = rng.randrange(1, len(data) // PAGE)
        start = page * PAGE
        if data[start] != 0x0D:  # a table leaf page
            continue
        ncells = int.from_bytes(data[start + 3 : start + 5], "big")
        if not ncells:
            continue
        cell = int.from_bytes(data[start + 8 + 2 * rng.randrange(ncells) :][:2], "big")
        # payload length and rowid (varints, mostly 1-3 bytes), then the record header
        i = start + cell
        for _ in range(2):
            while data[i] & 0x80:
                i += 1
            i += 1
        j = i + 1 + rng.randrange(max(1, min(data[i] - 1, 20)))
        data[j] = rng.choice([0, 1, 2, 4, 6, 7, 8, 9, 13, 14, 0x81, 0x0F])
    path.write_bytes(bytes(data))


def _pages(path: Path, rng: random.Random) -> None:
    data = bytearray(path.read_bytes())
    page = rng.randrange(1, len(data) // PAGE)
    fill = rng.choice([b"\x00", b"\xff", bytes([rng.randrange(256)])])
    data[page * PAGE : (page + 1) * PAGE] = fill * PAGE
    path.write_bytes(bytes(data))


def _cut(path: Path, rng: random.Random) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: rng.randrange(PAGE, len(data))])


def _wal(path: Path, rng: random.Random) -> None:
    wal = path.with_name(path.name + "-wal")
    data = bytearray(wal.read_bytes())
    how = rng.randrange(3)
    if how == 0:
        for _ in range(rng.randint(1, 4)):
            data[rng.randrange(32, len(data))] ^= 1 << rng.randrange(8)
    elif how == 1:
        data = data[: rng.randrange(32, len(data))]
    else:
        wal.unlink()
        return
    wal.write_bytes(bytes(data))


MUTATIONS: dict[str, Callable[[Path, random.Random], None]] = {
    "values": _values,
    "bits": _bits,
    "types": _types,
    "pages": _pages,
    "cut": _cut,
}


def _commands(session: Path, out: Path) -> list[list[str]]:
    s = str(session)
    return [
        ["log", "summary", s],
        ["log", "summary", s, "--json"],
        [
            "log", "export", s, "--events", str(out / "ev.ndjson"), "--csv", str(out / "s.csv"),
            "--log-events", str(out / "le.ndjson"), "--config", str(out / "c.toml"),
            "--can", str(out / "can.log"),
        ],
        ["log", "export", s, "--out", str(out / "m.gpkg")],
        ["log", "map", s, "--out", str(out / "m.html")],
        ["log", "salvage", s, "--out", str(out / "saved.sqlite")],
    ]  # fmt: skip


def _run_all(session: Path, out: Path, capsys: pytest.CaptureFixture[str]) -> list[int]:
    size = session.stat().st_size
    wal = session.with_name(session.name + "-wal")
    size += wal.stat().st_size if wal.exists() else 0
    codes = []
    for argv in _commands(session, out):
        codes.append(main(argv))  # any exception but a TopdressError fails the test here
    events = out / "ev.ndjson"
    if events.exists():
        codes.append(main(["replay", str(events), "--out", str(out / "r.csv")]))
    saved = out / "saved.sqlite"
    if saved.exists():
        codes.append(main(["log", "summary", str(saved)]))
    for f in out.iterdir():  # bounded by the session: no 2 GB trace from one integer
        assert f.stat().st_size < 10 * size + 1_000_000, f
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert all(code in (0, 2) for code in codes), (codes, err)
    return codes


@pytest.fixture(scope="module")
def originals(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    where = tmp_path_factory.mktemp("originals")
    closed = closed_session(where / "closed", seconds=30.0)
    live = live_copy(where / "terminal", where / "live", seconds=30.0)
    return closed, live


@pytest.mark.parametrize("n", range(30))
def test_no_log_command_crashes_on_a_mutated_session(
    n: int, originals: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rng = random.Random(SEED * 1000 + n)
    closed, live = originals
    names = sorted(MUTATIONS)
    kind = names[n % len(names)] if n < 25 else "wal"
    source = live if kind == "wal" else closed
    session = tmp_path / source.name
    shutil.copyfile(source, session)
    if kind == "wal":
        shutil.copyfile(
            source.with_name(source.name + "-wal"), session.with_name(session.name + "-wal")
        )
        _wal(session, rng)
    else:
        MUTATIONS[kind](session, rng)
    out = tmp_path / "out"
    out.mkdir()
    _run_all(session, out, capsys)
