"""Prescription maps: the rate to apply where the meters' outlet is.

From polygons (GeoPackage, Shapefile, GeoJSON: the rate attribute named in the configuration,
in its configured units) or from an ISOXML task's grid (types 1 and 2; units from the DDI).
`lookup(lat, lon)` gives the zone there, None outside every zone. Polygons are found with an
STR-tree of their bounding boxes, then an exact point-in-polygon test on the candidates (a
point on a zone's edge is in it); where zones overlap, the first in the file wins.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Final, Protocol

import numpy as np
import numpy.typing as npt
import shapely

from topdress.config import PrescriptionConfig
from topdress.errors import MapError
from topdress.geo.isoxml import Grid, read_grid
from topdress.geo.polygons import PROGRESS_FEATURES, read_polygons

KG_HA_PER_UNIT: Final = {"kg/ha": 1.0, "lb/ac": 0.45359237 / 0.40468564224, "t/ha": 1000.0}
MAX_KG_HA: Final = 1200.0  # beyond any topdressing rate: a value in other units


@dataclass(frozen=True)
class Zone:
    rate_kg_ha: float
    min_kg_ha: float = math.nan  # the zone's limits (bound mode), NaN when not given
    max_kg_ha: float = math.nan
    label: str = ""


class RateMap(Protocol):
    source: Path

    def lookup(self, lat: float, lon: float) -> Zone | None: ...

    def describe(self) -> MapInfo: ...


@dataclass(frozen=True)
class MapInfo:
    """What a map holds, said when it is loaded: its parts (zones or cells), the rate range in
    the file's units, the extent (WGS 84) and the CRS it was read in."""

    parts: str  # "5000 zones", "20 grid cells (5 x 4) in 3 treatment zones"
    rate_lo: float  # kg/ha
    rate_hi: float
    units: str
    bounds: tuple[float, float, float, float]  # lon min, lat min, lon max, lat max
    crs: str

    def text(self) -> str:
        lon0, lat0, lon1, lat1 = self.bounds
        f = KG_HA_PER_UNIT.get(self.units, 1.0)
        mid = math.radians((lat0 + lat1) / 2)
        ew, ns = (lon1 - lon0) * 111_320.0 * math.cos(mid), (lat1 - lat0) * 110_540.0
        return (
            f"{self.parts}, {self.rate_lo / f:g}..{self.rate_hi / f:g} {self.units}"
            + (f" ({self.rate_lo:.4g}..{self.rate_hi:.4g} kg/ha)" if f != 1.0 else "")
            + f", extent {lat0:.6f}..{lat1:.6f} N, {lon0:.6f}..{lon1:.6f} E"
            + f" ({ew:.0f} x {ns:.0f} m), read in {self.crs}"
        )

    def distance_m(self, lat: float, lon: float) -> float:
        """From (lat, lon) to the extent, m (0 inside it)."""
        lon0, lat0, lon1, lat1 = self.bounds
        dlat = max(lat0 - lat, 0.0, lat - lat1) * 110_540.0
        dlon = max(lon0 - lon, 0.0, lon - lon1) * 111_320.0 * math.cos(math.radians(lat))
        return math.hypot(dlat, dlon)


class PolygonPrescription:
    def __init__(
        self,
        source: Path,
        geoms: npt.NDArray[np.object_],
        rate: npt.NDArray[np.float64],
        low: npt.NDArray[np.float64],
        high: npt.NDArray[np.float64],
        label: Callable[[int], str] = lambda i: f"feature {i}",
        units: str = "kg/ha",
        crs: str = "EPSG:4326",
    ) -> None:
        self.source = source
        self.geoms = geoms
        self.tree = shapely.STRtree(geoms)
        # Zones are made when looked up: a million Zone objects cost seconds and memory.
        self.rate, self.low, self.high = rate, low, high
        self.label = label
        self.units = units
        self.crs = crs

    def lookup(self, lat: float, lon: float) -> Zone | None:
        # One GEOS call: the tree's bounding boxes, then the exact test on the candidates.
        hits = self.tree.query(shapely.Point(lon, lat), predicate="intersects")
        if hits.size == 0:
            return None
        i = int(hits.min())  # overlapping zones: the first in the file
        return Zone(float(self.rate[i]), float(self.low[i]), float(self.high[i]), self.label(i))

    def describe(self) -> MapInfo:
        b = shapely.total_bounds(self.geoms)
        n = self.geoms.size
        return MapInfo(
            f"{n} zone{'s' if n != 1 else ''}",
            float(np.min(self.rate)),
            float(np.max(self.rate)),
            self.units,
            (float(b[0]), float(b[1]), float(b[2]), float(b[3])),
            self.crs,
        )


