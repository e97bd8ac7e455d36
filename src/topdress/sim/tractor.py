"""Tractor motion and the driver's plan (Drive): straight runs, headland turns, stops."""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

from topdress.sim.cplant import CField, attach, ffi, lib, refill

KMH = 1.0 / 3.6


@dataclass(frozen=True)
class TractorParams:
    """Longitudinal dynamics of a loaded tractor with the topdresser.

    The driver brings the machine to the target speed over about the same run-up whatever
    the target (gear and hand throttle chosen for the pass): from rest the acceleration limit
    is target^2 / (2 * runup_m), within accel_min_ms2..accel_max_ms2, so a slow pass creeps
    off (0.14 m/s^2 at 3.5 km/h) and a fast one pulls away (0.71 m/s^2 at 8.0 km/h). The
    clutch takes clutch_s to engage: the acceleration ramps up over that time. Otherwise the
    acceleration changes at most by jerk_ms3.
    """

    runup_m: float = 3.5
    accel_min_ms2: float = 0.05
    accel_max_ms2: float = 0.8  # traction and engine power of the loaded tractor
    clutch_s: float = 0.3
    decel_ms2: float = 0.80
    jerk_ms3: float = 0.60
    speed_tau_s: float = 0.6
    ripple_sd: float = 0.004  # relative speed ripple in steady motion (engine, terrain)
    ripple_tau_s: float = 1.0
    stall_at_s: float = -1.0  # fault knob: engine stalls (speed -> 0) at this time; < 0 never


@dataclass(frozen=True)
class Segment:
    """One element of a Drive.

    kind "straight": drive length_m at speed_kmh; with hold=True length_m counts only from the
    moment the speed first reaches the target (the paper's "40 m at constant speed").
    kind "turn": turn angle_deg (left positive) on radius_m at speed_kmh.
    kind "stop": stand still for duration_s.
    """

    kind: str
    speed_kmh: float = 0.0
    length_m: float = 0.0
    hold: bool = False
    angle_deg: float = 0.0
    radius_m: float = 0.0
    duration_s: float = 0.0


@dataclass
class Drive:
    """A driver following a list of segments; gives the tractor its speed and curvature targets."""

    segments: list[Segment]
    index: int = 0
    _progress: float = 0.0
    reached: bool = False
    _heading0: float = 0.0
    finished: bool = False

    @staticmethod
    def paper_run(target_kmh: float, hold_m: float = 40.0, wait_s: float = 3.0) -> Drive:
        """The paper's protocol: stand, accelerate, hold the target speed for hold_m, stop.

        Vary wait_s between runs: the moment the driver lets the clutch in is not tied to
        the ECU's 500 ms wheel-update grid.
        """
        return Drive(
            [
                Segment("stop", duration_s=wait_s),
                Segment("straight", speed_kmh=target_kmh, length_m=hold_m, hold=True),
                Segment("stop", duration_s=4.0),
            ]
        )

    @staticmethod
    def field_passes(
        passes: int,
        length_m: float,
        speed_kmh: float,
        width_m: float = 3.6,
        turn_kmh: float = 3.0,
        headland_stop_s: float = 2.0,
    ) -> Drive:
        """Back-and-forth passes; at each headland slow down, stop, turn 180 deg, go on."""
        segs: list[Segment] = [Segment("stop", duration_s=3.0)]
        for i in range(passes):
            segs.append(Segment("straight", speed_kmh=speed_kmh, length_m=length_m))
            if i == passes - 1:
                break
            segs.append(Segment("stop", duration_s=headland_stop_s))
            sign = 1.0 if i % 2 == 0 else -1.0
            segs.append(
                Segment("turn", speed_kmh=turn_kmh, angle_deg=180.0 * sign, radius_m=width_m / 2)
            )
        segs.append(Segment("stop", duration_s=3.0))
        return Drive(segs)

    @property
    def segment(self) -> Segment | None:
        return None if self.finished else self.segments[self.index]

    def phase(self, v_ms: float) -> str:
        """rest, accel, uniform (a hold segment at speed), decel, turn or run (other straight)."""
        seg = self.segment
        if seg is None or seg.kind == "stop":
            return "decel" if v_ms > 0.0 else "rest"
        if seg.kind == "turn":
            return "turn"
        if seg.hold:
            return "uniform" if self.reached else "accel"
        return "run"

    def command(self, tr: Tractor, dt: float) -> tuple[float, float]:
        """Advance the plan by one step; return (target speed m/s, curvature 1/m)."""
        if self.finished:
            return 0.0, 0.0
        segs = self.segments
        seg = segs[self.index]
        kind = seg.kind
        v = tr.v
        if kind == "stop":
            if v < 0.01:
                self._progress += dt
            if self._progress >= seg.duration_s:
                self._advance()
            return 0.0, 0.0
        v_t = seg.speed_kmh * KMH
        ds = v * dt
        if kind == "turn":
            if self._progress == 0.0:
                self._heading0 = tr.heading
            self._progress += ds / seg.radius_m
            if self._progress >= math.radians(abs(seg.angle_deg)):
                # the driver straightens up on the new line exactly
                tr.heading = self._heading0 + math.radians(seg.angle_deg)
                self._advance()
            return v_t, math.copysign(1.0 / seg.radius_m, seg.angle_deg)
        if seg.hold:
            if not self.reached and v >= 0.995 * v_t:
                self.reached = True
            if self.reached:
                self._progress += ds
            if self._progress >= seg.length_m:
                self._advance()
            return v_t, 0.0
        progress = self._progress + ds
        self._progress = progress
        remaining = seg.length_m - progress
        nxt = self.index + 1  # the speed of the next segment, the end of this one
        v_next = segs[nxt].speed_kmh * KMH if nxt < len(segs) else 0.0
        p = tr.p
        decel = p.decel_ms2
        brake_m = (v * v - v_next * v_next) / (2.0 * decel)
        brake_m = brake_m if brake_m > 0.0 else 0.0  # max(0.0, brake_m)
        if remaining <= brake_m + v * decel / p.jerk_ms3:
            v_t = v_next if v_next < v_t else v_t  # min(v_t, v_next)
        if remaining <= 0.0:
            self._advance()
        return v_t, 0.0

    def _advance(self) -> None:
        self.index += 1
        self._progress = 0.0
        self.reached = False
        if self.index >= len(self.segments):
            self.finished = True


