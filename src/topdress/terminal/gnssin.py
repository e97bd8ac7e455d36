"""The GNSS input of the terminal loop: NMEA lines decoded, the speed to the ECU, where the
machine and its outlet are, and how far it is from the maps.

A new GNSS speed goes to the ECU at once (PcCommand with `send_on_gnss`, and PcGnssTime with
the fix's age: the time from the line's arrival, its receive timestamp on the line source, to
the frame's transmission, so a wait in the loop's inbox is not learned as receiver lag). A lost
GNSS (no fix, port gone, stale speed) goes out as "not available" at the next tick, so the ECU
falls back to the wheel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from topdress.config import TerminalConfig
from topdress.geo.outlet import OutletFix, OutletTracker
from topdress.gnss.nmea import NmeaDecoder
from topdress.gnss.tracker import GnssSpeedTracker
from topdress.gnss.utc import UtcClock
from topdress.i18n import text
from topdress.terminal.canlink import CanLink
from topdress.terminal.gnsslag import LagKeeper
from topdress.terminal.journal import Journal, Settings
from topdress.terminal.lines import Lines
from topdress.terminal.site import MapGuard, OffMap

# At most one GNSS speed to the ECU this often (a 40 Hz cap, above any receiver's rate): a
# receiver or a replayed file flooding lines must not flood the bus to the ECU with PcGnssTime
GNSS_SEND_MIN_S = 0.025


@dataclass(frozen=True)
class Where:
    """The tick's GNSS: the speed (None: not available), the outlet now and where it will be
    when the product commanded now lands, and the maps it is too far outside of."""

    gnss_kmh: float | None
    outlet: OutletFix | None
    target: OutletFix | None
    off_map: tuple[OffMap, ...]


class GnssIn:
    """Decodes the GNSS lines and keeps the speed, the position and the UTC time they give."""

    def __init__(
        self,
        settings: Settings,
        journal: Journal,
        lines: Lines,
        guard: MapGuard,
        lags: LagKeeper,
    ) -> None:
        cfg = settings.cfg
        self._settings = settings
        self._journal = journal
        self._lines = lines
        self._lags = lags
        self.guard = guard
        self.nmea = NmeaDecoder()
        self.tracker = GnssSpeedTracker(cfg.gnss.rmc_timeout_s, cfg.gnss.stale_s)
        self.utc = UtcClock()
        self.outlet = OutletTracker(cfg.machine.outlet_along_m, cfg.machine.outlet_across_m)
        self.seen = False  # a GNSS speed was heard
        self._sent_t = -math.inf
        self._map_distance_said = False
        settings.on_change(self._take)

    def _take(self, section: str, new: TerminalConfig) -> None:
        if section == "gnss":
            self.tracker.retune(new.gnss.rmc_timeout_s, new.gnss.stale_s)

    def on_line(self, t: float, line: bytes, link: CanLink, odometer_m: float) -> None:
        """One NMEA line that arrived at `t` (the source's receive timestamp)."""
        self._journal.raw("nmea", t, line.decode("latin-1"))
        fix = self.nmea.decode(line)
        self._lags.see(t, fix, line)
        if not fix.ok:
            return
        if fix.fix_valid:
            self.utc.on_fix(t, fix.utc)
            self.outlet.on_fix(fix.lat, fix.lon, fix.course_deg, fix.speed_kmh, odometer_m)
            if not self._map_distance_said and fix.lat is not None and fix.lon is not None:
                self._map_distance_said = True
                self._say_map_distances(t, fix.lat, fix.lon)
        if self.tracker.update(t, fix) is None:
            return
        self.seen = True
        if t - self._sent_t < GNSS_SEND_MIN_S:
            self._journal.counters["gnss_send_skipped"] += 1
            return
        self._sent_t = t
        kmh = self.tracker.current(t, self._lines.gnss.connected)
        link.set_gnss(kmh, t)
        # The fix's age when its frame goes out: from the line's arrival, not the loop's tick.
        link.send_gnss_time(kmh, 1000.0 * max(0.0, self._journal.clock() - t))

    def tick(self, now: float, link: CanLink, odometer_m: float, ahead_m: float) -> Where:
        """The tick's turn: a GNSS speed lost is told the ECU at once (not at the next command
        period); the outlet now and `ahead_m` further on; the maps it is outside of."""
        gnss_kmh = self.tracker.current(now, self._lines.gnss.connected)
        if gnss_kmh is None and link.command.gnss_kmh is not None:
            link.set_gnss(None, now)
            if not self._settings.cfg.can.send_on_gnss:  # else set_gnss has sent it
                link.send_now()
        outlet = self.outlet.position(odometer_m)
        target = self.outlet.position(odometer_m + ahead_m) if ahead_m > 0.0 else outlet
        if outlet is not None:
            off_map = self.guard.outside(outlet.lat, outlet.lon)
        else:
            off_map = ()
            self.guard.forget()
        return Where(gnss_kmh, outlet, target, off_map)

    def _say_map_distances(self, t: float, lat: float, lon: float) -> None:
        """Once, at the first fix: how far each map is from the machine (a map of another field
        shows before the meters start)."""
        event = self._journal.event
        for which, name, d in self.guard.distances(lat, lon):
            self._journal.log_event(t, "map.distance", map=which, file=name, distance_m=round(d, 1))
            what = text(f"map.{which}")
            if d <= 0.0:
                event(text("event.map_inside", map=what, file=name))
            elif d < 1000.0:
                event(text("event.map_far_m", map=what, file=name, distance_m=round(d)))
            else:
                event(text("event.map_far_km", map=what, file=name, distance_km=d / 1000))
