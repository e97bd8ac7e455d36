"""The topdress ECU's private frames on an ISOBUS (terminal/proplink.py), in virtual time: the
terminal is the Task Controller of the simulated topdress ECU on ISOBUS (the C node and core,
topdress.sim.isobus) and speaks to it, from the TC's address, the parameter push, the catch test,
the GNSS speed with its age, and takes its Proprietary B broadcasts into the Snapshot; a foreign
implement gets none of it, and private frames from other addresses are ignored and counted."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from types import SimpleNamespace
from typing import Any, cast

import can
import pytest
from topdress.ecu._core import lib as ecu_lib

from term_rig import TerminalParts
from topdress import protocol
from topdress.config import DEFAULT_TOML, TerminalConfig, loads_config
from topdress.ecu.params import EcuParams, check
from topdress.i18n import Text, render, set_language
from topdress.i18n.catalogue import CATALOGUE
from topdress.isobus.ddop import Machine
from topdress.isobus.node import (
    Frame,
    IsobusNode,
    from_bus,
    name_of,
    split_id,
    to_bus,
    topdress_name,
)
from topdress.isobus.tcserver import Client
from topdress.protocol import AckResult
from topdress.protocol.dbc import frame_ids
from topdress.sim.actuators import MeterParams
from topdress.sim.isobus import IsobusMachine, tc_timeout_ms
from topdress.sim.tractor import Drive, Segment
from topdress.sim.world import SimConfig, World
from topdress.terminal.proplink import PropLink, not_topdress
from topdress.view import commands as op
from topdress.view.snapshot import Snapshot

TC, ECU, STRANGER = 0xF7, 0x84, 0x90
PROP_A, PROP_A2, GNSS_TIME_PGN, STATUS_PGN = 0xEF00, 0x1EF00, 0xFF62, 0xFF5C
PAPER_IDS = set(frame_ids().values())


def _ack(param_id: int, result: AckResult, raw: int) -> Frame:
    msg = protocol.database().get_message_by_name("EcuParamAck")
    data = msg.encode({"AckParamId": param_id, "AckResult": int(result), "AckRaw": raw})
    return Frame(msg.frame_id, bytes(data))


class PropRig(TerminalParts):
    """Terminal (the TC) + the topdress ECU on ISOBUS + the plant, one virtual clock (10 ms
    steps, the tick every 100 ms). Knobs: `manufacturer` (the ECU NAME's code), `refuse` (the
    ECU answers these parameters with a refusal instead of taking them), `deaf` (the ECU's
    core gets none of the terminal's private frames), `off` (the implement unplugged),
    `nmea_hold_s` (each NMEA line handled this long after it came), `extra` (frames of
    other nodes, on the bus at the next step whether the ECU is plugged or not), `tick_ms`
    (where in each 100 ms the terminal's tick falls: 0, 10, ... 90)."""

    def __init__(
        self,
        cfg: TerminalConfig,
        drive: Drive,
        manufacturer: int = 0,
        refuse: dict[int, AckResult] | None = None,
        meter: tuple[MeterParams, MeterParams] | None = None,
        gnss_from_tc: bool = False,
    ) -> None:
        sim = SimConfig.of_machine(cfg) if meter is None else SimConfig.of_machine(cfg, meter=meter)
        self.world = World(sim, seed=5, drive=drive)
        node = IsobusNode(
            topdress_name(manufacturer, b"prop-rig"),
            tc_timeout_ms=tc_timeout_ms(self.world.ecu.params.cmd_timeout_ms),
        )
        m = cfg.machine
        sections = Machine.from_config(m).sections
        self.sim = IsobusMachine(self.world, node, m.width_m, sections, m.fan_rpm, gnss_from_tc)
        self.refuse = refuse or {}
        self.deaf = False
        self.off = False
        self.nmea_hold_s = 0.0
        self.tick_ms = 0
        self.bus_log: list[tuple[float, Frame]] = []  # every frame the terminal sent
        self.ecu_log: list[tuple[float, Frame]] = []  # every frame the implement sent
        self.extra: list[Frame] = []
        self.snapshots: list[tuple[float, Snapshot]] = []
        self.node_rates: list[tuple[float, float, float]] = []
        self.peak_kg_ha = 0.0  # the highest rate the ECU's core was told, any step
        self._held: list[tuple[str, float, object]] = []
        super().__init__(cfg, lambda: self.world.t_s, None, "isobus")

    def _to_ecu(self, heard: list[Frame]) -> tuple[list[Frame], list[Frame]]:
        """What the node gets, and the refusals the ECU answers in place of its core."""
        node, passed, answers = self.sim.node, [], []
        for f in heard:
            core = None
            if split_id(f.can_id)[1] == PROP_A:
                core = from_bus(f, by_ecu=False, peer=TC, my_address=ECU)
            if core is not None and (self.deaf or core.can_id == frame_ids()["PcParamSet"]):
                decoded = protocol.decode((core.can_id, core.data))
                assert isinstance(decoded, protocol.PcParamSet)
                result = self.refuse.get(decoded.param_id)
                if self.deaf:
                    node.rx(f.can_id, f.data, self.world.now_us)  # the node hears, not the core
                    continue
                if result is not None:
                    spec = protocol.param(decoded.param_id)
                    held = self.world.ecu.params.get(decoded.param_id)
                    ack = node.prop_tx(_ack(decoded.param_id, result, spec.to_raw(held)))
                    assert ack is not None
                    answers.append(ack)
                    continue
            passed.append(f)
        return passed, answers

    def run(self, until_s: float) -> None:
        w, term = self.world, self.term
        while w.t_s < until_s - 1e-9:
            heard = []
            while (msg := self.ecu_bus.recv(timeout=0)) is not None:
                f = Frame(msg.arbitration_id, bytes(msg.data))
                heard.append(f)
                self.bus_log.append((w.t_s, f))
            passed, answers = self._to_ecu(heard)
            frames = self.sim.step([] if self.off else passed) + answers
            self.ecu_log += [(w.t_s, f) for f in frames]
            node = self.sim.node
            self.peak_kg_ha = max(self.peak_kg_ha, node.rate_kg_ha(0), node.rate_kg_ha(1))
            out = self.sim.out
            assert out is not None
            t = out.t_s
            others, self.extra = self.extra, []  # other nodes are on the bus, plugged or not
            msgs = (can.Message(arbitration_id=f.can_id, data=f.data, is_extended_id=True)
                    for f in ([] if self.off else frames) + others)  # fmt: skip
            self.deliver(t, out.nmea, out.crop, msgs)
            self._handle(t)
            if round(t * 1000) % 100 == self.tick_ms:
                term.tick(t)
                self.snapshots.append((t, term.snapshot))
                node = self.sim.node
                self.node_rates.append((t, node.rate_kg_ha(0), node.rate_kg_ha(1)))

    def reboot(self) -> None:
        """The ECU restarts at once (a watchdog reset): core on its defaults, node unclaimed."""
        w, node = self.world, self.sim.node
        check(ecu_lib.td_app_init(w.ecu._app, EcuParams.defaults().to_c(), w.now_us), "reboot")
        node.__init__(node.name, tc_timeout_ms=tc_timeout_ms(w.ecu.params.cmd_timeout_ms))  # type: ignore[misc]
        node.start(w.now_us)

    def _handle(self, t: float) -> None:
        term = self.term
        while not term.inbox.empty():
            item = term.inbox.get()
            if item is not None and item[0] == "nmea" and self.nmea_hold_s > 0.0:
                self._held.append(item)
            elif item is not None:
                term.handle(*item)
        while self._held and self._held[0][1] <= t - self.nmea_hold_s + 1e-9:
            term.handle(*self._held.pop(0))

    def sent(self, pgn: int) -> list[tuple[float, Frame]]:
        """The terminal's frames on `pgn` (all from the TC's address)."""
        return [(t, f) for t, f in self.bus_log if split_id(f.can_id)[1] == pgn]

    def post(self, command: object) -> op.CommandResult:
        fut = self.term.post(command)
        self.run(self.world.t_s + 0.2)
        assert fut.done()
        return fut.result()


def _cfg(extra: str = "") -> TerminalConfig:
    return loads_config(DEFAULT_TOML + extra)


def _drive(speed_kmh: float = 8.0, length_m: float = 40.0) -> Drive:
    return Drive(
        [
            Segment("stop", duration_s=4.0),
            Segment("straight", speed_kmh=speed_kmh, length_m=length_m, hold=True),
            Segment("stop", duration_s=30.0),
        ]
    )


def _decoded(rig: PropRig, pgn: int) -> list[tuple[float, Any]]:
    out: list[tuple[float, Any]] = []
    for t, f in rig.sent(pgn):
        core = from_bus(f, by_ecu=False, peer=TC, my_address=ECU)
        assert core is not None
        out.append((t, protocol.decode((core.can_id, core.data))))
    return out


def test_a_topdress_ecu_is_recognised_by_its_name_and_ddop() -> None:
    ours = topdress_name(0, b"x")
    assert not_topdress(ours, "topdress", 0) is None
    assert "manufacturer is 0, not 7" in str(not_topdress(ours, "topdress", 7))
    assert "DDOP is 'Spreader'" in str(not_topdress(ours, "Spreader", 0))
    assert str(not_topdress(None, "topdress", 0)) == "no NAME heard from it"
    # a spreader of another kind (function 131) with the same maker and designator
    other = name_of(industry_group=2, device_class=5, function=131, self_configurable=1)
    assert "function 131" in str(not_topdress(other, "topdress", 0))


@dataclass
class _Tc:
    """The Task Controller as the PropLink sees it (proplink.Served)."""

    client: Client | None
    address: int | None = TC
    names: dict[int, int] = field(default_factory=dict)
    counters: dict[str, int] = field(default_factory=lambda: {"activations": 1})


def test_why_an_implement_is_not_a_topdress_ecu_is_said_in_the_operators_language() -> None:
    ours, spreader = topdress_name(0, b"x"), name_of(industry_group=2, device_class=5, function=131)
    said: list[Text | str] = []
    tc = _Tc(Client(STRANGER, 0, device=cast(Any, SimpleNamespace(designator="Spreader")),
                    active=True, name=spreader))  # fmt: skip
    link = PropLink(cast(Any, None), tc, 0, say=said.append)
    link.watch()
    tc.client = Client(ECU, 0, device=cast(Any, SimpleNamespace(designator="topdress")),
                       active=True, name=ours)  # fmt: skip
    tc.names[ECU] = ours  # its address claim
    assert link.watch() == "first" and link.serving
    set_language("zh")
    try:
        assert [render(s) for s in said] == [
            "地址 0x90 的机具不是 topdress 控制器（其 NAME 为行业组 2、设备类 5、功能 131）",
            "地址 0x84 的机具是 topdress 控制器：使用其专有帧",
        ]
        assert render(not_topdress(ours, "topdress", 7)) == "其 NAME 的制造商代码为 0，而非 7"
        assert render(not_topdress(ours, "Spreader", 0)) == "其 DDOP 为“Spreader”，而非“topdress”"
        assert render(not_topdress(None, "topdress", 0)) == "未收到其 NAME"
    finally:
        set_language("en")


def test_parameters_pushed_on_proprietary_a_and_acknowledged_then_the_ecus_frames() -> None:
    cfg = _cfg("")
    cfg = replace(
        cfg,
        machine=replace(cfg.machine, kg_per_rev_lower=0.25),
        speed=replace(cfg.speed, queue_len=7),
    )
    rig = PropRig(cfg, _drive())
    try:
        rig.run(14.0)
        link = rig.term.link
        params = rig.term.cfg.ecu_params(None)  # no GNSS lag known yet at the push
        snaps = rig.snapshots
    finally:
        rig.close()
    assert link.isobus and link.params_done and link.ready
    # in force in the ECU's core
    p = rig.world.ecu.params
    assert p.kg_per_rev[1] == pytest.approx(0.25) and p.queue_len == 7
    # every PcParamSet on Proprietary A from the TC to the ECU, one each, none retried
    sets = _decoded(rig, PROP_A)
    assert [d.param_id for _, d in sets] == sorted(params)
    assert {split_id(f.can_id)[2:] for _, f in rig.sent(PROP_A)} == {(TC, ECU)}
    assert link.counters.tx_params == len(params) and link.counters.param_retries == 0
    # no paper identifier and no PcCommand on the ISOBUS
    assert not [f for _, f in rig.bus_log if f.can_id in PAPER_IDS]
    # the TC held the implement at rate 0 until the last parameter was acknowledged
    last_set = sets[-1][0]
    assert all(u == 0.0 and lo == 0.0 for t, u, lo in rig.node_rates if t <= last_set)
    assert max(u for _, u, _ in rig.node_rates) > 50.0
    # PcGnssTime on Proprietary B from the TC, taken by the ECU's core
    gnss = _decoded(rig, GNSS_TIME_PGN)
    assert len(gnss) > 50
    last = gnss[-1][1]
    assert isinstance(last, protocol.PcGnssTime)
    assert last.gnss_kmh == pytest.approx(8.0, abs=0.3)  # still on the pass
    # the node handed the core every private frame from the TC, and the core took them
    assert rig.sim.node.counters["prop_rx"] == len(sets) + len(gnss)
    assert rig.sim.node.counters["prop_wrong_source"] == 0
    c = rig.world.ecu.counters
    assert c.rx_bad_length == 0 and c.rx_out_of_range == 0 and c.rx_param_rejected == 0
    # the ECU's broadcasts in the Snapshot's fields, as on its own bus
    moving = [s for t, s in snaps if s.v_wheel_kmh > 7.0]
    assert len(moving) > 10
    s = moving[len(moving) // 2]
    assert s.source in ("gnss", "wheel", "fused") and s.cv_pct is not None
    assert min(s.fan_rpm) > 1000.0 and s.faults == 0
    assert s.v_kmh == pytest.approx(8.0, abs=0.5)
    assert s.counters["prop_rx"] > 100 and "prop_wrong_source" not in s.counters


def test_the_ecus_fault_word_on_proprietary_b_raises_its_alarm() -> None:
    # the lower meter jams 12 s in: the ECU latches "blocked" in its EcuDiag (Proprietary B),
    # which the TC's process data does not carry
    rig = PropRig(_cfg(""), _drive(8.0, 80.0), meter=(MeterParams(), MeterParams(jammed_at_s=12.0)))
    try:
        rig.run(16.0)
        snap = rig.term.snapshot
    finally:
        rig.close()
    assert snap.faults != 0
    alarms = {a.name: a.state for a in snap.alarms}
    assert alarms.get("blocked_lower") == "active", alarms
    assert "blocked_upper" not in alarms


def _applied_error_pct(manufacturer: int) -> float:
    """What the implement applied (its DDI 7, from the plant's truth) against the TC's setpoint
    over a steady 8 km/h pass, the ECU's core given only what the ISOBUS firmware gives it."""
    rig = PropRig(_cfg(""), _drive(8.0, 80.0), manufacturer=manufacturer, gnss_from_tc=True)
    try:
        rig.run(36.0)
    finally:
        rig.close()
    steady = [s.isobus.products for t, s in rig.snapshots if t >= 15.0 and s.isobus is not None]
    assert len(steady) > 150
    actual = sum(p.actual or 0.0 for ps in steady for p in ps)
    setpoint = sum(p.setpoint for ps in steady for p in ps)
    return 100.0 * (actual / setpoint - 1.0)


def test_the_terminals_gnss_speed_lets_the_ecu_meter_through_wheel_slip() -> None:
    # the firmware's command carries the terminal's PcGnssTime from the TC (fw_isobus.c): a
    # topdress ECU recognised gets it and meters the set rate; the same ECU under another
    # manufacturer code gets no private frame and runs on its slipping wheel
    assert abs(_applied_error_pct(0)) < 1.0
    assert _applied_error_pct(7) < -5.0


def test_the_gnss_speed_goes_with_the_fixs_true_age() -> None:
    rig = PropRig(_cfg(""), _drive())
    rig.nmea_hold_s = 0.3  # every NMEA line waits 300 ms in the terminal's inbox
    try:
        rig.run(10.0)
    finally:
        rig.close()
    ages = [d.age_ms for _, d in _decoded(rig, GNSS_TIME_PGN)]
    assert len(ages) > 20
    assert all(290 <= a <= 310 for a in ages), ages[:10]


def test_an_ecu_busy_metering_is_stopped_by_the_tcs_work_state_then_takes_the_value() -> None:
    rig = PropRig(_cfg(""), _drive(8.0, 80.0))
    try:
        rig.run(12.0)
        assert rig.sim.running  # metering at the TC's rate
        told: list[str | None] = []
        switch = protocol.param("SwitchSpeed").id
        rig.term.link.push_params({switch: 7.0}, 12.0, lambda why, ids: told.append(why))
        pushed_at = len(rig.node_rates)
        rig.run(14.0)
    finally:
        rig.close()
    acks = []
    for t, f in rig.ecu_log:
        if split_id(f.can_id)[1] == PROP_A and t >= 12.0:
            core = from_bus(f, by_ecu=True, peer=ECU, my_address=TC)
            assert core is not None
            acks.append(protocol.decode((core.can_id, core.data)))
    # Busy while metering: no PcCommand on an ISOBUS; the TC's rate 0 stopped it, then Ok
    results = [a.result for a in acks if isinstance(a, protocol.EcuParamAck)]
    assert results[0] is AckResult.BUSY and results[-1] is AckResult.OK, results
    assert results.count(AckResult.BUSY) <= 2, results  # asked again after 0.2 s, not at once
    assert told == [None] and rig.world.ecu.params.switch_speed_kmh == pytest.approx(7.0)
    after = rig.node_rates[pushed_at:]
    assert min(u for _, u, _ in after) == 0.0 and after[-1][1] > 50.0  # held, then metering
    assert not [f for _, f in rig.bus_log if f.can_id in PAPER_IDS]


def test_a_refused_parameter_is_an_alarm_naming_it_and_the_tc_holds_the_implement() -> None:
    # on its own bus a refusal at start ends the program; on an ISOBUS the ECU may be recognised
    # mid-field: the TC goes on (its other implements' links too), this one held at rate 0
    lag_auto = protocol.param("GnssLagAuto").id
    rig = PropRig(_cfg(""), _drive(8.0, 80.0), refuse={lag_auto: AckResult.OUT_OF_RANGE})
    try:
        rig.run(6.0)  # on the pass
        link, can_ = rig.term.link, rig.term.can
        assert not link.params_done
        sets = len(rig.sent(PROP_A))
        assert rig.post(op.Stop()).ok and rig.post(op.Start()).ok  # sent off the tick: held too
        rig.run(12.0)
        snap = rig.term.snapshot
        assert can_.tc is not None and can_.tc.state == "ok"
        assert len(rig.sent(PROP_A)) == sets  # the refused one is not asked again and again
        peak = rig.peak_kg_ha
        # its firmware mended, it connects again: pushed from the top, then it meters
        del rig.refuse[lag_auto]
        rig.reboot()
        rig.run(16.0)
        back = rig.term.snapshot
        assert link.params_done and rig.node_rates[-1][1] > 50.0
    finally:
        rig.close()
    assert {a.name: a.state for a in back.alarms}["ecu_param_refused"] == "cleared"
    alarms = {a.name: a for a in snap.alarms}
    refused = alarms["ecu_param_refused"]
    assert refused.state == "active"
    assert str(refused.text) == (
        "the ECU refused its parameter GnssLagAuto = 1 (out of range): "
        "the implement is held at rate 0"
    )
    said = [e for _, e in rig.events]
    assert any("GnssLagAuto = 1: refused by the ECU: out of range" in e for e in said), said
    # the loop went on: the TC's status, the GNSS link, the implement commanded to rate 0
    assert snap.t_s > 11.5 and snap.gnss_link == "ok" and snap.v_kmh == pytest.approx(8.0, abs=0.5)
    assert peak == 0.0 and snap.ecu_link == "wait"
    status = [t for t, f in rig.bus_log if split_id(f.can_id)[1] == 0xCB00 and 6.0 < t < 12.0]
    assert status, "the TC status went on"
    set_language("zh")
    try:
        zh = "控制器拒绝参数 GnssLagAuto = 1（超出范围）：机具施肥量保持为 0"
        assert render(refused.text) == zh
    finally:
        set_language("en")
    for r in AckResult:  # each refusal's reason, in both languages
        assert r in (AckResult.OK, AckResult.BUSY) or f"ecu.ack.{r.name.lower()}" in CATALOGUE


def test_a_refused_setting_is_told_and_the_old_value_stays() -> None:
    rig = PropRig(_cfg(""), _drive(0.0, 0.0))
    try:
        rig.run(3.0)
        assert rig.term.link.params_done
        assert rig.post(op.Stop()).ok
        rig.refuse[protocol.param("SwitchSpeed").id] = AckResult.OUT_OF_RANGE
        result = rig.post(op.ApplySettings("speed", {"switch_speed_kmh": 7.0}))
        assert not result.ok and "SwitchSpeed = 7: refused by the ECU" in str(result.message)
        assert rig.term.cfg.speed.switch_speed_kmh == 6.0
        del rig.refuse[protocol.param("SwitchSpeed").id]
        result = rig.post(op.ApplySettings("speed", {"switch_speed_kmh": 7.5}))
        assert result.ok, result
        assert rig.world.ecu.params.switch_speed_kmh == pytest.approx(7.5)
    finally:
        rig.close()


def test_an_ecu_that_does_not_answer_is_waited_for_and_the_push_goes_on() -> None:
    rig = PropRig(_cfg(""), _drive())
    rig.deaf = True  # its core gets no private frame: no acknowledge
    try:
        rig.run(5.0)
        link = rig.term.link
        assert not link.params_done
        assert link.counters.param_retries >= 4  # 3 fast retries, then the backoff
        said = [e for _, e in rig.events]
        wait = "ECU wait: WorkingWidth unacknowledged after 4 tries"
        assert any(e.startswith(wait) and "does not answer" in e for e in said), said
        # held at rate 0 meanwhile, also when the operator starts again (sent off the tick)
        assert rig.post(op.Stop()).ok and rig.post(op.Start()).ok
        assert rig.peak_kg_ha == 0.0
        assert rig.term.snapshot.ecu_link == "wait"  # the TC serves it, its parameters are not in
        rig.deaf = False
        rig.run(9.0)
        assert link.params_done
        assert any(e.startswith("ECU ready: every parameter") for _, e in rig.events)
        assert rig.term.snapshot.ecu_link == "ok"
        assert rig.node_rates[-1][1] > 0.0  # the implement meters now
    finally:
        rig.close()


def test_an_ecu_lost_and_back_is_given_its_parameters_again() -> None:
    rig = PropRig(_cfg(""), _drive(8.0, 80.0))
    try:
        rig.run(6.0)
        link = rig.term.link
        assert link.params_done
        pushed = link.counters.tx_params
        rig.off = True  # unplugged: hears nothing, says nothing
        rig.run(9.0)
        assert link.state == "lost" and link.counters.ecu_lost == 1
        rig.off = False
        rig.run(16.0)
        assert link.state == "ok" and link.params_done
        assert link.counters.tx_params >= 2 * pushed  # every parameter again
        said = [e for _, e in rig.events]
        assert any("ECU lost" in e for e in said) and any("ECU back" in e for e in said), said
    finally:
        rig.close()


@pytest.mark.parametrize("tick_ms", range(0, 100, 10))
def test_the_ecu_says_who_it_is_once_connected_to_the_tc(tick_ms: int) -> None:
    # its core's first EcuIdent goes out before the node has an address, to no one: the port
    # announces it again once the node is connected to its TC (td_app_announce), about 10 ms
    # after its pool is activated: heard wherever the terminal's tick falls
    rig = PropRig(_cfg(""), _drive())
    rig.tick_ms = tick_ms
    try:
        rig.run(3.0)
        ident = rig.term.link.ecu.ident
        said = [e for _, e in rig.events]
    finally:
        rig.close()
    assert ident is not None and ident.target == "host" and ident.transport == "in-process"
    assert ident.protocol == protocol.protocol_version()
    assert f"ECU: host firmware {ident.firmware_version}, protocol 1.1 (in-process)" in said, said


def test_an_ecu_that_rebooted_faster_than_its_loss_is_given_its_parameters_again() -> None:
    # its new connection to the TC says it (and its EcuIdent, on its defaults, after that)
    cfg = _cfg("")
    rig = PropRig(replace(cfg, machine=replace(cfg.machine, kg_per_rev_lower=0.25)), _drive())
    try:
        rig.run(3.0)
        link = rig.term.link
        assert link.params_done and rig.world.ecu.params.kg_per_rev[1] == pytest.approx(0.25)
        rig.reboot()
        rig.run(3.3)
        assert rig.world.ecu.params.kg_per_rev[1] == pytest.approx(0.3)  # on its defaults
        rig.run(6.0)
        assert link.counters.ecu_lost == 0  # never unheard for ecu_timeout_s
        assert link.counters.ecu_restarts == 1 and link.params_done
        assert rig.world.ecu.params.kg_per_rev[1] == pytest.approx(0.25)
        said = [e for _, e in rig.events]
        assert "ECU connected to the Task Controller again: its parameters are sent again" in said
    finally:
        rig.close()


def test_a_catch_test_runs_over_isobus_end_to_end() -> None:
    rig = PropRig(_cfg(""), Drive([Segment("stop", duration_s=60.0)]))
    try:
        rig.run(3.0)
        assert rig.post(op.Stop()).ok
        started = rig.post(op.StartCatchTest("upper", revolutions=5.0, meter_rpm=30.0))
        assert started.ok, started
        rig.run(rig.world.t_s + 15.0)
        cal = rig.term.snapshot.calibration
        assert cal is not None and cal.step == "weigh", cal
        revs = rig.term.desk.cal.wizard.revolutions  # type: ignore[union-attr]
        assert revs == pytest.approx(5.0, abs=0.3)
        assert rig.post(op.FinishCatchTest(weighed_kg=1.5)).ok
        cal = rig.term.snapshot.calibration
        assert cal is not None and cal.result["kg_per_rev"] == pytest.approx(1.5 / revs)
        assert rig.post(op.CloseCalibration(apply=False)).ok
        # the fan check needs a PcCommand: refused on an ISOBUS, saying why
        fan = rig.post(op.StartFanCheck())
        assert not fan.ok and "ISOBUS does not carry" in str(fan.message)
    finally:
        rig.close()
    cmds = _decoded(rig, PROP_A2)
    assert cmds and all(isinstance(d, protocol.PcCalCommand) for _, d in cmds)
    assert {split_id(f.can_id)[2:] for _, f in rig.sent(PROP_A2)} == {(TC, ECU)}
    # the meter turned standing, by the ECU's catch test (the truth of the plant)
    assert rig.world.truth.v_kmh == 0.0


def test_a_wheel_calibration_counts_the_ecus_pulses_from_proprietary_b() -> None:
    rig = PropRig(_cfg(""), _drive(6.0, 40.0))  # 4 s standing, then about 40 m
    try:
        rig.run(3.0)
        assert rig.post(op.Stop()).ok
        assert rig.post(op.StartWheelCal(distance_m=40.0)).ok
        y0 = rig.world.truth.y_m
        rig.run(10.0)
        while rig.world.truth.v_kmh > 0.0 and rig.world.t_s < 60.0:
            rig.run(rig.world.t_s + 0.5)
        driven_m = rig.world.truth.y_m - y0  # as the operator measures it on the ground
        assert rig.post(op.FinishWheelCal(distance_m=driven_m)).ok
        cal = rig.term.snapshot.calibration
    finally:
        rig.close()
    assert cal is not None and cal.step == "done", cal
    assert driven_m > 35.0
    radius = rig.cfg.machine.wheel_radius_m
    # the ECU's pulses (EcuDiag) give the wheel's radius within its slip; GNSS the distance
    assert cal.result["pulses"] > 0 and cal.result["radius_m"] == pytest.approx(radius, rel=0.12)
    assert cal.result["gnss_distance_m"] == pytest.approx(driven_m, rel=0.03)


def test_an_implement_that_is_not_a_topdress_ecu_gets_no_private_frame() -> None:
    rig = PropRig(_cfg(""), _drive(), manufacturer=7)  # another maker's code in its NAME
    try:
        rig.run(10.0)
        link, prop = rig.term.link, rig.term.can.prop
        assert prop is not None and not prop.serving
        assert "manufacturer is 7, not 0" in str(prop.why)
        assert rig.post(op.Stop()).ok
        refused = rig.post(op.StartCatchTest("upper"))
    finally:
        rig.close()
    assert not link.params_done and link.counters.tx_params == 0
    ours = [f for _, f in rig.bus_log if split_id(f.can_id)[1] in (PROP_A, PROP_A2)]
    assert not ours and not rig.sent(GNSS_TIME_PGN)
    assert max(u for _, u, _ in rig.node_rates) > 50.0  # the TC sets its rates, not held
    assert not refused.ok and "not one" in str(refused.message)
    set_language("zh")
    try:
        assert "其 NAME 的制造商代码为 7，而非 0" in render(refused.message)
    finally:
        set_language("en")
    assert prop.counters.wrong_source == 0  # its broadcasts are not looked at


def test_private_frames_from_other_addresses_and_bad_frames_are_counted_not_taken() -> None:
    rig = PropRig(_cfg(""), _drive(0.0, 0.0))
    try:
        rig.run(0.5)  # the push is under way
        stranger_ack = _ack(protocol.param("WorkingWidth").id, AckResult.OUT_OF_RANGE, 360)
        bad_status = Frame(frame_ids()["EcuStatus"], bytes([1, 2, 3]))
        forged = [
            to_bus(stranger_ack, by_ecu=True, sa=STRANGER, da=TC),
            to_bus(Frame(frame_ids()["EcuStatus"], bytes(8)), by_ecu=True, sa=STRANGER),
        ]
        rig.extra = [f for f in forged if f is not None] * 3
        rig.run(0.7)
        short = to_bus(bad_status, by_ecu=True, sa=ECU)
        assert short is not None
        rig.extra = [short]
        rig.run(3.0)
        link, prop = rig.term.link, rig.term.can.prop
        assert prop is not None
        assert prop.counters.wrong_source == 6
        assert link.counters.rx_malformed == 1
        assert link.params_done  # the forged refusal did not stop the push
        snap = rig.term.snapshot
        assert snap.counters["prop_wrong_source"] == 6 and snap.counters["prop_bad"] == 1
    finally:
        rig.close()


def test_a_can_change_from_isobus_to_the_ecus_own_bus_pushes_there_with_the_paper_frames() -> None:
    import time as wall

    rig = PropRig(_cfg(""), _drive(0.0, 0.0))
    try:
        rig.run(2.0)
        assert rig.term.link.isobus and rig.term.link.params_done
        fut = rig.term.post(op.ApplySettings("can", {"implement": "topdress"}))
        deadline = wall.monotonic() + 10.0
        while not fut.done() and wall.monotonic() < deadline:  # the bus opens in its thread
            rig.run(rig.world.t_s + 0.1)
            wall.sleep(0.005)
        assert fut.done() and fut.result().ok, fut.result()
        since = rig.world.t_s
        rig.run(since + 1.0)
        link = rig.term.link
    finally:
        rig.close()
    assert rig.term.can.tc is None and rig.term.can.prop is None and not link.isobus
    # its own push, with the paper's identifiers (the ISOBUS ECU there does not answer them)
    sets = [f for t, f in rig.bus_log if t >= since and f.can_id == frame_ids()["PcParamSet"]]
    assert sets and not link.params_done and rig.term.snapshot.ecu_link == "wait"


def _claim(sa: int, name: int) -> Frame:
    """An address claim (PGN 0xEE00) of `name` at `sa`."""
    return Frame(6 << 26 | 0xEEFF << 8 | sa, name.to_bytes(8, "little"))


def test_another_implement_at_the_ecus_address_gets_and_gives_no_private_frame() -> None:
    # the topdress ECU is unplugged; another maker's implement claims its address and sends on
    # the Proprietary B group extension of the ECU's EcuStatus (0x18FF5C84)
    rig = PropRig(_cfg(""), _drive(0.0, 0.0))
    try:
        rig.run(3.0)
        link, prop = rig.term.link, rig.term.can.prop
        assert prop is not None and prop.serving and link.params_done
        pushed = link.counters.tx_params
        rig.off = True
        rig.run(4.0)
        assert link.state == "lost"
        foreign = name_of(industry_group=2, device_class=5, function=128, manufacturer_code=7)
        status = to_bus(Frame(frame_ids()["EcuStatus"], bytes(8)), by_ecu=True, sa=ECU)
        assert status is not None and split_id(status.can_id)[1:3] == (STATUS_PGN, ECU)
        rig.extra = [_claim(ECU, foreign)]
        rig.run(4.1)
        since = rig.world.t_s
        assert not prop.serving  # its client was displaced, its NAME is not ours
        for _ in range(10):
            rig.extra = [status]
            rig.run(rig.world.t_s + 0.1)
        assert link.state == "lost" and link.ecu.status_t is not None
        assert link.ecu.status_t < since  # its frames are not the ECU's
        assert not link.send(protocol.encode_param_set(protocol.param("SwitchSpeed").id, 6.0))
        assert not [f for t, f in rig.bus_log if t >= since and split_id(f.can_id)[1] == PROP_A]
        assert prop.counters.tx_refused > 0 and prop.counters.wrong_source == 0
        assert not any("ECU back" in e for _, e in rig.events)
        # the topdress ECU plugged in again (it starts over): served again, given its parameters
        rig.off = False
        rig.reboot()
        rig.run(rig.world.t_s + 4.0)
        assert prop.serving and link.state == "ok" and link.params_done
        assert link.counters.tx_params >= 2 * pushed
        assert any("ECU back" in e for _, e in rig.events)
    finally:
        rig.close()


def test_a_setting_changed_while_another_implement_is_served_reaches_the_ecu_back() -> None:
    cfg = _cfg("")
    rig = PropRig(replace(cfg, machine=replace(cfg.machine, kg_per_rev_lower=0.28)), _drive())
    try:
        rig.run(3.0)
        assert rig.world.ecu.params.kg_per_rev[1] == pytest.approx(0.28)
        rig.off = True  # unplugged; another maker's implement takes its address
        foreign = name_of(industry_group=2, device_class=5, function=128, manufacturer_code=7)
        rig.extra = [_claim(ECU, foreign)]
        rig.run(4.0)
        prop = rig.term.can.prop
        assert prop is not None and not prop.serving and not rig.term.can.pushes_params
        # that implement has no topdress parameters: the change is taken as it is
        result = rig.post(op.ApplySettings("machine", {"kg_per_rev_lower": 0.25}))
        assert result.ok, result
        assert rig.term.cfg.machine.kg_per_rev_lower == 0.25
        sets_before = len(rig.sent(PROP_A))
        rig.off = False  # the topdress ECU plugged in again, on its defaults
        rig.reboot()
        rig.run(rig.world.t_s + 4.0)
        link = rig.term.link
        assert prop.serving and link.params_done
    finally:
        rig.close()
    assert rig.world.ecu.params.kg_per_rev[1] == pytest.approx(0.25)  # the new value, not 0.28
    lower = protocol.param("LowerKgPerRev").id
    again = [d for _, d in _decoded(rig, PROP_A)[sets_before:] if d.param_id == lower]
    assert [d.value for d in again] == [pytest.approx(0.25)]


def test_a_refused_parameter_mended_in_the_settings_is_pushed_again_from_the_top() -> None:
    switch = protocol.param("SwitchSpeed").id
    rig = PropRig(_cfg(""), _drive(0.0, 0.0), refuse={switch: AckResult.OUT_OF_RANGE})
    try:
        rig.run(3.0)
        link = rig.term.link
        assert rig.term.can.refused is not None and not link.params_done
        del rig.refuse[switch]  # the ECU takes the value the operator puts in its place
        result = rig.post(op.ApplySettings("speed", {"switch_speed_kmh": 7.0}))
        assert result.ok, result
        rig.run(rig.world.t_s + 2.0)
        snap = rig.term.snapshot
    finally:
        rig.close()
    assert link.params_done and rig.term.can.refused is None
    assert rig.world.ecu.params.switch_speed_kmh == pytest.approx(7.0)
    assert rig.term.cfg.speed.switch_speed_kmh == 7.0
    assert {a.name: a.state for a in snap.alarms}["ecu_param_refused"] == "cleared"
