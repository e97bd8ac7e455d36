"""The simulated topdress ECU on ISOBUS, with a Task Controller in front of it.

`topdress demo --isobus` (`run_terminal_isobus_demo`): the terminal, unchanged, is the Task
Controller. The machine (the World, its ECU on ISOBUS: topdress.sim.isobus) runs paced to the
wall clock in its own thread, on the demo's pseudo-terminals (GNSS and crop sensors) and an
in-process python-can bus; the terminal runs with `[can] implement = "isobus"`, so the
crop-sensor rate reaches the implement's setpoint DDI and what the implement reports comes back
into the console and the terminal's session log. At the end it says what the implement applied
against what the terminal set, from that log.

`run_isobus_demo`: the implement alone with a scripted Task Controller (the terminal's TC
server setting fixed rates, topdress.sim.tc), on virtual time or paced, for the node's faults.

Either way the implement keeps a session log of its own (topdress.log, `isobus*.sqlite` in the
output folder): every frame both ways (the ECU's as can_rx, the Task Controller's as can_tx)
and the node's events (isobus.claimed, isobus.ddop, isobus.set, isobus.tc_lost, ...), for
`topdress log export` and `replay`; the node's faults are said on the console."""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import TextIO

import can
import tomlkit

from topdress.cli.demo import _check_out_dir, demo_config_toml, run_terminal
from topdress.config import TerminalConfig, loads_config, redacted_text
from topdress.devices.can import open_bus
from topdress.errors import DeviceError
from topdress.isobus.ddop import DDI_TOTAL_MASS, Machine, build
from topdress.isobus.node import Frame, IsobusNode, topdress_name
from topdress.log.isobus import IsobusWatch
from topdress.log.model import LogEvent
from topdress.log.session import SessionLog, SessionReader
from topdress.log.summary import summarise
from topdress.sim.isobus import ELEMENT_BINS, IsobusMachine, tc_timeout_ms
from topdress.sim.live import LiveMachine
from topdress.sim.tc import MiniTc
from topdress.sim.tractor import Drive
from topdress.sim.world import SimConfig, World
from topdress.view.snapshot import Snapshot

MANUFACTURER_CODE = 0  # reserved/unassigned: set your own for a real bus
DEMO_UID = b"topdress-demo"
RATES_KG_HA = (150.0, 100.0)
ALL_ON = -4096 + 0x555  # condensed work state: sections 1-6 on, 7-16 not installed
#: The demo's field work: 40 m passes at 7 km/h with a headland turn between them.
DEMO_PASSES, DEMO_PASS_M, DEMO_SPEED_KMH = 30, 40.0, 7.0
REPORT_S = 5.0
#: Applied within this of what the setpoints asked for is "at the terminal's rate" (the
#: start from rest, the first seconds, is where the rest of it goes).
RATE_TOLERANCE_PCT = 3.0


def _record(log: SessionLog, kind: str, t: float, frames: list[Frame]) -> None:
    for f in frames:
        log.raw(kind, t, (f.can_id, f.data))


def _demo_machine(cfg: TerminalConfig, seed: int) -> tuple[World, IsobusNode, IsobusMachine]:
    """The demo's field passes and the topdress implement on ISOBUS driving them."""
    drive = Drive.field_passes(DEMO_PASSES, DEMO_PASS_M, DEMO_SPEED_KMH)
    world = World(SimConfig.of_machine(cfg), seed=seed, drive=drive)
    sections = Machine.from_config(cfg.machine).sections
    node = IsobusNode(
        topdress_name(MANUFACTURER_CODE, DEMO_UID),
        tc_timeout_ms=tc_timeout_ms(world.ecu.params.cmd_timeout_ms),  # the core's own
    )
    return (
        world,
        node,
        IsobusMachine(world, node, cfg.machine.width_m, sections, cfg.machine.fan_rpm),
    )


def run_isobus_demo(
    cfg: TerminalConfig,
    duration_s: float,
    out_dir: Path,
    seed: int,
    out: TextIO,
    config_toml: str = "",
    *,
    pace: bool = True,
) -> int:
    world, node, sim = _demo_machine(cfg, seed)
    ddop_bytes = len(build(Machine.from_config(cfg.machine))[0])
    tc = MiniTc()
    log = SessionLog.create(out_dir, redacted_text(config_toml), name="isobus")
    if not log.ok:
        print(f"warning: session log not written: {log.last_error}", file=out)
    watch = IsobusWatch(node)
    said: set[str] = set()
    pending: list[Frame] = []
    t0 = time.monotonic()
    with log:
        print(f"ISOBUS demo: NAME {node.name:016X}, DDOP {ddop_bytes} bytes; "
              f"session log {log.path}", file=out)  # fmt: skip
        for n in range(round(duration_s / world.dt)):
            frames = sim.step(pending)
            _record(log, "can_rx", world.t_s, frames)
            for ev in watch.events(world.t_s):
                log.event(ev)
                line = console_line(ev)
                if line is not None:
                    print(line, file=out)
            pending = tc.step(world.now_us, frames)
            _record(log, "can_tx", world.t_s, pending)
            _say(out, said, sim, tc, n)
            if pace:
                time.sleep(max(0.0, t0 + world.t_s - time.monotonic()))
    return 0


