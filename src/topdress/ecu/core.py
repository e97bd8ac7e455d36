"""The ECU application (td_app_t) from Python: frames in, a control step, frames out.

The same C code as on the microcontroller; the caller plays the port (td_port.h): it passes
the time and the cumulative encoder counters into every step, applies the duties, hands over
received frames and drains the transmit queue. Counters and times wrap modulo 2**32.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import can

from topdress.ecu._core import ffi, lib
from topdress.ecu.params import EcuParams, check
from topdress.errors import ProtocolError
from topdress.protocol import CanFrame, Fault, Source

_U32 = 0xFFFFFFFF
_MAX_ID = 0x1FFFFFFF


@dataclass(frozen=True)
class Outputs:
    """PWM duties to apply after a step, 0..1, [upper, lower]."""

    meter_duty: tuple[float, float]
    fan_duty: tuple[float, float]


@dataclass(frozen=True)
class EcuState:
    """A snapshot of td_state_t; per-layer values are (upper, lower); cv_pct None = undefined."""

    running: bool
    source: Source
    cv_pct: float | None
    uniform: bool
    v_wheel_kmh: float
    v_gnss_kmh: float
    gnss_valid: bool
    v_kmh: float
    rate_kg_ha: tuple[float, float]
    target_rpm: tuple[float, float]
    meter_rpm: tuple[float, float]
    fan_rpm: tuple[float, float]
    fan_target_rpm: float
    meter_duty: tuple[float, float]
    fan_duty: tuple[float, float]
    faults: Fault
    wheel_updates: int
    wheel_pulses: int
    # the fused estimate, slip, look-ahead and drives (every step, in every mode)
    v_fused_kmh: float
    a_fused_ms2: float
    slip_pct: float
    innov_kmh: float
    speed_std_kmh: float
    v_edge_kmh: float
    v_lead_kmh: float
    drive_rpm_per_duty: tuple[float, float]
    gnss_delay_ms: int
    # the GNSS lag in use (ms), the one learned (None until learned), where it comes from
    # (0 start value, 1 learned, 2 fixed, 3 a fixed lag overruled by the data), how often a
    # fixed lag was overruled, the evidence (s of speed change) behind it and how far the last
    # change found it off (share, 1 before any change settled)
    gnss_lag_ms: int
    lag_learned_ms: int | None
    lag_state: int
    lag_overruled: int
    lag_evidence_s: float
    lag_fit: float
    slip_learning: bool
    edge_timing: bool
    gnss_fused: bool
    gnss_fixes: int
    gnss_rejected: int
    wheel_rejected: int


@dataclass(frozen=True)
class EcuCounters:
    """Frames received and refused, and frames dropped for a full transmit queue."""

    rx_ok: int
    rx_unknown_id: int
    rx_bad_length: int
    rx_out_of_range: int
    rx_param_rejected: int
    tx_dropped: int


_CAL_STATES = ("idle", "running", "done", "aborted")


@dataclass(frozen=True)
class CalState:
    """The catch test in the core (td_cal_t): state, layer (0 upper), reason code, revolutions."""

    state: str
    layer: int
    reason: int
    target_rev: float
    done_rev: float


def _pair(a: Any) -> tuple[float, float]:
    return (float(a[0]), float(a[1]))


class Ecu:
    """One ECU core instance (a td_app_t owned by Python)."""

    def __init__(self, params: EcuParams | None = None, now_us: int = 0) -> None:
        self._app = ffi.new("td_app_t *")
        p = (params or EcuParams.defaults()).to_c()
        check(lib.td_app_init(self._app, p, now_us & _U32), "Ecu")
        self._out = ffi.new("float[4]")
        # bound once: step_raw is the simulator's inner loop
        self._step_fn = lib.tdpy_step
        self._drain_fn = lib.tdpy_tx_drain
        self._tx_ids = ffi.new("uint32_t[]", lib.TD_TXQ_LEN)
        self._tx_lens = ffi.new("uint8_t[]", lib.TD_TXQ_LEN)
        self._tx_buf = ffi.new("char[]", 8 * lib.TD_TXQ_LEN)

    def rx(self, frame: can.Message | CanFrame, now_us: int) -> int:
        """Hand one received frame to the core. Returns TD_OK (0) when acted on, or the negative
        reason it was refused (counted in `counters`, never acted on). A tuple frame is
        extended when its id does not fit 11 bits."""
        if isinstance(frame, can.Message):
            frame_id, data, ext = frame.arbitration_id, bytes(frame.data), frame.is_extended_id
        else:
            frame_id, data = frame[0], bytes(frame[1])
            ext = frame_id > 0x7FF
        if not 0 <= frame_id <= _MAX_ID:
            raise ProtocolError(f"CAN id {frame_id:#x} is not an 11- or 29-bit identifier")
        return int(lib.tdpy_rx(self._app, frame_id, ext, data, len(data), now_us & _U32))

    def step_raw(
        self,
        now_us: int,
        wheel_count: int,
        m0: int,
        m1: int,
        f0: int,
        f1: int,
        wheel_edge_us: int | None = None,
    ) -> tuple[float, float, float, float]:
        """One control step on plain values: (meter_duty_upper, meter_duty_lower,
        fan_duty_upper, fan_duty_lower). `wheel_edge_us`: the time (same clock as now_us) of
        the wheel pulse that made wheel_count what it is, as a capture timer gives it; None for
        a port that only counts."""
        out = self._out
        rc = self._step_fn(
            self._app,
            now_us & _U32,
            wheel_count & _U32,
            m0 & _U32,
            m1 & _U32,
            f0 & _U32,
            f1 & _U32,
            0 if wheel_edge_us is None else wheel_edge_us & _U32,
            wheel_edge_us is not None,
            out,
        )
        if rc < 0:
            check(rc, "Ecu.step")
        return (out[0], out[1], out[2], out[3])

    def step(
        self,
        now_us: int,
        wheel_count: int,
        meter_counts: tuple[int, int],
        fan_counts: tuple[int, int],
        wheel_edge_us: int | None = None,
    ) -> Outputs:
        """One control step: cumulative counters (and the wheel's last edge time, if the port
        captures it) in, the duties to apply out."""
        d = self.step_raw(now_us, wheel_count, *meter_counts, *fan_counts, wheel_edge_us)
        return Outputs(meter_duty=(d[0], d[1]), fan_duty=(d[2], d[3]))

    def tx_raw(self) -> list[CanFrame]:
        """Drain the transmit queue as (arbitration_id, data) tuples, oldest first."""
        ids, lens = self._tx_ids, self._tx_lens
        n = self._drain_fn(self._app, ids, lens, self._tx_buf)
        buf = ffi.unpack(self._tx_buf, 8 * n)
        return [(int(ids[i]), buf[8 * i : 8 * i + lens[i]]) for i in range(n)]

    def announce(self) -> None:
        """EcuIdent again at the next step (td_app_announce): the port's link has just come up."""
        check(lib.td_app_announce(self._app), "announce")

    def tx_discard(self) -> int:
        """Empty the transmit queue without reading it (a replay needs none of the frames);
        returns how many frames were dropped."""
        return int(self._drain_fn(self._app, self._tx_ids, self._tx_lens, self._tx_buf))

    def tx(self) -> list[can.Message]:
        """Drain the transmit queue as python-can messages (29-bit ids), oldest first."""
        return [
            can.Message(arbitration_id=i, data=d, is_extended_id=True) for i, d in self.tx_raw()
        ]

    @property
    def state(self) -> EcuState:
        """A snapshot of the core's state, built on demand."""
        s = lib.td_app_state(self._app)
        return EcuState(
            running=bool(s.running),
            source=Source.from_code(int(s.source)),
            cv_pct=None if s.cv_pct < 0 else float(s.cv_pct),
            uniform=bool(s.uniform),
            v_wheel_kmh=float(s.v_wheel_kmh),
            v_gnss_kmh=float(s.v_gnss_kmh),
            gnss_valid=bool(s.gnss_valid),
            v_kmh=float(s.v_kmh),
            rate_kg_ha=_pair(s.rate_kg_ha),
            target_rpm=_pair(s.target_rpm),
            meter_rpm=_pair(s.meter_rpm),
            fan_rpm=_pair(s.fan_rpm),
            fan_target_rpm=float(s.fan_target_rpm),
            meter_duty=_pair(s.meter_duty),
            fan_duty=_pair(s.fan_duty),
            faults=Fault(int(s.faults)),
            wheel_updates=int(s.wheel_updates),
            wheel_pulses=int(s.wheel_pulses),
            v_fused_kmh=float(s.v_fused_kmh),
            a_fused_ms2=float(s.a_fused_ms2),
            slip_pct=float(s.slip_pct),
            innov_kmh=float(s.innov_kmh),
            speed_std_kmh=float(s.speed_std_kmh),
            v_edge_kmh=float(s.v_edge_kmh),
            v_lead_kmh=float(s.v_lead_kmh),
            drive_rpm_per_duty=_pair(s.drive_rpm_per_duty),
            gnss_delay_ms=int(s.gnss_delay_ms),
            gnss_lag_ms=int(s.gnss_lag_ms),
            lag_learned_ms=None if s.lag_learned_ms == 0xFFFF else int(s.lag_learned_ms),
            lag_state=int(s.lag_state),
            lag_overruled=int(s.lag_overruled),
            lag_evidence_s=float(s.lag_evidence_s),
            lag_fit=float(s.lag_fit),
            slip_learning=bool(s.slip_learning),
            edge_timing=bool(s.edge_timing),
            gnss_fused=bool(s.gnss_fused),
            gnss_fixes=int(s.gnss_fixes),
            gnss_rejected=int(s.gnss_rejected),
            wheel_rejected=int(s.wheel_rejected),
        )

    @property
    def wheel_updates(self) -> int:
        """Wheel-speed updates so far (EcuState.wheel_updates without the whole snapshot)."""
        return int(lib.td_app_state(self._app).wheel_updates)

    @property
    def cal_state(self) -> CalState | None:
        """The metering catch test (td_cal.h); None while idle."""
        c = self._app.cal
        if c.state == 0:
            return None
        return CalState(
            state=_CAL_STATES[c.state],
            layer=int(c.layer),
            reason=int(c.reason),
            target_rev=float(c.target_rev),
            done_rev=float(c.done_rev),
        )

    @property
    def counters(self) -> EcuCounters:
        """Receive and transmit counters of the core."""
        c = self._app.cnt
        return EcuCounters(
            rx_ok=int(c.rx_ok),
            rx_unknown_id=int(c.rx_unknown_id),
            rx_bad_length=int(c.rx_bad_length),
            rx_out_of_range=int(c.rx_out_of_range),
            rx_param_rejected=int(c.rx_param_rejected),
            tx_dropped=int(c.tx_dropped),
        )

    @property
    def params(self) -> EcuParams:
        """The parameters in force (they change through PcParamSet frames)."""
        return EcuParams.from_c(ffi.addressof(self._app, "p"))
