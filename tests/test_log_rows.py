"""The state row the terminal logs: the Snapshot of the tick, whose ECU values come from the
ECU's own frames."""

from __future__ import annotations

import math

import pytest

from topdress import protocol
from topdress.ecu import Ecu
from topdress.log.rows import state_row
from topdress.view.snapshot import Snapshot, ecu_values


def test_row_from_the_frames_of_a_running_ecu_matches_its_state() -> None:
    ecu = Ecu()
    frames: dict[type, object] = {}
    # 5 km/h on the wheel (eq. 1 inverted: pulses/s = v / (2 pi r) * K), GNSS 5.0 km/h.
    pps = 5.0 / 3.6 / (2 * math.pi * 0.0615) * 500
    for k in range(1, 301):
        now_us = k * 10_000
        if k % 50 == 1:
            ecu.rx(protocol.encode_command(True, 3000, 150, 120, 5.0), now_us)
        fan = 15 * k  # 3000 r/min x 30 pulses/rev = 1500 pulses/s
        # Meters turning at their eq. 4 targets (15 and 12 r/min, 6400 counts/rev).
        ecu.step_raw(now_us, int(pps * k * 0.01), 16 * k, int(12.8 * k), fan, fan)
        for frame in ecu.tx_raw():
            decoded = protocol.decode(frame)
            frames[type(decoded)] = decoded
    values = ecu_values(
        frames[protocol.EcuStatus],  # type: ignore[arg-type]
        frames[protocol.EcuDiag],  # type: ignore[arg-type]
        frames[protocol.EcuSpeeds],  # type: ignore[arg-type]
        frames[protocol.EcuTargets],  # type: ignore[arg-type]
    )
    snap = Snapshot(**values, lat=45.75, lon=126.63, ndvi=0.62, rate_kg_ha=(150.0, 120.0))
    row = state_row(3.0, snap)
    s = ecu.state
    assert row.v_wheel_kmh == pytest.approx(s.v_wheel_kmh, abs=0.005)
    assert row.v_wheel_kmh == pytest.approx(5.0, abs=0.02)
    assert row.v_gnss_kmh == pytest.approx(5.0)
    assert row.v_kmh == pytest.approx(s.v_kmh, abs=0.005)
    assert row.source == "wheel"  # 5 km/h is below the 6.0 km/h switch speed
    assert row.cv_pct == pytest.approx(s.cv_pct, abs=0.005)
    # Eq. 4 for the upper layer: 3.6 * 150 * 5.0 / (600 * 0.3) = 15 r/min.
    assert row.target_rpm_upper == pytest.approx(s.target_rpm[0], abs=0.005)
    assert row.target_rpm_upper == pytest.approx(15.0, abs=0.1)
    assert row.meter_rpm_upper == pytest.approx(15.0, abs=0.01)
    assert row.meter_rpm_lower == pytest.approx(12.0, abs=0.01)
    assert row.fan_rpm_upper == pytest.approx(3000.0, abs=20)
    assert row.faults == int(s.faults) == 0
    assert (row.lat, row.lon, row.ndvi) == (45.75, 126.63, 0.62)
    assert (row.rate_kg_ha_upper, row.rate_kg_ha_lower) == (150.0, 120.0)


def test_row_before_any_frame() -> None:
    row = state_row(1.0, Snapshot(**ecu_values(None, None, None, None)))
    assert row.source == "none" and row.v_kmh == 0.0 and row.v_gnss_kmh is None
    assert row.lat is None and row.cv_pct is None and row.faults == 0
