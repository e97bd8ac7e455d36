"""A whole session from the simulator, through the command line: the terminal-side loop logs a
Table 2 drive (8.0 km/h, 40 m) into a session file; `topdress log summary` is checked against
the simulator's ground truth, and `log export` + `replay` give the speeds the ECU reported."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from topdress import protocol
from topdress.cli.main import main
from topdress.config import default_config
from topdress.gnss.nmea import NmeaDecoder
from topdress.gnss.tracker import GnssSpeedTracker
from topdress.log.rows import state_row
from topdress.log.session import SessionLog
from topdress.sim.tractor import Drive
from topdress.sim.world import SimConfig, Truth, World
from topdress.view.snapshot import Snapshot, ecu_values

RATE = (180.0, 150.0)


def record(directory: Path) -> tuple[Path, Truth]:
    """Log the drive as the terminal does; returns the session file and the final truth."""
    cfg = default_config()
    world = World(SimConfig(), seed=4, drive=Drive.paper_run(8.0))
    decoder = NmeaDecoder()
    tracker = GnssSpeedTracker(cfg.gnss.rmc_timeout_s, cfg.gnss.stale_s)
    latest: dict[type, object] = {}
    with SessionLog.create(directory, "") as log:
        for n in range(4500):
            out = world.step()
            t = 50.0 + out.t_s
            for frame in out.can:
                log.raw("can_rx", t, frame)
                decoded = protocol.decode(frame)
                latest[type(decoded)] = decoded
            for line in out.nmea:
                log.raw("nmea", t, line)
                tracker.update(t, decoder.decode(line))
            for line in out.crop:
                log.raw("crop", t, line)
            if n % 50 == 0:
                msg = protocol.encode_command(True, 3000, *RATE, tracker.current(t))
                log.raw("can_tx", t, (msg.arbitration_id, bytes(msg.data)))
                world.deliver_can(msg)
            if n % 10 == 9:
                pos = tracker.position
                log.state(
                    state_row(
                        t,
                        Snapshot(
                            **ecu_values(
                                latest.get(protocol.EcuStatus),  # type: ignore[arg-type]
                                latest.get(protocol.EcuDiag),  # type: ignore[arg-type]
                                latest.get(protocol.EcuSpeeds),  # type: ignore[arg-type]
                                latest.get(protocol.EcuTargets),  # type: ignore[arg-type]
                            ),
                            lat=None if pos is None else pos.lat,
                            lon=None if pos is None else pos.lon,
                            rate_kg_ha=RATE,
                        ),
                    )
                )
    assert log.errors == 0 and log.dropped == 0
    return log.path, world.truth


def test_summary_matches_the_simulated_truth(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path, truth = record(tmp_path)
    assert main(["log", "summary", str(path), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["duration_s"] == pytest.approx(44.9, abs=0.01)
    # Distance from the selected speed against the true odometer (the wheel under-reads by
    # its slip while it is the source; GNSS is within 0.1 m/s).
    assert s["distance_m"] == pytest.approx(truth.odometer_m, rel=0.03)
    for i, layer in enumerate(("upper", "lower")):
        true_kg = truth.applied_kg[i] + truth.in_flight_kg[i]
        assert s["layers"][layer]["applied_kg"] == pytest.approx(true_kg, rel=0.03)
        assert abs(s["layers"][layer]["rate_error_pct"]) < 5.0
    assert s["source_s"]["gnss"] > 10.0 and s["source_s"]["wheel"] > 5.0
    assert s["raw_inputs"]["nmea"] > 0 and s["raw_inputs"]["crop"] > 0
    assert s["log_meta"]["errors"] == "0"


def test_export_and_replay_from_the_command_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path, _ = record(tmp_path)
    events, state_csv, replayed = (tmp_path / n for n in ("e.ndjson", "s.csv", "r.csv"))
    assert main(["log", "export", str(path), "--events", str(events), "--csv", str(state_csv)]) == 0
    assert main(["replay", str(events), "--speed-mode", "paper", "--out", str(replayed)]) == 0
    assert "89 speed updates" in capsys.readouterr().out
    with replayed.open() as f:
        rows = list(csv.DictReader(f))
    with state_csv.open() as f:
        logged = list(csv.DictReader(f))
    # The logged state (EcuSpeeds at 0.01 km/h, EcuDiag) 100 ms after each replayed update:
    # the wheel speed and the source change only at updates, so they must agree (the replay's
    # wheel counts are interpolated between EcuDiag frames). The GNSS speed is not compared
    # here: the command sent right after an update has already changed it in the log.
    by_t = {round(float(r["t"]), 1): r for r in logged}
    matched = 0
    for r in rows:
        later = by_t.get(round(float(r["t"]) + 0.1, 1))
        if later is None:
            continue
        matched += 1
        assert float(r["v_wheel_kmh"]) == pytest.approx(float(later["v_wheel_kmh"]), abs=0.03)
        if r["cv_pct"] and abs(float(r["cv_pct"]) - 4.2) < 0.1:
            continue  # a CV at the threshold may fall either side with interpolated counts
        assert r["source"] == later["source"], r["t"]
        if r["source"] == "wheel":
            assert float(r["v_kmh"]) == pytest.approx(float(later["v_kmh"]), abs=0.03)
    assert matched >= 80
