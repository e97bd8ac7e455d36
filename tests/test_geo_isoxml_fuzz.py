"""Broken ISOXML prescriptions and boundaries: every mutation of the TASKDATA.XML attributes
and of the grid binary is loaded, or refused with a MapError naming the file; never another
exception (a traceback in the cab)."""

from __future__ import annotations

import random
import re
from pathlib import Path

import numpy as np
import pytest

from geo_rig import latlon
from test_geo_prescription import ZONES, _iso_grid
from topdress.config import BoundaryConfig, PrescriptionConfig
from topdress.errors import MapError
from topdress.geo.boundary import load_boundary
from topdress.geo.prescription import load_prescription

VALUES = [
    "ZZZZ", "x", "", "-1", "0", "1e999", "nan", "inf", "-inf", "1" * 400, "0x10", " 6",
    "6 ", "٣", "1.5", "-0", "99999999999999999999", "256", "-2147483649", "\x00", "A", "0006",
    "FFFF", "1e-320", "2", "3", "+1", "1_0",
]  # fmt: skip


def _mutations(xml: str, rng: random.Random, n: int) -> list[str]:
    attrs = [m.span(1) for m in re.finditer(r'="([^"]*)"', xml)]
    out = []
    for _ in range(n):
        text = xml
        for a, b in sorted(rng.sample(attrs, rng.randint(1, 3)), reverse=True):
            value = rng.choice(VALUES)
            text = text[:a] + value.replace('"', "&quot;") + text[b:]
        out.append(text)
    return out


def _load(path: Path, mode: str) -> None:
    try:
        load_prescription(PrescriptionConfig(path=str(path), mode=mode))
    except MapError as exc:
        assert "TASKDATA.XML" in str(exc) or "GRD00001" in str(exc), exc


@pytest.mark.parametrize("gtype", [1, 2])
def test_mutated_taskdata_attributes_are_loaded_or_refused_clearly(
    tmp_path: Path, gtype: int
) -> None:
    rng = random.Random(23 + gtype)
    if gtype == 1:
        codes = np.array([[1, 1, 1, 1], [1, 1, 2, 2], [2, 2, 2, 2], [0, 0, 0, 0], [1, 2, 0, 1]])
        path = _iso_grid(tmp_path, 1, codes.astype(np.uint8).tobytes(), ZONES)
    else:
        rates = (np.arange(40).reshape(5, 4, 2) * 1000 + 5000).astype("<i4")
        zone = '<TZN A="3" B="v"><PDV A="0006" B="0"/><PDV A="000A" B="0"/></TZN>'
        path = _iso_grid(tmp_path, 2, rates.tobytes(), zone, ' J="3"')
    xml = path.read_text()
    for text in _mutations(xml, rng, 600):
        path.write_text(text)
        _load(path, rng.choice(["alone", "bound"]))


@pytest.mark.parametrize("gtype", [1, 2])
def test_mutated_grid_binaries_are_loaded_or_refused_clearly(tmp_path: Path, gtype: int) -> None:
    rng = random.Random(5 + gtype)
    if gtype == 1:
        body = np.array([[1, 1, 2, 2]] * 5, dtype=np.uint8).tobytes()
        path = _iso_grid(tmp_path, 1, body, ZONES)
    else:
        body = (np.arange(20).reshape(5, 4) * 1000 + 5000).astype("<i4").tobytes()
        path = _iso_grid(
            tmp_path, 2, body, '<TZN A="3" B="v"><PDV A="0006" B="0"/></TZN>', ' J="3"'
        )
    grid = tmp_path / "GRD00001.BIN"
    loaded = 0
    for _ in range(400):
        data = bytearray(body)
        kind = rng.randrange(4)
        if kind == 0:
            del data[rng.randrange(len(data)) :]
        elif kind == 1:
            data += bytes(rng.randrange(256) for _ in range(rng.randint(1, 9)))
        else:
            for _ in range(rng.randint(1, 6)):
                data[rng.randrange(len(data))] = rng.randrange(256)
        grid.write_bytes(bytes(data))
        try:
            rx = load_prescription(PrescriptionConfig(path=str(path)))
        except MapError as exc:
            assert "GRD00001" in str(exc) or "TASKDATA.XML" in str(exc), exc
            continue
        loaded += 1
        zone = rx.lookup(*latlon(-15, -5))
        assert zone is None or 0.0 <= zone.rate_kg_ha <= 1200.0
    assert loaded > 2  # the bytes cut or added are refused; some flips still load


def test_mutated_partfield_boundaries_are_loaded_or_refused_clearly(tmp_path: Path) -> None:
    ring = [latlon(x, y) for x, y in ((-50, -50), (50, -50), (50, 50), (-50, 50))]
    pnts = "".join(f'<PNT A="2" C="{la!r}" D="{lo!r}"/>' for la, lo in ring)
    hole = [latlon(x, y) for x, y in ((-5, -5), (5, -5), (5, 5), (-5, 5))]
    hpnts = "".join(f'<PNT A="2" C="{la!r}" D="{lo!r}"/>' for la, lo in hole)
    xml = (
        '<ISO11783_TaskData VersionMajor="4" VersionMinor="3" DataTransferOrigin="1">'
        f'<PFD A="PFD1" C="north field" D="10000"><PLN A="1"><LSG A="1">{pnts}</LSG>'
        f'<LSG A="2">{hpnts}</LSG></PLN></PFD></ISO11783_TaskData>'
    )
    path = tmp_path / "TASKDATA.XML"
    rng = random.Random(3)
    for text in _mutations(xml, rng, 500):
        path.write_text(text)
        try:
            b = load_boundary(BoundaryConfig(path=str(path), headland_m=5.0))
        except MapError as exc:
            assert "TASKDATA.XML" in str(exc), exc
            continue
        assert b.zone(*latlon(0, 30)) in ("field", "headland", "outside")


@pytest.mark.parametrize(
    ("zones", "words"),
    [
        ('<TZN A="1"><PDV A="ZZZZ" B="10000"/></TZN>', ["TZN 1 PDV", "'ZZZZ'", "not a DDI"]),
        ('<TZN A="x"><PDV A="0006" B="10000"/></TZN>', ["treatment zone", "'x'", "0..254"]),
        ('<TZN A="1"><PDV A="0006" B="1.5e3x"/></TZN>', ["TZN 1 PDV 6", "'1.5e3x'"]),
    ],
)
def test_the_issues_broken_values_name_the_element(
    tmp_path: Path, zones: str, words: list[str]
) -> None:
    path = _iso_grid(tmp_path, 1, np.ones((5, 4), np.uint8).tobytes(), zones)
    with pytest.raises(MapError) as err:
        load_prescription(PrescriptionConfig(path=str(path)))
    for w in words:
        assert w in str(err.value)
