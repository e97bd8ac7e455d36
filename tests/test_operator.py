"""The operator's commands against the simulated machine (World: plant + C ECU core) on virtual
time: start/stop/pause, manual rate, alarms, counters, the calibration wizards and settings."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from test_terminal import VirtualRig
from topdress import protocol
from topdress.config import DEFAULT_TOML, loads_config
from topdress.config_edit import section_version
from topdress.crop.rate import build_rate_model
from topdress.ecu import meter_target_rpm
from topdress.gnss.nmea import make_sentence
from topdress.log.session import SessionLog, SessionReader
from topdress.sim.actuators import MeterParams
from topdress.sim.tractor import Drive, Segment
from topdress.sim.world import SimConfig, StepOutput, World
from topdress.terminal.leadcal import LeadCal
from topdress.view import commands as op
from topdress.view.commands import CommandResult

# the paper's rule: the operator's "why" line and the alarms below are written in its terms
CFG = loads_config(DEFAULT_TOML.replace('mode = "fused"', 'mode = "paper"', 1))


def drive(*segments: Segment) -> Drive:
    return Drive(list(segments))


def stand(seconds: float) -> Segment:
    return Segment("stop", duration_s=seconds)


def straight(kmh: float, m: float) -> Segment:
    return Segment("straight", speed_kmh=kmh, length_m=m)


def make_rig(d: Drive, autostart: bool = False, **kw: Any) -> VirtualRig:
    """A rig whose terminal waits for the operator (autostart False) unless told."""
    rig = VirtualRig(CFG, d, **kw)
    rig.term.desk.op.state = op.RUNNING if autostart else op.STOPPED
    return rig


def post(rig: VirtualRig, command: Any, settle_s: float = 0.2) -> CommandResult:
    """The answer, its message in English (as the program log writes it)."""
    fut = rig.term.post(command)
    rig.run(rig.world.t_s + settle_s)
    assert fut.done()
    result = fut.result()
    return replace(result, message=str(result.message))


def post_opening(rig: VirtualRig, command: Any, timeout_s: float = 10.0) -> CommandResult:
    """The answer to a command that opens a CAN bus: the bus opens in a thread of its own, on
    the wall clock, while the loop goes on (virtual time runs on meanwhile)."""
    import time as wall

    fut = rig.term.post(command)
    deadline = wall.monotonic() + timeout_s
    while not fut.done() and wall.monotonic() < deadline:
        rig.run(rig.world.t_s + 0.1)
        wall.sleep(0.005)
    assert fut.done()
    result = fut.result()
    return replace(result, message=str(result.message))


def snap_at(rig: VirtualRig, t: float) -> Any:
    return min(rig.snapshots, key=lambda ts: abs(ts[0] - t))[1]


def test_meters_wait_for_start_then_stop_is_one_command() -> None:
    rig = make_rig(drive(stand(2.0), straight(8.0, 200.0)))
    try:
        rig.run(8.0)
        s = rig.term.snapshot
        assert s.operator == "stopped" and not s.running
        assert s.v_kmh > 7.0 and s.meter_rpm == (0.0, 0.0)  # moving, nothing metered
        assert s.rate_model_kg_ha[0] > 0 and s.rate_kg_ha == (0.0, 0.0)
        assert post(rig, op.Start()).ok
        rig.run(16.0)
        s = rig.term.snapshot
        assert s.operator == "running" and s.running
        assert s.meter_rpm[0] == pytest.approx(s.target_rpm[0], rel=0.05)
        t_stop = rig.world.t_s
        assert post(rig, op.Stop(), settle_s=0.05).ok
        # the stop goes out at once, not at the next command period
        assert not rig.world.ecu.state.running
        assert rig.world.t_s - t_stop < 0.06
        rig.run(t_stop + 1.0)
        assert rig.term.snapshot.operator == "stopped" and not rig.term.snapshot.running
    finally:
        rig.close()
    assert any("operator: started" in e for _, e in rig.events)


def test_pause_keeps_the_fans_and_start_resumes() -> None:
    rig = make_rig(drive(straight(8.0, 300.0)), autostart=True)
    try:
        rig.run(10.0)
        assert rig.term.snapshot.meter_rpm[0] > 10.0
        assert post(rig, op.Pause()).ok
        rig.run(14.0)
        s = rig.term.snapshot
        assert s.operator == "paused" and s.running  # the ECU stays started
        assert s.rate_kg_ha == (0.0, 0.0) and s.meter_rpm[0] < 0.5
        assert min(s.fan_rpm) > 2500.0  # fans kept
        assert "FAN_LOW" not in str(protocol.Fault(s.faults))
        assert not post(rig, op.Pause()).ok  # only running meters pause
        assert post(rig, op.Start()).message == "resumed"
        rig.run(20.0)
        assert rig.term.snapshot.meter_rpm[0] > 10.0
    finally:
        rig.close()


def test_manual_fixed_and_percent_rates_are_commanded_and_shown() -> None:
    rig = make_rig(drive(straight(8.0, 400.0)), autostart=True)
    m = CFG.machine
    try:
        rig.run(8.0)
        res = post(rig, op.SetManual("fixed", upper_kg_ha=200.0, lower_kg_ha=100.0))
        assert res.ok and res.message == "rate: manual 200.0/100.0 kg/ha"
        rig.run(16.0)
        s = rig.term.snapshot
        assert s.manual == op.ManualView("fixed", 200.0, 100.0, 0.0)
        assert s.rate_kg_ha == (200.0, 100.0)
        for i, kg_rev in enumerate((m.kg_per_rev_upper, m.kg_per_rev_lower)):
            eq4 = meter_target_rpm(m.width_m, s.rate_kg_ha[i], s.v_kmh, kg_rev)
            assert s.target_rpm[i] == pytest.approx(eq4, rel=0.03)
        # the rate actually applied, from the measured metering speed (eq. 4 inverted)
        assert s.applied_kg_ha[0] == pytest.approx(200.0, rel=0.05)
        assert s.applied_kg_ha[1] == pytest.approx(100.0, rel=0.05)
        assert len(s.ndvi_per_sensor) == 4 and all(0.2 < x < 1.0 for x in s.ndvi_per_sensor if x)
        assert s.ndvi_sensors == pytest.approx(
            sum(x for x in s.ndvi_per_sensor if x) / sum(1 for x in s.ndvi_per_sensor if x)
        )
        assert (s.cv_threshold_pct, s.switch_speed_kmh) == (4.2, 6.0)
        why = str(s.speed_why)
        assert why.startswith("GNSS: CV ") and why.endswith(", GNSS 8.0 km/h > 6 km/h"), why
        assert post(rig, op.SetManual("percent", percent=20.0)).ok
        rig.run(17.0)
        s = rig.term.snapshot
        assert s.rate_kg_ha[0] == pytest.approx(s.rate_model_kg_ha[0] * 1.2, abs=0.01)
        bad = post(rig, op.SetManual("fixed", upper_kg_ha=700.0))
        assert not bad.ok and "upper_kg_ha" in bad.message
        assert rig.term.snapshot.manual.mode == "percent"  # unchanged
        assert post(rig, op.SetManual("off")).ok
        rig.run(18.0)
        s = rig.term.snapshot
        assert s.rate_kg_ha == s.rate_model_kg_ha
    finally:
        rig.close()
    texts = [e for _, e in rig.events]
    assert "operator: rate: manual +20 % on the planned rate" in texts


def test_off_rate_and_blocked_meters_raise_alarms_the_operator_acknowledges(
    tmp_path: Path,
) -> None:
    # upper: a motor too weak for its target (off rate); lower: jams at 12 s (blocked)
    sim = SimConfig(meter=(MeterParams(max_rpm=15.0), MeterParams(jammed_at_s=12.0)))
    session = SessionLog.create(tmp_path, DEFAULT_TOML)
    rig = make_rig(drive(straight(8.0, 400.0)), autostart=True, session=session)
    rig.world = World(sim, seed=3, drive=rig.world.drive)
    try:
        rig.run(20.0)
        # off rate: more than 10 % off its target for more than operator.off_rate_s (5 s)
        off = [
            t
            for t, s in rig.snapshots
            if s.target_rpm[0] >= 1.0
            and abs(s.meter_rpm[0] - s.target_rpm[0]) > 0.1 * s.target_rpm[0]
        ]
        alarms = {a.name: a for a in rig.term.snapshot.alarms}
        assert alarms["off_rate_upper"].since_s == pytest.approx(off[0] + 5.0, abs=0.15)
        assert alarms["off_rate_upper"].state == "active"
        assert alarms["blocked_lower"].state == "active"
        assert 13.0 < alarms["blocked_lower"].since_s < 13.6  # blocked_time_ms 1 s after the jam
        assert "off_rate_lower" not in alarms  # the ECU stopped it: target 0, not off rate
        assert post(rig, op.AckAlarm("blocked_lower")).ok
        states = {a.name: a.state for a in rig.term.snapshot.alarms}
        assert states["blocked_lower"] == "acked" and states["off_rate_upper"] == "active"
        assert not post(rig, op.AckAlarm("no_such")).ok
        # a stop clears the latched fault: the acknowledged alarm leaves; the other, gone,
        # stays as cleared until acknowledged
        post(rig, op.Stop(), settle_s=0.5)
        states = {a.name: a.state for a in rig.term.snapshot.alarms}
        assert "blocked_lower" not in states and states["off_rate_upper"] == "cleared"
        assert post(rig, op.AckAlarm()).message == "1 acknowledged"
        assert rig.term.snapshot.alarms == ()
    finally:
        rig.close()
    assert any(e.startswith("alarm: lower meter blocked") for _, e in rig.events)
    # the session log has each alarm with its time, an off-rate one with its figures
    with SessionReader(session.path) as reader:
        raised = {e.detail["name"]: e for e in reader.events() if e.kind == "alarm.raised"}
    off_rate = raised["off_rate_upper"]
    assert off_rate.t - rig.term._t0 == pytest.approx(alarms["off_rate_upper"].since_s, abs=0.01)
    assert off_rate.detail["rpm"] <= 15.5 and off_rate.detail["target"] > 17.0
    assert (off_rate.detail["pct"], off_rate.detail["s"]) == (10.0, 5.0)
    assert dict(raised["blocked_lower"].detail) == {"name": "blocked_lower"}


def test_counters_count_what_was_applied_and_persist(tmp_path: Path) -> None:
    session = SessionLog.create(tmp_path, DEFAULT_TOML)
    rig = make_rig(
        drive(stand(2.0), straight(8.0, 60.0), stand(5.0)), autostart=True, session=session
    )
    try:
        rig.run(40.0)
        truth = rig.world.truth
        s = rig.term.snapshot
        f = s.count_field
        assert f == replace(s.count_season, since=f.since)
        # distance worked: what the ECU metered over (the meters start after the fans spin up
        # and stop below min_work_speed_kmh)
        assert 0.9 * truth.odometer_m < f.distance_m < truth.odometer_m + 0.5
        assert f.area_ha == pytest.approx(f.distance_m * CFG.machine.width_m / 1e4, rel=1e-9)
        metered = [rig.world.meters[i].revolutions * 0.3 for i in (0, 1)]
        assert f.kg[0] == pytest.approx(metered[0], rel=0.03)
        assert f.kg[1] == pytest.approx(metered[1], rel=0.03)
        assert truth.applied_kg[0] + truth.in_flight_kg[0] == pytest.approx(metered[0], rel=0.01)
        assert post(rig, op.ResetCounter("field")).ok
        assert rig.term.snapshot.count_field.area_ha == 0.0
        assert rig.term.snapshot.count_season.area_ha == pytest.approx(f.area_ha)
        assert not post(rig, op.ResetCounter("year")).ok
    finally:
        rig.close()
    doc = json.loads((tmp_path / "counters.json").read_text())
    assert doc["field"]["area_ha"] == 0.0
    assert doc["season"]["kg"][0] == pytest.approx(f.kg[0], rel=1e-6)


def test_counters_file_damaged_is_kept_aside(tmp_path: Path) -> None:
    from topdress.terminal.counters import WorkCounters

    path = tmp_path / "counters.json"
    c = WorkCounters(path)
    c.add(0.5, (10.0, 5.0), 60.0, 1000.0)
    c.save()
    again = WorkCounters(path)
    assert again.view("season").kg == (10.0, 5.0) and again.error is None
    path.write_text('{"field": {"area_ha": 1.0}, "sea')
    broken = WorkCounters(path)
    assert broken.view("season").area_ha == 0.0
    assert broken.error is not None and "damaged" in broken.error
    assert (tmp_path / "counters.json.damaged").read_text().startswith('{"field"')
    assert not list(tmp_path.glob(".*.tmp"))


def test_periodic_counter_saves_do_not_hold_the_control_loop(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import threading

    from topdress.terminal import counters as mod

    disk = threading.Event()  # the disk's fsync, held until the test lets it finish
    writing = threading.Event()
    writers: list[str] = []
    real_write = mod.atomic_write

    def slow_write(path: Path, text: str) -> None:
        writers.append(threading.current_thread().name)
        writing.set()
        assert disk.wait(5.0)
        real_write(path, text)

    monkeypatch.setattr(mod, "atomic_write", slow_write)
    path = tmp_path / "counters.json"
    c = mod.WorkCounters(path)
    c.maybe_save(0.0)
    c.add(0.5, (10.0, 5.0), 60.0, 1000.0)
    c.maybe_save(mod.SAVE_PERIOD_S)  # returns while the disk still holds the write
    assert writing.wait(5.0)
    assert not path.exists() and writers == ["counters"]
    c.add(0.25, (5.0, 2.5), 30.0, 500.0)
    c.maybe_save(mod.SAVE_PERIOD_S + 1.0)  # not due yet: nothing more queued
    disk.set()
    c.save()  # the end of the run: waits for the background write, then writes the last
    assert json.loads(path.read_text())["season"]["kg"] == [15.0, 7.5]
    assert writers == ["counters", "MainThread"] and c.error is None


def test_a_counter_save_that_fails_is_said_and_tried_again(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from topdress.terminal import counters as mod

    path = tmp_path / "counters.json"
    c = mod.WorkCounters(path)
    c.add(0.5, (10.0, 5.0), 60.0, 1000.0)

    def full_disk(path: Path, text: str) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(mod, "atomic_write", full_disk)
    c.maybe_save(0.0)
    c.maybe_save(mod.SAVE_PERIOD_S)
    assert c._saver.wait()
    assert c.error is not None and "No space left on device" in c.error
    monkeypatch.undo()
    c.maybe_save(2 * mod.SAVE_PERIOD_S)  # still owed: written at the next period
    assert c._saver.wait()
    assert json.loads(path.read_text())["field"]["area_ha"] == 0.5


def _config_file(tmp_path: Path) -> Path:
    path = tmp_path / "terminal.toml"
    path.write_text(DEFAULT_TOML, encoding="utf-8")
    return path


def test_catch_test_standing_gives_kg_per_rev_and_applies_it(tmp_path: Path) -> None:
    true_kg_rev = 0.3
    path = _config_file(tmp_path)
    rig = make_rig(drive(stand(120.0)))
    rig.term.desk.settings.config_path = path
    try:
        rig.run(3.0)
        res = post(rig, op.StartCatchTest("lower", revolutions=10.0, meter_rpm=20.0))
        assert res.ok, res.message
        assert rig.term.snapshot.operator == "calibrating"
        assert not post(rig, op.Start()).ok  # no start during a calibration
        rig.run(20.0)
        cal = rig.term.snapshot.calibration
        assert cal is not None and cal.step == "running" and 0.3 < cal.progress < 0.9
        rig.run(40.0)
        cal = rig.term.snapshot.calibration
        assert cal is not None and cal.step == "weigh", cal.text
        revs = rig.world.meters[1].revolutions
        assert 10.0 <= revs < 10.3 and rig.world.meters[0].revolutions == 0.0
        assert rig.world.tractor.odometer == 0.0
        weighed = revs * true_kg_rev  # what the scale says
        weigh_text = str(cal.text)
        res = post(rig, op.FinishCatchTest(weighed))
        assert res.ok
        cal = rig.term.snapshot.calibration
        assert cal is not None and cal.result["kg_per_rev"] == pytest.approx(true_kg_rev, rel=2e-3)
        # the weigh step showed the revolutions the result divides by (the meter coasts after
        # the ECU's "done"), and the result is said: on the screen's answer and in the events
        assert f"{cal.result['revolutions']:.3f} revolutions" in weigh_text
        assert f"over {cal.result['revolutions']:.3f} rev" in str(res.message)
        assert any(e.startswith("operator: lower: 0.30") for _, e in rig.events)
        assert cal.key == "machine.kg_per_rev_lower"
        fut = rig.term.post(op.CloseCalibration(apply=True))
        rig.run(rig.world.t_s + 0.5)
        assert fut.result().ok, fut.result().message
        assert rig.world.ecu.params.kg_per_rev[1] == pytest.approx(true_kg_rev, abs=1e-4)
        assert rig.term.cfg.machine.kg_per_rev_lower == pytest.approx(cal.result["kg_per_rev"])
        assert rig.term.snapshot.operator == "stopped"
    finally:
        rig.close()
    assert (tmp_path / "terminal.toml.bak").read_text() == DEFAULT_TOML
    text = path.read_text()
    assert "# working width, m (6 rows x 0.60 m)" in text  # comments kept
    assert loads_config(text).machine.kg_per_rev_lower == pytest.approx(cal.result["kg_per_rev"])


def test_catch_test_aborts_when_the_machine_moves_and_weighing_then_is_refused() -> None:
    rig = make_rig(drive(stand(5.0), straight(3.0, 50.0)))
    try:
        rig.run(1.0)
        assert post(rig, op.StartCatchTest("upper", revolutions=50.0, meter_rpm=20.0)).ok
        rig.run(10.0)
        cal = rig.term.snapshot.calibration
        assert cal is not None and cal.step == "aborted" and "moving" in str(cal.text)
        assert rig.term.snapshot.meter_rpm[0] < 0.5
        assert not post(rig, op.FinishCatchTest(3.0)).ok
        assert post(rig, op.CloseCalibration()).message == "calibration closed, nothing changed"
    finally:
        rig.close()


def test_wheel_calibration_over_a_measured_run() -> None:
    rig = make_rig(drive(stand(2.0), straight(3.5, 40.0), stand(5.0)))
    try:
        rig.run(1.0)
        assert post(rig, op.StartWheelCal(40.0)).ok
        rig.run(60.0)
        odo = rig.world.tractor.odometer  # the tape measure
        assert odo == pytest.approx(40.0, abs=1.0)
        assert post(rig, op.FinishWheelCal(distance_m=odo)).ok
        cal = rig.term.snapshot.calibration
        assert cal is not None and cal.step == "done"
        revs = rig.world.wheel.revolutions
        r = cal.result
        assert r["revolutions"] == pytest.approx(revs, abs=0.01)
        # eq. 3 against the measured distance with the configured radius, through the C core
        want = abs(2 * math.pi * 0.0615 * r["revolutions"] - odo) / odo * 100.0
        assert r["slip_pct"] == pytest.approx(want, rel=1e-3)
        assert r["radius_m"] == pytest.approx(odo / (2 * math.pi * r["revolutions"]), rel=1e-6)
        assert r["gnss_distance_m"] == pytest.approx(odo, abs=1.0)
        assert 0.0 < r["slip_gnss_pct"] < 5.0
    finally:
        rig.close()


def test_fan_check_standing() -> None:
    rig = make_rig(drive(stand(60.0)))
    try:
        rig.run(1.0)
        assert post(rig, op.StartFanCheck(seconds=8.0)).ok
        rig.run(4.0)
        assert rig.term.snapshot.running and rig.term.snapshot.meter_rpm == (0.0, 0.0)
        rig.run(12.0)
        cal = rig.term.snapshot.calibration
        assert cal is not None and cal.step == "done", cal.text
        assert cal.result["upper_ok"] == 1.0 and cal.result["lower_ok"] == 1.0
        assert cal.result["upper_rpm"] == pytest.approx(3000.0, abs=100.0)
        assert 0.5 < cal.result["upper_to_min_s"] < 4.0
        rig.run(13.0)
        assert not rig.term.snapshot.running  # stopped again at the end
    finally:
        rig.close()


def _refuse_param(rig: VirtualRig, param_id: int) -> None:
    """The ECU refuses `param_id` as out of range (an older firmware with a narrower range):
    the frame never reaches the core, the answer is OutOfRange with the value in force."""
    world = rig.world
    deliver, step = world.deliver_can, world.step
    acks: list[tuple[int, bytes]] = []

    def deliver_can(frame: Any, now_us: int | None = None) -> int:
        if frame.arbitration_id == protocol.DEFAULT_IDS.param_set and frame.data[0] == param_id:
            raw = protocol.param(param_id).to_raw(world.ecu.params.get(param_id))
            acks.append(
                (
                    protocol.DEFAULT_IDS.param_ack,
                    bytes([param_id, 2, 0, 0]) + raw.to_bytes(4, "little"),
                )
            )
            return 0
        return deliver(frame, now_us)

    def wrapped() -> StepOutput:
        out = step()
        extra = list(acks)
        acks.clear()
        return replace(out, can=out.can + extra)

    world.deliver_can = deliver_can  # type: ignore[method-assign]
    world.step = wrapped  # type: ignore[method-assign]


def test_settings_to_the_ecu_acknowledged_saved_or_refused_and_put_back(tmp_path: Path) -> None:
    path = _config_file(tmp_path)
    rig = make_rig(drive(stand(60.0)))
    rig.term.desk.settings.config_path = path
    try:
        rig.run(2.0)
        bad = post(rig, op.ApplySettings("speed", {"cv_threshold_pct": 80.0}))
        assert not bad.ok and bad.errors == {"speed.cv_threshold_pct": "80.0 is outside 0.1..50"}
        res = post(rig, op.ApplySettings("speed", {"cv_threshold_pct": 5.0}))
        assert res.ok, res.message
        assert rig.world.ecu.params.cv_threshold_pct == pytest.approx(5.0)
        assert rig.term.cfg.speed.cv_threshold_pct == 5.0
        assert rig.term.snapshot.settings_state == {"speed.cv_threshold_pct": "ok"}
        assert rig.term.snapshot.cv_threshold_pct == 5.0
        assert "cv_threshold_pct = 5.0" in path.read_text()
        # refused by the ECU: the field is named and what it took of the change goes back
        _refuse_param(rig, 9)
        res = post(
            rig, op.ApplySettings("speed", {"cv_threshold_pct": 3.0, "switch_speed_kmh": 7.0})
        )
        assert not res.ok
        assert list(res.errors) == ["speed.switch_speed_kmh"]
        state = rig.term.snapshot.settings_state
        assert state["speed.cv_threshold_pct"] == "put back"
        assert state["speed.switch_speed_kmh"].startswith("refused: SwitchSpeed = 7: ")
        rig.run(rig.world.t_s + 0.5)
        assert rig.world.ecu.params.cv_threshold_pct == pytest.approx(5.0)  # put back
        assert rig.world.ecu.params.switch_speed_kmh == pytest.approx(6.0)
        assert rig.term.cfg.speed.cv_threshold_pct == 5.0
        assert "switch_speed_kmh = 7.0" not in path.read_text()
        # the ECU takes parameters only with the meters stopped
        post(rig, op.Start())
        res = post(rig, op.ApplySettings("speed", {"cv_threshold_pct": 4.0}))
        assert not res.ok and "stopped" in res.message
    finally:
        rig.close()


def test_live_settings_device_test_and_a_bus_that_cannot_be_opened(tmp_path: Path) -> None:
    rig = make_rig(drive(stand(60.0)))
    try:
        rig.run(3.0)
        assert post(rig, op.ApplySettings("rate", {"model": "table"})).message.endswith(
            "(not saved: no configuration file)"
        )
        assert rig.term.cfg.rate.model == "table"
        # a crop key that is not the port's: taken at once, the same source kept
        source = rig.term.crop
        assert post(rig, op.ApplySettings("crop", {"sensors": 2})).ok
        bad_before = rig.term.snapshot.counters["crop_bad"]
        rig.run(rig.world.t_s + 2.0)
        assert rig.term.crop is source
        assert len(rig.term.snapshot.ndvi_per_sensor) == 2
        assert rig.term.snapshot.counters["crop_bad"] > bad_before  # sensors 3 and 4 refused
        assert post(rig, op.ApplySettings("gnss", {"stale_s": 5.0})).ok
        assert rig.term.tracker.stale_s == 5.0 and rig.term.gnss is rig.gnss
        res = post_opening(rig, op.ApplySettings("can", {"interface": "no_such_interface"}))
        assert not res.ok and list(res.errors) == ["can.interface"]
        assert "no_such_interface" in res.errors["can.interface"]
        assert rig.term.cfg.can.interface == "virtual"
        # an slcan adapter that is not plugged in: said at every key changed, the old bus kept
        bus = rig.term.bus
        slcan = {"interface": "slcan", "channel": str(tmp_path / "ttyACM9")}
        slcan_options = {**slcan, "options": {"tty_baudrate": 115200}}
        res = post_opening(rig, op.ApplySettings("can", slcan_options))
        assert not res.ok
        assert list(res.errors) == ["can.interface", "can.channel", "can.options"]
        assert rig.term.bus is bus and rig.term.cfg.can.options == {}
        rig.gnss.emit(rig.world.t_s, make_sentence("GPGGA,,,,,,0,,,,,,,,"))
        gnss = post(rig, op.TestDevice("gnss")).data
        assert len(gnss) == 20
        assert any("km/h" in line.decoded for line in gnss)
        can_lines = post(rig, op.TestDevice("can")).data
        assert any(line.decoded.startswith("EcuStatus(") for line in can_lines)
        crop = post(rig, op.TestDevice("crop")).data
        decoded = {line.decoded.split(" NDVI")[0] for line in crop}
        # with crop.sensors = 2 now: sensors 1 and 2 read, 3 and 4 refused, each line said why
        assert {"sensor 1", "sensor 2", "not usable: sensor_id: '3' is not 1..2"} <= decoded
        assert not post(rig, op.TestDevice("radar")).ok
    finally:
        rig.close()


def test_a_can_change_where_no_ecu_answers_keeps_the_bus_in_use() -> None:
    # The new bus opens (here a virtual channel with nobody on it) while the ECU keeps being
    # commanded on the old one; nobody takes the parameters there: the change is refused.
    rig = make_rig(drive(straight(8.0, 200.0)), autostart=True)
    try:
        rig.run(4.0)
        assert rig.term.snapshot.ecu_link == "ok" and rig.world.ecu.state.running
        bus, t_change = rig.term.bus, rig.world.t_s
        res = post_opening(rig, op.ApplySettings("can", {"channel": "test-operator-nobody"}))
        assert not res.ok and list(res.errors) == ["can.channel"]
        assert res.message.startswith(
            "no ECU took its parameters on virtual:test-operator-nobody within 3 s"
        )
        assert rig.term.bus is bus and rig.term.cfg.can.channel != "test-operator-nobody"
        during = [s for t, s in rig.snapshots if t >= t_change]
        assert during and all(s.ecu_link == "ok" and s.running for s in during)
        assert rig.world.ecu.state.running  # never stopped for want of a command
    finally:
        rig.close()


def test_gnss_port_changed_while_running_is_reopened_on_the_new_device() -> None:
    import time as wall

    from topdress.gnss import sentences as nmea
    from topdress.sim.live import PtyPort

    port = PtyPort()
    rig = make_rig(drive(stand(30.0)))
    try:
        rig.run(2.0)
        old = rig.term.gnss
        res = post(rig, op.ApplySettings("gnss", {"port": port.path, "baud": 115200}))
        assert res.ok, res.message
        assert rig.term.gnss is not old and rig.term.gnss.name == f"serial:{port.path}"
        assert rig.term.cfg.gnss.port == port.path
        line = nmea.rmc("GN", 3600.0, True, 43.9, 125.3, 5.0 / 3.6, 90.0, "210526")
        deadline = wall.monotonic() + 5.0
        seen: list[Any] = []
        while not seen and wall.monotonic() < deadline:
            port.write(line.encode())
            wall.sleep(0.05)
            rig.run(rig.world.t_s + 0.1)
            seen = [
                x for x in post(rig, op.TestDevice("gnss"), 0.01).data if "5.00 km/h" in x.decoded
            ]
        assert seen and seen[-1].raw == line.strip()
        assert rig.term.link.command.gnss_kmh == pytest.approx(5.0, abs=0.01)
    finally:
        rig.close()
        port.close()


def test_a_command_is_served_before_a_flood_of_lines() -> None:
    rig = make_rig(drive(stand(10.0)), autostart=True)
    try:
        rig.run(1.0)
        for _ in range(400):
            rig.term.inbox.put(("nmea", rig.world.t_s, b"$GPGGA,garbage*00"))
        fut = rig.term.post(op.Stop())
        kind, t, payload = rig.term.inbox.get(timeout=0)
        assert kind == "op"  # ahead of the 400 lines queued before it
        rig.term.handle(kind, t, payload)
        assert fut.result(timeout=0).ok
        assert rig.term.desk.op.state == op.STOPPED
        assert rig.term.link.command.start is False
    finally:
        rig.close()


def test_lookahead_calibration_measures_meter_and_air_line_times(tmp_path: Path) -> None:
    """Standing with the fans on, the ECU runs the meter; the 'operator' presses seen 200 ms
    (their reaction) after the simulated product first lands. The wizard's two times add up
    to the simulated command-to-landing time and the air-line part to the plant's transport."""
    path = _config_file(tmp_path)
    rig = make_rig(drive(stand(200.0)))
    rig.term.desk.settings.config_path = path
    world = rig.world
    try:
        rig.run(2.0)
        res = post(rig, op.StartLeadCal("upper", trials=3, meter_rpm=20.0))
        assert res.ok, res.message
        assert not post(rig, op.LeadSeen()).ok  # nothing runs yet: the fans spin up first
        lag_ms: list[float] = []
        for k in range(3):
            # wait for the ECU to start this trial's meter, then for the product at the outlet
            t_cmd = None
            while t_cmd is None:
                rig.run(world.t_s + 0.01)
                w = rig.term.desk.wizard
                assert isinstance(w, LeadCal) and w.step == "running", w
                if len(w.done) == k and w._pause_until is None:
                    t_cmd = w._t_cmd
            landed0 = world.airlines[0].landed_kg
            rev0 = world.meters[0].revolutions
            while world.airlines[0].landed_kg == landed0:
                rig.run(world.t_s + 0.01)
            rig.run(world.t_s + 0.2)  # the operator's reaction
            # the plant's own meter delay: how far its turn is behind one that jumped at once
            rpm = world.meters[0].rpm
            lag_s = (world.t_s - t_cmd) - (world.meters[0].revolutions - rev0) / (rpm / 60.0)
            lag_ms.append(lag_s * 1000.0)
            seen = post(rig, op.LeadSeen(), settle_s=0.01)
            assert seen.ok, seen.message
            assert not post(rig, op.LeadSeen(), settle_s=0.01).ok  # one press per trial
        rig.run(world.t_s + 0.2)  # the next snapshot
        cal = rig.term.snapshot.calibration
        assert cal is not None and cal.step == "done", cal.text
        r = cal.result
        # the meter: its flow's delay, as the plant turned (10 ms steps)
        assert r["meter_ms"] == pytest.approx(sorted(lag_ms)[1], abs=15.0)
        # the air line: drop 50 ms + 1.5 m at 11 m/s at the nominal fan
        transport_ms = world.airlines[0].delay_s(CFG.machine.fan_rpm) * 1000.0
        assert transport_ms == pytest.approx(186.4, abs=0.1)
        assert r["airline_ms"] == pytest.approx(transport_ms, abs=40.0)
        assert world.tractor.odometer == 0.0
        meter_ms, airline_ms = round(r["meter_ms"]), round(r["airline_ms"])
        print(
            f"lead calibration: meter {r['meter_ms']:.1f} ms (plant {sorted(lag_ms)[1]:.1f}), "
            f"air line {r['airline_ms']:.1f} ms (plant {transport_ms:.1f})"
        )
        fut = rig.term.post(op.CloseCalibration(apply=True))
        rig.run(world.t_s + 0.5)
        assert fut.result().ok, fut.result().message
        assert rig.term.cfg.lookahead.meter_ms == meter_ms
        assert rig.term.cfg.lookahead.airline_ms == airline_ms
        assert rig.term.ndvi.lookahead_s == rig.term.cfg.lookahead.total_s
        # and the ECU has them: its look-ahead runs on the measured machine
        assert (world.ecu.params.lead_meter_ms, world.ecu.params.lead_air_ms) == (
            meter_ms,
            airline_ms,
        )
        assert rig.term.snapshot.operator == "stopped"
    finally:
        rig.close()
    saved = loads_config(path.read_text())
    assert (saved.lookahead.meter_ms, saved.lookahead.airline_ms) == (meter_ms, airline_ms)
    assert saved.machine == CFG.machine  # nothing else changed


