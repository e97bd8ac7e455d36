"""Section control in the terminal's TC link: the real terminal loop (IsobusRig) with the
simulated topdress ECU on ISOBUS, driving a pass north and back south on a pass that overlaps
the first by two of its six 0.6 m sections, in a field whose west edge cuts two more."""

from __future__ import annotations

import itertools
import json
import os
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
import shapely

from test_terminal_isobus import IsobusRig
from test_terminal_isobus_prop import PropRig
from test_terminal_isobus_prop import _drive as prop_drive
from topdress.config import DEFAULT_TOML, ConfigError, TerminalConfig, loads_config
from topdress.geo.outlet import offset_position
from topdress.log.session import SessionLog, SessionReader
from topdress.sim.gnss import GnssParams
from topdress.sim.tractor import Drive, Segment
from topdress.view import commands as op
from topdress.view.commands import ApplySettings

# The turn's 1.2 m radius puts the way back about 2.2 m west (the tractor drifts back a little):
# its sections 1 and 2 (0.6 m each, left going south) are over the first pass; the field's west
# edge 3.0 m west of the first pass's centre leaves section 6 (and part of 5) outside.
WEST_EDGE_M = -3.0


def _drive() -> Drive:
    return Drive(
        [
            Segment("stop", duration_s=3.0),
            Segment("straight", speed_kmh=6.0, length_m=40.0, hold=True),
            Segment("turn", speed_kmh=4.0, angle_deg=-180.0, radius_m=1.2),
            Segment("straight", speed_kmh=6.0, length_m=40.0),
            Segment("stop", duration_s=2.0),
        ]
    )


def _boundary(tmp_path: Path, east_m: float = 30.0) -> str:
    p = GnssParams()
    corners = [(WEST_EDGE_M, -30.0), (east_m, -30.0), (east_m, 100.0), (WEST_EDGE_M, 100.0)]
    ring = [offset_position(p.lat0_deg, p.lon0_deg, 0.0, n, e)[::-1] for e, n in corners]
    path = tmp_path / "field.geojson"
    feature = {"type": "Feature", "properties": {},
               "geometry": {"type": "Polygon", "coordinates": [[*ring, ring[0]]]}}  # fmt: skip
    path.write_text(json.dumps({"type": "FeatureCollection", "features": [feature]}))
    return str(path)


def _run(
    cfg: TerminalConfig, session: SessionLog | None = None
) -> list[tuple[float, tuple[bool, ...], tuple[bool, ...]]]:
    """(time, the sections the terminal reports from DDI 161, the sim's sections) at each tick
    of the way back, once well clear of the turn."""
    rig = IsobusRig(cfg, _drive(), session)
    out = []
    try:
        while rig.world.t_s < 58.0:
            rig.run(rig.world.t_s + 0.1)
            tr = rig.world.tractor
            if abs(tr.heading) > 3.0 and 10.0 < tr.y < 30.0 and tr.v > 1.0:
                iso = rig.term.snapshot.isobus
                assert iso is not None
                n = rig.sim.node.sections_on
                sim = tuple(bool(n >> i & 1) for i in range(6))
                out.append((rig.world.t_s, iso.sections, sim))
    finally:
        rig.close()
    return out


def _cfg(tmp_path: Path | None, **isobus: object) -> TerminalConfig:
    cfg = loads_config(DEFAULT_TOML)
    cfg = replace(cfg, isobus=replace(cfg.isobus, **isobus))  # type: ignore[arg-type]
    if tmp_path is not None:
        cfg = replace(cfg, boundary=replace(cfg.boundary, path=_boundary(tmp_path)))
    return cfg


def test_way_back_sections_off_over_the_first_pass_and_outside_the_field(tmp_path: Path) -> None:
    back = _run(_cfg(tmp_path))
    assert len(back) > 50
    # what the implement reports (DDI 161) is what it does, but for a tick's lag at a switch
    assert sum(reported == sim for _, reported, sim in back) >= 0.9 * len(back)
    for _, _, sim in back:
        assert not (sim[0] or sim[1])  # over the first pass: off
        assert not sim[5]  # outside the field: off


