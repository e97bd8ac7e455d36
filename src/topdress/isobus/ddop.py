"""The machine's ISO 11783-10 device description object pool (DDOP), built from one description.

The numbers come from the terminal's `[machine]` configuration (width, rows, layers, outlet
offsets) and the protocol's rate range (the DBC's PcCommand.UpperRate), so nothing is typed
twice. `scripts/gen_ddop.py` writes the pool of the default machine into the ECU's C sources at
build time, as cantools writes the CAN codec from the DBC.

Elements: the device (0), its connector (1), the boom (2, a function: working width, outlet
offsets, section control), one bin per layer (3.., rates DDI 6-10, content 75, total mass 81)
and one section per row (working width and offsets, their work states condensed on the boom).
"""

from __future__ import annotations

import hashlib
import struct
from dataclasses import dataclass, field
from typing import Any
from xml.sax.saxutils import quoteattr

from topdress.config import MachineConfig
from topdress.protocol.dbc import message

# Element types (ISO 11783-10 DET)
DEVICE, FUNCTION, BIN, SECTION, CONNECTOR = 1, 2, 3, 4, 6
# DPD properties and trigger methods
PROP_DEFAULT_SET, PROP_SETTABLE = 1, 2  # (4, control source, excludes settable)
TRIG_TIME, TRIG_DISTANCE, TRIG_THRESHOLD, TRIG_CHANGE, TRIG_TOTAL = 1, 2, 4, 8, 16
NO_DVP = 0xFFFF

# Data dictionary identifiers used by the pool (ISO 11783-11)
DDI_SETPOINT_RATE = 6  # mass per area, mg/m^2
DDI_ACTUAL_RATE = 7
DDI_DEFAULT_RATE = 8
DDI_MIN_RATE = 9
DDI_MAX_RATE = 10
DDI_WORKING_WIDTH = 67  # mm
DDI_ACTUAL_CONTENT = 75  # g
DDI_TOTAL_MASS = 81  # kg
DDI_TOTAL_AREA = 116  # m^2
DDI_OFFSET_X = 134  # mm, forward
DDI_OFFSET_Y = 135  # mm, right
DDI_OFFSET_Z = 136  # mm, up
DDI_ACTUAL_WORK_STATE = 141
DDI_CONNECTOR_TYPE = 157
DDI_SECTION_CONTROL_STATE = 160
DDI_ACTUAL_CONDENSED_1_16 = 161
DDI_SETPOINT_WORK_STATE = 289
DDI_SETPOINT_CONDENSED_1_16 = 290
DDI_REQUEST_DEFAULT_PD = 57343

CONNECTOR_3POINT_MOUNTED = 3  # DDI 157 value: ISO 730 three-point hitch, mounted
MG_M2_PER_KG_HA = 100  # 1 kg/ha = 100 mg/m^2
NAME_PLACEHOLDER = b"\x00" * 8


def _text(s: str) -> bytes:
    raw = s.encode("utf-8")
    if len(raw) > 32:
        raise ValueError(f"designator {s!r} is longer than 32 bytes")
    return bytes([len(raw)]) + raw


@dataclass(frozen=True)
class Machine:
    """What the DDOP says about the machine (lengths in mm, rates in kg/ha)."""

    width_mm: int
    sections: int
    layers: int
    outlet_x_mm: int
    outlet_y_mm: int
    rate_min_kg_ha: float
    rate_max_kg_ha: float
    rate_default_kg_ha: float = 0.0
    software_version: str = "0.1.0"

    @classmethod
    def from_config(cls, m: MachineConfig) -> Machine:
        sig = message("PcCommand").get_signal_by_name("UpperRate")
        return cls(
            width_mm=round(m.width_m * 1000.0),
            sections=m.rows,
            layers=m.layers,
            outlet_x_mm=round(m.outlet_along_m * 1000.0),
            outlet_y_mm=round(m.outlet_across_m * 1000.0),
            rate_min_kg_ha=float(sig.minimum),
            rate_max_kg_ha=float(sig.maximum),
        )

    def section_offsets_mm(self) -> list[tuple[int, int]]:
        """(x, y) of each section's centre: the row outlets spread evenly across the width."""
        w = self.width_mm / self.sections
        left = self.outlet_y_mm - self.width_mm / 2.0
        return [(self.outlet_x_mm, round(left + (i + 0.5) * w)) for i in range(self.sections)]


@dataclass
class Layout:
    """Element numbers and object ids of the built pool (what the ECU and a TC address)."""

    device: int = 0
    connector: int = 1
    boom: int = 2
    bins: list[int] = field(default_factory=list)
    sections: list[int] = field(default_factory=list)
    name_offset: int = 0
    localization_offset: int = 0
    structure_label: bytes = b""


