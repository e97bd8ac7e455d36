"""Section control from the boundary and the ground covered, on real geometry: a 60 m x 100 m
field in Bavaria (WGS 84, worked in UTM 32N), the AgIsoStack++ spreader's six 2 m sections as
its DDOP places them (Y -5..5 m, left to right), driven up and down in passes with the setpoints
followed: sections off outside the field, over the first pass's ground, and over as-applied
swaths of an earlier session; the condensed work state the TC sends."""

from __future__ import annotations

import os
import sqlite3
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
import shapely

from tc_rig import DDOP, connected
from topdress.geo.asapplied import utm_crs
from topdress.geo.boundary import FieldBoundary
from topdress.geo.outlet import offset_position
from topdress.geo.sectionctl import (
    Section,
    SectionControl,
    covered_tiles,
    earlier_coverage,
    sections_from_device,
)
from topdress.isobus.devicemap import map_device
from topdress.isobus.tcserver import TcServer, tc_name
from topdress.isobus.workstate import condensed_states, condensed_value
from topdress.log.model import StateRow
from topdress.log.session import SessionLog

SW = (48.10, 11.50)  # the field's south-west corner
NORTH, SOUTH = 0.0, 180.0


def at(east_m: float, north_m: float) -> tuple[float, float]:
    return offset_position(*SW, 0.0, north_m, east_m)


def _field(headland_m: float = 0.0) -> FieldBoundary:
    ring = [at(0, 0), at(60, 0), at(60, 100), at(0, 100)]
    return FieldBoundary(Path("field"), shapely.Polygon([(lon, lat) for lat, lon in ring]),
                         headland_m)  # fmt: skip


def _spreader(boundary: FieldBoundary | None) -> SectionControl:
    sections = sections_from_device(map_device(DDOP.read_bytes()))
    return SectionControl(sections, boundary)


def _drive(sc: SectionControl, east: float, heading: float, north: list[float]) -> list[list[bool]]:
    """Drives the line, the implement following the setpoints (and reporting them worked)."""
    out = []
    for n in north:
        lat, lon = at(east, n)
        states = sc.decide(lat, lon, heading)
        sc.cover(lat, lon, heading, list(states))
        out.append(states)
    return out


def _steps(a: float, b: float, step: float = 0.5) -> list[float]:
    n = round(abs(b - a) / step)
    return [a + (b - a) * i / n for i in range(n + 1)]


def test_spreader_geometry_from_its_ddop() -> None:
    sections = sections_from_device(map_device(DDOP.read_bytes()))
    assert sections == [Section(0.0, y, 2.0) for y in (-5.0, -3.0, -1.0, 1.0, 3.0, 5.0)]


def test_first_pass_on_inside_off_outside_and_at_the_far_end() -> None:
    sc = _spreader(_field())
    north = _steps(-4.0, 103.0)
    by = dict(zip(north, _drive(sc, 6.0, NORTH, north), strict=True))
    assert by[-4.0] == [False] * 6  # still south of the field
    assert by[0.0] == [True] * 6
    assert by[50.0] == [True] * 6
    assert by[99.0] == [True] * 6  # the strip 99..100 m: inside
    assert by[100.0] == [False] * 6  # beyond the north edge
    lat, lon = at(6.0, 50.0)
    assert sc.decide(lat, lon, NORTH) == [False] * 6  # all of the pass covered now
    # the edges: a section goes off when more than half of its look strip (1 m) is outside
    fresh = _spreader(_field())
    for n, on in ((-0.4, True), (-0.6, False), (99.4, True), (99.6, False)):
        lat, lon = at(6.0, n)
        assert fresh.decide(lat, lon, NORTH) == [on] * 6, n


def test_lead_switches_before_the_edge() -> None:
    sc = _spreader(_field())
    lat, lon = at(6.0, 98.5)
    assert sc.decide(lat, lon, NORTH, lead_m=0.0) == [True] * 6
    assert sc.decide(lat, lon, NORTH, lead_m=2.0) == [False] * 6  # 100.5..101.5 m: outside