def console_line(ev: LogEvent) -> str | None:
    """The console's line for one of the node's faults (the session log has every event)."""
    d, t = ev.detail, f"{ev.t:6.2f} s  "
    if ev.kind == "isobus.tc_lost":
        return t + "ALARM: Task Controller lost, meters stopped"
    if ev.kind == "isobus.ddop" and not d["accepted"]:
        return t + (f"ALARM: TC 0x{d['tc'] or 0:02X} refused the DDOP (code 0x{d['code']:02X}), "
                    "meters stopped")  # fmt: skip
    if ev.kind == "isobus.claimed" and d["address"] is None:
        return t + f"ALARM: no ISOBUS address ({d['state']}), meters stopped"
    if ev.kind == "isobus.claimed" and "moved" in d:
        now = f"0x{d['address']:02X}"
        return t + f"address 0x{d['moved']:02X} taken by a higher-priority NAME: now {now}"
    if ev.kind == "isobus.value_refused":
        return t + (f"TC values refused: {d['refused']} ({d['total']} so far), out of range or "
                    "for no element of the DDOP; the rate in force kept")  # fmt: skip
    if ev.kind == "isobus.tp_aborted":
        return t + f"DDOP transfer {d['state']} (reason {d['reason']}), sent again in 2 s"
    if ev.kind == "isobus.bus_load":
        state = "overloaded" if d["overloaded"] else "back to normal"
        return t + f"ISOBUS {state}: {d['load_pct']:.0f} % of the bus"
    return None


def _say(out: TextIO, said: set[str], sim: IsobusMachine, tc: MiniTc, n: int) -> None:
    node, w = sim.node, sim.world
    if node.address is not None and "claim" not in said:
        said.add("claim")
        print(f"{w.t_s:6.2f} s  address 0x{node.address:02X} claimed", file=out)
    if node.tc_state == "connected" and "pool" not in said:
        said.add("pool")
        print(f"{w.t_s:6.2f} s  TC 0x{node.tc_address or 0:02X}: DDOP accepted and activated",
              file=out)  # fmt: skip
        for element, ddi, value in ((2, 160, 1), (2, 289, 1), (2, 290, ALL_ON)):
            tc.command(element, ddi, value)
        for element, rate in zip((3, 4), RATES_KG_HA, strict=True):
            tc.command(element, 6, round(rate * 100))
    if node.rate_kg_ha(0) > 0.0 and "rate" not in said:
        said.add("rate")
        rates = f"upper {node.rate_kg_ha(0):.0f} kg/ha, lower {node.rate_kg_ha(1):.0f} kg/ha"
        print(f"{w.t_s:6.2f} s  TC set {rates}, sections {node.sections_on:06b}", file=out)
    if n % 500 == 0 and "rate" in said:
        t = w.truth
        a = sim.actual_kg_ha
        print(f"{w.t_s:6.2f} s  {t.v_kmh:4.1f} km/h  applying {a[0]:5.1f} / {a[1]:5.1f} kg/ha"
              f"{'  ALARM: TC lost' if node.alarm else ''}", file=out)  # fmt: skip


class IsobusLive(LiveMachine):
    """The World with its ECU on ISOBUS, live: each step the frames heard go to the node, the
    World steps, its lines go to the ptys and the node's frames onto the bus. The implement's
    session log gets every frame and the node's events; its faults are said on `out`. Its
    totals (DDI 81) are the kg its meters turned out."""

    def __init__(self, sim: IsobusMachine, bus: can.BusABC, log: SessionLog, out: TextIO) -> None:
        super().__init__(sim.world, bus)
        self.sim = sim
        self.log = log
        self._out = out
        self._watch = IsobusWatch(sim.node)

    def step_once(self) -> None:
        sim, w, log = self.sim, self.world, self.log
        heard = []
        while (msg := self.bus.recv(timeout=0)) is not None:
            if msg.is_extended_id:
                heard.append(Frame(msg.arbitration_id, bytes(msg.data)))
        _record(log, "can_tx", w.t_s, heard)  # the Task Controller's, as the node hears them
        for layer, element in enumerate(ELEMENT_BINS):
            sim.node.set_actual(element, DDI_TOTAL_MASS, round(w.truth.applied_kg[layer]))
        frames = sim.step(heard)
        out = sim.out
        if out is not None:
            dropped = self.gnss_port.write("".join(out.nmea).encode("ascii"))
            dropped += self.crop_port.write("".join(out.crop).encode("ascii"))
            self.counters["serial_dropped_bytes"] += dropped
        _record(log, "can_rx", w.t_s, frames)
        for ev in self._watch.events(w.t_s):
            log.event(ev)
            line = console_line(ev)
            if line is not None:
                print(f"implement: {line.strip()}", file=self._out)
        for f in frames:
            try:
                self.bus.send(can.Message(arbitration_id=f.can_id, data=f.data))
            except can.CanError:
                self.counters["can_tx_errors"] += 1


