"""Section control from the field boundary and the ground already covered (ISO 11783-10
TC-SC): which of an implement's sections should work now, so that sections go off over ground
covered before and outside the field, and on again over ground still to do.

Each section is where its client's DDOP puts it (DDI 134 X forward, 135 Y right, 67 width, mm
from the device reference point; `Device.section_geometry_mm`), and the device reference point
is where the terminal's configuration puts it from the GNSS antenna. A section looks at the
ground just ahead of it: a strip its width wide and `look_m` long, starting `lead_m` ahead (the
distance the machine drives while a section switches, speed x the DDOP's latency, DDI 142/143).
It goes off when more than `off_pct` % of that strip is outside the field or already covered.

Coverage is built from the sections the implement reports working (DDI 161): the ground between
a section's last footprint and its present one, kept in the as-applied map's tiles (`Cover`);
as-applied swaths of earlier sessions of the same field are added (`earlier_coverage` reads
them from the session logs, so a terminal restarted mid-field keeps what it had covered). Work
is done in the field's UTM zone.
"""

from __future__ import annotations

import sqlite3
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from pyproj import CRS, Transformer

from topdress.config import loads_config
from topdress.errors import ConfigError, LogError, MapError
from topdress.geo.asapplied import WGS84, Cover, utm_crs
from topdress.geo.asapplied import build as build_as_applied
from topdress.geo.boundary import FieldBoundary
from topdress.geo.outlet import offset_position
from topdress.isobus.devicemap import Device
from topdress.log.session import SUFFIX, SessionReader

FLUSH_EVERY = 10  # positions whose covered quads go into the coverage together
MAX_STEP_M = 5.0  # a longer jump between two positions is a gap: nothing is counted covered
MTIME_SLACK_S = 600.0  # a file last written this long before the window may still be in it
OUTSIDE, COVERED = "outside", "covered"  # why `decide` put a section off (`SectionControl.why`)


@dataclass(frozen=True)
class Section:
    """One section's place: metres from the device reference point, forward and right."""

    x_m: float
    y_m: float
    width_m: float


def sections_from_device(device: Device) -> list[Section]:
    """The sections of a client's DDOP, in its order (section 1 first)."""
    return [Section(x / 1000, y / 1000, w / 1000) for x, y, w in device.section_geometry_mm()]


