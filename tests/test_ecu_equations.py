"""The paper's equations and the dual speed rule, through the binding, on worked values."""

from __future__ import annotations

import math

import numpy as np
import pytest
from topdress.ecu._core import ffi, lib

from topdress.ecu import (
    cv_pct,
    meter_target_rpm,
    slip_measured_pct,
    slip_model_pct,
    slip_model_speed_kmh,
    speed_rule,
    wheel_speed_kmh,
)
from topdress.errors import EcuError
from topdress.protocol import Compare, Source, SpeedMode


def test_eq1_wheel_speed() -> None:
    # 500 Hz on a 500 PPR wheel = 1 rev/s; circumference 2*pi*0.0615 m = 0.3864 m -> 1.3911 km/h
    assert wheel_speed_kmh(500.0) == pytest.approx(2 * math.pi * 0.0615 * 3.6, rel=1e-6)
    assert wheel_speed_kmh(500.0) == pytest.approx(1.3911, abs=1e-4)
    # the pulse rate of 6.0 km/h (the switch speed): 2156.6 Hz
    f6 = 6.0 / 3.6 / (2 * math.pi * 0.0615) * 500
    assert f6 == pytest.approx(2156.6, abs=0.1)
    assert wheel_speed_kmh(f6) == pytest.approx(6.0, rel=1e-6)
    assert wheel_speed_kmh(100.0, radius_m=0.1, ppr=100) == pytest.approx(2 * math.pi * 0.1 * 3.6)
    assert wheel_speed_kmh(0.0) == 0.0
    with pytest.raises(EcuError):
        wheel_speed_kmh(10.0, ppr=0)


def _wheel_updates(hz_of_t: list[int], update_ms: int, samples: int) -> list[tuple[int, float]]:
    """Feed 10 ms steps of pulses (hz_of_t[i] during step i) from t = 0; the speed updates."""
    w = ffi.new("td_wheel_t *")
    assert lib.td_wheel_init(w, 0.0615, 500, samples, update_ms) == lib.TD_OK
    out = ffi.new("float *")
    assert not lib.td_wheel_step(w, 0, 0, out)
    count, updates = 0, []
    for i, hz in enumerate(hz_of_t, start=1):
        count += hz // 100
        if lib.td_wheel_step(w, i * 10_000, count, out):
            updates.append((i * 10, float(out[0])))
    return updates


def test_wheel_speed_is_updated_every_500_ms() -> None:
    updates = _wheel_updates([2000] * 100 + [3000] * 50, update_ms=500, samples=4)
    assert [t for t, _ in updates] == [500, 1000, 1500]
    assert updates[0][1] == pytest.approx(wheel_speed_kmh(2000.0), rel=1e-5)
    assert updates[2][1] == pytest.approx(wheel_speed_kmh(3000.0), rel=1e-5)


def test_wheel_speed_is_the_mean_of_the_frequency_samples() -> None:
    # 4 samples of 100 ms: 1000, 1000, 3000, 3000 Hz -> the mean 2000 Hz, not the last sample
    updates = _wheel_updates([1000] * 20 + [3000] * 20, update_ms=400, samples=4)
    assert updates == [(400, pytest.approx(wheel_speed_kmh(2000.0), rel=1e-5))]
    updates = _wheel_updates([1000] * 30 + [3000] * 10, update_ms=400, samples=4)
    assert updates[0][1] == pytest.approx(wheel_speed_kmh(1500.0), rel=1e-5)