def test_the_decisions_are_in_the_session_log_on_change_only(tmp_path: Path) -> None:
    """Each switch of the sections commanded is an `isobus.sections` event with why each one
    off is off; nothing between two switches."""
    session = SessionLog.create(tmp_path / "logs", DEFAULT_TOML)
    _run(_cfg(tmp_path), session)
    with SessionReader(session.path) as reader:
        events = [e for e in reader.events() if e.kind == "isobus.sections"]
    assert 5 <= len(events) < 60  # one per switch, not one per position (about 530)
    ons = [e.detail["on"] for e in events]
    assert all(a != b for a, b in itertools.pairwise(ons))  # only on a change
    for e in events:  # a reason for each section off, none for one on
        on, why = e.detail["on"], e.detail["why"]
        assert [w == "" for w in why] == on
    # at connection off while the topdress ECU takes its parameters (the TC holds it stopped
    # though the operator runs), then all on
    first_on = ons.index([True] * 6)
    assert events[first_on].t < 3.0
    assert [e.detail["why"] for e in events[:first_on]] == [["params"] * 6]
    # the way back: over the first pass covered, past the west edge outside
    back = [e.detail["why"] for e in events if 40.0 < e.t < 56.0]
    assert back and all(w[:2] == ["covered"] * 2 and w[5] == "outside" for w in back)
    # the terminal closes: the operator's stop puts every section off
    assert events[-1].detail == {"on": [False] * 6, "why": ["operator"] * 6}


def _covered_north_m(actual_ms: int | None) -> float:
    """The northern end of the ground covered (UTM metres) 20 s into the first pass, still
    driving at 6 km/h, the implement's actual-value delay (DDI 143) `actual_ms`."""
    rig = IsobusRig(_cfg(None), _drive())
    try:
        rig.run(5.0)
        tc = rig.term.can.tc
        assert tc is not None and tc.state == "ok"
        if actual_ms is not None:
            tc.latency_ms[143] = actual_ms  # as its pool's DPT 143 gives it
        rig.run(20.0)
        sc = tc.section_control
        assert sc is not None and rig.world.tractor.v > 1.5
        covered = shapely.union_all(list(sc.coverage.tiles.values()))
    finally:
        rig.close()
    return float(shapely.bounds(covered)[3])


def test_the_actual_value_delay_puts_the_coverage_where_the_machine_was() -> None:
    """What the implement reports working now it worked its DDI 143 ago: with 1 s at 6 km/h
    the covered ground ends 1.67 m further back than without."""
    back = _covered_north_m(None) - _covered_north_m(1000)
    assert back == pytest.approx(6.0 / 3.6, abs=0.15)  # 1.69 m measured


def test_without_a_boundary_only_the_overlap_goes_off() -> None:
    back = _run(_cfg(None))
    assert len(back) > 50
    assert sum(reported == sim for _, reported, sim in back) >= 0.9 * len(back)
    for _, _, sim in back:
        assert not (sim[0] or sim[1])  # over the first pass: off
        assert sim[4] and sim[5]  # on fresh ground, with no boundary to leave: on


def test_the_coverage_outlives_the_implement_lost_and_back() -> None:
    drive = _drive()
    drive.segments.insert(3, Segment("stop", duration_s=12.0))  # after the turn: unplugged
    cfg = _cfg(None)
    rig = IsobusRig(cfg, drive)
    try:
        rig.run(40.0)
        tc = rig.term.can.tc
        assert tc is not None
        rig.implement_off = True
        rig.run(48.0)
        assert tc.state == "lost"
        rig.implement_off = False
        rig.run(51.0)
        assert tc.state == "ok"
        back = []
        while rig.world.t_s < 72.0:
            rig.run(rig.world.t_s + 0.1)
            tr = rig.world.tractor
            if abs(tr.heading) > 3.0 and 10.0 < tr.y < 30.0 and tr.v > 1.0:
                back.append(rig.sim.node.sections_on)
    finally:
        rig.close()
    assert len(back) > 50
    # the two sections over the first pass stay off (the coverage before the loss is kept),
    # the outermost, on fresh ground, works
    assert all(not (n & 0b11) and n & 0b100000 for n in back)


def _first_pass(rig: IsobusRig, until_s: float) -> list[tuple[float, int]]:
    """(north of the start in m, the sim's sections) at each tick of the first pass north."""
    out = []
    while rig.world.t_s < until_s:
        rig.run(rig.world.t_s + 0.1)
        tr = rig.world.tractor
        if tr.v > 1.0:
            out.append((tr.y, rig.sim.node.sections_on))
    return out


