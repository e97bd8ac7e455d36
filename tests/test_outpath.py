"""Outputs never destroy an input: not the session, not its WAL, not a link to it; written
under a temporary name and renamed; `-` is standard output."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from test_export_events import make_session
from test_log_durability import run_and_kill
from topdress.cli.main import main
from topdress.errors import OutputError
from topdress.log.export import STATE_COLUMNS
from topdress.outpath import check_output, open_text_output, write_output


def test_export_refuses_the_wal_of_a_session_left_by_kill_9(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # `log export S --events S-wal` truncated the WAL of a killed session: every row lost.
    run_and_kill(tmp_path, 0.8)
    (session,) = tmp_path.glob("*.sqlite")
    wal = session.with_name(session.name + "-wal")
    assert wal.stat().st_size > 0  # the rows are still in the WAL, not yet checkpointed
    before = wal.read_bytes()
    for victim in (wal, session.with_name(session.name + "-shm"), session):
        assert main(["log", "export", str(session), "--events", str(victim)]) == 2
        assert "is the input" in capsys.readouterr().err
    assert wal.read_bytes() == before
    assert main(["log", "export", str(session), "--events", str(tmp_path / "ev.ndjson")]) == 0
    assert (tmp_path / "ev.ndjson").stat().st_size > 0


def test_replay_refuses_to_overwrite_its_input(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    session = make_session(tmp_path)
    events = tmp_path / "ev.ndjson"
    assert main(["log", "export", str(session), "--events", str(events)]) == 0
    text = events.read_text()
    link = tmp_path / "link.ndjson"
    os.link(events, link)  # the same inode under another name
    for out in (events, link, Path(str(tmp_path) + "/./ev.ndjson")):
        assert main(["replay", str(events), "--out", str(out)]) == 2
        assert "is the input" in capsys.readouterr().err
    assert events.read_text() == text


def test_dash_is_standard_output_everywhere(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    session = make_session(tmp_path)
    monkeypatch.chdir(tmp_path)
    capsys.readouterr()
    assert main(["log", "export", str(session), "--events", "-"]) == 0
    out = capsys.readouterr().out
    assert [sorted(json.loads(line))[0] for line in out.splitlines()][:2] == ["nmea", "crop"]
    events = tmp_path / "ev.ndjson"
    events.write_text(out)
    assert main(["replay", str(events), "--out", "-"]) == 0
    assert capsys.readouterr().out.startswith("t,v_wheel_kmh,")
    assert main(["log", "export", str(session), "--csv", "-"]) == 0
    assert capsys.readouterr().out.splitlines()[0].split(",")[0] == STATE_COLUMNS[0]
    assert not (tmp_path / "-").exists()  # it used to make a file named '-'


def test_a_failed_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path: Path) -> None:
    out = tmp_path / "result.csv"
    out.write_text("old\n")
    with pytest.raises(RuntimeError), open_text_output(out, []) as f:
        f.write("half")
        raise RuntimeError("the writer failed")
    assert out.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["result.csv"]

    def boom(tmp: Path) -> None:
        tmp.write_text("half")
        raise OutputError("format failed")

    with pytest.raises(OutputError):
        write_output(out, [], boom, ".csv")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["result.csv"]
    assert write_output(out, [], lambda tmp: tmp.write_text("new\n"), ".csv") == 4
    assert out.read_text() == "new\n"


def test_check_output_companions_and_unrelated_files(tmp_path: Path) -> None:
    source = tmp_path / "s.sqlite"
    source.write_text("x")
    for name in ("s.sqlite", "s.sqlite-wal", "s.sqlite-shm", "s.sqlite-journal"):
        with pytest.raises(OutputError):
            check_output(tmp_path / name, [source])
    check_output(tmp_path / "s.csv", [source])  # another file: fine
    check_output("-", [source])