def test_lookahead_trial_refuses_a_press_before_the_meter_turned() -> None:
    from topdress.terminal.calibration import CalibrationError
    from topdress.terminal.leadcal import trial

    # A meter that starts 0.1 s after the command and then turns 0.5 rev/s at once: its flow
    # is 0.1 s late; the product seen 0.55 s after the command, 0.2 s of it reaction.
    reports = [(1.0 + k / 10, max(0.0, (k / 10 - 0.1) * 0.5)) for k in range(1, 8)]
    t = trial(1.0, reports, t_seen=1.55, reaction_s=0.2)
    assert t.meter_s == pytest.approx(0.1)
    assert t.airline_s == pytest.approx(0.25)  # from the last still report (1.1 s) to 1.35 s
    with pytest.raises(CalibrationError, match="before the meter turned"):
        trial(1.0, reports, t_seen=1.25, reaction_s=0.2)
    with pytest.raises(CalibrationError, match="too late"):
        trial(1.0, reports, t_seen=12.0, reaction_s=0.2)
    with pytest.raises(CalibrationError, match="not turned"):
        trial(1.0, reports[:1], t_seen=1.5, reaction_s=0.2)
    with pytest.raises(CalibrationError, match="long enough"):
        trial(1.0, reports[:4], t_seen=1.5, reaction_s=0.2)


