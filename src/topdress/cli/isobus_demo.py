"""`topdress demo --isobus`: the terminal, unchanged, as the Task Controller of the simulated
topdress ECU on ISOBUS. The machine (the World, its ECU on ISOBUS: topdress.sim.isobus) runs
paced to the wall clock in its own thread, on the demo's pseudo-terminals (GNSS and crop
sensors) and an in-process python-can bus; the terminal runs with `[can] implement = "isobus"`,
so the crop-sensor rate reaches the implement's setpoint DDI and what the implement reports
comes back into the console and the session log. Every frame the machine hears and sends goes
into a candump log beside the session logs. At the end it says what the implement applied
against what the terminal set, from the session log."""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import TextIO

import can
import tomlkit

from topdress.cli.demo import _check_out_dir, demo_config_toml, run_terminal
from topdress.config import TerminalConfig, loads_config
from topdress.devices.can import open_bus
from topdress.errors import DeviceError
from topdress.isobus.ddop import DDI_TOTAL_MASS, Machine, build
from topdress.isobus.node import Frame, IsobusNode, topdress_name
from topdress.log.session import SessionReader
from topdress.log.summary import summarise
from topdress.sim.isobus import ELEMENT_BINS, IsobusMachine, tc_timeout_ms
from topdress.sim.live import LiveMachine
from topdress.sim.tractor import Drive
from topdress.sim.world import SimConfig, World
from topdress.view.snapshot import Snapshot

MANUFACTURER_CODE = 0  # reserved/unassigned: set your own for a real bus
DEMO_UID = b"topdress-demo"
#: The demo's field work: 40 m passes at 7 km/h with a headland turn between them.
DEMO_PASSES, DEMO_PASS_M, DEMO_SPEED_KMH = 30, 40.0, 7.0
REPORT_S = 5.0
#: Applied within this of what the setpoints asked for is "at the terminal's rate" (the
#: start from rest, the first seconds, is where the rest of it goes).
RATE_TOLERANCE_PCT = 3.0


class IsobusLive(LiveMachine):
    """The World with its ECU on ISOBUS, live: each step the frames heard go to the node, the
    World steps, its lines go to the ptys and the node's frames onto the bus (and all into the
    candump log). The implement's totals (DDI 81) are the kg its meters turned out."""

    def __init__(self, sim: IsobusMachine, bus: can.BusABC, candump: TextIO) -> None:
        super().__init__(sim.world, bus)
        self.sim = sim
        self._log = candump

    def step_once(self) -> None:
        sim, w = self.sim, self.world
        heard = []
        while (msg := self.bus.recv(timeout=0)) is not None:
            if msg.is_extended_id:
                heard.append(Frame(msg.arbitration_id, bytes(msg.data)))
        self._dump(w.t_s, heard)
        for layer, element in enumerate(ELEMENT_BINS):
            sim.node.set_actual(element, DDI_TOTAL_MASS, round(w.truth.applied_kg[layer]))
        frames = sim.step(heard)
        out = sim.out
        if out is not None:
            dropped = self.gnss_port.write("".join(out.nmea).encode("ascii"))
            dropped += self.crop_port.write("".join(out.crop).encode("ascii"))
            self.counters["serial_dropped_bytes"] += dropped
        self._dump(w.t_s, frames)
        for f in frames:
            try:
                self.bus.send(can.Message(arbitration_id=f.can_id, data=f.data))
            except can.CanError:
                self.counters["can_tx_errors"] += 1

    def _dump(self, t: float, frames: list[Frame]) -> None:
        for f in frames:
            self._log.write(f"({t:.6f}) isobus {f.can_id:08X}#{f.data.hex().upper()}\n")


def isobus_config_toml(text: str) -> str:
    """The demo's configuration with the bus an ISOBUS and the terminal its Task Controller."""
    doc = tomlkit.parse(text)
    doc["can"]["implement"] = "isobus"
    return tomlkit.dumps(doc)


def run_isobus_demo(
    cfg: TerminalConfig,
    duration_s: float,
    out_dir: Path,
    seed: int,
    out: TextIO,
    user_text: str = "",
) -> int:
    """The machine on ISOBUS in a thread, the terminal as its TC in front of it; exit code."""
    _check_out_dir(out_dir)
    drive = Drive.field_passes(DEMO_PASSES, DEMO_PASS_M, DEMO_SPEED_KMH)
    world = World(SimConfig.of_machine(cfg), seed=seed, drive=drive)
    machine = Machine.from_config(cfg.machine)
    node = IsobusNode(
        topdress_name(MANUFACTURER_CODE, DEMO_UID),
        tc_timeout_ms=tc_timeout_ms(world.ecu.params.cmd_timeout_ms),  # the core's own
    )
    sim = IsobusMachine(world, node, cfg.machine.width_m, machine.sections, cfg.machine.fan_rpm)
    channel = f"topdress-isobus-{os.getpid()}"
    out_dir.mkdir(parents=True, exist_ok=True)
    dump_path = out_dir / time.strftime("isobus-%Y%m%d-%H%M%S.log")
    sim_bus = open_bus(loads_config(f'[can]\nchannel = "{channel}"\n').can)
    with dump_path.open("w", encoding="ascii") as dump:
        try:
            live = IsobusLive(sim, sim_bus, dump)
        except OSError as exc:
            sim_bus.shutdown()
            why = f"cannot make the simulated machine's pseudo-terminals: {exc}"
            raise DeviceError(why) from exc
        try:
            text = isobus_config_toml(
                demo_config_toml(
                    live.gnss_port.path, live.crop_port.path, channel, out_dir, user_text
                )
            )
            term_cfg = loads_config(text)
            config_path = out_dir / "topdress-demo.toml"
            config_path.write_text(text, encoding="utf-8")
            print(
                f"topdress demo --isobus: the terminal is the Task Controller; the topdress ECU "
                f"on ISOBUS (NAME {node.name:016X}, DDOP {len(build(machine)[0])} bytes); "
                f"GNSS {live.gnss_port.path}, crop sensors {live.crop_port.path}, "
                f"CAN virtual:{channel}; traffic in {dump_path}",
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
