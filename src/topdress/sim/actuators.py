"""Metering motors (DC motor + gearbox + metering wheel, 6400 counts/rev encoder) and fans."""

from __future__ import annotations

import math
from dataclasses import dataclass

_TWO_PI = 2.0 * math.pi


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
    """A shaft with first-order speed: its speed, revolutions and cumulative encoder count."""

    def __init__(self, tau_s: float, dt: float) -> None:
        self._decay = math.exp(-dt / tau_s)  # exact discretisation of the first-order lag
        self.rpm = 0.0
        self.revolutions = 0.0
        self.count = 0


class MeterMotor(_Shaft):
    def __init__(self, p: MeterParams, dt: float) -> None:
        super().__init__(p.tau_s, dt)
        self.p = p

    def step(self, t: float, dt: float, duty: float) -> int:
        """Apply duty for dt; return the cumulative encoder count."""
        p = self.p
        duty = 0.0 if duty < 0.0 else (1.0 if duty > 1.0 else duty)  # PWM saturates
        if 0.0 <= p.jammed_at_s <= t:
            self.rpm = 0.0
            return self.count
        rpm = self.rpm
        if rpm <= 0.0 and duty <= p.breakaway_duty + p.load_duty:
            return self.count
        load = p.load_duty
        if p.load_ripple:
            load *= 1.0 + p.load_ripple * math.sin(_TWO_PI * p.flutes * self.revolutions)
        w_ss = p.max_rpm * (duty - p.friction_duty - load)
        w = w_ss + (rpm - w_ss) * self._decay
        if w <= 0.0:
            w = 0.0  # friction holds the shaft; it does not turn backwards
        revolutions = self.revolutions + 0.5 * (rpm + w) * dt / 60.0
        self.revolutions = revolutions
        self.rpm = w
        if not 0.0 <= p.encoder_dead_at_s <= t:
            self.count = int(revolutions * p.counts_per_rev)
        return self.count

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
        super().__init__(p.tau_s, dt)
        self.p = p

    def step(self, t: float, dt: float, duty: float) -> int:
        """Apply duty for dt; return the cumulative tachometer count."""
        p = self.p
        duty = 0.0 if duty < 0.0 else (1.0 if duty > 1.0 else duty)  # PWM saturates
        if 0.0 <= p.failed_at_s <= t:
            duty = 0.0
        w_ss = p.max_rpm * duty * (1.0 - p.belt_slip)
        rpm = w_ss + (self.rpm - w_ss) * self._decay
        self.rpm = rpm
        revolutions = self.revolutions + rpm * dt / 60.0
        self.revolutions = revolutions
        self.count = int(revolutions * p.ppr)
        return self.count
