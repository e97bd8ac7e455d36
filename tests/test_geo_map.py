"""`topdress log map`: PNG and offline HTML of a simulated session, and the rate classes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from geo_rig import record
from topdress.cli.main import main
from topdress.config import DEFAULT_TOML
from topdress.geo.mapview import rate_classes, rpm_classes
from topdress.log.session import SessionReader
from topdress.log.summary import summarise
from topdress.sim.tractor import Drive, Segment


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return record(
        tmp_path_factory.mktemp("m"), DEFAULT_TOML, Drive.field_passes(2, 30.0, 8.0), 45.0
    )


def test_png_and_offline_html(
    session: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    png, html = tmp_path / "map.png", tmp_path / "map.html"
    assert main(["log", "map", str(session), "--out", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["log", "map", str(session), "--out", str(html), "--classes", "rpm"]) == 0
    text = html.read_text(encoding="utf-8")
    # one file that works offline: Leaflet inlined, nothing fetched, no tile layer
    assert "Leaflet 1.9.4" in text and "L.map(" in text
    assert "<script src" not in text and "<link" not in text and "tileLayer(" not in text
    assert '"unit":"r/min"' in text
    out = capsys.readouterr().out
    assert "stops" in out and "swaths" in out
    assert main(["log", "map", str(session), "--out", str(tmp_path / "map.jpg")]) == 2


def test_rate_classes_cover_the_values_with_a_class_for_nothing_applied() -> None:
    values = np.array([0.0, 0.0, 152.0, 180.0, 199.0, 240.0, 251.0])
    classes = rate_classes(values, n=5)
    assert classes[0].label == "0 kg/ha"
    # the first class holds every value above 0 below its top, also those under its 2nd
    # percentile bound: its label must not say it starts there
    assert classes[1].lo == 1e-9 and classes[1].label == f"<{classes[1].hi:g} kg/ha"
    assert classes[1].lo < 152.0 and classes[-1].hi == float("inf")
    for v in values:
        hits = [c for c in classes if c.lo <= v < c.hi]
        assert len(hits) == 1
        assert (hits[0] is classes[0]) == (v == 0.0)
    assert rpm_classes()[1].label == "0-10 r/min" and rpm_classes()[-1].label == ">40 r/min"


def test_the_map_shows_the_summarys_stops(
    session: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with SessionReader(session) as r:
        stops = [e for e in summarise(r).stops if e.kind == "stop"]
    html = tmp_path / "m.html"
    assert main(["log", "map", str(session), "--out", str(html)]) == 0
    assert f", {len(stops)} stops" in capsys.readouterr().out
    text = html.read_text(encoding="utf-8")
    drawn = json.loads(text.split("const L_DATA = ", 1)[1].split(";\n", 1)[0])["stops"]
    assert len(drawn) == len(stops) >= 1
    for (lon, lat), e in zip(drawn, stops, strict=True):
        assert (lat, lon) == pytest.approx((e.lat, e.lon), abs=1e-7)


def test_the_png_holds_its_legend_and_labels_whole(tmp_path: Path) -> None:
    # a map wider than high (one pass east): the legend beside it used to run off the image
    east = Drive(
        [
            Segment("stop", duration_s=2.0),
            Segment("turn", speed_kmh=3.0, angle_deg=-90.0, radius_m=2.0),
            Segment("straight", speed_kmh=8.0, length_m=60.0),
            Segment("stop", duration_s=3.0),
        ]
    )
    path = record(tmp_path, DEFAULT_TOML, east, 40.0)
    png = tmp_path / "map.png"
    assert main(["log", "map", str(path), "--out", str(png)]) == 0
    import matplotlib.image

    img = matplotlib.image.imread(png)[:, :, :3]
    border = np.concatenate([img[0], img[-1], img[:, 0], img[:, -1]])
    # nothing drawn touches the edge: a cut legend, title or axis label would
    assert np.all(border > 0.99)


def test_a_long_sessions_map_is_thinned_and_covers_the_same_ground(
    session: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import shapely

    from topdress.geo import mapview

    def drawn(name: str) -> dict[str, object]:
        html = tmp_path / name
        assert main(["log", "map", str(session), "--out", str(html)]) == 0
        text = html.read_text(encoding="utf-8")
        data: dict[str, object] = json.loads(text.split("const L_DATA = ", 1)[1].split(";\n")[0])
        return data

    full = drawn("full.html")
    monkeypatch.setattr(mapview, "THIN_FROM_ROWS", 100)  # the session has 450 rows
    thin = drawn("thin.html")
    assert thin["classes"] == full["classes"] and thin["stops"] == full["stops"]
    swaths_full, swaths_thin = full["swaths"], thin["swaths"]
    assert isinstance(swaths_full, list) and isinstance(swaths_thin, list)
    # a pass is a few polygons: 13 against 47 one per class change (the steadier fused speed
    # changes class less often than the 4x this bound had before)
    assert len(swaths_thin) * 3 < len(swaths_full)

    def ground(feats: list[dict[str, object]]) -> float:
        return float(shapely.union_all([shapely.Polygon(f["ring"]) for f in feats]).area)

    assert ground(swaths_thin) == pytest.approx(ground(swaths_full), rel=0.01)
    classes = thin["classes"]
    assert isinstance(classes, list)
    for f in swaths_thin:  # a joined run's dose stays in its class
        c = classes[f["cls"]]
        lo = -np.inf if c["lo"] is None else c["lo"]
        hi = np.inf if c["hi"] is None else c["hi"]
        assert lo - 0.01 <= f["value"] < hi + 0.01
    track_full = shapely.LineString(full["track"])
    track_thin = shapely.LineString(thin["track"])
    assert len(thin["track"]) * 3 < len(full["track"])  # type: ignore[arg-type]
    # both tracks are written rounded to 1e-8 degrees: that rounding may add to the tolerance
    assert shapely.hausdorff_distance(track_full, track_thin) <= mapview.TRACK_TOLERANCE_DEG + 2e-8
