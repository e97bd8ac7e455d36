"""Fertilizer transport from the metering wheel through the air line into the soil."""

from __future__ import annotations

from dataclasses import dataclass

from topdress.sim.cplant import CField, ffi, lib


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
    """FIFO of fertilizer parcels in flight; step() returns the mass landing now. The FIFO
    lives in C (csrc/plant.c, tdsim_airline_step); `p` is copied there when replaced."""

    def __init__(self, p: AirLineParams) -> None:
        s = lib.tdsim_airline_new()
        if s == ffi.NULL:
            raise MemoryError("air line")
        self._s = ffi.gc(s, lib.tdsim_airline_free)
        self.p = p

    @property
    def p(self) -> AirLineParams:
        return self._p

    @p.setter
    def p(self, p: AirLineParams) -> None:
        self._p = p
        s = self._s
        s.line_length_m, s.air_speed_ms, s.drop_s = p.line_length_m, p.air_speed_ms, p.drop_s
        s.nominal_fan_rpm, s.min_fan_rpm = p.nominal_fan_rpm, p.min_fan_rpm
        s.release_rev, s.blocked = p.release_rev, p.blocked

    in_flight_kg = CField[float]("in_flight_kg")
    landed_kg = CField[float]("landed_kg")

    @property
    def parcels(self) -> int:
        """Parcels in flight."""
        n: int = lib.tdsim_airline_len(self._s)
        return n

    def delay_s(self, fan_rpm: float) -> float:
        """Transport time for a parcel entering now, inf if the air cannot carry it."""
        p = self.p
        if fan_rpm < p.min_fan_rpm:
            return float("inf")
        return p.drop_s + p.line_length_m / (p.air_speed_ms * fan_rpm / p.nominal_fan_rpm)

    def step(self, t: float, d_rev: float, kg_per_rev: float, fan_rpm: float) -> float:
        """Feed d_rev metering revolutions at time t; return kg landing in (t - dt, t]."""
        landed: float = lib.tdsim_airline_step(self._s, t, d_rev, kg_per_rev, fan_rpm)
        if landed < 0.0:
            raise MemoryError("air line: no memory for more parcels in flight")
        return landed
