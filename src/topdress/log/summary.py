"""The figures an engineer checks after a run, from a session's state rows.

Integrals are left sums over consecutive rows (each row's values hold until the next row);
an interval longer than MAX_GAP_S (the log lost rows, or the terminal was paused) is not
integrated and is reported as a gap instead.
"""

from __future__ import annotations

import json
import logging
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from typing import Any, Final

from topdress import protocol
from topdress.config import SpeedConfig
from topdress.errors import ProtocolError
from topdress.log.model import OPERATOR_KINDS, RAW_KINDS, SOURCES, LogEvent, StateRow
from topdress.log.session import SessionReader, session_config

_log = logging.getLogger(__name__)

MAX_GAP_S: Final = 1.0
LAYERS: Final = ("upper", "lower")


@dataclass
class LayerSummary:
    applied_kg: float = 0.0  # integral of measured metering speed x kg/rev
    target_kg: float = 0.0  # integral of target metering speed x kg/rev
    applied_kg_ha: float | None = None  # over the metered area
    rate_error_pct: float | None = None  # (applied - target) / target; None when no target


@dataclass
class StopEvent:
    """A stop in the field (the machine's speed fell below the working speed) or a headland
    entry (the outlet crossed from the field into the headland or outside the boundary), and
    what the meters did after it, until the machine moved on (or left the headland)."""

    kind: str  # "stop" or "headland"
    t: float  # log time of the event
    lat: float | None
    lon: float | None
    reached_zero: bool  # both meters at 0 r/min before the machine moved on
    zero_after_s: float | None  # from the event to both meters at rest
    kg_after: float = 0.0  # fertilizer metered from the event until then
    m_after: float = 0.0  # distance travelled (selected speed) while still metering


@dataclass
class Action:
    """One operator action from the event table."""

    t: float  # log time
    t_s: float  # from the start of the session (its first state row or event)
    kind: str  # operator.start, operator.stop, operator.pause, manual.set, manual.off
    detail: dict[str, Any]


@dataclass
class LagSummary:
    """The GNSS lag the ECU learned in the session, from its `gnss_lag.*` events."""

    learned_ms: int | None = None  # the last lag learned (kept at the end, else last reported)
    start_ms: int | None = None  # the lag kept from an earlier session, pushed at start
    fixed_ms: float | None = None  # [ecu] gnss_lag_ms when fixed
    state: str | None = None  # the last state: start, learned, fixed, overruled
    overruled: int = 0  # times the data overruled a fixed lag
    restored: int = 0  # times an ECU that restarted was pushed the lag learned so far
    changes: int = 0  # gnss_lag.changed events


