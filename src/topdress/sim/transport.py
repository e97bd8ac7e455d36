"""Fertilizer transport from the metering wheel through the air line into the soil."""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass


@dataclass(frozen=True)
class AirLineParams:
    """Transport delay = fall into the venturi + line_length_m / air speed.

    The air speed scales with the fan speed (nominal at nominal_fan_rpm); below
    min_fan_rpm the air cannot carry the granules and they pile up in the line until the
    fan is back. The first granules leave the metering wheel after it has turned
    release_rev (the granules heaped on the outlet lip fall within the first degrees).
    """

    line_length_m: float = 1.5
    air_speed_ms: float = 11.0
    nominal_fan_rpm: float = 3000.0
    min_fan_rpm: float = 1200.0
    drop_s: float = 0.05
    release_rev: float = 0.0035
    blocked: bool = False  # fault knob: clogged line, nothing arrives


class AirLine:
    """FIFO of fertilizer parcels in flight; step() returns the mass landing now."""

    def __init__(self, p: AirLineParams) -> None:
        self.p = p
        self._q: deque[tuple[float, float]] = deque()
        self._rev_in = 0.0
        self.in_flight_kg = 0.0
        self.landed_kg = 0.0

    def delay_s(self, fan_rpm: float) -> float:
        """Transport time for a parcel entering now, inf if the air cannot carry it."""
        p = self.p
        if fan_rpm < p.min_fan_rpm:
            return float("inf")
        return p.drop_s + p.line_length_m / (p.air_speed_ms * fan_rpm / p.nominal_fan_rpm)

    def step(self, t: float, d_rev: float, kg_per_rev: float, fan_rpm: float) -> float:
        """Feed d_rev metering revolutions at time t; return kg landing in (t - dt, t]."""
        q = self._q
        p = self.p
        if d_rev > 0.0:
            before = self._rev_in
            rev_in = before + d_rev
            self._rev_in = rev_in
            release = p.release_rev
            released = rev_in - (release if release > before else before)  # max(before, release)
            if released > 0.0:
                m = released * kg_per_rev
                self.in_flight_kg += m
                # delay_s(fan_rpm), inlined: every metering step comes here
                if fan_rpm < p.min_fan_rpm:
                    q.append((t + math.inf, m))
                else:
                    air_ms = p.air_speed_ms * fan_rpm / p.nominal_fan_rpm
                    q.append((t + (p.drop_s + p.line_length_m / air_ms), m))
        if not q or q[0][0] > t or p.blocked:
            return 0.0
        landed = 0.0
        while q and q[0][0] <= t:
            landed += q.popleft()[1]
        self.in_flight_kg -= landed
        self.landed_kg += landed
        return landed