def test_second_pass_overlapping_the_first_switches_the_overlap_off() -> None:
    sc = _spreader(_field())
    _drive(sc, 6.0, NORTH, _steps(-4.0, 103.0))  # covers east 0..12 m
    back = _drive(sc, 10.0, SOUTH, _steps(103.0, -4.0))
    # heading south the right is west: sections 1-2 at east 14-16 and 12-14 m are new ground,
    # sections 3-6 (east 4..12 m) over the first pass
    assert back[len(back) // 2] == [True, True, False, False, False, False]
    # a fresh line: all on
    lat, lon = at(30.0, 50.0)
    assert sc.decide(lat, lon, SOUTH) == [True] * 6


def test_boom_hanging_over_the_side_of_the_field() -> None:
    sc = _spreader(_field())
    lat, lon = at(58.0, 50.0)  # heading north: sections at east 52..64 m, the edge at 60 m
    assert sc.decide(lat, lon, NORTH) == [True, True, True, True, False, False]


def test_earlier_session_swaths_count_as_covered() -> None:
    sc = _spreader(_field())
    swath = [at(20, 0), at(40, 0), at(40, 100), at(20, 100)]
    cover, crs = covered_tiles([shapely.Polygon([(lon, lat) for lat, lon in swath])])
    assert cover is not None and crs is not None and sc.add_cover(cover, crs)
    lat, lon = at(30.0, 50.0)
    assert sc.decide(lat, lon, NORTH) == [False] * 6
    lat, lon = at(44.0, 50.0)  # sections at east 38..50 m: only the first over the swath
    assert sc.decide(lat, lon, NORTH) == [False, True, True, True, True, True]


def test_headland_is_field_and_without_boundary_only_coverage_counts() -> None:
    sc = _spreader(_field(headland_m=12.0))
    lat, lon = at(6.0, 5.0)  # in the headland strip: inside the field, worked
    assert sc.decide(lat, lon, NORTH) == [True] * 6
    free = _spreader(None)
    lat, lon = at(-50.0, -50.0)  # nowhere near a field: no boundary, nothing covered
    assert free.decide(lat, lon, NORTH) == [True] * 6
    _drive(free, -50.0, NORTH, _steps(-60.0, -40.0))
    assert free.decide(lat, lon, SOUTH) == [False] * 6


def test_a_gap_in_the_fixes_covers_nothing() -> None:
    sc = _spreader(_field())
    _drive(sc, 6.0, NORTH, [10.0, 30.0])  # a 20 m jump: no fix between
    lat, lon = at(6.0, 20.0)
    assert sc.decide(lat, lon, NORTH) == [True] * 6


def test_bad_settings_are_named() -> None:
    with pytest.raises(ValueError, match="at least one section"):
        SectionControl([], None)
    with pytest.raises(ValueError, match="off_pct"):
        SectionControl([Section(0, 0, 1)], None, off_pct=100.0)


def test_condensed_work_state_as_the_client_reads_it() -> None:
    # the AgIsoStack++ session's values: sections 1-6 on, 7-16 not installed; 1-3 off
    assert condensed_value([True] * 6) == -4096 + 0x555 == 0xFFFFF555 - (1 << 32)
    assert condensed_value([False, False, False, True, True, True]) == 0xFFFFF540 - (1 << 32)
    assert condensed_states(0xFFFFF540 - (1 << 32), 6) == [False] * 3 + [True] * 3
    assert condensed_states(condensed_value([True, None, False]), 4) == [True, None, False, None]


def test_closed_loop_with_the_ecu_client_through_the_tc() -> None:
    """The chain end to end: the topdress ECU's C TC client connects to the terminal's TC; its
    pool's six 0.6 m sections are placed by SectionControl, whose setpoints the TC sends (DDI
    290) as the machine drives; the ECU's sections follow, it reports them (DDI 161, on change)
    and that report is what counts as covered. Up a pass at east 2 m, back at 5 m: the one
    section over the first pass is off, the others on."""
    bus = connected(TcServer(tc_name(7)))
    tc, node = bus.tc, bus.node
    c = tc.client
    assert c is not None and c.device is not None
    sc = SectionControl(sections_from_device(c.device), _field())
    assert [round(s.width_m, 3) for s in sc.sections] == [0.6] * 6
    tc.set_value(2, 160, 1)  # automatic section control
    tc.set_value(2, 289, 1)
    tc.measure_on_change(2, 161, 1)
    sent: list[list[bool]] = []

    def drive(east: float, heading: float, north: list[float]) -> int:
        for n in north:
            lat, lon = at(east, n)
            states = sc.decide(lat, lon, heading)
            if not sent or states != sent[-1]:
                tc.set_sections(list[bool | None](states))
                sent.append(states)
            bus.run(0.1)  # 10 km/h: 0.28 m
            mask = node.sections_on
            node.set_actual(2, 161, condensed_value([bool(mask >> i & 1) for i in range(6)]))
            sc.cover(lat, lon, heading, tc.sections_working() or [False] * 6)
        return node.sections_on

    drive(2.0, NORTH, _steps(-2.0, 102.0, 0.28))
    assert sent[0] == [False] * 6 and [True] * 6 in sent and sent[-1] == [False] * 6
    mid = drive(5.0, SOUTH, _steps(102.0, 50.0, 0.28))
    assert mid == 0b011111  # heading south section 6 is at east 3.2..3.8 m: the first pass's
    assert tc.errors == [] and tc.counters["pdacks_ok"] >= len(sent)


def _session(logs: Path, toml: str, east_m: float, created: str | None = None) -> Path:
    """A session of one 40 m pass north at 8 km/h, `east_m` east of the field's corner, its
    meters turning; `created` overrides its creation time (ISO 8601)."""
    with SessionLog.create(logs, toml) as log:
        for i in range(200):
            t = i * 0.1
            lat, lon = at(east_m, 5.0 + t * 8.0 / 3.6)
            log.state(
                StateRow(
                    t, lat, lon, 8.0, 8.0, 8.0, "gnss", 1.0, 0.6, 120.0, 120.0,
                    20.0, 20.0, 20.0, 20.0, 3000.0, 3000.0, 0, utc=1.78e9 + t,
                    utc_source="gnss", heading_deg=0.0, outlet_lat=lat, outlet_lon=lon,
                )
            )  # fmt: skip
    if created is not None:
        with sqlite3.connect(log.path) as db:
            db.execute("UPDATE meta SET value = ? WHERE key = 'created_utc'", (created,))
    return log.path


def test_earlier_sessions_of_the_same_field_and_window_count_and_make_tiles(
    tmp_path: Path,
) -> None:
    logs = tmp_path / "logs"
    field = '[boundary]\npath = "field.geojson"\n'
    now = datetime.now(UTC)
    recent = (now - timedelta(hours=3)).isoformat(timespec="seconds")
    old = (now - timedelta(hours=30)).isoformat(timespec="seconds")
    same = _session(logs, field, 10.0, recent)
    _session(logs, field, 20.0, old)  # the field's last dressing, a day before: not covered
    _session(logs, '[boundary]\npath = "other.geojson"\n', 30.0, recent)  # another field
    (logs / "broken.sqlite").write_bytes(b"not a session")
    with SessionLog.create(logs, field):  # a session of the field that applied nothing
        pass
    current = SessionLog.create(logs, field)
    try:
        got = earlier_coverage(current.path, 24.0)
        wider = earlier_coverage(current.path, 48.0)
    finally:
        current.close()
    assert got.sessions == (same.name,)
    assert len(got.skipped) == 1 and got.skipped[0].startswith("broken.sqlite: ")
    assert len(wider.sessions) == 2
    # the swaths as tiles, in their UTM zone (the field's, 32N): 44.4 m of a pass of the
    # machine's width (3.6 m, the session's [machine] width_m)
    assert got.cover is not None and got.crs == utm_crs(*SW)
    area = sum(shapely.area(g) for g in got.cover.tiles.values())
    assert area == pytest.approx(3.6 * 44.4, rel=0.02)
    # taken by a section control working in that zone; refused by one in another
    sc = SectionControl([Section(0.0, 0.0, 3.0)], _field())
    assert sc.add_cover(got.cover, got.crs)
    assert sc.decide(*at(10.0, 20.0), NORTH) == [False]  # over the earlier pass: off
    assert sc.decide(*at(40.0, 20.0), NORTH) == [True]
    elsewhere = SectionControl([Section(0.0, 0.0, 3.0)], None)
    elsewhere.decide(48.10, 5.90, NORTH)  # its first fix in UTM 31N
    assert not elsewhere.add_cover(got.cover, got.crs)
    # made in the zone a section control works in (a field across a zone's edge): the same
    # ground, taken there
    east = utm_crs(48.10, 12.10)
    with SessionLog.create(logs, field) as again:
        there = earlier_coverage(again.path, 24.0, east)
    assert there.crs == east and there.cover is not None and there.sessions == got.sessions
    across = SectionControl([Section(0.0, 0.0, 3.0)], None, crs=east)
    assert across.add_cover(there.cover, east)
    assert across.decide(*at(10.0, 20.0), NORTH) == [False]
    assert across.decide(*at(40.0, 20.0), NORTH) == [True]


def test_old_files_are_not_opened_and_sessions_of_an_unknown_field_are_skipped(
    tmp_path: Path,
) -> None:
    """A damaged file last written three days ago is not opened at all (it is no session of
    the window); a session whose configuration cannot be read is of no known field, so it is
    skipped and named even though the current session has no boundary either; a creation
    time written without a zone is UTC."""
    logs = tmp_path / "logs"
    now = datetime.now(UTC)
    naive = (now - timedelta(hours=2)).replace(tzinfo=None).isoformat(timespec="seconds")
    counted = _session(logs, "", 10.0, naive)
    unknown = _session(logs, "[boundery]\npath = 'field.geojson'\n", 20.0)
    old = logs / "old.sqlite"
    old.write_bytes(b"a damaged file of an old day")
    three_days = (now - timedelta(days=3)).timestamp()
    os.utime(old, (three_days, three_days))
    current = SessionLog.create(logs, "")
    try:
        got = earlier_coverage(current.path, 24.0)
    finally:
        current.close()
    assert got.sessions == (counted.name,)
    (skipped,) = got.skipped
    assert skipped.startswith(f"{unknown.name}: boundery")
    area = sum(shapely.area(g) for g in got.cover.tiles.values()) if got.cover else 0.0
    assert area == pytest.approx(3.6 * 44.4, rel=0.02)  # the one pass of the session counted
