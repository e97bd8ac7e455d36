"""As-applied points and swaths to GDAL vector formats (pyogrio): GeoPackage, Shapefile,
GeoJSON, CSV.

A GeoPackage holds both layers (`as_applied_points`, `as_applied_swaths`) in one file; the
single-layer formats get one file per layer beside the path given (`NAME_points.shp`,
`NAME_swaths.shp`, with a QGIS style `NAME_swaths.qml` of the rate classes that QGIS applies
by itself). Shapefile (dBASE) names are cut to 10 characters: the one longer name is
written as SHAPEFILE_NAMES says, and a `NAME_fields.csv` sidecar gives every field's full name
and unit (dBASE has no place for units).

`fmis=True` (Shapefile only) writes what farm management software imports without mapping:
numeric attributes only, at most 20, names of at most 10 characters; the time as UTC seconds,
the speed source and the zone as codes, and the units in `NAME_units.txt` beside the files.
"""

from __future__ import annotations

import csv
import tempfile
from collections.abc import Callable, Iterable, Iterator
from importlib import resources
from pathlib import Path
from typing import Final, Protocol, TextIO

import numpy as np
import numpy.typing as npt
import pyarrow as pa
import pyogrio
import shapely
from pyogrio.errors import DataSourceError, FieldError, GeometryError
from pyproj import CRS, Transformer

from topdress.errors import MapError
from topdress.geo.asapplied import SPEED_SOURCE_CODES, WGS84, Batch

FORMATS: Final = ("gpkg", "shp", "geojson", "csv")
DRIVERS: Final = {"gpkg": "GPKG", "shp": "ESRI Shapefile", "geojson": "GeoJSON", "csv": "CSV"}
SUFFIX: Final = {"gpkg": ".gpkg", "shp": ".shp", "geojson": ".geojson", "csv": ".csv"}
POINTS_LAYER: Final = "as_applied_points"
SWATHS_LAYER: Final = "as_applied_swaths"
SHAPEFILE_NAMES: Final = {"AppliedRate": "AppliedRt"}

#: The FMIS points: at most 20 numeric attributes (LogTime, the target r/min and the fault word
#: are left out: they are in the full export).
FMIS_POINTS: Final = (
    "UnixTime",
    "Heading",
    "SPEED",
    "SpeedSrc",
    "DISTANCE",
    "SWATHWIDTH",
    "NDVI",
    "TargetRate",
    "AppliedRate",
    "TgtRateUp",
    "TgtRateLo",
    "AppRateUp",
    "AppRateLo",
    "RpmUp",
    "RpmLo",
    "AppliedKg",
    "TargetKg",
    "WorkState",
    "Zone",
    "PrescRate",
)
FMIS_MAX_FIELDS: Final = 20
ZONE_CODES: Final = {"": 0, "field": 1, "headland": 2, "outside": 3}
FMIS_FIELDS: Final = {
    "UnixTime": ("s", "UTC, seconds since 1970-01-01 (POSIX)"),
    "SpeedSrc": ("", "speed source: 1 wheel, 3 GNSS, 4 fused (blended), 0 none (as DDI 400)"),
    "Zone": ("", "field boundary: 1 field, 2 headland, 3 outside, 0 no boundary"),
}

# field -> (unit, meaning)
FIELDS: Final = {
    "IsoTime": ("ISO 8601 UTC", "time of the record"),
    "Time": ("UTC", "time of the record, YYYY-MM-DD hh:mm:ss.sss"),
    "UtcSource": ("", "gnss (fix time), system (PC clock) or created (session start + log time)"),
    "LogTime": ("s", "the terminal's monotonic clock"),
    "Heading": ("deg", "course over ground, clockwise from north"),
    "SPEED": ("km/h", "selected speed (the one that drove the meters)"),
    "SpeedSrc": ("", "speed source: wheel, gnss, none"),
    "DISTANCE": ("m", "distance to the next record (swaths: their length along the path)"),
    "DURATION": ("s", "time the machine took over the swath"),
    "SWATHWIDTH": ("m", "working width"),
    "AREA": ("ha", "swath area"),
    "NDVI": ("", "NDVI at the meters"),
    "TargetRate": ("kg/ha", "target rate, both layers (swaths: TargetKg / AREA)"),
    "AppliedRate": ("kg/ha", "actual rate, both layers, eq. 4 inverted (swaths: AppliedKg / AREA)"),
    "CmdRate": ("kg/ha", "rate commanded to the ECU, both layers (swaths: mean over the path)"),
    "TgtRateUp": ("kg/ha", "target rate, upper layer"),
    "AppRateUp": ("kg/ha", "actual rate, upper layer"),
    "TgtRateLo": ("kg/ha", "target rate, lower layer"),
    "AppRateLo": ("kg/ha", "actual rate, lower layer"),
    "TgtRpmUp": ("r/min", "target metering speed, upper"),
    "RpmUp": ("r/min", "measured metering speed, upper"),
    "TgtRpmLo": ("r/min", "target metering speed, lower"),
    "RpmLo": ("r/min", "measured metering speed, lower"),
    "AppliedKg": ("kg", "fertilizer applied until the next record (swaths: on it), both layers"),
    "TargetKg": ("kg", "target fertilizer until the next record (swaths: on it), both layers"),
    "Overlap": ("%", "share of the swath's area that earlier swaths covered already"),
    "WorkState": ("", "1 while a meter turns"),
    "Faults": ("", "ECU fault word"),
    "Zone": ("", "field boundary: field, headland, outside; empty = no boundary"),
    "PrescRate": ("kg/ha", "prescription map rate at the outlet"),
}


