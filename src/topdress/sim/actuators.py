"""Metering motors (DC motor + gearbox + metering wheel, 6400 counts/rev encoder) and fans."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from topdress.sim.cplant import CField, ffi, lib


@dataclass(frozen=True)
class MeterParams:
    """One metering drive seen at the metering shaft.

    A brushed DC gear motor is first order in speed (electrical time constant negligible):
    tau_s * dw/dt = max_rpm * (duty - friction_duty - load_duty) - w while turning.
    From standstill it breaks away only when duty exceeds breakaway_duty + load_duty
    (static friction). PWM duty saturates to 0..1. max_rpm is the no-load shaft speed at
    full duty after the gearbox. Encoder: counts_per_rev at the metering shaft. The load
    pulses as each of the `flutes` grooves of the metering wheel fills and empties:
    load_duty * (1 + load_ripple * sin(2*pi*flutes*revolutions)).
    """

    max_rpm: float = 66.0
    tau_s: float = 0.15
    breakaway_duty: float = 0.03
    friction_duty: float = 0.02
    load_duty: float = 0.02  # fertilizer in the box drags the metering wheel
    flutes: int = 12
    load_ripple: float = 0.5
    counts_per_rev: int = 6400
    jammed_at_s: float = -1.0  # fault knob: metering wheel blocked; < 0 never
    encoder_dead_at_s: float = -1.0  # fault knob: encoder stops counting; < 0 never


class _Shaft:
    """A shaft with first-order speed: its speed, revolutions and cumulative encoder count,
    in a C struct (`_s`) that csrc/plant.c steps."""

    _s: Any

    def __init__(self, dt: float) -> None:
        self._dt = dt

    def _decay(self, tau_s: float) -> float:
        """The exact discretisation of the first-order lag over one step."""
        return math.exp(-self._dt / tau_s)

    rpm = CField[float]("rpm")
    revolutions = CField[float]("revolutions")
    count = CField[int]("count")


class MeterMotor(_Shaft):
    def __init__(self, p: MeterParams, dt: float) -> None:
        super().__init__(dt)
        self._s = ffi.new("tdsim_meter_t *")
        self.p = p

    @property
    def p(self) -> MeterParams:
        return self._p

    @p.setter
    def p(self, p: MeterParams) -> None:
        self._p = p
        s = self._s
        s.max_rpm, s.breakaway_duty, s.friction_duty = p.max_rpm, p.breakaway_duty, p.friction_duty
        s.load_duty, s.flutes, s.load_ripple = p.load_duty, p.flutes, p.load_ripple
        s.counts_per_rev, s.jammed_at_s = p.counts_per_rev, p.jammed_at_s
        s.encoder_dead_at_s, s.decay = p.encoder_dead_at_s, self._decay(p.tau_s)

    def step(self, t: float, dt: float, duty: float) -> int:
        """Apply duty for dt; return the cumulative encoder count (tdsim_meter_step)."""
        n: int = lib.tdsim_meter_step(self._s, t, dt, duty)
        return n

    def steady_rpm(self, duty: float) -> float:
        """Steady-state shaft speed for a constant duty (0 below breakaway)."""
        p = self.p
        if duty <= p.breakaway_duty + p.load_duty:
            return 0.0
        return p.max_rpm * (min(duty, 1.0) - p.friction_duty - p.load_duty)


@dataclass(frozen=True)
class FanParams:
    """Blower: first order to max_rpm * duty, tachometer with ppr pulses per revolution."""

    max_rpm: float = 4000.0
    tau_s: float = 0.8
    ppr: int = 30
    failed_at_s: float = -1.0  # fault knob: fan motor dies (coasts down); < 0 never
    belt_slip: float = 0.0  # fault knob: fraction of speed lost to a slipping belt


class Fan(_Shaft):
    def __init__(self, p: FanParams, dt: float) -> None:
        super().__init__(dt)
        self._s = ffi.new("tdsim_fan_t *")
        self.p = p

    @property
    def p(self) -> FanParams:
        return self._p

    @p.setter
    def p(self, p: FanParams) -> None:
        self._p = p
        s = self._s
        s.max_rpm, s.ppr, s.failed_at_s = p.max_rpm, p.ppr, p.failed_at_s
        s.belt_slip, s.decay = p.belt_slip, self._decay(p.tau_s)

    def step(self, t: float, dt: float, duty: float) -> int:
        """Apply duty for dt; return the cumulative tachometer count (tdsim_fan_step)."""
        n: int = lib.tdsim_fan_step(self._s, t, dt, duty)
        return n
