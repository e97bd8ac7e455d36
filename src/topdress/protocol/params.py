"""ECU parameters on CAN: id <-> DBC signal <-> td_params_t / EcuParams field.

Resolution, unit and range come from the DBC (PcParamSet, multiplexed by ParamId); only the
field each signal sets is written here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

from topdress.errors import ProtocolError
from topdress.protocol.dbc import message

# DBC signal -> (EcuParams field, index into an array field or None).
_FIELDS: dict[str, tuple[str, int | None]] = {
    "WorkingWidth": ("working_width_m", None),
    "UpperKgPerRev": ("kg_per_rev", 0),
    "LowerKgPerRev": ("kg_per_rev", 1),
    "WheelRadius": ("wheel_radius_m", None),
    "WheelPulsesPerRev": ("wheel_ppr", None),
    "QueueLength": ("queue_len", None),
    "CvWindow": ("cv_window", None),
    "CvThreshold": ("cv_threshold_pct", None),
    "SwitchSpeed": ("switch_speed_kmh", None),
    "SpeedMode": ("speed_mode", None),
    "SwitchCompare": ("switch_compare", None),
    "PidKp": ("pid_kp", None),
    "PidKi": ("pid_ki", None),
    "PidKd": ("pid_kd", None),
    "PidKff": ("pid_kff", None),
    "CmdTimeout": ("cmd_timeout_ms", None),
    "GnssTimeout": ("gnss_timeout_ms", None),
    "MinWorkSpeed": ("min_work_speed_kmh", None),
    "WheelUpdatePeriod": ("wheel_update_ms", None),
    "WheelSamples": ("wheel_samples", None),
    "MeterCountsPerRev": ("meter_counts_per_rev", None),
    "FanMinSpeed": ("fan_min_rpm", None),
    "FanPulsesPerRev": ("fan_ppr", None),
    "EncFaultGnssSpeed": ("enc_fault_gnss_kmh", None),
    "EncFaultTime": ("enc_fault_time_ms", None),
    "BlockedTime": ("blocked_time_ms", None),
    "StatusPeriod": ("status_period_ms", None),
    "SlipComp": ("slip_comp", None),
    "GnssLag": ("gnss_lag_ms", None),
    "LeadMeter": ("lead_meter_ms", None),
    "LeadAirLine": ("lead_air_ms", None),
    "FusedJerk": ("fused_jerk_ms3", None),
    "FusedGnssStd": ("fused_gnss_std_kmh", None),
    "FusedWheelNoise": ("fused_wheel_noise_pct", None),
    "WheelStopTime": ("wheel_stop_ms", None),
    "DriveAdapt": ("drive_adapt", None),
    "MeterTau": ("meter_tau_ms", None),
    "LeadStop": ("lead_stop_ms", None),
    "GnssLagAuto": ("gnss_lag_auto", None),
}


def decimals(scale: float) -> int:
    """Decimal places of a DBC resolution (0.01 -> 2), to give back the value that was sent."""
    return max(0, -math.floor(math.log10(scale) + 1e-9))


@dataclass(frozen=True)
class ParamSpec:
    """One ECU parameter as carried by PcParamSet."""

    id: int
    signal: str
    field: str
    index: int | None
    unit: str
    scale: float
    minimum: float
    maximum: float

    @property
    def key(self) -> str:
        """The EcuParams name: the field, or `field[index]` for a per-layer value."""
        return self.field if self.index is None else f"{self.field}[{self.index}]"

    @property
    def integer(self) -> bool:
        """True when the parameter takes whole numbers only."""
        return self.scale == 1

    def to_raw(self, value: float) -> int:
        """Physical value -> raw DBC units (rounded to the resolution)."""
        return round(value / self.scale)

    def from_raw(self, raw: int) -> float:
        """Raw DBC units -> physical value."""
        return round(raw * self.scale, decimals(self.scale))

    def check(self, value: float) -> None:
        """Raise ProtocolError if `value` cannot be sent for this parameter."""
        if value != value or not self.minimum <= value <= self.maximum:
            raise ProtocolError(
                f"parameter {self.signal} ({self.key}) = {value} {self.unit} "
                f"outside {self.minimum:g}..{self.maximum:g}"
            )
        if self.integer and value != int(value):
            raise ProtocolError(f"parameter {self.signal} ({self.key}) = {value} is not whole")


@cache
def params() -> tuple[ParamSpec, ...]:
    """Every parameter, by id (1..39)."""
    specs = []
    for sig in message("PcParamSet").signals:
        if sig.is_multiplexer:
            continue
        field, index = _FIELDS[sig.name]
        specs.append(
            ParamSpec(
                id=sig.multiplexer_ids[0],
                signal=sig.name,
                field=field,
                index=index,
                unit=sig.unit or "",
                scale=float(sig.scale),
                minimum=float(sig.minimum),
                maximum=float(sig.maximum),
            )
        )
    return tuple(sorted(specs, key=lambda s: s.id))


@cache
def _index() -> dict[str | int, ParamSpec]:
    out: dict[str | int, ParamSpec] = {}
    for spec in params():
        out[spec.id] = spec
        out[spec.signal] = spec
        out[spec.key] = spec
    return out


def param(key: int | str) -> ParamSpec:
    """Look a parameter up by id, DBC signal name or EcuParams name (`kg_per_rev[1]`)."""
    try:
        return _index()[key]
    except KeyError:
        raise ProtocolError(f"unknown ECU parameter {key!r}") from None


def param_name(key: int | str) -> str:
    """The DBC name of a parameter (`CvThreshold`), for messages."""
    return param(key).signal