def isobus_config_toml(text: str) -> str:
    """The demo's configuration with the bus an ISOBUS and the terminal its Task Controller."""
    doc = tomlkit.parse(text)
    doc["can"]["implement"] = "isobus"
    return tomlkit.dumps(doc)


def run_terminal_isobus_demo(
    cfg: TerminalConfig,
    duration_s: float,
    out_dir: Path,
    seed: int,
    out: TextIO,
    user_text: str = "",
) -> int:
    """The machine on ISOBUS in a thread, the terminal as its TC in front of it; exit code."""
    _check_out_dir(out_dir)
    world, node, sim = _demo_machine(cfg, seed)
    ddop_bytes = len(build(Machine.from_config(cfg.machine))[0])
    channel = f"topdress-isobus-{os.getpid()}"
    sim_bus = open_bus(loads_config(f'[can]\nchannel = "{channel}"\n').can)
    log = SessionLog.create(out_dir, redacted_text(user_text), name="isobus")
    try:
        live = IsobusLive(sim, sim_bus, log, out)
    except OSError as exc:
        sim_bus.shutdown()
        log.close()
        why = f"cannot make the simulated machine's pseudo-terminals: {exc}"
        raise DeviceError(why) from exc
    try:
        text = isobus_config_toml(
            demo_config_toml(live.gnss_port.path, live.crop_port.path, channel, out_dir, user_text)
        )
        term_cfg = loads_config(text)
        config_path = out_dir / "topdress-demo.toml"
        config_path.write_text(text, encoding="utf-8")
        print(
            f"topdress demo --isobus: the terminal is the Task Controller; the topdress ECU "
            f"on ISOBUS (NAME {node.name:016X}, DDOP {ddop_bytes} bytes); "
            f"GNSS {live.gnss_port.path}, crop sensors {live.crop_port.path}, "
            f"CAN virtual:{channel}; the implement's session log {log.path}",
            file=out,
        )
        live.start()
        result = run_terminal(
            term_cfg,
            text,
            duration_s,
            out,
            live,
            True,
            config_path,
            None,
            None,
            watch=_Reporter(out).tick,
        )
    finally:
        live.stop()
        sim_bus.shutdown()
        log.close()
    _say_applied(out, result.session_path, sim, world)
    return 0


class _Reporter:
    """Every REPORT_S, a line of what the implement reports to the terminal: its rates, its
    sections and its totals (DDI 7, 161, 81), beside the rates the terminal set."""

    def __init__(self, out: TextIO) -> None:
        self._out = out
        self._next = 0.0

    def tick(self, s: Snapshot, now: float) -> None:
        iso = s.isobus
        if iso is None or iso.state != "ok" or now < self._next:
            return
        self._next = now + REPORT_S
        rates = ", ".join(
            f"{p.setpoint:.1f} set / {_opt(p.actual, '.1f')} reported {p.unit}"
            f" ({_opt(p.total, '.0f')} kg total)"
            for p in iso.products
        )
        sections = "".join("1" if on else "0" for on in iso.sections) or "--"
        kg = sum(s.count_field.kg)
        print(
            f"implement {iso.implement} 0x{iso.implement_address or 0:02X}: {rates}; "
            f"sections {sections}; {kg:.2f} kg applied this field",
            file=self._out,
        )


def _opt(v: float | None, fmt: str) -> str:
    return "--" if v is None else format(v, fmt)


def _say_applied(out: TextIO, path: Path | None, sim: IsobusMachine, world: World) -> None:
    """What the implement applied against what the terminal set (the session log's summary),
    and what the plant metered."""
    truth_kg = sum(world.truth.applied_kg)
    print(
        f"simulated implement: {world.truth.t_s:.1f} s, {world.truth.odometer_m:.1f} m driven, "
        f"{truth_kg:.2f} kg metered; node at 0x{sim.node.address or 0:02X}, "
        f"TC connection {sim.node.tc_state}",
        file=out,
    )
    if path is None:
        return
    with SessionReader(path) as reader:
        s = summarise(reader)
    applied = sum(x.applied_kg for x in s.layers.values())
    target = sum(x.target_kg for x in s.layers.values())
    if target <= 0.0:
        print("the implement was given no rate: nothing applied", file=out)
        return
    off = (applied - target) / target * 100.0
    verdict = "at" if abs(off) <= RATE_TOLERANCE_PCT else "OFF"
    print(
        f"ISOBUS implement applied {applied:.2f} kg {verdict} the terminal's rate "
        f"({off:+.1f} % of the {target:.2f} kg its setpoints asked for, "
        f"over {s.area_ha:.3f} ha)",
        file=out,
    )
