"""The outlet's position from the antenna's, UTC on every record, eq. 4 inverted."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from pyproj import Geod

from topdress.ecu import meter_rate_kg_ha, meter_target_rpm
from topdress.errors import EcuError
from topdress.geo.outlet import OutletTracker, offset_position, offset_positions
from topdress.gnss.utc import UtcClock, parse_fix_utc

GEOD = Geod(ellps="WGS84")


@pytest.mark.parametrize("heading", [0.0, 90.0, 180.0, 270.0, 33.0])
def test_offset_matches_the_ellipsoid(heading: float) -> None:
    lat, lon = 43.8853, 125.3245
    # 3 m behind the antenna, 1.2 m to the right
    olat, olon = offset_position(lat, lon, heading, -3.0, 1.2)
    az, _, dist = GEOD.inv(lon, lat, olon, olat)
    assert dist == pytest.approx(math.hypot(3.0, 1.2), abs=0.001)
    # behind and to the right: the bearing is heading + 180 - atan(1.2/3)
    expected = (heading + 180.0 - math.degrees(math.atan2(1.2, 3.0))) % 360.0
    assert (az % 360.0) == pytest.approx(expected, abs=0.2)


def test_offsets_over_arrays_equal_the_scalar() -> None:
    lat = np.array([43.0, 43.001]), np.array([125.0, 125.002]), np.array([10.0, 200.0])
    alat, alon = offset_positions(*lat, -2.5, 0.7)
    for i in range(2):
        assert (alat[i], alon[i]) == pytest.approx(
            offset_position(lat[0][i], lat[1][i], lat[2][i], -2.5, 0.7), abs=1e-12
        )


def test_outlet_carried_forward_by_the_odometer_and_heading_held_when_slow() -> None:
    tr = OutletTracker(along_m=-2.0)
    assert tr.position(0.0) is None  # no fix yet
    tr.on_fix(43.0, 125.0, None, 0.0, 0.0)
    assert tr.position(0.0) is None  # an offset needs a heading
    tr.on_fix(43.0, 125.0, 90.0, 8.0, 10.0)  # eastward
    fix = tr.position(13.0)  # 3 m run since the fix, outlet 2 m behind: 1 m east
    assert fix is not None and fix.heading_deg == 90.0
    _, _, dist = GEOD.inv(125.0, 43.0, fix.lon, fix.lat)
    assert dist == pytest.approx(1.0, abs=0.002) and fix.lon > 125.0
    tr.on_fix(43.0, 125.0, 270.0, 0.3, 13.0)  # standing: the course is noise, heading held
    assert tr.heading_deg == 90.0


def test_utc_from_the_fix_carried_forward_never_the_system_clock(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    clock = UtcClock()
    assert clock.now(5.0) is None  # no fix yet: no UTC, not the PC's clock
    clock.on_fix(5.0, "2026-11-22T08:15:03.200Z")
    base = parse_fix_utc("2026-11-22T08:15:03.200Z")
    assert base is not None
    utc, src = clock.now(5.5) or (0.0, "")
    assert src == "gnss" and utc == pytest.approx(base + 0.5)
    clock.on_fix(6.0, "08:15:04.000")  # GGA: time of day without a date is not enough
    assert (clock.now(6.0) or (0.0,))[0] == pytest.approx(base + 1.0)
    # 25 s, then 10 min without a fix, the PC's clock set back a day meanwhile: the times
    # go on from the receiver's (they switched to the system clock after 10 s, and ran back)
    monkeypatch.setattr(time, "time", lambda: base - 86_400.0)
    assert clock.now(30.0) == (pytest.approx(base + 25.0), "gnss")
    assert clock.now(605.0) == (pytest.approx(base + 600.0), "gnss")


def test_eq4_inverted_in_c_is_linear_in_the_meter_speed() -> None:
    assert meter_rate_kg_ha(3.6, 24.0, 6.0, 0.3) == pytest.approx(200.0, rel=1e-6)
    r = meter_target_rpm(3.6, 137.5, 7.3, 0.25)
    assert meter_rate_kg_ha(3.6, r, 7.3, 0.25) == pytest.approx(137.5, rel=1e-5)
    # linear: the exports scale it over many rows (q = k * R / v, k = 600 p / w)
    for rpm, v in ((5.0, 2.0), (31.7, 9.4), (60.0, 12.0)):
        assert meter_rate_kg_ha(3.6, rpm, v, 0.3) == pytest.approx(
            600 * 0.3 * rpm / (3.6 * v), 1e-5
        )
    assert meter_rate_kg_ha(3.6, 24.0, 0.2, 0.3, 0.5) == 0.0  # standing: not a rate per area
    with pytest.raises(EcuError):
        meter_rate_kg_ha(0.0, 24.0, 6.0, 0.3)