@dataclass
class Summary:
    path: str
    duration_s: float = 0.0
    distance_m: float = 0.0  # of the selected speed (the one that drove the meters)
    metering_distance_m: float = 0.0
    area_ha: float = 0.0  # metering distance x working width
    width_m: float = 0.0
    layers: dict[str, LayerSummary] = field(default_factory=dict)
    source_s: dict[str, float] = field(default_factory=dict)
    faults_s: dict[str, float] = field(default_factory=dict)
    gaps: int = 0
    gap_s: float = 0.0
    state_rows: int = 0
    raw_inputs: dict[str, int] = field(default_factory=dict)
    log_meta: dict[str, str] = field(default_factory=dict)  # loss counters stored at close
    stops: list[StopEvent] = field(default_factory=list)  # headlands: stops and entries
    stops_zero_pct: float | None = None  # stops after which the metering reached zero
    headland_zero_pct: float | None = None  # headland entries likewise (with a boundary)
    write_failure: dict[str, Any] | None = None  # the log's first write failure, as recorded
    wal_missing: bool = False  # not closed, and no -wal beside the file
    start_utc: float | None = None  # the first and last state rows' GNSS time (POSIX s)
    end_utc: float | None = None
    schema: int = 0  # the file's schema version (1: no events recorded)
    events: dict[str, int] = field(default_factory=dict)  # logged events by kind
    actions: list[Action] = field(default_factory=list)  # the operator's, in time order
    gnss_lag: LagSummary | None = None  # None: no lag event (a session from before them)
    # who the ECU said it was (the last ecu.ident event, else the last EcuIdent in can_rx)
    ecu: dict[str, Any] | None = None
    # the ISOBUS implement the terminal served as Task Controller (its last isobus.implement
    # event); None: none
    implement: dict[str, Any] | None = None

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def summarise(reader: SessionReader) -> Summary:
    cfg = session_config(reader.config_toml)
    machine = cfg.machine
    kg_per_rev = (machine.kg_per_rev_upper, machine.kg_per_rev_lower)
    s = Summary(str(reader.path), width_m=machine.width_m)
    s.source_s = dict.fromkeys(SOURCES, 0.0)
    s.raw_inputs = reader.raw_counts()
    s.log_meta = {
        k: v
        for k, v in reader.meta.items()
        if k in ("created_utc", "start_utc", "closed_utc", "dropped", "lost", "errors")
    }
    s.write_failure = _write_failure(reader.meta.get("write_failed"))
    s.wal_missing = reader.wal_missing
    layers = [LayerSummary(), LayerSummary()]
    first: StateRow | None = None
    prev: StateRow | None = None
    stops = _Stops(kg_per_rev, cfg.speed)  # row by row: a long day is not held
    for row in reader.states():
        stops.feed(row)
        s.state_rows += 1
        if prev is None:
            first = row
        else:
            _integrate(s, layers, kg_per_rev, prev, row.t - prev.t)
        prev = row
        if row.utc is not None and row.utc_source == "gnss":
            s.end_utc = row.utc
            if s.start_utc is None:
                s.start_utc = row.utc
    if first is not None and prev is not None:
        s.duration_s = prev.t - first.t
    s.schema = reader.version
    logged = list(reader.events())  # read once: the counts and what follows
    s.events = dict(sorted(Counter(e.kind for e in logged).items()))
    starts = [x.t for x in (first, logged[0] if logged else None) if x is not None]
    s.actions = operator_actions(logged, min(starts) if starts else 0.0)
    s.gnss_lag = lag_summary(logged)
    idents = [dict(e.detail) for e in logged if e.kind == "ecu.ident"]
    s.ecu = idents[-1] if idents else ecu_from_frames(reader, protocol.FrameIds(**cfg.can.ids))
    implements = [dict(e.detail) for e in logged if e.kind == "isobus.implement"]
    s.implement = implements[-1] if implements else None
    s.area_ha = s.metering_distance_m * machine.width_m / 10_000.0
    for layer in layers:
        if s.area_ha > 0:
            layer.applied_kg_ha = layer.applied_kg / s.area_ha
        if layer.target_kg > 0:
            layer.rate_error_pct = (layer.applied_kg - layer.target_kg) / layer.target_kg * 100.0
    s.layers = dict(zip(LAYERS, layers, strict=True))
    s.stops = stops.finish()
    for kind, attr in (("stop", "stops_zero_pct"), ("headland", "headland_zero_pct")):
        events = [e for e in s.stops if e.kind == kind]
        if events:
            setattr(s, attr, 100.0 * sum(e.reached_zero for e in events) / len(events))
    return s


def ecu_from_frames(reader: SessionReader, ids: protocol.FrameIds) -> dict[str, Any] | None:
    """The ECU's identity from the last EcuIdent among the received frames (a session logged
    before the terminal took EcuIdent, or one whose event was lost), as an ecu.ident event's
    detail; None when the ECU never sent one."""
    last = None
    for rec in reader.can_frames("can_rx", ids.ident):
        if rec.data is not None and rec.can_id is not None:
            try:
                ident = protocol.decode((rec.can_id, rec.data), ids)
            except ProtocolError:
                continue
            if isinstance(ident, protocol.EcuIdent):
                last = ident
    if last is None:
        return None
    return {
        "target": last.target,
        "firmware": last.firmware_version,
        "protocol": last.protocol_version,
        "transport": last.transport,
        "reset_cause": last.reset_cause,
        "clock_fallback": last.clock_fallback,
    }


