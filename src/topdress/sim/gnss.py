"""Single-point GNSS receiver: 5 Hz fixes, velocity filter, latency, static hold, outages."""

from __future__ import annotations

import math
import random
from collections import deque
from dataclasses import dataclass

from topdress.gnss import sentences as nmea

EARTH_R_M = 6_371_000.0


@dataclass(frozen=True)
class GnssParams:
    """A Beidou single-point receiver of the 0.1 m/s speed class.

    Speed is measured with white noise speed_sd_ms per axis and smoothed by the receiver's
    own first-order filter (filter_tau_s); the solution reaches the PC's serial port latency_s
    after its epoch (the receiver's computation plus the data logger that forwards the NMEA).
    Static hold: while the filtered speed is below hold_ms the receiver reports speed 0 and
    freezes its position (as most single-point receivers do at rest), and releases only
    above hold_ms.
    """

    rate_hz: float = 5.0
    latency_s: float = 0.30
    filter_tau_s: float = 1.0
    speed_sd_ms: float = 0.05
    hold_ms: float = 0.10
    pos_sd_m: float = 0.8
    pos_tau_s: float = 60.0
    talker: str = "GN"
    lat0_deg: float = 43.8853  # origin of the field's local frame (Changchun area)
    lon0_deg: float = 125.3245
    alt_m: float = 215.0
    utc_start_s: float = 2 * 3600.0  # 02:00 UTC = 10:00 local
    date_ddmmyy: str = "150626"
    # the antenna from the outlets (the tractor's reference point): forward and to the right, m
    antenna_along_m: float = 0.0
    antenna_across_m: float = 0.0
    outages: tuple[tuple[float, float], ...] = ()  # fault knob: (from_s, to_s) with no fix
    speed_bias_ms: float = 0.0  # fault knob: constant speed error


@dataclass(frozen=True)
class GnssFix:
    """What one epoch reports (after filter, hold and latency)."""

    t_s: float
    valid: bool
    speed_ms: float
    course_deg: float
    lat_deg: float
    lon_deg: float


class GnssReceiver:
    """Call step() every control period with the true state; collect NMEA lines when due."""

    def __init__(self, p: GnssParams, seed: int) -> None:
        if p.talker not in nmea.TALKERS:
            raise ValueError(f"unknown NMEA talker {p.talker!r}")
        self.p = p
        self._rng = random.Random(seed)
        self._period = 1.0 / p.rate_hz
        self._next_epoch = self._period
        self._k = self._period / (p.filter_tau_s + self._period)
        self._pos_k = self._period / p.pos_tau_s
        self._vx = 0.0
        self._vy = 0.0
        self._ex = 0.0
        self._ey = 0.0
        self._held = True
        self._hold_x = 0.0
        self._hold_y = 0.0
        self._pending: deque[tuple[float, GnssFix]] = deque()
        self.last_fix: GnssFix | None = None
        # the first time step() has anything to do: the next epoch or the next solution
        # due at the port (the World skips the call before it)
        self.next_due_s = self._next_epoch
        self._cos_lat0 = math.cos(math.radians(p.lat0_deg))

    def step(self, t: float, x: float, y: float, v: float, heading: float) -> list[str]:
        """Advance to time t; return the NMEA lines (RMC, VTG, GGA per fix) output now."""
        if t + 1e-9 >= self._next_epoch:
            self._epoch(self._next_epoch, x, y, v, heading)
            self._next_epoch += self._period
        lines: list[str] = []
        pending = self._pending
        while pending and pending[0][0] <= t + 1e-9:
            fix = pending.popleft()[1]
            self.last_fix = fix
            lines.extend(self.sentences(fix))
        self.next_due_s = min(self._next_epoch, pending[0][0]) if pending else self._next_epoch
        return lines

    def _epoch(self, te: float, x: float, y: float, v: float, heading: float) -> None:
        p = self.p
        if p.antenna_along_m or p.antenna_across_m:  # the antenna, not the outlets, is fixed
            sin_h, cos_h = math.sin(heading), math.cos(heading)
            x += p.antenna_along_m * sin_h + p.antenna_across_m * cos_h
            y += p.antenna_along_m * cos_h - p.antenna_across_m * sin_h
        g = self._rng.gauss
        vx = v * math.sin(heading) + g(0.0, p.speed_sd_ms)
        vy = v * math.cos(heading) + g(0.0, p.speed_sd_ms)
        self._vx += self._k * (vx - self._vx)
        self._vy += self._k * (vy - self._vy)
        s = math.hypot(self._vx, self._vy)
        sq = math.sqrt(2 * self._pos_k) * p.pos_sd_m
        self._ex += -self._pos_k * self._ex + sq * g(0.0, 1.0)
        self._ey += -self._pos_k * self._ey + sq * g(0.0, 1.0)
        valid = not any(a <= te < b for a, b in p.outages)
        if s < p.hold_ms:
            if not self._held:
                self._hold_x, self._hold_y = x + self._ex, y + self._ey
            self._held = True
        else:
            self._held = False
        if self._held:
            px, py, speed = self._hold_x, self._hold_y, 0.0
        else:
            px, py, speed = x + self._ex, y + self._ey, s + p.speed_bias_ms
        lat = p.lat0_deg + math.degrees(py / EARTH_R_M)
        lon = p.lon0_deg + math.degrees(px / (EARTH_R_M * self._cos_lat0))
        course = nmea.course_deg(self._vx, self._vy) if speed > 0.0 else 0.0
        fix = GnssFix(te, valid, max(0.0, speed), course, lat, lon)
        self._pending.append((te + p.latency_s, fix))

    def sentences(self, fix: GnssFix) -> list[str]:
        p = self.p
        tu = p.utc_start_s + fix.t_s
        return [
            nmea.rmc(
                p.talker,
                tu,
                fix.valid,
                fix.lat_deg,
                fix.lon_deg,
                fix.speed_ms,
                fix.course_deg,
                p.date_ddmmyy,
            ),
            nmea.vtg(p.talker, fix.valid, fix.speed_ms, fix.course_deg),
            nmea.gga(p.talker, tu, fix.valid, fix.lat_deg, fix.lon_deg, 12, 1.1, p.alt_m),
        ]