def output_paths(path: Path, fmt: str) -> dict[str, Path]:
    """Layer -> file for `fmt`: one GeoPackage, else NAME_points / NAME_swaths."""
    if fmt == "gpkg":
        return {POINTS_LAYER: path, SWATHS_LAYER: path}
    stem = path.with_suffix("") if path.suffix.lower() == SUFFIX[fmt] else path
    return {
        POINTS_LAYER: stem.with_name(f"{stem.name}_points{SUFFIX[fmt]}"),
        SWATHS_LAYER: stem.with_name(f"{stem.name}_swaths{SUFFIX[fmt]}"),
    }


class Layers(Protocol):
    """What is written: the field's UTM zone and the two layers in batches (`AsApplied` gives
    each in one, `AsAppliedStream` a chunk of the session at a time)."""

    @property
    def utm(self) -> CRS | None: ...

    def point_batches(self) -> Iterator[Batch]: ...

    def swath_batches(self) -> Iterator[Batch]: ...


def write(data: Layers, path: Path, fmt: str, crs: str = "wgs84", fmis: bool = False) -> list[Path]:
    """Write both layers, a batch at a time; returns the files written. `crs` is wgs84 or utm
    (the field's zone); `fmis`: numeric attributes only, for farm management software
    (Shapefile only)."""
    if fmt not in FORMATS:
        raise MapError(f"{path}: unknown format {fmt!r} (one of {', '.join(FORMATS)})")
    if fmis:
        if fmt != "shp":
            raise MapError(f"{path}: --fmis is a Shapefile option (--format shp)")
        return _write_fmis(data, path, crs)
    target = WGS84 if crs == "wgs84" or data.utm is None else data.utm
    paths = output_paths(path, fmt)
    for p in set(paths.values()):
        _remove(p, fmt)
    written: list[Path] = []
    names: list[str] = []
    for layer, batches, gtype in (
        (POINTS_LAYER, data.point_batches(), "Point"),
        (SWATHS_LAYER, data.swath_batches(), "Polygon"),
    ):
        out = paths[layer]
        names += _write_batches(out, layer, fmt, batches, gtype, target)
        if out not in written:
            written.append(out)
    if fmt in ("shp", "geojson"):
        # QGIS applies a style named like the layer's file by itself
        style = paths[SWATHS_LAYER].with_suffix(".qml")
        qml = resources.files("topdress.geo").joinpath("data", "as_applied_rate.qml")
        attr = SHAPEFILE_NAMES.get("AppliedRate", "AppliedRate") if fmt == "shp" else "AppliedRate"
        text = qml.read_text(encoding="utf-8").replace('attr="AppliedRate"', f'attr="{attr}"')
        style.write_text(text, encoding="utf-8")
        written.append(style)
    if fmt in ("shp", "csv"):
        sidecar = path.with_suffix("") if path.suffix.lower() == SUFFIX[fmt] else path
        sidecar = sidecar.with_name(f"{sidecar.name}_fields.csv")
        _write_units(sidecar, fmt, names)
        written.append(sidecar)
    return written


