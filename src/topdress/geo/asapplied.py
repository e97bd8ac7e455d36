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
from collections.abc import Iterator
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
#: The speed source as ISO 11783-11 DDI 400 codes it (4: blended), one table for every export.
SPEED_SOURCE_CODES: Final = {"wheel": 1, "gnss": 3, "fused": 4, "none": 0}

FloatArray = npt.NDArray[np.float64]
ObjArray = npt.NDArray[np.object_]
#: a batch of features: attribute columns and geometries
Batch = tuple[dict[str, npt.NDArray[np.generic]], npt.NDArray[np.object_]]


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

    def point_batches(self) -> Iterator[Batch]:
        if self.point_geom.size:
            yield self.points, self.point_geom

    def swath_batches(self) -> Iterator[Batch]:
        if self.swath_geom.size:
            yield self.swaths, self.swath_geom


Columns = dict[str, list[Any]]

CHUNK_ROWS: Final = 10_000  # state rows read, and points made and written, at a time
SWATH_BATCH: Final = 5_000  # runs made into swath polygons at a time


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


@dataclass
class _Day:
    """What the swaths need of every state row, as numbers (about 170 bytes a row: a 12 h day
    is 75 MB); the text, the point columns and the geometries are made a chunk at a time."""

    t: FloatArray
    dt: FloatArray  # to the next row; 0 over a gap
    v: FloatArray
    lat: FloatArray  # the outlet (the antenna's offset to it where not logged); NaN: none
    lon: FloatArray
    heading: FloatArray  # as logged (or from the track in older files)
    path_heading: FloatArray  # known everywhere the machine's direction is
    utc: FloatArray
    created: npt.NDArray[np.bool_]  # utc from the session's creation time
    rpm: tuple[FloatArray, FloatArray]
    kg: FloatArray  # applied until the next row, both layers
    tkg: FloatArray
    cmd: FloatArray  # commanded rate, both layers
    presc: FloatArray
    zone: npt.NDArray[np.int32]  # index into zones
    zones: list[str]
    has: npt.NDArray[np.bool_]  # a position


class AsAppliedStream:
    """A session's as-applied points and swaths in batches, so that a long day exports in
    bounded memory: the state rows are read CHUNK_ROWS at a time (twice: once for the numbers
    the path needs, once for the points), the swaths are made SWATH_BATCH runs at a time. The
    batches join into what one pass over the whole session gives (`build`).

    `notes`, `points`, `swaths` and `applied_kg` are complete once both layers were read."""

    def __init__(
        self, reader: SessionReader, chunk_rows: int | None = None, swath_batch: int | None = None
    ) -> None:
        chunk_rows = CHUNK_ROWS if chunk_rows is None else chunk_rows
        swath_batch = SWATH_BATCH if swath_batch is None else swath_batch
        if chunk_rows < 1 or swath_batch < 1:
            raise ValueError("chunk sizes must be at least 1")
        cfg = session_config(reader.config_toml)
        self.path = str(reader.path)
        self.machine = cfg.machine
        self._min_kmh = cfg.speed.min_work_speed_kmh
        self.notes: list[str] = []
        self.utm: CRS | None = None
        self.points = self.swaths = 0  # written so far
        self.applied_kg = 0.0
        self._reader = reader
        self._chunk = chunk_rows
        self._batch = swath_batch
        present = reader.state_columns()
        self._cols = tuple(c for c in STATE_COLUMNS if c in present)
        for col, what in (
            ("outlet_lat", "the outlet position (the antenna's is used)"),
            ("heading_deg", "the heading (taken from successive positions)"),
            ("utc", "UTC (the session's creation time plus the monotonic time is used)"),
        ):
            if col not in present:
                self.notes.append(f"this session log has no {col} column: {what}")
        self._day = _read_day(
            self._chunks(),
            reader.count("state"),
            cfg.machine,
            cfg.speed,
            reader.meta.get("created_utc"),
            "outlet_lat" in present,
            self.notes,
        )
        self.rows = self._day.t.size
        if self._day.has.any():
            d = self._day
            self.utm = utm_crs(float(np.nanmean(d.lat[d.has])), float(np.nanmean(d.lon[d.has])))

    def _chunks(self) -> Iterator[Columns]:
        return self._reader.state_chunks(STATE_COLUMNS, self._chunk)

    def point_batches(self) -> Iterator[Batch]:
        """The points, CHUNK_ROWS state rows at a time (fewer: rows without a position)."""
        d, m = self._day, self.machine
        start = 0
        for rows in self._chunks():
            sl = slice(start, start + len(rows["t"]))
            cols = _point_columns(d, rows, sl.start, sl.stop, m, self._min_kmh)
            start = sl.stop
            has = d.has[sl]
            if not has.any():
                continue
            self.points += int(np.count_nonzero(has))
            self.applied_kg += float(np.sum(cols["AppliedKg"][has]))
            yield (
                {k: c[has] for k, c in cols.items()},
                shapely.points(d.lon[sl][has], d.lat[sl][has]),
            )

    def positions(self) -> FloatArray:
        """The points' coordinates (lon, lat), as `point_batches` gives them, without reading
        the rows again."""
        d = self._day
        return np.column_stack([d.lon[d.has], d.lat[d.has]])

    def swath_batches(self) -> Iterator[Batch]:
        """The swaths, up to SWATH_BATCH runs at a time."""
        if self.utm is None:
            return
        maker = _SwathMaker(self._day, self.utm, self.machine.width_m)
        back = Transformer.from_crs(self.utm, WGS84, always_xy=True)
        for built in maker.batches(self._batch):
            geoms = shapely.transform(
                built.geoms, lambda xy: np.column_stack(back.transform(xy[:, 0], xy[:, 1]))
            )
            # RFC 7946: exterior rings counter-clockwise (GDAL writes Shapefiles clockwise)
            self.swaths += built.geoms.size
            yield built.columns, np.asarray(shapely.orient_polygons(geoms, exterior_cw=False))
        if maker.repaired:
            self.notes.append(
                f"{maker.repaired} swaths in tight turns were repaired (inner edge folded)"
            )


