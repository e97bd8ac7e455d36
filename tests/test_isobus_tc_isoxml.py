"""A device described by another tool: a liquid-fertilizer sprayer (volume per area, one tank,
three sections with their own offsets) written as an ISO 11783-10 XML device description by the
`isoxml` package, turned into the binary pool (`ddopxml`), mapped by the terminal's Task
Controller and uploaded to it by a scripted client over TP: accepted, activated, its rate set."""

from __future__ import annotations

from decimal import Decimal

import pytest
from isoxml.models.base.v4 import (
    Device,
    DeviceElement,
    DeviceElementType,
    DeviceObjectReference,
    DeviceProcessData,
    DeviceProperty,
    DeviceValuePresentation,
    Iso11783TaskData,
)
from isoxml.models.base.v4.iso11783_task_data import Iso11783TaskDataDataTransferOrigin
from isoxml.util.isoxml_io import isoxml_to_text

from tc_rig import STEP_US
from topdress.errors import ProtocolError
from topdress.isobus.ddop import Machine, build, to_isoxml
from topdress.isobus.ddopxml import pool_from_isoxml
from topdress.isobus.devicemap import TRIG_CHANGE, TRIG_TIME, map_device
from topdress.isobus.node import Frame, TpEndpoint, split_id
from topdress.isobus.tcserver import TcServer, pd_frame, tc_name

pytestmark = pytest.mark.interop

SPRAYER_NAME = 0xA00C8000AFE00321  # industry group 2, device class 6 (sprayers), identity 801
TC, CLIENT = 0xF7, 0x8A


def _ddi(n: int) -> bytes:
    return n.to_bytes(2, "big")


def _sprayer_xml() -> str:
    """The sprayer as the isoxml package writes it: DDI 1 setpoint / 2 actual volume per
    area (mm^3/m^2), 3 sections of 8 m on a 24 m boom 4.5 m behind the device point."""
    dvp_l_ha = DeviceValuePresentation(
        object_id=100, offset=0, scale=Decimal("0.01"), number_of_decimals=1, unit_designator="l/ha"
    )
    pd = [
        DeviceProcessData(object_id=10, ddi=_ddi(141), property=1, trigger_methods=8,
                          designator="Work state"),
        DeviceProcessData(object_id=11, ddi=_ddi(289), property=3, trigger_methods=8,
                          designator="Setpoint work state"),
        DeviceProcessData(object_id=12, ddi=_ddi(290), property=3, trigger_methods=8,
                          designator="Setpoint condensed"),
        DeviceProcessData(object_id=13, ddi=_ddi(161), property=1, trigger_methods=9,
                          designator="Actual condensed"),
        DeviceProcessData(object_id=14, ddi=_ddi(1), property=3, trigger_methods=8,
                          designator="Setpoint rate", device_value_presentation_object_id=100),
        DeviceProcessData(object_id=15, ddi=_ddi(2), property=1, trigger_methods=9,
                          designator="Actual rate", device_value_presentation_object_id=100),
    ]  # fmt: skip
    props = [
        DeviceProperty(object_id=20, ddi=_ddi(134), value=-4500, designator="Boom X"),
        DeviceProperty(object_id=21, ddi=_ddi(67), value=24000, designator="Boom width"),
        DeviceProperty(object_id=22, ddi=_ddi(72), value=3_000_000, designator="Tank volume"),
    ]
    for i, y in enumerate((-8000, 0, 8000)):
        props += [
            DeviceProperty(object_id=30 + 2 * i, ddi=_ddi(135), value=y, designator="Y"),
            DeviceProperty(object_id=31 + 2 * i, ddi=_ddi(67), value=8000, designator="Width"),
        ]

    def refs(*ids: int) -> list[DeviceObjectReference]:
        return [DeviceObjectReference(device_object_id=i) for i in ids]

    elements = [
        DeviceElement(id="DET-1", object_id=1, type=DeviceElementType.Device,
                      designator="Sprayer", number=0, parent_object_id=0,
                      device_object_references=refs(10)),
        DeviceElement(id="DET-2", object_id=2, type=DeviceElementType.Function,
                      designator="Boom", number=1, parent_object_id=1,
                      device_object_references=refs(20, 21, 11, 12, 13)),
        DeviceElement(id="DET-3", object_id=3, type=DeviceElementType.Bin, designator="Tank",
                      number=2, parent_object_id=1, device_object_references=refs(14, 15, 22)),
    ]  # fmt: skip
    for i in range(3):
        elements.append(
            DeviceElement(id=f"DET-{4 + i}", object_id=4 + i, type=DeviceElementType.Section,
                          designator=f"Section {i + 1}", number=3 + i, parent_object_id=2,
                          device_object_references=refs(30 + 2 * i, 31 + 2 * i))
        )  # fmt: skip
    dvc = Device(
        id="DVC-1", designator="Field sprayer", software_version="2.1",
        client_name=SPRAYER_NAME.to_bytes(8, "big"), serial_number="SP-801",
        structure_label=b"SPRAY01", localization_label=b"en\x50\x00\x00\x00\xff",
        elements=elements, process_data=pd, properties=props, value_presentations=[dvp_l_ha],
    )  # fmt: skip
    task_data = Iso11783TaskData(
        management_software_manufacturer="isoxml test", devices=[dvc],
        data_transfer_origin=Iso11783TaskDataDataTransferOrigin.FMIS,
    )  # fmt: skip
    return isoxml_to_text(task_data)


