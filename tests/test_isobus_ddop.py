"""The machine's DDOP: generated from the [machine] configuration, read back by the `isoxml`
package (an ISOXML reader nobody here wrote) after conversion to the ISO 11783-10 XML device
description, with every element, DDI, offset and width as the configuration says."""

from __future__ import annotations

import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from isoxml.util.isoxml_io import isoxml_from_text

from topdress.config import default_config
from topdress.isobus.ddop import Machine, build, parse, to_isoxml

pytestmark = pytest.mark.interop

REPO = Path(__file__).resolve().parents[1]


def _ddi(raw: bytes) -> int:
    return int.from_bytes(raw, "big")  # isoxml keeps the hex attribute as big-endian bytes


def _read(machine: Machine) -> tuple[Any, dict[int, Any]]:
    pool, _ = build(machine)
    device = isoxml_from_text(to_isoxml(pool)).devices[0]
    objects = {o.object_id: o for o in [*device.process_data, *device.properties]}
    return device, objects


def _element(device: Any, number: int) -> Any:
    return next(e for e in device.elements if e.number == number)


def _ddis(element: Any, objects: dict[int, Any]) -> dict[int, Any]:
    refs = [r.device_object_id for r in element.device_object_references]
    return {_ddi(objects[r].ddi): objects[r] for r in refs}


def test_default_machine_reads_back_as_configured() -> None:
    m = Machine.from_config(default_config().machine)
    device, objects = _read(m)
    types = [(e.number, e.type.value, e.designator) for e in device.elements]
    assert types == [
        (0, "1", "topdress"),
        (1, "6", "Connector"),
        (2, "2", "Boom"),
        (3, "3", "Upper layer"),
        (4, "3", "Lower layer"),
        *[(5 + i, "4", f"Row {i + 1}") for i in range(6)],
    ]
    boom = _ddis(_element(device, 2), objects)
    assert set(boom) == {134, 135, 136, 67, 160, 289, 161, 290, 116}
    assert boom[67].value == 3600  # working width, mm
    assert boom[289].property & 2 and boom[290].property & 2 and boom[160].property & 2
    for number in (3, 4):
        b = _ddis(_element(device, number), objects)
        assert set(b) == {6, 7, 8, 9, 10, 75, 81}
        assert b[6].property == 3  # default set, settable (not both settable and control source)
        assert b[7].trigger_methods == 15  # time, distance, threshold, on change
        assert (b[8].value, b[9].value, b[10].value) == (0, 0, 60000)  # mg/m^2: 600 kg/ha max
    ys = [_ddis(_element(device, 5 + i), objects)[135].value for i in range(6)]
    assert ys == [-1500, -900, -300, 300, 900, 1500]
    assert {_ddis(_element(device, 5 + i), objects)[67].value for i in range(6)} == {600}
    rate_dvp = next(v for v in device.value_presentations if v.unit_designator == "kg/ha")
    assert float(rate_dvp.scale) == pytest.approx(0.01)
    # every section and bin hangs under the boom, the boom and connector under the device
    boom_oid = _element(device, 2).object_id
    dev_oid = _element(device, 0).object_id
    assert {e.parent_object_id for e in device.elements if e.number >= 3} == {boom_oid}
    assert _element(device, 1).parent_object_id == dev_oid


def test_another_machine_changes_numbers_and_label() -> None:
    base = default_config().machine
    other = replace(base, width_m=6.0, rows=8, layers=1, outlet_along_m=-2.5, outlet_across_m=0.4)
    m = Machine.from_config(other)
    device, objects = _read(m)
    assert [e.number for e in device.elements if e.type.value == "4"] == list(range(4, 12))
    assert [e.designator for e in device.elements if e.type.value == "3"] == ["Upper layer"]
    sec0 = _ddis(_element(device, 4), objects)
    assert (sec0[134].value, sec0[135].value, sec0[67].value) == (-2500, 400 - 3000 + 375, 750)
    assert _ddis(_element(device, 2), objects)[134].value == -2500
    assert build(m)[1].structure_label != build(Machine.from_config(base))[1].structure_label


def test_bad_descriptions_and_pools_are_refused() -> None:
    base = Machine.from_config(default_config().machine)
    with pytest.raises(ValueError, match=r"machine\.rows 17"):
        build(replace(base, sections=17))
    pool, _ = build(base)
    with pytest.raises(ValueError, match="truncated or malformed"):
        parse(pool[:-3])
    at = pool.index(b"DET")
    with pytest.raises(ValueError, match=f"unknown object 'XYZ' at byte {at}"):
        parse(pool[:at] + b"XYZ" + pool[at + 3 :])


def test_c_pool_is_generated_from_the_description(tmp_path: Path) -> None:
    subprocess.run(
        [sys.executable, str(REPO / "scripts" / "gen_ddop.py"), "--out", str(tmp_path)],
        check=True,
        cwd=REPO,
    )
    for name in ("td_ddop_gen.h", "td_ddop_gen.c"):
        fresh = (tmp_path / name).read_text(encoding="utf-8")
        committed = (REPO / "ecu/isobus/src/gen" / name).read_text(encoding="utf-8")
        assert fresh == committed, f"ecu/isobus/src/gen/{name} is stale: run scripts/gen_ddop.py"
    body = (REPO / "ecu/isobus/src/gen/td_ddop_gen.c").read_text(encoding="utf-8")
    array = body.split("td_ddop_pool[TD_DDOP_LEN] = {")[1].split("};")[0]
    c_pool = bytes(int(h, 16) for h in re.findall(r"0x([0-9A-F]{2})", array))
    assert c_pool == build(Machine.from_config(default_config().machine))[0]