@pytest.mark.parametrize(
    ("values", "pid", "key"),
    [
        ({"meter_ms": 300, "airline_ms": 600}, 31, "lookahead.airline_ms"),
        ({"meter_ms": 300}, 30, "lookahead.meter_ms"),
        ({"stop_ms": 400}, 38, "lookahead.stop_ms"),
    ],
)
def test_a_refused_look_ahead_parameter_is_shown_at_its_field(
    tmp_path: Path, values: dict[str, int], pid: int, key: str
) -> None:
    rig = make_rig(drive(stand(30.0)))
    rig.term.desk.settings.config_path = _config_file(tmp_path)
    try:
        rig.run(2.0)
        _refuse_param(rig, pid)
        res = post(rig, op.ApplySettings("lookahead", values))
        assert not res.ok
        assert list(res.errors) == [key]  # the field, not the whole [lookahead] section
        assert rig.term.snapshot.settings_state[key].startswith("refused: ")
        assert rig.term.cfg.lookahead.total_s == 0.0  # nothing half-applied
    finally:
        rig.close()


def test_a_rate_model_changed_while_running_sets_the_rate_at_once() -> None:
    """[rate] is taken live: the rate commanded follows the new curve from the next tick."""
    rig = make_rig(drive(stand(2.0), straight(8.0, 200.0)), autostart=True)
    try:
        rig.run(10.0)
        before = rig.term.snapshot
        assert before.ndvi is not None and before.rate_model_kg_ha[0] > 0
        res = post(rig, op.ApplySettings("rate", {"linear": {"rate_0_kg_ha": 500.0}}))
        assert res.ok, res.message
        rig.run(rig.world.t_s + 0.3)
        s = rig.term.snapshot
        assert s.ndvi is not None
        want = build_rate_model(rig.term.cfg.rate).rate_kg_ha(s.ndvi) / 2
        assert rig.term.cfg.rate.linear.rate_0_kg_ha == 500.0
        assert s.rate_model_kg_ha == pytest.approx((want, want), abs=0.01)
        old = build_rate_model(CFG.rate).rate_kg_ha(s.ndvi) / 2
        assert abs(want - old) > 5.0  # the new curve, not the old one
    finally:
        rig.close()


