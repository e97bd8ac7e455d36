"""The GNSS lag the ECU learns: watched, told, and kept per receiver for the next session.

The ECU learns the lag of the GNSS speed behind the wheel and reports it in `EcuGnssLag` every
100 ms (docs/speed.md, "The GNSS lag, learned"). The terminal

- **watches** it (`LagWatch`): a change of where the lag in use comes from (start value,
  learned, fixed, a fixed lag overruled by the data) and a learned lag that moves by more than
  `MOVE_MS` are events (`gnss_lag.changed` in the session log). The operator is told when a lag
  is first learned, and warned when the data overrule a fixed lag for `WARN_S` (the learner's
  first estimate, after 1.5 s of speed change, can still be far from where it settles: it
  overruled a right 1.3 s for 5 s on the simulated machine; the session log has it at once);
- **keeps** it (`LagStore`, terminal.lagstore): the last learned lag per receiver
  (topdress.terminal.receiver) in a small JSON file beside the session logs, `STORE_FILE`,
  written atomically whenever the learned lag changes (a background thread: the write ends in an
  fsync) and at the end of the session; the next session pushes the lag kept for its GNSS input
  as `GnssLag`, the start of the learning. Within a session the last learned lag is the start
  value an ECU that restarted is pushed again, so a reboot does not send it back to the
  session's start;
- and `LagKeeper` does all of this for the terminal loop: the receiver on the GNSS input, the
  start value pushed, the watch, the store, the learned lag renewed in the link.

A file that cannot be read or parsed is an error told to the operator and logged, never a crash:
a damaged one is moved aside (`.damaged`) and the lags are learned anew.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from topdress import protocol
from topdress.gnss.nmea import GnssFix
from topdress.i18n import Text, text
from topdress.terminal.canlink import CanLink
from topdress.terminal.journal import Journal, Settings
from topdress.terminal.lagstore import MAX_LAG_MS, STORE_FILE, LagStore
from topdress.terminal.parampush import GNSS_LAG_ID
from topdress.terminal.receiver import ReceiverWatch, input_key
from topdress.view.snapshot import LagView

log = logging.getLogger(__name__)

MOVE_MS = 100  # a learned lag that moves by more than this is an event (and kept)
WARN_S = 10.0  # a fixed lag overruled this long is a warning to the operator


@dataclass(frozen=True)
class LagChange:
    """A change of the ECU's GNSS lag worth an event: where the lag in use comes from (`state`,
    `was` before; None for the first frame heard), or a learned lag moved by more than MOVE_MS
    (`moved_from_ms`)."""

    view: LagView
    was: str | None
    evidence_s: float
    fit: float
    moved_from_ms: int | None = None
    warned: bool = False  # it ends an overrule the operator was warned of

    @property
    def state(self) -> str:
        return self.view.state

    def detail(self) -> dict[str, Any]:
        """The `gnss_lag.changed` event's detail (docs/log.md)."""
        v = self.view
        out: dict[str, Any] = {
            "state": v.state,
            "was": self.was,
            "lag_ms": v.in_use_ms,
            "learned_ms": v.learned_ms,
            "evidence_s": round(self.evidence_s, 1),
            "fit": round(self.fit, 2),
            "fixed_ms": v.fixed_ms,
        }
        if self.moved_from_ms is not None:
            out["moved_from_ms"] = self.moved_from_ms
        return out

    def message(self) -> Text:
        """The change in words (the program log)."""
        v, s = self.view, self.view.in_use_ms / 1000
        if self.moved_from_ms is not None and v.learned_ms is not None:
            was = self.moved_from_ms / 1000
            return text("event.gnss_lag_moved", s=v.learned_ms / 1000, was=was)
        if v.state == "overruled":
            return text("event.gnss_lag_overruled", fixed=(v.fixed_ms or 0.0) / 1000, s=s)
        if v.state == "fixed" and self.was == "overruled":
            return text("event.gnss_lag_fixed", fixed=(v.fixed_ms or 0.0) / 1000)
        if v.state == "start":
            return text("event.gnss_lag_start", s=s)
        return text("event.gnss_lag_learned", s=s) if v.learned_ms is not None else v.text()

    def tell(self) -> bool:
        """Whether the operator is told: a lag learned (not its moves, shown on the screens),
        learning started again, the end of an overrule they were warned of. The first frame's
        start and a fixed lag in force are the normal start, and an overrule is told by
        `LagWatch.warning` once it holds."""
        if self.moved_from_ms is not None or self.was is None:
            return False
        if self.view.state in ("learned", "start"):
            return True
        return self.view.state == "fixed" and self.warned


class LagWatch:
    """Turns the stream of EcuGnssLag frames into the changes worth an event."""

    def __init__(self) -> None:
        self.state: str | None = None
        # the last learned lag the ECU reported: kept, and pushed again to an ECU back from a
        # loss (docs/terminal.md)
        self.learned_ms: int | None = None
        self._told_ms: int | None = None  # the learned lag of the last change
        self._view: LagView | None = None
        self._overruled_t: float | None = None  # since when the data overrule a fixed lag
        self._warned = False

    def warning(self, now: float) -> Text | None:
        """The warning, once, when the data have overruled the fixed lag for WARN_S."""
        v, since = self._view, self._overruled_t
        if v is None or since is None or self._warned or now - since < WARN_S - 1e-9:
            return None
        self._warned = True
        return text(
            "event.gnss_lag_overruled", fixed=(v.fixed_ms or 0.0) / 1000, s=v.in_use_ms / 1000
        )

    def update(
        self, now: float, frame: protocol.EcuGnssLag, fixed_ms: float | None
    ) -> LagChange | None:
        view = LagView.of(frame, fixed_ms)
        self._view = view
        if frame.learned_ms is not None and view.state != "start":
            self.learned_ms = frame.learned_ms  # never a start value: the ECU learned it
        was, moved = self.state, None
        if view.state == was:
            told, learned = self._told_ms, frame.learned_ms
            if learned is None or (told is not None and abs(learned - told) <= MOVE_MS):
                return None
            if told is None:  # learned while the state stayed (fixed, agreeing)
                self._told_ms = learned
                return None
            moved = told
        warned = False
        if view.state != was:
            warned, self._warned = self._warned, False
            self._overruled_t = now if view.state == "overruled" else None
        self.state = view.state
        self._told_ms = frame.learned_ms
        return LagChange(view, was, frame.evidence_s, frame.fit, moved, warned)


