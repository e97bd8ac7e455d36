"""Calibration wizards: metering catch test, ground-wheel distance, fan check.

Each wizard changes nothing but what it measures: its result is proposed, and saved (file and
ECU, through the settings) only when the operator closes it with apply. The terminal's loop
drives a wizard: `tick(now, CalInputs)` every 100 ms returns the frames to send, `view()` is
what the display shows, `command` what PcCommand carries meanwhile.

- Catch test: the ECU turns one layer's meter a set number of revolutions with the machine
  standing (PcCalCommand, td_cal.c); the operator weighs what came out; kg/rev = kg / the
  revolutions the ECU counted (coasting included).
- Wheel: the operator drives a measured distance (40 m, as the paper's slip runs); the pulses
  the ECU counted give the effective radius, L / (2 pi n), and the slip by eq. 3 (td_slip, the
  C core) against the distance the GNSS receiver saw.
- Fan check: standing, meters off, fans to their target for some seconds: the speed each
  reaches, and how long until the ECU's minimum.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import can

from topdress import protocol
from topdress.ecu.helpers import slip_measured_pct
from topdress.i18n import Text, text
from topdress.protocol import EcuCalStatus, FrameIds
from topdress.view.snapshot import CalibrationView

LAYER_INDEX = {"upper": 0, "lower": 1}
WHEEL_PULSE_MOD = 1 << 24  # EcuDiag.WheelPulses wraps here
CAL_ANSWER_S = 0.5  # a present ECU answers the calibration command within a status period
CAL_TRIES = 3


@dataclass(frozen=True)
class CalInputs:
    """What a wizard sees each tick (from the loop's latest ECU frames and inputs)."""

    ecu_live: bool
    cal_status: EcuCalStatus | None
    wheel_pulses: int | None
    v_wheel_kmh: float
    gnss_kmh: float | None
    fan_rpm: tuple[float, float]
    dt_s: float
    cal_t: float | None = None  # arrival time of cal_status


@dataclass(frozen=True)
class CalCommand:
    """What PcCommand carries while the wizard works."""

    start: bool = False
    fan_rpm: float = 0.0


class CalibrationError(ValueError):
    """A value the operator entered that cannot give a result (its message a Text)."""

    def __init__(self, message: Text) -> None:
        super().__init__(message)
        self.text = message


def _layer(layer: str) -> Text:
    return text(f"main.{layer}")


def _step(step: str) -> Text:
    return text(f"cal.step.{step}")


def kg_per_rev(weighed_kg: float, revolutions: float) -> float:
    """Fertilizer per metering revolution from a catch test."""
    if not revolutions > 0:
        raise CalibrationError(text("cal.error.no_revolutions"))
    if not (math.isfinite(weighed_kg) and weighed_kg > 0):
        raise CalibrationError(text("cal.error.weight", kg=weighed_kg))
    return weighed_kg / revolutions


@dataclass(frozen=True)
class WheelResult:
    pulses: int
    revolutions: float
    radius_m: float  # effective radius over the measured distance
    slip_pct: float  # eq. 3 with the configured radius against the measured distance
    gnss_distance_m: float | None
    slip_gnss_pct: float | None  # eq. 3 with the configured radius against the GNSS distance


def wheel_result(
    pulses: int, ppr: int, distance_m: float, radius_m: float, gnss_distance_m: float | None
) -> WheelResult:
    """Effective radius and slip (eq. 3, the C core's td_slip) of a measured-distance run."""
    if pulses <= 0:
        raise CalibrationError(text("cal.error.no_pulses"))
    if not distance_m > 0:
        raise CalibrationError(text("cal.error.distance", distance=distance_m))
    n = pulses / ppr
    slip_gnss = None
    if gnss_distance_m is not None and gnss_distance_m > 0:
        slip_gnss = slip_measured_pct(n, radius_m, gnss_distance_m)
    return WheelResult(
        pulses=pulses,
        revolutions=n,
        radius_m=distance_m / (2.0 * math.pi * n),
        slip_pct=slip_measured_pct(n, radius_m, distance_m),
        gnss_distance_m=gnss_distance_m,
        slip_gnss_pct=slip_gnss,
    )


class CatchTest:
    """One layer's meter turned standing by the ECU; the operator weighs and enters kg."""

    kind = "catch"
    command = CalCommand(start=False)

    def __init__(
        self, layer: str, revolutions: float, meter_rpm: float, seq: int, ids: FrameIds
    ) -> None:
        if layer not in LAYER_INDEX:
            raise CalibrationError(text("cal.error.layer", layer=layer))
        self.layer = layer
        self.target_rev = revolutions
        self.meter_rpm = meter_rpm
        self.seq = seq % 256
        self.ids = ids
        self.key = f"machine.kg_per_rev_{layer}"
        # Range-checked here, before anything is sent (ProtocolError naming the signal).
        self._start_msg = protocol.encode_cal_command(
            1, LAYER_INDEX[layer], revolutions, meter_rpm, self.seq, ids=ids
        )
        self.step = "running"
        self.text = text(
            "cal.text.catch_running", layer=_layer(layer), rev=revolutions, rpm=meter_rpm
        )
        self.revolutions = 0.0
        self.result: dict[str, float] = {}
        self._sent_t: float | None = None
        self._tries = 0
        self._answered = False

    def tick(self, now: float, x: CalInputs) -> list[can.Message]:
        st = x.cal_status
        if st is not None and st.seq == self.seq and st.state != "idle":
            self._answered = True
            self.revolutions = st.revolutions
            if self.step == "running":
                if st.state == "done":
                    self.step = "weigh"
                    self.text = text(
                        "cal.text.catch_weigh", layer=_layer(self.layer), rev=st.revolutions
                    )
                elif st.state == "aborted":
                    self.step = "aborted"
                    self.text = text("cal.text.catch_aborted", reason=st.reason)
            elif self.step == "weigh":
                # The meter coasts a little after its stop: the revolutions shown while
                # weighing are the ones the result will divide by.
                self.text = text(
                    "cal.text.catch_weigh", layer=_layer(self.layer), rev=self.revolutions
                )
        if self._answered or self.step != "running":
            return []
        if self._sent_t is None or now - self._sent_t >= CAL_ANSWER_S - 1e-9:
            if self._tries >= CAL_TRIES:
                self.step = "aborted"
                self.text = text("cal.text.no_answer")
                return []
            self._tries += 1
            self._sent_t = now
            return [self._start_msg]
        return []

    def finish(self, weighed_kg: float) -> None:
        if self.step not in ("weigh", "done"):
            raise CalibrationError(text("cal.error.not_weighing", step=_step(self.step)))
        k = kg_per_rev(weighed_kg, self.revolutions)
        self.result = {"kg_per_rev": k, "weighed_kg": weighed_kg, "revolutions": self.revolutions}
        self.step = "done"
        self.text = text(
            "cal.text.catch_done",
            layer=_layer(self.layer),
            kg_per_rev=k,
            kg=weighed_kg,
            rev=self.revolutions,
        )

    def close(self) -> list[can.Message]:
        """Frames that end the test at the ECU (reset: the meter stops, the status goes idle)."""
        return [protocol.encode_cal_command(0, 0, 0.0, 0.0, self.seq, ids=self.ids)]

    def view(self) -> CalibrationView:
        progress = min(self.revolutions / self.target_rev, 1.0) if self.target_rev else 0.0
        return CalibrationView(
            self.kind, self.step, self.text, progress, dict(self.result), self.key
        )

    def value(self) -> float | None:
        return self.result.get("kg_per_rev")


class WheelCal:
    """Drive `distance_m` between start and finish: pulses -> radius, slip against GNSS."""

    kind = "wheel"
    command = CalCommand(start=False)
    key = "machine.wheel_radius_m"

    def __init__(self, distance_m: float, radius_m: float, ppr: int) -> None:
        if not 1.0 <= distance_m <= 1000.0:
            raise CalibrationError(text("cal.error.distance_range", distance=distance_m))
        self.distance_m = distance_m
        self.radius_m = radius_m
        self.ppr = ppr
        self.step = "drive"
        self.text = text("cal.text.wheel_drive", distance=distance_m)
        self._pulses0: int | None = None
        self.pulses = 0
        self.gnss_m = 0.0
        self._gnss_ok = True
        self.result: dict[str, float] = {}

    def tick(self, now: float, x: CalInputs) -> list[can.Message]:
        if self.step != "drive":
            return []
        if x.wheel_pulses is not None:
            if self._pulses0 is None:
                self._pulses0 = x.wheel_pulses
            self.pulses = (x.wheel_pulses - self._pulses0) % WHEEL_PULSE_MOD
        if x.gnss_kmh is None:
            self._gnss_ok = False  # a gap: the GNSS distance would be short
        else:
            self.gnss_m += x.gnss_kmh / 3.6 * x.dt_s
        return []

    def finish(self, distance_m: float | None = None) -> None:
        if self.step != "drive":
            raise CalibrationError(text("cal.error.wheel_step", step=_step(self.step)))
        if distance_m is not None:
            if not 1.0 <= distance_m <= 1000.0:
                raise CalibrationError(text("cal.error.distance_range", distance=distance_m))
            self.distance_m = distance_m
        r = wheel_result(
            self.pulses,
            self.ppr,
            self.distance_m,
            self.radius_m,
            self.gnss_m if self._gnss_ok else None,
        )
        self.result = {
            "pulses": float(r.pulses),
            "revolutions": r.revolutions,
            "radius_m": r.radius_m,
            "slip_pct": r.slip_pct,
        }
        if r.gnss_distance_m is not None and r.slip_gnss_pct is not None:
            self.result["gnss_distance_m"] = r.gnss_distance_m
            self.result["slip_gnss_pct"] = r.slip_gnss_pct
        self.step = "done"
        radius = dict(radius_mm=r.radius_m * 1000.0, rev=r.revolutions)
        if r.gnss_distance_m is not None and r.slip_gnss_pct is not None:
            self.text = text(
                "cal.text.wheel_done", gnss_m=r.gnss_distance_m, slip=r.slip_gnss_pct, **radius
            )
        else:
            self.text = text("cal.text.wheel_done_no_gnss", **radius)

    def close(self) -> list[can.Message]:
        return []

    def view(self) -> CalibrationView:
        progress = min(self.gnss_m / self.distance_m, 1.0)
        return CalibrationView(
            self.kind, self.step, self.text, progress, dict(self.result), self.key
        )

    def value(self) -> float | None:
        return self.result.get("radius_m")


class FanCheck:
    """Fans to their target, meters off, standing, for `seconds`: the speed each reaches."""

    kind = "fan"
    key = ""

    def __init__(self, seconds: float, fan_rpm: float, fan_min_rpm: float) -> None:
        self.seconds = seconds
        self.fan_rpm = fan_rpm
        self.fan_min_rpm = fan_min_rpm
        self.command = CalCommand(start=True, fan_rpm=fan_rpm)
        self.step = "running"
        self.text = text("cal.text.fan_running", rpm=fan_rpm, s=seconds)
        self.t = 0.0
        self._reached: list[float | None] = [None, None]
        self._last: tuple[float, float] = (0.0, 0.0)
        self.result: dict[str, float] = {}

    def tick(self, now: float, x: CalInputs) -> list[can.Message]:
        if self.step != "running":
            return []
        if not x.ecu_live:
            self.step, self.text = "aborted", text("cal.text.fan_no_ecu")
            self.command = CalCommand()
            return []
        if x.v_wheel_kmh > 0.5:
            self.step, self.text = "aborted", text("cal.text.fan_moves")
            self.command = CalCommand()
            return []
        self.t += x.dt_s
        self._last = x.fan_rpm
        for i, rpm in enumerate(x.fan_rpm):
            if self._reached[i] is None and rpm >= self.fan_min_rpm:
                self._reached[i] = self.t
        if self.t >= self.seconds - 1e-9:
            self._conclude()
        return []

    def _conclude(self) -> None:
        self.command = CalCommand()
        self.step = "done"
        parts: list[Text] = []
        for i, layer in enumerate(("upper", "lower")):
            rpm = self._last[i]
            ok = rpm >= self.fan_min_rpm
            self.result[f"{layer}_rpm"] = rpm
            self.result[f"{layer}_ok"] = 1.0 if ok else 0.0
            reached = self._reached[i]
            if reached is not None:
                self.result[f"{layer}_to_min_s"] = reached
            parts.append(
                text(f"cal.text.fan_{'ok' if ok else 'low'}", layer=_layer(layer), rpm=rpm)
            )
        self.text = text(
            "cal.text.fan_done",
            target=self.fan_rpm,
            min=self.fan_min_rpm,
            upper=parts[0],
            lower=parts[1],
        )

    def close(self) -> list[can.Message]:
        return []

    def view(self) -> CalibrationView:
        progress = min(self.t / self.seconds, 1.0)
        return CalibrationView(self.kind, self.step, self.text, progress, dict(self.result))

    def value(self) -> float | None:
        return None


Wizard = CatchTest | WheelCal | FanCheck


def isobus_refusal(needs_fans: bool, why_not_topdress: Text | None) -> Text | None:
    """Why a calibration cannot run with the ECU on an ISOBUS (None: it can).

    The catch test (PcCalCommand) and the wheel calibration (EcuDiag's pulses) go through the
    ECU's private frames when the implement served is a topdress ECU (`why_not_topdress` None;
    else why it is not one). The fan check and the look-ahead calibration (`needs_fans`) run
    the fans with a start command at zero rate, a PcCommand, which has no ISOBUS form: there the
    Task Controller's rates start the machine, and the firmware sets the fans itself."""
    if why_not_topdress is not None:
        return text("op.error.cal_isobus_not_topdress", why=why_not_topdress)
    if needs_fans:
        return text("op.error.cal_isobus_fans")
    return None