def test_a_waiting_ecu_with_the_meters_on_is_an_alarm() -> None:
    # A [can] change while running never leaves the ECU unheard: the new bus is readied while
    # the old one commands (test_a_can_change_where_no_ecu_answers_keeps_the_bus_in_use).
    # An ECU that does not answer (a channel nobody is on): waiting, values unknown
    rig = make_rig(drive(stand(60.0)))
    rig.ecu_off = True
    try:
        rig.run(5.0)
        assert rig.term.snapshot.ecu_link == "wait"
        assert rig.term.snapshot.alarms == ()  # stopped: waiting is no alarm
        start = rig.world.t_s - rig.term._t0
        assert post(rig, op.Start()).ok
        rig.run(rig.world.t_s + 2.0)
        assert "ecu_link" not in {a.name for a in rig.term.snapshot.alarms}  # its grace
        rig.run(rig.world.t_s + 2.0)
        (alarm,) = [a for a in rig.term.snapshot.alarms if a.name == "ecu_link"]
        assert str(alarm.text) == "ECU waiting while the meters are on"
        assert alarm.state == "active" and 3.0 <= alarm.since_s - start <= 3.3
    finally:
        rig.close()


def test_a_section_changed_from_another_screen_meanwhile_is_refused_not_undone() -> None:
    rig = make_rig(drive(stand(30.0)))
    try:
        rig.run(2.0)
        base = section_version(rig.term.cfg, "rate")  # both screens filled from this
        first = post(rig, op.ApplySettings("rate", {"model": "table"}, base))
        assert first.ok and first.data == section_version(rig.term.cfg, "rate") != base
        # the second screen still holds model = linear: applying its split would undo it
        stale = post(rig, op.ApplySettings("rate", {"model": "linear", "split_upper": 0.6}, base))
        assert not stale.ok and stale.data == "stale"
        assert "changed from another screen meanwhile" in stale.message
        assert (rig.term.cfg.rate.model, rig.term.cfg.rate.split_upper) == ("table", 0.5)
        # the first screen goes on from the version its answer gave
        again = post(rig, op.ApplySettings("rate", {"split_upper": 0.6}, first.data))
        assert again.ok and rig.term.cfg.rate.split_upper == 0.6
    finally:
        rig.close()