class SectionControl:
    """Section setpoints for one implement; what `decide` answers depends only on the position
    and the ground covered so far, `cover` adds what the implement reports it worked. It works
    in the boundary's UTM zone; without a boundary in `crs`, else the first position's."""

    def __init__(
        self,
        sections: list[Section],
        boundary: FieldBoundary | None,
        drp_along_m: float = 0.0,
        drp_across_m: float = 0.0,
        off_pct: float = 50.0,
        look_m: float = 1.0,
        crs: CRS | None = None,
    ) -> None:
        if not sections:
            raise ValueError("section control needs at least one section")
        if not 0.0 <= off_pct < 100.0 or look_m <= 0.0:
            raise ValueError(f"off_pct {off_pct} must be in 0..100, look_m {look_m} above 0")
        self.sections = sections
        self.boundary = boundary
        self.drp = (drp_along_m, drp_across_m)
        self.off_pct = off_pct
        self.look_m = look_m
        self.coverage = Cover()
        self.crs: CRS | None = None  # the UTM zone worked in: the boundary's, or the first fix's
        self._fwd: Transformer | None = None
        self._last: list[tuple[Any, Any]] | None = None  # each section's footprint ends, UTM
        self._quads: list[tuple[Any, Any, Any, Any]] = []  # covered, not yet in `coverage`
        self._since = 0
        self.why: tuple[str, ...] = ()  # per section, why the last `decide` put it off ("": on)
        if boundary is not None:
            self._use(boundary.crs)
        elif crs is not None:
            self._use(crs)

    def _use(self, crs: CRS) -> None:
        self.crs = crs
        self._fwd = Transformer.from_crs(WGS84, crs, always_xy=True)

    def _utm(self, lat: float, lon: float) -> np.ndarray:
        if self._fwd is None:
            self._use(utm_crs(lat, lon))
        assert self._fwd is not None
        x, y = self._fwd.transform(lon, lat)
        return np.array([x, y])

    def _frame(self, lat: float, lon: float, heading_deg: float) -> tuple[Any, Any, Any]:
        """The device reference point and the unit vectors forward and right, in UTM metres
        (forward from a point 10 m ahead, so the grid's convergence is taken into account)."""
        along, across = self.drp
        p = self._utm(*offset_position(lat, lon, heading_deg, along, across))
        ahead = self._utm(*offset_position(lat, lon, heading_deg, along + 10.0, across))
        fwd = (ahead - p) / np.linalg.norm(ahead - p)
        return p, fwd, np.array([fwd[1], -fwd[0]])

    def footprints(self, lat: float, lon: float, heading_deg: float) -> list[tuple[Any, Any]]:
        """Each section's left and right end on the ground, UTM metres."""
        return self._ends(*self._frame(lat, lon, heading_deg))

    def _ends(self, p: Any, fwd: Any, right: Any) -> list[tuple[Any, Any]]:
        out = []
        for s in self.sections:
            c = p + s.x_m * fwd + s.y_m * right
            out.append((c - right * s.width_m / 2, c + right * s.width_m / 2))
        return out

    def decide(self, lat: float, lon: float, heading_deg: float, lead_m: float = 0.0) -> list[bool]:
        """Each section's setpoint work state (True: work) at this antenna position."""
        self._flush()
        p, fwd, right = self._frame(lat, lon, heading_deg)
        start, end = fwd * max(lead_m, 0.0), fwd * (max(lead_m, 0.0) + self.look_m)
        ends = self._ends(p, fwd, right)
        looks = shapely.polygons(
            np.array([[a + start, b + start, b + end, a + end] for a, b in ends])
        )
        whole = shapely.area(looks)
        inside = (
            looks if self.boundary is None else shapely.intersection(looks, self.boundary.outer)
        )
        field = shapely.area(inside)
        todo = np.maximum(field - self.coverage.covered_m2(inside), 0.0)
        need = whole * (1.0 - self.off_pct / 100.0)
        on = [bool(w > 0.0 and t >= n) for t, w, n in zip(todo, whole, need, strict=True)]
        # why each is off: too little of its ground in the field, else too much of it covered
        self.why = tuple(
            "" if o else OUTSIDE if f < n else COVERED
            for o, f, n in zip(on, field, need, strict=True)
        )
        return on

    def cover(self, lat: float, lon: float, heading_deg: float, working: list[bool | None]) -> None:
        """The implement reports `working` (DDI 161, section 1 first) at this position: the ground
        each working section passed since the last call is covered (added to the coverage with
        the next `decide`, or every FLUSH_EVERY positions)."""
        now = self.footprints(lat, lon, heading_deg)
        last, self._last = self._last, now
        if last is None:
            return
        for (a0, b0), (a1, b1), on in zip(last, now, working, strict=False):
            moved = max(np.linalg.norm(a1 - a0), np.linalg.norm(b1 - b0))
            if not (on and 0.0 < moved <= MAX_STEP_M):
                continue
            prev = self._quads[-1] if self._quads else None
            if prev is not None and np.linalg.norm(prev[1] - a0) < 0.05:
                self._quads[-1] = (prev[0], b0, b1, prev[3])  # neighbours make one quad
            else:
                self._quads.append((a0, b0, b1, a1))
        self._since += 1
        if self._since >= FLUSH_EVERY:
            self._flush()

    def _flush(self) -> None:
        """Adds the quads gathered since the last flush to the coverage at once: the union into
        the tiles is the cost, so once a second, not ten times."""
        self._since = 0
        if not self._quads:
            return
        quads = shapely.make_valid(shapely.polygons(np.array(self._quads)))
        self._quads = []
        self.coverage.add(np.asarray(quads, dtype=object))

    def ground(self) -> tuple[Cover, CRS | None]:
        """The ground covered so far (the positions gathered since the last flush too), in
        the zone worked in (None before any position)."""
        self._flush()
        return self.coverage, self.crs

    def add_cover(self, cover: Cover, crs: CRS) -> bool:
        """Ground covered before, as tiles made elsewhere (off the loop: `earlier_coverage`) in
        `crs`: taken tile by tile (a union only where this coverage has ground in the same
        tile). False, nothing taken, when this section control works in another zone."""
        if self.crs is None:
            self._use(crs)
        if self.crs != crs:
            return False
        self._flush()
        tiles = self.coverage.tiles
        for key, g in cover.tiles.items():
            old = tiles.get(key)
            tiles[key] = g if old is None else shapely.union(old, g)
        return True