def build(
    reader: SessionReader, chunk_rows: int | None = None, swath_batch: int | None = None
) -> AsApplied:
    """The whole session's as-applied points and swaths at once (for the map and ISOXML)."""
    stream = AsAppliedStream(reader, chunk_rows, swath_batch)
    out = AsApplied(stream.path, stream.machine, rows=stream.rows, utm=stream.utm)
    out.points, out.point_geom = _join(stream.point_batches())
    out.swaths, out.swath_geom = _join(stream.swath_batches())
    out.notes = stream.notes
    return out


def _join(batches: Iterator[Batch]) -> Batch:
    got = list(batches)
    if not got:
        return {}, np.empty(0, object)
    cols = {k: np.concatenate([c[k] for c, _ in got]) for k in got[0][0]}
    return cols, np.concatenate([g for _, g in got])


def _read_day(
    chunks: Iterator[Columns],
    size: int,
    m: MachineConfig,
    speed: SpeedConfig,
    created_utc: str | None,
    has_outlet: bool,
    notes: list[str],
) -> _Day:
    """The numbers of every state row (read a chunk at a time), positions and times filled in."""
    names = (
        "t", "v_kmh", "outlet_lat", "outlet_lon", "lat", "lon", "heading_deg", "utc",
        "meter_rpm_upper", "meter_rpm_lower", "target_rpm_upper", "target_rpm_lower",
        "rate_kg_ha_upper", "rate_kg_ha_lower", "prescription_kg_ha",
    )  # fmt: skip
    # filled in place (joining chunks would hold the day twice); `size`: the rows the file
    # holds, damaged ones included, so a few may be left over
    col = {n: np.empty(size) for n in names}
    zone = np.empty(size, np.int32)
    zones: dict[str, int] = {}
    n_rows = 0
    for rows in chunks:
        end = n_rows + len(rows["t"])
        for n in names:
            col[n][n_rows:end] = rows[n]  # None -> nan
        zone[n_rows:end] = [zones.setdefault(z or "", len(zones)) for z in rows["zone"]]
        n_rows = end
    col = {n: c[:n_rows] for n, c in col.items()}
    t = col["t"]
    if not t.size:
        notes.append("no state rows")
    dt = np.zeros_like(t)
    dt[:-1] = np.diff(t)
    dt[(dt > MAX_GAP_S) | (dt < 0)] = 0.0
    lat, lon = col["outlet_lat"], col["outlet_lon"]
    antenna = np.isnan(lat)
    lat[antenna], lon[antenna] = col["lat"][antenna], col["lon"][antenna]
    heading = col["heading_deg"]
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
    utc = col["utc"]
    missing = np.isnan(utc)
    created = np.zeros(t.size, dtype=bool)
    if missing.any():
        base = _created(created_utc)
        if base is None:
            notes.append("no UTC for some rows and no creation time: those rows have none")
        else:
            utc[missing] = base + (t[missing] - t[0])
            created = missing
    kg_rev = (m.kg_per_rev_upper, m.kg_per_rev_lower)
    rpm = (col["meter_rpm_upper"], col["meter_rpm_lower"])
    kg = [rpm[i] / 60.0 * kg_rev[i] * dt for i in (0, 1)]
    tkg = [col[f"target_rpm_{k}"] / 60.0 * kg_rev[i] * dt for i, k in enumerate(("upper", "lower"))]
    has = ~np.isnan(lat) & ~np.isnan(lon)
    lost = float(np.sum((kg[0] + kg[1])[~has]))
    if lost > 0:
        notes.append(f"{lost:.3f} kg applied in rows without a position are not in the map")
    return _Day(
        t=t,
        dt=dt,
        v=col["v_kmh"],
        lat=lat,
        lon=lon,
        heading=heading,
        path_heading=path_heading,
        utc=utc,
        created=created,
        rpm=rpm,
        kg=kg[0] + kg[1],
        tkg=tkg[0] + tkg[1],
        cmd=col["rate_kg_ha_upper"] + col["rate_kg_ha_lower"],
        presc=col["prescription_kg_ha"],
        zone=zone[:n_rows],
        zones=list(zones),
        has=has,
    )


