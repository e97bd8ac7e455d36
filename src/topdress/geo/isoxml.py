"""ISO 11783-10 TaskData: a session as a task with its time log, and grids and partfields read
for prescriptions and boundaries.

Written (`write_taskdata`): a directory with
- `TASKDATA.XML`: the device (the applicator: one device element for the machine and one per
  layer, with their process data and value presentations), one task per session (TSK) with its
  time (TIM: start, stop, the total mass applied per layer) and its time log (TLG00001);
- `TLG00001.XML`, the time log's header: which values each binary record carries;
- `TLG00001.BIN`, one record per positioned state row.

DDIs, from the ISO 11783-11 data dictionary:

| DDI | hex | name | unit in the log |
|---|---|---|---|
| 6 | 0006 | Setpoint Mass Per Area Application Rate | mg/m² (1 kg/ha = 100 mg/m²) |
| 7 | 0007 | Actual Mass Per Area Application Rate | mg/m² |
| 67 | 0043 | Actual Working Width | mm |
| 81 | 0051 | Application Total Mass in kg (in the task's TIM) | kg, resolution 1 kg |
| 352 | 0160 | Application Total Mass in gram (in the task's TIM) | g |
| 141 | 008D | Actual Work State | 1 on, 0 off |
| 397 | 018D | Actual Speed | mm/s |
| 400 | 0190 | Speed Source | 1 wheel, 3 navigation-based (GNSS), 4 blended (fused), 0 unknown |

Binary record layout (ISO 11783-10, time log binary file, little-endian): TimeStart as
uint32 milliseconds since midnight and uint16 days since 1980-01-01; then the position values
the header leaves empty (PTN A north and B east as int32 in 1e-7 degrees, D status as uint8);
then uint8 the number of data log values, and per value uint8 its index in the header's DLV
list and int32 the value. Times are UTC (the standard says local time; the farm software
shows what the receiver gave).

Read (`read_grid`, `read_partfield_boundary`): a task's grid of type 1 (uint8 cells naming
treatment zones whose process data value carries the rate) or type 2 (int32 cells, one value
per process data variable of the treatment zone the grid names), and a partfield's boundary
polygon (PLN type 1, LSG type 1 exterior and 2 interior rings).
"""

from __future__ import annotations

import math
import re
import struct
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Final

import numpy as np
import numpy.typing as npt
import shapely

from topdress import __version__
from topdress.errors import MapError
from topdress.geo.asapplied import SPEED_SOURCE_CODES, AsApplied, AsAppliedStream
from topdress.log.session import SessionReader

DDI_SETPOINT_MASS_PER_AREA: Final = 6
DDI_ACTUAL_MASS_PER_AREA: Final = 7
DDI_MIN_MASS_PER_AREA: Final = 9
DDI_MAX_MASS_PER_AREA: Final = 10
DDI_WORKING_WIDTH: Final = 67
DDI_TOTAL_MASS: Final = 81  # kg: its resolution is 1 kg
DDI_TOTAL_MASS_G: Final = 352  # g: a small plot's 3.56 kg stay 3.56 kg, not 4
DDI_WORK_STATE: Final = 141
DDI_ACTUAL_SPEED: Final = 397
DDI_SPEED_SOURCE: Final = 400
MG_M2_PER_KG_HA: Final = 100.0
EPOCH_1980: Final = datetime(1980, 1, 1, tzinfo=UTC)
TLG: Final = "TLG00001"


def _hex(ddi: int) -> str:
    return f"{ddi:04X}"


@dataclass(frozen=True)
class _Dlv:
    ddi: int
    det: str


@dataclass(frozen=True)
class Implement:
    """The ISOBUS implement a session was worked with (its `isobus.implement` event): the
    designator of its DDOP's device object and its NAME, 16 hex digits."""

    designator: str
    name: str


def implement_of(reader: SessionReader) -> Implement | None:
    """The last ISOBUS implement the session's terminal served (None: the topdress ECU)."""
    found = None
    for e in reader.events():
        if e.kind == "isobus.implement":
            found = Implement(str(e.detail.get("device", "")), str(e.detail.get("name", "")))
    return found