def ecu_text(ecu: dict[str, Any] | None) -> str:
    """The summary's ECU line: target, firmware, protocol (and the terminal's when it differs),
    transport, the cause of its last reset."""
    if ecu is None:
        return "not identified (no EcuIdent from the ECU in this session)"
    line = (
        f"{ecu.get('target', '?')} firmware {ecu.get('firmware', '?')}, "
        f"protocol {ecu.get('protocol', '?')} ({ecu.get('transport', '?')}, "
        f"last reset: {ecu.get('reset_cause', '?')})"
    )
    ours = ecu.get("terminal_protocol")
    if ours is not None and ours != ecu.get("protocol"):
        line += f"; the terminal spoke protocol {ours}"
    return line


def operator_actions(events: Iterable[LogEvent], t0: float) -> list[Action]:
    """The operator's actions, timed from `t0` (the session's first state row or event)."""
    return [
        Action(ev.t, ev.t - t0, ev.kind, dict(ev.detail))
        for ev in events
        if ev.kind in OPERATOR_KINDS
    ]


def _int(value: Any) -> int | None:
    return value if type(value) is int else None


def lag_summary(events: Iterable[LogEvent]) -> LagSummary | None:
    """The session's GNSS lag from its events: the lag kept at the end (`gnss_lag.kept`), or for
    a session cut short the last learned one a `gnss_lag.changed` reported (within MOVE_MS, 0.1 s,
    of the last the ECU had)."""
    out: LagSummary | None = None
    kept: int | None = None
    for ev in events:
        if not ev.kind.startswith("gnss_lag."):
            continue
        out = out or LagSummary()
        d = ev.detail
        if ev.kind == "gnss_lag.start":
            out.start_ms = _int(d.get("kept_ms"))
            fixed = d.get("fixed_ms")
            out.fixed_ms = float(fixed) if isinstance(fixed, int | float) else None
        elif ev.kind == "gnss_lag.changed":
            out.changes += 1
            out.state = d.get("state") if isinstance(d.get("state"), str) else out.state
            if d.get("state") == "overruled" and d.get("was") != "overruled":
                out.overruled += 1
            learned = _int(d.get("learned_ms"))
            out.learned_ms = learned if learned is not None else out.learned_ms
        elif ev.kind == "gnss_lag.restored":
            out.restored += 1
        elif ev.kind == "gnss_lag.kept":
            lag = _int(d.get("lag_ms"))
            kept = lag if lag is not None else kept
    if out is not None and kept is not None:
        out.learned_ms = kept
    return out


def lag_text(lag: LagSummary | None) -> str:
    """The summary's line on the GNSS lag."""
    if lag is None:
        return "not recorded (a session from before the terminal logged it)"
    start = "none" if lag.start_ms is None else f"{lag.start_ms / 1000:.2f} s"
    if lag.learned_ms is None:
        head = "not learned (no start or speed change with GNSS)"
    else:
        head = f"learned {lag.learned_ms / 1000:.2f} s"
    parts = [head, f"kept from before {start}"]
    if lag.fixed_ms is not None:
        parts.append(f"configured {lag.fixed_ms / 1000:.2f} s")
    if lag.overruled:
        parts.append(f"overruled by the data {lag.overruled}x")
    if lag.restored:
        parts.append(f"pushed again to the restarted ECU {lag.restored}x")
    if lag.state is not None:
        parts.append(f"last state {lag.state}")
    return ", ".join(parts)


def headland_events(
    rows: Iterable[StateRow], kg_per_rev: tuple[float, float], speed: SpeedConfig
) -> list[StopEvent]:
    """Every stop in the field and every headland entry, with what was metered after it (the
    paper judged its headlands by whether the metering reached zero)."""
    stops = _Stops(kg_per_rev, speed)
    for row in rows:
        stops.feed(row)
    return stops.finish()