def _point_columns(
    d: _Day, rows: Columns, start: int, end: int, m: MachineConfig, min_kmh: float
) -> dict[str, npt.NDArray[np.generic]]:
    """The points' columns of state rows start..end (`rows`: their values as read)."""
    sl = slice(start, end)
    t, dt, v = d.t[sl], d.dt[sl], d.v[sl]
    src = _text(rows, "utc_source")
    src[d.created[sl]] = "created"
    kg_rev = (m.kg_per_rev_upper, m.kg_per_rev_lower)
    rpm = (d.rpm[0][sl], d.rpm[1][sl])
    trpm = (_col(rows, "target_rpm_upper"), _col(rows, "target_rpm_lower"))
    cmd = (_col(rows, "rate_kg_ha_upper"), _col(rows, "rate_kg_ha_lower"))
    app = [rate_kg_ha(rpm[i], v, m.width_m, kg_rev[i], min_kmh) for i in (0, 1)]
    iso = _iso(d.utc[sl])
    return {
        "IsoTime": iso,
        "Time": np.array([s.replace("T", " ").rstrip("Z") for s in iso], dtype=object),
        "UtcSource": src,
        "LogTime": t,
        "Heading": d.heading[sl],
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
        "AppliedKg": d.kg[sl],
        "TargetKg": d.tkg[sl],
        "WorkState": ((rpm[0] > 0) | (rpm[1] > 0)).astype(np.int32),
        "Faults": np.array(rows["faults"], dtype=np.int64),
        "Zone": _text(rows, "zone"),
        "PrescRate": _opt(rows, "prescription_kg_ha"),
    }


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


def _ratio(a: FloatArray, b: FloatArray) -> FloatArray:
    return np.divide(a, b, out=np.zeros_like(a), where=b > 0)


def require_points(data: AsApplied) -> None:
    if data.point_geom.size == 0:
        _no_points(data.path)


def require_any_point(stream: AsAppliedStream) -> None:
    """As `require_points`, before the stream is read."""
    if stream.utm is None:
        _no_points(stream.path)