def _device(implement: Implement | None = None) -> ET.Element:
    name = "A000860000000000"
    if implement is not None and re.fullmatch(r"[0-9A-F]{16}", implement.name):
        name = implement.name
    dvc = ET.Element(
        "DVC",
        A="DVC1",
        B=implement.designator if implement is not None else "topdress applicator",
        C=__version__,
        D=name,
        E="1",
        F="00000000000001",
        G="FF000000006E65",
    )
    dets = (
        ("DET1", "1", "1", "applicator", "0", "0", (DDI_ACTUAL_SPEED, DDI_SPEED_SOURCE)),
        ("DET2", "2", "2", "upper layer", "1", "1", ()),
        ("DET3", "3", "2", "lower layer", "2", "1", ()),
    )
    rate_ddis = (
        DDI_SETPOINT_MASS_PER_AREA,
        DDI_ACTUAL_MASS_PER_AREA,
        DDI_TOTAL_MASS,
        DDI_TOTAL_MASS_G,
    )
    dpds: list[tuple[int, int, str, int | None]] = []
    next_id = 10
    for det_id, obj, kind, name, number, parent, extra in dets:
        det = ET.SubElement(dvc, "DET", A=det_id, B=obj, C=kind, D=name, E=number, F=parent)
        ddis = (*extra, DDI_WORK_STATE, DDI_WORKING_WIDTH) if kind == "1" else rate_ddis
        for ddi in ddis:
            ET.SubElement(det, "DOR", A=str(next_id))
            dvp = {6: 1, 7: 1, 81: 3, 352: 5, 397: 2, 67: 4}.get(ddi)
            dpds.append((next_id, ddi, f"{name} {ddi}", dvp))
            next_id += 1
    for obj_id, ddi, name, dvp in dpds:
        attrs = {"A": str(obj_id), "B": _hex(ddi), "C": "1", "D": "8", "E": name}
        if dvp is not None:
            attrs["F"] = str(dvp)
        ET.SubElement(dvc, "DPD", attrs)
    for obj_id, scale, digits, unit in (
        (1, "0.01", "1", "kg/ha"),
        (2, "0.0036", "2", "km/h"),
        (3, "1", "2", "kg"),
        (4, "0.001", "2", "m"),
        (5, "0.001", "3", "kg"),
    ):
        ET.SubElement(dvc, "DVP", A=str(obj_id), B="0", C=scale, D=digits, E=unit)
    return dvc


def _dlvs() -> list[_Dlv]:
    out = [_Dlv(DDI_ACTUAL_SPEED, "DET1"), _Dlv(DDI_SPEED_SOURCE, "DET1")]
    out += [_Dlv(DDI_WORK_STATE, "DET1"), _Dlv(DDI_WORKING_WIDTH, "DET1")]
    for det in ("DET2", "DET3"):
        out += [_Dlv(DDI_SETPOINT_MASS_PER_AREA, det), _Dlv(DDI_ACTUAL_MASS_PER_AREA, det)]
    return out


def _iso_time(utc: float) -> str:
    """xs:dateTime in UTC, marked so (without the Z a reader takes it as local time)."""
    return datetime.fromtimestamp(utc, UTC).isoformat(timespec="seconds").replace("+00:00", "Z")


