"""ECU parameters on CAN: id <-> DBC signal <-> td_params_t / EcuParams field <-> the
terminal's configuration key, in one table.

Resolution, unit and range come from the DBC (PcParamSet, multiplexed by ParamId); the field
each signal sets, the configuration key it comes from and the ECU's default are written here.
The configuration's keys and ranges, the ECU parameters it pushes, the display's fields and the
field a refused parameter is shown at all come from this table.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from functools import cache

from topdress.errors import ProtocolError
from topdress.protocol.dbc import dbc_text

# The one table of ECU parameters. Id, resolution, unit and range come from the DBC
# (PcParamSet, multiplexed by ParamId), and so does the td_params_t / EcuParams field each sets
# (the signal's TdField attribute, which the C core's table is generated from); only what the
# DBC cannot say is written here: DBC signal -> (the terminal's configuration key, the ECU's
# default (td_params_defaults; a test holds it to the C core)). The configuration key is also
# the display's field and where a refusal is shown.
_TABLE: dict[str, tuple[str, float]] = {
    "WorkingWidth": ("machine.width_m", 3.6),
    "UpperKgPerRev": ("machine.kg_per_rev_upper", 0.3),
    "LowerKgPerRev": ("machine.kg_per_rev_lower", 0.3),
    "WheelRadius": ("machine.wheel_radius_m", 0.0615),
    "WheelPulsesPerRev": ("machine.wheel_ppr", 500),
    "QueueLength": ("speed.queue_len", 5),
    "CvWindow": ("speed.cv_window", 5),
    "CvThreshold": ("speed.cv_threshold_pct", 4.2),
    "SwitchSpeed": ("speed.switch_speed_kmh", 6.0),
    "SpeedMode": ("speed.mode", 0),
    "SwitchCompare": ("speed.switch_compare", 0),
    "PidKp": ("ecu.pid_kp", 0.015),
    "PidKi": ("ecu.pid_ki", 0.01),
    "PidKd": ("ecu.pid_kd", 0.0),
    "PidKff": ("ecu.pid_kff", 0.01666667),
    "CmdTimeout": ("ecu.cmd_timeout_ms", 1500),
    "GnssTimeout": ("ecu.gnss_timeout_ms", 1200),
    "MinWorkSpeed": ("speed.min_work_speed_kmh", 0.5),
    "WheelUpdatePeriod": ("ecu.wheel_update_ms", 500),
    "WheelSamples": ("ecu.wheel_samples", 4),
    "MeterCountsPerRev": ("ecu.meter_counts_per_rev", 6400),
    "FanMinSpeed": ("ecu.fan_min_rpm", 2000),
    "FanPulsesPerRev": ("ecu.fan_ppr", 30),
    "EncFaultGnssSpeed": ("ecu.enc_fault_gnss_kmh", 2.0),
    "EncFaultTime": ("ecu.enc_fault_time_ms", 2000),
    "BlockedTime": ("ecu.blocked_time_ms", 1000),
    "StatusPeriod": ("ecu.status_period_ms", 100),
    "SlipComp": ("ecu.slip_comp", 0),
    "GnssLag": ("ecu.gnss_lag_ms", 0),
    "LeadMeter": ("lookahead.meter_ms", 0),
    "LeadAirLine": ("lookahead.airline_ms", 0),
    "FusedJerk": ("ecu.fused_jerk_ms3", 0.3),
    "FusedGnssStd": ("ecu.fused_gnss_std_kmh", 0.2),
    "FusedWheelNoise": ("ecu.fused_wheel_noise_pct", 15.0),
    "WheelStopTime": ("ecu.wheel_stop_ms", 300),
    "DriveAdapt": ("ecu.drive_adapt", 1),
    "MeterTau": ("ecu.meter_tau_ms", 200),
    "LeadStop": ("lookahead.stop_ms", 0),
    "GnssLagAuto": ("ecu.gnss_lag_auto", 1),
}

# A multiplexed signal of PcParamSet: ` SG_ Name m12 : 32|32@1+ (0.01,0) [0|25] "km/h" ECU`.
# Read from the DBC's text, not through cantools, so that a screen can have the table without
# loading cantools and python-can (a test holds this reading to cantools').
_FIELD = re.compile(
    r'^BA_ "TdField" SG_ \d+ (?P<name>\w+) "(?P<field>\w+)(?:\[(?P<index>\d+)\])?";', re.M
)
_SIGNAL = re.compile(
    r"^ SG_ (?P<name>\w+) m(?P<id>\d+) : \d+\|\d+@[01][+-] "
    r"\((?P<scale>[^,]+),[^)]+\) \[(?P<lo>[^|]+)\|(?P<hi>[^\]]+)\] \"(?P<unit>[^\"]*)\""
)


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
    config_key: str  # `section.key` of the terminal's configuration (and the display's field)
    default: float  # what the ECU runs with until the parameter is set

    @property
    def section(self) -> str:
        """The configuration section of the parameter (`machine`, `speed`, `ecu`, ...)."""
        return self.config_key.split(".", 1)[0]

    @property
    def name(self) -> str:
        """The parameter's key within its configuration section."""
        return self.config_key.split(".", 1)[1]

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
    for line in _param_set_lines():
        m = _SIGNAL.match(line)
        if m is None:
            raise ProtocolError(f"PcParamSet: cannot read the DBC line {line.strip()!r}")
        field, index = _fields()[m["name"]]
        config_key, default = _TABLE[m["name"]]
        specs.append(
            ParamSpec(
                id=int(m["id"]),
                signal=m["name"],
                field=field,
                index=index,
                unit=m["unit"],
                scale=float(m["scale"]),
                minimum=float(m["lo"]),
                maximum=float(m["hi"]),
                config_key=config_key,
                default=default,
            )
        )
    return tuple(sorted(specs, key=lambda s: s.id))


@cache
def _fields() -> dict[str, tuple[str, int | None]]:
    """The td_params_t field each PcParamSet signal sets (its TdField attribute in the DBC):
    signal -> (field, index into an array field or None)."""
    out = {}
    for m in _FIELD.finditer(dbc_text()):
        out[m["name"]] = (m["field"], None if m["index"] is None else int(m["index"]))
    return out


def _param_set_lines() -> list[str]:
    """The multiplexed signal lines of PcParamSet in the DBC (its multiplexer left out)."""
    lines = dbc_text().splitlines()
    start = next(i for i, line in enumerate(lines) if re.match(r"^BO_ \d+ PcParamSet:", line))
    out = []
    for line in lines[start + 1 :]:
        if not line.startswith(" SG_ "):
            break
        if " M : " not in line:
            out.append(line)
    return out


@cache
def _index() -> dict[str | int, ParamSpec]:
    out: dict[str | int, ParamSpec] = {}
    for spec in params():
        out[spec.id] = spec
        out[spec.signal] = spec
        out[spec.key] = spec
        out[spec.config_key] = spec
    return out


def param(key: int | str) -> ParamSpec:
    """Look a parameter up by id, DBC signal name, EcuParams name (`kg_per_rev[1]`) or
    configuration key (`machine.kg_per_rev_lower`)."""
    try:
        return _index()[key]
    except KeyError:
        raise ProtocolError(f"unknown ECU parameter {key!r}") from None


def param_name(key: int | str) -> str:
    """The DBC name of a parameter (`CvThreshold`), for messages."""
    return param(key).signal