def _no_points(path: str) -> None:
    raise MapError(
        f"{path}: no state row has a position (no GNSS fix in the session): nothing to map"
    )


# ---- swaths: the machine's path, cut into pieces while product is applied --------------------

SWATH_M: Final = 1.0  # a swath is cut after this much path (and where zone or prescription change)
MIN_RUN_M: Final = 0.25  # a work run shorter than this has no polygon (its kg go to a neighbour)
POS_SD_M: Final = 0.3  # position noise the smoother takes off (a fix's jitter, not its bias)
STEP_SD_M: Final = 0.01  # dead-reckoning error per row: this plus STEP_SD_FRAC of the step
STEP_SD_FRAC: Final = 0.05  # (speed and heading errors of a few percent and degrees)
TANGENT_M: Final = 0.25  # the path's direction is taken over this much path either side
COVER_TILE_M: Final = 20.0  # the ground covered so far is kept in tiles of this side


class _SwathMaker:
    """The swaths of a day (see the module's doc) made a batch of runs at a time. The path is
    smoothed and cut into runs over the whole day's numbers (a few arrays of floats); the
    polygons, their overlap and their sums are made per batch. A swath's sums take the rows
    metered off the path after it until the next swath (`_attach`): the last swath of a
    batch waits for the next batch's first."""

    def __init__(self, d: _Day, utm: CRS, width_m: float) -> None:
        self.d = d
        self.width_m = width_m
        x, y = Transformer.from_crs(WGS84, utm, always_xy=True).transform(d.lon, d.lat)
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        n = x.size
        has = np.isfinite(x) & np.isfinite(y)
        link = np.zeros(n, dtype=bool)  # interval i (row i to i+1) is a usable step
        link[:-1] = has[:-1] & has[1:] & (d.dt[:-1] > 0)
        self.step_m = d.v / 3.6 * d.dt  # the machine's own step
        step = np.where(link, self.step_m, 0.0)
        self.sx, self.sy = smooth_path(x, y, step, d.path_heading, link)
        del x, y
        self.work = (d.rpm[0] > 0) | (d.rpm[1] > 0)
        self.moving = link & self.work & (step > 0)
        presc = np.nan_to_num(d.presc, nan=-1.0)
        breaks = np.zeros(n, dtype=bool)  # a swath ends where the zone or prescription changes
        breaks[1:] = (d.zone[1:] != d.zone[:-1]) | (presc[1:] != presc[:-1])
        self.starts, self.ends = _runs(self.moving, breaks, step)
        # for the path's direction, made a batch at a time (`_tangents`)
        self.s = np.concatenate([[0.0], np.cumsum(step[:-1])])
        self.comp = np.concatenate([[0], np.cumsum(~link[:-1])])
        self.metered = has & self.work & (d.dt > 0)
        self.cover = Cover()
        self.repaired = 0
        self.made = 0  # swaths made so far

    def batches(self, size: int) -> Iterator[_Swaths]:
        pending: list[tuple[int, int, Any]] = []  # (first row, last row, polygon)
        for i0 in range(0, self.starts.size, size):
            starts = self.starts[i0 : i0 + size].tolist()
            ends = self.ends[i0 : i0 + size].tolist()
            lo, hi = starts[0], ends[-1] + 2  # a swath's edge runs to the row after its last
            tangent = _tangents(self.sx, self.sy, self.s, self.comp, self.d.path_heading, lo, hi)
            for a, b in zip(starts, ends, strict=True):
                rows = np.arange(a, b + 1)
                poly, fixed = _strip(self.sx, self.sy, rows, self.width_m, tangent, lo)
                self.repaired += fixed
                if poly is not None:
                    pending.append((a, b, poly))
            if len(pending) > 1:
                yield self._finish(pending[:-1], pending[-1][0])
                del pending[:-1]
        if pending:
            yield self._finish(pending, self.d.t.size)

    def _finish(self, group: list[tuple[int, int, Any]], next_first: int) -> _Swaths:
        """The swaths of `group` with their sums over their rows and the rows attached to
        them (up to `next_first`, the next swath's first row)."""
        d = self.d
        lo = 0 if self.made == 0 else group[0][0]
        hi = next_first
        sid = np.full(hi - lo, -1, dtype=np.intp)
        for k, (a, b, _) in enumerate(group):
            sid[a - lo : b + 1 - lo] = k
        _attach(sid, self.metered[lo:hi])
        self.made += len(group)
        n = len(group)
        first = np.array([a for a, _, _ in group], dtype=np.intp)
        sx, sy = self.sx, self.sy
        heading = np.array(
            [
                math.degrees(math.atan2(sx[b + 1] - sx[a], sy[b + 1] - sy[a])) % 360.0
                for a, b, _ in group
            ]
        )
        geoms = np.array([g for _, _, g in group], dtype=object)
        ok = sid >= 0
        sid_ok = sid[ok]

        def total(values: FloatArray) -> FloatArray:
            w = np.nan_to_num(values)
            return np.bincount(sid_ok, weights=w[ok], minlength=n).astype(float)

        dt = d.dt[lo:hi]
        step = self.step_m[lo:hi]
        moving = self.moving[lo:hi] & ok
        width = self.width_m
        dist = total(step * moving)
        secs = total(dt * moving)
        area_ha = total(step * width / 10_000.0)
        kg = total(d.kg[lo:hi])
        tkg = total(d.tkg[lo:hi])
        columns: dict[str, npt.NDArray[np.generic]] = {
            "IsoTime": _iso(d.utc[first]),
            "LogTime": d.t[first],
            "Heading": heading,
            "SPEED": _ratio(dist * 3.6, secs),
            "DISTANCE": dist,
            "DURATION": secs,
            "SWATHWIDTH": np.full(n, width),
            "AREA": area_ha,
            # the dose on the swath's ground: what was metered over it per its area
            "AppliedRate": _ratio(kg, area_ha),
            "TargetRate": _ratio(tkg, area_ha),
            "CmdRate": _ratio(total(d.cmd[lo:hi] * step), dist),
            "RpmUp": _ratio(total(d.rpm[0][lo:hi] * dt), total(dt)),
            "RpmLo": _ratio(total(d.rpm[1][lo:hi] * dt), total(dt)),
            "AppliedKg": kg,
            "TargetKg": tkg,
            "Overlap": self.cover.add(geoms),
            "Zone": np.array([d.zones[z] for z in d.zone[first].tolist()], dtype=object),
            "PrescRate": d.presc[first],
        }
        return _Swaths(geoms=geoms, columns=columns)