def write_taskdata(
    data: AsApplied | AsAppliedStream,
    directory: Path,
    task_name: str,
    implement: Implement | None = None,
) -> list[Path]:
    """TASKDATA.XML, TLG00001.XML and TLG00001.BIN in `directory` (made if missing); the time
    log is written a batch of points at a time. `implement`: the ISOBUS implement that worked
    (its DDOP's designator and NAME name the device), else the topdress applicator."""
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise MapError(f"cannot make {directory}: {exc}") from exc
    files = [directory / "TASKDATA.XML", directory / f"{TLG}.XML", directory / f"{TLG}.BIN"]
    dlvs = _dlvs()
    m = data.machine
    layer_kg = [0.0, 0.0]
    first_utc: float | None = None
    last_utc = 0.0
    try:
        with files[2].open("wb") as binary:
            for p, geom in data.point_batches():
                utc = _utc_seconds(p["IsoTime"])
                first_utc = float(utc[0]) if first_utc is None else first_utc
                last_utc = float(utc[-1])
                kg = np.asarray(p["AppliedKg"], float)
                rpm = (np.asarray(p["RpmUp"], float), np.asarray(p["RpmLo"], float))
                mass = rpm[0] * m.kg_per_rev_upper + rpm[1] * m.kg_per_rev_lower
                for i, kg_rev in enumerate((m.kg_per_rev_upper, m.kg_per_rev_lower)):
                    # split the row's kg between the layers by their share of the metered mass
                    share = np.divide(
                        rpm[i] * kg_rev, mass, out=np.zeros_like(mass), where=rpm[0] + rpm[1] > 0
                    )
                    layer_kg[i] += float(np.sum(kg * share))
                binary.write(_records(p, shapely.get_coordinates(geom), utc, dlvs))
    except OSError as exc:
        raise MapError(f"cannot write the task data in {directory}: {exc}") from exc
    if first_utc is None:
        files[2].unlink(missing_ok=True)
        raise MapError(f"{data.path}: no state row has a position: no time log to write")
    root = ET.Element(
        "ISO11783_TaskData",
        VersionMajor="4",
        VersionMinor="3",
        ManagementSoftwareManufacturer="topdress",
        ManagementSoftwareVersion=__version__,
        TaskControllerManufacturer="topdress",
        TaskControllerVersion=__version__,
        DataTransferOrigin="2",
    )
    root.append(_device(implement))
    tsk = ET.SubElement(root, "TSK", A="TSK1", B=task_name, G="4")
    tim = ET.SubElement(tsk, "TIM", A=_iso_time(first_utc), B=_iso_time(last_utc), D="4")
    for det, kg_total in zip(("DET2", "DET3"), layer_kg, strict=True):
        # DDI 81 at its resolution (whole kg) for the software that reads only it; DDI 352
        # the same total in g
        ET.SubElement(tim, "DLV", A=_hex(DDI_TOTAL_MASS), B=str(round(kg_total)), C=det)
        ET.SubElement(tim, "DLV", A=_hex(DDI_TOTAL_MASS_G), B=str(round(kg_total * 1000.0)), C=det)
    ET.SubElement(tsk, "TLG", A=TLG, C="1")  # C 1: binary time log
    header = ET.Element("TIM", A="", D="4")
    ET.SubElement(header, "PTN", A="", B="", D="")
    for d in dlvs:
        ET.SubElement(header, "DLV", A=_hex(d.ddi), B="", C=d.det)
    try:
        _write_xml(root, files[0])
        _write_xml(header, files[1])
    except OSError as exc:
        raise MapError(f"cannot write the task data in {directory}: {exc}") from exc
    return files


def _write_xml(root: ET.Element, path: Path) -> None:
    ET.indent(root)
    tree = ET.ElementTree(root)
    tree.write(path, encoding="UTF-8", xml_declaration=True)


def _utc_seconds(iso: npt.NDArray[np.generic]) -> npt.NDArray[np.float64]:
    ms = np.array([s.rstrip("Z") for s in iso], dtype="datetime64[ms]")
    return ms.astype(np.int64).astype(float) / 1000.0