def test_a_counter_reset_is_undone_and_keeps_what_was_counted_since(tmp_path: Path) -> None:
    session = SessionLog.create(tmp_path, DEFAULT_TOML)
    rig = make_rig(drive(stand(2.0), straight(8.0, 80.0), stand(5.0)), True, session=session)
    try:
        rig.run(14.0)
        before = rig.term.snapshot.count_field
        assert before.area_ha > 0.005
        assert not post(rig, op.UndoReset("field")).ok  # nothing reset yet
        assert post(rig, op.ResetCounter("field")).ok
        assert rig.term.snapshot.count_undo == ("field",)
        rig.run(20.0)
        since = rig.term.snapshot.count_field
        assert 0.0 < since.area_ha < before.area_ha
        assert post(rig, op.UndoReset("field")).ok
        back, season = rig.term.snapshot.count_field, rig.term.snapshot.count_season
        assert back.since == before.since
        # as if never reset: what the season (never reset) counted
        assert back.area_ha == pytest.approx(season.area_ha, rel=1e-9)
        assert back.kg == pytest.approx(season.kg, rel=1e-9)
        assert rig.term.snapshot.count_undo == ()
    finally:
        rig.close()
    with SessionReader(session.path) as reader:
        kinds = [e.kind for e in reader.events() if e.kind.startswith("counter.")]
    assert kinds == ["counter.reset", "counter.undo"]


