"""What a Task Controller learns from a client's device description (DDOP): where its rates,
sections, work states and offsets are, which process data it may set and which measurement
triggers each one offers. Any client's pool, not only topdress's: elements are found by their
type and DDIs, never by number."""

from __future__ import annotations

from dataclasses import dataclass, field

from topdress.errors import ProtocolError
from topdress.isobus.ddop import PoolObject, parse

MAX_POOL_BYTES = 65_536  # what the terminal keeps; a larger pool is refused for memory

# DDIs the mapping looks for (ISO 11783-11)
SETPOINT_VOLUME_HA, ACTUAL_VOLUME_HA = 1, 2  # mm^3/m^2
SETPOINT_MASS_HA, ACTUAL_MASS_HA = 6, 7  # mg/m^2
RATE_DDIS = frozenset({SETPOINT_VOLUME_HA, ACTUAL_VOLUME_HA, SETPOINT_MASS_HA, ACTUAL_MASS_HA})
WORKING_WIDTH, OFFSET_X, OFFSET_Y = 67, 134, 135  # mm
SETPOINT_WORK_STATE, ACTUAL_WORK_STATE = 289, 141
SETPOINT_CONDENSED, ACTUAL_CONDENSED = 290, 161
DET_DEVICE, DET_FUNCTION, DET_BIN, DET_SECTION = 1, 2, 3, 4
PROP_SETTABLE = 2  # DPD property bit 1
# DPD trigger methods (bits), what a measurement command needs
TRIG_TIME, TRIG_DISTANCE, TRIG_THRESHOLD, TRIG_CHANGE, TRIG_TOTAL = 1, 2, 4, 8, 16


@dataclass(frozen=True)
class Device:
    """What the terminal learnt from a device's pool: where its rates and sections are."""

    designator: str
    bins: dict[int, set[int]]  # element number -> DDIs it carries (bins with a rate)
    sections: list[int]  # element numbers of the sections, in pool order
    condensed: dict[int, int]  # DDI 161/290 -> element number that carries it
    settable: frozenset[tuple[int, int]]  # (element, DDI) of the settable process data
    objects: int
    triggers: dict[tuple[int, int], int] = field(default_factory=dict)  # (element, DDI) -> bits
    properties: dict[tuple[int, int], int] = field(default_factory=dict)  # DPT values
    parents: dict[int, int] = field(default_factory=dict)  # element -> parent element
    name: int = 0  # the NAME the client wrote into its DVC (often a placeholder)
    structure_label: bytes = b""
    localization_label: bytes = b""

    def measured(self, element: int, ddi: int, trigger: int) -> bool:
        """The pool offers `trigger` (TRIG_*) for this process data."""
        return bool(self.triggers.get((element, ddi), 0) & trigger)

    def property_up(self, element: int, ddi: int) -> int | None:
        """A property of the element, or of the nearest parent that has it (an offset given
        on the boom holds for its sections)."""
        seen: set[int] = set()
        while element not in seen:
            seen.add(element)
            if (element, ddi) in self.properties:
                return self.properties[(element, ddi)]
            if element not in self.parents:
                return None
            element = self.parents[element]
        return None

    def section_geometry_mm(self) -> list[tuple[int, int, int]]:
        """(x forward, y right, width) of each section, mm from the device reference point; a
        section without its own offset takes its parent's, without width the boom's share."""
        n = len(self.sections)
        out = []
        for e in self.sections:
            x = self.property_up(e, OFFSET_X) or 0
            y = self.property_up(e, OFFSET_Y) or 0
            w = self.properties.get((e, WORKING_WIDTH))
            if w is None:
                boom = self.property_up(e, WORKING_WIDTH) or 0
                w = boom // n if n else 0
            out.append((x, y, w))
        return out


def _index(objs: list[PoolObject]) -> dict[int, PoolObject]:
    by_id: dict[int, PoolObject] = {}
    for o in objs:
        if o.object_id in by_id:
            raise ProtocolError(f"DDOP object id {o.object_id} used twice")
        by_id[o.object_id] = o
    return by_id


def map_device(pool: bytes) -> Device:
    """Parses and maps a pool; ProtocolError names what is wrong (never another exception)."""
    if len(pool) > MAX_POOL_BYTES:
        raise ProtocolError(f"DDOP of {len(pool)} bytes over the {MAX_POOL_BYTES} kept")
    try:
        objs = parse(pool)
    except ValueError as exc:
        raise ProtocolError(f"DDOP malformed: {exc}") from None
    by_id = _index(objs)
    dvcs = [o for o in objs if o.table == "DVC"]
    if len(dvcs) != 1:
        raise ProtocolError(f"DDOP has {len(dvcs)} device objects (DVC), 1 expected")
    bins: dict[int, set[int]] = {}
    sections: list[int] = []
    condensed: dict[int, int] = {}
    settable: set[tuple[int, int]] = set()
    triggers: dict[tuple[int, int], int] = {}
    properties: dict[tuple[int, int], int] = {}
    parent_ids: dict[int, int] = {}
    element_of: dict[int, int] = {}  # DET object id -> element number
    for o in objs:
        if o.table != "DET":
            continue
        element = int(o.fields["element"])
        if element > 4095:
            raise ProtocolError(f"DDOP element number {element} over 4095")
        if o.fields["parent"] not in by_id:
            raise ProtocolError(f"DDOP element {o.object_id} has missing parent")
        element_of[o.object_id] = element
        parent_ids[element] = int(o.fields["parent"])
        ddis = set()
        for child in o.fields["children"]:
            c = by_id.get(child)
            if c is None:
                raise ProtocolError(f"DDOP element {o.object_id} names missing object {child}")
            if c.table not in ("DPD", "DPT"):
                continue
            ddi = int(c.fields["ddi"])
            ddis.add(ddi)
            if c.table == "DPD":
                triggers[(element, ddi)] = int(c.fields["triggers"])
                if c.fields["properties"] & PROP_SETTABLE:
                    settable.add((element, ddi))
            else:
                properties[(element, ddi)] = int(c.fields["value"])
        if o.fields["type"] == DET_BIN and ddis & RATE_DDIS:
            bins[element] = ddis
        if o.fields["type"] == DET_SECTION:
            sections.append(element)
        for ddi in (SETPOINT_CONDENSED, ACTUAL_CONDENSED):
            if ddi in ddis:
                condensed[ddi] = element
    parents = {e: element_of[p] for e, p in parent_ids.items() if element_of.get(p, e) != e}
    f = dvcs[0].fields
    return Device(
        str(f["designator"]), bins, sections, condensed, frozenset(settable), len(objs),
        triggers, properties, parents, int(f["name"]), bytes(f["structure_label"]),
        bytes(f["localization_label"]),
    )  # fmt: skip
