"""Events in the session log: what the terminal writes as it happens (virtual time), the round
trip, version-1 files, the PIN never written, export, summary and an abrupt end. Run as a
script, this file is a writer that is killed."""

from __future__ import annotations

import itertools
import json
import logging
import math
import os
import signal
import sqlite3
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from test_operator import drive, make_rig, post, stand, straight
from topdress.cli.main import main
from topdress.config import DEFAULT_TOML
from topdress.errors import LogError
from topdress.log.model import LogEvent, StateRow
from topdress.log.session import SCHEMA_VERSION, SessionLog, SessionReader
from topdress.log.summary import summarise
from topdress.view import commands as op

PIN = "80412957"  # a value no other part of a session holds


def _row(t: float, faults: int = 0) -> StateRow:
    return StateRow(t, None, None, None, 0.0, 0.0, "wheel", None, None, *[0.0] * 8, faults)


def _events(path: Path) -> list[LogEvent]:
    with SessionReader(path) as reader:
        return list(reader.events())


def test_events_round_trip_in_time_order_with_their_details(tmp_path: Path) -> None:
    written = [
        LogEvent(12.5, "operator.start", {"was": "stopped"}),
        LogEvent(12.6, "manual.set", {"mode": "fixed", "upper_kg_ha": 200.0, "lower_kg_ha": 0.0}),
        LogEvent(13.0, "fault.changed", {"faults": 24, "was": 0, "set": ["UPPER_BLOCKED"]}),
        LogEvent(14.25, "calibration.catch", {"kg_per_rev": 0.2987, "layer": "lower"}),
        LogEvent(15.0, "operator.stop", {"was": "running"}),
    ]
    with SessionLog.create(tmp_path, "[log]\n") as log:
        log.state(_row(12.4))
        for ev in written:
            log.event(ev)
        log.state(_row(12.7))
    assert (log.errors, log.dropped, log.lost) == (0, 0, 0)
    with SessionReader(log.path) as reader:
        assert reader.version == SCHEMA_VERSION == 2
        assert list(reader.events()) == written
        assert reader.event_counts() == {
            "calibration.catch": 1,
            "fault.changed": 1,
            "manual.set": 1,
            "operator.start": 1,
            "operator.stop": 1,
        }
        assert reader.count("event") == 5 and reader.count("state") == 2
    # stored as the kind and a JSON object: no sentence
    conn = sqlite3.connect(log.path)
    kind, detail = conn.execute(
        "SELECT kind, detail FROM event WHERE kind = 'manual.set'"
    ).fetchone()
    conn.close()
    assert (kind, json.loads(detail)) == ("manual.set", dict(written[1].detail))


def test_an_unknown_kind_or_a_detail_json_cannot_hold_is_counted_not_raised(
    tmp_path: Path,
) -> None:
    with SessionLog.create(tmp_path, "[log]\n") as log:
        log.event(LogEvent(1.0, "operator.launch", {}))
        log.event(LogEvent(2.0, "setting.changed", {"key": "speed.mode", "new": math.nan}))
        log.event(LogEvent(3.0, "setting.changed", {"key": "log.dir", "new": Path("/x")}))
        log.event(LogEvent(4.0, "operator.pause", {"was": "running"}))
    assert log.dropped == 3 and log.errors == 3
    assert _events(log.path) == [LogEvent(4.0, "operator.pause", {"was": "running"})]


_V1_SCHEMA = """
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE raw (
    id INTEGER PRIMARY KEY, t REAL NOT NULL,
    kind TEXT NOT NULL CHECK (kind IN ('nmea', 'crop', 'can_rx', 'can_tx')),
    line TEXT, can_id INTEGER, data BLOB
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
PRAGMA user_version = 1;
"""