class _Stops:
    """`headland_events` a row at a time: each stop or headland entry stays open, summing
    what is metered, until the machine moves on, the meters reach zero or it leaves the
    headland. A row's interval is known when the next row comes."""

    def __init__(self, kg_per_rev: tuple[float, float], speed: SpeedConfig) -> None:
        self.kg_per_rev = kg_per_rev
        self.v_min = speed.min_work_speed_kmh
        self.out: list[StopEvent] = []
        self.open: list[tuple[StopEvent, Callable[[StateRow], bool]]] = []
        self.prev: StateRow | None = None

    def feed(self, row: StateRow) -> None:
        prev, v_min = self.prev, self.v_min
        if prev is not None:
            self._advance(prev, row.t - prev.t)
            if _moving(prev, v_min) and not _moving(row, v_min):
                self._start(row, "stop", lambda r: not _moving(r, v_min))
            if prev.zone == "field" and row.zone in ("headland", "outside"):
                self._start(row, "headland", lambda r: r.zone != "field")
        self.prev = row

    def finish(self) -> list[StopEvent]:
        if self.prev is not None:
            self._advance(self.prev, 0.0)  # the last row: nothing after it
            self.prev = None
        return self.out

    def _start(self, start: StateRow, kind: str, lasts: Callable[[StateRow], bool]) -> None:
        lat = start.outlet_lat if start.outlet_lat is not None else start.lat
        lon = start.outlet_lon if start.outlet_lon is not None else start.lon
        ev = StopEvent(kind, start.t, lat, lon, reached_zero=False, zero_after_s=None)
        self.out.append(ev)
        self.open.append((ev, lasts))

    def _advance(self, row: StateRow, dt: float) -> None:
        """Row `row` (its interval `dt`) for every open event."""
        if not self.open:
            return
        still = []
        kg_per_rev = self.kg_per_rev
        for ev, lasts in self.open:
            if not lasts(row):
                continue
            if row.meter_rpm_upper <= 0 and row.meter_rpm_lower <= 0:
                ev.reached_zero, ev.zero_after_s = True, row.t - ev.t
                continue
            if 0 <= dt <= MAX_GAP_S:
                ev.kg_after += (row.meter_rpm_upper * kg_per_rev[0]) / 60.0 * dt
                ev.kg_after += (row.meter_rpm_lower * kg_per_rev[1]) / 60.0 * dt
                ev.m_after += row.v_kmh / 3.6 * dt
            still.append((ev, lasts))
        self.open = still


def _moving(row: StateRow, v_min: float) -> bool:
    # The GNSS speed where there is one: the selected wheel speed lags a stop by its update.
    v = row.v_gnss_kmh if row.v_gnss_kmh is not None else row.v_kmh
    return v >= v_min


def _integrate(
    s: Summary,
    layers: list[LayerSummary],
    kg_per_rev: tuple[float, float],
    row: StateRow,
    dt: float,
) -> None:
    if dt > MAX_GAP_S or dt < 0:
        s.gaps += 1
        s.gap_s += max(dt, 0.0)
        return
    metres = row.v_kmh / 3.6 * dt
    s.distance_m += metres
    meter_rpm = (row.meter_rpm_upper, row.meter_rpm_lower)
    target_rpm = (row.target_rpm_upper, row.target_rpm_lower)
    if any(rpm > 0 for rpm in meter_rpm):
        s.metering_distance_m += metres
    for i, layer in enumerate(layers):
        layer.applied_kg += meter_rpm[i] / 60.0 * kg_per_rev[i] * dt
        layer.target_kg += target_rpm[i] / 60.0 * kg_per_rev[i] * dt
    s.source_s[row.source] = s.source_s.get(row.source, 0.0) + dt
    for fault in protocol.Fault(row.faults & 0xFFFF):
        name = fault.name or str(int(fault))
        s.faults_s[name] = s.faults_s.get(name, 0.0) + dt


