"""The 10 Hz state row: the Snapshot of the tick as the session log stores it, so the log and
the screens can never mean different things by one name."""

from __future__ import annotations

from topdress.log.model import StateRow
from topdress.view.snapshot import Snapshot


def state_row(t: float, s: Snapshot) -> StateRow:
    """The row of the snapshot `s` taken at `t` (the loop's clock, as the raw inputs). While
    the ECU is not heard its values are unknown in the snapshot (source none, zeros), and so in
    the row: the summary does not integrate stale meter speeds."""
    return StateRow(
        t=t,
        lat=s.lat,
        lon=s.lon,
        v_gnss_kmh=s.v_gnss_kmh,
        v_wheel_kmh=s.v_wheel_kmh,
        v_kmh=s.v_kmh,
        source=s.source,
        cv_pct=s.cv_pct,
        ndvi=s.ndvi,
        rate_kg_ha_upper=s.rate_kg_ha[0],
        rate_kg_ha_lower=s.rate_kg_ha[1],
        target_rpm_upper=s.target_rpm[0],
        target_rpm_lower=s.target_rpm[1],
        meter_rpm_upper=s.meter_rpm[0],
        meter_rpm_lower=s.meter_rpm[1],
        fan_rpm_upper=s.fan_rpm[0],
        fan_rpm_lower=s.fan_rpm[1],
        faults=s.faults,
        utc=s.utc[0] if s.utc is not None else None,
        utc_source=s.utc[1] if s.utc is not None else None,
        heading_deg=s.heading_deg,
        outlet_lat=s.outlet_lat,
        outlet_lon=s.outlet_lon,
        zone=s.zone,
        prescription_kg_ha=s.prescription_kg_ha,
    )