@dataclass
class _Swaths:
    geoms: npt.NDArray[np.object_]  # UTM polygons
    columns: dict[str, npt.NDArray[np.generic]]


_BLOCK: Final = 1 << 13  # rows the smoother holds as Python floats at a time


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
    jitter no longer lengthens the path; a heading that is not known links nothing.
    Solved _BLOCK rows at a time as Python floats (faster than numpy element by element),
    the coefficients kept in arrays."""
    n = x.size
    # Thomas algorithm; row i: (1 + l[i-1] + l[i]) s[i] - l[i-1] s[i-1] - l[i] s[i+1]
    #                          = p[i] + l[i-1] d[i-1] - l[i] d[i]
    cp_all, qx_all, qy_all = np.empty(n), np.empty(n), np.empty(n)
    lo = c_prev = qx_prev = qy_prev = 0.0
    dx_prev = dy_prev = 0.0
    for b0 in range(0, n, _BLOCK):
        b1 = min(b0 + _BLOCK, n)
        lm, dx, dy = _smoothing_terms(heading_deg, step_m, link, b0, b1)
        px, py = np.nan_to_num(x[b0:b1]).tolist(), np.nan_to_num(y[b0:b1]).tolist()
        cp, qx, qy = [0.0] * (b1 - b0), [0.0] * (b1 - b0), [0.0] * (b1 - b0)
        for i in range(b1 - b0):
            hi = lm[i]
            denom = 1.0 + lo + hi - lo * c_prev
            c_prev = hi / denom
            qx_prev = (px[i] + lo * dx_prev - hi * dx[i] + lo * qx_prev) / denom
            qy_prev = (py[i] + lo * dy_prev - hi * dy[i] + lo * qy_prev) / denom
            cp[i], qx[i], qy[i] = c_prev, qx_prev, qy_prev
            lo, dx_prev, dy_prev = hi, dx[i], dy[i]
        cp_all[b0:b1], qx_all[b0:b1], qy_all[b0:b1] = cp, qx, qy
    out_x, out_y = np.empty(n), np.empty(n)
    nx = ny = 0.0
    for b1 in range(n, 0, -_BLOCK):
        b0 = max(b1 - _BLOCK, 0)
        cp, qx, qy = cp_all[b0:b1].tolist(), qx_all[b0:b1].tolist(), qy_all[b0:b1].tolist()
        sx, sy = [0.0] * (b1 - b0), [0.0] * (b1 - b0)
        for i in range(b1 - b0 - 1, -1, -1):
            nx = qx[i] + cp[i] * nx
            ny = qy[i] + cp[i] * ny
            sx[i], sy[i] = nx, ny
        out_x[b0:b1], out_y[b0:b1] = sx, sy
    missing = ~(np.isfinite(x) & np.isfinite(y))
    out_x[missing] = out_y[missing] = math.nan
    return out_x, out_y


def _smoothing_terms(
    heading_deg: FloatArray, step_m: FloatArray, link: npt.NDArray[np.bool_], b0: int, b1: int
) -> tuple[list[float], list[float], list[float]]:
    """Rows b0..b1 of the smoother's weights and of the machine's steps (east, north)."""
    n = heading_deg.size
    h0 = np.radians(heading_deg[b0:b1])
    h1 = np.radians(heading_deg[b0 + 1 : b1 + 1]) if b1 < n else np.radians(heading_deg[b0 + 1 :])
    if b1 == n:  # the last row's interval takes its own heading
        h1 = np.append(h1, h0[-1:])
    # the interval's heading: the mean of its two ends (a turn's step is a chord)
    hx = np.nan_to_num(np.sin(h0)) + np.nan_to_num(np.sin(h1))
    hy = np.nan_to_num(np.cos(h0)) + np.nan_to_num(np.cos(h1))
    norm = np.hypot(hx, hy)
    ok = link[b0:b1] & (norm > 1e-9)
    ux = np.divide(hx, norm, out=np.zeros(b1 - b0), where=ok)
    uy = np.divide(hy, norm, out=np.zeros(b1 - b0), where=ok)
    step = step_m[b0:b1]
    lam = np.where(ok, (POS_SD_M / (STEP_SD_M + STEP_SD_FRAC * step)) ** 2, 0.0)
    if b1 == n:
        lam[-1] = 0.0  # the last row links to nothing
    return lam.tolist(), (ux * step).tolist(), (uy * step).tolist()


def _runs(
    moving: npt.NDArray[np.bool_], breaks: npt.NDArray[np.bool_], step: FloatArray
) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """The first and last row (interval) of each swath: consecutive moving intervals, cut
    after SWATH_M of path and where a break row starts; a last piece shorter than half of
    SWATH_M joins the one before it in its run."""
    idx = np.nonzero(moving)[0]
    if idx.size == 0:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    cut_run = np.concatenate([[True], np.diff(idx) != 1])
    starts: list[int] = []
    ends: list[int] = []
    acc = 0.0
    run_start = 0  # index of the first swath of the current run
    steps = step[idx].tolist()
    for i, new_run, brk, si in zip(
        idx.tolist(), cut_run.tolist(), breaks[idx].tolist(), steps, strict=True
    ):
        if new_run:
            if len(starts) - run_start > 1 and _length(starts[-1], ends[-1], step) < SWATH_M / 2:
                starts.pop()
                ends[-2:] = ends[-1:]  # the piece joins the one before it
            run_start = len(starts)
            starts.append(i)
            ends.append(i)
            acc = si
        elif acc >= SWATH_M or brk:
            starts.append(i)
            ends.append(i)
            acc = si
        else:
            ends[-1] = i
            acc += si
    if len(starts) - run_start > 1 and _length(starts[-1], ends[-1], step) < SWATH_M / 2:
        starts.pop()
        ends[-2:] = ends[-1:]  # the piece joins the one before it
    a, b = np.array(starts, dtype=np.intp), np.array(ends, dtype=np.intp)
    keep = np.array(
        [_length(i, j, step) >= MIN_RUN_M for i, j in zip(starts, ends, strict=True)], dtype=bool
    )
    return a[keep], b[keep]


def _length(first: int, last: int, step: FloatArray) -> float:
    return float(np.sum(step[first : last + 1]))


def _strip(
    sx: FloatArray,
    sy: FloatArray,
    rows: npt.NDArray[np.intp],
    width_m: float,
    tangent: tuple[FloatArray, FloatArray],
    first: int = 0,
) -> tuple[Any, int]:
    """The swath over intervals `rows` (consecutive): the working width across the path's
    direction at each of its rows and at the row after the last (so that swaths along a pass
    share their ends). Returns (polygon or None when degenerate, 1 if it was repaired)."""
    v = np.append(rows, rows[-1] + 1)
    x, y = sx[v], sy[v]
    tx, ty = tangent[0][v - first], tangent[1][v - first]  # `tangent` from row `first` on
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
    s: FloatArray,
    comp: npt.NDArray[np.intp],
    heading_deg: FloatArray,
    lo: int,
    hi: int,
) -> tuple[FloatArray, FloatArray]:
    """The path's direction at rows lo..hi (`s`: the path length at each row, `comp`: its
    stretch of linked rows): the chord from TANGENT_M of path behind to as far ahead (rows a
    few centimetres apart would turn a centimetre of jitter into degrees), within the stretch;
    the heading where the path has not moved."""
    n = sx.size
    s_here, comp_here = s[lo:hi], comp[lo:hi]
    starts = np.searchsorted(comp, comp_here, side="left")
    ends = np.searchsorted(comp, comp_here, side="right") - 1
    ahead = np.clip(np.searchsorted(s, s_here + TANGENT_M, side="left"), starts, ends)
    behind = np.clip(np.searchsorted(s, s_here - TANGENT_M, side="right") - 1, starts, ends)
    ahead = np.minimum(ahead, n - 1)
    tx, ty = sx[ahead] - sx[behind], sy[ahead] - sy[behind]
    norm = np.hypot(tx, ty)
    h = np.radians(heading_deg[lo:hi])
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
    """Per swath, the % of its area that earlier swaths had covered already."""
    return Cover().add(geoms)


class Cover:
    """The ground covered so far, kept as one union per COVER_TILE_M square tile: a swath's
    overlap is its intersection with the tiles it touches, then it is added to them. The cost
    and memory grow with the ground covered, not with the time spent on it (comparing each
    swath with every earlier one it touches made a day driven over the same passes quadratic:
    1,000 earlier swaths each by the evening); swaths come a batch at a time."""

    def __init__(self) -> None:
        self.tiles: dict[tuple[int, int], Any] = {}

    def covered_m2(self, geoms: npt.NDArray[np.object_]) -> FloatArray:
        """The area of each of `geoms` that the ground covered so far holds (nothing added)."""
        out = np.zeros(geoms.size)
        full = ~shapely.is_empty(geoms)
        if not full.any() or not self.tiles:
            return out
        b = np.floor(shapely.bounds(geoms[full]) / COVER_TILE_M)
        i0, j0 = np.nanmin(b[:, :2], axis=0).astype(int)
        i1, j1 = np.nanmax(b[:, 2:], axis=0).astype(int)
        earlier = [self.tiles[(i, j)] for i in range(i0, i1 + 1) for j in range(j0, j1 + 1)
                   if (i, j) in self.tiles]  # fmt: skip
        if earlier:
            cut = shapely.intersection(geoms[full][:, None], np.array(earlier, dtype=object))
            out[full] = shapely.area(cut).sum(axis=1)
        return out

    def add(self, geoms: npt.NDArray[np.object_]) -> FloatArray:
        """The overlap % of each of `geoms` (in order) with what came before; then covered."""
        out = np.zeros(geoms.size)
        if geoms.size == 0:
            return out
        cover = self.tiles
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
