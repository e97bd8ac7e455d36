"""The live map: the field boundary, the prescription zones, the track as a swath of the
working width coloured by rate, and the machine.

Leaflet without any tile layer (the cab has no network): everything is drawn on a blank
background in geographic coordinates, so scale and shape are true. The boundary and the zones
are read from the files the configuration names, with the terminal's own readers (topdress.geo),
once when the display starts; nothing is imported for them when none is configured.
"""

from __future__ import annotations

import json
import logging
import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from nicegui import ui

from topdress.config import TerminalConfig
from topdress.display.hub import DisplayHub, TrackPoint
from topdress.errors import TopdressError
from topdress.view.snapshot import ZONE_UNKNOWN

log = logging.getLogger(__name__)

_EARTH_R_M = 6_371_000.0
MAX_SEGMENTS = 3000  # swath pieces kept on the live map (older ones drop off)
MACHINE_LEN_M = 3.0  # the machine's arrow
ARROW_FIX = {
    "color": "#000",
    "weight": 1,
    "dashArray": "",
    "fillColor": "#fdd835",
    "fillOpacity": 1,
}
#: The arrow while the position is dead reckoned past its limit: hollow, dashed, an estimate
#: (its red 3.7:1 on the night map and 3.9:1 on the day one).
ARROW_ESTIMATED = {"color": "#ff1744", "weight": 3, "dashArray": "4 3", "fillOpacity": 0.2}

LatLon = tuple[float, float]
Ring = list[LatLon]
MAX_ZONES = 2000  # zones or grid cells drawn (a finer grid is drawn up to this many)


@dataclass(frozen=True)
class ZoneShape:
    rings: list[Ring]  # the outer ring, then any holes, as (lat, lon)
    rate_kg_ha: float
    label: str


@dataclass
class FieldMaps:
    """The field's boundary and prescription zones as plain rings (lat, lon) for the map."""

    boundary: list[Ring] = field(default_factory=list)  # outer rings (several parts)
    headland: list[Ring] = field(default_factory=list)  # the worked field inside the headland
    zones: list[ZoneShape] = field(default_factory=list)
    field_ha: float | None = None  # area inside the headland: what is to be worked
    errors: list[str] = field(default_factory=list)


def _rings(geom: Any) -> list[list[Ring]]:
    """Each polygon of a (multi)polygon as its rings of (lat, lon)."""
    parts = getattr(geom, "geoms", [geom])
    out = []
    for poly in parts:
        rings = [poly.exterior, *poly.interiors]
        out.append([[(float(y), float(x)) for x, y in ring.coords] for ring in rings])
    return out


def load_field_maps(cfg: TerminalConfig) -> FieldMaps:
    """The boundary and the zones the configuration names; a file that cannot be read is
    said (the terminal itself refuses to start with it, so this is rare) and left out."""
    maps = FieldMaps()
    if cfg.boundary.path:
        try:
            from topdress.geo.boundary import load_boundary

            b = load_boundary(cfg.boundary)
            maps.boundary = [rings[0] for rings in _rings(b.boundary)]
            if cfg.boundary.headland_m > 0:
                maps.headland = [rings[0] for rings in _rings(b.inner_wgs84())]
            maps.field_ha = float(b.inner.area) / 10_000.0
        except (TopdressError, OSError, ValueError) as exc:
            maps.errors.append(f"boundary: {exc}")
    if cfg.prescription.path:
        try:
            maps.zones = _zones(cfg)
        except (TopdressError, OSError, ValueError) as exc:
            maps.errors.append(f"prescription: {exc}")
    for error in maps.errors:
        log.warning("map: %s", error)
    return maps


def _zones(cfg: TerminalConfig) -> list[ZoneShape]:
    from topdress.geo.prescription import GridPrescription, PolygonPrescription, load_prescription

    rx = load_prescription(cfg.prescription)
    out: list[ZoneShape] = []
    if isinstance(rx, PolygonPrescription):
        for i, geom in enumerate(rx.geoms[:MAX_ZONES]):
            for rings in _rings(geom):
                out.append(ZoneShape(rings, float(rx.rate[i]), rx.label(i)))
    elif isinstance(rx, GridPrescription):
        g = rx.grid
        rows, cols = g.values.shape
        for r in range(rows):
            for c in range(cols):
                rate = float(g.values[r, c])
                if math.isnan(rate):
                    continue
                lat, lon = g.min_lat + r * g.cell_lat, g.min_lon + c * g.cell_lon
                cell = [(lat, lon), (lat + g.cell_lat, lon), (lat + g.cell_lat, lon + g.cell_lon),
                        (lat, lon + g.cell_lon)]  # fmt: skip
                out.append(ZoneShape([cell], rate, f"row {r} column {c}"))
    return out[:MAX_ZONES]


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


