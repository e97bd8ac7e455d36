"""Values stored in a session log: the decoded state row, the raw input kinds, the events."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from operator import attrgetter
from typing import Any, Final

from topdress.protocol.model import Source

# Raw input kinds. "can_rx" = ECU -> terminal, "can_tx" = terminal -> ECU (the terminal's view).
RAW_KINDS: Final = ("nmea", "crop", "can_rx", "can_tx")
LINE_KINDS: Final = frozenset({"nmea", "crop"})
CAN_KINDS: Final = frozenset({"can_rx", "can_tx"})

#: The speed sources a state row names (the DBC's EcuDiag.SpeedSource, in code order).
SOURCES: Final = tuple(str(s) for s in Source)


@dataclass(frozen=True, slots=True)
class StateRow:
    """The decoded state of the machine at one instant (the terminal writes one at 10 Hz).

    `t` is time.monotonic() seconds, the same clock as the raw inputs. None = not available
    (no GNSS fix, CV undefined, no crop reading yet). Index 0 of a layer pair is the upper layer.
    """

    t: float
    lat: float | None
    lon: float | None
    v_gnss_kmh: float | None
    v_wheel_kmh: float
    v_kmh: float
    source: str
    cv_pct: float | None
    ndvi: float | None
    rate_kg_ha_upper: float
    rate_kg_ha_lower: float
    target_rpm_upper: float
    target_rpm_lower: float
    meter_rpm_upper: float
    meter_rpm_lower: float
    fan_rpm_upper: float
    fan_rpm_lower: float
    faults: int
    # Added columns (None in files written before them, and when not known):
    utc: float | None = None  # UTC, POSIX seconds, of this row
    utc_source: str | None = None  # "gnss" (the last fix's time carried forward) or "system"
    heading_deg: float | None = None  # course over ground, degrees clockwise from north
    outlet_lat: float | None = None  # the meters' outlet, from the antenna by [machine] offsets
    outlet_lon: float | None = None
    zone: str | None = None  # field boundary: "field", "headland", "outside"; None = no boundary
    prescription_kg_ha: float | None = None  # prescription map's total rate at the outlet

    def as_tuple(self) -> tuple[object, ...]:
        # The fields are plain values: no deep copy (dataclasses.astuple) needed, at 10 Hz.
        values: tuple[object, ...] = _STATE_VALUES(self)
        return values


STATE_COLUMNS: Final = tuple(f.name for f in fields(StateRow))
_STATE_VALUES: Final = attrgetter(*STATE_COLUMNS)
UTC_SOURCES: Final = ("gnss", "system")
ZONES: Final = ("field", "headland", "outside")


#: What happened, by kind (the `event` table). The kind and its detail are the whole message:
#: no sentence is stored, so a reader renders them in its own language. See docs/log.md.
EVENT_KINDS: Final = (
    "operator.start",
    "operator.stop",
    "operator.pause",
    "manual.set",
    "manual.off",
    "setting.changed",
    "alarm.raised",
    "alarm.acked",
    "link.lost",
    "link.restored",
    "fault.changed",
    "ecu.ident",
    "calibration.catch",
    "calibration.wheel",
    "calibration.fan",
    "calibration.lead",
    "gnss_lag.start",
    "gnss_lag.receiver",
    "gnss_lag.changed",
    "gnss_lag.kept",
    "gnss_lag.restored",
    "map.distance",
    "display.restarted",
    "display.lost",
    "display.back",
    "display.pin_failed",
    "display.pin_lockout",
    "counter.reset",
    "counter.undo",
    "tank.filled",
    "isobus.implement",
    "isobus.connected",
    "isobus.refused",
    "isobus.problem",
    "isobus.totals",
    "isobus.sections",
    "isobus.coverage",
    "isobus.claimed",
    "isobus.ddop",
    "isobus.set",
    "isobus.tc_lost",
    "isobus.bus_load",
    "isobus.value_refused",
    "isobus.tp_aborted",
)
#: Operator actions (listed with their times by `topdress log summary`).
OPERATOR_KINDS: Final = (
    "operator.start",
    "operator.stop",
    "operator.pause",
    "manual.set",
    "manual.off",
)
#: Settings whose values never reach the log: the key is kept, each value written as MASK.
SECRET_KEYS: Final = frozenset({"display.pin"})
MASK: Final = "***"


@dataclass(frozen=True, slots=True)
class LogEvent:
    """One thing that happened: `t` on the state rows' clock, `kind` one of EVENT_KINDS,
    `detail` plain JSON values (numbers, strings, booleans, lists of them) keyed by name."""

    t: float
    kind: str
    detail: Mapping[str, Any] = field(default_factory=dict)


def masked(event: LogEvent) -> LogEvent:
    """The event with the values of a secret setting replaced by MASK."""
    d = event.detail
    if event.kind != "setting.changed" or d.get("key") not in SECRET_KEYS:
        return event
    return LogEvent(event.t, event.kind, {"key": d["key"], "old": MASK, "new": MASK})
