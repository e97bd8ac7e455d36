"""The states of the terminal's links (GNSS, crop sensors, ECU), the ECU's fault word, and the
hints about inputs that never give what the terminal needs.

Once per tick `LinkWatch.tick` works out each link's state and tells the operator of a change;
a loss (a state of LOST_STATES) is a `link.lost` event in the session log when entered and a
`link.restored` when left; a change of the ECU's fault word is a `fault.changed`.
"""

from __future__ import annotations

from topdress.crop.sensors import CompensatedNdvi
from topdress.i18n import text
from topdress.protocol import fault_names
from topdress.terminal.busswitch import BusSwitch
from topdress.terminal.gnssin import GnssIn
from topdress.terminal.journal import Journal, Settings
from topdress.terminal.lines import Lines, why
from topdress.view.links import link_state

CROP_HOLD_S = 0.5  # a crop sensor state must hold this long to be an event
#: The states of each link that are a loss (an event when entered, another when left).
LOST_STATES = {"ecu": ("lost",), "gnss": ("lost", "no fix"), "crop": ("lost", "silent")}
HINT_LINES = 20  # unusable lines in a row from one input before the operator is told why


class LinkWatch:
    """The GNSS, crop and ECU links' states as shown, and what is logged and told of them."""

    def __init__(
        self,
        settings: Settings,
        journal: Journal,
        lines: Lines,
        gnss: GnssIn,
        ndvi: CompensatedNdvi,
        bus: BusSwitch,
    ) -> None:
        self._settings = settings
        self._journal = journal
        self._lines = lines
        self._gin = gnss
        self._ndvi = ndvi
        self._bus = bus
        self.gnss_state = "wait"
        self.crop_state = "wait"
        self._crop_reported = "wait"
        self._crop_since = 0.0
        self._crop_ok_once = False
        self._hinted: set[str] = set()
        self._lost_since: dict[str, float] = {}  # link -> when it was lost
        self._faults = 0  # the ECU's fault word as last heard

    def tick(self, now: float, gnss_kmh: float | None) -> None:
        """The states now; a link lost is logged ahead of the alarm it raises (the desk's)."""
        self._gnss(gnss_kmh, now)
        self._crop(now)
        self._hint_unusable_input()
        self._track_links(now)
        self._track_faults(now)

    def _gnss(self, gnss_kmh: float | None, now: float) -> None:
        source, seen, tracker = self._lines.gnss, self._gin.seen, self._gin.tracker
        if gnss_kmh is not None:
            state = "ok"
        elif not source.connected:
            # Before the first attempt to open the port has failed, it is still "wait".
            state = "lost" if seen or source.last_error is not None else "wait"
        elif not seen:
            state = "wait"
        elif tracker.heard(now):
            state = "no fix"
        else:
            state = "lost"  # the port is open but the receiver fell silent
        if state == self.gnss_state:
            return
        if self.gnss_state != "wait" or state != "ok":
            if state != "lost":
                self._journal.event(text("event.gnss", state=link_state(state)))
            elif source.connected:
                self._journal.event(text("event.gnss_silent", s=tracker.stale_s))
            else:
                self._journal.event(text("event.gnss_lost", why=why(source)))
        self.gnss_state = state

    def _crop(self, now: float) -> None:
        sensors, source = self._ndvi.sensors, self._lines.crop
        n, fresh = self._settings.cfg.crop.sensors, len(sensors.fresh(now))
        heard = sensors.counters["ok"] > 0
        if not source.connected and (heard or source.last_error is not None):
            state = "lost"
        elif fresh == n:
            state = "ok"
        elif fresh:
            state = f"{fresh}/{n}"
        else:
            state = "silent" if heard else "wait"
        if state != self.crop_state:
            self.crop_state, self._crop_since = state, now
        # A sensor a moment late (a 1 Hz logger against stale_s = 1 s) is shown, not announced:
        # an event once the state has held CROP_HOLD_S; a loss at once.
        held = state == "lost" or now - self._crop_since >= CROP_HOLD_S - 1e-9
        if state == self._crop_reported or not held:
            return
        self._crop_reported = state
        was_ok = self._crop_ok_once
        self._crop_ok_once |= state == "ok"
        # Sensors come up one by one at start: report changes once all were there, or a loss.
        if state == "lost":
            self._journal.event(text("event.crop_lost", why=why(source)))
        elif was_ok:
            if state in ("ok", "silent"):
                self._journal.event(text(f"event.crop_{state}"))
            else:
                self._journal.event(text("event.crop_fresh", fresh=fresh, n=n))

    def _hint_unusable_input(self) -> None:
        """Lines that keep coming and never give what the terminal needs are a setting to fix
        (baud rate, the receiver's sentences, the column map): said once per input."""
        nmea, crop = self._gin.nmea.counters, self._ndvi.sensors.counters
        if "gnss" not in self._hinted and not self._gin.seen:
            lines = sum(v for k, v in nmea.items() if k != "resync")
            if lines >= HINT_LINES:
                self._hinted.add("gnss")
                hint = "event.gnss_no_speed" if nmea["ok"] else "event.gnss_no_decode"
                self._journal.event(text(hint, lines=lines))
        if "crop" not in self._hinted and crop["ok"] == 0:
            bad = sum(v for k, v in crop.items() if k != "stale")
            if bad >= HINT_LINES:
                self._hinted.add("crop")
                last = self._ndvi.sensors.last_error
                self._journal.event(text("event.crop_unusable", lines=bad, last=last))

    def _track_links(self, now: float) -> None:
        states = {"ecu": self._bus.ecu_state, "gnss": self.gnss_state, "crop": self._crop_reported}
        for link, state in states.items():
            lost = state in LOST_STATES[link]
            since = self._lost_since.get(link)
            if lost and since is None:
                self._lost_since[link] = now
                self._journal.log_event(now, "link.lost", link=link, state=state)
            elif not lost and since is not None:
                del self._lost_since[link]
                lost_s = round(now - since, 3)
                self._journal.log_event(now, "link.restored", link=link, state=state, lost_s=lost_s)

    def _track_faults(self, now: float) -> None:
        """The fault word as the ECU sends it; while it is not heard the word is not known."""
        link = self._bus.link
        diag = link.ecu.diag
        if not link.ecu_alive or diag is None or int(diag.faults) == self._faults:
            return
        was, word = self._faults, int(diag.faults)
        self._faults = word
        self._journal.log_event(
            now,
            "fault.changed",
            faults=word,
            was=was,
            set=fault_names(word & ~was),
            cleared=fault_names(was & ~word),
        )