def test_eq2_cv_is_sample_sd_over_mean() -> None:
    g = [6.0, 6.2, 5.8, 6.1, 5.9]
    # mean 6.0, sample SD sqrt(0.1/4) = 0.1581 -> 2.635 %
    assert cv_pct(g) == pytest.approx(2.6352, abs=1e-3)
    assert cv_pct(g) == pytest.approx(np.std(g, ddof=1) / np.mean(g) * 100, rel=1e-5)
    assert cv_pct([5.0, 5.0, 5.0]) == 0.0
    assert cv_pct([0.0, 0.0, 0.0, 0.0, 0.0]) == 0.0  # standing still counts as uniform
    assert cv_pct([0.0, 0.1, 0.0, 0.0, 0.0]) is None  # mean ~0 but moving: undefined
    assert cv_pct([4.0]) is None
    with pytest.raises(EcuError):
        cv_pct([])


def test_eq2_queue_keeps_the_last_n() -> None:
    q = ffi.new("td_speedq_t *")
    assert lib.td_speedq_init(q, 5) == lib.TD_OK
    assert lib.td_speedq_init(q, 1) == lib.TD_E_ARG
    assert lib.td_speedq_init(q, 17) == lib.TD_E_ARG
    assert lib.td_speedq_init(q, 5) == lib.TD_OK
    for v in (1.0, 2.0, 3.0, 4.0):
        lib.td_speedq_push(q, v)
    assert lib.td_speedq_cv_pct(q, 5) < 0  # only 4 of N = 5 values: undefined
    for v in (6.0, 6.2, 5.8, 6.1, 5.9):  # the first four values fall out
        lib.td_speedq_push(q, v)
    assert lib.td_speedq_cv_pct(q, 5) == pytest.approx(2.6352, abs=1e-3)
    assert lib.td_speedq_cv_pct(q, 3) == pytest.approx(cv_pct([5.8, 6.1, 5.9]), rel=1e-6)


def test_eq3_measured_slip() -> None:
    # 40 m run (the paper's), wheel turned 98.3 revolutions of 0.38642 m = 37.98 m -> 5.04 %
    assert slip_measured_pct(98.3, 0.0615, 40.0) == pytest.approx(
        abs(2 * math.pi * 0.0615 * 98.3 - 40) / 40 * 100, rel=1e-5
    )
    revs_5pct = 40 * 0.95 / (2 * math.pi * 0.0615)
    assert slip_measured_pct(revs_5pct, 0.0615, 40.0) == pytest.approx(5.0, abs=1e-4)
    assert slip_measured_pct(0.0, 0.0615, 40.0) == pytest.approx(100.0)
    for bad in (0.0, -40.0):
        with pytest.raises(EcuError, match="distance"):
            slip_measured_pct(100, 0.0615, bad)


def test_eq5_slip_model_gives_5_percent_at_6_kmh() -> None:
    assert slip_model_pct(6.0) == pytest.approx(5.009, abs=1e-3)
    assert slip_model_pct(0.0) == pytest.approx(0.773)
    assert slip_model_pct(8.0) == pytest.approx(0.167 * 64 - 0.296 * 8 + 0.773, rel=1e-6)
    v = slip_model_speed_kmh(5.0)
    assert v is not None and v == pytest.approx(5.995, abs=1e-3)  # V_Grmax = 6.0 km/h
    assert round(v, 1) == 6.0
    assert slip_model_pct(v) == pytest.approx(5.0, abs=1e-4)
    assert slip_model_speed_kmh(0.5) is None  # the parabola's minimum is 0.642 %


