"""Values stored in a session log: the decoded state row and the raw input kinds."""

from __future__ import annotations

from dataclasses import astuple, dataclass, fields
from typing import Final

# Raw input kinds. "can_rx" = ECU -> terminal, "can_tx" = terminal -> ECU (the terminal's view).
RAW_KINDS: Final = ("nmea", "crop", "can_rx", "can_tx")
LINE_KINDS: Final = frozenset({"nmea", "crop"})
CAN_KINDS: Final = frozenset({"can_rx", "can_tx"})

SOURCES: Final = ("wheel", "gnss", "none")


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

    def as_tuple(self) -> tuple[object, ...]:
        return astuple(self)


STATE_COLUMNS: Final = tuple(f.name for f in fields(StateRow))
