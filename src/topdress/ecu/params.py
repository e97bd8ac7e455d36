"""EcuParams: the td_params_t parameter set as a Python value, validated by the C core."""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any

from topdress.ecu._core import ffi, lib
from topdress.errors import EcuError
from topdress.protocol import param

ERROR_NAMES = {
    lib.TD_OK: "ok",
    lib.TD_E_ARG: "bad argument",
    lib.TD_E_UNKNOWN_ID: "unknown CAN id",
    lib.TD_E_LENGTH: "wrong frame length",
    lib.TD_E_RANGE: "value out of range",
    lib.TD_E_BUSY: "busy (running)",
    lib.TD_E_UNKNOWN_PARAM: "unknown parameter",
    lib.TD_E_INCONSISTENT: "inconsistent parameters",
    lib.TD_E_FULL: "transmit queue full",
}


def check(code: int, what: str) -> int:
    """Raise EcuError for a negative C return code, naming it."""
    if code < 0:
        raise EcuError(code, f"{what}: {ERROR_NAMES.get(code, 'error')}")
    return code


def _f32(x: float) -> float:
    # C floats carry ~7 significant digits: give back the number that was meant (0.0615).
    return float(f"{x:.7g}")


@dataclass(frozen=True)
class EcuParams:
    """Every field of td_params_t (units and ranges in ecu/include/td_params.h)."""

    working_width_m: float
    kg_per_rev: tuple[float, float]
    wheel_radius_m: float
    wheel_ppr: int
    queue_len: int
    cv_window: int
    cv_threshold_pct: float
    switch_speed_kmh: float
    speed_mode: int
    switch_compare: int
    pid_kp: float
    pid_ki: float
    pid_kd: float
    pid_kff: float
    cmd_timeout_ms: int
    gnss_timeout_ms: int
    min_work_speed_kmh: float
    wheel_update_ms: int
    wheel_samples: int
    meter_counts_per_rev: int
    fan_min_rpm: int
    fan_ppr: int
    enc_fault_gnss_kmh: float
    enc_fault_time_ms: int
    blocked_time_ms: int
    status_period_ms: int
    slip_comp: int
    gnss_lag_ms: int
    lead_meter_ms: int
    lead_air_ms: int
    fused_jerk_ms3: float
    fused_gnss_std_kmh: float
    fused_wheel_noise_pct: float
    wheel_stop_ms: int
    drive_adapt: int
    meter_tau_ms: int
    lead_stop_ms: int
    gnss_lag_auto: int
    fan_rpm_at_full_duty: float
    fan_spinup_ms: int
    status_id: int
    command_id: int

    @classmethod
    def defaults(cls) -> EcuParams:
        """The core's defaults (td_params_default): the paper's values where it gives one."""
        p = ffi.new("td_params_t *")
        lib.td_params_default(p)
        return cls.from_c(p)

    @classmethod
    def from_c(cls, p: Any) -> EcuParams:
        """From a `td_params_t *`."""
        values: dict[str, Any] = {}
        for f in fields(cls):
            if f.name == "kg_per_rev":
                values[f.name] = (_f32(p.kg_per_rev[0]), _f32(p.kg_per_rev[1]))
            else:
                v = getattr(p, f.name)
                values[f.name] = _f32(v) if isinstance(v, float) else int(v)
        return cls(**values)

    def to_c(self) -> Any:
        """A new `td_params_t *` holding these values (not validated)."""
        p = ffi.new("td_params_t *")
        lib.td_params_default(p)  # also fills fields a newer header may add
        try:
            for f in fields(self):
                if f.name == "kg_per_rev":
                    p.kg_per_rev[0], p.kg_per_rev[1] = self.kg_per_rev
                else:
                    setattr(p, f.name, getattr(self, f.name))
        except (OverflowError, TypeError) as exc:
            raise EcuError(lib.TD_E_RANGE, f"EcuParams: value out of range ({exc})") from None
        return p

    def validate(self) -> EcuParams:
        """Check every range and cross-constraint in C; EcuError if the set is refused."""
        check(lib.td_params_validate(self.to_c()), "EcuParams")
        return self

    def with_param(self, key: int | str, value: float) -> EcuParams:
        """A copy with one CAN parameter set (by id, DBC name or field name), as the ECU would."""
        spec = param(key)
        p = self.to_c()
        check(lib.td_params_set(p, spec.id, value), f"parameter {spec.signal} = {value}")
        return EcuParams.from_c(p)

    def get(self, key: int | str) -> float:
        """The value of one CAN parameter (by id, DBC name or field name)."""
        spec = param(key)
        value: float = getattr(self, spec.field)
        return value if spec.index is None else self.kg_per_rev[spec.index]

    def replace(self, **changes: Any) -> EcuParams:
        """A copy with fields changed (not validated; Ecu() validates)."""
        return replace(self, **changes)