def _v1_file(path: Path) -> Path:
    """A session file as version 1 of the schema wrote it: no event table."""
    conn = sqlite3.connect(path)
    conn.executescript(_V1_SCHEMA)
    conn.executemany(
        "INSERT INTO meta VALUES (?, ?)",
        [("config_toml", "[machine]\nwidth_m = 3.6\n"), ("closed_utc", "2026-05-01T08:00:00")],
    )
    rows = [(10.0 + 0.1 * i, 7.2, 7.2, "gnss", 20.0, 20.0, 0) for i in range(11)]
    conn.executemany(
        "INSERT INTO state (t, v_wheel_kmh, v_kmh, source, rate_kg_ha_upper, rate_kg_ha_lower,"
        " target_rpm_upper, target_rpm_lower, meter_rpm_upper, meter_rpm_lower,"
        " fan_rpm_upper, fan_rpm_lower, faults) VALUES (?, ?, ?, ?, 150, 150, ?, ?, ?, ?, 0, 0, ?)",
        [(t, w, v, s, a, b, a, b, f) for t, w, v, s, a, b, f in rows],
    )
    conn.commit()
    conn.close()
    return path


def test_a_version_1_file_reads_with_no_events(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _v1_file(tmp_path / "old.sqlite")
    with SessionReader(path) as reader:
        assert reader.version == 1
        assert list(reader.events()) == [] and reader.event_counts() == {}
        assert reader.count("event") == 0
        assert len(list(reader.states())) == 11
        s = summarise(reader)
    assert s.duration_s == pytest.approx(1.0) and s.distance_m == pytest.approx(2.0)
    assert s.schema == 1 and s.events == {} and s.actions == []
    assert main(["log", "summary", str(path)]) == 0
    assert "none recorded (session schema 1" in capsys.readouterr().out
    out = tmp_path / "ev.ndjson"
    assert main(["log", "export", str(path), "--log-events", str(out)]) == 0
    assert out.read_text() == ""
    assert "0 logged events (a version-1 session file" in capsys.readouterr().out


def test_a_newer_schema_is_refused_naming_its_version(tmp_path: Path) -> None:
    path = _v1_file(tmp_path / "new.sqlite")
    conn = sqlite3.connect(path)
    conn.execute("PRAGMA user_version = 3")
    conn.close()
    with pytest.raises(LogError, match="session schema 3, this software reads 1 to 2"):
        SessionReader(path)


def _session_bytes(path: Path) -> bytes:
    return b"".join(
        p.read_bytes() for p in (path, Path(f"{path}-wal"), Path(f"{path}-shm")) if p.exists()
    )


def test_the_pin_is_never_written_only_its_key(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG)
    config = tmp_path / "terminal.toml"
    config.write_text(DEFAULT_TOML, encoding="utf-8")
    session = SessionLog.create(tmp_path / "logs", DEFAULT_TOML)
    rig = make_rig(drive(stand(30.0)), session=session)
    rig.term.desk.settings.config_path = config
    try:
        rig.run(2.0)
        res = post(rig, op.ApplySettings("display", {"host": "0.0.0.0", "pin": PIN}))
        assert res.ok, res.message
        assert rig.term.cfg.display.pin == PIN  # in force (at the next start) and in the file
        assert PIN in config.read_text()
        # and an event built by hand with the value: the writer masks it all the same
        session.event(LogEvent(2.5, "setting.changed", {"key": "display.pin", "new": PIN}))
        rig.run(4.0)
        assert session.sync()
        assert PIN.encode() not in _session_bytes(session.path)  # the file and its WAL
    finally:
        rig.close()
    assert PIN.encode() not in _session_bytes(session.path)
    assert PIN not in caplog.text
    changed = [e for e in _events(session.path) if e.kind == "setting.changed"]
    assert [(e.t, dict(e.detail)) for e in changed] == [
        (2.0, {"key": "display.host", "old": "127.0.0.1", "new": "0.0.0.0"}),
        (2.0, {"key": "display.pin", "old": "***", "new": "***"}),
        (2.5, {"key": "display.pin", "old": "***", "new": "***"}),
    ]


def _kinds(events: list[LogEvent], *kinds: str) -> list[tuple[float, str, dict[str, Any]]]:
    return [(round(e.t, 3), e.kind, dict(e.detail)) for e in events if e.kind in kinds]


def test_operator_actions_are_logged_when_they_happen(tmp_path: Path) -> None:
    session = SessionLog.create(tmp_path, DEFAULT_TOML)
    rig = make_rig(drive(stand(2.0), straight(8.0, 300.0)), session=session)
    try:
        rig.run(3.0)
        assert post(rig, op.Start()).ok  # posted at 3.0 s
        rig.run(10.0)
        assert post(rig, op.SetManual("fixed", upper_kg_ha=180.0, lower_kg_ha=90.0)).ok
        assert post(rig, op.Pause()).ok  # at 10.2 s
        assert not post(rig, op.Pause()).ok  # refused: no event
        assert post(rig, op.Start()).message == "resumed"  # at 10.4 s
        assert post(rig, op.SetManual("percent", percent=-20.0)).ok
        assert post(rig, op.SetManual("off")).ok
        rig.run(14.0)
        assert post(rig, op.Stop()).ok  # at 14.0 s
        rig.run(15.0)
    finally:
        rig.close()
    events = _events(session.path)
    ops = ("operator.start", "operator.stop", "operator.pause", "manual.set", "manual.off")
    assert _kinds([e for e in events if e.t > 0], *ops) == [
        (3.0, "operator.start", {"was": "stopped"}),
        (10.0, "manual.set", {"mode": "fixed", "upper_kg_ha": 180.0, "lower_kg_ha": 90.0}),
        (10.2, "operator.pause", {"was": "running"}),
        (10.6, "operator.start", {"was": "paused"}),
        (10.8, "manual.set", {"mode": "percent", "percent": -20.0}),
        (11.0, "manual.off", {}),
        (14.0, "operator.stop", {"was": "running"}),
    ]
    # the state rows agree: the meters turn only between start and stop, none while paused
    with SessionReader(session.path) as reader:
        rows = list(reader.states())
    turning = [r.t for r in rows if r.meter_rpm_upper > 1.0]
    assert turning and 3.0 < turning[0] < 8.0 and turning[-1] < 15.0
    assert not any(10.4 < r.t < 10.6 and r.rate_kg_ha_upper > 0 for r in rows)
    # export and summary carry them
    out = tmp_path / "what.ndjson"
    assert main(["log", "export", str(session.path), "--log-events", str(out)]) == 0
    lines = [json.loads(x) for x in out.read_text().splitlines()]
    assert [(x["t"], x["kind"], x["detail"]) for x in lines] == [
        (e.t, e.kind, dict(e.detail)) for e in events
    ]
    with SessionReader(session.path) as reader:
        s = summarise(reader)
    assert s.events["operator.start"] == 3  # the headless start at 0 s, start, resume
    assert s.events["manual.set"] == 2 and s.events["operator.stop"] == 1
    assert [(round(a.t_s, 3), a.kind) for a in s.actions][-3:] == [
        (10.8, "manual.set"),
        (11.0, "manual.off"),
        (14.0, "operator.stop"),
    ]


def test_links_alarms_faults_and_a_calibration_are_logged(tmp_path: Path) -> None:
    session = SessionLog.create(tmp_path, DEFAULT_TOML)
    rig = make_rig(drive(stand(40.0)), session=session)
    try:
        rig.run(3.0)
        rig.ecu_silent = True  # its frames stop reaching the terminal at 3.0 s
        rig.run(6.0)
        rig.ecu_silent = False
        rig.run(8.0)
        assert post(rig, op.AckAlarm()).message == "1 acknowledged"  # at 8.0 s
        assert post(rig, op.StartFanCheck(seconds=5.0)).ok
        rig.run(16.0)
        cal = rig.term.snapshot.calibration
        assert cal is not None and cal.step == "done"
    finally:
        rig.close()
    events = _events(session.path)
    timeout = rig.cfg.can.ecu_timeout_s
    lost = _kinds(events, "link.lost", "link.restored", "alarm.raised", "alarm.acked")
    (t_lost, *_), (t_alarm, *_), (t_back, _, back), (t_ack, *_) = lost
    assert [k for _, k, _ in lost] == ["link.lost", "alarm.raised", "link.restored", "alarm.acked"]
    assert lost[0][2] == {"link": "ecu", "state": "lost"} and lost[1][2] == {"name": "ecu_lost"}
    assert 3.0 + timeout - 0.2 <= t_lost <= 3.0 + timeout + 0.2 and t_alarm == t_lost
    assert 6.0 <= t_back <= 6.2 and back["link"] == "ecu"
    assert back["lost_s"] == pytest.approx(t_back - t_lost, abs=1e-3)
    assert t_ack == 8.0 and lost[3][2] == {"name": "ecu_lost"}
    # every change of the fault word in the state rows (ECU heard) is one event, same time
    with SessionReader(session.path) as reader:
        rows = [r for r in reader.states() if r.source != "none"]
    changes = [(r.t, r.faults) for a, r in itertools.pairwise(rows) if r.faults != a.faults]
    faults = [(e.t, e.detail["faults"]) for e in events if e.kind == "fault.changed"]
    assert changes and set(changes) <= set(faults)
    for e in events:
        if e.kind == "fault.changed":
            d = e.detail
            assert d["faults"] == d["was"] ^ sum(1 << _bit(n) for n in d["set"] + d["cleared"])
    (fan,) = [e for e in events if e.kind == "calibration.fan"]
    assert dict(fan.detail) == cal.result and fan.detail["upper_ok"] == 1.0
    assert 13.0 <= fan.t <= 13.6  # 5 s of fans after the start at 8.2 s


def _bit(name: str) -> int:
    from topdress.protocol import Fault

    return int(Fault[name]).bit_length() - 1


def test_catch_and_wheel_results_are_logged_and_applying_one_is_a_setting_change(
    tmp_path: Path,
) -> None:
    session = SessionLog.create(tmp_path, DEFAULT_TOML)
    rig = make_rig(drive(stand(2.0), straight(3.5, 40.0), stand(60.0)), session=session)
    try:
        rig.run(1.0)
        assert post(rig, op.StartWheelCal(40.0)).ok
        rig.run(50.0)
        odo = rig.world.tractor.odometer  # the tape measure
        assert post(rig, op.FinishWheelCal(distance_m=odo)).ok  # at 50.0 s
        wheel = rig.term.snapshot.calibration
        assert post(rig, op.CloseCalibration(apply=True), settle_s=0.5).ok
        assert post(rig, op.StartCatchTest("upper", revolutions=5.0, meter_rpm=20.0)).ok
        rig.run(75.0)
        assert post(rig, op.FinishCatchTest(1.5)).ok
        catch = rig.term.snapshot.calibration
        rig.run(76.0)
    finally:
        rig.close()
    assert wheel is not None and catch is not None
    events = _events(session.path)
    (w,) = [e for e in events if e.kind == "calibration.wheel"]
    assert w.t == 50.0 and dict(w.detail) == {**wheel.result, "distance_m": odo}
    assert w.detail["radius_m"] == pytest.approx(odo / (2 * math.pi * w.detail["revolutions"]))
    (radius,) = [e for e in events if e.kind == "setting.changed"]
    assert radius.detail == {
        "key": "machine.wheel_radius_m",
        "old": 0.0615,
        "new": wheel.result["radius_m"],
    }
    (c,) = [e for e in events if e.kind == "calibration.catch"]
    assert c.detail == {**catch.result, "layer": "upper"} and c.detail["weighed_kg"] == 1.5
    assert 5.0 <= c.detail["revolutions"] < 5.3  # as the ECU counted them
    assert c.detail["kg_per_rev"] == pytest.approx(1.5 / c.detail["revolutions"], rel=1e-9)


def writer(directory: str) -> None:
    """An event, then a state row, committed; then the process is killed (no close)."""
    log = SessionLog.create(directory, "[log]\n", commit_period_s=60.0)
    log.event(LogEvent(7.25, "operator.stop", {"was": "running"}))
    log.state(_row(7.3))
    assert log.sync()
    print("committed", flush=True)
    os.kill(os.getpid(), signal.SIGKILL)


def test_an_event_written_just_before_an_abrupt_end_is_readable(tmp_path: Path) -> None:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    proc = subprocess.run(
        [sys.executable, __file__, str(tmp_path)], capture_output=True, text=True, env=env
    )
    assert proc.returncode == -signal.SIGKILL and proc.stdout == "committed\n"
    (path,) = tmp_path.glob("*.sqlite")
    assert Path(f"{path}-wal").exists()  # never checkpointed: the rows are in the WAL only
    with SessionReader(path) as reader:
        assert "closed_utc" not in reader.meta
        assert list(reader.events()) == [LogEvent(7.25, "operator.stop", {"was": "running"})]
        assert [r.t for r in reader.states()] == [7.3]


if __name__ == "__main__":
    writer(sys.argv[1])
