"""The terminal as the Task Controller of an ISOBUS implement (`[can] implement = "isobus"`), in
virtual time: the topdress ECU on ISOBUS (the C node and core, topdress.sim.isobus) is the
implement; the crop-sensor rate must reach its setpoint DDI and what it reports must come back
into the Snapshot, the alarms and the session log."""

from __future__ import annotations

import struct
import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import can
import pytest
from pyproj import Geod

from term_rig import TerminalParts
from topdress.cli.isobus_demo import DEMO_PASS_M, DEMO_PASSES, DEMO_SPEED_KMH
from topdress.cli.main import main
from topdress.config import DEFAULT_TOML, TerminalConfig, loads_config
from topdress.display import isobus_names
from topdress.errors import ConfigError
from topdress.geo.asapplied import build as build_as_applied
from topdress.geo.export import export_maps
from topdress.gnss import sentences as nmea
from topdress.i18n import Text, render, text
from topdress.i18n.catalogue import CATALOGUE
from topdress.isobus.ddop import Machine, build
from topdress.isobus.node import Frame, IsobusNode, TpEndpoint, topdress_name
from topdress.isobus.tcserver import map_device, pdack_texts, tc_name
from topdress.isobus.workstate import condensed_states, condensed_value
from topdress.log.session import SessionLog, SessionReader
from topdress.log.summary import format_text, summarise
from topdress.sim.isobus import ELEMENT_BINS, IsobusMachine, tc_timeout_ms
from topdress.sim.tractor import Drive, Segment
from topdress.sim.world import SimConfig, World
from topdress.terminal.alarms import AlarmBook, AlarmInputs
from topdress.terminal.journal import Journal, Settings
from topdress.terminal.tclink import TcLink, known_ddis, pool_ddis
from topdress.view.commands import ApplySettings, Stop
from topdress.view.snapshot import Snapshot

_QUIET = AlarmInputs(False, (0.0, 0.0), (0.0, 0.0), 0, "ok", "ok", "ok")


class IsobusRig(TerminalParts):
    """Terminal (the TC) + the ECU on ISOBUS + the plant, on one virtual clock (10 ms steps,
    the terminal's tick every 100 ms)."""

    def __init__(
        self,
        cfg: TerminalConfig,
        drive: Drive,
        session: SessionLog | None = None,
        implement: str = "isobus",
    ):
        self.world = World(SimConfig.of_machine(cfg), seed=3, drive=drive)
        node = IsobusNode(
            topdress_name(0, b"rig"),
            tc_timeout_ms=tc_timeout_ms(self.world.ecu.params.cmd_timeout_ms),
        )
        sections = Machine.from_config(cfg.machine).sections
        m = cfg.machine
        self.sim = IsobusMachine(self.world, node, m.width_m, sections, m.fan_rpm)
        super().__init__(cfg, lambda: self.world.t_s, session, implement)
        self.snapshots: list[tuple[float, Snapshot]] = []
        self.node_rates: list[tuple[float, float, float]] = []  # t, what the node was set
        self.implement_off = False  # the implement unplugged: hears nothing, says nothing

    def run(self, until_s: float) -> None:
        w, term = self.world, self.term
        while w.t_s < until_s - 1e-9:
            heard = []
            while (msg := self.ecu_bus.recv(timeout=0)) is not None:
                heard.append(Frame(msg.arbitration_id, bytes(msg.data)))
            for layer, element in enumerate(ELEMENT_BINS):  # its totals: what it metered
                self.sim.node.set_actual(element, 81, round(w.truth.applied_kg[layer]))
            frames = self.sim.step([] if self.implement_off else heard)
            out = self.sim.out
            assert out is not None
            t = out.t_s
            msgs = (can.Message(arbitration_id=f.can_id, data=f.data, is_extended_id=True)
                    for f in ([] if self.implement_off else frames))  # fmt: skip
            self.deliver(t, out.nmea, out.crop, msgs)
            while not term.inbox.empty():
                term.handle(*term.inbox.get())
            if round(t * 100) % 10 == 0:
                term.tick(t)
                self.snapshots.append((t, term.snapshot))
                node = self.sim.node
                self.node_rates.append((t, node.rate_kg_ha(0), node.rate_kg_ha(1)))


