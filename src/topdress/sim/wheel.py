"""Ground (depth-gauge) wheel with its 500 PPR optical encoder."""

from __future__ import annotations

import math
import random
from dataclasses import dataclass


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
    """Integrates the tractor's travel into cumulative encoder pulses."""

    def __init__(self, p: WheelParams, seed: int) -> None:
        self.p = p
        self._rng = random.Random(seed)
        self._gauss = self._rng.gauss
        self._circ = 2.0 * math.pi * p.radius_m
        self._slip_offset = self._rng.gauss(0.0, p.slip_sd_pct)
        self._bounce = 0.0
        self._bounce_for: tuple[float, WheelParams] | None = None  # (dt, p) of the two below
        self._bounce_k = 0.0
        self._bounce_c = 0.0
        self.revolutions = 0.0
        self.count = 0

    def slip_pct(self, v_kmh: float) -> float:
        """Mean slip at speed v for this run (eq. 5 plus the run's offset), >= 0."""
        p = self.p
        return max(0.0, p.slip_a * v_kmh * v_kmh + p.slip_b * v_kmh + p.slip_c + self._slip_offset)

    def step(self, t: float, dt: float, v_ms: float, slip_floor_pct: float = 0.0) -> int:
        """Advance by dt at true ground speed v_ms (on ground where the slip is at least
        slip_floor_pct, e.g. a loose patch); return the cumulative pulse count."""
        p = self.p
        if v_ms <= 0.0 or (0.0 <= p.lifted_at_s <= t):
            return self.count
        if p.bounce_sd > 0.0:
            if (
                self._bounce_for is None
                or dt != self._bounce_for[0]
                or p is not self._bounce_for[1]
            ):
                self._bounce_for = (dt, p)
                self._bounce_k = dt / p.bounce_tau_s
                self._bounce_c = p.bounce_sd * math.sqrt(2 * self._bounce_k)
            self._bounce += -self._bounce_k * self._bounce + self._bounce_c * self._gauss(0.0, 1.0)
        # slip_pct inlined (the simulator's inner loop): max(0, eq. 5), then max(that, floor)
        v_kmh = v_ms * 3.6
        slip = p.slip_a * v_kmh * v_kmh + p.slip_b * v_kmh + p.slip_c + self._slip_offset
        slip = slip if slip > 0.0 else 0.0
        slip = (slip_floor_pct if slip_floor_pct > slip else slip) * 0.01
        self.revolutions += v_ms * dt * (1.0 - slip) * (1.0 + self._bounce) / self._circ
        if not 0.0 <= p.encoder_dead_at_s <= t:
            self.count = int(self.revolutions * p.ppr)
        return self.count
