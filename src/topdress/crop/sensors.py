"""Crop sensor readings: parsing the logger's lines, averaging the sensors, and carrying the
NDVI seen at the sensors forward to the moment the meters reach that spot.

Line format (default column map, configurable in [crop.columns]): one ASCII line per reading,
comma separated, `<sensor_id>,<red_670>,<red_edge_730>,<nir_780>,<ndre>,<ndvi>`, e.g.
`2,0.0412,0.2104,0.4419,0.3541,0.8295`. An empty NDVI field (or no NDVI column) means NDVI is
computed from red and NIR: (nir - red) / (nir + red).
"""

from __future__ import annotations

import math
import re
from collections import Counter, deque
from collections.abc import Mapping
from dataclasses import dataclass

from topdress.config import CropConfig
from topdress.errors import ConfigError, SensorError

_REFLECTANCES = ("red", "red_edge", "nir")
# The logger writes plain decimals. float() and int() would also read "1_0", "+1", "1e0",
# "inf" or "nan": such a field is refused, not read as a number.
_DECIMAL = re.compile(r"^-?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)$")
_SENSOR_ID = re.compile(r"^[0-9]{1,3}$")
_TEXT = re.compile(rb"[\x20-\x7e\t]*")  # printable ASCII and tab only
_INDICES = ("ndre", "ndvi")


@dataclass(frozen=True)
class CropReading:
    t: float
    sensor_id: int
    ndvi: float
    red: float | None = None
    red_edge: float | None = None
    nir: float | None = None
    ndre: float | None = None


def parse_crop_line(
    t: float, line: bytes | str, columns: Mapping[str, int], sensors: int
) -> CropReading:
    """One reading from one line; SensorError('<reason>: ...') when the line cannot be used.
    Reasons: empty, binary, fields, number, sensor_id, reflectance_range, index_range,
    ndvi_undefined."""
    text = _text(line)
    fields = [f.strip() for f in text.split(",")]
    need = max(columns.values()) + 1
    if len(fields) < need:
        raise SensorError(f"fields: {len(fields)} fields, the column map needs {need}")
    id_text = fields[columns["sensor_id"]]
    _field(id_text, "sensor_id")  # not a decimal at all: a 'number' error like the others
    if not _SENSOR_ID.match(id_text) or not 1 <= int(id_text) <= sensors:
        raise SensorError(f"sensor_id: {id_text!r} is not 1..{sensors}")
    sensor = int(id_text)
    values = {name: _field(fields[i], name) for name, i in columns.items() if name != "sensor_id"}
    for name in _REFLECTANCES:
        v = values.get(name)
        if v is not None and not 0.0 <= v <= 1.0:
            raise SensorError(f"reflectance_range: {name} {v} outside 0..1")
    for name in _INDICES:
        v = values.get(name)
        if v is not None and not -1.0 <= v <= 1.0:
            raise SensorError(f"index_range: {name} {v} outside -1..1")
    ndvi = values.get("ndvi")
    if ndvi is None:
        ndvi = _ndvi(values.get("red"), values.get("nir"))
    return CropReading(
        t=t,
        sensor_id=sensor,
        ndvi=ndvi,
        red=values.get("red"),
        red_edge=values.get("red_edge"),
        nir=values.get("nir"),
        ndre=values.get("ndre"),
    )


def _text(line: bytes | str) -> str:
    raw = line.encode("latin-1", "replace") if isinstance(line, str) else line
    raw = raw.strip(b"\r\n\x00 ")
    if not raw:
        raise SensorError("empty: empty line")
    if _TEXT.fullmatch(raw) is None:
        raise SensorError("binary: non-text bytes in the line")
    return raw.decode("ascii")


def _field(text: str, name: str) -> float | None:
    if not text:
        return None
    if not _DECIMAL.match(text):
        raise SensorError(f"number: {name} {text!r} is not a decimal number")
    value = float(text)
    if not math.isfinite(value):  # a decimal of over 308 digits
        raise SensorError(f"number: {name} {text!r} is not finite")
    return value


def _ndvi(red: float | None, nir: float | None) -> float:
    if red is None or nir is None:
        raise SensorError("ndvi_undefined: no NDVI and no red and NIR to compute it")
    if nir + red <= 0.0:
        raise SensorError("ndvi_undefined: red + NIR is zero")
    return (nir - red) / (nir + red)