def _write_batches(
    path: Path,
    layer: str,
    fmt: str,
    batches: Iterable[Batch],
    gtype: str,
    crs: CRS,
    columns: Callable[[dict[str, npt.NDArray[np.generic]]], dict[str, npt.NDArray[np.generic]]]
    | None = None,
) -> list[str]:
    """A layer written a batch at a time (appended: a long day in bounded memory; CSV cannot
    append, its batches are joined first; GeoJSON's batches are stitched, see
    `_write_geojson`); returns its columns' names."""
    if fmt == "geojson":
        return _write_geojson(path, layer, batches, gtype, crs, columns)
    if fmt == "csv":
        got = list(batches)
        if got:
            cols = {k: np.concatenate([c[k] for c, _ in got]) for k in got[0][0]}
            batches = [(cols, np.concatenate([g for _, g in got]))]
        else:
            batches = []
    names: list[str] = []
    first = True
    for cols, geom in batches:
        if columns is not None:
            cols = columns(cols)
        if first:
            names = list(cols)
        # a GeoPackage's second layer goes into the file the first made
        append = not first or (fmt == "gpkg" and layer == SWATHS_LAYER)
        _write_layer(path, layer, fmt, cols, _project(geom, crs), gtype, crs, append)
        first = False
    if first:  # nothing: the layer is made empty
        cols = {} if columns is None else columns({})
        append = fmt == "gpkg" and layer == SWATHS_LAYER
        _write_layer(path, layer, fmt, cols, np.empty(0, object), gtype, crs, append)
    return names


def _write_geojson(
    path: Path,
    layer: str,
    batches: Iterable[Batch],
    gtype: str,
    crs: CRS,
    columns: Callable[[dict[str, npt.NDArray[np.generic]]], dict[str, npt.NDArray[np.generic]]]
    | None,
) -> list[str]:
    """GeoJSON a batch at a time in linear time: GDAL appends to a GeoJSON file by reading it
    whole again, so each batch is written to a file of its own and its features (GDAL writes
    one a line) are copied into the output after the first batch's header."""
    names: list[str] = []
    out: TextIO | None = None
    features = 0
    try:
        with tempfile.TemporaryDirectory(prefix="topdress-geojson-") as tmp:
            part = Path(tmp) / "batch.geojson"
            for cols, geom in batches:
                if columns is not None:
                    cols = columns(cols)
                first = out is None
                if out is None:
                    names = list(cols)
                    out = path.open("w", encoding="utf-8")
                _write_layer(part, layer, "geojson", cols, _project(geom, crs), gtype, crs, False)
                features = _copy_features(part, out, first, features)
                part.unlink()
            if out is not None:
                out.write("\n]\n}\n")
    except OSError as exc:
        raise MapError(f"cannot write {path}: {exc}") from exc
    finally:
        if out is not None:
            out.close()
    if out is None:  # nothing: the layer is made empty
        cols = {} if columns is None else columns({})
        _write_layer(path, layer, "geojson", cols, np.empty(0, object), gtype, crs, False)
    return names


def _copy_features(part: Path, out: TextIO, header: bool, n: int) -> int:
    """The features of one batch's file into `out` (with the file's header when `header`);
    returns how many features `out` has now (`n` before)."""
    with part.open(encoding="utf-8") as f:
        for line in f:
            if header:
                out.write(line)
            if line.rstrip("\n") == '"features": [':
                break
        else:
            raise MapError(f"{part}: no features array where GDAL writes it")
        for line in f:
            feature = line.rstrip("\n").rstrip(",")
            if feature == "]":
                break
            out.write(",\n" if n else "")
            out.write(feature)
            n += 1
    return n


def fmis_columns(
    cols: dict[str, npt.NDArray[np.generic]], keep: tuple[str, ...] | None = None
) -> dict[str, npt.NDArray[np.generic]]:
    """A layer's columns as numbers only: the time as UTC seconds, the speed source and the
    zone as codes, other text left out; `keep`: these, in this order."""
    out: dict[str, npt.NDArray[np.generic]] = {}
    for name, col in cols.items():
        if name == "IsoTime":
            ms = np.array([str(v).rstrip("Z") for v in col], dtype="datetime64[ms]")
            out["UnixTime"] = ms.astype(np.int64).astype(float) / 1000.0
        elif name == "SpeedSrc":
            out[name] = np.array([SPEED_SOURCE_CODES.get(str(v), 0) for v in col], np.int32)
        elif name == "Zone":
            out[name] = np.array([ZONE_CODES.get(str(v or ""), 0) for v in col], np.int32)
        elif np.asarray(col).dtype.kind in "biuf":
            out[name] = col
    if keep is not None:
        out = {k: out[k] for k in keep if k in out}
    return out