class GridPrescription:
    def __init__(self, source: Path, grid: Grid) -> None:
        self.source = source
        self.grid = grid

    def lookup(self, lat: float, lon: float) -> Zone | None:
        g = self.grid
        row = math.floor((lat - g.min_lat) / g.cell_lat)
        col = math.floor((lon - g.min_lon) / g.cell_lon)
        rows, cols = g.values.shape
        if not (0 <= row < rows and 0 <= col < cols):
            return None
        rate = float(g.values[row, col])
        if math.isnan(rate):
            return None
        label = f"cell row {row} column {col}"
        return Zone(rate, float(g.low[row, col]), float(g.high[row, col]), label)

    def describe(self) -> MapInfo:
        g = self.grid
        rows, cols = g.values.shape
        rated = g.values[np.isfinite(g.values)]
        zones = np.unique(rated).size
        return MapInfo(
            f"{rows * cols} grid cells ({rows} x {cols}), {rated.size} with a rate, "
            f"{zones} rate{'s' if zones != 1 else ''}",
            float(np.min(rated)) if rated.size else 0.0,
            float(np.max(rated)) if rated.size else 0.0,
            "kg/ha",
            (g.min_lon, g.min_lat, g.min_lon + cols * g.cell_lon, g.min_lat + rows * g.cell_lat),
            "EPSG:4326 (ISOXML)",
        )


def load_prescription(
    cfg: PrescriptionConfig, progress: Callable[[str], None] | None = None
) -> RateMap:
    """The map `cfg.path` names; MapError naming the file (and feature) when it is not usable.
    `progress` gets a line per stage of a large file."""
    path = Path(cfg.path)
    if path.suffix.lower() == ".xml":
        grid = read_grid(path)
        if cfg.mode == "bound" and np.isnan(grid.low).all() and np.isnan(grid.high).all():
            raise MapError(
                f"{path}: prescription.mode = bound needs the zones' limits (DDIs 9 and 10, "
                "minimum and maximum mass per area), which this grid does not give"
            )
        _check_range(path, grid.values[np.isfinite(grid.values)], lambda i: "a cell")
        return GridPrescription(path, grid)
    attrs: tuple[str, ...] = (cfg.attribute,)
    if cfg.mode == "bound":
        attrs += (cfg.min_attribute, cfg.max_attribute)
    polys = read_polygons(path, cfg.layer, attrs, progress)
    factor = KG_HA_PER_UNIT[cfg.units]
    rate = polys.values[cfg.attribute] * factor
    _check_range(path, rate, polys.label, cfg.attribute, cfg.units)
    if cfg.mode == "bound":
        low = polys.values[cfg.min_attribute] * factor
        high = polys.values[cfg.max_attribute] * factor
        for name, col in ((cfg.min_attribute, low), (cfg.max_attribute, high)):
            _check_range(path, col, polys.label, name, cfg.units)
        bad = np.nonzero(low > high)[0]
        if bad.size:
            raise MapError(
                f"{path}: {polys.label(int(bad[0]))}: {cfg.min_attribute} is above "
                f"{cfg.max_attribute}"
            )
    else:
        low = high = np.full_like(rate, math.nan)
    if progress is not None and rate.size >= PROGRESS_FEATURES:
        progress(f"{path.name}: indexing {rate.size:,} zones")
    return PolygonPrescription(
        path, polys.geoms, rate, low, high, polys.label, cfg.units, polys.crs
    )


def _check_range(
    path: Path,
    kg_ha: npt.NDArray[np.float64],
    label: Callable[[int], str],
    attr: str = "rate",
    units: str = "kg/ha",
) -> None:
    bad = np.nonzero((kg_ha < 0) | (kg_ha > MAX_KG_HA))[0]
    if bad.size:
        i = int(bad[0])
        value = kg_ha[i] / KG_HA_PER_UNIT.get(units, 1.0)
        raise MapError(
            f"{path}: {label(i)}: {attr} = {value:g} {units} is outside 0..{MAX_KG_HA:g} kg/ha "
            "(are prescription.units right?)"
        )
