"""A GNSS outage at a headland turn: the outlet is dead reckoned along the heading from before
the turn for `gnss.dead_reckon_m` only; past it the position is unknown, the boundary's
switch-off does not act and the last rate metered in the field is kept (or
`gnss.unknown_kg_ha`).

The replay: a field of 100 × 100 m with a 10 m headland, NDVI 0.55 (300 kg/ha by the linear
model). The machine drives north at 8 km/h along x = 0, turns (radius 1.8 m) in the headland at
y = 44 m and comes back south along x = 3.6 m; fixes come at 5 Hz, and none from y = 42 m on the
way up for 20 s (44.4 m of travel, 32.8 of them back in the field).
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import shapely

from geo_rig import latlon
from test_geo_prescription import box, write_polygons
from topdress.config import BoundaryConfig, LinearRateConfig, loads_config
from topdress.crop.rate import LinearRate
from topdress.errors import ConfigError
from topdress.geo.boundary import load_boundary
from topdress.geo.outlet import OutletTracker
from topdress.terminal.site import UNKNOWN, SiteRate

V_MS = 8.0 / 3.6
DT_S = 0.1
RADIUS_M = 1.8
TURN_Y_M = 44.0
OUTAGE_FROM_Y_M = 42.0
OUTAGE_S = 20.0
FIELD_KG_HA = 300.0  # NDVI 0.55 by the linear model


def path_at(s_m: float) -> tuple[float, float, float]:
    """(x, y, heading°) after `s_m` metres from (0, 0) northward: up, the turn, back down."""
    if s_m <= TURN_Y_M:
        return 0.0, s_m, 0.0
    arc = s_m - TURN_Y_M
    if arc <= math.pi * RADIUS_M:
        a = arc / RADIUS_M  # the angle turned, clockwise (east) from north
        return RADIUS_M - RADIUS_M * math.cos(a), TURN_Y_M + RADIUS_M * math.sin(a), math.degrees(a)
    return 2 * RADIUS_M, TURN_Y_M - (arc - math.pi * RADIUS_M), 180.0


def replay(site: SiteRate, limit_m: float) -> tuple[float, float, set[str]]:
    """(metres driven in the field during the outage, metres of them metered at the field's
    rate, the zones decided)."""
    tracker = OutletTracker()
    t_out = None
    in_field = right = 0.0
    zones = set()
    boundary = site.boundary
    assert boundary is not None
    for step in range(int(40.0 / DT_S)):
        t = step * DT_S
        odo = V_MS * t
        x, y, heading = path_at(odo)
        if t_out is None and odo >= OUTAGE_FROM_Y_M:
            t_out = t
        out = t_out is not None and t < t_out + OUTAGE_S
        if step % 2 == 0 and not out:  # 5 Hz fixes
            tracker.on_fix(*latlon(x, y), heading, 8.0, odo)
        outlet = tracker.position(odo)
        assert outlet is not None
        d = site.decide(0.55, (outlet.lat, outlet.lon), lost=outlet.reckoned_past(limit_m))
        zones.add(str(d.zone))
        if out and boundary.zone(*latlon(x, y)) == "field":
            in_field += V_MS * DT_S
            right += V_MS * DT_S if d.total_kg_ha == FIELD_KG_HA else 0.0
    return in_field, right, zones


@pytest.fixture
def site(tmp_path: Path) -> SiteRate:
    polygons: list[shapely.Geometry] = [box(-50, -50, 50, 50)]
    field = write_polygons(tmp_path / "f.gpkg", polygons, {"n": [1]})
    boundary = load_boundary(BoundaryConfig(path=str(field), headland_m=10.0))
    return SiteRate(LinearRate(LinearRateConfig()), None, boundary)


def test_an_outage_at_a_turn_meters_the_field_at_its_rate(site: SiteRate) -> None:
    in_field, right, zones = replay(site, limit_m=10.0)
    assert in_field == pytest.approx(32.8, abs=0.5)  # back in the field before the fix returns
    assert right == pytest.approx(in_field)  # every metre of it at 300 kg/ha
    assert UNKNOWN in zones and "headland" in zones
    # Without a limit (carried along the old heading for ever) the same outage meters none of
    # it: the estimate runs north out of the field while the machine is back inside.
    _, unlimited, _ = replay(site, limit_m=math.inf)
    assert unlimited == 0.0


def test_a_configured_fallback_rate_while_the_position_is_unknown(site: SiteRate) -> None:
    site.unknown_kg_ha = 150.0
    d = site.decide(0.55, latlon(0, 0), lost=True)
    assert (d.total_kg_ha, d.zone, d.used_ndvi) == (150.0, UNKNOWN, False)
    site.unknown_kg_ha = -1.0
    assert site.decide(0.55, latlon(0, 0)).total_kg_ha == FIELD_KG_HA
    assert site.decide(0.55, latlon(0, 45)).total_kg_ha == 0.0  # the headland: not remembered
    assert site.decide(0.55, latlon(0, 45), lost=True).total_kg_ha == FIELD_KG_HA


def test_the_tracker_says_how_far_it_carried_the_position() -> None:
    tracker = OutletTracker()
    tracker.on_fix(*latlon(0, 0), 0.0, 8.0, 100.0)
    at = tracker.position(112.5)
    assert at is not None and at.carried_m == 12.5
    assert at.reckoned_past(10.0) and not at.reckoned_past(12.5)


@pytest.mark.parametrize(
    ("line", "key"),
    [("dead_reckon_m = -1", "gnss.dead_reckon_m"), ("unknown_kg_ha = 5000", "gnss.unknown_kg_ha")],
)
def test_the_dead_reckoning_keys_are_checked(line: str, key: str) -> None:
    with pytest.raises(ConfigError, match=key):
        loads_config(f"[gnss]\n{line}\n")
    assert loads_config("[gnss]\ndead_reckon_m = 25.0\n").gnss.dead_reckon_m == 25.0


def test_an_unknown_position_is_an_alarm_while_operating() -> None:
    from topdress.terminal.alarms import AlarmBook, AlarmInputs

    def inputs(lost: bool, operating: bool) -> AlarmInputs:
        return AlarmInputs(
            metering=operating,
            target_rpm=(0.0, 0.0),
            meter_rpm=(0.0, 0.0),
            faults=0,
            gnss_link="ok",
            crop_link="ok",
            ecu_link="ok",
            operating=operating,
            position_lost=lost,
        )

    book = AlarmBook(10.0, 3.0)
    assert [n for n, _ in book.update(0.0, inputs(lost=True, operating=False))] == []
    assert [n for n, _ in book.update(0.1, inputs(lost=False, operating=True))] == []
    assert [n for n, _ in book.update(0.2, inputs(lost=True, operating=True))] == [
        "position_unknown"
    ]