@pytest.mark.parametrize(
    ("hours", "east_m", "zone"),
    [(24.0, 30.0, "EPSG:32651"), (0.0, 30.0, ""), (24.0, 150_000.0, "EPSG:32652")],
)
def test_the_coverage_survives_a_terminal_killed_mid_field_and_restarted(
    tmp_path: Path, hours: float, east_m: float, zone: str
) -> None:
    """The terminal killed 20 s into the first pass (about 26 m north), then started again
    and driven over the same line from the start: over the ground the killed session covered
    the sections stay off (its as-applied swaths, read from its log); past it they work.
    With `coverage_hours = 0` earlier sessions do not count: the sections work all the way.
    A field reaching 150 km east (its boundary's centre past 126 E, in UTM zone 52; the swaths
    in 51): the swaths' tiles are made in the boundary's zone, off the loop."""
    field = _boundary(tmp_path, east_m)
    boundary_line = 'path = ""' + " " * 18 + "# .gpkg, .shp, .geojson polygons or ISOXML "
    boundary_line += "TASKDATA.XML\n"
    assert DEFAULT_TOML.count(boundary_line) == 1
    toml = DEFAULT_TOML.replace(boundary_line, f'path = "{field}"\n').replace(
        "coverage_hours = 24.0", f"coverage_hours = {hours}"
    )
    cfg = loads_config(toml)
    logs = tmp_path / "logs"
    killed = SessionLog.create(logs, toml)
    rig = IsobusRig(cfg, _drive(), killed)
    try:
        first = _first_pass(rig, 20.0)
        assert all(n == 0b111111 for y, n in first if 2.0 < y < 20.0)  # fresh ground: all work
        killed.sync()  # what a killed terminal leaves: the rows committed up to its last 0.5 s
    finally:
        rig.pc_bus.shutdown()  # no close: the terminal is gone, its log never closed
        rig.ecu_bus.shutdown()
    # a damaged file of today and one of three days ago in the log directory: the first is
    # named in the session log only, never told at every start; the second is not even opened
    (logs / "broken.sqlite").write_bytes(b"not a session")
    (logs / "old.sqlite").write_bytes(b"a damaged file of an old day")
    three_days = time.time() - 3 * 86400.0
    os.utime(logs / "old.sqlite", (three_days, three_days))
    session = SessionLog.create(logs, toml)
    again = IsobusRig(cfg, _drive(), session)
    try:
        tc = again.term.can.tc
        assert tc is not None
        deadline = time.monotonic() + 30.0  # the earlier log is read in a thread of its own
        while not tc.coverage_read and time.monotonic() < deadline:
            again.run(again.world.t_s + 0.1)
            time.sleep(0.01)
        second = _first_pass(again, 30.0)
    finally:
        again.close()
        killed.close()
    with SessionReader(session.path) as reader:
        coverage = [e.detail for e in reader.events() if e.kind == "isobus.coverage"]
        problems = [e.detail for e in reader.events() if e.kind == "isobus.problem"]
    assert not any("sqlite" in p["what"] for p in problems), problems
    over = [n for y, n in second if 4.0 < y < 22.0]  # inside what the killed one covered
    beyond = [n for y, n in second if 30.0 < y < 38.0]
    assert len(over) > 50 and len(beyond) > 20
    assert all(n & 0b011110 == 0b011110 for n in beyond)  # fresh ground again: they work
    if hours:
        (taken,) = coverage
        assert taken["sessions"] == [killed.path.name] and taken["swaths"] > 10
        assert taken["zone"] == zone
        (skipped,) = taken["skipped"]
        assert skipped.startswith("broken.sqlite: ")
        assert all(n == 0 for n in over)
    else:  # not read at all
        assert coverage == []
        assert all(n & 0b011110 == 0b011110 for n in over)


def test_a_bad_coverage_window_is_refused_naming_the_key() -> None:
    for bad in ("-1.0", "9000.0", '"day"'):
        lines = [
            f"coverage_hours = {bad}" if x.startswith("coverage_hours = ") else x
            for x in DEFAULT_TOML.splitlines()
        ]
        with pytest.raises(ConfigError, match=r"isobus\.coverage_hours"):
            loads_config("\n".join(lines))


def test_section_control_off_switches_all_sections_with_the_rate(tmp_path: Path) -> None:
    back = _run(_cfg(tmp_path, section_control=False))
    assert len(back) > 50
    assert all(reported == sim == (True,) * 6 for _, reported, sim in back)


@pytest.mark.parametrize(
    ("line", "key"),
    [
        ("overlap_pct = 100.0", "isobus.overlap_pct"),
        ("section_look_m = 0.0", "isobus.section_look_m"),
        ('section_control = "yes"', "isobus.section_control"),
    ],
)
def test_a_bad_section_control_key_is_refused_naming_it(line: str, key: str) -> None:
    name = line.split(" = ")[0]
    lines = [line if x.startswith(f"{name} = ") else x for x in DEFAULT_TOML.splitlines()]
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        loads_config("\n".join(lines))


