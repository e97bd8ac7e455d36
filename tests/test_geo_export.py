"""As-applied exports of a simulated session, read back by independent readers: GDAL (pyogrio)
for the vector formats, the `isoxml` package and a reader written from the ISO 11783-10 record
layout for the task data, python-can and cantools for the CAN trace."""

from __future__ import annotations

import itertools
import json
import shutil
import sqlite3
import struct
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import can
import numpy as np
import pyogrio
import pyogrio.raw
import pytest
from isoxml.util.isoxml_io import isoxml_from_path

from geo_rig import record
from topdress.cli.main import main
from topdress.config import DEFAULT_TOML
from topdress.ecu import meter_rate_kg_ha
from topdress.geo import vector
from topdress.geo.asapplied import AsAppliedStream, rate_kg_ha
from topdress.log.session import SessionReader
from topdress.log.summary import summarise
from topdress.sim.tractor import Drive

DBC = Path(__file__).parents[1] / "src/topdress/protocol/topdress.dbc"


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two 40 m passes at 8 km/h with a headland turn, outlet 1.5 m behind the antenna."""
    toml = DEFAULT_TOML + "\n"
    toml = toml.replace("outlet_along_m = 0.0", "outlet_along_m = -1.5")
    return record(tmp_path_factory.mktemp("s"), toml, Drive.field_passes(2, 40.0, 8.0), 60.0)


def _summary_kg(path: Path) -> float:
    with SessionReader(path) as r:
        s = summarise(r)
    return s.layers["upper"].applied_kg + s.layers["lower"].applied_kg


def _read(path: Path, layer: str | None = None) -> tuple[dict[str, object], dict[str, np.ndarray]]:
    meta, _, geom, fields = pyogrio.raw.read(path, layer=layer)
    cols = dict(zip(meta["fields"], fields, strict=True))
    return meta, cols | {"__geom__": geom}


@pytest.mark.parametrize("fmt", ["gpkg", "shp", "geojson", "csv"])
def test_every_vector_format_reads_back_in_gdal(session: Path, tmp_path: Path, fmt: str) -> None:
    out = tmp_path / f"field.{fmt}"
    assert main(["log", "export", str(session), "--format", fmt, "--out", str(out)]) == 0
    layers = (
        {"points": (out, "as_applied_points"), "swaths": (out, "as_applied_swaths")}
        if fmt == "gpkg"
        else {k: (tmp_path / f"field_{k}.{fmt}", None) for k in ("points", "swaths")}
    )
    want_kg = _summary_kg(session)
    for kind, (path, layer) in layers.items():
        info = pyogrio.read_info(path, layer=layer)
        meta, cols = _read(path, layer)
        names = list(meta["fields"])
        if fmt == "csv":  # GDAL's CSV: X,Y columns (points) or WKT (swaths), WGS 84 by the docs
            assert ("X" in names and "Y" in names) if kind == "points" else "WKT" in names
            continue
        assert info["crs"] == "EPSG:4326"
        assert info["geometry_type"] == ("Point" if kind == "points" else "Polygon")
        assert info["features"] > (100 if kind == "points" else 60)  # swaths: ~1 m each
        if fmt == "shp":
            assert all(len(n) <= 10 for n in names)
            assert "AppliedRt" in names and "SWATHWIDTH" in names
        else:
            assert "AppliedRate" in names
        # the kg of both layers are the summary's (swaths: also what was metered standing)
        assert float(np.sum(cols["AppliedKg"])) == pytest.approx(want_kg, rel=0.005)
        assert set(np.unique(cols["SWATHWIDTH"])) == {3.6}
    if fmt in ("shp", "geojson"):  # the rate classes' style, on the field QGIS reads
        style = (tmp_path / "field_swaths.qml").read_text()
        assert f'attr="{"AppliedRt" if fmt == "shp" else "AppliedRate"}"' in style
    if fmt in ("shp", "csv"):
        units = (tmp_path / "field_fields.csv").read_text()
        assert "AppliedRt,AppliedRate,kg/ha" in units if fmt == "shp" else "AppliedRate" in units


def test_points_carry_time_heading_rates_and_the_outlet_position(
    session: Path, tmp_path: Path
) -> None:
    out = tmp_path / "a.gpkg"
    assert main(["log", "export", str(session), "--out", str(out)]) == 0
    _, p = _read(out, "as_applied_points")
    assert all(str(s).endswith("Z") and str(s).startswith("20") for s in p["IsoTime"])
    assert set(p["UtcSource"]) == {"gnss"}
    speed = p["SPEED"]
    first_pass = (speed > 7.5) & (p["LogTime"] < 25.0)
    # the first pass runs north: heading near 0 (or 360), the outlet 1.5 m south of the antenna
    h = p["Heading"][first_pass]
    assert np.all(np.minimum(h, 360.0 - h) < 3.0)
    steady = first_pass & (p["RpmUp"] > 0)
    # actual rate from eq. 4 inverted: close to the target in steady work
    assert np.median(np.abs(p["AppliedRate"][steady] - p["TargetRate"][steady])) < 10.0
    assert np.all(p["AppliedRate"][speed < 0.5] == 0.0)  # no rate per area at a standstill
    with SessionReader(session) as r:
        rows = [row for row in r.states() if row.outlet_lat is not None and row.v_kmh > 7.5]
    row = rows[len(rows) // 3]
    assert row.lat is not None and row.outlet_lat < row.lat  # type: ignore[operator]
    dlat_m = (row.lat - row.outlet_lat) * 111_100.0  # type: ignore[operator]
    assert 1.0 < dlat_m < 3.0  # 1.5 m offset + the run since the last fix - the fix's age


def test_utm_option_projects_to_the_fields_zone(session: Path, tmp_path: Path) -> None:
    out = tmp_path / "u.gpkg"
    assert main(["log", "export", str(session), "--out", str(out), "--crs", "utm"]) == 0
    info = pyogrio.read_info(out, layer="as_applied_swaths")
    assert info["crs"] == "EPSG:32651"  # 125.3 deg E, northern hemisphere
    bounds = pyogrio.read_bounds(out, layer="as_applied_swaths")[1]
    assert 100_000 < np.min(bounds[0]) < 900_000 and np.min(bounds[1]) > 4_000_000
    # 2 passes of 40 m at 3.6 m: the swaths cover about that much (plus the turn)
    _, cols = _read(out, "as_applied_swaths")
    assert 0.025 < float(np.sum(cols["AREA"])) < 0.04


def test_isoxml_task_data_reads_back(session: Path, tmp_path: Path) -> None:
    out = tmp_path / "TASKDATA"
    assert main(["log", "export", str(session), "--format", "isoxml", "--out", str(out)]) == 0
    task_data, bins = isoxml_from_path(out)
    task = task_data.tasks[0]
    assert [t.filename for t in task.time_logs] == ["TLG00001"]
    ddis = {int.from_bytes(d.ddi, "big") for d in task_data.devices[0].process_data}
    assert {6, 7, 67, 81, 141, 352, 397, 400} <= ddis
    tim = task.times[0]
    assert (tim.start.offset, tim.stop.offset) == (0, 0)  # UTC, not a local time
    totals = {
        (int.from_bytes(v.process_data_ddi, "big"), v.device_element_id_ref): v.process_data_value
        for v in tim.data_log_values
    }
    kg = _summary_kg(session)
    # DDI 352 in g: the summary's kg to the gram (one gram of rounding per layer); DDI 81 in
    # whole kg, its resolution
    assert totals[(352, "DET2")] + totals[(352, "DET3")] == pytest.approx(kg * 1000.0, abs=2.0)
    assert totals[(81, "DET2")] == round(totals[(352, "DET2")] / 1000.0)
    assert totals[(81, "DET2")] + totals[(81, "DET3")] == pytest.approx(kg, abs=1.0)
    records = _read_tlg(out / "TLG00001.XML", bins["TLG00001"])
    _, pts = _read(_gpkg(session, tmp_path), "as_applied_points")
    assert len(records) == len(pts["IsoTime"])
    lonlat = np.array([[r["east"], r["north"]] for r in records]) * 1e-7
    import shapely

    want = shapely.get_coordinates(shapely.from_wkb(pts["__geom__"]))
    assert np.max(np.abs(lonlat - want)) < 2e-7
    actual_upper = np.array([r[(7, "DET2")] for r in records]) / 100.0  # mg/m2 -> kg/ha
    assert actual_upper == pytest.approx(pts["AppRateUp"], abs=0.01)
    speed = np.array([r[(397, "DET1")] for r in records]) * 0.0036  # mm/s -> km/h
    assert speed == pytest.approx(pts["SPEED"], abs=0.002)
    # DDI 400 as the vector exports code the same points: the default (fused) mode is 4, blended
    codes = {"wheel": 1, "gnss": 3, "fused": 4, "none": 0}
    sources = [r[(400, "DET1")] for r in records]
    assert sources == [codes[str(s)] for s in pts["SpeedSrc"]]
    assert 4 in sources
    assert {r[(141, "DET1")] for r in records} == {0, 1}


def _gpkg(session: Path, tmp_path: Path) -> Path:
    out = tmp_path / "ref.gpkg"
    assert main(["log", "export", str(session), "--out", str(out)]) == 0
    return out


def _read_tlg(header: Path, data: bytes) -> list[dict[object, int]]:
    """ISO 11783-10 binary time log records, from the header's empty attributes (read here,
    independently of the writer)."""
    tim = ET.parse(header).getroot()
    ptn = tim.find("PTN")
    assert ptn is not None
    pos_fields = [
        (name, fmt)
        for key, name, fmt in (
            ("A", "north", "i"),
            ("B", "east", "i"),
            ("C", "up", "i"),
            ("D", "status", "B"),
            ("E", "pdop", "H"),
            ("F", "hdop", "H"),
            ("G", "sats", "B"),
            ("H", "gps_time", "I"),
            ("I", "gps_date", "H"),
        )
        if ptn.get(key) == ""
    ]
    dlvs = [(int(d.get("A", ""), 16), d.get("C")) for d in tim.findall("DLV")]
    out: list[dict[object, int]] = []
    i = 0
    while i < len(data):
        rec: dict[object, int] = {}
        rec["ms"], rec["days"] = struct.unpack_from("<IH", data, i)
        i += 6
        for name, fmt in pos_fields:
            (rec[name],) = struct.unpack_from("<" + fmt, data, i)
            i += struct.calcsize(fmt)
        n = data[i]
        i += 1
        for _ in range(n):
            k, value = struct.unpack_from("<Bi", data, i)
            i += 5
            rec[dlvs[k]] = value
        out.append(rec)
    return out


def test_can_trace_reads_in_python_can_and_cantools(session: Path, tmp_path: Path) -> None:
    log, asc = tmp_path / "bus.log", tmp_path / "bus.asc"
    assert main(["log", "export", str(session), "--can", str(log)]) == 0
    assert main(["log", "export", str(session), "--can", str(asc)]) == 0
    with SessionReader(session) as r:
        counts = r.raw_counts()
    n = counts["can_rx"] + counts["can_tx"]
    for path in (log, asc):
        msgs = list(can.LogReader(path))
        assert len(msgs) == n
        assert {m.arbitration_id for m in msgs} >= {0x185C6465, 0x0A5C6465}
        # candump: UTC time stamps; asc: relative to its header's UTC start
        assert msgs[0].timestamp > 1.5e9 if path == log else msgs[0].timestamp == 0.0
        assert all(b.timestamp >= a.timestamp for a, b in itertools.pairwise(msgs))
    decoded = subprocess.run(
        [sys.executable, "-m", "cantools", "decode", "--single-line", str(DBC)],
        stdin=log.open(),
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert decoded.count("EcuStatus(") == sum(
        1 for m in can.LogReader(log) if m.arbitration_id == 0x185C6465
    )
    played = subprocess.run(
        [
            sys.executable,
            "-m",
            "can.player",
            "-i",
            "virtual",
            "-c",
            "play",
            "--ignore-timestamps",
            "-g",
            "0",
            "-v",
            str(log),
        ],
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    ).stdout
    assert played.count("ID: 185c6465") == decoded.count("EcuStatus(")


def test_the_asc_header_is_the_sessions_utc_in_any_time_zone(
    session: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    log, asc = tmp_path / "bus.log", tmp_path / "bus.asc"
    assert main(["log", "export", str(session), "--can", str(log)]) == 0
    first = next(iter(can.LogReader(log))).timestamp  # candump: UTC seconds
    want = datetime.fromtimestamp(first, UTC)
    stamp = want.strftime("%a %b %d %H:%M:%S.") + f"{want.microsecond // 1000:03d} {want.year}"
    monkeypatch.setenv("TZ", "Asia/Shanghai")  # UTC+8: a local time would read 8 h later
    time.tzset()
    try:
        assert main(["log", "export", str(session), "--can", str(asc)]) == 0
    finally:
        monkeypatch.undo()
        time.tzset()
    head = asc.read_text().splitlines()[:4]
    # the file's date and its trigger block: the session's first frame, not the export's day
    assert head[0] == f"date {stamp}" and head[3] == f"Begin Triggerblock {stamp}"


def test_a_trace_of_another_format_is_refused_naming_the_users_path(
    session: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    blf, csv = tmp_path / "bus.blf", tmp_path / "state.csv"
    assert main(["log", "export", str(session), "--csv", str(csv), "--can", str(blf)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"topdress: error: {blf}: a CAN trace is .log (candump) or .asc")
    assert ".tmp" not in err and not blf.exists() and not csv.exists()  # nothing half done


def test_a_session_without_the_added_columns_still_exports(session: Path, tmp_path: Path) -> None:
    old = tmp_path / "old.sqlite"
    shutil.copy(session, old)
    with sqlite3.connect(old) as conn:
        for col in (
            "utc",
            "utc_source",
            "heading_deg",
            "outlet_lat",
            "outlet_lon",
            "zone",
            "prescription_kg_ha",
        ):
            conn.execute(f"ALTER TABLE state DROP COLUMN {col}")
    out = tmp_path / "old.gpkg"
    assert main(["log", "export", str(old), "--out", str(out)]) == 0
    _, p = _read(out, "as_applied_points")
    assert set(p["UtcSource"]) == {"created"}
    assert float(np.sum(p["AppliedKg"])) == pytest.approx(_summary_kg(session), rel=0.005)
    moving = p["SPEED"] > 7.5
    assert np.nanmedian(np.abs(p["Heading"][moving & (p["LogTime"] < 20)])) < 5.0


def test_no_position_at_all_is_a_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from topdress.log.rows import state_row
    from topdress.log.session import SessionLog
    from topdress.view.snapshot import Snapshot

    with SessionLog.create(tmp_path, "") as log:
        for i in range(5):
            log.state(state_row(i * 0.1, Snapshot()))
    assert main(["log", "export", str(log.path), "--out", str(tmp_path / "x.gpkg")]) == 2
    assert "no state row has a position" in capsys.readouterr().err


def test_eq4_inverted_over_columns_is_the_c_function() -> None:
    rng = np.random.default_rng(1)
    rpm = rng.uniform(0, 80, 200)
    v = rng.uniform(0, 14, 200)
    got = rate_kg_ha(rpm, v, 3.6, 0.3, 0.5)
    want = [meter_rate_kg_ha(3.6, r, s, 0.3, 0.5) for r, s in zip(rpm, v, strict=True)]
    assert got == pytest.approx(want, rel=1e-5, abs=1e-6)


def test_the_fmis_shapefile_has_numeric_attributes_only(session: Path, tmp_path: Path) -> None:
    out = tmp_path / "f.shp"
    args = ["log", "export", str(session), "--format", "shp", "--fmis", "--out", str(out)]
    assert main(args) == 0
    units = dict(
        line.split("\t")[:2] for line in (tmp_path / "f_units.txt").read_text().splitlines()[1:]
    )
    for layer in ("f_points.shp", "f_swaths.shp"):
        info = pyogrio.read_info(tmp_path / layer)
        names = list(info["fields"])
        assert len(names) <= 20 and all(len(n) <= 10 for n in names)
        assert all(t in ("float64", "int32", "int64") for t in info["dtypes"])
        assert set(names) <= set(units)  # every field's unit beside it
    assert units["AppliedRt"] == "kg/ha" and units["UnixTime"] == "s"
    _, full = _read(_gpkg(session, tmp_path), "as_applied_points")
    meta, _, _, fields = pyogrio.raw.read(tmp_path / "f_points.shp")
    cols = dict(zip(meta["fields"], fields, strict=True))
    iso = np.array([s.rstrip("Z") for s in full["IsoTime"]], dtype="datetime64[ms]")
    assert cols["UnixTime"] == pytest.approx(iso.astype(np.int64) / 1000.0, abs=1e-3)
    assert cols["AppliedRt"] == pytest.approx(full["AppliedRate"])
    codes = {"wheel": 1, "gnss": 3, "fused": 4, "none": 0}
    assert list(cols["SpeedSrc"]) == [codes[s] for s in full["SpeedSrc"]]
    assert main([*args[:-2], "--format", "gpkg", "--out", str(tmp_path / "x.gpkg")]) == 2


def test_geojson_in_many_batches_is_one_collection_as_written_at_once(
    session: Path, tmp_path: Path
) -> None:
    """GeoJSON's batches are stitched into one FeatureCollection (GDAL's own append reads the
    whole file again at each batch): the same features, in order, as one batch gives."""
    layers: dict[str, dict[str, Any]] = {}
    for label, chunk, batch in (("one", 1_000_000, 1_000_000), ("many", 7, 3)):
        with SessionReader(session) as reader:
            written = vector.write(
                AsAppliedStream(reader, chunk, batch), tmp_path / f"{label}.geojson", "geojson"
            )
        assert [p.name for p in written] == [
            f"{label}_points.geojson",
            f"{label}_swaths.geojson",
            f"{label}_swaths.qml",
        ]
        layers[label] = {p.stem.split("_")[1]: json.loads(p.read_text()) for p in written[:2]}
    for kind in ("points", "swaths"):
        one, many = layers["one"][kind], layers["many"][kind]
        assert many["type"] == "FeatureCollection" and many["crs"] == one["crs"]
        assert len(many["features"]) == len(one["features"]) > 60
        assert many["features"] == one["features"]
        _, cols = _read(tmp_path / f"many_{kind}.geojson")
        assert len(cols["__geom__"]) == len(one["features"])
