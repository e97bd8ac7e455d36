"""The as-applied map: swaths coloured by rate class (or by the paper's metering-speed
classes), the track, the stops, the boundary zones; as PNG (matplotlib) or as one offline HTML
file (Leaflet 1.9.4 bundled in the package and inlined: no tile server, no network).

`map_layers()` gives the layers as GeoJSON-like dicts (plus `boundary_rings()` for the
field boundary and its headland line); the PNG, the HTML and a live display
draw the same layers.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, Final

import numpy as np
import numpy.typing as npt
import shapely

from topdress.errors import MapError
from topdress.geo.asapplied import AsApplied, AsAppliedStream, require_any_point
from topdress.geo.boundary import load_boundary
from topdress.log.session import SessionReader, session_config
from topdress.log.summary import summarise

# Colour ramp for the classes (low to high), readable in print and for most colour vision.
RAMP: Final = ("#ffffcc", "#c2e699", "#78c679", "#31a354", "#006837", "#004529")
ZERO_COLOUR: Final = "#d7301f"  # nothing applied
# The paper's metering-speed classes (r/min, Fig. 11 style): stopped, then 10 r/min steps.
RPM_BREAKS: Final = (0.0, 10.0, 20.0, 30.0, 40.0, 50.0)
STOP_KMH: Final = 0.5
# A long session's map is thinned (`_thinned`): from THIN_FROM_ROWS state rows (half an hour at
# 10 Hz) on, neighbouring swaths of a class are joined (MERGE_MAX at most, their shared edges
# taken out to MERGE_TOLERANCE_DEG, about 5 mm) and the track keeps the points that turn it
# by more than TRACK_TOLERANCE_DEG (about 0.1 m).
THIN_FROM_ROWS: Final = 18_000
MERGE_MAX: Final = 50
MERGE_TOLERANCE_DEG: Final = 5e-8
TRACK_TOLERANCE_DEG: Final = 1e-6


@dataclass(frozen=True)
class MapClass:
    label: str
    colour: str
    lo: float
    hi: float


def rate_classes(values: npt.NDArray[np.float64], n: int = 5) -> list[MapClass]:
    """A class for nothing applied and `n` equal classes of 10 kg/ha-rounded bounds over the
    rest (between its 2nd and 98th percentiles: the last class is open above)."""
    pos = values[np.isfinite(values) & (values > 0)]
    if pos.size:
        pos = pos[(pos >= np.percentile(pos, 2)) & (pos <= np.percentile(pos, 98))]
    classes = [MapClass("0 kg/ha", ZERO_COLOUR, -math.inf, 1e-9)]
    if pos.size == 0:
        return classes
    lo = math.floor(float(np.min(pos)) / 10.0) * 10.0
    hi = math.ceil(float(np.max(pos)) / 10.0) * 10.0
    step = max(math.ceil((hi - lo) / n / 10.0) * 10.0, 10.0)
    edges = [lo + i * step for i in range(n + 1)]
    for i in range(n):
        top = math.inf if i == n - 1 else edges[i + 1]
        # the first class takes everything above 0 below its top (the values under the 2nd
        # percentile too): its label says so
        if i == 0:
            label = f"<{edges[1]:g} kg/ha"
        elif i < n - 1:
            label = f"{edges[i]:g}-{edges[i + 1]:g} kg/ha"
        else:
            label = f">{edges[i]:g} kg/ha"
        classes.append(MapClass(label, RAMP[i], 1e-9 if i == 0 else edges[i], top))
    return classes


def rpm_classes() -> list[MapClass]:
    out = [MapClass("0 r/min", ZERO_COLOUR, -math.inf, 1e-9)]
    for i, lo in enumerate(RPM_BREAKS[:-1]):
        hi = RPM_BREAKS[i + 1]
        top = math.inf if i == len(RPM_BREAKS) - 2 else hi
        label = f"{lo:g}-{hi:g} r/min" if top != math.inf else f">{lo:g} r/min"
        out.append(MapClass(label, RAMP[i], max(lo, 1e-9), top))
    return out


def map_layers(
    data: AsApplied, classes: str = "rate", stops: list[tuple[float, float]] | None = None
) -> dict[str, Any]:
    """swaths (each with its class), track, stops, classes: lon/lat GeoJSON-like dicts.
    `stops`: (lon, lat) of each stop (`log summary`'s, which `render` passes); None: where the
    exported speed falls below 0.5 km/h."""
    pts = shapely.get_coordinates(data.point_geom)
    if stops is None:
        speed = np.asarray(data.points.get("SPEED", np.zeros(0)), float)
        moving_before = np.concatenate([[False], speed[:-1] >= STOP_KMH])
        where = pts[np.nonzero((speed < STOP_KMH) & moving_before)[0]]
    else:
        where = np.array(stops, dtype=float).reshape(-1, 2)
    return _layers(pts, data.swath_geom, data.swaths, classes, where, thin=False)


def _layers(
    track: npt.NDArray[np.float64],
    swath_geom: npt.NDArray[np.object_],
    swaths: dict[str, npt.NDArray[np.generic]],
    classes: str,
    stops: npt.NDArray[np.float64],
    thin: bool,
) -> dict[str, Any]:
    """The map's layers; `thin`: a long session's track without the points on a straight
    line, and neighbouring swaths of one class drawn as one polygon (`_thinned`)."""
    if classes == "rpm":
        value = np.asarray(swaths.get("RpmUp", np.zeros(0)), float)
        cls = rpm_classes()
    else:
        value = np.asarray(swaths.get("AppliedRate", np.zeros(0)), float)
        cls = rate_classes(value)
    zone = np.asarray(swaths.get("Zone", np.array([""] * swath_geom.size, dtype=object)))
    k = np.zeros(value.size, dtype=np.intp)
    for i in range(len(cls) - 1, -1, -1):  # the first class that holds a value, as before
        k[(cls[i].lo <= value) & (value < cls[i].hi)] = i
    geoms = swath_geom
    if thin and geoms.size > 1:
        geoms, value, k, zone = _thinned(geoms, swaths, classes, value, k, zone)
        if track.shape[0] > 2:
            line = shapely.simplify(
                shapely.LineString(track), TRACK_TOLERANCE_DEG, preserve_topology=False
            )
            track = shapely.get_coordinates(line)
    feats = []
    for g, v, c, z in zip(geoms, value.tolist(), k.tolist(), zone.tolist(), strict=True):
        ring = shapely.get_coordinates(g).round(8).tolist()
        feats.append({"ring": ring, "value": round(v, 2), "cls": c, "zone": str(z)})
    return {
        "classes": [c.__dict__ | {"lo": _finite(c.lo), "hi": _finite(c.hi)} for c in cls],
        "swaths": feats,
        "track": track.round(8).tolist(),
        "stops": stops.round(8).tolist(),
        "unit": "r/min" if classes == "rpm" else "kg/ha",
    }


def _thinned(
    geoms: npt.NDArray[np.object_],
    swaths: dict[str, npt.NDArray[np.generic]],
    classes: str,
    value: npt.NDArray[np.float64],
    k: npt.NDArray[np.intp],
    zone: npt.NDArray[np.generic],
) -> tuple[
    npt.NDArray[np.object_], npt.NDArray[np.float64], npt.NDArray[np.intp], npt.NDArray[np.generic]
]:
    """Runs of neighbouring swaths (one after the other, touching) in one class and zone, at
    most MERGE_MAX of them, as one polygon: its value the run's dose (kg over area), or its
    metering speed over time. A pass is a few polygons instead of one per metre."""
    same = (k[1:] == k[:-1]) & (zone[1:] == zone[:-1]) & shapely.intersects(geoms[:-1], geoms[1:])
    starts = [0]
    for i, joined in enumerate(same.tolist(), start=1):
        if not joined or i - starts[-1] >= MERGE_MAX:
            starts.append(i)
    bounds = np.append(starts, geoms.size)
    if classes == "rpm":
        num = np.asarray(swaths["RpmUp"], float) * np.asarray(swaths["DURATION"], float)
        den = np.asarray(swaths["DURATION"], float)
    else:
        num, den = np.asarray(swaths["AppliedKg"], float), np.asarray(swaths["AREA"], float)
    out_g, out_v, out_k, out_z = [], [], [], []
    for a, b in zip(bounds[:-1].tolist(), bounds[1:].tolist(), strict=True):
        if b - a == 1:
            parts = [geoms[a]]
            v = float(value[a])
        else:
            merged = shapely.simplify(shapely.union_all(geoms[a:b]), MERGE_TOLERANCE_DEG)
            parts = [shapely.Polygon(p.exterior) for p in shapely.get_parts(merged) if p.area > 0]
            total = float(np.sum(den[a:b]))
            v = float(np.sum(num[a:b])) / total if total > 0 else float(value[a])
        for part in parts:
            out_g.append(part)
            out_v.append(v)
            out_k.append(int(k[a]))
            out_z.append(zone[a])
    return (
        np.array(out_g, dtype=object),
        np.array(out_v, dtype=float),
        np.array(out_k, dtype=np.intp),
        np.array(out_z, dtype=object),
    )


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None


def boundary_rings(reader: SessionReader) -> tuple[list[list[list[float]]], str | None]:
    """The session's field boundary and headland line (lon/lat rings), when its configuration
    names a boundary file that is still there; else no rings and why not."""
    cfg = session_config(reader.config_toml).boundary
    if not cfg.path:
        return [], None
    try:
        b = load_boundary(cfg)
    except MapError as exc:
        return [], f"boundary not drawn: {exc}"
    rings = []
    for geom in (b.boundary, b.inner_wgs84()):
        for line in shapely.get_parts(shapely.boundary(geom)):
            for part in shapely.get_parts(line):
                rings.append(shapely.get_coordinates(part).round(8).tolist())
    return rings, None


def render(reader: SessionReader, out: Path, classes: str = "rate") -> str:
    """The map of the session to `out` (.png or .html); returns a line saying what was drawn."""
    stream = AsAppliedStream(reader)
    require_any_point(stream)
    # The summary's stops (its speed and threshold): the map shows as many as it counts.
    stops = [
        (e.lon, e.lat)
        for e in summarise(reader).stops
        if e.kind == "stop" and e.lat is not None and e.lon is not None
    ]
    # Read a chunk at a time: only the track's coordinates and the swaths are kept.
    track = stream.positions()
    keep = ("AppliedRate", "RpmUp", "Zone", "AppliedKg", "AREA", "DURATION")
    got = [({n: c[n] for n in keep}, g) for c, g in stream.swath_batches()]
    swaths = {n: np.concatenate([c[n] for c, _ in got]) for n in keep} if got else {}
    geoms = np.concatenate([g for _, g in got]) if got else np.empty(0, object)
    n_swaths, thin = stream.swaths, stream.rows >= THIN_FROM_ROWS
    del got, stream  # the day's columns: not needed for drawing
    where = np.array(stops, dtype=float).reshape(-1, 2)
    layers = _layers(track, geoms, swaths, classes, where, thin)
    layers["boundary"], why = boundary_rings(reader)
    suffix = out.suffix.lower()
    try:
        if suffix == ".png":
            _png(layers, out, reader.path.name)
        elif suffix in (".html", ".htm"):
            out.write_text(_html(layers, reader.path.name), encoding="utf-8")
        else:
            raise MapError(f"{out}: the map is .png or .html")
    except OSError as exc:
        raise MapError(f"cannot write {out}: {exc}") from exc
    return (
        f"{out}: {n_swaths} swaths"
        + (f" (drawn as {len(layers['swaths'])} polygons)" if thin else "")
        + f" in {len(layers['classes'])} classes, "
        f"{len(layers['stops'])} stops" + (f"; {why}" if why else "")
    )


def _png(layers: dict[str, Any], out: Path, title: str) -> None:
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection
    from matplotlib.patches import Patch

    fig, ax = plt.subplots(figsize=(8, 8), dpi=120)
    classes = layers["classes"]
    track = np.array(layers["track"])
    lat0 = float(np.mean(track[:, 1])) if track.size else 0.0
    if layers["swaths"]:
        polys = [np.array(s["ring"]) for s in layers["swaths"]]
        colours = [classes[s["cls"]]["colour"] for s in layers["swaths"]]
        ax.add_collection(PolyCollection(polys, facecolors=colours, edgecolors="none"))
    if track.size:
        ax.plot(track[:, 0], track[:, 1], color="#555555", lw=0.6, label="track")
    for k, ring in enumerate(layers.get("boundary", [])):
        r = np.array(ring)
        ax.plot(r[:, 0], r[:, 1], color="#0b4f9c", lw=1.0, label="boundary" if k == 0 else None)
    stops = np.array(layers["stops"])
    if stops.size:
        ax.plot(stops[:, 0], stops[:, 1], "kx", ms=7, label="stops")
    ax.set_aspect(1.0 / math.cos(math.radians(lat0)))
    ax.autoscale_view()
    ax.set_xlabel("longitude, deg")
    ax.set_ylabel("latitude, deg")
    ax.ticklabel_format(useOffset=False)
    ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(3))
    ax.tick_params(axis="x", labelrotation=30)
    ax.set_title(f"as applied: {title}")
    handles = [Patch(color=c["colour"], label=c["label"]) for c in classes]
    ax.legend(
        handles=handles + ax.get_legend_handles_labels()[0],
        fontsize=8,
        loc="upper left",
        bbox_to_anchor=(1.02, 1.0),
    )
    # the legend sits outside the axes: the saved figure grows to hold it and the labels
    fig.savefig(out, bbox_inches="tight", pad_inches=0.15)
    plt.close(fig)


def _asset(name: str) -> str:
    return resources.files("topdress.geo").joinpath("data", name).read_text(encoding="utf-8")


def _html(layers: dict[str, Any], title: str) -> str:
    js = _asset("leaflet.js").replace("</script", "<\\/script")
    css = _asset("leaflet.css")
    data = json.dumps(layers, separators=(",", ":")).replace("</", "<\\/")
    return f"""<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>as applied: {title}</title>
<style>{css}
html,body,#map{{height:100%;margin:0}} .legend{{background:#fff;padding:6px;font:12px sans-serif}}
.legend i{{display:inline-block;width:14px;height:10px;margin-right:4px}}</style>
<script>{js}</script></head>
<body><div id="map"></div><script>
const L_DATA = {data};
const map = L.map("map", {{preferCanvas: true}});
const swaths = L.layerGroup(L_DATA.swaths.map(s => L.polygon(
  s.ring.map(p => [p[1], p[0]]),
  {{stroke: false, fillOpacity: 0.85, fillColor: L_DATA.classes[s.cls].colour}}
).bindTooltip(s.value + " " + L_DATA.unit + (s.zone ? " (" + s.zone + ")" : ""))));
const track = L.polyline(L_DATA.track.map(p => [p[1], p[0]]), {{color: "#555", weight: 1}});
const stops = L.layerGroup(L_DATA.stops.map(p => L.circleMarker([p[1], p[0]],
  {{radius: 5, color: "#000", fill: false}}).bindTooltip("stop")));
const boundary = L.layerGroup((L_DATA.boundary || []).map(r => L.polyline(
  r.map(p => [p[1], p[0]]), {{color: "#0b4f9c", weight: 2}})));
swaths.addTo(map); track.addTo(map); stops.addTo(map); boundary.addTo(map);
L.control.layers(null, {{"swaths": swaths, "track": track, "stops": stops, "boundary": boundary}})
  .addTo(map);
L.control.scale({{imperial: false}}).addTo(map);
map.fitBounds(track.getBounds(), {{padding: [20, 20]}});
const legend = L.control({{position: "bottomright"}});
legend.onAdd = () => {{
  const d = L.DomUtil.create("div", "legend");
  d.innerHTML = L_DATA.classes.map(c => '<i style="background:' + c.colour + '"></i>' + c.label)
    .join("<br>");
  return d;
}};
legend.addTo(map);
</script></body></html>
"""