def det_object(oid: int, kind: int, designator: bytes, element: int, parent: int,
               kids: list[int]) -> bytes:  # fmt: skip
    """A device element object (DET); `designator` as a pool writes it (its length first)."""
    return (
        b"DET"
        + struct.pack("<HB", oid, kind)
        + designator
        + struct.pack("<HHH", element, parent, len(kids))
        + b"".join(struct.pack("<H", k) for k in kids)
    )


def dpd_object(oid: int, ddi: int, props: int, triggers: int, designator: bytes, dvp: int) -> bytes:
    """A device process data object (DPD)."""
    return (
        b"DPD"
        + struct.pack("<HHBB", oid, ddi, props, triggers)
        + designator
        + struct.pack("<H", dvp)
    )


def dpt_object(oid: int, ddi: int, value: int, designator: bytes, dvp: int) -> bytes:
    """A device property object (DPT)."""
    return b"DPT" + struct.pack("<HHi", oid, ddi, value) + designator + struct.pack("<H", dvp)


def dvp_object(oid: int, offset: int, scale: float, decimals: int, unit: bytes) -> bytes:
    """A device value presentation object (DVP)."""
    return b"DVP" + struct.pack("<Hifb", oid, offset, scale, decimals) + unit


@dataclass
class _Pool:
    objects: list[bytes] = field(default_factory=list)
    next_id: int = 0

    def new_id(self) -> int:
        oid = self.next_id
        self.next_id += 1
        return oid

    def dpd(self, ddi: int, props: int, triggers: int, name: str, dvp: int) -> int:
        oid = self.new_id()
        self.objects.append(dpd_object(oid, ddi, props, triggers, _text(name), dvp))
        return oid

    def dpt(self, ddi: int, value: int, name: str, dvp: int) -> int:
        oid = self.new_id()
        self.objects.append(dpt_object(oid, ddi, value, _text(name), dvp))
        return oid

    def dvp(self, offset: int, scale: float, decimals: int, unit: str) -> int:
        oid = self.new_id()
        self.objects.append(dvp_object(oid, offset, scale, decimals, _text(unit)))
        return oid

    def det(
        self, oid: int, kind: int, name: str, element: int, parent: int, kids: list[int]
    ) -> bytes:
        return det_object(oid, kind, _text(name), element, parent, kids)


def _kg_ha(v: float) -> int:
    return round(v * MG_M2_PER_KG_HA)


