"""The display's one link to the terminal.

The control loop calls `publish(snapshot)` every tick (constant time, one short lock: it never
waits on the display); the page pulls `latest()` and `history()` from its own event loop in its
own thread. Commands go the other way through the `Operator` the hub was given.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from concurrent.futures import Future
from dataclasses import dataclass, replace
from typing import Any

from topdress import i18n
from topdress.config import TerminalConfig, check_pin
from topdress.display.guard import GLOBAL, PinGate
from topdress.view.commands import CommandResult
from topdress.view.snapshot import TICK_S, Snapshot

#: Posts an operator command into the terminal's inbox (thread-safe; `Terminal.post`).
Post = Callable[[Any], "Future[CommandResult]"]
#: An event for the terminal's session log: (kind, detail).
Report = Callable[[str, dict[str, Any]], None]

HISTORY_S = 60.0  # what the live charts show
TRACK_STEP_M = 1.0  # a new track point every metre driven
TRACK_MAX_POINTS = 20_000  # 20 km of track; older points drop off the live map
_EARTH_R_M = 6_371_000.0


@dataclass(frozen=True)
class TrackPoint:
    """One point of the driven track, for the live map."""

    lat: float
    lon: float
    heading_deg: float  # clockwise from north: the receiver's course, else from the last point
    rate_kg_ha: float  # total rate applied (both layers, measured) while metering, else 0
    metering: bool


@dataclass(frozen=True)
class ViewPrefs:
    """How the cab's screen shows things (every open page at once, as the language)."""

    night: bool = False
    units: str = "metric"  # metric | imperial (topdress.display.units)


