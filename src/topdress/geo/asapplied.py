"""As-applied records of a session: one point per state row with a position, and swath
polygons where product was applied, with the target and the actual rate per layer.

Swaths follow the machine's path, not its raw fixes: the outlet positions are smoothed with
the steps the machine itself measured (selected speed x interval, along the heading), which
takes a fix's jitter out of the length and the shape; only intervals with a meter turning and
the machine moving make swaths, cut every SWATH_M of path (and where the zone or the
prescription rate changes), each across the path's own direction so that neighbours share
their ends. What was metered standing belongs to the swath where the machine stood. Each
swath's kg and area are sums over its state rows, so the swaths add up to the summary's area
and kg; ground that earlier swaths had covered is flagged (`Overlap`), not cut away.

Each state row holds until the next (left sums, as `topdress log summary` integrates): the
fertilizer a row carries is measured metering speed x kg/rev x its interval, so the kg of the
points add up to the summary's. The actual rate in kg/ha is eq. 4 inverted from the measured
metering speed (`td_meter_rate_kg_ha` of the ECU core; it is linear in the metering speed,
q = 600 p R / (w v), and evaluated here over whole columns at once, checked against the C
function in the tests). At a standstill a rate per area is not defined: the rate is 0 there and
the kg still count (AppliedKg), which is what the headland figures look at.

Sessions written before the outlet, heading and UTC columns existed still export: the antenna
position, a heading from successive positions and UTC from the session's creation time are
used instead, and `notes` says so.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any, Final

import numpy as np
import numpy.typing as npt
import shapely
from pyproj import CRS, Transformer

from topdress.config import MachineConfig, SpeedConfig
from topdress.errors import MapError
from topdress.geo.outlet import offset_positions
from topdress.log.model import STATE_COLUMNS
from topdress.log.session import SessionReader, session_config

_log = logging.getLogger(__name__)

MAX_GAP_S: Final = 1.0  # as the summary: a longer interval is a gap in the log, not integrated
WGS84: Final = CRS.from_epsg(4326)

FloatArray = npt.NDArray[np.float64]
ObjArray = npt.NDArray[np.object_]


def rate_kg_ha(
    meter_rpm: FloatArray, v_kmh: FloatArray, width_m: float, kg_per_rev: float, min_kmh: float
) -> FloatArray:
    """Eq. 4 inverted over columns, as td_meter_rate_kg_ha: 0 below min_kmh, at rest or at a
    standstill."""
    ok = (v_kmh >= min_kmh) & (v_kmh > 0.0) & (meter_rpm > 0.0)
    q = np.zeros_like(meter_rpm)
    np.divide(600.0 * kg_per_rev * meter_rpm, width_m * v_kmh, out=q, where=ok)
    return q


@dataclass
class AsApplied:
    """Columns of the as-applied points (`points`) and swaths (`swaths`), geometry in WGS 84."""

    path: str
    machine: MachineConfig
    points: dict[str, npt.NDArray[np.generic]] = field(default_factory=dict)
    point_geom: npt.NDArray[np.object_] = field(default_factory=lambda: np.empty(0, object))
    swaths: dict[str, npt.NDArray[np.generic]] = field(default_factory=dict)
    swath_geom: npt.NDArray[np.object_] = field(default_factory=lambda: np.empty(0, object))
    notes: list[str] = field(default_factory=list)
    rows: int = 0  # state rows in the session
    utm: CRS | None = None  # the UTM zone of the field

    @property
    def applied_kg(self) -> float:
        return float(np.sum(self.points.get("AppliedKg", np.zeros(0))))


Columns = dict[str, list[Any]]


def _col(rows: Columns, name: str) -> FloatArray:
    return np.array(rows[name], dtype=float)  # None -> nan


def _opt(rows: Columns, name: str) -> FloatArray:
    return np.array(rows[name], dtype=float)


def _text(rows: Columns, name: str) -> ObjArray:
    return np.array(["" if v is None else v for v in rows[name]], dtype=object)


def _iso(utc: FloatArray) -> ObjArray:
    ms = np.round(utc * 1000.0).astype("datetime64[ms]")
    text = np.datetime_as_string(ms, unit="ms")
    return np.array([f"{s}Z" for s in text], dtype=object)


def utm_crs(lat: float, lon: float) -> CRS:
    """The UTM zone (WGS 84) of a point."""
    zone = min(int((lon + 180.0) // 6.0) + 1, 60)
    return CRS.from_epsg((32600 if lat >= 0 else 32700) + zone)


def build(reader: SessionReader) -> AsApplied:
    cfg = session_config(reader.config_toml)
    rows = reader.state_values(STATE_COLUMNS)
    out = AsApplied(str(reader.path), cfg.machine, rows=len(rows["t"]))
    present = reader.state_columns()
    for col, what in (
        ("outlet_lat", "the outlet position (the antenna's is used)"),
        ("heading_deg", "the heading (taken from successive positions)"),
        ("utc", "UTC (the session's creation time plus the monotonic time is used)"),
    ):
        if col not in present:
            out.notes.append(f"this session log has no {col} column: {what}")
    _points(
        out, rows, cfg.machine, cfg.speed, reader.meta.get("created_utc"), "outlet_lat" in present
    )
    return out


def _points(
    out: AsApplied,
    rows: Columns,
    m: MachineConfig,
    speed: SpeedConfig,
    created_utc: str | None,
    has_outlet: bool = True,
) -> None:
    if not rows["t"]:
        out.notes.append("no state rows")
        return
    t = _col(rows, "t")
    dt = np.zeros_like(t)
    dt[:-1] = np.diff(t)
    dt[(dt > MAX_GAP_S) | (dt < 0)] = 0.0
    v = _col(rows, "v_kmh")
    lat, lon = _opt(rows, "outlet_lat"), _opt(rows, "outlet_lon")
    antenna = np.isnan(lat)
    lat[antenna], lon[antenna] = _opt(rows, "lat")[antenna], _opt(rows, "lon")[antenna]
    heading = _opt(rows, "heading_deg")
    if np.isnan(heading).all():
        heading = _track_heading(lat, lon)
    # Until the machine first moves its heading is not known, and the terminal logs no outlet
    # position: the machine starts in the direction it first takes, so the outlet is placed
    # with that heading (else the swaths jump from the antenna to the outlet).
    path_heading = _fill(heading)
    if has_outlet and (m.outlet_along_m or m.outlet_across_m):
        fix = antenna & ~np.isnan(lat) & ~np.isnan(path_heading)
        lat[fix], lon[fix] = offset_positions(
            lat[fix], lon[fix], path_heading[fix], m.outlet_along_m, m.outlet_across_m
        )
    utc = _opt(rows, "utc")
    src = _text(rows, "utc_source")
    missing = np.isnan(utc)
    if missing.any():
        base = _created(created_utc)
        if base is None:
            out.notes.append("no UTC for some rows and no creation time: those rows have none")
        else:
            utc[missing] = base + (t[missing] - t[0])
            src[missing] = "created"
    kg_rev = (m.kg_per_rev_upper, m.kg_per_rev_lower)
    rpm = (_col(rows, "meter_rpm_upper"), _col(rows, "meter_rpm_lower"))
    trpm = (_col(rows, "target_rpm_upper"), _col(rows, "target_rpm_lower"))
    cmd = (_col(rows, "rate_kg_ha_upper"), _col(rows, "rate_kg_ha_lower"))
    app = [rate_kg_ha(rpm[i], v, m.width_m, kg_rev[i], speed.min_work_speed_kmh) for i in (0, 1)]
    kg = [rpm[i] / 60.0 * kg_rev[i] * dt for i in (0, 1)]
    tkg = [trpm[i] / 60.0 * kg_rev[i] * dt for i in (0, 1)]
    has = ~np.isnan(lat) & ~np.isnan(lon)
    lost = float(np.sum((kg[0] + kg[1])[~has]))
    if lost > 0:
        out.notes.append(f"{lost:.3f} kg applied in rows without a position are not in the map")
    cols: dict[str, npt.NDArray[np.generic]] = {
        "IsoTime": _iso(utc),
        "Time": np.array([s.replace("T", " ").rstrip("Z") for s in _iso(utc)], dtype=object),
        "UtcSource": src,
        "LogTime": t,
        "Heading": heading,
        "SPEED": v,
        "SpeedSrc": _text(rows, "source"),
        "DISTANCE": v / 3.6 * dt,
        "SWATHWIDTH": np.full_like(t, m.width_m),
        "NDVI": _opt(rows, "ndvi"),
        "TargetRate": cmd[0] + cmd[1],
        "AppliedRate": app[0] + app[1],
        "TgtRateUp": cmd[0],
        "AppRateUp": app[0],
        "TgtRateLo": cmd[1],
        "AppRateLo": app[1],
        "TgtRpmUp": trpm[0],
        "RpmUp": rpm[0],
        "TgtRpmLo": trpm[1],
        "RpmLo": rpm[1],
        "AppliedKg": kg[0] + kg[1],
        "TargetKg": tkg[0] + tkg[1],
        "WorkState": ((rpm[0] > 0) | (rpm[1] > 0)).astype(np.int32),
        "Faults": np.array(rows["faults"], dtype=np.int64),
        "Zone": _text(rows, "zone"),
        "PrescRate": _opt(rows, "prescription_kg_ha"),
    }
    out.points = {k: c[has] for k, c in cols.items()}
    out.point_geom = shapely.points(lon[has], lat[has])
    if has.any():
        out.utm = utm_crs(float(np.nanmean(lat[has])), float(np.nanmean(lon[has])))
        _swaths(out, cols, lat, lon, dt, m.width_m, path_heading)


def _fill(values: FloatArray) -> FloatArray:
    """NaNs take the last value before them; those before the first value, the first."""
    ok = ~np.isnan(values)
    if not ok.any():
        return values.copy()
    idx = np.where(ok, np.arange(values.size), 0)
    np.maximum.accumulate(idx, out=idx)
    out = values[idx]
    out[: int(np.argmax(ok))] = values[int(np.argmax(ok))]
    return np.asarray(out, dtype=float)


def _created(text: str | None) -> float | None:
    if not text:
        return None
    try:
        return datetime.fromisoformat(text).timestamp()
    except ValueError:
        return None


def _track_heading(lat: FloatArray, lon: FloatArray, base_m: float = 2.0) -> FloatArray:
    """Course over the last `base_m` of track at each row (old logs without a heading column;
    over a shorter base the GNSS noise would swing it), held while standing."""
    if np.isnan(lat).all():
        return np.full_like(lat, math.nan)
    n_m = np.nan_to_num(np.radians(lat) * 6_367_000.0)
    e_m = np.nan_to_num(np.radians(lon) * 6_367_000.0 * np.cos(np.radians(np.nanmean(lat))))
    step = np.hypot(np.diff(n_m), np.diff(e_m))
    step[~np.isfinite(step) | np.isnan(np.diff(lat))] = 0.0
    s = np.concatenate([[0.0], np.cumsum(step)])
    j = np.maximum(np.searchsorted(s, s - base_m, side="right") - 1, 0)
    h = np.degrees(np.arctan2(e_m - e_m[j], n_m - n_m[j])) % 360.0
    h[(s - s[j]) < base_m / 2] = np.nan
    # hold the last heading through stops
    idx = np.where(np.isnan(h), 0, np.arange(h.size))
    np.maximum.accumulate(idx, out=idx)
    held = h[idx]
    held[np.isnan(h) & (idx == 0) & np.isnan(h[0])] = np.nan
    return np.asarray(held, dtype=float)


def _swaths(
    out: AsApplied,
    cols: dict[str, npt.NDArray[np.generic]],
    lat: FloatArray,
    lon: FloatArray,
    dt: FloatArray,
    width_m: float,
    heading_deg: FloatArray,
) -> None:
    """Swaths along the machine's smoothed path while product is applied (see the module's
    doc): the attributes are sums over the state rows each swath holds, so the map adds up to
    the summary."""
    assert out.utm is not None
    fwd = Transformer.from_crs(WGS84, out.utm, always_xy=True)
    back = Transformer.from_crs(out.utm, WGS84, always_xy=True)
    x, y = fwd.transform(lon, lat)
    path = _Path(
        x=np.asarray(x, dtype=float),
        y=np.asarray(y, dtype=float),
        step_m=np.asarray(cols["SPEED"], dtype=float) / 3.6 * dt,
        dt=dt,
        heading_deg=heading_deg,
        work=np.asarray(cols["WorkState"]) > 0,
        breaks=_breaks(cols),
    )
    built = _build_swaths(path, width_m)
    if built.notes:
        out.notes.extend(built.notes)
    if built.geoms.size == 0:
        return
    geoms = shapely.transform(
        built.geoms, lambda xy: np.column_stack(back.transform(xy[:, 0], xy[:, 1]))
    )
    # RFC 7946: exterior rings counter-clockwise (GDAL writes Shapefiles clockwise itself)
    out.swath_geom = np.asarray(shapely.orient_polygons(geoms, exterior_cw=False))
    sid, first = built.swath_of_row, built.first_row
    n = built.geoms.size

    def total(values: npt.NDArray[np.generic]) -> FloatArray:
        w = np.nan_to_num(np.asarray(values, dtype=float))
        ok = sid >= 0
        return np.bincount(sid[ok], weights=w[ok], minlength=n).astype(float)

    step = np.asarray(path.step_m, dtype=float)
    dist = total(step * built.moving)
    secs = total(dt * built.moving)
    area_ha = total(step * width_m / 10_000.0)
    kg = total(cols["AppliedKg"])
    tkg = total(cols["TargetKg"])
    out.swaths = {
        "IsoTime": cols["IsoTime"][first],
        "LogTime": cols["LogTime"][first],
        "Heading": built.heading_deg,
        "SPEED": _ratio(dist * 3.6, secs),
        "DISTANCE": dist,
        "DURATION": secs,
        "SWATHWIDTH": np.full(n, width_m),
        "AREA": area_ha,
        # the dose on the swath's ground: what was metered over it per its area
        "AppliedRate": _ratio(kg, area_ha),
        "TargetRate": _ratio(tkg, area_ha),
        "CmdRate": _ratio(total(np.asarray(cols["TargetRate"], float) * step), dist),
        "RpmUp": _ratio(total(np.asarray(cols["RpmUp"], float) * dt), total(dt)),
        "RpmLo": _ratio(total(np.asarray(cols["RpmLo"], float) * dt), total(dt)),
        "AppliedKg": kg,
        "TargetKg": tkg,
        "Overlap": built.overlap_pct,
        "Zone": cols["Zone"][first],
        "PrescRate": cols["PrescRate"][first],
    }


def _breaks(cols: dict[str, npt.NDArray[np.generic]]) -> npt.NDArray[np.bool_]:
    """Rows where the zone or the prescription rate changes: a swath ends there, so that its
    Zone and PrescRate hold over all of it."""
    zone = np.asarray(cols["Zone"], dtype=object)
    presc = np.nan_to_num(np.asarray(cols["PrescRate"], dtype=float), nan=-1.0)
    out = np.zeros(zone.size, dtype=bool)
    out[1:] = (zone[1:] != zone[:-1]) | (presc[1:] != presc[:-1])
    return out


def _ratio(a: FloatArray, b: FloatArray) -> FloatArray:
    return np.divide(a, b, out=np.zeros_like(a), where=b > 0)


def require_points(data: AsApplied) -> None:
    if data.point_geom.size == 0:
        raise MapError(
            f"{data.path}: no state row has a position (no GNSS fix in the session): nothing to map"
        )


# ---- swaths: the machine's path, cut into pieces while product is applied --------------------

SWATH_M: Final = 1.0  # a swath is cut after this much path (and where zone or prescription change)
MIN_RUN_M: Final = 0.25  # a work run shorter than this has no polygon (its kg go to a neighbour)
POS_SD_M: Final = 0.3  # position noise the smoother takes off (a fix's jitter, not its bias)
STEP_SD_M: Final = 0.01  # dead-reckoning error per row: this plus STEP_SD_FRAC of the step
STEP_SD_FRAC: Final = 0.05  # (speed and heading errors of a few percent and degrees)
TANGENT_M: Final = 0.25  # the path's direction is taken over this much path either side
COVER_TILE_M: Final = 20.0  # the ground covered so far is kept in tiles of this side


@dataclass(frozen=True)
class _Path:
    """Per state row: the outlet in metres (UTM; NaN without a position), the step to the next
    row by the selected speed (m), the interval (s), the heading, whether a meter turns, and
    where a swath must end."""

    x: FloatArray
    y: FloatArray
    step_m: FloatArray
    dt: FloatArray
    heading_deg: FloatArray
    work: npt.NDArray[np.bool_]
    breaks: npt.NDArray[np.bool_]


@dataclass
class _Swaths:
    geoms: npt.NDArray[np.object_]  # UTM polygons
    swath_of_row: npt.NDArray[np.intp]  # the swath each row's interval counts in, -1: none
    first_row: npt.NDArray[np.intp]
    moving: npt.NDArray[np.bool_]  # rows whose interval is part of a swath's path
    heading_deg: FloatArray
    overlap_pct: FloatArray
    notes: list[str]


def _build_swaths(p: _Path, width_m: float) -> _Swaths:
    n = p.x.size
    has = np.isfinite(p.x) & np.isfinite(p.y)
    link = np.zeros(n, dtype=bool)  # interval i (row i to i+1) is a usable step
    link[:-1] = has[:-1] & has[1:] & (p.dt[:-1] > 0)
    step = np.where(link, p.step_m, 0.0)
    sx, sy = smooth_path(p.x, p.y, step, p.heading_deg, link)
    moving = link & p.work & (step > 0)
    runs = _runs(moving, p.breaks, step)
    tangent = _tangents(sx, sy, step, link, p.heading_deg)
    geoms: list[Any] = []
    first: list[int] = []
    heading: list[float] = []
    sid = np.full(n, -1, dtype=np.intp)
    repaired = 0
    for rows in runs:
        poly, fixed = _strip(sx, sy, rows, width_m, tangent)
        repaired += fixed
        if poly is None:
            continue
        k = len(geoms)
        sid[rows] = k
        geoms.append(poly)
        first.append(int(rows[0]))
        a, b = rows[0], rows[-1] + 1
        heading.append(math.degrees(math.atan2(sx[b] - sx[a], sy[b] - sy[a])) % 360.0)
    # What was metered off the path (standing, a run too short to draw, a step to a row
    # without a position) belongs to the swath where the machine was: the one before it
    # (or, before the first, the next one).
    metered = has & p.work & (p.dt > 0)
    _attach(sid, metered)
    notes = []
    if repaired:
        notes.append(f"{repaired} swaths in tight turns were repaired (inner edge folded)")
    g = np.array(geoms, dtype=object)
    return _Swaths(
        geoms=g,
        swath_of_row=sid,
        first_row=np.array(first, dtype=np.intp),
        moving=moving & (sid >= 0),
        heading_deg=np.array(heading, dtype=float),
        overlap_pct=_overlap_pct(g),
        notes=notes,
    )


def smooth_path(
    x: FloatArray,
    y: FloatArray,
    step_m: FloatArray,
    heading_deg: FloatArray,
    link: npt.NDArray[np.bool_],
) -> tuple[FloatArray, FloatArray]:
    """The path that best fits both the positions and the machine's own steps (selected
    speed x interval along the heading): least squares of the positions (POS_SD_M) and the
    steps (STEP_SD_M + STEP_SD_FRAC of each), a tridiagonal system solved once. A fix's
    jitter no longer lengthens the path; a heading that is not known links nothing."""
    n = x.size
    h0 = np.radians(heading_deg)
    h1 = np.empty_like(h0)
    h1[:-1], h1[-1:] = h0[1:], h0[-1:]
    # the interval's heading: the mean of its two ends (a turn's step is a chord)
    hx = np.nan_to_num(np.sin(h0)) + np.nan_to_num(np.sin(h1))
    hy = np.nan_to_num(np.cos(h0)) + np.nan_to_num(np.cos(h1))
    norm = np.hypot(hx, hy)
    ok = link & (norm > 1e-9)
    ux = np.divide(hx, norm, out=np.zeros(n), where=ok)
    uy = np.divide(hy, norm, out=np.zeros(n), where=ok)
    lam = np.where(ok, (POS_SD_M / (STEP_SD_M + STEP_SD_FRAC * step_m)) ** 2, 0.0)
    dx, dy = (ux * step_m).tolist(), (uy * step_m).tolist()
    px, py = np.nan_to_num(x).tolist(), np.nan_to_num(y).tolist()
    lm = lam.tolist()
    # Thomas algorithm; row i: (1 + l[i-1] + l[i]) s[i] - l[i-1] s[i-1] - l[i] s[i+1]
    #                          = p[i] + l[i-1] d[i-1] - l[i] d[i]
    cp = [0.0] * n
    qx, qy = [0.0] * n, [0.0] * n
    lo = c_prev = qx_prev = qy_prev = 0.0
    dx_prev = dy_prev = 0.0
    for i in range(n):
        hi = lm[i] if i < n - 1 else 0.0
        denom = 1.0 + lo + hi - lo * c_prev
        c_prev = hi / denom
        qx_prev = (px[i] + lo * dx_prev - hi * dx[i] + lo * qx_prev) / denom
        qy_prev = (py[i] + lo * dy_prev - hi * dy[i] + lo * qy_prev) / denom
        cp[i], qx[i], qy[i] = c_prev, qx_prev, qy_prev
        lo, dx_prev, dy_prev = hi, dx[i], dy[i]
    sx, sy = [0.0] * n, [0.0] * n
    nx = ny = 0.0
    for i in range(n - 1, -1, -1):
        nx = qx[i] + cp[i] * nx
        ny = qy[i] + cp[i] * ny
        sx[i], sy[i] = nx, ny
    out_x, out_y = np.array(sx), np.array(sy)
    missing = ~(np.isfinite(x) & np.isfinite(y))
    out_x[missing] = out_y[missing] = math.nan
    return out_x, out_y


def _runs(
    moving: npt.NDArray[np.bool_], breaks: npt.NDArray[np.bool_], step: FloatArray
) -> list[npt.NDArray[np.intp]]:
    """The rows (intervals) of each swath: consecutive moving intervals, cut after SWATH_M of
    path and where a break row starts; a last piece shorter than half of SWATH_M joins the
    one before it in its run."""
    idx = np.nonzero(moving)[0]
    if idx.size == 0:
        return []
    cut_run = np.concatenate([[True], np.diff(idx) != 1])
    out: list[list[int]] = []
    acc = 0.0
    run_start = 0  # index in `out` of the first swath of the current run
    for i, new_run, brk in zip(idx.tolist(), cut_run.tolist(), breaks[idx].tolist(), strict=True):
        if new_run:
            if out and len(out) - run_start > 1 and _length(out[-1], step) < SWATH_M / 2:
                out[-2].extend(out.pop())
            run_start = len(out)
            out.append([i])
            acc = float(step[i])
            continue
        if acc >= SWATH_M or brk:
            out.append([i])
            acc = float(step[i])
        else:
            out[-1].append(i)
            acc += float(step[i])
    if len(out) - run_start > 1 and _length(out[-1], step) < SWATH_M / 2:
        out[-2].extend(out.pop())
    return [np.array(r, dtype=np.intp) for r in out if _length(r, step) >= MIN_RUN_M]


def _length(rows: list[int], step: FloatArray) -> float:
    return float(np.sum(step[rows]))


def _strip(
    sx: FloatArray,
    sy: FloatArray,
    rows: npt.NDArray[np.intp],
    width_m: float,
    tangent: tuple[FloatArray, FloatArray],
) -> tuple[Any, int]:
    """The swath over intervals `rows` (consecutive): the working width across the path's
    direction at each of its rows and at the row after the last (so that swaths along a pass
    share their ends). Returns (polygon or None when degenerate, 1 if it was repaired)."""
    v = np.append(rows, rows[-1] + 1)
    x, y = sx[v], sy[v]
    tx, ty = tangent[0][v], tangent[1][v]
    half = width_m / 2.0
    rx, ry = ty * half, -tx * half  # to the right of the direction of travel
    right = _no_backstep(np.column_stack([x + rx, y + ry]), tx, ty)
    left = _no_backstep(np.column_stack([x - rx, y - ry]), tx, ty)
    ring = np.concatenate([left, right[::-1], left[:1]])
    poly = shapely.Polygon(ring)
    fixed = 0
    if not poly.is_valid:
        poly, fixed = _repair(poly), 1
    if poly is None or poly.is_empty or poly.area < 1e-4:
        return None, fixed
    return poly, fixed


def _tangents(
    sx: FloatArray,
    sy: FloatArray,
    step: FloatArray,
    link: npt.NDArray[np.bool_],
    heading_deg: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """The path's direction at each row: the chord from TANGENT_M of path behind to as far
    ahead (rows a few centimetres apart would turn a centimetre of jitter into degrees),
    within the stretch of linked rows; the heading where the path has not moved."""
    n = sx.size
    s = np.concatenate([[0.0], np.cumsum(step[:-1])])
    comp = np.concatenate([[0], np.cumsum(~link[:-1])])
    starts = np.searchsorted(comp, comp, side="left")
    ends = np.searchsorted(comp, comp, side="right") - 1
    ahead = np.clip(np.searchsorted(s, s + TANGENT_M, side="left"), starts, ends)
    behind = np.clip(np.searchsorted(s, s - TANGENT_M, side="right") - 1, starts, ends)
    ahead = np.minimum(ahead, n - 1)
    tx, ty = sx[ahead] - sx[behind], sy[ahead] - sy[behind]
    norm = np.hypot(tx, ty)
    h = np.radians(heading_deg)
    flat = ~(norm > 1e-3)
    tx = np.where(flat, np.nan_to_num(np.sin(h)), tx / np.where(flat, 1.0, norm))
    ty = np.where(flat, np.nan_to_num(np.cos(h)), ty / np.where(flat, 1.0, norm))
    return tx, ty


def _no_backstep(side: FloatArray, tx: FloatArray, ty: FloatArray) -> FloatArray:
    """An edge of the swath never runs backwards: in a turn tighter than half the width the
    inner edge pivots (stands) instead of sweeping back over ground already passed."""
    out = side.copy()
    for k in range(1, len(out)):
        if (out[k, 0] - out[k - 1, 0]) * tx[k] + (out[k, 1] - out[k - 1, 1]) * ty[k] < 0.0:
            out[k] = out[k - 1]
    return out


def _repair(poly: Any) -> Any:
    """A folded swath made valid; parts that only touch are joined, else the largest part."""
    g = shapely.make_valid(poly)
    parts = [q for q in shapely.get_parts(g) if q.geom_type == "Polygon" and q.area > 0]
    if not parts:
        return None
    if len(parts) > 1:
        joined = (
            shapely.union_all(parts)
            .buffer(0.001, join_style="mitre")
            .buffer(-0.001, join_style="mitre")
        )
        parts = [q for q in shapely.get_parts(joined) if q.geom_type == "Polygon"]
    best = max(parts, key=lambda q: q.area) if parts else None
    return best if best is not None and best.is_valid else None


def _attach(sid: npt.NDArray[np.intp], metered: npt.NDArray[np.bool_]) -> None:
    """Rows metered but in no swath take the swath of the nearest row before them that has
    one (the first swath for those before it)."""
    have = sid >= 0
    if not have.any():
        return
    idx = np.where(have, np.arange(sid.size), 0)
    np.maximum.accumulate(idx, out=idx)
    before = sid[idx]
    first = int(np.argmax(have))
    before[:first] = sid[first]
    todo = metered & ~have
    sid[todo] = before[todo]


def _overlap_pct(geoms: npt.NDArray[np.object_]) -> FloatArray:
    """Per swath, the % of its area that earlier swaths had covered already.

    The ground covered so far is kept as one union per COVER_TILE_M square tile: a swath's
    overlap is its intersection with the tiles it touches, then it is added to them. The cost
    and memory grow with the ground covered, not with the time spent on it (comparing each
    swath with every earlier one it touches made a day driven over the same passes quadratic:
    1,000 earlier swaths each by the evening)."""
    out = np.zeros(geoms.size)
    if geoms.size < 2:
        return out
    cover: dict[tuple[int, int], Any] = {}
    tile = COVER_TILE_M
    bounds = np.floor(shapely.bounds(geoms) / tile).astype(np.int64).tolist()
    for k, (g, (i0, j0, i1, j1)) in enumerate(zip(geoms, bounds, strict=True)):
        keys = [(i, j) for i in range(i0, i1 + 1) for j in range(j0, j1 + 1)]
        earlier = [cover[key] for key in keys if key in cover]
        if earlier:
            covered = float(np.sum(shapely.area(shapely.intersection(g, earlier))))
            out[k] = covered if covered > 1e-4 else 0.0  # neighbours share an edge, not area
        for i, j in keys:
            piece = shapely.intersection(
                g, shapely.box(i * tile, j * tile, (i + 1) * tile, (j + 1) * tile)
            )
            if shapely.is_empty(piece):
                continue
            old = cover.get((i, j))
            cover[(i, j)] = piece if old is None else shapely.union(old, piece)
    return np.asarray(100.0 * out / shapely.area(geoms), dtype=float)
