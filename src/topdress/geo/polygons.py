"""Polygons from a GeoPackage, Shapefile or GeoJSON file (GDAL through pyogrio), in WGS 84,
with the attributes asked for. Every way such a file goes wrong is a MapError naming the file
and, where there is one, the feature: missing file or layer, unreadable or truncated file, no
coordinate reference system, no features, a missing attribute, a value that is not a number,
a geometry that is not a polygon, coordinates that land outside WGS 84 once projected (a file
whose declared CRS is not the one its coordinates are in).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pyarrow as pa
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
    fids: npt.NDArray[np.int64] | None = None
    crs: str = "EPSG:4326"  # the file's own CRS (as read)

    def label(self, i: int) -> str:
        """ "feature 3 (fid 4)" for messages."""
        return _label(self.fids, i)


#: From this many features on, loading says what it does (a 10^6-polygon map takes seconds).
PROGRESS_FEATURES = 100_000


def read_polygons(
    path: Path,
    layer: str = "",
    attributes: tuple[str, ...] = (),
    progress: Callable[[str], None] | None = None,
) -> Polygons:
    """The polygons of `path` with the numeric `attributes` (only those are read: a text
    attribute the map does not use cannot refuse it). `progress` gets a line per stage of a
    large file."""
    if not path.exists():
        raise MapError(f"{path}: no such file")
    where = f"{path}" + (f" layer {layer}" if layer else "")
    try:
        info = pyogrio.read_info(path, layer=layer or None)
        names = [str(n) for n in info["fields"]]
        if info.get("crs") is None:
            raise MapError(
                f"{where}: no coordinate reference system (a Shapefile needs its .prj): "
                "the polygons cannot be placed"
            )
        if info.get("features") == 0:
            raise MapError(f"{where}: no features")
        for attr in attributes:
            if attr not in names:
                raise MapError(
                    f"{where}: no attribute {attr!r} (attributes: {', '.join(names) or 'none'})"
                )
        n = int(info.get("features") or 0)
        if progress is not None and n >= PROGRESS_FEATURES:
            progress(f"{path.name}: reading {n:,} features")
        # Arrow: whole columns from GDAL (a million features in a fraction of a second), and
        # text that is not in the file's encoding arrives replaced (U+FFFD), not as an error.
        meta, table = pyogrio.raw.read_arrow(
            path, layer=layer or None, return_fids=True, columns=list(attributes)
        )
    except DataLayerError as exc:
        layers = _layers(path)
        raise MapError(f"{path}: no layer {layer!r} (layers: {', '.join(layers)}): {exc}") from exc
    except (DataSourceError, ValueError, RuntimeError, OSError) as exc:
        raise MapError(f"{path}: not a readable GeoPackage, Shapefile or GeoJSON: {exc}") from exc
    if meta.get("crs") is None:
        raise MapError(
            f"{where}: no coordinate reference system (a Shapefile needs its .prj): "
            "the polygons cannot be placed"
        )
    if table.num_rows == 0:
        raise MapError(f"{where}: no features")
    fid_name = str(meta.get("fid_column") or "")
    rest = [c for c in table.column_names if c != fid_name and c not in attributes]
    wkb = table.column(rest[-1]).to_numpy(zero_copy_only=False)
    fid_arr = (
        np.asarray(table.column(fid_name).to_numpy(), dtype=np.int64)
        if fid_name in table.column_names
        else None
    )
    values = {attr: _numbers(_column(table, attr), attr, where, fid_arr) for attr in attributes}
    if progress is not None and len(wkb) >= PROGRESS_FEATURES:
        progress(f"{path.name}: checking {len(wkb):,} polygons")
    geoms = _polygons(wkb, where, fid_arr)
    geoms = _to_wgs84(geoms, str(meta["crs"]), where, fid_arr)
    return Polygons(path, geoms, values, fid_arr, str(meta["crs"]))


def _column(table: pa.Table, name: str) -> npt.NDArray[np.generic]:
    """A column as numbers or text; text that is not valid UTF-8 (a file whose encoding is
    not the one it declares) has its bad bytes replaced, so the message can show it."""
    col = table.column(name)
    try:
        return np.asarray(col.to_numpy(zero_copy_only=False))
    except pa.ArrowException:
        raw = col.cast(pa.binary()).to_pylist()
        text = [None if b is None else b.decode("utf-8", "replace") for b in raw]
        return np.array(text, dtype=object)


def _label(fids: npt.NDArray[np.int64] | None, i: int) -> str:
    if fids is not None and i < len(fids):
        return f"feature {i} (fid {int(fids[i])})"
    return f"feature {i}"


def _layers(path: Path) -> list[str]:
    try:
        return [str(name) for name, _ in pyogrio.list_layers(path)]
    except (DataSourceError, OSError):
        return []


def _numbers(
    column: npt.NDArray[np.generic], attr: str, where: str, fids: npt.NDArray[np.int64] | None
) -> npt.NDArray[np.float64]:
    try:
        out = np.asarray(column, dtype=float)
    except (TypeError, ValueError):
        out = np.empty(len(column), dtype=float)
        for i, v in enumerate(column):
            try:
                out[i] = float(v)
            except (TypeError, ValueError):
                raise MapError(
                    f"{where}: {_label(fids, i)}: {attr} = {v!r} is not a number"
                ) from None
    bad = np.nonzero(~np.isfinite(out))[0]
    if bad.size:
        raise MapError(f"{where}: {_label(fids, int(bad[0]))}: {attr} is empty or not a number")
    return out


def _polygons(
    wkb: npt.NDArray[np.object_], where: str, fids: npt.NDArray[np.int64] | None
) -> npt.NDArray[np.object_]:
    geoms = np.asarray(shapely.from_wkb(wkb, on_invalid="ignore"), dtype=object)
    missing = np.nonzero(shapely.is_missing(geoms))[0]
    if missing.size:
        i = int(missing[0])
        if wkb[i] is None:
            raise MapError(f"{where}: {_label(fids, i)} has no geometry")
        raise MapError(f"{where}: {_label(fids, i)}: unreadable geometry")
    kind = shapely.get_type_id(geoms)
    bad = np.nonzero(~np.isin(kind, (3, 6)) | shapely.is_empty(geoms))[0]
    if bad.size:
        i = int(bad[0])
        raise MapError(f"{where}: {_label(fids, i)} is a {geoms[i].geom_type}, not a polygon")
    # a self-touching ring from a hand-drawn zone: repaired, not refused
    invalid = ~shapely.is_valid(geoms)
    if invalid.any():
        geoms[invalid] = shapely.make_valid(geoms[invalid])
    return geoms


def _to_wgs84(
    geoms: npt.NDArray[np.object_], crs_text: str, where: str, fids: npt.NDArray[np.int64] | None
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
            f"{where}: {_label(fids, i)}: coordinates {bounds[i].round(3).tolist()} are not on the "
            f"earth once read as {crs.name}: mis-projected (is the declared CRS the right one?)"
        )
    return geoms
