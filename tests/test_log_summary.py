"""`topdress log summary`: worked values from a synthetic run."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from topdress.cli.main import main
from topdress.log.model import StateRow
from topdress.log.session import SessionLog, SessionReader
from topdress.log.summary import format_text, summarise

CONFIG = "[machine]\nwidth_m = 3.6\nkg_per_rev_upper = 0.3\nkg_per_rev_lower = 0.2\n"


def row(t: float, v: float, source: str, rpm_up: float, rpm_lo: float, faults: int = 0) -> StateRow:
    # Measured upper = target; measured lower 5 % below target.
    return StateRow(
        t, 45.0, 126.0, v, v, v, source, 1.0, 0.8, 150.0, 100.0,
        rpm_up, rpm_lo, rpm_up, rpm_lo * 0.95, 3000.0, 3000.0, faults,
    )  # fmt: skip


def write_run(directory: Path) -> Path:
    """100 s at 7.2 km/h (2 m/s), 10 Hz: eq. 4 gives R = 3.6*150*7.2/(600*0.3) = 21.6 r/min
    upper and 3.6*100*7.2/(600*0.2) = 21.6 r/min lower. Then 10 s standing still, not metering,
    GNSS lost; then a 5 s hole in the log; then 1 s more standing."""
    with SessionLog.create(directory, CONFIG) as log:
        for i in range(1000):
            log.state(row(50.0 + i * 0.1, 7.2, "gnss" if i >= 200 else "wheel", 21.6, 21.6))
        for i in range(100):
            log.state(row(150.0 + i * 0.1, 0.0, "wheel", 0.0, 0.0, faults=0x02))
        for i in range(11):
            log.state(row(165.0 + i * 0.1, 0.0, "wheel", 0.0, 0.0))
    return log.path


def test_summary_worked_values(tmp_path: Path) -> None:
    with SessionReader(write_run(tmp_path)) as reader:
        s = summarise(reader)
    assert s.state_rows == 1111
    assert s.duration_s == pytest.approx(116.0)
    assert s.distance_m == pytest.approx(200.0)
    assert s.metering_distance_m == pytest.approx(200.0)
    assert s.area_ha == pytest.approx(200.0 * 3.6 / 10_000)
    up, lo = s.layers["upper"], s.layers["lower"]
    # 21.6 r/min for 100 s = 36 rev; x 0.3 kg = 10.8 kg; over 0.072 ha = 150 kg/ha.
    assert up.applied_kg == pytest.approx(10.8)
    assert up.applied_kg_ha == pytest.approx(150.0)
    assert up.rate_error_pct == pytest.approx(0.0, abs=1e-9)
    assert lo.target_kg == pytest.approx(7.2)
    assert lo.applied_kg_ha == pytest.approx(95.0)
    assert lo.rate_error_pct == pytest.approx(-5.0)
    # The standing rows 150.0..159.9 count 9.9 s: the 5.1 s to 165.0 is a gap.
    assert s.source_s["wheel"] == pytest.approx(20.0 + 9.9 + 1.0)
    assert s.source_s["gnss"] == pytest.approx(80.0)
    assert s.faults_s == {"GNSS_LOST": pytest.approx(9.9)}
    assert s.gaps == 1 and s.gap_s == pytest.approx(5.1)


def test_summary_of_an_empty_session_has_no_rate_error(tmp_path: Path) -> None:
    log = SessionLog.create(tmp_path, CONFIG)
    log.close()
    with SessionReader(log.path) as reader:
        s = summarise(reader)
    assert s.duration_s == 0.0 and s.distance_m == 0.0 and s.area_ha == 0.0
    assert s.layers["upper"].rate_error_pct is None
    assert s.layers["upper"].applied_kg_ha is None


def test_summary_command_text_and_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = write_run(tmp_path)
    assert main(["log", "summary", str(path)]) == 0
    text = capsys.readouterr().out
    assert "distance         200.0 m" in text
    assert (
        "upper layer      applied 10.80 kg (150.0 kg/ha), target 10.80 kg, rate error +0.0 %"
        in text
    )
    assert "rate error -5.0 %" in text
    assert "GNSS_LOST 9.9 s" in text
    assert main(["log", "summary", str(path), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["layers"]["lower"]["applied_kg"] == pytest.approx(6.84)
    assert data["log_meta"]["dropped"] == "0"


def test_start_and_end_are_the_receivers_utc_not_the_pcs_clock(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # An 85 s run logged while the PC's clock was set back a day: its log said it ended 23 h
    # after it started (created and closed from the PC's clock).
    import topdress.log.session as session

    class Jumping(session.datetime):  # type: ignore[name-defined,misc]
        calls = 0

        @classmethod
        def now(cls, tz: object = None) -> session.datetime:  # type: ignore[name-defined]
            cls.calls += 1
            return (
                session.datetime(2020, 1, 1, tzinfo=session.UTC)
                if cls.calls > 1
                else (session.datetime(2026, 5, 28, 12, 0, tzinfo=session.UTC))
            )

    monkeypatch.setattr(session, "datetime", Jumping)
    utc0 = 1_780_000_000.0
    with SessionLog.create(tmp_path, CONFIG) as log:
        for i in range(851):
            r = row(50.0 + i * 0.1, 7.2, "gnss", 21.6, 21.6)
            log.state(replace(r, utc=utc0 + i * 0.1, utc_source="gnss"))
    with SessionReader(log.path) as reader:
        assert reader.meta["start_utc"] == "2026-05-28T20:26:40.000+00:00"
        assert reader.meta["closed_utc"] == "2026-05-28T20:28:05.000+00:00"
        s = summarise(reader)
    assert s.start_utc == utc0 and s.end_utc == pytest.approx(utc0 + 85.0)
    assert "2026-05-28 20:26:40 to 2026-05-28 20:28:05 UTC" in format_text(s)