def build(m: Machine, structure_label: bytes | None = None) -> tuple[bytes, Layout]:
    """The binary pool (version 4) and its layout. The structure label (7 bytes) is a hash of
    the pool unless given, so any change of the description changes the label a TC keeps."""
    if not 1 <= m.sections <= 16:
        raise ValueError(f"machine.rows {m.sections}: 1..16 sections fit the condensed work state")
    if m.layers not in (1, 2):
        raise ValueError(f"machine.layers {m.layers}: 1 or 2")
    p = _Pool(next_id=2)  # 0 = DVC, 1 = the device element
    v_rate = p.dvp(0, 1.0 / MG_M2_PER_KG_HA, 2, "kg/ha")
    v_mm = p.dvp(0, 0.001, 2, "m")
    v_g = p.dvp(0, 0.001, 1, "kg")
    v_kg = p.dvp(0, 1.0, 0, "kg")
    v_m2 = p.dvp(0, 0.0001, 2, "ha")
    layout = Layout()
    dets: list[bytes] = []
    dev_kids = [
        p.dpd(
            DDI_ACTUAL_WORK_STATE,
            PROP_DEFAULT_SET,
            TRIG_CHANGE | TRIG_THRESHOLD,
            "Work state",
            NO_DVP,
        ),
        p.dpd(DDI_REQUEST_DEFAULT_PD, 0, TRIG_TOTAL, "Request default PD", NO_DVP),
    ]
    dets.append(p.det(1, DEVICE, "topdress", 0, 0, dev_kids))
    con_id = p.new_id()
    con_kids = [
        p.dpt(DDI_OFFSET_X, 0, "Connector X", v_mm),
        p.dpt(DDI_OFFSET_Y, 0, "Connector Y", v_mm),
        p.dpt(DDI_CONNECTOR_TYPE, CONNECTOR_3POINT_MOUNTED, "Type", NO_DVP),
    ]
    dets.append(p.det(con_id, CONNECTOR, "Connector", layout.connector, 1, con_kids))
    boom_id = p.new_id()
    time_dist_thr = TRIG_TIME | TRIG_DISTANCE | TRIG_THRESHOLD | TRIG_CHANGE
    boom_kids = [
        p.dpt(DDI_OFFSET_X, m.outlet_x_mm, "Offset X", v_mm),
        p.dpt(DDI_OFFSET_Y, m.outlet_y_mm, "Offset Y", v_mm),
        p.dpt(DDI_OFFSET_Z, 0, "Offset Z", v_mm),
        p.dpt(DDI_WORKING_WIDTH, m.width_mm, "Working width", v_mm),
        p.dpd(
            DDI_SECTION_CONTROL_STATE,
            PROP_DEFAULT_SET | PROP_SETTABLE,
            TRIG_CHANGE,
            "Section control state",
            NO_DVP,
        ),
        p.dpd(
            DDI_SETPOINT_WORK_STATE,
            PROP_DEFAULT_SET | PROP_SETTABLE,
            TRIG_CHANGE,
            "Setpoint work state",
            NO_DVP,
        ),
        p.dpd(
            DDI_ACTUAL_CONDENSED_1_16,
            PROP_DEFAULT_SET,
            TRIG_CHANGE | TRIG_TIME,
            "Actual condensed WS",
            NO_DVP,
        ),
        p.dpd(
            DDI_SETPOINT_CONDENSED_1_16,
            PROP_DEFAULT_SET | PROP_SETTABLE,
            TRIG_CHANGE,
            "Setpoint condensed WS",
            NO_DVP,
        ),
        p.dpd(DDI_TOTAL_AREA, PROP_DEFAULT_SET, TRIG_TOTAL | TRIG_TIME, "Total area", v_m2),
    ]
    dets.append(p.det(boom_id, FUNCTION, "Boom", layout.boom, 1, boom_kids))
    element = layout.boom + 1
    for name in ("Upper layer", "Lower layer")[: m.layers]:
        bin_id = p.new_id()
        kids = [
            p.dpd(
                DDI_SETPOINT_RATE,
                PROP_DEFAULT_SET | PROP_SETTABLE,  # control source excludes settable
                TRIG_CHANGE,
                "Setpoint rate",
                v_rate,
            ),
            p.dpd(DDI_ACTUAL_RATE, PROP_DEFAULT_SET, time_dist_thr, "Actual rate", v_rate),
            p.dpt(DDI_DEFAULT_RATE, _kg_ha(m.rate_default_kg_ha), "Default rate", v_rate),
            p.dpt(DDI_MIN_RATE, _kg_ha(m.rate_min_kg_ha), "Minimum rate", v_rate),
            p.dpt(DDI_MAX_RATE, _kg_ha(m.rate_max_kg_ha), "Maximum rate", v_rate),
            p.dpd(DDI_ACTUAL_CONTENT, PROP_DEFAULT_SET, TRIG_TIME | TRIG_THRESHOLD, "Content", v_g),
            p.dpd(DDI_TOTAL_MASS, PROP_DEFAULT_SET, TRIG_TOTAL | TRIG_TIME, "Total mass", v_kg),
        ]
        dets.append(p.det(bin_id, BIN, name, element, boom_id, kids))
        layout.bins.append(element)
        element += 1
    sec_w = round(m.width_mm / m.sections)
    for i, (x, y) in enumerate(m.section_offsets_mm()):
        sec_id = p.new_id()
        kids = [
            p.dpt(DDI_OFFSET_X, x, "Offset X", v_mm),
            p.dpt(DDI_OFFSET_Y, y, "Offset Y", v_mm),
            p.dpt(DDI_WORKING_WIDTH, sec_w, "Width", v_mm),
        ]
        dets.append(p.det(sec_id, SECTION, f"Row {i + 1}", element, boom_id, kids))
        layout.sections.append(element)
        element += 1
    body = b"".join(dets) + b"".join(p.objects)

    def dvc(label: bytes) -> bytes:
        return (
            b"DVC"
            + struct.pack("<H", 0)
            + _text("topdress")
            + _text(m.software_version)
            + NAME_PLACEHOLDER
            + _text("0")
            + label
            + b"en\x50\x00\x00\x00\xff"  # localization: English, metric
            + b"\x00"  # no extended structure label (version 4)
        )

    if structure_label is None:
        structure_label = hashlib.sha1(dvc(b"\x00" * 7) + body).hexdigest()[:7].encode()
    if len(structure_label) != 7:
        raise ValueError("the structure label is 7 bytes")
    head = dvc(structure_label)
    layout.name_offset = 3 + 2 + len(_text("topdress")) + len(_text(m.software_version))
    layout.localization_offset = len(head) - 8  # 7 bytes and the extended label's length
    layout.structure_label = structure_label
    return head + body, layout


@dataclass(frozen=True)
class PoolObject:
    """One object of a binary pool: its table ("DVC", "DET", ...), id and decoded fields."""

    table: str
    object_id: int
    fields: dict[str, Any]