def test_an_isobus_change_while_running_is_saved_for_the_next_start(tmp_path: Path) -> None:
    """[isobus] turned off section control mid-pass: the operator is told it is in force at
    the next start, the configuration has it, and the TC link serving goes on as it was made
    (sections still decided), not half-changed."""
    rig = IsobusRig(_cfg(tmp_path), _drive())
    try:
        rig.run(8.0)  # moving on the first pass: sections decided
        tc = rig.term.can.tc
        assert tc is not None and tc.section_on is not None
        fut = rig.term.post(ApplySettings("isobus", {"section_control": False}))
        rig.run(8.5)
        assert fut.done() and fut.result().ok, fut.result()
        assert str(fut.result().message).endswith("(in force at the next start)")
        assert rig.term.cfg.isobus.section_control is False
        rig.run(10.0)
        assert tc.section_on is not None and rig.term.can.tc is tc
    finally:
        rig.close()


def test_sections_held_off_for_the_ecus_parameters_say_so_in_the_session_log() -> None:
    """A topdress ECU that takes no parameter (its core deaf): the TC holds its sections off
    while the operator runs, and the session log says why (`params`, not `operator`); once
    the parameters are in, they work."""
    rig = PropRig(loads_config(DEFAULT_TOML), prop_drive())
    rig.deaf = True
    logged: list[dict[str, Any]] = []
    journal = rig.term.journal
    log_event = journal.log_event

    def keep(t: float, kind: str, **detail: Any) -> None:
        if kind == "isobus.sections":
            logged.append(detail)
        log_event(t, kind, **detail)

    journal.log_event = keep  # type: ignore[method-assign]
    try:
        rig.run(5.0)
        assert not rig.term.link.params_done and rig.term.desk.op.state == op.RUNNING
        assert logged == [{"on": [False] * 6, "why": ["params"] * 6}]
        rig.deaf = False
        rig.run(9.0)
        assert rig.term.link.params_done
        assert logged[1:] == [{"on": [True] * 6, "why": [""] * 6}]
    finally:
        rig.close()


def test_the_coverage_goes_on_over_a_can_change_mid_field(tmp_path: Path) -> None:
    """[can] changed 12 s into the first pass (about 12 m north), the implement on the same
    bus: the TC is made anew there and keeps its status back 8 s, so the implement takes it
    for lost (its fail-safe stop) and connects again, as to a TC that booted. The new TC link
    takes the ground covered so far with it: on the way back sections 1 and 2 stay off over
    the first pass's first 10 m as over what was covered after the change; over the ground
    driven while the implement was not served (nothing applied) they work."""
    rig = IsobusRig(_cfg(tmp_path), _drive())
    back: list[tuple[float, int]] = []
    try:
        rig.run(12.0)
        old = rig.term.can.tc
        assert old is not None and old.section_control is not None
        fut = rig.term.post(ApplySettings("can", {"ecu_timeout_s": 0.6}))
        deadline = time.monotonic() + 10.0  # the new bus opens in a thread of its own
        while not fut.done() and time.monotonic() < deadline:
            rig.run(rig.world.t_s + 0.1)
            time.sleep(0.005)
        assert fut.done() and fut.result().ok, fut.result()
        changed = rig.world.t_s
        assert changed < 14.0
        new = rig.term.can.tc
        assert new is not None and new is not old
        rig.run(changed + 7.5)
        assert new.state == "wait"  # still silent: the implement has not connected again
        rig.run(changed + 9.0)
        assert new.state == "ok"
        while rig.world.t_s < 62.0:
            rig.run(rig.world.t_s + 0.1)
            tr = rig.world.tractor
            if abs(tr.heading) > 3.0 and tr.v > 1.0:
                back.append((tr.y, rig.sim.node.sections_on))
    finally:
        rig.close()
    told = [e for _, e in rig.events if "started anew" in e]
    assert told == [
        "ISOBUS: Task Controller started anew on the new bus: silent 8 s, so that the "
        "implement at 0x84 takes it for a new one and connects again"
    ]
    # the NAMEs heard again (the TC asked for the claims): the topdress ECU is known as such
    assert not [e for _, e in rig.events if "not a topdress ECU" in e]
    before = [n for y, n in back if y < 10.5]  # covered before the change (the pass ends at 8 m)
    unserved = [n for y, n in back if 15.0 < y < 23.0]  # nothing applied there
    after = [n for y, n in back if 27.0 < y < 34.0]  # covered after the change
    assert len(before) > 10 and len(unserved) > 30 and len(after) > 30
    assert all(n & 0b11 == 0 for n in before + after)
    assert all(n & 0b11 == 0b11 for n in unserved)
