"""The as-applied swaths: built from the machine's smoothed path while product is applied, they
add up to the session summary, lie only where product went, and every export format holds
them as clean polygons."""

from __future__ import annotations

import json
import math
import struct
from pathlib import Path

import numpy as np
import pyogrio.raw
import pytest
import shapely
import shapely.affinity
from pyproj import Transformer

from geo_rig import record
from topdress.cli.main import main
from topdress.config import DEFAULT_TOML
from topdress.geo import asapplied
from topdress.geo.asapplied import smooth_path
from topdress.log.session import SessionReader
from topdress.log.summary import summarise
from topdress.sim.tractor import Drive

UTM = "EPSG:32651"  # the simulator's field, 125.3 deg E


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The start, three 30 m passes at 8 km/h, a stop and a headland turn between them, the
    outlet 1.5 m behind the antenna."""
    toml = DEFAULT_TOML.replace("outlet_along_m = 0.0", "outlet_along_m = -1.5")
    return record(tmp_path_factory.mktemp("s"), toml, Drive.field_passes(3, 30.0, 8.0), 75.0)


def _swaths(path: Path, layer: str | None = None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    meta, _, wkb, fields = pyogrio.raw.read(path, layer=layer)
    return shapely.from_wkb(wkb), dict(zip(meta["fields"], fields, strict=True))


def _utm(geoms: np.ndarray) -> np.ndarray:
    tr = Transformer.from_crs("EPSG:4326", UTM, always_xy=True)
    return np.asarray(shapely.transform(geoms, lambda xy: np.column_stack(tr.transform(*xy.T))))


def test_swath_area_and_dose_add_up_to_the_summary(session: Path, tmp_path: Path) -> None:
    out = tmp_path / "f.gpkg"
    assert main(["log", "export", str(session), "--out", str(out)]) == 0
    geoms, c = _swaths(out, "as_applied_swaths")
    with SessionReader(session) as r:
        s = summarise(r)
    kg = s.layers["upper"].applied_kg + s.layers["lower"].applied_kg
    assert s.area_ha > 0.02 and len(s.stops) >= 2  # the session has its stops and turns
    assert float(np.sum(c["AREA"])) == pytest.approx(s.area_ha, rel=0.01)
    dose = float(np.sum(c["AppliedKg"]) / np.sum(c["AREA"]))
    assert dose == pytest.approx(kg / s.area_ha, rel=0.01)
    assert float(np.sum(c["DISTANCE"])) == pytest.approx(s.metering_distance_m, rel=0.01)
    # each swath's rate is its dose: the kg on it over its area
    assert c["AppliedRate"] == pytest.approx(c["AppliedKg"] / c["AREA"], rel=1e-6)
    # nothing drawn where nothing was applied, nor while standing
    assert np.all(c["AppliedKg"] > 0) and np.all(c["AppliedRate"] > 0)
    assert np.all(c["DISTANCE"] >= 0.25) and np.all(c["SPEED"] > 0.0)
    # the polygons are the area they stand for (turns included)
    poly_m2 = shapely.area(_utm(geoms))
    assert float(np.sum(poly_m2)) == pytest.approx(float(np.sum(c["AREA"])) * 1e4, rel=0.03)
    assert np.all(poly_m2 > 0.5 * c["AREA"] * 1e4)
    # passes side by side (the turn's radius is half the width): little ground covered twice
    union_m2 = shapely.union_all(_utm(geoms)).area
    assert union_m2 > 0.9 * float(np.sum(poly_m2))


def test_swaths_run_forward_from_the_start(session: Path, tmp_path: Path) -> None:
    out = tmp_path / "f.gpkg"
    assert main(["log", "export", str(session), "--out", str(out)]) == 0
    _, c = _swaths(out, "as_applied_swaths")
    order = np.argsort(c["LogTime"])
    heading, speed = c["Heading"][order], c["SPEED"][order]
    # the first pass runs north from the start: no swath of it points elsewhere
    at_speed = int(np.argmax(speed > 6.5))
    first_pass = np.arange(speed.size) < at_speed + int(np.argmax(speed[at_speed:] < 5.0))
    assert first_pass.sum() > 10
    assert np.all(np.minimum(heading[first_pass], 360.0 - heading[first_pass]) < 10.0)
    # on every pass at work speed the swaths follow the pass (north or south)
    fast = speed > 6.5
    off = np.minimum(np.abs(heading[fast] - 180.0), np.minimum(heading[fast], 360 - heading[fast]))
    assert np.all(off < 10.0)


@pytest.mark.parametrize("fmt", ["gpkg", "shp", "geojson", "csv", "isoxml"])
def test_every_format_has_no_empty_or_degenerate_geometry(
    session: Path, tmp_path: Path, fmt: str
) -> None:
    out = tmp_path / ("TASKDATA" if fmt == "isoxml" else f"f.{fmt}")
    assert main(["log", "export", str(session), "--format", fmt, "--out", str(out)]) == 0
    if fmt == "isoxml":
        _check_time_log(out / "TLG00001.BIN")
        return
    if fmt == "gpkg":
        layers = [(out, "as_applied_points"), (out, "as_applied_swaths")]
    else:
        layers = [(tmp_path / f"f_{k}.{fmt}", None) for k in ("points", "swaths")]
    for path, layer in layers:
        if fmt == "csv":
            geoms = _csv_geoms(path)
        else:
            geoms, _ = _swaths(path, layer)
        assert geoms.size > 50
        assert not np.any(shapely.is_empty(geoms)) and np.all(shapely.is_valid(geoms))
        assert np.all(np.isfinite(shapely.get_coordinates(geoms)))
        if "swaths" in path.name or layer == "as_applied_swaths":
            assert set(shapely.get_type_id(geoms)) == {3}  # Polygon
            assert np.all(shapely.area(_utm(geoms)) > 0.5)  # m²: at least 0.25 m x 3.6 m / 2
    if fmt == "geojson":  # RFC 7946 3.1.6: exterior rings counter-clockwise
        doc = json.loads((tmp_path / "f_swaths.geojson").read_text())
        for feat in doc["features"]:
            ring = np.array(feat["geometry"]["coordinates"][0])
            assert len(ring) >= 4
            x, y = ring[:, 0], ring[:, 1]
            assert np.sum(x[:-1] * y[1:] - x[1:] * y[:-1]) > 0


def _csv_geoms(path: Path) -> np.ndarray:
    import csv

    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    if "WKT" in rows[0]:
        return np.asarray(shapely.from_wkt([r["WKT"] for r in rows]))
    return np.asarray(shapely.points([float(r["X"]) for r in rows], [float(r["Y"]) for r in rows]))


def _check_time_log(path: Path) -> None:
    """Every record of the binary time log has a position on the field (its layout: time,
    PTN A/B/D, 8 data log values; docs/maps.md)."""
    rec = struct.Struct("<IHiiBB" + "Bi" * 8)
    data = path.read_bytes()
    assert len(data) % rec.size == 0 and len(data) // rec.size > 50
    for fields in rec.iter_unpack(data):
        north, east = fields[2] * 1e-7, fields[3] * 1e-7
        assert 43.8 < north < 44.0 and 125.2 < east < 125.4


def test_ground_covered_twice_is_flagged(tmp_path: Path) -> None:
    # passes 2 m apart with a 3.6 m width: each later pass covers (3.6 - 2) / 3.6 = 44 % of
    # its ground a second time
    drive = Drive.field_passes(2, 25.0, 8.0, width_m=2.0)
    path = record(tmp_path, DEFAULT_TOML, drive, 45.0)
    out = tmp_path / "o.gpkg"
    assert main(["log", "export", str(path), "--out", str(out)]) == 0
    _, c = _swaths(out, "as_applied_swaths")
    order = np.argsort(c["LogTime"])
    overlap, speed = c["Overlap"][order], c["SPEED"][order]
    at_speed = int(np.argmax(speed > 6.5))
    end_first = at_speed + int(np.argmax(speed[at_speed:] < 5.0))
    first = np.arange(speed.size) < end_first
    second = (np.arange(speed.size) > end_first) & (speed > 7.0)
    assert np.median(overlap[first]) == pytest.approx(0.0, abs=0.5)
    assert np.median(overlap[second]) == pytest.approx(44.4, abs=12.0)


def test_smoothed_path_takes_the_jitter_out_of_the_distance() -> None:
    # 60 m north at 8 km/h in 0.1 s rows, positions with 10 cm of jitter: the raw track is
    # longer than the way driven; the smoothed one is the way driven
    rng = np.random.default_rng(3)
    n = 270
    step = np.full(n, 8.0 / 3.6 * 0.1)
    true_y = np.concatenate([[0.0], np.cumsum(step[:-1])])
    x = rng.normal(0.0, 0.1, n)
    y = true_y + rng.normal(0.0, 0.1, n)
    link = np.ones(n, dtype=bool)
    link[-1] = False
    sx, sy = smooth_path(x, y, step, np.zeros(n), link)
    raw = float(np.sum(np.hypot(np.diff(x), np.diff(y))))
    smooth = float(np.sum(np.hypot(np.diff(sx), np.diff(sy))))
    driven = float(np.sum(step[:-1]))
    assert raw > 1.15 * driven
    assert smooth == pytest.approx(driven, rel=0.01)
    assert float(np.max(np.abs(sy - true_y))) < 0.15  # not dragged off the positions


def test_overlap_from_tiles_equals_the_union_of_every_earlier_swath() -> None:
    # Swaths 1 m x 3.6 m at random places and angles over 50 m (across several cover tiles),
    # some driven again; the reference is the plain formulation: each swath against the union
    # of every earlier one.
    rng = np.random.default_rng(3)
    geoms = []
    for _ in range(150):
        x, y, a = rng.uniform(0.0, 50.0), rng.uniform(0.0, 50.0), rng.uniform(0.0, math.pi)
        rect = shapely.box(-0.5, -1.8, 0.5, 1.8)
        geoms.append(
            shapely.affinity.translate(shapely.affinity.rotate(rect, a, use_radians=True), x, y)
        )
    geoms += geoms[:50]  # the same ground again: fully covered
    g = np.array(geoms, dtype=object)
    got = asapplied._overlap_pct(g)
    want = np.zeros(g.size)
    for k in range(1, g.size):
        earlier = shapely.union_all(g[:k])
        want[k] = 100.0 * shapely.area(shapely.intersection(g[k], earlier)) / shapely.area(g[k])
    assert got[150:] == pytest.approx(np.full(50, 100.0), abs=1e-9)
    assert got == pytest.approx(want, abs=1e-9)
    assert (got[:150] > 1.0).sum() > 20  # the random swaths do overlap


def _same(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> None:
    assert list(a) == list(b)
    for name in a:
        x, y = np.asarray(a[name]), np.asarray(b[name])
        if x.dtype.kind == "f":
            assert np.array_equal(x, y, equal_nan=True), name
        else:
            assert np.array_equal(x, y), name


def test_streamed_in_small_chunks_is_the_whole_session(session: Path) -> None:
    # Chunks of 37 state rows and batches of 3 runs: swaths cross chunk edges, the path's
    # smoothing, the runs, the rows metered standing and the covered ground carry over.
    with SessionReader(session) as r:
        whole = asapplied.build(r, chunk_rows=10**9, swath_batch=10**9)
        small = asapplied.build(r, chunk_rows=37, swath_batch=3)
        stream = asapplied.AsAppliedStream(r, chunk_rows=37, swath_batch=3)
        points = [g.size for _, g in stream.point_batches()]
        swaths = [g.size for _, g in stream.swath_batches()]
    assert whole.swath_geom.size > 60 and whole.notes == small.notes
    _same(whole.points, small.points)
    _same(whole.swaths, small.swaths)
    assert float(np.sum(small.swaths["Overlap"])) > 0  # the turns overlap the passes
    for a, b in ((whole.point_geom, small.point_geom), (whole.swath_geom, small.swath_geom)):
        xy_a, xy_b = shapely.get_coordinates(a), shapely.get_coordinates(b)
        assert xy_a.shape == xy_b.shape and np.max(np.abs(xy_a - xy_b)) <= 1e-9
    # bounded: no batch holds more than its chunk, and every feature comes once
    assert max(points) <= 37 and len(points) >= 20 and sum(points) == whole.point_geom.size
    assert max(swaths) <= 3 and sum(swaths) == whole.swath_geom.size
    assert stream.points == sum(points) and stream.swaths == sum(swaths)
    assert stream.applied_kg == pytest.approx(whole.applied_kg, rel=1e-12)
    with SessionReader(session) as r, pytest.raises(ValueError, match="at least 1"):
        asapplied.AsAppliedStream(r, chunk_rows=0)


@pytest.mark.parametrize("fmt", ["gpkg", "shp", "geojson"])
def test_files_appended_batch_by_batch_are_those_written_at_once(
    session: Path, tmp_path: Path, fmt: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    def export(name: str) -> dict[str, tuple[np.ndarray, dict[str, np.ndarray]]]:
        out = tmp_path / name / f"f.{fmt}"
        out.parent.mkdir()
        assert main(["log", "export", str(session), "--out", str(out), "--format", fmt]) == 0
        layers = {"points": "as_applied_points", "swaths": "as_applied_swaths"}
        if fmt == "gpkg":
            return {k: _swaths(out, layer) for k, layer in layers.items()}
        return {k: _swaths(out.with_name(f"f_{k}.{fmt}")) for k in layers}

    once = export("once")
    monkeypatch.setattr(asapplied, "CHUNK_ROWS", 50)
    monkeypatch.setattr(asapplied, "SWATH_BATCH", 4)
    batched = export("batched")
    for kind in ("points", "swaths"):
        (g1, c1), (g2, c2) = once[kind], batched[kind]
        assert g1.size == g2.size > 60
        _same(c1, c2)
        assert np.array_equal(shapely.get_coordinates(g1), shapely.get_coordinates(g2))


def test_the_smoother_solved_in_blocks_is_solved_whole(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(5)
    n = 1000
    x = np.cumsum(rng.uniform(0.0, 0.3, n)) + rng.normal(0.0, 0.3, n)
    y = rng.normal(0.0, 0.3, n)
    x[400:410] = np.nan  # no position
    heading = np.full(n, 90.0) + rng.normal(0.0, 2.0, n)
    heading[:5] = np.nan  # not known before the machine moves
    link = np.ones(n, dtype=bool)
    link[-1] = link[399:410] = False
    step = rng.uniform(0.0, 0.3, n)
    whole = smooth_path(x, y, step, heading, link)
    monkeypatch.setattr(asapplied, "_BLOCK", 7)
    blocks = smooth_path(x, y, step, heading, link)
    for a, b in zip(whole, blocks, strict=True):
        assert np.array_equal(a, b, equal_nan=True)
    assert np.isnan(whole[0][400]) and np.isfinite(whole[0]).sum() == n - 10