@dataclass(frozen=True)
class EarlierCoverage:
    """The ground earlier sessions of the field covered: their as-applied swaths (WGS 84),
    the same as covered tiles (`cover`, in `crs`: the zone asked for, else theirs; None
    without swaths), the session files they came from, and those that could not be read
    (name: why)."""

    swaths: tuple[Any, ...]
    sessions: tuple[str, ...]
    skipped: tuple[str, ...]
    cover: Cover | None = None
    crs: CRS | None = None


def covered_tiles(swaths: list[Any], crs: CRS | None = None) -> tuple[Cover | None, CRS | None]:
    """The swaths (WGS 84) as covered tiles in `crs` (the zone the section control works in),
    else in their own UTM zone; (None, None) without swaths."""
    if not swaths:
        return None, None
    if crs is None:
        x0, y0, x1, y1 = shapely.total_bounds(np.array(swaths, dtype=object))
        crs = utm_crs((y0 + y1) / 2, (x0 + x1) / 2)
    fwd = Transformer.from_crs(WGS84, crs, always_xy=True)
    utm = shapely.transform(
        np.array(swaths, dtype=object),
        lambda xy: np.column_stack(fwd.transform(xy[:, 0], xy[:, 1])),
    )
    cover = Cover()
    cover.add(shapely.make_valid(utm))
    return cover, crs


def _created(reader: SessionReader) -> datetime | None:
    """When the session was created, in UTC (a time without a zone is taken as UTC, as the
    log writes it); None when missing or not a time."""
    try:
        t = datetime.fromisoformat(reader.meta["created_utc"])
    except (KeyError, ValueError):
        return None
    return t.replace(tzinfo=UTC) if t.tzinfo is None else t


def _boundary_key(reader: SessionReader) -> tuple[str, str]:
    """The session's field: its `[boundary] path` and `layer` (ConfigError: its configuration
    cannot be read, so its field is unknown)."""
    b = loads_config(reader.config_toml).boundary
    return (b.path, b.layer)


def earlier_coverage(session: Path, hours: float, crs: CRS | None = None) -> EarlierCoverage:
    """The as-applied swaths of the sessions beside `session` (the one being written) that
    count for its coverage: created within `hours` before it, with the same `[boundary] path`
    and `layer` (the same field; two sessions without a boundary count alike, their swaths
    only matter where the machine drives again), also made into covered tiles (in `crs`, the
    section control's zone, so that it takes them as they are; else the swaths'). Files last
    written before the window are not opened; a session of the window that cannot be read,
    or whose configuration cannot (its field unknown), is skipped and named. Reads files and
    unites the swaths (seconds for an hour of log): run it off the control loop."""
    with SessionReader(session) as reader:
        now = _created(reader)
        mine = _boundary_key(reader)
    if now is None:
        raise LogError(f"{session}: no creation time")
    since = now - timedelta(hours=hours)
    oldest = since.timestamp() - MTIME_SLACK_S
    swaths: list[Any] = []
    used: list[str] = []
    skipped: list[str] = []
    for path in sorted(session.parent.glob(f"*{SUFFIX}")):
        if path.resolve() == session.resolve():
            continue
        try:
            if path.stat().st_mtime < oldest:
                continue  # written before the window: an old day's log, or not a session
            with SessionReader(path) as reader:
                created = _created(reader)
                if created is None or not since <= created <= now:
                    continue
                if _boundary_key(reader) != mine:
                    continue
                got = build_as_applied(reader).swath_geom
        except (ConfigError, LogError, MapError, OSError, sqlite3.Error, ValueError) as exc:
            skipped.append(f"{path.name}: {exc}")
            continue
        if len(got):  # a log that applied nothing (an implement's, too) adds nothing
            used.append(path.name)
            swaths.extend(got)
    cover, zone = covered_tiles(swaths, crs)
    return EarlierCoverage(tuple(swaths), tuple(used), tuple(skipped), cover, zone)
