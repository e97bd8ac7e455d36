"""Damage SQLite does not see: the log commands skip and count bad rows, never crash, never blow
up; a copy without its -wal and a torn -wal are named; `log salvage` saves what is left."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import pytest

from session_rig import closed_session, live_copy
from topdress.cli.main import main
from topdress.errors import LogError
from topdress.log.session import SessionReader


def poke(path: Path, sql: str, *args: object) -> None:
    """A foreign writer (or a flipped type byte): a value SQLite stores without complaint."""
    conn = sqlite3.connect(path)
    with conn:
        conn.execute(sql, args)
    conn.close()


def test_a_value_of_the_wrong_type_is_skipped_and_counted(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # A text in a speed, a blob in a time, a JSON array as a detail: a traceback before.
    path = closed_session(tmp_path)
    poke(path, "UPDATE state SET v_kmh = 'fast' WHERE id = 7")
    poke(path, "UPDATE state SET t = x'00ff' WHERE id = 9")
    poke(path, "UPDATE raw SET t = 'later' WHERE id = 3")
    poke(path, "UPDATE event SET detail = '[1, 2]' WHERE id = 1")
    assert main(["log", "summary", str(path), "--json"]) == 0
    out = capsys.readouterr()
    assert json.loads(out.out)["state_rows"] == 198  # 200 written, 2 damaged
    assert "3 damaged rows skipped (state 2, event 1)" in out.err
    ev, csv = tmp_path / "ev.ndjson", tmp_path / "s.csv"
    gpkg = tmp_path / "m.gpkg"
    argv = ["log", "export", str(path), "--events", str(ev), "--csv", str(csv)]
    assert main([*argv, "--log-events", str(tmp_path / "le.ndjson")]) == 0
    assert "4 damaged rows skipped (raw 1, state 2, event 1)" in capsys.readouterr().err
    assert len(csv.read_text().splitlines()) == 1 + 198
    assert main(["log", "export", str(path), "--out", str(gpkg)]) == 0
    assert "2 damaged rows skipped (state 2)" in capsys.readouterr().err
    assert main(["replay", str(ev), "--out", str(tmp_path / "r.csv")]) == 0


def test_out_of_range_values_are_damage_too(tmp_path: Path) -> None:
    # A flipped exponent bit turns 8 km/h into 1e300, a latitude into 200, a fault word
    # negative; a bit flipped in an event kind makes it unknown.
    path = closed_session(tmp_path)
    poke(path, "UPDATE state SET v_kmh = 1e300 WHERE id = 2")
    poke(path, "UPDATE state SET lat = 200.0 WHERE id = 3")
    poke(path, "UPDATE state SET faults = -1 WHERE id = 4")
    poke(path, "UPDATE state SET utc = 1e12 WHERE id = 5")
    poke(path, "UPDATE event SET kind = 'operator.stbrt' WHERE id = 1")
    poke(path, "UPDATE raw SET can_id = 1 << 40 WHERE kind = 'can_tx' AND id < 50")
    with SessionReader(path) as reader:
        assert len(list(reader.states())) == 196
        assert [e.kind for e in reader.events()] == ["operator.stop"]
        raws = list(reader.raw())
        assert all(r.can_id is None or r.can_id < 1 << 29 for r in raws)
        assert reader.damaged["state"] == 4 and reader.damaged["event"] == 1
        assert reader.damaged["raw"] >= 1


def test_one_bad_integer_in_a_can_row_does_not_make_a_huge_trace(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # An integer where the 8 data bytes belong: bytes(n) made an n-byte frame (2 GB before).
    path = closed_session(tmp_path)
    poke(path, "UPDATE raw SET data = 5000000 WHERE kind = 'can_rx' AND id = 3")
    trace = tmp_path / "can.log"
    assert main(["log", "export", str(path), "--can", str(trace)]) == 0
    assert "1 damaged row skipped (raw 1)" in capsys.readouterr().err
    assert trace.stat().st_size < path.stat().st_size
    assert len(trace.read_text().splitlines()) == 200 + 40 - 1


def test_a_live_session_copied_without_its_wal_is_named(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    copy = live_copy(tmp_path / "terminal", tmp_path / "stick")
    copy.with_name(copy.name + "-wal").unlink()
    assert main(["log", "summary", str(copy)]) == 2
    err = capsys.readouterr().err
    assert "a live session copied without its -wal file" in err
    assert "not a topdress session log" not in err
    assert not copy.with_name(copy.name + "-wal").exists()  # the reader created nothing


def test_a_live_copy_with_its_wal_reads_whole_and_is_not_changed(tmp_path: Path) -> None:
    copy = live_copy(tmp_path / "terminal", tmp_path / "stick")
    wal = copy.with_name(copy.name + "-wal")
    before = (copy.read_bytes(), wal.read_bytes())
    with SessionReader(copy) as reader:
        assert reader.count("state") == 200 and reader.warnings() == []
    assert (copy.read_bytes(), wal.read_bytes()) == before


def _frame_offsets(wal: Path) -> list[int]:
    page = int.from_bytes(wal.read_bytes()[8:12], "big")
    n = (wal.stat().st_size - 32) // (24 + page)
    return [32 + i * (24 + page) for i in range(n)]


def test_a_damaged_wal_frame_is_reported_not_dropped_in_silence(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    copy = live_copy(tmp_path / "terminal", tmp_path / "stick", seconds=60.0)
    wal = copy.with_name(copy.name + "-wal")
    frames = _frame_offsets(wal)
    assert len(frames) > 20
    data = bytearray(wal.read_bytes())
    intact = bytes(data)
    k = len(frames) // 2
    data[frames[k] + 24 + 100] ^= 0x10  # one bit in a frame's page
    wal.write_bytes(bytes(data))
    assert main(["log", "summary", str(copy)]) == 0
    err = capsys.readouterr().err
    assert f"-wal: damaged at frame {k}: " in err
    assert "cannot be read" in err
    # in the first frames (the schema): no session, and the -wal named as the reason
    data = bytearray(intact)
    data[frames[1] + 24 + 100] ^= 0x10
    wal.write_bytes(bytes(data))
    assert main(["log", "summary", str(copy)]) == 2
    assert "-wal: damaged at frame 1" in capsys.readouterr().err


def test_a_wal_cut_in_its_last_frame_is_reported_as_a_cut_write(tmp_path: Path) -> None:
    copy = live_copy(tmp_path / "terminal", tmp_path / "stick")
    wal = copy.with_name(copy.name + "-wal")
    wal.write_bytes(wal.read_bytes()[:-1000])
    with SessionReader(copy) as reader:
        assert any("the last write was cut off" in w for w in reader.warnings())


def test_salvage_copies_what_a_damaged_page_left_and_says_how_much(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = closed_session(tmp_path, seconds=120.0)
    data = bytearray(path.read_bytes())
    page = 4096
    pages = len(data) // page
    data[(pages // 2) * page : (pages // 2 + 2) * page] = b"\x5a" * (2 * page)
    path.write_bytes(bytes(data))
    assert main(["log", "export", str(path), "--events", str(tmp_path / "e.ndjson")]) == 2
    assert f"topdress log salvage {path} --out" in capsys.readouterr().err
    new = tmp_path / "saved.sqlite"
    assert main(["log", "salvage", str(path), "--out", str(new)]) == 0
    line = capsys.readouterr().out
    assert f"{new}: " in line and " rows recovered (" in line
    with SessionReader(new) as reader:
        kept = reader.count("raw") + reader.count("state") + reader.count("event")
        assert reader.warnings() == []
        assert len(list(reader.states())) == reader.count("state")
        assert reader.meta["config_toml"].startswith("[machine]")
    assert 0.8 * 5042 < kept < 5042  # 2 of ~100 pages lost: most rows saved, not all
    assert main(["log", "summary", str(new)]) == 0
    assert main(["log", "salvage", str(path), "--out", str(new)]) == 2  # never overwrites


def test_salvage_of_a_file_cut_short(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = closed_session(tmp_path, seconds=120.0)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) * 6 // 10])
    new = tmp_path / "saved.sqlite"
    assert main(["log", "salvage", str(path), "--out", str(new)]) == 0
    line = capsys.readouterr().out
    with SessionReader(new) as reader:
        kept = reader.count("raw") + reader.count("state")
    assert kept > 0.3 * 5040, line


def test_salvage_of_no_session_is_a_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    junk = tmp_path / "junk.sqlite"
    junk.write_bytes(b"\x00" * 8192)
    assert main(["log", "salvage", str(junk), "--out", str(tmp_path / "n.sqlite")]) == 2
    assert "topdress: error:" in capsys.readouterr().err
    assert not (tmp_path / "n.sqlite").exists()
    with pytest.raises(LogError):
        SessionReader(junk)


def test_a_line_that_is_not_utf8_is_one_damaged_row(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # One flipped bit in an NMEA line made sqlite3 stop the whole export (exit 2).
    path = closed_session(tmp_path)
    poke(path, "UPDATE raw SET line = CAST(x'2447505203ff4d43' AS TEXT) WHERE id = 1")
    ev = tmp_path / "ev.ndjson"
    assert main(["log", "export", str(path), "--events", str(ev)]) == 0
    assert "1 damaged row skipped (raw 1)" in capsys.readouterr().err
    assert len(ev.read_text().splitlines()) == 200 * 3 + 40 + 200 - 1  # + wheel counts
