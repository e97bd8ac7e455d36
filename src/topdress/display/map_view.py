"""The live map: the track as a swath of the working width coloured by rate, and the machine.

Leaflet without any tile layer (the cab has no network): the swath and the machine are drawn on
a blank background in geographic coordinates, so scale and shape are true.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

from nicegui import ui

from topdress.display.hub import DisplayHub, TrackPoint

_EARTH_R_M = 6_371_000.0
MAX_SEGMENTS = 3000  # swath pieces kept on the live map (older ones drop off)
MACHINE_LEN_M = 3.0  # the machine's arrow

LatLon = tuple[float, float]


def offset(lat: float, lon: float, east_m: float, north_m: float) -> LatLon:
    """The point `east_m`, `north_m` away on a local plane."""
    dlat = math.degrees(north_m / _EARTH_R_M)
    dlon = math.degrees(east_m / (_EARTH_R_M * math.cos(math.radians(lat))))
    return (lat + dlat, lon + dlon)


def swath_quad(a: TrackPoint, b: TrackPoint, width_m: float) -> list[LatLon]:
    """The strip of `width_m` covered between two track points (heading of the second)."""
    h = math.radians(b.heading_deg)
    # Unit vector to the right of the direction of travel: (east, north) = (cos h, -sin h).
    rx, ry = math.cos(h) * width_m / 2, -math.sin(h) * width_m / 2
    return [
        offset(a.lat, a.lon, -rx, -ry),
        offset(a.lat, a.lon, rx, ry),
        offset(b.lat, b.lon, rx, ry),
        offset(b.lat, b.lon, -rx, -ry),
    ]


def machine_arrow(lat: float, lon: float, heading_deg: float, length_m: float) -> list[LatLon]:
    """A triangle pointing along the heading, its tip at the machine's position."""
    h = math.radians(heading_deg)
    fx, fy = math.sin(h), math.cos(h)  # forward (east, north)
    rx, ry = math.cos(h), -math.sin(h)  # right
    back_x, back_y = -fx * length_m, -fy * length_m
    half = length_m * 0.4
    return [
        (lat, lon),
        offset(lat, lon, back_x + rx * half, back_y + ry * half),
        offset(lat, lon, back_x - rx * half, back_y - ry * half),
    ]


def rate_colour(rate_kg_ha: float, max_kg_ha: float) -> str:
    """Blue (low) through green to red (high); grey when nothing is applied."""
    if rate_kg_ha <= 0:
        return "#bdbdbd"
    x = min(1.0, max(0.0, rate_kg_ha / max_kg_ha))
    hue = 240 * (1 - x)  # 240 blue .. 0 red
    return f"hsl({hue:.0f}, 80%, 45%)"


class LiveMap:
    """A Leaflet map fed from the hub's track; `update()` adds what was driven since."""

    def __init__(self, hub: DisplayHub, width_m: float, max_kg_ha: float) -> None:
        self.hub = hub
        self.width_m = width_m
        self.max_kg_ha = max_kg_ha
        self.map = ui.leaflet(
            center=(0.0, 0.0),
            zoom=19,
            options={"attributionControl": False, "maxZoom": 23, "zoomSnap": 0.5},
        ).classes("w-full h-64 bg-white")
        self.map.clear_layers()  # no tile server in the cab: Leaflet's default layer goes
        self._seen = 0
        self._last: TrackPoint | None = None
        self._segments: deque[Any] = deque()
        self._machine: Any = None
        self._centred = False

    def update(self) -> None:
        if not self.map.is_initialized:
            return  # layers added before the map exists in the browser would be lost
        self._seen, points = self.hub.track_since(self._seen)
        for p in points:
            if self._last is not None and p.metering:
                quad = swath_quad(self._last, p, self.width_m)
                colour = rate_colour(p.rate_kg_ha, self.max_kg_ha)
                style = {"stroke": False, "fillColor": colour, "fillOpacity": 0.85}
                self._segments.append(self.map.generic_layer(name="polygon", args=[quad, style]))
                if len(self._segments) > MAX_SEGMENTS:
                    self.map.remove_layer(self._segments.popleft())
            self._last = p
        if self._last is None:
            return
        p = self._last
        arrow = machine_arrow(p.lat, p.lon, p.heading_deg, MACHINE_LEN_M)
        if self._machine is None:
            style = {"color": "#000", "weight": 1, "fillColor": "#fdd835", "fillOpacity": 1}
            self._machine = self.map.generic_layer(name="polygon", args=[arrow, style])
        elif points:
            self.map.run_layer_method(self._machine.id, "setLatLngs", arrow)
            self.map.run_layer_method(self._machine.id, "bringToFront")
        if not self._centred:
            self.map.set_center((p.lat, p.lon))
            self._centred = True
        elif points:
            # Pan only when the machine nears the edge: redrawing the whole swath every second
            # would cost the browser (and a 2-core cab PC) for nothing.
            self.map.run_map_method("panInside", [p.lat, p.lon], {"padding": [40, 40]})