def _records(
    p: dict[str, npt.NDArray[np.generic]],
    coords: npt.NDArray[np.float64],
    utc: npt.NDArray[np.float64],
    dlvs: list[_Dlv],
) -> bytes:
    days_since = np.floor((utc - EPOCH_1980.timestamp()) / 86400.0)
    ms_of_day = np.round((utc - EPOCH_1980.timestamp() - days_since * 86400.0) * 1000.0)
    speed_mm_s = np.round(np.asarray(p["SPEED"], float) / 3.6 * 1000.0)
    width_mm = np.round(np.asarray(p["SWATHWIDTH"], float) * 1000.0)
    cols = {
        (DDI_ACTUAL_SPEED, "DET1"): speed_mm_s,
        (DDI_SPEED_SOURCE, "DET1"): np.array([SPEED_SOURCE_CODES.get(s, 0) for s in p["SpeedSrc"]]),
        (DDI_WORK_STATE, "DET1"): np.asarray(p["WorkState"]),
        (DDI_WORKING_WIDTH, "DET1"): width_mm,
    }
    for det, suffix in (("DET2", "Up"), ("DET3", "Lo")):
        cols[(DDI_SETPOINT_MASS_PER_AREA, det)] = np.round(
            np.asarray(p[f"TgtRate{suffix}"], float) * MG_M2_PER_KG_HA
        )
        cols[(DDI_ACTUAL_MASS_PER_AREA, det)] = np.round(
            np.asarray(p[f"AppRate{suffix}"], float) * MG_M2_PER_KG_HA
        )
    values = np.stack([np.asarray(cols[(d.ddi, d.det)], float) for d in dlvs], axis=1)
    values = np.nan_to_num(values).astype(np.int64)
    rec = struct.Struct("<IHiiBB" + "Bi" * len(dlvs))
    out = bytearray()
    for i in range(len(utc)):
        fields: list[int] = [int(ms_of_day[i]), int(days_since[i])]
        fields += [round(coords[i, 1] * 1e7), round(coords[i, 0] * 1e7), 1, len(dlvs)]
        for k in range(len(dlvs)):
            fields += [k, int(values[i, k])]
        out += rec.pack(*fields)
    return bytes(out)


# ---- reading: grids (prescriptions) and partfields (boundaries) -----------------------------


@dataclass(frozen=True)
class Grid:
    """A task's grid: cell (row, col) covers lat min_lat + row*cell_lat .. +cell_lat, and lon
    likewise; `values[row, col]` in kg/ha, NaN outside every zone; `low`/`high` the zone's
    limits (DDIs 9 and 10) where given, else NaN."""

    min_lat: float
    min_lon: float
    cell_lat: float
    cell_lon: float
    values: npt.NDArray[np.float64]
    low: npt.NDArray[np.float64]
    high: npt.NDArray[np.float64]


def _parse(path: Path) -> ET.Element:
    try:
        return ET.parse(path).getroot()
    except (OSError, ET.ParseError, LookupError, ValueError) as exc:  # LookupError: encoding
        raise MapError(f"{path}: not a readable ISOXML file: {exc}") from exc


def _attr(el: ET.Element, key: str, path: Path, what: str) -> str:
    value = el.get(key)
    if value is None:
        raise MapError(f"{path}: {what} has no attribute {key}")
    return value


def _float(el: ET.Element, key: str, path: Path, what: str) -> float:
    text = _attr(el, key, path, what)
    try:
        value = float(text)
    except ValueError:
        raise MapError(f"{path}: {what}: attribute {key} = {text!r} is not a number") from None
    if not math.isfinite(value):
        raise MapError(f"{path}: {what}: attribute {key} = {text!r} is not a number")
    return value


_DDI = re.compile(r"^[0-9A-Fa-f]{4}$")
_INT = re.compile(r"^[+-]?[0-9]{1,12}$")
MAX_GRID_CELLS: Final = 50_000_000  # 50 M cells: a 1 m grid over 5,000 ha, far beyond a field


def _ddi(el: ET.Element, path: Path, what: str) -> int:
    text = _attr(el, "A", path, what)
    if not _DDI.match(text):
        raise MapError(f"{path}: {what}: A = {text!r} is not a DDI (4 hex digits, e.g. 0006)")
    return int(text, 16)


def _int(el: ET.Element, key: str, path: Path, what: str, lo: int, hi: int) -> int:
    """A whole-number attribute within lo..hi (ISO 11783-10 writes them as plain digits)."""
    text = _attr(el, key, path, what)
    if not _INT.match(text.strip()) or not lo <= int(text) <= hi:
        raise MapError(f"{path}: {what}: {key} = {text!r} is not a whole number in {lo}..{hi}")
    return int(text)