class LagKeeper:
    """The terminal's side of the GNSS lag: the receiver on the GNSS input, the lag kept for it
    (the start value pushed), the ECU's reports watched, the learned lag kept and renewed."""

    def __init__(self, settings: Settings, journal: Journal, where: Path | None) -> None:
        """`where`: the folder of the session logs (None: kept in memory only)."""
        self._settings = settings
        self._journal = journal
        self.receiver = ReceiverWatch(input_key(settings.cfg.gnss))
        self.store = LagStore(where / STORE_FILE if where is not None else None)
        self.watch = LagWatch()
        self.start = self.store.for_input(self.receiver.input)
        self._renewed_ms: int | None = None  # the learned lag an ECU back is pushed
        if self.store.error:
            journal.event(text("event.gnss_lag_store", error=self.store.error))

    def start_ms(self) -> int | None:
        """Where the ECU's learning starts: the lag learned so far in this session, else the
        one kept for this receiver's input (a fixed gnss_lag_ms overrides both)."""
        if self.watch.learned_ms is not None:
            return self.watch.learned_ms
        return self.start.lag_ms if self.start is not None else None

    def opened(self, now: float) -> None:
        """The `gnss_lag.start` event at open."""
        start = self.start
        self._journal.log_event(
            now,
            "gnss_lag.start",
            input=self.receiver.input,
            kept_ms=start.lag_ms if start is not None else None,
            fixed_ms=self._settings.fixed_lag_ms(),
            error=self.store.error,
        )

    def see(self, t: float, fix: GnssFix, line: bytes) -> None:
        """A decoded line: the receiver's identity, said once it settles, and told when the
        lag pushed at start was kept for another receiver on this input."""
        if not self.receiver.see(t, fix, line):
            return
        rid = self.receiver.receiver
        start = self.start
        same = start.receiver.same(rid) if start is not None else None
        self._journal.log_event(
            t,
            "gnss_lag.receiver",
            input=rid.input,
            sentences=list(rid.sentences),
            versions=list(rid.versions),
            start_ms=start.lag_ms if start is not None else None,
            same_receiver=same,
        )
        if same is False:
            self._journal.event(text("event.gnss_lag_other", input=rid.input))

    def track(self, now: float, link: CanLink) -> LagView | None:
        """The tick's turn: the ECU's last EcuGnssLag watched, the learned lag kept; the lag as
        shown (None while the ECU is not heard or has not said)."""
        frame = link.ecu.lag
        if frame is None or not link.ecu_alive:
            return None
        change = self.watch.update(now, frame, self._settings.fixed_lag_ms())
        self._renew(link)
        if change is not None:
            self._journal.log_event(now, "gnss_lag.changed", **change.detail())
            if change.tell():
                self._journal.event(change.message())
            else:
                log.info("%s", change.message())
            if frame.learned_ms is not None:
                self.keep(now, final=False)
        warning = self.watch.warning(now)
        if warning is not None:
            log.warning("%s", warning)
            self._journal.event(warning)
        return LagView.of(frame, self._settings.fixed_lag_ms())

    def _renew(self, link: CanLink) -> None:
        """The lag learned so far becomes the start value an ECU back from a loss is pushed, as
        the session's start value was at open; a number in gnss_lag_ms stays the one pushed."""
        learned = self.watch.learned_ms
        if self._settings.fixed_lag_ms() is not None:
            self._renewed_ms = None  # set to "auto" again later: renewed then
            return
        if learned is None or learned == self._renewed_ms:
            return
        link.renew({GNSS_LAG_ID: float(min(max(learned, 0), MAX_LAG_MS))})
        self._renewed_ms = learned

    def again(self, params: Mapping[int, float], now: float, link: CanLink) -> None:
        """The parameters are in force again in an ECU back from a loss: when they carried the
        lag learned so far and the ECU has reported no learned lag of its own since (it
        restarted), that lag is where its learning starts again: logged and told."""
        learned = self._renewed_ms
        if learned is None or params.get(GNSS_LAG_ID) != learned:
            return
        frame = link.ecu.lag
        if self._settings.fixed_lag_ms() is not None:
            return
        if frame is not None and frame.learned_ms is not None:
            return  # it kept what it learned: nothing was restored
        start = self.start
        self._journal.log_event(
            now,
            "gnss_lag.restored",
            input=self.receiver.input,
            lag_ms=learned,
            start_ms=start.lag_ms if start is not None else None,
        )
        self._journal.event(text("event.gnss_lag_restored", s=learned / 1000))

    def keep(self, now: float, final: bool) -> None:
        """Keep the learned lag for this receiver (in the background while running); at the end
        of the session also the `gnss_lag.kept` event, saying what was kept."""
        rid = self.receiver.receiver
        learned = self.watch.learned_ms
        if learned is not None and rid.known:
            self.store.keep(rid, learned, wait=final)
        if final:
            self.store.wait()
            self._journal.log_event(
                now,
                "gnss_lag.kept",
                input=rid.input,
                sentences=list(rid.sentences),
                lag_ms=learned if rid.known else None,
                error=self.store.error,
            )
