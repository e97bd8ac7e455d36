"""A session of the real terminal against the simulated machine on a virtual clock, for the
map and export tests (a few seconds of CPU for a minute of field work)."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import can

from topdress.config import loads_config
from topdress.devices.can import open_bus
from topdress.devices.lines import FakeLineSource
from topdress.i18n import render
from topdress.log.session import SessionLog
from topdress.sim.gnss import GnssParams
from topdress.sim.tractor import Drive
from topdress.sim.world import World
from topdress.terminal.app import Terminal

_channels = itertools.count()
LAT0, LON0 = GnssParams().lat0_deg, GnssParams().lon0_deg
EARTH_R_M = 6_371_000.0  # the simulator's local frame (topdress.sim.gnss)


def latlon(x_east_m: float, y_north_m: float) -> tuple[float, float]:
    """The simulator's local metres (origin = where the tractor starts) as WGS 84."""
    lat = LAT0 + math.degrees(y_north_m / EARTH_R_M)
    lon = LON0 + math.degrees(x_east_m / (EARTH_R_M * math.cos(math.radians(LAT0))))
    return lat, lon


def record(
    directory: Path,
    config_toml: str,
    drive: Drive,
    until_s: float,
    on_step: Callable[[World], None] | None = None,
    on_event: list[str] | None = None,
) -> Path:
    """Run the terminal with `config_toml` over `drive` until `until_s`; the session file.
    `on_step` sees the simulated world after each of its steps (its ground truth); `on_event`
    gets what the operator is told, in English."""
    cfg = loads_config(config_toml)
    cfg = replace(cfg, can=replace(cfg.can, channel=f"test-geo-{next(_channels)}"))
    world = World(seed=5, drive=drive)
    gnss, crop = FakeLineSource(), FakeLineSource()
    pc_bus, ecu_bus = open_bus(cfg.can), open_bus(cfg.can)
    session = SessionLog.create(directory, config_toml)
    told = (lambda m: on_event.append(render(m, "en"))) if on_event is not None else None
    term = Terminal(cfg, gnss, crop, pc_bus, session, clock=lambda: world.t_s, on_event=told)
    term.open()
    try:
        while world.t_s < until_s - 1e-9:
            while (msg := ecu_bus.recv(timeout=0)) is not None:
                world.deliver_can(msg)
            out = world.step()
            if on_step is not None:
                on_step(world)
            t = out.t_s
            for line in out.nmea:
                gnss.emit(t, line.encode())
            for line in out.crop:
                crop.emit(t, line.encode())
            for frame_id, data in out.can:
                term.inbox.put(("can", t, can.Message(arbitration_id=frame_id, data=data)))
            while not term.inbox.empty():
                term.handle(*term.inbox.get())
            if round(t * 100) % 10 == 0:
                term.tick(t)
    finally:
        term.close()
        pc_bus.shutdown()
        ecu_bus.shutdown()
    return session.path
