"""The pure functions of the C core (paper eqs. 1-5, the speed rule) and its PID, from Python."""

from __future__ import annotations

from collections.abc import Sequence

from topdress.ecu._core import ffi, lib
from topdress.ecu.params import check
from topdress.errors import EcuError
from topdress.protocol import Compare, Source, SpeedMode

WHEEL_RADIUS_M = 0.0615  # paper: wheel diameter 12.3 cm
WHEEL_PPR = 500  # paper: 500 pulses per revolution


def wheel_speed_kmh(f_hz: float, radius_m: float = WHEEL_RADIUS_M, ppr: int = WHEEL_PPR) -> float:
    """Eq. 1: V_G = 2*pi*f*r*3.6/K, km/h."""
    if not 1 <= ppr <= 0xFFFF:
        raise EcuError(lib.TD_E_ARG, f"wheel_speed_kmh: ppr {ppr} outside 1..65535")
    return float(lib.td_wheel_speed_kmh(f_hz, radius_m, ppr))


def cv_pct(values: Sequence[float]) -> float | None:
    """Eq. 2: sample SD / mean * 100 %; None where the core leaves it undefined."""
    n = len(values)
    if not 1 <= n <= 255:
        raise EcuError(lib.TD_E_ARG, f"cv_pct: {n} values, expected 1..255")
    cv = float(lib.td_cv_pct(ffi.new("float[]", list(values)), n))
    return None if cv < 0 else cv


def slip_measured_pct(revolutions: float, radius_m: float, distance_m: float) -> float:
    """Eq. 3: |2*pi*r*n - L| / L * 100 %."""
    slip = float(lib.td_slip_measured_pct(revolutions, radius_m, distance_m))
    if slip < 0:
        raise EcuError(lib.TD_E_ARG, f"slip_measured_pct: distance {distance_m} m must be > 0")
    return slip


def slip_model_pct(v_kmh: float) -> float:
    """Eq. 5: 0.167 v^2 - 0.296 v + 0.773 %, wheat stubble."""
    return float(lib.td_slip_model_pct(v_kmh))


def slip_model_speed_kmh(slip_pct: float) -> float | None:
    """The speed at which eq. 5 reaches `slip_pct` (5 % -> ~6.0 km/h); None if never."""
    v = float(lib.td_slip_model_speed_kmh(slip_pct))
    return None if v < 0 else v


def meter_target_rpm(
    width_m: float,
    rate_kg_ha: float,
    v_kmh: float,
    kg_per_rev: float,
    min_speed_kmh: float = 0.0,
) -> float:
    """Eq. 4: R = w*q*v / (600*p), r/min; zero below min_speed_kmh or for no rate."""
    r = float(lib.td_meter_target_rpm(width_m, rate_kg_ha, v_kmh, kg_per_rev, min_speed_kmh))
    if r < 0:
        raise EcuError(lib.TD_E_ARG, f"meter_target_rpm: kg_per_rev {kg_per_rev} must be > 0")
    return r


def meter_rate_kg_ha(
    width_m: float,
    meter_rpm: float,
    v_kmh: float,
    kg_per_rev: float,
    min_speed_kmh: float = 0.0,
) -> float:
    """Eq. 4 inverted: q = 600*p*R / (w*v), kg/ha; zero at a standstill, below min_speed_kmh
    or with the meter at rest."""
    q = float(lib.td_meter_rate_kg_ha(width_m, meter_rpm, v_kmh, kg_per_rev, min_speed_kmh))
    if q < 0:
        raise EcuError(
            lib.TD_E_ARG,
            f"meter_rate_kg_ha: width {width_m} and kg_per_rev {kg_per_rev} must be > 0",
        )
    return q


def speed_rule(
    mode: SpeedMode,
    compare: Compare,
    cv: float | None,
    cv_threshold_pct: float,
    switch_speed_kmh: float,
    v_wheel_kmh: float,
    v_gnss_kmh: float,
    gnss_valid: bool = True,
    wheel_valid: bool = True,
) -> Source:
    """The dual speed rule with its fail-safes (td_speedsel_rule); cv None = undefined."""
    code = lib.td_speedsel_rule(
        mode.code,
        compare.code,
        -1.0 if cv is None else cv,
        cv_threshold_pct,
        switch_speed_kmh,
        v_wheel_kmh,
        v_gnss_kmh,
        gnss_valid,
        wheel_valid,
    )
    return Source.from_code(code)


class Pid:
    """The core's PID (td_pid_t): feed-forward, limits, anti-windup, filtered derivative."""

    def __init__(
        self,
        kp: float,
        ki: float,
        kd: float = 0.0,
        kff: float = 0.0,
        out_min: float = 0.0,
        out_max: float = 1.0,
    ) -> None:
        if not out_min < out_max:
            raise EcuError(lib.TD_E_ARG, f"Pid: out_min {out_min} must be < out_max {out_max}")
        self._pid = ffi.new("td_pid_t *")
        lib.td_pid_init(self._pid, kp, ki, kd, kff, out_min, out_max)

    def step(self, setpoint: float, measured: float, dt_s: float) -> float:
        """One update over dt_s seconds; the clamped output."""
        if not dt_s > 0:
            check(lib.TD_E_ARG, f"Pid.step: dt_s {dt_s} must be > 0")
        return float(lib.td_pid_step(self._pid, setpoint, measured, dt_s))

    def reset(self) -> None:
        """Forget the integral and derivative memory."""
        lib.td_pid_reset(self._pid)

    @property
    def integral(self) -> float:
        """The integral term, in output units."""
        return float(self._pid.integ)