def test_the_tank_counts_down_what_was_applied_and_alarms_at_its_level() -> None:
    rig = make_rig(drive(stand(2.0), straight(8.0, 200.0)), autostart=True)
    try:
        assert not post(rig, op.FillTank(5.0, 6.0)).ok  # the alarm level above the fill
        assert post(rig, op.FillTank(5.0, 2.0)).ok
        assert rig.term.snapshot.tank.remaining_kg == 5.0
        rig.run(12.0)
        s = rig.term.snapshot
        applied = sum(s.count_field.kg)
        assert s.tank.remaining_kg == pytest.approx(5.0 - applied, abs=1e-6)
        assert "tank_low" not in {a.name for a in s.alarms}
        rig.run(40.0)
        s = rig.term.snapshot
        assert s.tank.remaining_kg is not None and s.tank.remaining_kg < 2.0
        (low,) = [a for a in s.alarms if a.name == "tank_low"]
        assert str(low.text).startswith("tank low: 2 kg left")
    finally:
        rig.close()


def test_the_tank_outlives_a_terminal_started_again(tmp_path: Path) -> None:
    """The fill entered and what was applied from it: kept with the counters, so the next
    terminal goes on from what is left (not "no fill entered")."""
    rig = make_rig(
        drive(stand(2.0), straight(8.0, 60.0), stand(5.0)),
        autostart=True,
        session=SessionLog.create(tmp_path, DEFAULT_TOML),
    )
    try:
        assert post(rig, op.FillTank(500.0, 50.0)).ok
        rig.run(30.0)
        tank = rig.term.snapshot.tank
        assert tank.remaining_kg is not None and tank.remaining_kg < 500.0
    finally:
        rig.close()
    again = make_rig(drive(stand(5.0)), session=SessionLog.create(tmp_path, DEFAULT_TOML))
    try:
        again.run(1.0)
        assert again.term.snapshot.tank == tank
    finally:
        again.close()
