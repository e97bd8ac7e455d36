"""The field boundary and its headland: where the meters may work.

`zone(lat, lon)` is "field" inside the boundary and farther than `headland_m` from it,
"headland" in the strip of that width inside it, "outside" beyond it. The strip is the
boundary buffered inwards in the field's UTM zone (metres); islands (inner rings) get their
own strip. The boundary comes from polygons (GeoPackage, Shapefile, GeoJSON; several features
are joined) or from an ISOXML partfield (PLN type 1).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import shapely
from pyproj import Transformer

from topdress.config import BoundaryConfig
from topdress.errors import MapError
from topdress.geo.asapplied import WGS84, utm_crs
from topdress.geo.isoxml import read_partfield_boundary
from topdress.geo.polygons import read_polygons


class FieldBoundary:
    def __init__(
        self, source: Path, boundary_wgs84: Any, headland_m: float, crs: str = "EPSG:4326"
    ) -> None:
        self.source = source
        self.crs_read = crs
        self.headland_m = headland_m
        self.boundary = boundary_wgs84
        c = boundary_wgs84.centroid
        self.crs = utm_crs(c.y, c.x)
        self._fwd = Transformer.from_crs(WGS84, self.crs, always_xy=True)
        self.outer = shapely.transform(
            boundary_wgs84, lambda xy: np.column_stack(self._fwd.transform(xy[:, 0], xy[:, 1]))
        )
        self.inner = self.outer.buffer(-headland_m) if headland_m > 0 else self.outer
        shapely.prepare(self.outer)
        shapely.prepare(self.inner)

    def zone(self, lat: float, lon: float) -> str:
        x, y = self._fwd.transform(lon, lat)
        if not shapely.contains_xy(self.outer, x, y):
            return "outside"
        return "field" if shapely.contains_xy(self.inner, x, y) else "headland"

    def zones(self, lat: npt.NDArray[np.float64], lon: npt.NDArray[np.float64]) -> list[str]:
        x, y = self._fwd.transform(lon, lat)
        outer = shapely.contains_xy(self.outer, x, y)
        inner = shapely.contains_xy(self.inner, x, y)
        return [
            "field" if i else "headland" if o else "outside"
            for o, i in zip(outer, inner, strict=True)
        ]

    def describe(self) -> str:
        """What was loaded: polygons, area, the field left inside the headland, extent, CRS."""
        n = len(shapely.get_parts(self.boundary))
        lon0, lat0, lon1, lat1 = self.boundary.bounds
        return (
            f"{n} polygon{'s' if n != 1 else ''}, {self.outer.area / 10_000:.2f} ha, "
            f"headland {self.headland_m:g} m leaves {self.inner.area / 10_000:.2f} ha, "
            f"extent {lat0:.6f}..{lat1:.6f} N, {lon0:.6f}..{lon1:.6f} E, read in {self.crs_read}"
        )

    def distance_m(self, lat: float, lon: float) -> float:
        """From (lat, lon) to the boundary, m (0 inside it)."""
        x, y = self._fwd.transform(lon, lat)
        return float(shapely.distance(self.outer, shapely.Point(x, y)))

    def inner_wgs84(self) -> Any:
        back = Transformer.from_crs(self.crs, WGS84, always_xy=True)
        return shapely.transform(
            self.inner, lambda xy: np.column_stack(back.transform(xy[:, 0], xy[:, 1]))
        )


def load_boundary(cfg: BoundaryConfig) -> FieldBoundary:
    path = Path(cfg.path)
    crs = "EPSG:4326 (ISOXML)"
    if path.suffix.lower() == ".xml":
        geom = read_partfield_boundary(path)
    else:
        polys = read_polygons(path, cfg.layer)
        geom, crs = shapely.union_all(polys.geoms), polys.crs
    if geom.is_empty or geom.area == 0:
        raise MapError(f"{path}: the boundary encloses no area")
    out = FieldBoundary(path, geom, cfg.headland_m, crs)
    if out.inner.is_empty:
        raise MapError(
            f"{path}: a headland of {cfg.headland_m:g} m (boundary.headland_m) leaves no field "
            "inside the boundary"
        )
    return out