def test_eq4_metering_target() -> None:
    # the header's check: 3.6 m, 200 kg/ha, 6 km/h, 0.3 kg/r -> 24.0 r/min
    assert meter_target_rpm(3.6, 200.0, 6.0, 0.3) == pytest.approx(24.0)
    # linear in w, q and v, inverse in p
    assert meter_target_rpm(3.6, 200.0, 3.0, 0.3) == pytest.approx(12.0)
    assert meter_target_rpm(3.6, 100.0, 6.0, 0.15) == pytest.approx(24.0)
    assert meter_target_rpm(7.2, 200.0, 6.0, 0.3) == pytest.approx(48.0)
    # a jump in speed dv gives dR = w*q*dv/(600 p): 0.4 km/h at 3.6 m, 200 kg/ha, 0.3 kg/r = 1.6
    d_r = meter_target_rpm(3.6, 200.0, 3.9, 0.3) - meter_target_rpm(3.6, 200.0, 3.5, 0.3)
    assert d_r == pytest.approx(1.6, abs=1e-4)
    # below the minimum working speed, no rate, NaN speed -> 0; boundary is inclusive
    assert meter_target_rpm(3.6, 200.0, 0.49, 0.3, min_speed_kmh=0.5) == 0.0
    assert meter_target_rpm(3.6, 200.0, 0.5, 0.3, min_speed_kmh=0.5) == pytest.approx(2.0)
    assert meter_target_rpm(3.6, 0.0, 6.0, 0.3) == 0.0
    assert meter_target_rpm(3.6, 200.0, float("nan"), 0.3) == 0.0
    with pytest.raises(EcuError, match="kg_per_rev"):
        meter_target_rpm(3.6, 200.0, 6.0, 0.0)


# mode, compare, cv, v_wheel, v_gnss, gnss_valid, wheel_valid -> source
# (threshold 4.2 %, switch speed 6.0 km/h)
D, W, G = SpeedMode.PAPER, SpeedMode.WHEEL_ONLY, SpeedMode.GNSS_ONLY
TRUTH = [
    (D, Compare.GNSS, 2.0, 7.0, 8.0, True, True, Source.GNSS),  # uniform, fast: GNSS
    (D, Compare.GNSS, 4.19, 6.0, 6.01, True, True, Source.GNSS),  # just inside both limits
    (D, Compare.GNSS, 4.2, 7.0, 8.0, True, True, Source.WHEEL),  # CV == threshold: wheel
    (D, Compare.GNSS, 4.21, 7.0, 8.0, True, True, Source.WHEEL),  # accelerating
    (D, Compare.GNSS, 2.0, 7.0, 6.0, True, True, Source.WHEEL),  # v == switch speed: wheel
    (D, Compare.GNSS, 2.0, 7.0, 5.99, True, True, Source.WHEEL),  # slow
    (D, Compare.GNSS, None, 7.0, 8.0, True, True, Source.WHEEL),  # CV undefined
    (D, Compare.GNSS, 0.0, 0.0, 0.0, True, True, Source.WHEEL),  # standing still
    (D, Compare.WHEEL, 2.0, 5.9, 8.0, True, True, Source.WHEEL),  # compare the wheel speed
    (D, Compare.WHEEL, 2.0, 6.1, 5.0, True, True, Source.GNSS),
    (D, Compare.GNSS, 2.0, 7.0, 8.0, False, True, Source.WHEEL),  # GNSS lost
    (D, Compare.GNSS, 9.0, 0.0, 3.0, True, False, Source.GNSS),  # wheel encoder fault
    (D, Compare.GNSS, 2.0, 7.0, 8.0, False, False, Source.NONE),
    (W, Compare.GNSS, 2.0, 7.0, 8.0, True, True, Source.WHEEL),  # wheel only
    (W, Compare.GNSS, 2.0, 7.0, 8.0, True, False, Source.GNSS),  # ... unless it failed
    (G, Compare.GNSS, 9.0, 1.0, 2.0, True, True, Source.GNSS),  # GNSS only
    (G, Compare.GNSS, 2.0, 7.0, 8.0, False, True, Source.WHEEL),  # ... unless it is lost
]


@pytest.mark.parametrize(("mode", "cmp", "cv", "vw", "vg", "gok", "wok", "want"), TRUTH)
def test_switching_rule_truth_table(
    mode: SpeedMode,
    cmp: Compare,
    cv: float | None,
    vw: float,
    vg: float,
    gok: bool,
    wok: bool,
    want: Source,
) -> None:
    assert speed_rule(mode, cmp, cv, 4.2, 6.0, vw, vg, gok, wok) is want
