"""`topdress demo --isobus`: the simulated machine with its ECU on ISOBUS and the terminal's
Task Controller (topdress.isobus.tcserver), paced to the wall clock. The console says what the
bus does (address claimed, DDOP accepted, the rate the TC set, what is applied). The session
log (topdress.log, one SQLite file in the output folder) records every frame both ways (the
ECU's as can_rx, the Task Controller's as can_tx) and the node's events (isobus.claimed,
isobus.ddop, isobus.set, isobus.tc_lost), for `topdress log export` and `replay`."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TextIO

from topdress.config import TerminalConfig, redacted_text
from topdress.isobus.ddop import Machine, build
from topdress.isobus.node import Frame, IsobusNode, topdress_name
from topdress.log.isobus import IsobusWatch
from topdress.log.model import LogEvent
from topdress.log.session import SessionLog
from topdress.sim.isobus import IsobusMachine, tc_timeout_ms
from topdress.sim.tc import MiniTc
from topdress.sim.tractor import Drive
from topdress.sim.world import SimConfig, World

MANUFACTURER_CODE = 0  # reserved/unassigned: set your own for a real bus
DEMO_UID = b"topdress-demo"
RATES_KG_HA = (150.0, 100.0)
ALL_ON = -4096 + 0x555  # condensed work state: sections 1-6 on, 7-16 not installed


def _record(log: SessionLog, kind: str, t: float, frames: list[Frame]) -> None:
    for f in frames:
        log.raw(kind, t, (f.can_id, f.data))


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
    world = World(SimConfig.of_machine(cfg), seed=seed, drive=Drive.field_passes(30, 40.0, 7.0))
    machine = Machine.from_config(cfg.machine)
    node = IsobusNode(
        topdress_name(MANUFACTURER_CODE, DEMO_UID),
        tc_timeout_ms=tc_timeout_ms(world.ecu.params.cmd_timeout_ms),  # the core's own
    )
    sim = IsobusMachine(world, node, cfg.machine.width_m, machine.sections, cfg.machine.fan_rpm)
    tc = MiniTc()
    log = SessionLog.create(out_dir, redacted_text(config_toml), name="isobus")
    if not log.ok:
        print(f"warning: session log not written: {log.last_error}", file=out)
    watch = IsobusWatch(node)
    said: set[str] = set()
    pending: list[Frame] = []
    t0 = time.monotonic()
    with log:
        print(f"ISOBUS demo: NAME {node.name:016X}, DDOP {len(build(machine)[0])} bytes; "
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
