"""Ground (depth-gauge) wheel with its 500 PPR optical encoder."""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

from topdress.sim.cplant import CField, attach, ffi, lib, refill


@dataclass(frozen=True)
class WheelParams:
    """The wheel of the paper: 12.3 cm diameter, 500 pulses per revolution.

    Slip (%) follows eq. 5, slip_a*v^2 + slip_b*v + slip_c with v in km/h (wheat stubble);
    the wheel turns by distance*(1 - slip)/(2*pi*r). On stubble the wheel bounces and
    skids unevenly: its rotation rate fluctuates by bounce_sd (relative, correlated over
    bounce_tau_s), the source of the wheel-speed CV in uniform motion.
    """

    radius_m: float = 0.0615
    ppr: int = 500
    slip_a: float = 0.167
    slip_b: float = -0.296
    slip_c: float = 0.773
    slip_sd_pct: float = 0.25  # run-to-run variation of the slip (soil, straw), in % points
    bounce_sd: float = 0.036
    bounce_tau_s: float = 0.10
    encoder_dead_at_s: float = -1.0  # fault knob: encoder stops counting; < 0 never
    lifted_at_s: float = -1.0  # fault knob: wheel lifted off the ground; < 0 never


class GroundWheel:
    """Integrates the tractor's travel into cumulative encoder pulses (in C: csrc/plant.c,
    tdsim_wheel_step); this object holds the parameters and the bounce's random stream."""

    def __init__(self, p: WheelParams, seed: int) -> None:
        self._s = ffi.new("tdsim_wheel_t *")
        self.p = p
        self._rng = random.Random(seed)
        self._slip_offset = self._rng.gauss(0.0, p.slip_sd_pct)
        self._s.slip_offset_pct = self._slip_offset
        attach(self._rng, self._s.gauss)

    @property
    def p(self) -> WheelParams:
        return self._p

    @p.setter
    def p(self, p: WheelParams) -> None:
        self._p = p
        s = self._s
        s.circ_m = 2.0 * math.pi * p.radius_m
        s.slip_a, s.slip_b, s.slip_c = p.slip_a, p.slip_b, p.slip_c
        s.bounce_sd, s.bounce_tau_s = p.bounce_sd, p.bounce_tau_s
        s.encoder_dead_at_s, s.lifted_at_s, s.ppr = p.encoder_dead_at_s, p.lifted_at_s, p.ppr

    revolutions = CField[float]("revolutions", writable=True)
    count = CField[int]("count", "Cumulative encoder pulses.")

    def slip_pct(self, v_kmh: float) -> float:
        """Mean slip at speed v for this run (eq. 5 plus the run's offset), >= 0."""
        p = self.p
        return max(0.0, p.slip_a * v_kmh * v_kmh + p.slip_b * v_kmh + p.slip_c + self._slip_offset)

    def step(self, t: float, dt: float, v_ms: float, slip_floor_pct: float = 0.0) -> int:
        """Advance by dt at true ground speed v_ms (on ground where the slip is at least
        slip_floor_pct, e.g. a loose patch); return the cumulative pulse count."""
        n: int = lib.tdsim_wheel_step(self._s, t, dt, v_ms, slip_floor_pct)
        if self._s.gauss.n - self._s.gauss.next < 2:
            refill(self._rng, self._s.gauss)
        return n
