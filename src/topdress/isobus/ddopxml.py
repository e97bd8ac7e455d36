"""An ISO 11783-10 XML device description (a TASKDATA.XML `DVC`, as farm software, other
terminals and the `isoxml` package write them) turned into the binary device description object
pool a client uploads, so the Task Controller can read and map a device described by another
tool exactly as one uploaded on the bus. The inverse of `ddop.to_isoxml`: a pool written to XML
and read back gives the same bytes.

The XML names objects by the attributes of ISO 11783-10 Annex D (DVC A-G, DET A-F with DOR
children, DPD A-F, DPT A-E, DVP A-E); the device object itself is object 0 of the pool, as the
device element's parent (DET F) names it.
"""

from __future__ import annotations

import struct
import xml.etree.ElementTree as ET

from topdress.errors import ProtocolError
from topdress.isobus.ddop import NO_DVP, det_object, dpd_object, dpt_object, dvp_object


def _text(s: str, what: str) -> bytes:
    raw = s.encode("utf-8")
    if len(raw) > 32:
        raise ProtocolError(f"{what} {s!r} is longer than 32 bytes")
    return bytes([len(raw)]) + raw


def _int(e: ET.Element, key: str, default: int | None = None) -> int:
    v = e.get(key)
    if v is None:
        if default is None:
            raise ProtocolError(f"{e.tag} lacks attribute {key}")
        return default
    try:
        return int(v)
    except ValueError:
        raise ProtocolError(f"{e.tag} {key}={v!r} is not a number") from None


def _hex(e: ET.Element, key: str, size: int) -> bytes:
    v = e.get(key, "")
    try:
        raw = bytes.fromhex(v)
    except ValueError:
        raise ProtocolError(f"{e.tag} {key}={v!r} is not hex") from None
    if len(raw) != size:
        raise ProtocolError(f"{e.tag} {key}={v!r}: {size} bytes expected")
    return raw


def _ddi(e: ET.Element) -> int:
    v = e.get("B", "")
    try:
        ddi = int(v, 16)
    except ValueError:
        raise ProtocolError(f"{e.tag} DDI {v!r} is not hex") from None
    if not 0 <= ddi <= 0xFFFF:
        raise ProtocolError(f"{e.tag} DDI {v!r} out of range")
    return ddi


def _object(e: ET.Element) -> bytes:
    """One child of the DVC as its binary object."""
    if e.tag == "DET":
        kids = [_int(d, "A") for d in e.findall("DOR")]
        designator = _text(e.get("D", ""), "DET designator")
        return det_object(_int(e, "B"), _int(e, "C"), designator, _int(e, "E"), _int(e, "F"), kids)
    if e.tag == "DPD":
        designator = _text(e.get("E", ""), "DPD designator")
        return dpd_object(_int(e, "A"), _ddi(e), _int(e, "C"), _int(e, "D"), designator,
                          _int(e, "F", NO_DVP))  # fmt: skip
    if e.tag == "DPT":
        designator = _text(e.get("D", ""), "DPT designator")
        return dpt_object(_int(e, "A"), _ddi(e), _int(e, "C"), designator, _int(e, "E", NO_DVP))
    if e.tag == "DVP":
        try:
            scale = float(e.get("C", ""))
        except ValueError:
            raise ProtocolError(f"DVP {e.get('A')} scale {e.get('C')!r}") from None
        unit = _text(e.get("E", ""), "DVP unit")
        return dvp_object(_int(e, "A"), _int(e, "B"), scale, _int(e, "D"), unit)
    raise ProtocolError(f"DVC child <{e.tag}> is no device object")


def pool_from_isoxml(xml: str, device: int = 0) -> bytes:
    """The binary pool of the `device`-th DVC of a TASKDATA.XML text; ProtocolError names what
    is missing or wrong (never another exception)."""
    try:
        root = ET.fromstring(xml)
    except ET.ParseError as exc:
        raise ProtocolError(f"device description XML: {exc}") from None
    dvcs = root.findall("DVC") if root.tag != "DVC" else [root]
    if not 0 <= device < len(dvcs):
        raise ProtocolError(f"device description XML has {len(dvcs)} DVC, not #{device + 1}")
    d = dvcs[device]
    try:
        name = int(d.get("D", ""), 16)
    except ValueError:
        raise ProtocolError(f"DVC D (client NAME) {d.get('D')!r} is not hex") from None
    head = (
        b"DVC"
        + struct.pack("<H", 0)
        + _text(d.get("B", ""), "DVC designator")
        + _text(d.get("C", ""), "DVC software version")
        + name.to_bytes(8, "little")
        + _text(d.get("E", ""), "DVC serial number")
        + _hex(d, "F", 7)
        + _hex(d, "G", 7)
        + b"\x00"  # no extended structure label
    )
    return head + b"".join(_object(e) for e in d)
