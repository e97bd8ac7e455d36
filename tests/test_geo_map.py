"""`topdress log map`: PNG and offline HTML of a simulated session, and the rate classes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from geo_rig import record
from topdress.cli.main import main
from topdress.config import DEFAULT_TOML
from topdress.geo.mapview import rate_classes, rpm_classes
from topdress.sim.tractor import Drive


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
    assert classes[1].lo < 152.0 and classes[-1].hi == float("inf")
    for v in values:
        hits = [c for c in classes if c.lo <= v < c.hi]
        assert len(hits) == 1
        assert (hits[0] is classes[0]) == (v == 0.0)
    assert rpm_classes()[1].label == "0-10 r/min" and rpm_classes()[-1].label == ">40 r/min"