# The field fitted again when the map's size changes (another screen size, a window resized,
# the panel shown at another size): Leaflet keeps the zoom and only moves the centre.
REFIT_JS = """(() => {
  const c = getElement(%d); if (!c || !c.map) return;
  const box = c.$el; box.tdFit = %s;
  if (box.tdFitObserver) return;
  let size = [box.clientWidth, box.clientHeight];
  box.tdFitObserver = new ResizeObserver(() => {
    const now = [box.clientWidth, box.clientHeight];
    if (!now[0] || !now[1] || (now[0] === size[0] && now[1] === size[1])) return;
    size = now;
    c.map.invalidateSize({pan: false});
    c.map.fitBounds(box.tdFit, {padding: [8, 8]});
  });
  box.tdFitObserver.observe(box);
})();"""


class LiveMap:
    """A Leaflet map fed from the hub's track; `update()` adds what was driven since."""

    def __init__(
        self, hub: DisplayHub, width_m: float, max_kg_ha: float, maps: FieldMaps | None = None
    ) -> None:
        self.hub = hub
        self.width_m = width_m
        self.max_kg_ha = max_kg_ha
        self.maps = maps or FieldMaps()
        self._field_drawn = False
        self.map = (
            ui.leaflet(
                center=(0.0, 0.0),
                zoom=19,
                options={"attributionControl": False, "maxZoom": 23, "zoomSnap": 0.5},
            )
            .classes("w-full flex-1")
            .style("min-height: 160px")
            .mark("map")
        )
        self.map.clear_layers()  # no tile server in the cab: Leaflet's default layer goes
        self._seen = 0
        self._last: TrackPoint | None = None
        self._segments: deque[Any] = deque()
        self._machine: Any = None
        self._estimated = False  # the arrow drawn as an estimate (position unknown)
        self._centred = False

    def _draw_field(self) -> None:
        """The zones (filled by their rate, outlined) under the boundary (a thick line) and the
        headland's inner edge (dashed); the view fitted to the boundary."""
        self._field_drawn = True
        m = self.maps
        for z in m.zones:
            style = {
                "color": "#37474f",
                "className": "td-zone",  # lighter by night (style.py)
                "weight": 1,
                "fillColor": rate_colour(z.rate_kg_ha, self.max_kg_ha),
                "fillOpacity": 0.18,
            }
            self.map.generic_layer(name="polygon", args=[z.rings, style])
        for ring in m.boundary:
            style = {"color": "#000", "weight": 3, "fill": False, "className": "td-boundary"}
            self.map.generic_layer(name="polygon", args=[ring, style])
        for ring in m.headland:
            style = {
                "color": "#000",
                "weight": 1,
                "dashArray": "6 4",
                "fill": False,
                "className": "td-boundary",
            }
            self.map.generic_layer(name="polygon", args=[ring, style])
        outline = [p for ring in m.boundary for p in ring] or [
            p for z in m.zones for p in z.rings[0]
        ]
        if outline:
            lats, lons = [p[0] for p in outline], [p[1] for p in outline]
            bounds = [[min(lats), min(lons)], [max(lats), max(lons)]]
            self.map.run_map_method("fitBounds", bounds, {"padding": [8, 8]})
            self.map.client.run_javascript(REFIT_JS % (self.map.id, json.dumps(bounds)))
            self._centred = True

    def update(self) -> None:
        if not self.map.is_initialized:
            return  # layers added before the map exists in the browser would be lost
        if not self._field_drawn:
            self._draw_field()
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
            self._machine = self.map.generic_layer(name="polygon", args=[arrow, ARROW_FIX])
        elif points:
            self.map.run_layer_method(self._machine.id, "setLatLngs", arrow)
            self.map.run_layer_method(self._machine.id, "bringToFront")
        estimated = self.hub.latest()[2].zone == ZONE_UNKNOWN
        if estimated != self._estimated:
            self._estimated = estimated
            style = ARROW_ESTIMATED if estimated else ARROW_FIX
            self.map.run_layer_method(self._machine.id, "setStyle", style)
        if not self._centred:
            self.map.set_center((p.lat, p.lon))
            self._centred = True
        elif points:
            # Pan only when the machine nears the edge: redrawing the whole swath every second
            # would cost the browser (and a 2-core cab PC) for nothing.
            self.map.run_map_method("panInside", [p.lat, p.lon], {"padding": [40, 40]})
