"""The ECU application in a small closed loop in virtual time: every fail-safe.

A tiny plant here (tractor speed, ground wheel with eq. 5 slip, two first-order metering
motors with 6400-count encoders, two fans with 30-pulse tachometers) and the PC's command
frame every 500 ms; the ECU's frames are decoded with cantools from the DBC.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import pytest

from topdress.ecu import Ecu, EcuParams, meter_target_rpm, slip_model_pct
from topdress.protocol import (
    DEFAULT_IDS,
    EcuDiag,
    EcuSpeeds,
    EcuStatus,
    Fault,
    Source,
    database,
    decode,
    encode_command,
)

U32 = 1 << 32
STEP_US = 10_000
T0_US = U32 - 3_000_000  # the port's microsecond clock wraps 3 s into every run


@dataclass
class Plant:
    """Everything the ECU's port would read, driven by the duties the ECU writes."""

    v_kmh: float = 0.0  # true ground speed
    wheel_ok: bool = True
    blocked: list[bool] = field(default_factory=lambda: [False, False])
    fan_ok: list[bool] = field(default_factory=lambda: [True, True])
    meter_rpm: list[float] = field(default_factory=lambda: [0.0, 0.0])
    fan_rpm: list[float] = field(default_factory=lambda: [0.0, 0.0])
    # cumulative counters start near the 2^32 wrap, as a long-running port's would
    wheel_acc: float = U32 - 2000.0
    meter_acc: list[float] = field(default_factory=lambda: [U32 - 5000.0, U32 - 7000.0])
    fan_acc: list[float] = field(default_factory=lambda: [U32 - 100.0, 0.0])

    def advance(self, duties: tuple[float, float, float, float], dt_s: float) -> None:
        if self.wheel_ok:
            slip = slip_model_pct(self.v_kmh) / 100 if self.v_kmh > 0 else 0.0
            revs = self.v_kmh / 3.6 * dt_s / (2 * math.pi * 0.0615) * (1 - slip)
            self.wheel_acc += revs * 500
        for i in range(2):
            target = 0.0 if self.blocked[i] else 60.0 * duties[i]  # full duty: 60 r/min
            self.meter_rpm[i] += (target - self.meter_rpm[i]) * dt_s / 0.15
            self.meter_acc[i] += self.meter_rpm[i] / 60 * dt_s * 6400
            fan_target = 4000.0 * duties[2 + i] if self.fan_ok[i] else 0.0
            self.fan_rpm[i] += (fan_target - self.fan_rpm[i]) * dt_s / 0.5
            self.fan_acc[i] += self.fan_rpm[i] / 60 * dt_s * 30

    def counts(self) -> tuple[int, int, int, int, int]:
        # plain Python ints past 2^32: the binding wraps them as a uint32 counter would
        return (
            int(self.wheel_acc),
            int(self.meter_acc[0]),
            int(self.meter_acc[1]),
            int(self.fan_acc[0]),
            int(self.fan_acc[1]),
        )


@dataclass
class Pc:
    """The PC side: what goes into the command frame every 500 ms."""

    start: bool = True
    fan_rpm: float = 3000.0
    rates: tuple[float, float] = (200.0, 150.0)
    gnss: bool = True
    sending: bool = True
    gnss_jitter_kmh: float = 0.0  # added to every other GNSS speed: a live receiver's noise
    gnss_frozen_kmh: float | None = None  # a frozen receiver: this speed whatever the motion


class Loop:
    """ECU + plant + PC in virtual time (Python ints; the binding wraps them to uint32)."""

    def __init__(self, params: EcuParams | None = None) -> None:
        self.t_us = T0_US
        self.ecu = Ecu(params, now_us=self.t_us)
        self.plant = Plant()
        self.pc = Pc()
        self.frames: list[tuple[int, int, bytes]] = []  # (t_us, id, data)
        self.duties = (0.0, 0.0, 0.0, 0.0)
        self.last_cmd_us = self.t_us
        self._steps = 0
        self._commands = 0

    def command(self) -> None:
        jitter = self.pc.gnss_jitter_kmh if self._commands % 2 else 0.0
        self._commands += 1
        v = self.plant.v_kmh if self.pc.gnss_frozen_kmh is None else self.pc.gnss_frozen_kmh
        gnss = round(v + jitter, 1) if self.pc.gnss else None
        msg = encode_command(self.pc.start, self.pc.fan_rpm, *self.pc.rates, gnss)
        assert self.ecu.rx(msg, self.t_us) == 0
        self.last_cmd_us = self.t_us

    def run(self, seconds: float, during: Callable[[Loop], None] | None = None) -> None:
        for _ in range(round(seconds * 100)):
            if self._steps % 50 == 0 and self.pc.sending:
                self.command()
            self.t_us += STEP_US
            self._steps += 1
            self.plant.advance(self.duties, STEP_US / 1e6)
            self.duties = self.ecu.step_raw(self.t_us, *self.plant.counts())
            self.frames += [(self.t_us, i, d) for i, d in self.ecu.tx_raw()]
            if during is not None:
                during(self)

    def last(self, frame_id: int) -> dict[str, float]:
        """The newest frame with this id, decoded straight by cantools."""
        data = _newest(self, frame_id)
        decoded: dict[str, float] = database().decode_message(frame_id, data, decode_choices=False)
        return decoded

    def drive(self, v_kmh: float, ramp_s: float = 2.0, hold_s: float = 10.0) -> None:
        v0 = self.plant.v_kmh
        n = round(ramp_s * 10)
        for k in range(1, n + 1):
            self.plant.v_kmh = v0 + (v_kmh - v0) * k / n
            self.run(0.1)
        self.run(hold_s)


