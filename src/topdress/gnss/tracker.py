"""Which GNSS speed the terminal forwards to the ECU.

The paper takes the speed from RMC. Receivers that send VTG and no RMC still work: a VTG speed
is used only when no RMC has come for `rmc_timeout_s`, so a receiver sending both never flips
between the two. An RMC with status V (or mode N) means GNSS is lost at once, as does a line
source that reports itself disconnected; a speed older than `stale_s` is not forwarded.
"""

from __future__ import annotations

from dataclasses import dataclass

from topdress.gnss.nmea import GnssFix


@dataclass(frozen=True)
class GnssSpeed:
    """A speed the terminal may forward: `speed_kmh` None means 'no valid GNSS speed'."""

    t: float
    speed_kmh: float | None
    sentence: str  # "RMC" or "VTG"


@dataclass(frozen=True)
class GnssPosition:
    t: float
    lat: float
    lon: float


class GnssSpeedTracker:
    """Feed it every decoded fix with its arrival time (monotonic seconds)."""

    def __init__(self, rmc_timeout_s: float = 1.5, stale_s: float = 2.0) -> None:
        self.rmc_timeout_s = rmc_timeout_s
        self.stale_s = stale_s
        self._last_rmc_t: float | None = None
        self._latest: GnssSpeed | None = None
        self.position: GnssPosition | None = None

    def retune(self, rmc_timeout_s: float, stale_s: float) -> None:
        """A changed [gnss] section: the timeouts taken at the next fix."""
        self.rmc_timeout_s = rmc_timeout_s
        self.stale_s = stale_s

    def update(self, t: float, fix: GnssFix) -> GnssSpeed | None:
        """Returns the new speed sample this fix gives, or None when it gives none."""
        if not fix.ok:
            return None
        if fix.fix_valid and fix.lat is not None and fix.lon is not None:
            self.position = GnssPosition(t, fix.lat, fix.lon)
        if fix.type == "RMC":
            self._last_rmc_t = t
        elif fix.type != "VTG" or not self._vtg_allowed(t):
            return None
        sample = GnssSpeed(t, fix.speed_kmh if fix.fix_valid else None, fix.type)
        self._latest = sample
        return sample

    def current(self, t: float, connected: bool = True) -> float | None:
        """The speed to send now, or None (GNSS lost: disconnected, invalid or stale)."""
        latest = self._latest
        if not connected or latest is None or t - latest.t > self.stale_s:
            return None
        return latest.speed_kmh

    def heard(self, t: float) -> bool:
        """Whether a speed sample, valid or not, came within stale_s (the receiver talks)."""
        latest = self._latest
        return latest is not None and t - latest.t <= self.stale_s

    def _vtg_allowed(self, t: float) -> bool:
        return self._last_rmc_t is None or t - self._last_rmc_t > self.rmc_timeout_s