def test_sprayer_written_by_isoxml_maps() -> None:
    pool = pool_from_isoxml(_sprayer_xml())
    d = map_device(pool)
    assert d.designator == "Field sprayer" and d.name == SPRAYER_NAME
    assert d.structure_label == b"SPRAY01"
    assert d.bins == {2: {1, 2, 72}}  # a volume-per-area product
    assert d.settable == {(1, 289), (1, 290), (2, 1)}
    assert d.condensed == {290: 1, 161: 1}
    assert d.sections == [3, 4, 5]
    # the sections have their own Y and width; X comes from the boom
    assert d.section_geometry_mm() == [(-4500, -8000, 8000), (-4500, 0, 8000), (-4500, 8000, 8000)]
    assert d.measured(2, 2, TRIG_TIME) and d.measured(2, 2, TRIG_CHANGE)


def test_topdress_pool_to_xml_and_back_is_the_same_bytes() -> None:
    pool, _ = build(Machine(3600, 6, 2, -500, 0, 20.0, 600.0))
    assert pool_from_isoxml(to_isoxml(pool)) == pool


@pytest.mark.parametrize(
    ("xml", "said"),
    [
        ("<ISO11783_TaskData>", "device description XML"),
        ("<ISO11783_TaskData/>", "has 0 DVC"),
        ('<DVC A="DVC-1" D="nothex" F="00" G="00"/>', "client NAME"),
        ('<DVC A="DVC-1" D="A00C8000AFE00321" F="0011" G="00"/>', "7 bytes expected"),
        (
            '<DVC A="DVC-1" D="A00C8000AFE00321" F="53505241593031" G="656E5000000000">'
            '<DPD A="1" B="zz" C="1" D="1" E="x"/></DVC>',
            "DDI 'zz' is not hex",
        ),
        (
            '<DVC A="DVC-1" D="A00C8000AFE00321" F="53505241593031" G="656E5000000000">'
            '<DET A="DET-1" C="1" D="x" E="0" F="0"/></DVC>',
            "DET lacks attribute B",
        ),
        (
            '<DVC A="DVC-1" D="A00C8000AFE00321" F="53505241593031" G="656E5000000000">'
            "<PFD/></DVC>",
            "<PFD> is no device object",
        ),
    ],
)
def test_bad_device_descriptions_are_named(xml: str, said: str) -> None:
    with pytest.raises(ProtocolError, match=said):
        pool_from_isoxml(xml)


def test_sprayer_uploaded_to_the_tc_and_its_rate_set() -> None:
    """A scripted client at 0x8A: claim, working-set master, version, no label stored, pool
    size, the 400-odd byte pool over TP (the C transport), activate; then 200 l/ha set."""
    pool = pool_from_isoxml(_sprayer_xml())
    tc = TcServer(tc_name(7))
    tc.start(0)
    tp = TpEndpoint(CLIENT)
    t = 0
    answers: list[bytes] = []

    def pd(data: bytes) -> Frame:
        return Frame(6 << 26 | 0xCB00 << 8 | TC << 8 | CLIENT, data)

    def run(frames: list[Frame], steps: int = 1) -> None:
        nonlocal t
        for _ in range(steps):
            t += STEP_US
            tp.step(t)
            out = tc.step(t, frames + tp.tx())
            frames = []
            for f in out:
                tp.rx(f.can_id, f.data, t)
                if split_id(f.can_id)[3] == CLIENT and split_id(f.can_id)[1] == 0xCB00:
                    answers.append(f.data)

    run([], 40)  # the TC claims 0xF7
    claim = Frame(6 << 26 | 0xEE00 << 8 | 0xFF << 8 | CLIENT, SPRAYER_NAME.to_bytes(8, "little"))
    wsm = Frame(6 << 26 | 0xFE0D << 8 | CLIENT, bytes([1]) + b"\xff" * 7)
    run([claim, wsm])
    run([pd(bytes([0x10, 4, 0xFF, 0x11, 0, 1, 3, 1]))])  # our version, answering its request
    run([pd(bytes([0x01]) + b"\xff" * 7)])  # structure label?
    run([pd(bytes([0x41]) + len(pool).to_bytes(4, "little") + b"\xff" * 3)])
    tp.send(0xCB00, TC, bytes([0x61]) + pool, t)
    run([], 100)
    run([pd(bytes([0x81]) + b"\xff" * 7)])
    assert answers[:5] == [
        bytes([0x00]) + b"\xff" * 7,  # the TC asked the version
        bytes([0x11]) + b"\xff" * 7,  # no pool stored for it
        bytes([0x51, 0]) + b"\xff" * 6,  # room for it
        bytes([0x71, 0]) + len(pool).to_bytes(4, "little") + b"\xff\xff",  # pool taken
        bytes([0x91, 0, 0xFF, 0xFF, 0xFF, 0xFF, 0, 0xFF]),  # activated
    ]
    c = tc.client
    assert c is not None and c.active and c.pool == pool and c.name == SPRAYER_NAME
    assert c.version is not None and not c.geo and c.section_control
    tc.set_value(2, 1, 200_000)  # 200 l/ha = 200,000 mm^3/m^2 (the DDOP's unit)
    run([])
    assert answers[-1] == pd_frame(10, 2, 1, 200_000)
    with pytest.raises(ProtocolError):
        tc.set_value(2, 2, 1)  # the actual rate is not settable
