"""The terminal's control loop against the simulated machine (World: plant + C ECU core), in
virtual time: line sources are the fake twins, CAN goes through a python-can virtual bus."""

from __future__ import annotations

import itertools
from dataclasses import replace
from pathlib import Path

import can
import pytest

from term_rig import TerminalParts
from topdress import protocol
from topdress.config import DEFAULT_TOML, TerminalConfig, loads_config
from topdress.crop.rate import build_rate_model, split_layers
from topdress.devices.can import open_bus
from topdress.devices.lines import FakeLineSource
from topdress.display.console import render_line, render_lines
from topdress.ecu import meter_target_rpm
from topdress.gnss.nmea import make_sentence
from topdress.log.session import SessionLog, SessionReader
from topdress.sim.tractor import Drive, Segment
from topdress.sim.world import World
from topdress.terminal.app import Terminal
from topdress.view.snapshot import Snapshot

_channels = itertools.count()


class VirtualRig(TerminalParts):
    """Terminal + World on one virtual clock (10 ms steps, terminal tick every 100 ms)."""

    def __init__(self, cfg: TerminalConfig, drive: Drive, session: SessionLog | None = None):
        self.world = World(seed=3, drive=drive)
        super().__init__(cfg, lambda: self.world.t_s, session)
        self.snapshots: list[tuple[float, Snapshot]] = []
        self.ecu_silent = False  # its frames do not reach the terminal
        self.ecu_off = False  # not on the bus at all: hears nothing, says nothing

    def run(self, until_s: float) -> None:
        w, term = self.world, self.term
        while w.t_s < until_s - 1e-9:
            while (msg := self.ecu_bus.recv(timeout=0)) is not None:
                if not self.ecu_off:
                    w.deliver_can(msg)
            out = w.step()
            t = out.t_s
            silent = self.ecu_silent or self.ecu_off
            msgs = (can.Message(arbitration_id=i, data=d) for i, d in ([] if silent else out.can))
            self.deliver(t, out.nmea, out.crop, msgs)
            while not term.inbox.empty():
                term.handle(*term.inbox.get())
            if round(t * 100) % 10 == 0:
                term.tick(t)
                self.snapshots.append((t, term.snapshot))


def _drive(speed_kmh: float, length_m: float) -> Drive:
    return Drive(
        [
            Segment("stop", duration_s=2.0),
            Segment("straight", speed_kmh=speed_kmh, length_m=length_m, hold=True),
            Segment("stop", duration_s=5.0),
        ]
    )


