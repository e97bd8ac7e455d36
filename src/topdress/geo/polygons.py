"""Polygons from a GeoPackage, Shapefile or GeoJSON file (GDAL through pyogrio), in WGS 84,
with the attributes asked for. Every way such a file goes wrong is a MapError naming the file
and, where there is one, the feature: missing file or layer, unreadable or truncated file, no
coordinate reference system, no features, a missing attribute, a value that is not a number,
a geometry that is not a polygon, coordinates that land outside WGS 84 once projected (a file
whose declared CRS is not the one its coordinates are in).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pyogrio
import pyogrio.raw
import shapely
from pyogrio.errors import DataLayerError, DataSourceError
from pyproj import CRS, Transformer
from pyproj.exceptions import CRSError

from topdress.errors import MapError

WGS84 = CRS.from_epsg(4326)


@dataclass(frozen=True)
class Polygons:
    """Polygons (WGS 84 lon/lat), one per feature, and the numeric attributes asked for."""

    path: Path
    geoms: npt.NDArray[np.object_]
    values: dict[str, npt.NDArray[np.float64]]
    labels: list[str]  # "feature 3 (fid 4)" for messages


def read_polygons(path: Path, layer: str = "", attributes: tuple[str, ...] = ()) -> Polygons:
    if not path.exists():
        raise MapError(f"{path}: no such file")
    try:
        meta, fids, wkb, fields = pyogrio.raw.read(path, layer=layer or None, return_fids=True)
    except DataLayerError as exc:
        layers = _layers(path)
        raise MapError(f"{path}: no layer {layer!r} (layers: {', '.join(layers)}): {exc}") from exc
    except (DataSourceError, ValueError, RuntimeError, OSError) as exc:
        raise MapError(f"{path}: not a readable GeoPackage, Shapefile or GeoJSON: {exc}") from exc
    where = f"{path}" + (f" layer {layer}" if layer else "")
    if meta.get("crs") is None:
        raise MapError(
            f"{where}: no coordinate reference system (a Shapefile needs its .prj): "
            "the polygons cannot be placed"
        )
    if wkb is None or len(wkb) == 0:
        raise MapError(f"{where}: no features")
    names = [str(n) for n in meta["fields"]]
    labels = [f"feature {i} (fid {int(f)})" for i, f in enumerate(fids)] if fids is not None else []
    labels += [f"feature {i}" for i in range(len(labels), len(wkb))]
    values: dict[str, npt.NDArray[np.float64]] = {}
    for attr in attributes:
        if attr not in names:
            raise MapError(
                f"{where}: no attribute {attr!r} (attributes: {', '.join(names) or 'none'})"
            )
        values[attr] = _numbers(fields[names.index(attr)], attr, where, labels)
    geoms = _polygons(wkb, where, labels)
    geoms = _to_wgs84(geoms, str(meta["crs"]), where, labels)
    return Polygons(path, geoms, values, labels)


def _layers(path: Path) -> list[str]:
    try:
        return [str(name) for name, _ in pyogrio.list_layers(path)]
    except (DataSourceError, OSError):
        return []


def _numbers(
    column: npt.NDArray[np.generic], attr: str, where: str, labels: list[str]
) -> npt.NDArray[np.float64]:
    out = np.empty(len(column), dtype=float)
    for i, v in enumerate(column):
        try:
            x = float(v)
        except (TypeError, ValueError):
            raise MapError(f"{where}: {labels[i]}: {attr} = {v!r} is not a number") from None
        if not math.isfinite(x):
            raise MapError(f"{where}: {labels[i]}: {attr} is empty or not a number")
        out[i] = x
    return out


def _polygons(
    wkb: npt.NDArray[np.object_], where: str, labels: list[str]
) -> npt.NDArray[np.object_]:
    geoms = np.empty(len(wkb), dtype=object)
    for i, blob in enumerate(wkb):
        if blob is None:
            raise MapError(f"{where}: {labels[i]} has no geometry")
        try:
            g = shapely.from_wkb(blob)
        except shapely.errors.GEOSException as exc:
            raise MapError(f"{where}: {labels[i]}: unreadable geometry ({exc})") from exc
        if g.geom_type not in ("Polygon", "MultiPolygon") or g.is_empty:
            raise MapError(f"{where}: {labels[i]} is a {g.geom_type}, not a polygon")
        if not g.is_valid:  # a self-touching ring from a hand-drawn zone: repaired, not refused
            g = shapely.make_valid(g)
        geoms[i] = g
    return geoms


def _to_wgs84(
    geoms: npt.NDArray[np.object_], crs_text: str, where: str, labels: list[str]
) -> npt.NDArray[np.object_]:
    try:
        crs = CRS.from_user_input(crs_text)
    except CRSError as exc:
        raise MapError(f"{where}: coordinate reference system not understood: {exc}") from exc
    if crs != WGS84:
        tr = Transformer.from_crs(crs, WGS84, always_xy=True)
        geoms = np.asarray(
            shapely.transform(geoms, lambda xy: np.column_stack(tr.transform(xy[:, 0], xy[:, 1])))
        )
    bounds = shapely.bounds(geoms)
    bad = ~(
        np.isfinite(bounds).all(axis=1)
        & (bounds[:, 0] >= -180)
        & (bounds[:, 2] <= 180)
        & (bounds[:, 1] >= -90)
        & (bounds[:, 3] <= 90)
    )
    if bad.any():
        i = int(np.argmax(bad))
        raise MapError(
            f"{where}: {labels[i]}: coordinates {bounds[i].round(3).tolist()} are not on the "
            f"earth once read as {crs.name}: mis-projected (is the declared CRS the right one?)"
        )
    return geoms