def _newest(loop: Loop, frame_id: int) -> bytes:
    return next(d for _, i, d in reversed(loop.frames) if i == frame_id)


def test_metering_reaches_eq4_target_on_the_wheel_speed_below_6_kmh() -> None:
    loop = Loop()
    loop.drive(5.0, hold_s=12.0)
    status, speeds, diag = (
        loop.last(DEFAULT_IDS.status),
        loop.last(DEFAULT_IDS.speeds),
        loop.last(DEFAULT_IDS.diag),
    )
    wheel = 5.0 * (1 - slip_model_pct(5.0) / 100)  # the wheel under-reads by its slip: 4.83
    assert status["WheelSpeed"] == pytest.approx(wheel, abs=0.1)
    assert speeds["SelectedSpeed"] == pytest.approx(wheel, abs=0.02)
    assert diag["SpeedSource"] == Source.WHEEL.code  # 5 km/h is below the switch speed
    for layer, rate, sig in ((0, 200.0, "UpperMeterSpeed"), (1, 150.0, "LowerMeterSpeed")):
        target = meter_target_rpm(3.6, rate, speeds["SelectedSpeed"], 0.3)
        assert loop.ecu.state.target_rpm[layer] == pytest.approx(target, rel=0.005)
        assert status[sig] == pytest.approx(target, rel=0.02)
    assert status["RunState"] == 0x0A
    assert status["UpperFanSpeed"] == pytest.approx(3000, abs=60)
    assert diag["FaultWord"] == 0
    # the wheel pulses in EcuDiag count every pulse since the start, mod 2^24
    assert diag["WheelPulses"] == loop.ecu.state.wheel_pulses % (1 << 24)
    assert loop.ecu.state.wheel_pulses == pytest.approx(
        (loop.plant.wheel_acc - (U32 - 2000)), abs=60
    )


def test_uniform_motion_above_6_kmh_switches_to_gnss() -> None:
    loop = Loop()
    loop.drive(8.0, ramp_s=4.0, hold_s=6.0)
    st = loop.ecu.state
    assert st.source is Source.GNSS and st.uniform and st.cv_pct is not None
    assert st.cv_pct < 4.2
    target = meter_target_rpm(3.6, 200.0, 8.0, 0.3)  # 32.0 r/min on the GNSS speed
    assert target == pytest.approx(32.0)
    assert loop.last(DEFAULT_IDS.status)["UpperMeterSpeed"] == pytest.approx(target, rel=0.02)
    assert loop.last(DEFAULT_IDS.speeds)["SelectedSpeed"] == pytest.approx(8.0)
    diag = decode((DEFAULT_IDS.diag, _newest(loop, DEFAULT_IDS.diag)))
    assert isinstance(diag, EcuDiag) and diag.source is Source.GNSS and diag.uniform
    # slowing to 5 km/h: accelerating/decelerating or slow -> back to the wheel
    loop.drive(5.0, ramp_s=2.0, hold_s=0.0)
    assert loop.ecu.state.source is Source.WHEEL


def test_source_decisions_happen_every_500_ms_and_status_every_100_ms() -> None:
    loop = Loop()
    loop.drive(3.0, hold_s=3.0)
    ids = [(t, i) for t, i, _ in loop.frames]
    status_t = [t for t, i in ids if i == DEFAULT_IDS.status]
    gaps = {(b - a) % U32 for a, b in itertools.pairwise(status_t)}
    assert gaps == {100_000}  # across the 2^32 microsecond wrap too
    assert loop.t_us - T0_US == 5_000_000 and loop.t_us > U32
    # every 500 ms; the first step only starts the estimator: 9 updates in 5 s
    assert loop.ecu.state.wheel_updates == 9
    # every 100 ms: status, diag, speeds, targets, fused, fused aux, in that order
    per_period = [i for t, i in ids if t == status_t[-1]]
    assert per_period == [
        DEFAULT_IDS.status,
        DEFAULT_IDS.diag,
        DEFAULT_IDS.speeds,
        DEFAULT_IDS.targets,
        DEFAULT_IDS.fused,
        DEFAULT_IDS.fused_aux,
        DEFAULT_IDS.gnss_lag,
    ]


