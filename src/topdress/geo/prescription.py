"""Prescription maps: the rate to apply where the meters' outlet is.

From polygons (GeoPackage, Shapefile, GeoJSON: the rate attribute named in the configuration,
in its configured units) or from an ISOXML task's grid (types 1 and 2; units from the DDI).
`lookup(lat, lon)` gives the zone there, None outside every zone. Polygons are found with an
STR-tree of their bounding boxes, then an exact point-in-polygon test on the candidates (a
point on a zone's edge is in it); where zones overlap, the first in the file wins.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Final, Protocol

import numpy as np
import numpy.typing as npt
import shapely

from topdress.config import PrescriptionConfig
from topdress.errors import MapError
from topdress.geo.isoxml import Grid, read_grid
from topdress.geo.polygons import read_polygons

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


class PolygonPrescription:
    def __init__(
        self,
        source: Path,
        geoms: npt.NDArray[np.object_],
        rate: npt.NDArray[np.float64],
        low: npt.NDArray[np.float64],
        high: npt.NDArray[np.float64],
        labels: list[str],
    ) -> None:
        self.source = source
        self.geoms = geoms
        self.tree = shapely.STRtree(geoms)
        self.zones = [
            Zone(float(r), float(lo), float(hi), lab)
            for r, lo, hi, lab in zip(rate, low, high, labels, strict=True)
        ]

    def lookup(self, lat: float, lon: float) -> Zone | None:
        # One GEOS call: the tree's bounding boxes, then the exact test on the candidates.
        hits = self.tree.query(shapely.Point(lon, lat), predicate="intersects")
        if hits.size == 0:
            return None
        return self.zones[int(hits.min())]  # overlapping zones: the first in the file


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


def load_prescription(cfg: PrescriptionConfig) -> RateMap:
    """The map `cfg.path` names; MapError naming the file (and feature) when it is not usable."""
    path = Path(cfg.path)
    if path.suffix.lower() == ".xml":
        grid = read_grid(path)
        if cfg.mode == "bound" and np.isnan(grid.low).all() and np.isnan(grid.high).all():
            raise MapError(
                f"{path}: prescription.mode = bound needs the zones' limits (DDIs 9 and 10, "
                "minimum and maximum mass per area), which this grid does not give"
            )
        _check_range(path, grid.values[np.isfinite(grid.values)], ["a cell"] * grid.values.size)
        return GridPrescription(path, grid)
    attrs: tuple[str, ...] = (cfg.attribute,)
    if cfg.mode == "bound":
        attrs += (cfg.min_attribute, cfg.max_attribute)
    polys = read_polygons(path, cfg.layer, attrs)
    factor = KG_HA_PER_UNIT[cfg.units]
    rate = polys.values[cfg.attribute] * factor
    _check_range(path, rate, polys.labels, cfg.attribute, cfg.units)
    if cfg.mode == "bound":
        low = polys.values[cfg.min_attribute] * factor
        high = polys.values[cfg.max_attribute] * factor
        for name, col in ((cfg.min_attribute, low), (cfg.max_attribute, high)):
            _check_range(path, col, polys.labels, name, cfg.units)
        bad = np.nonzero(low > high)[0]
        if bad.size:
            raise MapError(
                f"{path}: {polys.labels[bad[0]]}: {cfg.min_attribute} is above {cfg.max_attribute}"
            )
    else:
        low = high = np.full_like(rate, math.nan)
    return PolygonPrescription(path, polys.geoms, rate, low, high, polys.labels)


def _check_range(
    path: Path,
    kg_ha: npt.NDArray[np.float64],
    labels: list[str],
    attr: str = "rate",
    units: str = "kg/ha",
) -> None:
    bad = np.nonzero((kg_ha < 0) | (kg_ha > MAX_KG_HA))[0]
    if bad.size:
        i = int(bad[0])
        value = kg_ha[i] / KG_HA_PER_UNIT.get(units, 1.0)
        raise MapError(
            f"{path}: {labels[i]}: {attr} = {value:g} {units} is outside 0..{MAX_KG_HA:g} kg/ha "
            "(are prescription.units right?)"
        )