def _zone_values(tzn: ET.Element, path: Path) -> dict[int, float]:
    """DDI -> value of a treatment zone's process data variables."""
    out: dict[int, float] = {}
    for pdv in tzn.findall("PDV"):
        ddi = _ddi(pdv, path, f"TZN {tzn.get('A')} PDV")
        out[ddi] = _float(pdv, "B", path, f"TZN {tzn.get('A')} PDV {ddi}")
    return out


def read_grid(path: Path) -> Grid:
    """The first task's grid of TASKDATA.XML at `path`, rates in kg/ha."""
    root = _parse(path)
    for tsk in root.iter("TSK"):
        grd = tsk.find("GRD")
        if grd is not None:
            return _grid(path, tsk, grd)
    raise MapError(f"{path}: no task with a grid (GRD): no prescription in it")


def _grid(path: Path, tsk: ET.Element, grd: ET.Element) -> Grid:
    what = f"task {tsk.get('A')} grid"
    min_lat, min_lon = _float(grd, "A", path, what), _float(grd, "B", path, what)
    cell_lat, cell_lon = _float(grd, "C", path, what), _float(grd, "D", path, what)
    cols = _int(grd, "E", path, what, 1, MAX_GRID_CELLS)
    rows = _int(grd, "F", path, what, 1, MAX_GRID_CELLS)
    if cell_lat <= 0 or cell_lon <= 0:
        raise MapError(f"{path}: {what}: cell sizes must be positive")
    if rows * cols > MAX_GRID_CELLS:
        raise MapError(f"{path}: {what}: {rows} x {cols} cells is beyond any field")
    if not (min_lat + rows * cell_lat <= 90.0 and min_lon + cols * cell_lon <= 180.0):
        raise MapError(f"{path}: {what}: the grid reaches beyond the earth (cell sizes?)")
    if not (-90 <= min_lat <= 90 and -180 <= min_lon <= 180):
        raise MapError(f"{path}: {what}: origin {min_lat}, {min_lon} is not a WGS 84 position")
    name = _attr(grd, "G", path, what)
    if not re.fullmatch(r"[A-Za-z0-9_]{1,32}", name):
        raise MapError(f"{path}: {what}: G = {name!r} is not a grid file name (GRD00001)")
    gtype = _attr(grd, "I", path, what)
    bin_path = path.parent / f"{name}.BIN"
    if not bin_path.exists():
        bin_path = path.parent / f"{name}.bin"
    try:
        raw = bin_path.read_bytes()
    except OSError as exc:
        raise MapError(f"{path}: {what}: cannot read its binary {bin_path.name}: {exc}") from exc
    zones = {
        _int(z, "A", path, "treatment zone", 0, 254): _zone_values(z, path)
        for z in tsk.findall("TZN")
    }
    shape = (rows, cols)
    if gtype == "1":
        if len(raw) != rows * cols:
            raise MapError(
                f"{bin_path}: {len(raw)} bytes, a type 1 grid of {rows} x {cols} needs "
                f"{rows * cols} (truncated?)"
            )
        codes = np.frombuffer(raw, dtype=np.uint8).reshape(shape)
        values, low, high = (np.full(shape, np.nan) for _ in range(3))
        for code in np.unique(codes):
            zone = zones.get(int(code))
            if zone is None:
                r, c = np.argwhere(codes == code)[0]
                raise MapError(
                    f"{bin_path}: cell row {r} column {c} names treatment zone {code}, "
                    f"which task {tsk.get('A')} does not define"
                )
            _check_units(zone, path, f"treatment zone {code}")
            sel = codes == code
            values[sel] = _kg_ha(zone.get(DDI_SETPOINT_MASS_PER_AREA))
            low[sel] = _kg_ha(zone.get(DDI_MIN_MASS_PER_AREA))
            high[sel] = _kg_ha(zone.get(DDI_MAX_MASS_PER_AREA))
        return Grid(min_lat, min_lon, cell_lat, cell_lon, values, low, high)
    if gtype == "2":
        code = _int(grd, "J", path, what, 0, 254)
        zone_el = next((z for z in tsk.findall("TZN") if z.get("A") == str(code)), None)
        if zone_el is None:
            raise MapError(f"{path}: {what} names treatment zone {code}, which is not defined")
        ddis = [_ddi(p, path, f"TZN {code} PDV") for p in zone_el.findall("PDV")]
        if DDI_SETPOINT_MASS_PER_AREA not in ddis:
            _check_units(dict.fromkeys(ddis, 0.0), path, f"treatment zone {code}")
            raise MapError(
                f"{path}: {what}: treatment zone {code} has no DDI 6 (Setpoint Mass Per Area "
                "Application Rate): no fertilizer rate in the grid"
            )
        n = len(ddis)
        if len(raw) != rows * cols * n * 4:
            raise MapError(
                f"{bin_path}: {len(raw)} bytes, a type 2 grid of {rows} x {cols} with {n} "
                f"value(s) per cell needs {rows * cols * n * 4} (truncated?)"
            )
        cells = np.frombuffer(raw, dtype="<i4").reshape((rows, cols, n)).astype(float)

        def layer(ddi: int) -> npt.NDArray[np.float64]:
            if ddi not in ddis:
                return np.full(shape, np.nan)
            return cells[:, :, ddis.index(ddi)] / MG_M2_PER_KG_HA

        return Grid(
            min_lat,
            min_lon,
            cell_lat,
            cell_lon,
            layer(DDI_SETPOINT_MASS_PER_AREA),
            layer(DDI_MIN_MASS_PER_AREA),
            layer(DDI_MAX_MASS_PER_AREA),
        )
    raise MapError(f"{path}: {what} is of type {gtype!r}; types 1 and 2 are read")