def test_stopping_below_min_work_speed_stops_the_meters() -> None:
    loop = Loop()
    loop.drive(4.0, hold_s=5.0)
    assert loop.ecu.state.target_rpm[0] > 10
    loop.drive(0.0, ramp_s=2.0, hold_s=2.0)
    st = loop.ecu.state
    assert st.target_rpm == (0.0, 0.0) and st.meter_duty == (0.0, 0.0)
    assert loop.plant.meter_rpm[0] < 0.5
    assert st.running  # still started, just not moving


def test_stop_command_stops_the_motors_and_fans() -> None:
    loop = Loop()
    loop.drive(4.0, hold_s=5.0)
    loop.pc.start = False
    loop.run(0.6)
    st = loop.ecu.state
    assert not st.running
    assert st.meter_duty == (0.0, 0.0) and st.fan_duty == (0.0, 0.0)
    assert loop.last(DEFAULT_IDS.status)["RunState"] == 0


def test_command_timeout_stops_the_meters_and_clears_on_the_next_command() -> None:
    loop = Loop()
    loop.drive(4.0, hold_s=5.0)
    loop.pc.sending = False
    seen: list[tuple[int, Fault, float]] = []
    loop.run(2.5, lambda lp: seen.append((lp.t_us, lp.ecu.state.faults, lp.duties[0])))

    def ms_to_first(bit: Fault) -> int:
        t = next(t for t, f, _ in seen if bit in f)
        return ((t - loop.last_cmd_us) % U32) // 1000

    assert ms_to_first(Fault.CMD_TIMEOUT) == 1510  # strictly longer than 1.5 s
    assert ms_to_first(Fault.GNSS_LOST) == 1210  # GNSS goes stale first (1.2 s)
    assert all(d == 0.0 for t, f, d in seen if Fault.CMD_TIMEOUT in f)
    assert loop.ecu.state.source is Source.WHEEL
    loop.pc.sending = True
    loop.run(3.0)
    assert Fault.CMD_TIMEOUT not in loop.ecu.state.faults
    assert loop.ecu.state.meter_duty[0] > 0


def test_gnss_not_available_uses_the_wheel() -> None:
    loop = Loop()
    loop.drive(8.0, ramp_s=4.0, hold_s=6.0)
    assert loop.ecu.state.source is Source.GNSS
    loop.pc.gnss = False  # the PC sends 0xFF
    loop.run(0.6)
    st = loop.ecu.state
    assert st.source is Source.WHEEL and Fault.GNSS_LOST in st.faults and not st.gnss_valid
    speeds = decode((DEFAULT_IDS.speeds, _newest(loop, DEFAULT_IDS.speeds)))
    assert isinstance(speeds, EcuSpeeds) and speeds.gnss_kmh is None
    assert st.target_rpm[0] == pytest.approx(meter_target_rpm(3.6, 200.0, st.v_wheel_kmh, 0.3))
    loop.pc.gnss = True
    loop.run(3.0)
    assert Fault.GNSS_LOST not in loop.ecu.state.faults
    assert loop.ecu.state.source is Source.GNSS


def test_wheel_encoder_fault_switches_to_gnss_latched_until_stop() -> None:
    loop = Loop()
    loop.drive(4.0, hold_s=5.0)
    loop.pc.gnss_jitter_kmh = 0.1  # a live receiver
    loop.plant.wheel_ok = False  # the encoder cable is cut
    seen: list[tuple[int, Fault, Source]] = []
    loop.run(4.0, lambda lp: seen.append((lp.t_us, lp.ecu.state.faults, lp.ecu.state.source)))
    hit = next(i for i, (_, f, _) in enumerate(seen) if Fault.WHEEL_ENCODER in f)
    # wheel reads 0 from the next 500 ms update on, then > 2 s of GNSS at 4 km/h
    assert 2.0 < hit / 100 <= 2.6
    assert seen[hit][2] is Source.GNSS and seen[hit - 1][2] is Source.WHEEL
    st = loop.ecu.state
    assert st.target_rpm[0] == pytest.approx(meter_target_rpm(3.6, 200.0, st.v_gnss_kmh, 0.3))
    assert st.v_gnss_kmh == pytest.approx(4.05, abs=0.051)
    # latched: the wheel coming back does not clear it; a stop command does
    loop.plant.wheel_ok = True
    loop.run(2.0)
    assert Fault.WHEEL_ENCODER in loop.ecu.state.faults
    loop.pc.start = False
    loop.run(0.6)
    assert Fault.WHEEL_ENCODER not in loop.ecu.state.faults
    assert loop.ecu.state.source is Source.WHEEL