class DisplayHub:
    """Latest snapshot, the last minute of them, and the track; safe across threads.

    `config` returns the configuration in force (the terminal's; it changes when settings are
    applied), `post` the terminal's command path (None: a display that only watches),
    `on_language` tells the terminal the language chosen (its console follows)."""

    def __init__(
        self,
        config: Callable[[], TerminalConfig],
        post: Post | None = None,
        history_s: float = HISTORY_S,
        on_language: Callable[[str], None] | None = None,
        report: Report | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.config = config
        self.post = post
        self._on_language = on_language
        self._report = report
        self._clock = clock
        self._pins = PinGate()
        self._pins_lock = threading.Lock()
        self._lock = threading.Lock()
        self._latest = Snapshot()
        self._published_wall_s = 0.0
        self._serial = 0
        self._history: deque[Snapshot] = deque(maxlen=max(1, round(history_s / TICK_S)))
        self._track: deque[TrackPoint] = deque(maxlen=TRACK_MAX_POINTS)
        self._track_serial = 0
        self._prefs = ViewPrefs()
        self._prefs_version = 0
        # The operator's pages (NiceGUI client ids): the cab's own browser's, and any page that
        # sent a command. Only these count as "a page open" for the terminal's pause rule: a
        # viewer tab left open elsewhere does not keep the meters going.
        self.operator_pages: set[str] = set()
        self.on_prefs: Callable[[ViewPrefs], None] | None = None  # told each change

    def operator_pages_connected(self, connected: Iterable[str]) -> int:
        """How many of the `connected` pages (client ids) are the operator's; forgets the
        operator's pages no longer there."""
        ids = set(connected)
        self.operator_pages &= ids
        return len(self.operator_pages)

    # ---- the control loop's side ---------------------------------------------------------
    def publish(self, snapshot: Snapshot) -> None:
        """The control loop's latest state (called every tick; never blocks on the page)."""
        point = self._track_point(snapshot)
        with self._lock:
            self._latest = snapshot
            self._published_wall_s = time.time()
            self._serial += 1
            self._history.append(snapshot)
            if point is not None:
                self._track.append(point)
                self._track_serial += 1

    def _track_point(self, s: Snapshot) -> TrackPoint | None:
        if s.lat is None or s.lon is None:
            return None
        last = self._track[-1] if self._track else None
        if last is not None and distance_m(last.lat, last.lon, s.lat, s.lon) < TRACK_STEP_M:
            return None
        # The receiver's course (held below walking pace) is smoother than the bearing between
        # two noisy fixes a metre apart; the bearing is for logs and feeds without a course.
        if s.heading_deg is not None:
            heading = s.heading_deg
        else:
            heading = bearing_deg(last.lat, last.lon, s.lat, s.lon) if last else 0.0
        metering = s.ecu_live and s.running and (s.meter_rpm[0] > 0 or s.meter_rpm[1] > 0)
        rate = s.applied_kg_ha[0] + s.applied_kg_ha[1] if metering else 0.0
        return TrackPoint(s.lat, s.lon, heading, rate, metering)

    # ---- the page's side -------------------------------------------------------------------
    def set_language(self, code: str) -> None:
        """Switch every page (and, through the terminal, the console) to `code`."""
        lang = i18n.set_language(code)
        if self._on_language is not None:
            self._on_language(lang)

    @property
    def prefs(self) -> ViewPrefs:
        return self._prefs

    @property
    def prefs_version(self) -> int:
        """Grows by one at each change: pages redraw their content as for a language."""
        return self._prefs_version

    def set_prefs(self, night: bool | None = None, units: str | None = None) -> None:
        new = replace(
            self._prefs,
            night=self._prefs.night if night is None else night,
            units=self._prefs.units if units is None else units,
        )
        if new != self._prefs:
            self._prefs = new
            self._prefs_version += 1
            if self.on_prefs is not None:
                self.on_prefs(new)

    @property
    def pin_required(self) -> bool:
        """Operating (start/stop, manual rate, settings) asks for the PIN when one is set."""
        return bool(self.config().display.pin)

    def try_pin(self, address: str, given: str) -> float | None:
        """A PIN typed at `address`: None when right; else the seconds that address must wait
        before its next try (0: it may try again at once). Wrong PINs are counted per address
        and in total (topdress.display.guard.PinGate), each one reported to the session log,
        and a lockout too; the PIN is compared in constant time and never logged."""
        locked = self.locked_for(address)
        if locked > 0:
            return locked
        if check_pin(self.config().display, given):
            with self._pins_lock:
                self._pins.succeeded(address)
            return None
        self.failed(address, "pin")
        return self.locked_for(address)

    def locked_for(self, address: str) -> float:
        with self._pins_lock:
            return self._pins.locked_for(address, self._clock())

    def failed(self, address: str, what: str) -> None:
        """A wrong guess of a secret (`pin`, `kiosk` token) from `address`."""
        with self._pins_lock:
            now = self._clock()
            failures, lockout_s = self._pins.failed(address, now)
            # the lockout of everyone (guesses from many addresses) is not this address's
            everyone = bool(lockout_s) and self._pins.locked_for(GLOBAL, now) >= lockout_s
        self.report("display.pin_failed", address=address, what=what, failures=failures)
        if lockout_s:
            self.report(
                "display.pin_lockout",
                address=GLOBAL if everyone else address,
                failures=failures,
                lockout_s=lockout_s,
            )

    def report(self, kind: str, **detail: Any) -> None:
        if self._report is not None:
            self._report(kind, detail)

    def latest(self) -> tuple[int, float, Snapshot]:
        """(serial, wall-clock time it was published, snapshot); the serial grows by one each
        tick, so a page sees whether anything changed since it last looked."""
        with self._lock:
            return self._serial, self._published_wall_s, self._latest

    def history(self) -> list[Snapshot]:
        """The snapshots of the last `history_s`, oldest first."""
        with self._lock:
            return list(self._history)

    def track_since(self, count: int) -> tuple[int, list[TrackPoint]]:
        """Track points after the first `count` ever added: (total added, the new points).
        Points that dropped off the bounded track are skipped."""
        with self._lock:
            total = self._track_serial
            new = min(total - count, len(self._track))
            # From the end: the control loop waits on this lock, so no copy of the whole track.
            return total, [self._track[-i] for i in range(new, 0, -1)]


def distance_m(lat0: float, lon0: float, lat1: float, lon1: float) -> float:
    """Distance on a local plane (equirectangular): exact enough over a field."""
    y = math.radians(lat1 - lat0) * _EARTH_R_M
    x = math.radians(lon1 - lon0) * _EARTH_R_M * math.cos(math.radians((lat0 + lat1) / 2))
    return math.hypot(x, y)


def bearing_deg(lat0: float, lon0: float, lat1: float, lon1: float) -> float:
    """Direction from the first point to the second, degrees clockwise from north."""
    y = math.radians(lat1 - lat0)
    x = math.radians(lon1 - lon0) * math.cos(math.radians((lat0 + lat1) / 2))
    return math.degrees(math.atan2(x, y)) % 360.0