def format_text(s: Summary) -> str:
    lines = [
        f"session          {s.path}",
        f"duration         {s.duration_s:.1f} s ({s.state_rows} state rows)",
        f"distance         {s.distance_m:.1f} m, metering {s.metering_distance_m:.1f} m",
        f"area             {s.area_ha:.4f} ha ({s.width_m:g} m working width)",
    ]
    for name, layer in s.layers.items():
        rate = "-" if layer.applied_kg_ha is None else f"{layer.applied_kg_ha:.1f} kg/ha"
        err = "-" if layer.rate_error_pct is None else f"{layer.rate_error_pct:+.1f} %"
        lines.append(
            f"{name + ' layer':<16} applied {layer.applied_kg:.2f} kg ({rate}), "
            f"target {layer.target_kg:.2f} kg, rate error {err}"
        )
    if s.implement is not None:
        i = s.implement
        lines.append(
            f"ISOBUS implement {i.get('device', '?')} at 0x{i.get('address', 0):02X} "
            f"(NAME {i.get('name', '?')}), {len(i.get('products', []))} products, "
            f"{i.get('sections', '?')} sections; the terminal its Task Controller"
        )
    else:
        lines.append(f"ECU              {ecu_text(s.ecu)}")
    if s.start_utc is not None and s.end_utc is not None:
        lines.append(f"time (GNSS)      {_utc_text(s.start_utc)} to {_utc_text(s.end_utc)} UTC")
    else:
        lines.append("time (GNSS)      none (no fix with a date in the session)")
    sources = ", ".join(f"{k} {v:.1f} s" for k, v in s.source_s.items())
    lines.append(f"speed source     {sources}")
    lines.append(f"GNSS lag         {lag_text(s.gnss_lag)}")
    faults = ", ".join(f"{k} {v:.1f} s" for k, v in sorted(s.faults_s.items())) or "none"
    lines.append(f"faults           {faults}")
    if s.gaps:
        lines.append(f"gaps             {s.gaps} (longer than {MAX_GAP_S:g} s), {s.gap_s:.1f} s")
    for kind, pct in (("stop", s.stops_zero_pct), ("headland", s.headland_zero_pct)):
        events = [e for e in s.stops if e.kind == kind]
        if not events:
            continue
        kg = sum(e.kg_after for e in events)
        m = sum(e.m_after for e in events)
        name = "stops" if kind == "stop" else "headland entries"
        lines.append(
            f"{name:<16} {len(events)}, metering reached zero after {pct:.0f} %, "
            f"{kg:.3f} kg and {m:.1f} m metered after them"
        )
    if s.events:
        lines.append("events           " + ", ".join(f"{k} {n}" for k, n in s.events.items()))
    elif s.schema < 2:
        lines.append("events           none recorded (session schema 1, written before events)")
    else:
        lines.append("events           none")
    for a in s.actions:
        detail = " ".join(f"{k}={v}" for k, v in a.detail.items())
        lines.append(f"  {a.t_s:>10.1f} s  {a.kind}" + (f" {detail}" if detail else ""))
    raw = ", ".join(f"{k} {s.raw_inputs.get(k, 0)}" for k in RAW_KINDS)
    lines.append(f"raw inputs       {raw}")
    if s.log_meta:
        lines.append("log              " + ", ".join(f"{k} {v}" for k, v in s.log_meta.items()))
    failure = s.write_failure
    if failure is not None:
        what = "disk full" if failure.get("kind") == "disk_full" else "write failed"
        when = f" at {failure['utc']} UTC" if failure.get("utc") else ""
        lines.append(f"log              {what}{when}: {failure.get('error', '')}")
    if "closed_utc" not in s.log_meta:
        if failure is not None:
            lines.append(
                "log              not closed cleanly after the log writes failed (see above); "
                "rows from then on are missing"
            )
        else:
            lines.append(
                "log              not closed cleanly (power cut or kill): the tail may be missing"
            )
        if s.wal_missing:
            lines.append(
                "log              and no -wal file beside it: if this is a copy, the -wal "
                "of the original holds the tail"
            )
    return "\n".join(lines)


def _utc_text(utc: float) -> str:
    return datetime.fromtimestamp(utc, UTC).strftime("%Y-%m-%d %H:%M:%S")


def _write_failure(text: str | None) -> dict[str, Any] | None:
    if text is None:
        return None
    try:
        value = json.loads(text)
    except ValueError:
        return {"kind": "write_failed", "error": text}
    return value if isinstance(value, dict) else {"kind": "write_failed", "error": text}