def test_no_usable_speed_holds_the_meters() -> None:
    loop = Loop()
    loop.drive(4.0, hold_s=5.0)
    loop.pc.gnss_jitter_kmh = 0.1
    loop.plant.wheel_ok = False
    loop.run(4.0)
    assert Fault.WHEEL_ENCODER in loop.ecu.state.faults
    loop.pc.gnss = False  # and now GNSS too
    loop.run(0.6)
    st = loop.ecu.state
    assert st.source is Source.NONE and Fault.NO_SPEED in st.faults
    assert st.target_rpm == (0.0, 0.0) and st.meter_duty == (0.0, 0.0)


def test_frozen_gnss_receiver_never_meters_a_standing_machine() -> None:
    loop = Loop()
    loop.drive(8.0, hold_s=6.0)
    assert loop.ecu.state.source is Source.GNSS
    loop.pc.gnss_frozen_kmh = 8.0  # the receiver repeats its last speed from here on
    loop.drive(0.0, ramp_s=4.0, hold_s=2.0)
    duties: list[float] = []
    loop.run(8.0, lambda lp: duties.append(lp.duties[0] + lp.duties[1]))
    # standing: queue G is all zeros (CV 0, uniform) and GNSS says 8 km/h, yet no metering
    assert duties == [0.0] * 800
    st = loop.ecu.state
    assert st.uniform and st.gnss_valid and st.v_wheel_kmh == 0.0
    assert st.source is Source.WHEEL
    assert Fault.GNSS_FROZEN in st.faults and Fault.WHEEL_ENCODER not in st.faults
    assert Fault.GNSS_FROZEN.value & int(loop.last(DEFAULT_IDS.diag)["FaultWord"])
    loop.pc.gnss_frozen_kmh = None  # the receiver recovers: 0 km/h
    loop.run(0.6)
    assert loop.ecu.state.faults == Fault(0)


@pytest.mark.parametrize("layer", [0, 1])
def test_blocked_meter_stops_that_motor_only(layer: int) -> None:
    loop = Loop()
    loop.drive(4.0, hold_s=5.0)
    loop.plant.blocked[layer] = True
    seen: list[tuple[Fault, tuple[float, float, float, float]]] = []
    loop.run(2.0, lambda lp: seen.append((lp.ecu.state.faults, lp.duties)))
    bit = (Fault.UPPER_BLOCKED, Fault.LOWER_BLOCKED)[layer]
    hit = next(i for i, (f, _) in enumerate(seen) if bit in f)
    # the 100 ms speed window and the PID reach their limits first, then > 1 s blocked
    assert 1.0 < hit / 100 < 1.5
    assert seen[hit][1][layer] == 0.0
    other = 1 - layer
    assert seen[-1][1][other] > 0.0 and seen[-1][1][layer] == 0.0
    assert loop.plant.meter_rpm[other] > 10
    assert loop.last(DEFAULT_IDS.diag)["FaultWord"] & bit
    # latched: freeing the motor does not restart it; stop then start does
    loop.plant.blocked[layer] = False
    loop.run(1.0)
    assert loop.ecu.state.meter_duty[layer] == 0.0
    loop.pc.start = False
    loop.run(0.6)
    loop.pc.start = True
    loop.run(5.0)
    assert bit not in loop.ecu.state.faults and loop.ecu.state.meter_duty[layer] > 0


def test_fan_below_minimum_holds_that_meter() -> None:
    loop = Loop()
    loop.plant.fan_ok[1] = False  # lower fan does not turn
    loop.drive(4.0, hold_s=5.0)
    st = loop.ecu.state
    assert Fault.LOWER_FAN_LOW in st.faults and Fault.UPPER_FAN_LOW not in st.faults
    assert st.target_rpm[1] == 0.0 and st.meter_duty[1] == 0.0
    assert st.target_rpm[0] > 10
    loop.plant.fan_ok[1] = True
    loop.run(3.0)
    assert Fault.LOWER_FAN_LOW not in loop.ecu.state.faults
    assert loop.ecu.state.target_rpm[1] > 5


def test_status_frames_are_what_the_state_says() -> None:
    loop = Loop()
    loop.drive(5.0, hold_s=3.0)
    data = _newest(loop, DEFAULT_IDS.status)
    status = decode((DEFAULT_IDS.status, data))
    st = loop.ecu.state
    assert isinstance(status, EcuStatus)
    assert status.meter_rpm_upper == pytest.approx(st.meter_rpm[0], abs=0.006)
    assert status.meter_rpm_lower == pytest.approx(st.meter_rpm[1], abs=0.006)
    assert status.fan_rpm_upper == pytest.approx(st.fan_rpm[0], abs=10)
    assert status.wheel_kmh == pytest.approx(st.v_wheel_kmh, abs=0.05)
