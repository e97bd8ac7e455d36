"""Headlands in `topdress log summary`: every stop and headland entry, whether the metering
reached zero, and the kg and metres metered after it (worked values)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from topdress.cli.main import main
from topdress.log.model import StateRow
from topdress.log.session import SessionLog, SessionReader
from topdress.log.summary import summarise

CONFIG = "[machine]\nkg_per_rev_upper = 0.3\nkg_per_rev_lower = 0.3\n"


def row(t: float, v_gnss: float, v: float, rpm: float, zone: str | None = None) -> StateRow:
    return StateRow(
        t, 45.0, 126.0, v_gnss, v, v, "wheel", 1.0, 0.8, 100.0, 100.0,
        21.6, 21.6, rpm, rpm, 3000.0, 3000.0, 0, zone=zone,
    )  # fmt: skip


def write(directory: Path) -> Path:
    rows: list[StateRow] = []
    t = 0.0

    def add(n: int, v_gnss: float, v: float, rpm: float, zone: str | None = "field") -> None:
        nonlocal t
        for _ in range(n):
            rows.append(row(t, v_gnss, v, rpm, zone))
            t += 0.1

    add(100, 7.2, 7.2, 21.6)  # 10 s of work at 2 m/s
    # stop 1: GNSS reads the stop at once, the wheel speed a 0.5 s update later, the meters
    # turn 1.0 s after the stop, then rest
    add(5, 0.0, 7.2, 21.6)
    add(5, 0.0, 0.0, 21.6)
    add(20, 0.0, 0.0, 0.0)
    add(50, 7.2, 7.2, 21.6)
    # stop 2: the meters never stop before the machine moves on
    add(10, 0.0, 0.0, 21.6)
    add(50, 7.2, 7.2, 21.6)
    # headland entry: the meters run 0.3 s into it
    add(3, 7.2, 7.2, 21.6, "headland")
    add(20, 7.2, 7.2, 0.0, "headland")
    with SessionLog.create(directory, CONFIG) as log:
        for r in rows:
            log.state(r)
    return log.path


def test_stops_and_headland_entries_worked_values(tmp_path: Path) -> None:
    with SessionReader(write(tmp_path)) as reader:
        s = summarise(reader)
    stops = [e for e in s.stops if e.kind == "stop"]
    assert [round(e.t, 1) for e in stops] == [10.0, 18.0]
    first, second = stops
    assert first.reached_zero and first.zero_after_s == pytest.approx(1.0)
    # 21.6 r/min x 0.3 kg x 2 layers for 1.0 s; 2 m/s for the 0.5 s the wheel still ran
    assert first.kg_after == pytest.approx(21.6 / 60 * 0.6 * 1.0)
    assert first.m_after == pytest.approx(1.0)
    assert not second.reached_zero and second.zero_after_s is None
    assert second.kg_after == pytest.approx(21.6 / 60 * 0.6 * 1.0)
    assert s.stops_zero_pct == pytest.approx(50.0)
    (entry,) = [e for e in s.stops if e.kind == "headland"]
    assert entry.reached_zero and entry.zero_after_s == pytest.approx(0.3)
    assert entry.kg_after == pytest.approx(21.6 / 60 * 0.6 * 0.3)
    assert entry.m_after == pytest.approx(0.6)
    assert s.headland_zero_pct == 100.0


def test_headlands_in_the_text_and_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = write(tmp_path)
    assert main(["log", "summary", str(path)]) == 0
    text = capsys.readouterr().out
    assert "stops            2, metering reached zero after 50 %, 0.432 kg and 1.0 m" in text
    assert "headland entries 1, metering reached zero after 100 %" in text
    assert main(["log", "summary", str(path), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["stops_zero_pct"] == 50.0 and len(doc["stops"]) == 3