def _take_text(pool: bytes, at: int) -> tuple[str, int]:
    n = pool[at]
    return pool[at + 1 : at + 1 + n].decode("utf-8"), at + 1 + n


def parse(pool: bytes) -> list[PoolObject]:
    """Decodes a binary pool (version 4 layouts); ValueError names the offset of a bad object."""
    out: list[PoolObject] = []
    at = 0
    try:
        while at < len(pool):
            table = pool[at : at + 3].decode("ascii")
            (oid,) = struct.unpack_from("<H", pool, at + 3)
            at += 5
            f: dict[str, Any] = {}
            if table == "DVC":
                f["designator"], at = _take_text(pool, at)
                f["software_version"], at = _take_text(pool, at)
                f["name"] = int.from_bytes(pool[at : at + 8], "little")
                f["serial"], at = _take_text(pool, at + 8)
                f["structure_label"] = pool[at : at + 7]
                f["localization_label"] = pool[at + 7 : at + 14]
                ext = pool[at + 14]
                at += 15 + ext
            elif table == "DET":
                f["type"] = pool[at]
                f["designator"], at = _take_text(pool, at + 1)
                element, parent, n = struct.unpack_from("<HHH", pool, at)
                at += 6
                f["element"], f["parent"] = element, parent
                f["children"] = list(struct.unpack_from(f"<{n}H", pool, at))
                at += 2 * n
            elif table == "DPD":
                f["ddi"], f["properties"], f["triggers"] = struct.unpack_from("<HBB", pool, at)
                f["designator"], at = _take_text(pool, at + 4)
                (f["dvp"],) = struct.unpack_from("<H", pool, at)
                at += 2
            elif table == "DPT":
                f["ddi"], f["value"] = struct.unpack_from("<Hi", pool, at)
                f["designator"], at = _take_text(pool, at + 6)
                (f["dvp"],) = struct.unpack_from("<H", pool, at)
                at += 2
            elif table == "DVP":
                f["offset"], f["scale"], f["decimals"] = struct.unpack_from("<ifb", pool, at)
                f["unit"], at = _take_text(pool, at + 9)
            else:
                raise ValueError(f"unknown object {table!r} at byte {at - 5}")
            out.append(PoolObject(table, oid, f))
    except (struct.error, IndexError, UnicodeDecodeError) as exc:
        raise ValueError(f"pool truncated or malformed at byte {at}: {exc}") from None
    return out


def _xml_attr(v: object) -> str:
    return quoteattr(str(v))


def to_isoxml(pool: bytes) -> str:
    """The pool as the ISO 11783-10 XML device description (a TASKDATA.XML with one DVC)."""
    objs = parse(pool)
    dvc = objs[0]
    f = dvc.fields
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        '<ISO11783_TaskData VersionMajor="4" VersionMinor="3" DataTransferOrigin="2"'
        ' ManagementSoftwareManufacturer="topdress" ManagementSoftwareVersion="0">',
        f'<DVC A="DVC-1" B={_xml_attr(f["designator"])} C={_xml_attr(f["software_version"])}'
        f' D="{f["name"]:016X}" E={_xml_attr(f["serial"])}'
        f' F="{f["structure_label"].hex().upper()}"'
        f' G="{f["localization_label"].hex().upper()}">',
    ]
    det_n = 0
    for o in objs[1:]:
        g = o.fields
        if o.table == "DET":
            det_n += 1
            kids = "".join(f'<DOR A="{k}"/>' for k in g["children"])
            lines.append(
                f'<DET A="DET-{det_n}" B="{o.object_id}" C="{g["type"]}"'
                f' D={_xml_attr(g["designator"])} E="{g["element"]}" F="{g["parent"]}">{kids}</DET>'
            )
        elif o.table == "DPD":
            dvp = "" if g["dvp"] == NO_DVP else f' F="{g["dvp"]}"'
            lines.append(
                f'<DPD A="{o.object_id}" B="{g["ddi"]:04X}" C="{g["properties"]}"'
                f' D="{g["triggers"]}" E={_xml_attr(g["designator"])}{dvp}/>'
            )
        elif o.table == "DPT":
            dvp = "" if g["dvp"] == NO_DVP else f' E="{g["dvp"]}"'
            lines.append(
                f'<DPT A="{o.object_id}" B="{g["ddi"]:04X}" C="{g["value"]}"'
                f" D={_xml_attr(g['designator'])}{dvp}/>"
            )
        elif o.table == "DVP":
            lines.append(
                f'<DVP A="{o.object_id}" B="{g["offset"]}" C="{g["scale"]:.9g}"'
                f' D="{g["decimals"]}" E={_xml_attr(g["unit"])}/>'
            )
    lines += ["</DVC>", "</ISO11783_TaskData>", ""]
    return "\n".join(lines)
