"""The core's metering PID on a first-order motor model simulated here, in virtual time."""

from __future__ import annotations

import numpy as np
import pytest

from topdress.ecu import EcuParams, Pid
from topdress.errors import EcuError

DT = 0.01  # the control period
RPM_AT_FULL = 60.0  # reference metering motor: full duty -> 60 r/min
TAU_S = 0.15


def _run(pid: Pid, setpoints: np.ndarray, w0: float = 0.0, tau_s: float = TAU_S) -> np.ndarray:
    """Speed of the motor (r/min) after each step; the motor saturates at full duty."""
    w, out = w0, np.empty(len(setpoints))
    for i, sp in enumerate(setpoints):
        u = pid.step(float(sp), w, DT)
        w += (RPM_AT_FULL * u - w) * DT / tau_s
        out[i] = w
    return out


def _default_pid() -> Pid:
    p = EcuParams.defaults()
    return Pid(p.pid_kp, p.pid_ki, p.pid_kd, p.pid_kff, 0.0, 1.0)


def _settling_s(w: np.ndarray, target: float, band: float = 0.05) -> float:
    """Time from the step until the speed stays within +-band of the target."""
    outside = np.nonzero(np.abs(w - target) > band * abs(target))[0]
    return 0.0 if len(outside) == 0 else float(outside[-1] + 1) * DT


def test_step_response_from_rest() -> None:
    target = 24.0  # eq. 4 at 3.6 m, 200 kg/ha, 6 km/h, 0.3 kg/r
    w = _run(_default_pid(), np.full(2000, target))
    overshoot_pct = (w.max() - target) / target * 100
    assert overshoot_pct < 8.7  # the paper's mean overshoot
    assert _settling_s(w, target) < 1.3  # the paper's mean response time
    assert w[4] > 0.4 * target  # not sluggish: 40 % of the way within 50 ms
    assert abs(w[299] - target) < 0.8  # the paper's mean steady-state error, at 3 s
    assert abs(w[-1] - target) < 0.05  # and the integral removes what is left


def test_downward_jump_as_in_table_5() -> None:
    # deceleration: the target drops by 6.6 r/min (Table 5, first row) from a settled 30 r/min
    sp = np.concatenate([np.full(300, 30.0), np.full(300, 23.4)])
    w = _run(_default_pid(), sp)[300:]
    undershoot_pct = (23.4 - w.min()) / 6.6 * 100
    assert undershoot_pct < 7.3
    assert _settling_s(w, 23.4) < 1.2
    assert abs(w[-1] - 23.4) < 0.6


def test_integral_removes_a_load_error_feed_forward_alone_cannot() -> None:
    # a loaded motor gives only 48 r/min at full duty; feed-forward alone stays 20 % low
    def run(pid: Pid) -> float:
        w = 0.0
        for _ in range(3000):
            u = pid.step(24.0, w, DT)
            w += (48.0 * u - w) * DT / TAU_S
        return w

    assert run(Pid(0.0, 0.0, 0.0, 1 / 60)) == pytest.approx(19.2, abs=0.01)
    assert run(_default_pid()) == pytest.approx(24.0, abs=0.1)


def test_anti_windup_after_saturation() -> None:
    # 5 s asking 100 r/min of a motor that does 60, then 30 r/min
    pid = _default_pid()
    w = _run(pid, np.full(500, 100.0))
    assert w[-1] == pytest.approx(60.0, abs=0.1)
    # integration stops while the output is saturated: a plain PI would hold
    # 0.01 * 40 r/min * 5 s = 2.0 of duty here and stay at full duty for seconds
    assert pid.integral == pytest.approx(0.0, abs=0.01)
    w = _run(pid, np.full(200, 30.0), w0=float(w[-1]))
    assert _settling_s(w, 30.0) < 0.5  # leaves the limit at once


def test_output_limits() -> None:
    pid = Pid(1.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    assert pid.step(5.0, 0.0, DT) == 1.0
    assert pid.step(0.0, 5.0, DT) == 0.0
    assert pid.step(0.0, -0.25, DT) == pytest.approx(0.25)
    pid = Pid(1.0, 0.0, 0.0, 0.0, -0.5, 0.5)
    assert pid.step(0.0, 3.0, DT) == -0.5


def test_filtered_derivative_acts_on_the_measurement_only() -> None:
    pid = Pid(0.0, 0.0, 0.01, 0.0, -100.0, 100.0)
    assert pid.step(10.0, 0.0, DT) == 0.0  # a setpoint step gives no derivative kick
    # measurement jumps by 10 in one step: raw D = -0.01 * 10 / 0.01 = -10, low-passed with
    # tau 0.05 s: -10 * 0.01 / 0.06 = -1.667, then it decays by 0.05 / 0.06 per step
    assert pid.step(10.0, 10.0, DT) == pytest.approx(-10 / 6, rel=1e-5)
    assert pid.step(10.0, 10.0, DT) == pytest.approx(-10 / 6 * 5 / 6, rel=1e-5)
    pid.reset()
    assert pid.integral == 0.0
    assert pid.step(10.0, 10.0, DT) == 0.0  # primed again on the first measurement


def test_bad_arguments() -> None:
    with pytest.raises(EcuError, match="out_min"):
        Pid(1.0, 0.0, out_min=1.0, out_max=1.0)
    with pytest.raises(EcuError, match="dt_s"):
        _default_pid().step(1.0, 0.0, 0.0)