def test_closed_loop_rate_follows_ndvi_and_meters_follow_eq4(tmp_path: Path) -> None:
    cfg = loads_config(DEFAULT_TOML)
    session = SessionLog.create(tmp_path, DEFAULT_TOML)
    rig = VirtualRig(cfg, _drive(8.0, 60.0), session)
    try:
        rig.run(30.0)
    finally:
        rig.close()
    term = rig.term
    assert term.link.params_done
    snaps = [s for _, s in rig.snapshots]
    working = [s for s in snaps if s.running and s.v_kmh > 7.5 and s.ndvi is not None]
    assert len(working) > 50
    model = build_rate_model(cfg.rate)
    m = cfg.machine
    for s in working:
        # the rate of each layer is the model's for the NDVI at the meters, split 50/50
        total = model.rate_kg_ha(s.ndvi)
        want = split_layers(total, cfg.rate.split_upper)
        assert s.rate_kg_ha == pytest.approx((want.upper_kg_ha, want.lower_kg_ha), abs=0.01)
    # in steady work the ECU's targets are eq. 4 of the commanded rate and the selected speed,
    # and the meters turn at their targets
    steady = working[len(working) // 2 :]
    for s in steady:
        eq4 = meter_target_rpm(m.width_m, s.rate_kg_ha[0], s.v_kmh, m.kg_per_rev_upper)
        assert s.target_rpm[0] == pytest.approx(eq4, rel=0.03, abs=0.05)
    mean_err = sum(abs(s.meter_rpm[0] - s.target_rpm[0]) for s in steady) / len(steady)
    assert mean_err < 0.05 * (sum(s.target_rpm[0] for s in steady) / len(steady))
    # the default speed mode: the fused estimate, fed by both sensors in steady work
    assert all(s.source == "fused" for s in steady)
    # and every input went to the log, with a state row every 100 ms
    with SessionReader(session.path) as reader:
        counts = reader.raw_counts()
        assert counts["nmea"] == term.nmea.counters["ok"]
        assert counts["crop"] > 100 and counts["can_rx"] > 1000 and counts["can_tx"] > 50
        assert reader.count("state") == len(rig.snapshots)


def test_gnss_port_lost_forwards_not_available_and_ecu_uses_the_wheel() -> None:
    rig = VirtualRig(loads_config(""), _drive(8.0, 200.0))
    try:
        rig.run(20.0)
        assert rig.term.snapshot.gnss_link == "ok"
        assert rig.term.link.command.gnss_kmh is not None
        rig.gnss.disconnect()
        rig.run(20.1)
        # the very next tick forwards "not available"
        assert rig.term.link.command.gnss_kmh is None
        assert (20.1, "GNSS lost (fake: disconnected)") in rig.events
        rig.run(22.0)
        state = rig.world.ecu.state
        assert not state.gnss_valid
        assert str(state.source) == "wheel"
        assert rig.term.snapshot.gnss_link == "lost"
        rig.gnss.reconnect()
        rig.run(23.0)
        assert rig.term.snapshot.gnss_link == "ok"
        assert rig.world.ecu.state.gnss_valid
    finally:
        rig.close()


def test_invalid_fix_is_no_fix() -> None:
    rig = VirtualRig(loads_config(""), _drive(5.0, 200.0))
    try:
        rig.run(5.0)
        assert rig.term.snapshot.gnss_link == "ok"
        # from now on the receiver reports status V
        rig.world.gnss.p = replace(rig.world.gnss.p, outages=((5.0, 100.0),))
        rig.run(8.0)
        assert rig.term.snapshot.gnss_link == "no fix"
        assert rig.term.link.command.gnss_kmh is None
        assert not rig.world.ecu.state.gnss_valid
    finally:
        rig.close()


def test_ecu_silent_is_shown_lost_and_the_stop_reaches_the_ecu_on_close() -> None:
    rig = VirtualRig(loads_config(""), _drive(5.0, 200.0))
    rig.run(6.0)
    assert rig.term.snapshot.ecu_link == "ok" and rig.world.ecu.state.running
    working = render_line(rig.term.snapshot)
    assert "src=-- " not in working and "meter=--" not in working
    rig.ecu_silent = True
    rig.run(7.0)
    lost = rig.term.snapshot
    assert lost.ecu_link == "lost" and not lost.ecu_live
    assert any(e.startswith("ECU lost") for _, e in rig.events)
    # its last frames are history: no speed, source, targets or meter speeds shown from them
    assert (lost.source, lost.v_kmh, lost.meter_rpm, lost.running) == ("none", 0.0, (0, 0), False)
    line = render_line(lost)
    assert "v=--km/h src=-- cv=--%" in line
    assert "target=--/-- meter=--/--r/min fan=--/--rpm faults=-- ecu=lost" in line
    # what the terminal knows by itself stays: the GNSS speed it reads, the rate it computes
    assert (
        lost.gnss_kmh is not None
        and lost.v_gnss_kmh is None  # the ECU's: not known while it is not heard
        and f"GNSS {lost.gnss_kmh:5.2f} km/h" in (render_lines(lost)[1])
    )
    rig.ecu_silent = False
    rig.run(8.0)
    assert rig.term.snapshot.ecu_link == "ok"
    rig.term.close()
    # the stop command sent on close is the ECU's last word from the terminal
    while (msg := rig.ecu_bus.recv(timeout=0)) is not None:
        rig.world.deliver_can(msg)
    rig.world.step()
    assert not rig.world.ecu.state.running
    rig.pc_bus.shutdown()
    rig.ecu_bus.shutdown()


def test_ecu_powered_after_the_terminal_is_waited_for_then_meters(tmp_path: Path) -> None:
    session = SessionLog.create(tmp_path, "")
    rig = VirtualRig(loads_config(""), _drive(8.0, 200.0), session)
    rig.ecu_off = True  # the implement's ECU is switched on 4 s after the terminal
    try:
        rig.run(4.0)
        waiting = [s for t, s in rig.snapshots]
        assert all(s.ecu_link == "wait" and not s.ecu_live for s in waiting)
        channel = rig.cfg.can.channel
        assert [e for _, e in rig.events if e.startswith("ECU")] == [
            f"ECU wait: WorkingWidth unacknowledged after 4 tries on CAN virtual:{channel};"
            " still trying (is the ECU powered, on this bus?)"
        ]
        # meanwhile the inputs are read: GNSS speed, NDVI and the rate it would command
        s = rig.term.snapshot
        assert s.gnss_link == "ok" and s.crop_link == "ok" and s.rate_kg_ha[0] > 0
        assert f"ecu=wait(virtual:{channel})" in render_line(s)
        assert f"ECU waiting (virtual:{channel})" in render_lines(s)[0]
        assert not rig.world.ecu.state.running
        rig.ecu_off = False
        rig.run(12.0)
        ready = [(t, e) for t, e in rig.events if e.startswith("ECU ready")]
        assert len(ready) == 1 and 4.0 < ready[0][0] < 4.5
        assert ready[0][1].startswith("ECU ready: every parameter acknowledged, 4.")
        s = rig.term.snapshot
        assert s.ecu_link == "ok" and s.running and s.source == "fused"  # the default mode
        m = rig.cfg.machine
        eq4 = meter_target_rpm(m.width_m, s.rate_kg_ha[0], s.v_kmh, m.kg_per_rev_upper)
        assert s.target_rpm[0] == pytest.approx(eq4, rel=0.03)
        assert s.meter_rpm[0] == pytest.approx(s.target_rpm[0], rel=0.1)
    finally:
        rig.close()
    with SessionReader(session.path) as reader:
        raw = list(reader.raw())
        rows = list(reader.states())
    # the inputs were logged while it waited; to the ECU only parameter tries, no command
    assert sum(1 for r in raw if r.kind == "nmea" and r.t < 4.0) > 30
    sent_before = {r.can_id for r in raw if r.kind == "can_tx" and r.t < 4.0}
    assert sent_before == {protocol.DEFAULT_IDS.param_set}
    assert all(r.source == "none" and r.meter_rpm_upper == 0.0 for r in rows if r.t < 4.0)
    assert any(r.meter_rpm_upper > 1.0 for r in rows if r.t > 6.0)


def test_bad_lines_are_counted_and_skipped() -> None:
    rig = VirtualRig(loads_config(""), _drive(5.0, 200.0))
    try:
        rig.run(2.0)
        rig.gnss.emit(2.0, b"$GNRMC,garbage*00")
        rig.gnss.emit(2.0, b"\x00\xff\xfe binary")
        rig.crop.emit(2.0, b"9,0.1,0.2,0.3,0.4,0.5")  # sensor 9 of 4
        rig.crop.emit(2.0, b"1,0.1,0.2")  # truncated
        rig.run(3.0)
        c = rig.term.snapshot.counters
        assert c["nmea_bad"] == 2 and c["crop_bad"] == 2
        assert c["nmea"] > 20 and c["crop"] > 10
    finally:
        rig.close()


def test_a_nan_speed_with_a_good_checksum_is_skipped_not_fatal() -> None:
    cfg = loads_config("[can]\nsend_on_gnss = true\n")
    rig = VirtualRig(cfg, _drive(8.0, 200.0))
    try:
        rig.run(3.0)
        assert rig.term.link.params_done
        sent = rig.term.link.counters.tx_commands
        # sent at once with send_on_gnss: a NaN here used to stop the terminal
        rig.gnss.emit(3.0, make_sentence("GNRMC,000003.00,A,4500.0,N,12600.0,E,nan,0.0,010126,,,A"))
        # a second '*' crashed the field parser; 1e308 knots became an infinite speed
        rig.gnss.emit(3.1, b"$GPRMC,,*,,,,,,,,,,*61\r\n")
        rig.gnss.emit(3.2, b"$GPVTG,,T,,M,,N*,,K,N*06\r\n")
        rig.gnss.emit(
            3.3, make_sentence("GPRMC,123519,A,4807.038,N,01131.000,E,1e308,084.4,230394,,W")
        )
        rig.run(4.0)
        assert rig.term.link.counters.tx_commands > sent
        assert rig.term.nmea.counters["malformed"] == 4
        assert rig.term.snapshot.counters["nmea_bad"] == 4
    finally:
        rig.close()


def test_gnss_stale_s_of_the_config_is_applied() -> None:
    cfg = loads_config("[gnss]\nstale_s = 0.5\n")
    bus = open_bus(replace(cfg.can, channel=f"test-terminal-{next(_channels)}"))
    term = Terminal(cfg, FakeLineSource(), FakeLineSource(), bus, clock=lambda: 0.0)
    try:
        term.open()
        term.handle(
            "nmea", 0.0, make_sentence("GNRMC,000000.00,A,4500.0,N,12600.0,E,4.0,0.0,010126,,,A")
        )
        term.tick(0.4)
        assert term.link.command.gnss_kmh == pytest.approx(4.0 * 1.852)
        term.tick(0.6)  # 0.6 s after the last RMC: stale by the file's 0.5 s (default 2 s)
        assert term.link.command.gnss_kmh is None
        assert term.snapshot.gnss_link == "lost"  # the receiver fell silent
    finally:
        term.close()
        bus.shutdown()


def test_gnss_lost_reaches_the_ecu_at_once_not_at_the_next_period() -> None:
    # a 1 s period (under the ECU's GNSS timeout): only a send on the loss tells it in 0.2 s
    rig = VirtualRig(loads_config("[can]\ncommand_period_s = 1.0\n"), _drive(8.0, 200.0))
    try:
        rig.run(20.5)
        assert rig.world.ecu.state.gnss_valid
        sent = rig.term.link.counters.tx_commands
        rig.gnss.disconnect()
        rig.run(20.7)
        assert rig.term.link.counters.tx_commands == sent + 1
        assert not rig.world.ecu.state.gnss_valid
    finally:
        rig.close()


def _crop_line(sensor: int) -> bytes:
    return f"{sensor},0.0412,0.2104,0.4419,0.3541,0.8295".encode()


def test_crop_sensors_falling_silent_or_lost_are_reported() -> None:
    cfg = loads_config("")
    bus = open_bus(replace(cfg.can, channel=f"test-terminal-{next(_channels)}"))
    crop = FakeLineSource()
    events: list[str] = []
    term = Terminal(
        cfg,
        FakeLineSource(),
        crop,
        bus,
        clock=lambda: 0.0,
        on_event=lambda e: events.append(str(e)),
    )
    try:  # not opened: no parameter push, so no ECU is needed for the loop's own logic
        term.tick(0.0)
        assert term.snapshot.crop_link == "wait"
        for sensor in (1, 2):  # sensors come up one by one: no event yet
            term.handle("crop", 0.0, _crop_line(sensor))
            term.tick(0.0)
        assert term.snapshot.crop_link == "2/4" and events == []
        for sensor in (3, 4):
            term.handle("crop", 0.0, _crop_line(sensor))
        term.tick(0.1)
        term.tick(0.6)
        assert term.snapshot.crop_link == "ok" and events == []  # the start is no event
        for t in (0.5, 1.0, 1.5):  # sensor 4 falls silent (stale after crop.stale_s = 1 s)
            for sensor in (1, 2, 3):
                term.handle("crop", t, _crop_line(sensor))
        term.tick(1.6)
        assert term.snapshot.crop_link == "3/4" and events == []  # shown at once
        term.tick(2.1)
        assert events == ["crop sensors: 3 of 4 fresh"]  # announced once it held 0.5 s
        term.tick(2.6)  # all silent: no NDVI, so no fertilizer; the operator must know
        term.tick(3.1)
        assert term.snapshot.crop_link == "silent" and term.snapshot.rate_kg_ha == (0.0, 0.0)
        assert events[-1] == "crop sensors silent: no NDVI, rate 0"
        crop.disconnect()
        term.tick(3.2)
        assert events[-1] == "crop sensors lost (fake: disconnected)"  # at once
        crop.reconnect()
        for t in (3.3, 3.8):
            for sensor in (1, 2, 3, 4):
                term.handle("crop", t, _crop_line(sensor))
            term.tick(t)
        assert term.snapshot.crop_link == "ok" and events[-1] == "crop sensors ok"
    finally:
        term.close()
        bus.shutdown()


def test_a_sensor_a_moment_late_is_not_announced() -> None:
    # a logger at 1 Hz per sensor against crop.stale_s = 1 s: now and then one tick late
    cfg = loads_config("")
    bus = open_bus(replace(cfg.can, channel=f"test-terminal-{next(_channels)}"))
    events: list[str] = []
    term = Terminal(
        cfg, FakeLineSource(), FakeLineSource(), bus, on_event=lambda e: events.append(str(e))
    )
    try:
        for k in range(100):  # 10 s of 10 Hz ticks
            t = k * 0.1
            if k % 10 == 0:
                for sensor in (1, 2, 3):
                    term.handle("crop", t, _crop_line(sensor))
            if (k % 10 == 0 and k % 30 != 0) or k % 30 == 2:  # sensor 4 late by 0.2 s at times
                term.handle("crop", t, _crop_line(4))
            term.tick(t)
        assert events == []
        assert term.ndvi.sensors.counters["stale"] > 0  # it was late, and counted
    finally:
        term.close()
        bus.shutdown()


def test_ecu_back_after_a_link_glitch_keeps_the_meters_running(tmp_path: Path) -> None:
    session = SessionLog.create(tmp_path, "")
    rig = VirtualRig(loads_config(""), _drive(8.0, 200.0), session)
    try:
        rig.run(10.0)
        assert rig.world.ecu.state.running
        rig.ecu_silent = True  # the ECU's frames do not reach the terminal for 1 s
        rig.run(11.0)
        assert rig.term.snapshot.ecu_link == "lost"
        rig.ecu_silent = False
        stopped = []
        for k in range(1, 301):  # 3 s after it is heard again, step by step
            rig.run(11.0 + k * 0.01)
            stopped += [] if rig.world.ecu.state.running else [rig.world.t_s]
        # the parameters went again (answered Busy with our values) and nothing stopped:
        # 13 at the start (machine, speed, GnssLagAuto), 14 again: the lag learned meanwhile
        # as GnssLag, answered Busy with the ECU's 0 while it reports its learned lag
        assert rig.term.link.params_done and rig.term.link.counters.tx_params == 13 + 14
        assert stopped == []
    finally:
        rig.close()
    # rows while the ECU was lost carry no stale ECU values
    with SessionReader(session.path) as reader:
        rows = [r for r in reader.states() if 10.5 < r.t < 11.0]
    assert rows and all(r.source == "none" and r.meter_rpm_upper == 0.0 for r in rows)
    assert all(r.v_kmh == 0.0 for r in rows)


def test_can_receive_errors_are_counted_and_reported_once_per_spell() -> None:
    cfg = loads_config("")
    bus = open_bus(replace(cfg.can, channel=f"test-terminal-{next(_channels)}"))
    events: list[str] = []
    term = Terminal(
        cfg, FakeLineSource(), FakeLineSource(), bus, on_event=lambda e: events.append(str(e))
    )
    try:
        for k in range(3):  # the reader retries every 0.5 s while the adapter is gone
            term.handle("can_error", k * 0.5, "Could not read from serial device")
        term.handle("can", 1.5, can.Message(arbitration_id=0x123, data=b""))
        term.handle("can_error", 2.0, "Could not read from serial device")
        assert events == ["CAN receive error: Could not read from serial device"] * 2
        term.tick(2.0)
        assert term.snapshot.counters["can_rx_errors"] == 4
    finally:
        term.close()
        bus.shutdown()


@pytest.mark.parametrize(
    ("kind", "line", "hint"),
    [
        # a wrong baud rate: bytes, but no sentence decodes
        (
            "nmea",
            b"\xf8\x80x\x00\xe6\x1e\x98",
            "GNSS: 20 lines, none with a speed: none decodes, check gnss.baud",
        ),
        # a receiver set to send GGA only: no speed to forward
        (
            "nmea",
            make_sentence("GNGGA,000000.00,4500.0,N,12600.0,E,1,08,1.0,100,M,0,M,,"),
            "GNSS: 20 lines, none with a speed: the receiver must send RMC (or VTG)",
        ),
        # a logger whose columns are not the configured ones
        (
            "crop",
            b"0.0412,0.2104,0.4419,0.3541,0.8295,2",
            "crop sensors: 20 lines, none usable (last: sensor_id: '0.0412' is not 1..4): "
            "check crop.baud and [crop.columns]",
        ),
    ],
)
def test_input_that_never_gives_what_is_needed_is_explained_once(
    kind: str, line: bytes, hint: str
) -> None:
    cfg = loads_config("")
    bus = open_bus(replace(cfg.can, channel=f"test-terminal-{next(_channels)}"))
    events: list[str] = []
    term = Terminal(
        cfg, FakeLineSource(), FakeLineSource(), bus, on_event=lambda e: events.append(str(e))
    )
    try:
        for k in range(40):
            term.handle(kind, k * 0.1, line.rstrip(b"\r\n"))
            term.tick(k * 0.1)
        assert [e for e in events if e.startswith(hint.split(":")[0] + ":")] == [hint]
    finally:
        term.close()
        bus.shutdown()


def test_the_logged_row_and_the_snapshot_mean_the_same_speeds(tmp_path: Path) -> None:
    """The state row is derived from the Snapshot: each speed is the ECU's in both (the GNSS
    speed it compares, at its resolution), while the terminal's own reading of the receiver
    is shown apart."""
    session = SessionLog.create(tmp_path, "")
    rig = VirtualRig(loads_config(""), _drive(8.0, 80.0), session)
    try:
        rig.run(20.0)
    finally:
        rig.close()
    with SessionReader(session.path) as reader:
        rows = list(reader.states())
    assert len(rows) == len(rig.snapshots)
    for (t, snap), row in zip(rig.snapshots, rows, strict=True):
        assert row.t == t
        assert (row.v_gnss_kmh, row.v_wheel_kmh, row.v_kmh) == (
            snap.v_gnss_kmh,
            snap.v_wheel_kmh,
            snap.v_kmh,
        )
        assert (row.source, row.cv_pct, row.faults) == (snap.source, snap.cv_pct, snap.faults)
    moving = [s for _, s in rig.snapshots if s.ecu_live and s.v_kmh > 7.0]
    assert len(moving) > 50
    # two readings of one receiver: the ECU's (as PcCommand and PcGnssTime carried it, when
    # the ECU last took it) and the terminal's own; in uniform motion they agree closely
    assert any(s.v_gnss_kmh != s.gnss_kmh for s in moving)
    uniform = [s for s in moving if s.uniform and s.v_gnss_kmh is not None]
    assert uniform and all(
        s.gnss_kmh is not None and abs(s.v_gnss_kmh - s.gnss_kmh) < 0.3  # type: ignore[operator]
        for s in uniform
    )


def test_a_full_log_disk_is_an_alarm_and_an_event(tmp_path: Path) -> None:
    # A full disk was an ERROR line on the console and a log_err counter, nothing more.
    cfg = loads_config(DEFAULT_TOML)
    session = SessionLog.create(tmp_path, DEFAULT_TOML, max_bytes=200 * 1024)
    rig = VirtualRig(cfg, _drive(8.0, 60.0), session)
    try:
        rig.run(5.0)
        assert "log_disk_full" not in {a.name for a in rig.snapshots[-1][1].alarms}
        for k in range(60):  # the writer commits in real time, the rig runs in virtual time
            rig.run(5.0 + (k + 1) * 0.5)
            session.sync()
            if session.lost:
                break
        rig.run(rig.world.t_s + 0.2)  # the next ticks see the health
    finally:
        rig.close()
    alarms = {a.name: a for a in rig.snapshots[-1][1].alarms}
    assert "log_disk_full" in alarms and alarms["log_disk_full"].state == "active"
    assert any("log disk full" in e for _, e in rig.events)
    with SessionReader(session.path) as reader:
        assert '"kind":"disk_full"' in reader.meta["write_failed"]
        assert "closed_utc" in reader.meta