def _write_fmis(data: Layers, path: Path, crs: str) -> list[Path]:
    target = WGS84 if crs == "wgs84" or data.utm is None else data.utm
    paths = output_paths(path, "shp")
    written: list[Path] = []
    used: list[str] = []

    def points(cols: dict[str, npt.NDArray[np.generic]]) -> dict[str, npt.NDArray[np.generic]]:
        return dict(list(fmis_columns(cols, FMIS_POINTS).items())[:FMIS_MAX_FIELDS])

    def swaths(cols: dict[str, npt.NDArray[np.generic]]) -> dict[str, npt.NDArray[np.generic]]:
        return dict(list(fmis_columns(cols).items())[:FMIS_MAX_FIELDS])

    for layer, batches, columns, gtype in (
        (POINTS_LAYER, data.point_batches(), points, "Point"),
        (SWATHS_LAYER, data.swath_batches(), swaths, "Polygon"),
    ):
        out = paths[layer]
        _remove(out, "shp")
        used += _write_batches(out, layer, "shp", batches, gtype, target, columns)
        written.append(out)
    stem = path.with_suffix("") if path.suffix.lower() == ".shp" else path
    units = stem.with_name(f"{stem.name}_units.txt")
    lines = ["field\tunit\tmeaning"]
    for name in dict.fromkeys(used):
        unit, meaning = FMIS_FIELDS.get(name) or FIELDS[name]
        lines.append(f"{SHAPEFILE_NAMES.get(name, name)}\t{unit}\t{meaning}")
    units.write_text("\n".join(lines) + "\n", encoding="utf-8")
    written.append(units)
    return written


def _remove(path: Path, fmt: str) -> None:
    exts = (".shp", ".shx", ".dbf", ".prj", ".cpg") if fmt == "shp" else (path.suffix,)
    for ext in exts:
        p = path.with_suffix(ext)
        if p.exists():
            p.unlink()


def _project(geom: npt.NDArray[np.object_], crs: CRS) -> npt.NDArray[np.object_]:
    if crs == WGS84 or geom.size == 0:
        return geom
    tr = Transformer.from_crs(WGS84, crs, always_xy=True)
    return np.asarray(shapely.transform(geom, lambda xy: np.column_stack(tr.transform(*xy.T))))


def _write_layer(
    path: Path,
    layer: str,
    fmt: str,
    cols: dict[str, npt.NDArray[np.generic]],
    geom: npt.NDArray[np.object_],
    gtype: str,
    crs: CRS,
    append: bool,
) -> None:
    names = [SHAPEFILE_NAMES.get(n, n) if fmt == "shp" else n for n in cols]
    # Arrow hands GDAL whole columns (several times faster than feature by feature); NaN is
    # written as an empty field.
    table = pa.table(
        {n: pa.array(c, from_pandas=True) for n, c in zip(names, cols.values(), strict=True)}
        | {"geometry": pa.array(shapely.to_wkb(geom).tolist(), type=pa.binary())}
    )
    options: dict[str, str] = {}
    if fmt == "csv":
        options["GEOMETRY"] = "AS_XY" if gtype == "Point" else "AS_WKT"
        options["CREATE_CSVT"] = "YES"
    elif fmt == "geojson":
        options["COORDINATE_PRECISION"] = "8"
    elif fmt == "gpkg":
        options["SPATIAL_INDEX"] = "YES"
    try:
        pyogrio.write_arrow(
            table,
            str(path),
            # a Shapefile's layer is its file: appending to another name writes nothing
            layer=path.stem if fmt == "shp" and append else layer,
            geometry_name="geometry",
            driver=DRIVERS[fmt],
            geometry_type=gtype,
            crs=crs.to_wkt(),
            append=append,
            layer_options=options,
            encoding="UTF-8" if fmt == "shp" else None,
        )
    except (DataSourceError, FieldError, GeometryError, OSError) as exc:
        raise MapError(f"cannot write {path}: {exc}") from exc


def _write_units(path: Path, fmt: str, names: list[str]) -> None:
    with path.open("w", encoding="utf-8", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["field", "name", "unit", "meaning"])
        for name in dict.fromkeys(names):
            unit, meaning = FIELDS[name]
            w.writerow(
                [SHAPEFILE_NAMES.get(name, name) if fmt == "shp" else name, name, unit, meaning]
            )
