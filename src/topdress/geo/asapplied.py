"""As-applied records of a session: one point per state row with a position, one swath
polygon per interval the machine moved, with the target and the actual rate per layer.

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
from topdress.log.model import STATE_COLUMNS
from topdress.log.session import SessionReader, session_config

_log = logging.getLogger(__name__)

MAX_GAP_S: Final = 1.0  # as the summary: a longer interval is a gap in the log, not integrated
MIN_SWATH_M: Final = 0.05  # an interval shorter than this gives no swath polygon
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
    _points(out, rows, cfg.machine, cfg.speed, reader.meta.get("created_utc"))
    return out


def _points(
    out: AsApplied,
    rows: Columns,
    m: MachineConfig,
    speed: SpeedConfig,
    created_utc: str | None,
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
        _swaths(out, cols, lat, lon, dt, m.width_m)


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
) -> None:
    """A rectangle of the working width over each interval between two positioned rows."""
    assert out.utm is not None
    fwd = Transformer.from_crs(WGS84, out.utm, always_xy=True)
    back = Transformer.from_crs(out.utm, WGS84, always_xy=True)
    x, y = fwd.transform(lon, lat)
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    dx, dy = np.diff(x), np.diff(y)
    length = np.hypot(dx, dy)
    ok = (dt[:-1] > 0) & np.isfinite(length) & (length >= MIN_SWATH_M)
    i = np.nonzero(ok)[0]
    if i.size == 0:
        return
    # Across the heading where it is known (consecutive positions a few decimetres apart
    # carry the receiver's noise in their direction), else across the segment.
    h = np.radians(np.asarray(cols["Heading"], dtype=float)[i])
    ux = np.where(np.isnan(h), dx[i] / length[i], np.sin(h))
    uy = np.where(np.isnan(h), dy[i] / length[i], np.cos(h))
    nx, ny = -uy * width_m / 2, ux * width_m / 2
    xs = np.stack([x[i] + nx, x[i + 1] + nx, x[i + 1] - nx, x[i] - nx, x[i] + nx], axis=1)
    ys = np.stack([y[i] + ny, y[i + 1] + ny, y[i + 1] - ny, y[i] - ny, y[i] + ny], axis=1)
    lo, la = back.transform(xs.ravel(), ys.ravel())
    ring = np.stack([np.asarray(lo), np.asarray(la)], axis=1).reshape(i.size, 5, 2)
    out.swath_geom = shapely.polygons(ring)
    area_ha = length[i] * width_m / 10_000.0
    kg = np.asarray(cols["AppliedKg"], dtype=float)[i]
    tkg = np.asarray(cols["TargetKg"], dtype=float)[i]
    out.swaths = {
        "IsoTime": cols["IsoTime"][i],
        "LogTime": cols["LogTime"][i],
        "Heading": cols["Heading"][i],
        "SPEED": cols["SPEED"][i],
        "DISTANCE": length[i],
        "SWATHWIDTH": cols["SWATHWIDTH"][i],
        "AREA": area_ha,
        # the swath's mean rates: of the rows at its two ends
        "AppliedRate": _mean_ends(cols["AppliedRate"], i),
        "TargetRate": _mean_ends(cols["TargetRate"], i),
        "CmdRate": cols["TargetRate"][i],
        "RpmUp": cols["RpmUp"][i],
        "RpmLo": cols["RpmLo"][i],
        "AppliedKg": kg,
        "TargetKg": tkg,
        "Zone": cols["Zone"][i],
        "PrescRate": cols["PrescRate"][i],
    }


def _mean_ends(col: npt.NDArray[np.generic], i: npt.NDArray[np.intp]) -> FloatArray:
    c = np.asarray(col, dtype=float)
    return np.asarray((c[i] + c[i + 1]) / 2.0, dtype=float)


def require_points(data: AsApplied) -> None:
    if data.point_geom.size == 0:
        raise MapError(
            f"{data.path}: no state row has a position (no GNSS fix in the session): nothing to map"
        )