class CropSensors:
    """The latest reading of each sensor, and their mean NDVI.

    `counters`: 'ok', each rejection reason of parse_crop_line, 'ndvi_range' for an NDVI
    outside [ndvi_min, ndvi_max], and 'stale' each time a sensor falls silent for > stale_s.
    """

    def __init__(self, cfg: CropConfig) -> None:
        self.cfg = cfg
        self.counters: Counter[str] = Counter()
        self.last_error: str | None = None
        self._latest: dict[int, CropReading] = {}
        self._stale: set[int] = set()

    def feed(self, t: float, line: bytes | str) -> CropReading | None:
        """Parse and keep one line; None (counted, `last_error` set) when rejected."""
        try:
            reading = parse_crop_line(t, line, self.cfg.columns, self.cfg.sensors)
            if not self.cfg.ndvi_min <= reading.ndvi <= self.cfg.ndvi_max:
                raise SensorError(
                    f"ndvi_range: sensor {reading.sensor_id} NDVI {reading.ndvi:.4f} outside "
                    f"{self.cfg.ndvi_min}..{self.cfg.ndvi_max}"
                )
        except SensorError as exc:
            self.last_error = str(exc)
            self.counters[self.last_error.split(":", 1)[0]] += 1
            return None
        self.counters["ok"] += 1
        self._latest[reading.sensor_id] = reading
        self._stale.discard(reading.sensor_id)
        return reading

    def fresh(self, t: float) -> list[CropReading]:
        """The latest reading of every sensor heard within stale_s, by sensor id."""
        fresh = []
        for sid in sorted(self._latest):
            reading = self._latest[sid]
            if t - reading.t <= self.cfg.stale_s:
                fresh.append(reading)
            elif sid not in self._stale:
                self._stale.add(sid)
                self.counters["stale"] += 1
        return fresh

    def mean_ndvi(self, t: float) -> float | None:
        """Mean NDVI of the fresh sensors; None when no sensor is fresh."""
        fresh = self.fresh(t)
        return sum(r.ndvi for r in fresh) / len(fresh) if fresh else None


class DistanceQueue:
    """NDVI by distance travelled: `at(odometer_m)` returns the NDVI pushed `offset_m` earlier
    along the track (the last one pushed at or before odometer_m - offset_m), or None before
    the meters reach the first spot sensed. Only the span the meters still need is kept."""

    def __init__(self, offset_m: float, max_len: int = 100_000) -> None:
        if not offset_m >= 0.0:
            raise ConfigError("crop.sensor_to_meter_m", f"must be >= 0, not {offset_m}")
        self.offset_m = offset_m
        self.counters: Counter[str] = Counter()
        self._q: deque[tuple[float, float | None]] = deque()
        self._max_len = max_len

    def push(self, odometer_m: float, ndvi: float | None) -> None:
        if self._q and odometer_m < self._q[-1][0]:
            self.counters["backwards"] += 1
            return
        if self._q and odometer_m == self._q[-1][0]:
            self._q[-1] = (odometer_m, ndvi)  # standing still: the latest view of this spot
            return
        if len(self._q) >= self._max_len:
            self._q.popleft()
            self.counters["overflow"] += 1
        self._q.append((odometer_m, ndvi))

    def at(self, odometer_m: float) -> float | None:
        spot = odometer_m - self.offset_m
        q = self._q
        if not q or spot < q[0][0]:
            return None
        while len(q) > 1 and q[1][0] <= spot:
            q.popleft()
        return q[0][1]

    def __len__(self) -> int:
        return len(self._q)


class Odometer:
    """Distance travelled, integrating the selected speed (held between updates)."""

    def __init__(self) -> None:
        self.distance_m = 0.0
        self._last: tuple[float, float] | None = None

    def advance(self, t: float, speed_kmh: float) -> float:
        if self._last is not None:
            t0, v0 = self._last
            if t > t0:
                self.distance_m += v0 / 3.6 * (t - t0)
        if self._last is None or t >= self._last[0]:
            self._last = (t, max(0.0, speed_kmh))
        return self.distance_m


class CompensatedNdvi:
    """Sensors + odometer + distance queue: the NDVI to apply where the meters are now, or,
    with a look-ahead of `lookahead_s` (command path + meter response + air line), where the
    outlets will be when the product commanded now lands: speed x lookahead_s further on."""

    def __init__(self, cfg: CropConfig, lookahead_s: float = 0.0) -> None:
        if not 0.0 <= lookahead_s <= 5.0:
            raise ConfigError("lookahead", f"total must be 0..5 s, not {lookahead_s}")
        self.sensors = CropSensors(cfg)
        self.odometer = Odometer()
        self.queue = DistanceQueue(cfg.sensor_to_meter_m)
        self.lookahead_s = lookahead_s

    def retune(self, cfg: CropConfig, lookahead_s: float) -> None:
        """A changed [crop] or [lookahead] section: columns, sensor count, NDVI range and
        stale_s at the next line, the look-ahead at the next tick. A new sensor distance
        starts the queue again: NDVI queued for the old one would land at the wrong spot."""
        self.sensors.cfg = cfg
        if cfg.sensor_to_meter_m != self.queue.offset_m:
            self.queue = DistanceQueue(cfg.sensor_to_meter_m)
        self.lookahead_s = lookahead_s

    def update(self, t: float, speed_kmh: float) -> float | None:
        """Call every control tick with the selected speed."""
        position = self.odometer.advance(t, speed_kmh)
        self.queue.push(position, self.sensors.mean_ndvi(t))
        # never further ahead than the sensors have seen
        ahead = min(max(0.0, speed_kmh) / 3.6 * self.lookahead_s, self.queue.offset_m)
        return self.queue.at(position + ahead)
