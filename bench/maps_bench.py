"""Maps benchmark: GeoPackage export time per hour of log, prescription lookup time, the load
time of a prescription of a million polygons.

    .venv/bin/python bench/maps_bench.py

- export: a 1 h session at 10 Hz (36,000 state rows: 8 km/h passes of 400 m across a field,
  positions, heading, UTC, meter speeds) is written to a session log, then exported with
  as `topdress log export SESSION --out X.gpkg` does after start-up (read the log, build the
  as-applied points and swaths, GDAL write), best of 3. Target: at most 3 s per hour of log.
- lookup: a prescription of 5,000 polygons (a 100 x 50 grid of 10 m zones, each a 12-sided
  ring, written as a GeoPackage and loaded as the terminal loads it) is queried at 20,000
  random positions, each lookup timed alone. Target: p99 at most 200 us.
- load: a prescription of 1,000,000 rectangles (5 m zones, a rate and a text attribute each,
  a GeoPackage) loaded as the terminal loads it: read, checked, projected, indexed. Target:
  under 5 s.

The machine is shared: the figures compared with the targets are CPU time (the process's for
the export, the thread's for each lookup), which a busy neighbour does not inflate; the wall
times are printed beside them.

Prints:
    export_gpkg_s_per_log_hour: X         (CPU s)
    export_gpkg_wall_s_per_log_hour: X
    prescription_lookup_us_p50: X         (CPU us)
    prescription_lookup_us_p99: X
    prescription_lookup_wall_us_p99: X
    prescription_load_1e6_s: X            (CPU s)
    prescription_load_1e6_wall_s: X
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import numpy as np
import pyogrio.raw
import shapely

from topdress.config import PrescriptionConfig
from topdress.geo.export import export_maps
from topdress.geo.outlet import offset_position
from topdress.geo.prescription import load_prescription
from topdress.log.model import StateRow
from topdress.log.session import SessionLog, SessionReader

LAT0, LON0 = 43.8853, 125.3245
ROWS = 36_000  # 1 h at 10 Hz


def write_hour(directory: Path) -> Path:
    """Back-and-forth passes of 400 m at 8 km/h, 3.6 m apart, a 5 s stop at each end."""
    v_ms = 8.0 / 3.6
    pass_s = 400.0 / v_ms
    cycle = pass_s + 5.0
    with SessionLog.create(directory, "", queue_size=ROWS + 10) as log:
        for i in range(ROWS):
            t = i * 0.1
            n, into = divmod(t, cycle)
            moving = into < pass_s
            along = min(into, pass_s) * v_ms
            heading = 0.0 if int(n) % 2 == 0 else 180.0
            y = along if heading == 0.0 else 400.0 - along
            lat, lon = offset_position(LAT0, LON0, 90.0, n * 3.6, 0.0)
            lat, lon = offset_position(lat, lon, 0.0, y, 0.0)
            v = 8.0 if moving else 0.0
            rpm = 20.0 + 5.0 * math.sin(t / 30.0) if moving else 0.0
            log.state(
                StateRow(
                    t, lat, lon, v, v, v, "gnss", 1.0, 0.6, 120.0, 120.0,
                    rpm, rpm, rpm * 1.01, rpm * 0.99, 3000.0, 3000.0, 0,
                    utc=1.78e9 + t, utc_source="gnss", heading_deg=heading,
                    outlet_lat=lat, outlet_lon=lon,
                )
            )  # fmt: skip
    return log.path


def bench_export(tmp: Path) -> tuple[float, float]:
    """What `log export --out X.gpkg` does after start-up: read, build, write. CPU and wall
    seconds, best of 3 (the machine is shared)."""
    session = write_hour(tmp)
    cpu = wall = math.inf
    for n in range(3):
        t0, c0 = time.perf_counter(), time.process_time()
        with SessionReader(session) as reader:
            export_maps(reader, tmp / f"hour{n}.gpkg", "gpkg", "wgs84", None)
        cpu = min(cpu, time.process_time() - c0)
        wall = min(wall, time.perf_counter() - t0)
    return cpu, wall


def write_zones(path: Path) -> None:
    geoms, rates = [], []
    cell = 10.0 / 111_000.0
    for i in range(100):
        for j in range(50):
            cx, cy = LON0 + (i + 0.5) * cell * 1.4, LAT0 + (j + 0.5) * cell
            ring = [
                (cx + 0.7 * cell * math.cos(a), cy + 0.5 * cell * math.sin(a))
                for a in np.linspace(0, 2 * math.pi, 12, endpoint=False)
            ]
            geoms.append(shapely.Polygon(ring))
            rates.append(100.0 + (i * 7 + j * 3) % 200)
    pyogrio.raw.write(
        str(path),
        shapely.to_wkb(np.array(geoms, dtype=object)),
        [np.array(rates)],
        ["rate"],
        geometry_type="Polygon",
        crs="EPSG:4326",
    )


def bench_lookup(tmp: Path) -> tuple[np.ndarray, np.ndarray]:
    path = tmp / "zones.gpkg"
    write_zones(path)
    rx = load_prescription(PrescriptionConfig(path=str(path)))
    rng = np.random.default_rng(7)
    cell = 10.0 / 111_000.0
    lats = LAT0 + rng.uniform(-2, 52, 20_000) * cell
    lons = LON0 + rng.uniform(-2, 142, 20_000) * cell
    cpu, wall = np.empty(lats.size), np.empty(lats.size)
    hits = 0
    for k in range(lats.size):
        w0, c0 = time.perf_counter_ns(), time.thread_time_ns()
        z = rx.lookup(float(lats[k]), float(lons[k]))
        cpu[k] = (time.thread_time_ns() - c0) / 1000.0
        wall[k] = (time.perf_counter_ns() - w0) / 1000.0
        hits += z is not None
    assert hits > lats.size // 2, hits
    return cpu, wall


def write_million(path: Path, n: int = 1_000_000) -> None:
    side = math.ceil(math.sqrt(n))
    cell = 5.0 / 111_000.0
    i = np.arange(n)
    x0 = LON0 + (i % side) * cell * 1.4
    y0 = LAT0 + (i // side) * cell
    pyogrio.raw.write(
        str(path),
        shapely.to_wkb(shapely.box(x0, y0, x0 + cell * 1.4, y0 + cell)),
        [100.0 + (i % 200).astype(float), np.full(n, "zone", dtype=object)],
        ["rate", "name"],
        geometry_type="Polygon",
        crs="EPSG:4326",
    )


def bench_load(tmp: Path) -> tuple[float, float]:
    path = tmp / "million.gpkg"
    write_million(path)
    t0, c0 = time.perf_counter(), time.process_time()
    rx = load_prescription(PrescriptionConfig(path=str(path)))
    cpu, wall = time.process_time() - c0, time.perf_counter() - t0
    assert rx.lookup(LAT0 + 1e-5, LON0 + 1e-5) is not None
    return cpu, wall


def main_bench() -> None:
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        export_cpu, export_wall = bench_export(tmp)
        cpu, wall = bench_lookup(tmp)
        load_cpu, load_wall = bench_load(tmp)
    print(f"export_gpkg_s_per_log_hour: {export_cpu:.2f}")
    print(f"export_gpkg_wall_s_per_log_hour: {export_wall:.2f}")
    print(f"prescription_lookup_us_p50: {np.percentile(cpu, 50):.1f}")
    print(f"prescription_lookup_us_p99: {np.percentile(cpu, 99):.1f}")
    print(f"prescription_lookup_wall_us_p99: {np.percentile(wall, 99):.1f}")
    print(f"prescription_load_1e6_s: {load_cpu:.2f}")
    print(f"prescription_load_1e6_wall_s: {load_wall:.2f}")


if __name__ == "__main__":
    main_bench()
