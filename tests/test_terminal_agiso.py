"""The terminal as the Task Controller of a client nobody here wrote: the client's side of a
session recorded with AgIsoStack++'s TaskControllerClient (a granular spreader, 2 bins, 6
sections; tests/data, the commit in docs/isobus.md) replayed at its recorded times into the
real terminal loop, which drives on the simulated field with its crop sensors. The terminal
must take the client's pool, send it the crop-sensor rate as its setpoints and switch its
sections, and take the client's reports into the Snapshot, the session log and the as-applied
map."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import can
import pytest

from tc_rig import AGISO_NAME, CLIENT, client_frames
from term_rig import TerminalParts
from topdress.config import DEFAULT_TOML, loads_config
from topdress.geo.export import export_maps
from topdress.isobus.node import Frame, split_id
from topdress.log.session import SessionLog, SessionReader
from topdress.sim.tractor import Drive, Segment
from topdress.sim.world import SimConfig, World
from topdress.view.snapshot import Snapshot

PD_PGN = 0xCB00


def _value(f: Frame) -> tuple[int, int, int, int] | None:
    """(command, element, DDI, value) of a process-data frame, None for anything else."""
    if split_id(f.can_id)[1] != PD_PGN:
        return None
    d = f.data
    return (
        d[0] & 0xF,
        (d[0] >> 4) | (d[1] << 4),
        d[2] | d[3] << 8,
        int.from_bytes(d[4:8], "little", signed=True),
    )


@pytest.mark.interop
def test_the_terminal_serves_an_agisostack_client(tmp_path: Path) -> None:
    session = SessionLog.create(tmp_path, DEFAULT_TOML)
    drive = Drive([Segment("stop", duration_s=2.0),
                   Segment("straight", speed_kmh=8.0, length_m=150.0, hold=True)])  # fmt: skip
    cfg = loads_config(DEFAULT_TOML)
    world = World(SimConfig.of_machine(cfg), seed=3, drive=drive)
    parts = TerminalParts(cfg, lambda: world.t_s, session, implement="isobus")
    term, gnss, crop, wire = parts.term, parts.gnss, parts.crop, parts.ecu_bus
    replay = client_frames()
    sent: list[tuple[float, Frame]] = []  # what the terminal's TC said
    snaps: list[Snapshot] = []
    try:
        i = 0
        while world.t_s < 56.0:
            out = world.step()
            t = out.t_s
            for line in out.nmea:
                gnss.emit(t, line.encode())
            for line in out.crop:
                crop.emit(t, line.encode())
            while i < len(replay) and replay[i][0] <= t * 1e6:
                f = replay[i][1]
                msg = can.Message(arbitration_id=f.can_id, data=f.data, is_extended_id=True)
                term.inbox.put(("can", t, msg))
                i += 1
            while (msg := wire.recv(timeout=0)) is not None:
                sent.append((t, Frame(msg.arbitration_id, bytes(msg.data))))
            while not term.inbox.empty():
                term.handle(*term.inbox.get())
            if round(t * 100) % 10 == 0:
                term.tick(t)
                snaps.append(term.snapshot)
    finally:
        parts.close()
    events = _events(session.path)
    # the pool taken: the client named by its NAME and its DDOP's designator, connected
    (implement,) = [e.detail for e in events if e.kind == "isobus.implement"]
    assert implement["device"] == "Spreader" and implement["name"] == f"{AGISO_NAME:016X}"
    assert implement["sections"] == 6 and implement["setpoint_latency_ms"] == 800
    assert "isobus.connected" in [e.kind for e in events]
    last = snaps[-1].isobus
    assert last is not None and last.state == "ok" and last.implement_address == CLIENT
    assert [(p.element, p.setpoint_ddi, p.unit) for p in last.products] == [
        (3, 6, "kg/ha"),
        (4, 6, "kg/ha"),
    ]
    assert last.lookahead_s == pytest.approx(0.8)  # its DDI 142, not the configured times
    # its setpoints: the crop-sensor rate of the terminal's ticks (mg/m2 = kg/ha x 100)
    to_client = [(t, v) for t, f in sent if split_id(f.can_id)[3] == CLIENT and (v := _value(f))]
    # (a change is set with acknowledge, command 10; a refresh without, command 3)
    setpoints = [(t, v[3] / 100) for t, v in to_client if v[0] in (3, 10) and v[1:3] == (3, 6)]
    assert len({r for _, r in setpoints}) > 5 and min(r for _, r in setpoints) > 100.0
    ticks = {round(snap.t_s, 1): snap.rate_kg_ha[0] for snap in snaps}
    for t, rate in setpoints:  # sent on the tick or at a fix between: the tick's rate, to 1 %
        near = [ticks[k] for k in (round(t, 1), round(t - 0.1, 1), round(t + 0.1, 1)) if k in ticks]
        assert any(abs(rate - r) <= 0.01 * r for r in near), (t, rate, near)
    # its sections switched: all six on while the meters are on (DDI 290, 7..16 not installed)
    sections = {v[3] for _, v in to_client if v[:3] == (3, 2, 290)}
    assert -4096 + 0x555 in sections
    # its reports (DDI 7, what it says it applies) in the Snapshot, tick by tick
    reports = [(t / 1e6, v) for t, f in replay if (v := _value(f)) and v[:3] == (3, 3, 7)]
    checked = 0
    for snap in snaps:
        said = [v[3] / 100 for t, v in reports if t <= snap.t_s]
        actual = snap.isobus.products[0].actual if snap.isobus and snap.isobus.products else None
        if said and actual is not None:
            assert actual == pytest.approx(said[-1], abs=0.01), snap.t_s
            checked += 1
    assert checked > 300
    # ... and in the session log's as-applied map: the rates it reported, where it drove
    with SessionReader(session.path) as reader:
        export_maps(reader, tmp_path / "map", "geojson", "wgs84", None)
    points = json.loads((tmp_path / "map_points.geojson").read_text())["features"]
    applied = [f["properties"]["AppRateUp"] for f in points if f["properties"]["SPEED"] > 7.0]
    said_values = {round(v[3] / 100, 1) for _, v in reports}
    assert max(applied) == pytest.approx(180.0, abs=0.1)  # its 180 kg/ha of the recording
    assert sum(round(a, 1) in said_values for a in applied) > 0.9 * len(applied)


def _events(path: Path) -> list[Any]:
    with SessionReader(path) as reader:
        return list(reader.events())