def _kg_ha(mg_m2: float | None) -> float:
    return math.nan if mg_m2 is None else mg_m2 / MG_M2_PER_KG_HA


def _check_units(zone: dict[int, float], path: Path, what: str) -> None:
    """A zone with a rate must give it as mass per area (DDI 6): a volume or count per area
    (a sprayer's or a seeder's map) is not a fertilizer rate in kg/ha."""
    other = sorted(d for d in zone if d in range(1, 6) or d in range(11, 16))
    if other and DDI_SETPOINT_MASS_PER_AREA not in zone:
        raise MapError(
            f"{path}: {what} gives DDI {other[0]} (not a mass per area rate): a fertilizer "
            "prescription needs DDI 6, Setpoint Mass Per Area Application Rate (mg/m²)"
        )


def read_partfield_boundary(path: Path) -> shapely.MultiPolygon:
    """The boundary polygons (PLN type 1) of the partfields in TASKDATA.XML at `path`."""
    root = _parse(path)
    polys: list[shapely.Polygon] = []
    for pfd in root.iter("PFD"):
        for pln in pfd.findall("PLN"):
            if pln.get("A") != "1":
                continue
            what = f"partfield {pfd.get('A')} polygon {pln.get('B', '')}".rstrip()
            shell: list[tuple[float, float]] | None = None
            holes: list[list[tuple[float, float]]] = []
            for lsg in pln.findall("LSG"):
                ring = [_lonlat(pnt, path, what) for pnt in lsg.findall("PNT")]
                if len(ring) < 3:
                    raise MapError(f"{path}: {what}: a ring of {len(ring)} points")
                if lsg.get("A") == "1":
                    shell = ring
                elif lsg.get("A") == "2":
                    holes.append(ring)
            if shell is None:
                raise MapError(f"{path}: {what} has no exterior ring (LSG type 1)")
            poly = shapely.Polygon(shell, holes)
            if not poly.is_valid:  # a hand-drawn ring that touches itself: repaired
                poly = shapely.make_valid(poly)
            polys.extend(q for q in shapely.get_parts(poly) if q.geom_type == "Polygon")
    if not polys:
        raise MapError(f"{path}: no partfield boundary (PFD with a PLN of type 1)")
    return shapely.MultiPolygon(polys)


def _lonlat(pnt: ET.Element, path: Path, what: str) -> tuple[float, float]:
    lat, lon = _float(pnt, "C", path, what), _float(pnt, "D", path, what)
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        raise MapError(f"{path}: {what}: point {lat}, {lon} is not a WGS 84 position")
    return lon, lat
