"""Where the meters' outlet is: the GNSS antenna's position moved by the configured offsets
along and across the track, using the heading.

Offsets are metres in the machine's frame: `along_m` positive forward (an outlet behind the
antenna is negative), `across_m` positive to the right. Over a few metres the earth is flat to
well under a millimetre, so the offset is applied in a local east/north frame scaled by the
WGS 84 ellipsoid's radii of curvature at the latitude.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

import numpy as np
import numpy.typing as npt

WGS84_A_M: Final = 6_378_137.0
WGS84_E2: Final = 6.694379990141317e-3
# Below this speed the course over ground is noise: the last good heading is held.
HEADING_MIN_KMH: Final = 1.0

FloatArray = npt.NDArray[np.float64]


def offset_position(
    lat: float, lon: float, heading_deg: float, along_m: float, across_m: float
) -> tuple[float, float]:
    """The point `along_m` ahead and `across_m` to the right of (lat, lon), heading clockwise
    from north."""
    h = math.radians(heading_deg)
    east = along_m * math.sin(h) + across_m * math.cos(h)
    north = along_m * math.cos(h) - across_m * math.sin(h)
    m_r, n_r = radii_m(lat)
    dlat = math.degrees(north / m_r)
    dlon = math.degrees(east / (n_r * math.cos(math.radians(lat))))
    return lat + dlat, lon + dlon


def radii_m(lat: float) -> tuple[float, float]:
    """Meridional and prime-vertical radii of curvature of WGS 84 at `lat`, m."""
    w2 = 1.0 - WGS84_E2 * math.sin(math.radians(lat)) ** 2
    return WGS84_A_M * (1.0 - WGS84_E2) / w2**1.5, WGS84_A_M / math.sqrt(w2)


def offset_positions(
    lat: FloatArray, lon: FloatArray, heading_deg: FloatArray, along_m: float, across_m: float
) -> tuple[FloatArray, FloatArray]:
    """`offset_position` over arrays."""
    h = np.radians(heading_deg)
    east = along_m * np.sin(h) + across_m * np.cos(h)
    north = along_m * np.cos(h) - across_m * np.sin(h)
    w2 = 1.0 - WGS84_E2 * np.sin(np.radians(lat)) ** 2
    m_r, n_r = WGS84_A_M * (1.0 - WGS84_E2) / w2**1.5, WGS84_A_M / np.sqrt(w2)
    dlat = np.degrees(north / m_r)
    dlon = np.degrees(east / (n_r * np.cos(np.radians(lat))))
    return lat + dlat, lon + dlon


@dataclass(frozen=True)
class OutletFix:
    lat: float
    lon: float
    heading_deg: float | None  # None: not known yet (no offset needed)
    carried_m: float = 0.0  # dead reckoned along the heading since the last fix, m

    def reckoned_past(self, limit_m: float) -> bool:
        """Carried farther from its fix than `limit_m` (gnss.dead_reckon_m): not known."""
        return self.carried_m > limit_m


class OutletTracker:
    """Feed it every GNSS fix with the odometer reading at its arrival; `position(odometer)`
    gives the outlet where it is now.

    Between fixes (5-10 Hz) and for the fix's age the antenna is carried forward along the
    heading by the distance the odometer ran since the fix: the odometer integrates the ECU's
    selected speed, the same distance compensation as the NDVI's distance queue.
    """

    def __init__(self, along_m: float = 0.0, across_m: float = 0.0) -> None:
        self.along_m = along_m
        self.across_m = across_m
        self.heading_deg: float | None = None
        self._fix: tuple[float, float, float] | None = None  # lat, lon, odometer at the fix

    def on_fix(
        self,
        lat: float | None,
        lon: float | None,
        course_deg: float | None,
        speed_kmh: float | None,
        odometer_m: float,
    ) -> None:
        if course_deg is not None and speed_kmh is not None and speed_kmh >= HEADING_MIN_KMH:
            self.heading_deg = course_deg % 360.0
        if lat is not None and lon is not None:
            self._fix = (lat, lon, odometer_m)

    def position(self, odometer_m: float) -> OutletFix | None:
        """None before the first fix, or while the heading is unknown (the offset needs it)."""
        if self._fix is None:
            return None
        lat, lon, odo = self._fix
        heading = self.heading_deg
        if heading is None:
            if self.along_m or self.across_m:
                return None
            return OutletFix(lat, lon, None, max(odometer_m - odo, 0.0))
        carried = max(odometer_m - odo, 0.0)
        lat, lon = offset_position(lat, lon, heading, carried + self.along_m, self.across_m)
        return OutletFix(lat, lon, heading, carried)
