"""What the operator's desk (terminal.desk) adds to every Snapshot: its fields, the rate each
layer applies now, and why the ECU meters on the speed it does."""

from __future__ import annotations

from dataclasses import dataclass

from topdress.config import TerminalConfig
from topdress.ecu import meter_rate_kg_ha
from topdress.i18n import Text, text
from topdress.protocol import Compare, Fault, Source, SpeedMode
from topdress.view import commands as op
from topdress.view.snapshot import AlarmView, CalibrationView, CounterView, Snapshot, TankView


@dataclass(frozen=True)
class DeskView:
    """The Snapshot fields the desk fills."""

    operator: str
    manual: op.ManualView
    rate_model_kg_ha: tuple[float, float]
    speed_why: Text | None
    alarms: tuple[AlarmView, ...]
    count_field: CounterView
    count_season: CounterView
    count_undo: tuple[str, ...]
    tank: TankView
    calibration: CalibrationView | None
    settings_pending: bool
    settings_state: dict[str, str]
    ndvi_per_sensor: tuple[float | None, ...]
    cv_threshold_pct: float
    switch_speed_kmh: float
    applied_kg_ha: tuple[float, float]


def applied_kg_ha(snap: Snapshot, cfg: TerminalConfig) -> tuple[float, float]:
    """The rate each layer applies now, from its measured metering speed and the ECU's
    selected speed (eq. 4 inverted, in the C core); 0 standing or while the ECU is not heard."""
    if not snap.ecu_live:
        return (0.0, 0.0)
    m = cfg.machine
    lo = cfg.speed.min_work_speed_kmh
    return (
        meter_rate_kg_ha(m.width_m, snap.meter_rpm[0], snap.v_kmh, m.kg_per_rev_upper, lo),
        meter_rate_kg_ha(m.width_m, snap.meter_rpm[1], snap.v_kmh, m.kg_per_rev_lower, lo),
    )


def speed_why(snap: Snapshot, cfg: TerminalConfig) -> Text | None:
    """Why the ECU meters on the speed it does, in the terms of the paper's rule (None while
    the ECU is not heard)."""
    if not snap.ecu_live:
        return None
    s = cfg.speed
    src = text(f"source.{snap.source}")
    if s.mode != SpeedMode.PAPER:
        return text("why.mode", source=src, mode=text(f"value.{SpeedMode(s.mode).value}"))
    faults = Fault(snap.faults)
    if snap.source == Source.NONE:
        return text("why.none")
    if snap.source == Source.GNSS and Fault.WHEEL_ENCODER in faults:
        return text("why.encoder_fault")
    if Fault.GNSS_FROZEN in faults:
        return text("why.gnss_frozen")
    if snap.gnss_kmh is None or Fault.GNSS_LOST in faults:
        return text("why.no_gnss", source=src)
    cmp_v = snap.gnss_kmh if s.switch_compare == Compare.GNSS else snap.v_wheel_kmh
    cv = text("why.cv_none") if snap.cv_pct is None else text("why.cv", cv=snap.cv_pct)
    rule = dict(
        cv=cv,
        threshold=s.cv_threshold_pct,
        compare=text(f"source.{s.switch_compare}"),
        kmh=cmp_v,
        switch_kmh=s.switch_speed_kmh,
    )
    if snap.source == Source.GNSS:
        return text("why.gnss", **rule)
    if not snap.uniform:
        return text("why.not_uniform", **rule)
    return text("why.slow", **rule)