def _drive(speed_kmh: float, length_m: float) -> Drive:
    return Drive(
        [
            Segment("stop", duration_s=4.0),
            Segment("straight", speed_kmh=speed_kmh, length_m=length_m, hold=True),
            Segment("stop", duration_s=3.0),
        ]
    )


def test_condensed_work_state_round_trip() -> None:
    # 6 sections on, 7..16 not installed: the value the AgIsoStack++ examples send
    assert condensed_value([True] * 6) == -4096 + 0x555
    assert condensed_value([False] * 6) == -4096
    assert condensed_states(condensed_value([True, False, True]), 3) == [True, False, True]
    assert condensed_states(-4096 + 0x555, 6) == [True] * 6


def test_implement_is_a_checked_choice() -> None:
    with pytest.raises(ConfigError, match=r"can\.implement"):
        loads_config('[can]\nimplement = "isobsu"\n')
    with pytest.raises(ConfigError, match=r"isobus\.tc_address"):
        loads_config("[isobus]\ntc_address = 100\n")
    assert loads_config('[can]\nimplement = "isobus"\n').can.implement == "isobus"


def test_crop_sensor_rate_reaches_the_implement_and_its_reports_come_back(
    tmp_path: Path,
) -> None:
    cfg = loads_config(DEFAULT_TOML)
    session = SessionLog.create(tmp_path, DEFAULT_TOML)
    rig = IsobusRig(cfg, _drive(8.0, 60.0), session)
    try:
        rig.run(34.0)
        last = rig.term.snapshot
        rig.term.post(Stop())  # the operator stops: rates 0, work state and sections off
        tc = rig.term.can.tc
        assert tc is not None
        sent = tc.counters.tx_commands
        while not rig.term.inbox.empty():  # handled off the tick: it goes out at once
            rig.term.handle(*rig.term.inbox.get())
        assert tc.setpoints == (0.0, 0.0)
        assert tc.counters.tx_commands - sent == 4  # 2 rates, work state, sections
        rig.run(36.0)
        stopped = rig.term.snapshot
    finally:
        rig.close()
    iso = last.isobus
    assert iso is not None
    assert iso.implement == "topdress"
    assert iso.implement_address == 0x84
    assert iso.tc_address == 0xF7
    assert [(p.element, p.setpoint_ddi, p.unit) for p in iso.products] == [
        (3, 6, "kg/ha"),
        (4, 6, "kg/ha"),
    ]
    # who is on the bus, NAMEs decoded: the TC (function 130) and the implement
    whats = {f.address: (f.function, isobus_names.what(f, iso)) for f in iso.functions}
    assert whats[0xF7] == (130, "task controller (this terminal)")
    assert whats[0x84] == (128, "implement served: Fertilize Rate Control")
    # the rates set on the implement are the terminal's crop-sensor rates, tick by tick (the
    # node holds what the last tick sent: compared with the tick before), to 0.01 kg/ha
    working = [
        (i, s)
        for i, (t, s) in enumerate(rig.snapshots)
        if i > 0 and t < 34.0 and s.running and s.v_kmh > 7.5 and s.ndvi is not None
    ]
    assert len(working) > 150
    rates = {round(s.rate_kg_ha[0], 1) for _, s in working}
    assert len(rates) > 10  # the NDVI model's rate moves with the crop
    for i, _ in working:
        _, upper, lower = rig.node_rates[i]
        sent = rig.snapshots[i - 1][1]
        assert (upper, lower) == pytest.approx(sent.rate_kg_ha, abs=0.011)
    # the implement meters at the terminal's rate: what it reports (DDI 7) within 3 % in
    # steady state (the second half of the pass), both layers
    steady = [s for _, s in working[len(working) // 2 :]]
    for layer in (0, 1):
        err = sum(abs(s.isobus.products[layer].actual - s.rate_kg_ha[layer]) for s in steady)
        want = sum(s.rate_kg_ha[layer] for s in steady)
        assert err / want < 0.03
    # sections: all six on while metering, reported back (DDI 161); work state on
    mid = steady[len(steady) // 2].isobus
    assert mid.sections == (True,) * 6
    assert mid.work_state is True
    # stopped by the operator: the implement says its work state and sections are off
    assert stopped.isobus is not None
    assert stopped.isobus.work_state is False and stopped.isobus.sections == (False,) * 6
    assert [p.setpoint for p in stopped.isobus.products] == [0.0, 0.0]
    assert rig.sim.node.rate_kg_ha(0) == 0.0
    # the kg the session log integrates from the implement's reports is what the plant metered
    path = session.path
    with SessionReader(path) as reader:
        summary = summarise(reader)
        events = list(reader.events())
    kinds = [e.kind for e in events]
    truth_kg = sum(rig.world.truth.applied_kg)
    assert truth_kg > 1.0
    assert sum(x.applied_kg for x in summary.layers.values()) == pytest.approx(truth_kg, rel=0.05)
    assert "isobus.implement" in kinds and "isobus.connected" in kinds
    assert "ISOBUS implement topdress at 0x84" in format_text(summary)
    (totals,) = [e.detail for e in events if e.kind == "isobus.totals"]
    assert totals["elements"] == [3, 4] and totals["units"] == ["kg", "kg"]
    assert sum(totals["totals"]) == pytest.approx(truth_kg, abs=2.0)  # DDI 81: whole kg
    # the ISOXML export names the device from the implement's DDOP and its NAME
    with SessionReader(path) as reader:
        export_maps(reader, tmp_path / "taskdata", "isoxml", "EPSG:4326", None)
    dvc = ET.parse(tmp_path / "taskdata" / "TASKDATA.XML").getroot().find("DVC")
    assert dvc is not None
    assert (dvc.get("B"), dvc.get("D")) == ("topdress", f"{rig.sim.node.name:016X}")
    assert not [a for a in last.alarms if a.name in ("implement_lost", "ddop_refused")]


def test_implement_lost_is_an_alarm_and_the_loop_goes_on(tmp_path: Path) -> None:
    cfg = loads_config(DEFAULT_TOML)
    session = SessionLog.create(tmp_path, DEFAULT_TOML)
    rig = IsobusRig(cfg, _drive(8.0, 200.0), session)
    try:
        rig.run(12.0)
        assert rig.term.snapshot.isobus is not None
        assert rig.term.snapshot.isobus.state == "ok"
        rig.implement_off = True
        rig.run(22.0)
        snap = rig.term.snapshot
        assert rig.sim.node.rate_kg_ha(0) == 0.0  # its own fail-safe: no TC, no rate
        rig.implement_off = False  # plugged back: it connects again and is set the rate
        rig.run(34.0)
        back = rig.term.snapshot
    finally:
        rig.close()
    assert back.isobus is not None and back.isobus.state == "ok"
    assert rig.sim.node.rate_kg_ha(0) == pytest.approx(back.rate_kg_ha[0], abs=2.0)
    lost_alarm = [a for a in back.alarms if a.name == "implement_lost"]
    assert [a.state for a in lost_alarm] == ["cleared"]  # until the operator acknowledges
    assert snap.isobus is not None and snap.isobus.state == "lost"
    assert snap.ecu_link == "lost"
    names = [a.name for a in snap.alarms]
    assert "implement_lost" in names and "ecu_lost" not in names
    # the loop still decides rates and logs rows
    assert snap.t_s > 21.0 and snap.gnss_link == "ok"
    with SessionReader(session.path) as reader:
        events = list(reader.events())
    # the implement's link is the machine's link ("ecu"); why, in the TC's words
    assert [e.detail["link"] for e in events if e.kind == "link.lost"] == ["ecu"]
    problems = [e.detail["what"] for e in events if e.kind == "isobus.problem"]
    # the setpoints it no longer acknowledged (said once, however many), then its silence
    assert len(problems) == 2, problems
    assert problems[0].startswith("client 0x84 did not acknowledge DDI 6 of element ")
    assert problems[1] == "client 0x84 silent for 6000 ms"
    tc = rig.term.can.tc
    assert tc is not None and tc.server.counters["pdacks_missing"] > 1


def test_the_demos_40_s_apply_at_the_terminals_rate(tmp_path: Path) -> None:
    """`topdress demo --isobus --duration 40`'s drive and machine, in virtual time: what the
    implement reports it applied is within 3 % of what the terminal's setpoints asked for, and
    of what the plant metered."""
    cfg = loads_config(DEFAULT_TOML)
    session = SessionLog.create(tmp_path, DEFAULT_TOML)
    rig = IsobusRig(cfg, Drive.field_passes(DEMO_PASSES, DEMO_PASS_M, DEMO_SPEED_KMH), session)
    try:
        rig.run(40.0)
    finally:
        rig.close()
    with SessionReader(session.path) as reader:
        s = summarise(reader)
    applied = sum(x.applied_kg for x in s.layers.values())
    target = sum(x.target_kg for x in s.layers.values())
    truth = sum(rig.world.truth.applied_kg)
    assert applied > 2.0
    assert applied == pytest.approx(target, rel=0.03)
    assert applied == pytest.approx(truth, rel=0.03)


class _Port:
    """The TC's frames, kept for the scripted client."""

    def __init__(self) -> None:
        self.sent: list[can.Message] = []
        self.values: dict[tuple[int, int], int] = {}  # the last Set Value, by element and DDI

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.sent.append(msg)
        d = bytes(msg.data)
        if (msg.arbitration_id >> 8) & 0x3FF00 == 0xCB00 and d[0] & 0x0F in (3, 10):
            element, ddi = d[0] >> 4 | d[1] << 4, d[2] | d[3] << 8
            self.values[(element, ddi)] = struct.unpack_from("<i", d, 4)[0]


def _client_session(pool: bytes, toml: str = "") -> tuple[TcLink, list[str], _Port]:
    """A client at 0x90 that announces itself and uploads `pool` over TP, then activates it."""
    settings = Settings(loads_config('[can]\nimplement = "isobus"\n' + toml))
    said: list[str] = []
    journal = Journal(None, lambda: 0.0, lambda e: said.append(str(e)))
    port = _Port()
    link = TcLink(port, settings, journal)
    client = TpEndpoint(0x90, 4096)
    t = 0.0

    def exchange(frames: list[Frame], seconds: float) -> None:
        nonlocal t
        for f in frames:
            link.on_frame(can.Message(arbitration_id=f.can_id, data=f.data), t)
        end = t + seconds
        while t < end:
            t += 0.01
            link.poll(t, (True, 0.0, 100.0, 100.0))
            for m in port.sent:
                client.rx(m.arbitration_id, bytes(m.data), round(t * 1e6))
            port.sent.clear()
            client.step(round(t * 1e6))
            for f in client.tx():
                link.on_frame(can.Message(arbitration_id=f.can_id, data=f.data), t)

    def pd(data: bytes) -> Frame:
        return Frame(5 << 26 | 0xCB00 << 8 | 0xF7 << 8 | 0x90, data)

    exchange([], 0.4)  # the TC claims its address
    exchange([Frame(6 << 26 | 0xFE0D << 8 | 0x90, bytes([0xF7]) + b"\xff" * 7)], 0.1)
    exchange([pd(bytes([0x41]) + len(pool).to_bytes(4, "little") + b"\xff" * 3)], 0.1)
    client.send(0xCB00, 0xF7, bytes([0x61]) + pool, round(t * 1e6))
    exchange([], 0.5)
    exchange([pd(bytes([0x81]) + b"\xff" * 7)], 0.2)
    return link, said, port


def test_a_malformed_ddop_is_refused_with_its_reason_and_an_alarm() -> None:
    link, said, _ = _client_session(b"DVC" + bytes(range(40)))
    assert link.state == "refused"
    view = link.view(0.0)
    assert view.problem.startswith("DDOP malformed")
    assert any("DDOP malformed" in s for s in said)
    book = AlarmBook(10.0, 5.0)
    new = book.update(1.0, replace(_QUIET, isobus=(view.state, view.implement, view.problem)))
    ((name, what),) = new
    assert name == "ddop_refused"
    assert "DDOP malformed" in str(what)


def test_a_good_ddop_from_a_scripted_client_is_served() -> None:
    pool, _ = build(Machine.from_config(loads_config("").machine))
    link, said, _ = _client_session(pool)
    assert link.state == "ok"
    assert [p.element for p in link.products] == [3, 4]
    assert link.setpoints == (100.0, 100.0)
    assert any("implement topdress at 0x90: DDOP active" in s for s in said)


def _text(s: str) -> bytes:
    return bytes([len(s)]) + s.encode()


def _spreader_pool(
    setpoint_ddi: int, latency_ms: int | None, actual_ms: int | None = None
) -> bytes:
    """A one-bin implement's pool written by hand (not by topdress's builder): a device with a
    setpoint latency (DDI 142) when given, a bin set in mass (DDI 6) or volume (DDI 1) per area."""
    actual = {6: 7, 1: 2}[setpoint_ddi]
    total = {6: 81, 1: 80}[setpoint_ddi]
    dvc = (
        b"DVC"
        + struct.pack("<H", 0)
        + _text("Spreader 3000")
        + _text("2.1")
        + bytes(8)
        + _text("SN1")
        + b"ABCDEFG"
        + b"en\x50\x00\x00\x00\xff"
        + b"\x00"
    )

    def det(oid: int, kind: int, name: str, element: int, parent: int, kids: list[int]) -> bytes:
        head = b"DET" + struct.pack("<HB", oid, kind) + _text(name)
        return (
            head
            + struct.pack("<HHH", element, parent, len(kids))
            + struct.pack(f"<{len(kids)}H", *kids)
        )

    def dpd(oid: int, ddi: int, props: int, trig: int) -> bytes:
        return b"DPD" + struct.pack("<HHBB", oid, ddi, props, trig) + _text("pd") + b"\xff\xff"

    device_kids = [11] + ([10] if latency_ms is not None else [])
    device_kids += [15] if actual_ms is not None else []
    objs = [
        dvc,
        det(1, 1, "Spreader", 0, 0, device_kids),
        det(2, 3, "Hopper", 1, 1, [12, 13, 14]),
        dpd(11, 141, 1, 8),
        dpd(12, setpoint_ddi, 3, 8),
        dpd(13, actual, 1, 1),
        dpd(14, total, 1, 16),
    ]
    if latency_ms is not None:
        objs.append(b"DPT" + struct.pack("<HHi", 10, 142, latency_ms) + _text("lat") + b"\xff\xff")
    if actual_ms is not None:
        objs.append(b"DPT" + struct.pack("<HHi", 15, 143, actual_ms) + _text("act") + b"\xff\xff")
    return b"".join(objs)


def test_a_foreign_one_bin_pool_in_mass_takes_the_whole_rate_and_gives_its_delay() -> None:
    link, _, port = _client_session(_spreader_pool(6, 800))
    assert link.state == "ok"
    (p,) = link.products
    assert (p.element, p.setpoint_ddi, p.actual_ddi, p.total_ddi, p.unit) == (1, 6, 7, 81, "kg/ha")
    assert link.setpoints == (200.0,)  # upper + lower: one product takes the whole rate
    assert port.values[(1, 6)] == 20000  # mg/m^2
    assert link.setpoint_latency_s() == 0.8
    view = link.view(0.9)
    assert (view.implement, view.setpoint_latency_ms, view.sections) == ("Spreader 3000", 800, ())


def test_a_pools_actual_value_delay_is_read() -> None:
    link, _, _ = _client_session(_spreader_pool(6, 800, 1000))
    assert link.state == "ok"
    assert link.latency_ms == {142: 800, 143: 1000}
    assert link.actual_latency_s() == 1.0
    assert link.view(0.9).actual_latency_ms == 1000


def _mapped_points(tmp_path: Path, actual_ms: int | None) -> dict[float, tuple[float, float]]:
    """The as-applied map's points (by log time) of a pass north at 8 km/h, the implement's
    DDI 143 `actual_ms` (as its pool's DPT 143 gives it, read at connection)."""
    cfg = loads_config(DEFAULT_TOML)
    session = SessionLog.create(tmp_path / f"logs-{actual_ms}", DEFAULT_TOML)
    rig = IsobusRig(cfg, _drive(8.0, 80.0), session)
    try:
        rig.run(5.0)
        tc = rig.term.can.tc
        assert tc is not None and tc.state == "ok"
        if actual_ms is not None:
            tc.latency_ms[143] = actual_ms
        rig.run(30.0)
    finally:
        rig.close()
    with SessionReader(session.path) as reader:
        data = build_as_applied(reader)
    times = data.points["LogTime"]
    return {round(float(t), 2): (g.y, g.x) for t, g in zip(times, data.point_geom, strict=True)}


def test_the_actual_value_delay_puts_the_reports_where_the_machine_was(tmp_path: Path) -> None:
    """A client reporting a 1 s actual-value delay (DDI 143), driven north at 8 km/h: the
    as-applied map's point of each report is 2.22 m (8 km/h x 1 s) behind, where the machine
    was when what it reports was metered; the same drive without the delay is the reference."""
    now = _mapped_points(tmp_path, None)
    delayed = _mapped_points(tmp_path, 1000)
    geod = Geod(ellps="WGS84")
    shifts, misses = [], []
    for t, (lat, lon) in delayed.items():
        before = round(t - 1.0, 2)
        if 12.0 < t < 28.0 and t in now and before in now:  # at 8 km/h, the delay applied
            az, _, dist = geod.inv(now[t][1], now[t][0], lon, lat)
            shifts.append((abs(az), dist))
            misses.append(geod.inv(now[before][1], now[before][0], lon, lat)[2])
    assert len(shifts) > 100
    # the point mapped is where the machine was mapped a second before, to a centimetre
    assert max(misses) < 0.01
    # back along the track (south), by 8 km/h x 1 s on average: 2.13 m measured, the fixes'
    # own error (0.8 m, drifting over a minute) moving them by a few cm a second
    assert all(az > 165.0 for az, _ in shifts)
    assert sum(d for _, d in shifts) / len(shifts) == pytest.approx(8.0 / 3.6, rel=0.06)


def test_a_volume_per_area_product_is_set_in_litres_by_the_density() -> None:
    link, _, port = _client_session(_spreader_pool(1, None), "[isobus]\ndensity_kg_l = 1.25\n")
    (p,) = link.products
    assert (p.setpoint_ddi, p.unit) == (1, "L/ha")
    # 200 kg/ha of a product of 1.25 kg/L: 160 L/ha, 16000 mm^3/m^2
    assert link.setpoints == (160.0,)
    assert port.values[(1, 1)] == 16000
    assert link.setpoint_latency_s() is None  # the configured look-ahead stays


def test_the_look_ahead_is_the_implements_delay_where_it_gives_one() -> None:
    cfg = loads_config("[lookahead]\ncommand_ms = 100\nmeter_ms = 400\nairline_ms = 600\n")
    rig = IsobusRig(cfg, _drive(8.0, 100.0))
    try:
        rig.run(6.0)
        tc = rig.term.can.tc
        assert tc is not None and tc.state == "ok"
        assert rig.term.ndvi.lookahead_s == pytest.approx(1.1)  # the pool gives none
        tc.latency_ms[142] = 750  # as a pool's DPT 142 gives it (read at connection)
        rig.run(6.2)
        assert rig.term.ndvi.lookahead_s == pytest.approx(0.85)  # command time + its delay
        assert rig.term.snapshot.isobus is not None
        assert rig.term.snapshot.isobus.lookahead_s == pytest.approx(0.85)
    finally:
        rig.close()


def test_with_send_on_gnss_a_fix_sends_the_rate_at_once() -> None:
    for send_on_gnss, want in ((True, 2), (False, 0)):
        cfg = loads_config(f"[can]\nsend_on_gnss = {str(send_on_gnss).lower()}\n")
        rig = IsobusRig(cfg, _drive(8.0, 100.0))
        try:
            rig.run(8.0)
            tc = rig.term.can.tc
            assert tc is not None and tc.state == "ok"
            sent = tc.counters.tx_commands
            t = rig.world.t_s + 0.05  # between two ticks, after the last fix
            line = nmea.rmc("GN", 36000.0 + t, True, 43.88, 125.32, 7.2 / 3.6, 90.0, "210526")
            rig.term.handle("nmea", t, line.encode())
            # both products' rates, in the handling of the line: no tick in between
            assert tc.counters.tx_commands - sent == want
        finally:
            rig.close()


def test_a_can_change_to_isobus_while_running_serves_the_implement() -> None:
    """The terminal started for the topdress ECU's frames on a bus where an ISOBUS implement
    is: nothing works; `[can] implement = "isobus"` applied while running puts the TC on the
    bus (opened anew in its thread), and the implement connects and is set the rate."""
    import time as wall

    rig = IsobusRig(loads_config(DEFAULT_TOML), _drive(8.0, 200.0), implement="topdress")
    try:
        rig.run(4.0)
        assert rig.term.can.tc is None and rig.term.snapshot.isobus is None
        assert rig.term.snapshot.ecu_link == "wait"
        fut = rig.term.post(ApplySettings("can", {"implement": "isobus"}))
        deadline = wall.monotonic() + 10.0
        while not fut.done() and wall.monotonic() < deadline:
            rig.run(rig.world.t_s + 0.1)
            wall.sleep(0.005)
        assert fut.done() and fut.result().ok, fut.result()
        rig.run(rig.world.t_s + 6.0)
        snap = rig.term.snapshot
    finally:
        rig.close()
    assert snap.isobus is not None and snap.isobus.state == "ok"
    assert snap.ecu_link == "ok"
    assert rig.sim.node.rate_kg_ha(0) == pytest.approx(snap.rate_kg_ha[0], abs=2.0)
    assert rig.sim.node.rate_kg_ha(0) > 50.0


def _driven_off_its_address(link: TcLink) -> None:
    """The TC claims 0xF7 (250 ms without a contest), then another TC with a NAME of lower
    value claims it too and wins: the link's TC goes on elsewhere (0.4 s more)."""
    t = 0.0
    for _ in range(40):
        t += 0.01
        link.poll(t, (False, 0.0, 0.0, 0.0))
    assert link.server.address == 0xF7
    other = tc_name(99) & ~0x1FFFFF & ~(0x7FF << 21)
    claim = can.Message(arbitration_id=6 << 26 | 0xEE00 << 8 | 0xFF << 8 | 0xF7)
    claim.data = bytearray(other.to_bytes(8, "little"))
    claim.dlc = 8
    link.on_frame(claim, t)
    for _ in range(40):
        t += 0.01
        link.poll(t, (False, 0.0, 0.0, 0.0))


def test_a_second_tc_taking_the_address_is_said_and_the_tc_goes_on_elsewhere() -> None:
    settings = Settings(loads_config('[can]\nimplement = "isobus"\n'))
    said: list[str] = []
    link = TcLink(_Port(), settings, Journal(None, lambda: 0.0, lambda e: said.append(str(e))))
    _driven_off_its_address(link)
    assert link.server.address not in (None, 0xF7)
    assert said[0] == "ISOBUS: Task Controller at address 0xF7"
    moved = f"ISOBUS: Task Controller moved from 0xF7 to 0x{link.server.address:02X}"
    assert any(moved in line for line in said), said
    assert "ISOBUS: another Task Controller at 0xf7, TC number 1" in said  # the server's word
    view = link.view(0.0)
    whats = {f.address: isobus_names.what(f, view) for f in view.functions}
    assert whats[0xF7] == "Task Controller (Mapping Computer)"  # the other TC, now there
    assert whats[link.server.address] == "task controller (this terminal)"


def test_the_tcs_words_are_in_the_operators_language() -> None:
    """What the TC link and server say are catalogue messages: Chinese on a Chinese screen,
    English in the session log and the program log."""
    settings = Settings(loads_config('[can]\nimplement = "isobus"\n'))
    said: list[Text] = []
    logged: list[str] = []
    journal = Journal(None, lambda: 0.0, said.append)
    journal.log_event = lambda t, kind, **d: logged.append(d.get("what", ""))  # type: ignore[method-assign]
    link = TcLink(_Port(), settings, journal)
    _driven_off_its_address(link)
    new = link.server.address
    assert new is not None
    zh = [render(m, "zh") for m in said]
    assert zh[0] == "ISOBUS：任务控制器地址 0xF7"
    assert "ISOBUS：总线上另有任务控制器，地址 0xf7，任务控制器编号 1" in zh
    assert f"ISOBUS：任务控制器从 0xF7 移至 0x{new:02X}：原地址被其他设备占用" in zh
    assert render(link.view(0.0).problem, "zh") in [z.removeprefix("ISOBUS：") for z in zh]
    # the session log keeps the English
    assert "another Task Controller at 0xf7, TC number 1" in logged
    assert f"Task Controller moved from 0xF7 to 0x{new:02X}: another took it" in logged


def test_the_servers_faults_render_in_both_languages() -> None:
    assert all(f"tc.pdack.{bit}" in CATALOGUE for bit in range(8))  # built at run time
    refused = text(
        "tc.pdack_refused", client=0x84, ddi=6, element=3,
        why=text("tc.and", a=pdack_texts(0x90)[0], b=pdack_texts(0x90)[1]),
    )  # fmt: skip
    assert str(refused) == (
        "client 0x84 refused DDI 6 of element 3: process data not settable, value outside the "
        "operational range"
    )
    assert (
        render(refused, "zh")
        == "客户端 0x84 拒绝了元素 3 的 DDI 6：过程数据不可设置，数值超出工作范围"
    )
    assert render(text("tc.silent", client=0x84, ms=6000), "zh") == "客户端 0x84 已 6000 ms 无响应"
    assert (
        render(text("tc.ack_again", client=0x84, n=6), "zh")
        == "客户端 0x84 恢复确认（此前缺少 6 次确认）"
    )


def test_an_ecu_setting_changed_with_an_isobus_implement_is_taken_without_a_push() -> None:
    # an implement that is not a topdress ECU (another manufacturer code in its NAME): it has no
    # topdress parameters (a topdress ECU's are pushed: tests/test_terminal_isobus_prop.py)
    cfg = loads_config(DEFAULT_TOML)
    rig = IsobusRig(replace(cfg, isobus=replace(cfg.isobus, ecu_manufacturer=5)), _drive(0.0, 0.0))
    try:
        rig.run(3.0)
        fut = rig.term.post(ApplySettings("speed", {"switch_speed_kmh": 7.0}))
        rig.run(3.2)
        assert fut.done() and fut.result().ok, fut.result()
        assert rig.term.cfg.speed.switch_speed_kmh == 7.0
    finally:
        rig.close()


def test_config_check_says_the_terminal_is_a_tc_and_warns_of_a_wrong_bitrate(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "t.toml"
    path.write_text('[can]\nimplement = "isobus"\nbitrate = 500000\n[isobus]\ntc_identity = 7\n')
    assert main(["config", "check", str(path)]) == 0
    out = capsys.readouterr().out
    assert "ISOBUS: the terminal is the Task Controller (address 0xF7, NAME identity 7)" in out
    assert "warning: can.bitrate 500000: an ISOBUS runs at 250000 bit/s" in out


def test_a_stored_pools_mapping_gives_what_the_link_needs() -> None:
    pool, _ = build(Machine.from_config(loads_config("").machine))
    ddis = known_ddis(map_device(pool))
    assert {6, 7, 81} <= ddis[3] and {6, 7, 81} <= ddis[4]
    assert {160, 161, 289, 290} <= ddis[2]  # the boom: section control, work states
    full, _ = pool_ddis(map_device(pool))
    assert all(v <= full[e] for e, v in ddis.items())  # nothing the pool does not carry