class Tractor:
    """Point-mass tractor: speed with acceleration, jerk and ripple; planar position and heading.

    The motion is integrated in C (csrc/plant.c, tdsim_tractor_step); this object holds the
    parameters (replace `p` to turn a fault knob) and the ripple's random stream."""

    def __init__(self, p: TractorParams | None = None, seed: int = 0) -> None:
        self._s = ffi.new("tdsim_tractor_t *")
        self.p = p if p is not None else TractorParams()
        self.seed = seed
        self._s.target_ms = -1.0
        self._rng = random.Random(seed)
        attach(self._rng, self._s.gauss)

    @property
    def p(self) -> TractorParams:
        return self._p

    @p.setter
    def p(self, p: TractorParams) -> None:
        self._p = p
        s = self._s
        s.runup_m, s.accel_min_ms2, s.accel_max_ms2 = p.runup_m, p.accel_min_ms2, p.accel_max_ms2
        s.clutch_s, s.decel_ms2, s.jerk_ms3 = p.clutch_s, p.decel_ms2, p.jerk_ms3
        s.speed_tau_s, s.ripple_sd, s.ripple_tau_s = p.speed_tau_s, p.ripple_sd, p.ripple_tau_s
        s.stall_at_s = p.stall_at_s

    def step(self, dt: float, v_target: float, curvature: float) -> None:
        lib.tdsim_tractor_step(self._s, dt, v_target, curvature)
        if self._s.gauss.n - self._s.gauss.next < 2:
            refill(self._rng, self._s.gauss)

    x = CField[float]("x_m", "East, m.")
    y = CField[float]("y_m", "North, m.")
    heading = CField[float]("heading_rad", "Radians, 0 = north, clockwise positive.", writable=True)
    v = CField[float]("v_ms")
    a = CField[float]("a_ms2")
    odometer = CField[float]("odometer_m")
    t = CField[float]("t_s")
    _vb = CField[float]("vb_ms", "Speed without ripple.")
    _ripple = CField[float]("ripple")
    _accel_limit = CField[float]("accel_limit_ms2")
    _jerk = CField[float]("jerk_now_ms3")
