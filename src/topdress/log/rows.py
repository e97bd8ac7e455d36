"""Build the 10 Hz state row from what the terminal knows: the latest ECU frames, the GNSS
position, the mean NDVI and the rates it commands."""

from __future__ import annotations

from topdress import protocol
from topdress.log.model import StateRow


def state_row(
    t: float,
    *,
    status: protocol.EcuStatus | None,
    diag: protocol.EcuDiag | None,
    speeds: protocol.EcuSpeeds | None,
    targets: protocol.EcuTargets | None,
    position: tuple[float, float] | None = None,
    ndvi: float | None = None,
    rates_kg_ha: tuple[float, float] = (0.0, 0.0),
    utc: tuple[float, str] | None = None,
    heading_deg: float | None = None,
    outlet: tuple[float, float] | None = None,
    zone: str | None = None,
    prescription_kg_ha: float | None = None,
) -> StateRow:
    """A frame not received yet gives zeros (and source "none"); speeds come at 0.01 km/h
    from EcuSpeeds, else at 0.1 km/h from EcuStatus. `utc` is (POSIX s, "gnss"|"system")."""
    lat, lon = position if position is not None else (None, None)
    outlet_lat, outlet_lon = outlet if outlet is not None else (None, None)
    if speeds is not None:
        v_wheel, v_gnss, v = speeds.wheel_kmh, speeds.gnss_kmh, speeds.selected_kmh
    else:
        v_wheel = status.wheel_kmh if status is not None else 0.0
        v_gnss, v = None, v_wheel
    return StateRow(
        t=t,
        lat=lat,
        lon=lon,
        v_gnss_kmh=v_gnss,
        v_wheel_kmh=v_wheel,
        v_kmh=v,
        source=str(diag.source) if diag is not None else "none",
        cv_pct=diag.cv_pct if diag is not None else None,
        ndvi=ndvi,
        rate_kg_ha_upper=rates_kg_ha[0],
        rate_kg_ha_lower=rates_kg_ha[1],
        target_rpm_upper=targets.target_rpm_upper if targets is not None else 0.0,
        target_rpm_lower=targets.target_rpm_lower if targets is not None else 0.0,
        meter_rpm_upper=status.meter_rpm_upper if status is not None else 0.0,
        meter_rpm_lower=status.meter_rpm_lower if status is not None else 0.0,
        fan_rpm_upper=status.fan_rpm_upper if status is not None else 0.0,
        fan_rpm_lower=status.fan_rpm_lower if status is not None else 0.0,
        faults=int(diag.faults) if diag is not None else 0,
        utc=utc[0] if utc is not None else None,
        utc_source=utc[1] if utc is not None else None,
        heading_deg=heading_deg,
        outlet_lat=outlet_lat,
        outlet_lon=outlet_lon,
        zone=zone,
        prescription_kg_ha=prescription_kg_ha,
    )
