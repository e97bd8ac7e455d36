"""The fused speed mode from Python: PcGnssTime in, EcuFused/EcuFusedAux out, both ends of the
protocol agreeing, and the core learning a wheel's slip from a port with a capture timer."""

from __future__ import annotations

import math

import pytest
from topdress.ecu._core import lib

from topdress.ecu import Ecu, EcuParams
from topdress.errors import ProtocolError
from topdress.protocol import (
    DEFAULT_IDS,
    EcuFused,
    EcuFusedAux,
    PcGnssTime,
    Source,
    SpeedMode,
    decode,
    encode_command,
    encode_gnss_time,
)

STEP_US = 10_000
M_PER_PULSE = 2 * math.pi * 0.0615 / 500


def test_gnss_time_round_trip_and_ranges() -> None:
    msg = encode_gnss_time(7.23, 1300, 258)
    assert msg.arbitration_id == DEFAULT_IDS.gnss_time == 0x0A626465
    assert bytes(msg.data) == bytes([0xD3, 0x02, 0x14, 0x05, 0x02, 0, 0, 0])  # 723, 1300, 258 % 256
    assert decode(msg) == PcGnssTime(7.23, 1300, 2)
    assert decode(encode_gnss_time(None, 0, 0)) == PcGnssTime(None, 0, 0)
    for bad in ((25.01, 0), (-0.1, 0), (5.0, 10_001)):
        with pytest.raises(ProtocolError):
            encode_gnss_time(bad[0], int(bad[1]), 0)
    # the wire values the C core refuses, the Python decoder refuses too
    for data in (bytes([0xC5, 0x09, 0, 0, 0, 0, 0, 0]), bytes([0, 0, 0x11, 0x27, 0, 0, 0, 0])):
        with pytest.raises(ProtocolError):
            decode((DEFAULT_IDS.gnss_time, data))
        ecu = Ecu()
        assert ecu.rx((DEFAULT_IDS.gnss_time, data), 0) == lib.TD_E_RANGE
        assert ecu.counters.rx_out_of_range == 1
    assert Ecu().rx(encode_gnss_time(7.23, 1300, 1), 0) == lib.TD_OK


class Machine:
    """A port with a capture timer: the wheel's last pulse time goes with its count."""

    def __init__(self, params: EcuParams) -> None:
        self.ecu = Ecu(params, now_us=0)
        self.t_us = 0
        self.pos = 0.0  # wheel pulses
        self.meter = [0.0, 0.0]
        self.edge_us = 0
        self.seq = 0

    def run(self, seconds: float, v_kmh: float, slip: float) -> None:
        wheel_rate = v_kmh / 3.6 * (1 - slip) / M_PER_PULSE  # pulses per second
        for _ in range(round(seconds / 0.01)):
            if self.t_us % 200_000 == 0:
                self.ecu.rx(encode_command(True, 3000, 200.0, 150.0, v_kmh), self.t_us)
                self.ecu.rx(encode_gnss_time(v_kmh, 120, self.seq), self.t_us)
                self.seq += 1
            before = self.pos
            self.t_us += STEP_US
            self.pos += wheel_rate * 0.01
            if int(self.pos) != int(before):
                back = (self.pos - math.floor(self.pos)) / wheel_rate
                self.edge_us = self.t_us - round(back * 1e6)
            duties = self.ecu.step_raw(
                self.t_us, int(self.pos), *(int(m) for m in self.meter), 0, 0, self.edge_us
            )
            for i in (0, 1):  # the reference drive: 60 r/min per unit duty
                self.meter[i] += 60.0 * duties[i] / 60.0 * 6400 * 0.01

    def frames(self) -> tuple[EcuFused, EcuFusedAux]:
        self.ecu.tx_raw()
        for _ in range(10):
            self.run(0.01, self.ecu.state.v_gnss_kmh, 0.0)
        found = [decode(f) for f in self.ecu.tx_raw()]
        fused = [f for f in found if isinstance(f, EcuFused)]
        aux = [f for f in found if isinstance(f, EcuFusedAux)]
        return fused[-1], aux[-1]


def test_fused_mode_learns_the_slip_and_reports_it() -> None:
    params = EcuParams.defaults().with_param("SpeedMode", SpeedMode.FUSED.code)
    # no fans in this rig; its drive has no lag of its own: the model is the 100 ms speed window
    params = params.replace(fan_min_rpm=0, meter_tau_ms=50)
    m = Machine(params)
    m.run(3.0, 0.0, 0.0)
    m.run(40.0, 8.0, 0.12)  # a loose field: 12 % slip at 8 km/h, eq. 5 says 9.0 %
    st = m.ecu.state
    assert st.source is Source.FUSED
    assert st.edge_timing and st.gnss_fused
    assert st.v_edge_kmh == pytest.approx(8.0 * 0.88, abs=0.02)
    assert st.slip_pct == pytest.approx(12.0, abs=0.5)
    assert st.v_kmh == pytest.approx(8.0, abs=0.1)
    assert st.gnss_delay_ms == 130  # age 120 ms + the 10 ms until the step that applied it
    fused, aux = m.frames()
    st = m.ecu.state
    assert fused.speed_kmh == pytest.approx(st.v_fused_kmh, abs=0.01)
    assert fused.slip_pct == pytest.approx(st.slip_pct, abs=0.01)
    assert fused.edge_timing and fused.gnss_fused
    assert aux.lead_kmh == pytest.approx(st.v_lead_kmh, abs=0.01)
    assert aux.wheel_edge_kmh == pytest.approx(st.v_edge_kmh, abs=0.01)
    assert aux.drive_slope_upper == pytest.approx(60.0, abs=0.5)
