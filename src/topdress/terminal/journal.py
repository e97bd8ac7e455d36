"""What every part of the terminal loop shares: the settings in force and the journal.

`Settings` holds the configuration in force; a section changed while running (the operator's
desk decides it) is taken by the parts that read it, through the takers they register.
`Journal` is where the parts say what happens: events to the session log (`log_event`), words
to the operator (`event`), raw inputs and frames (`raw`), and the loop's own anomaly counters.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable
from typing import Any

from topdress.config import TerminalConfig
from topdress.i18n import Text
from topdress.log.model import LogEvent
from topdress.log.session import SessionLog

log = logging.getLogger(__name__)

Taker = Callable[[str, TerminalConfig], None]


class Settings:
    """The configuration in force, and who takes a changed section."""

    def __init__(self, cfg: TerminalConfig) -> None:
        self.cfg = cfg
        self._takers: list[Taker] = []

    def on_change(self, taker: Taker) -> None:
        """`taker(section, new)` is called when a section changes."""
        self._takers.append(taker)

    def take(self, section: str, new: TerminalConfig) -> None:
        """The configuration with `section` changed, taken by the parts that read it."""
        self.cfg = new
        for taker in self._takers:
            taker(section, new)

    def fixed_lag_ms(self) -> float | None:
        """[ecu] gnss_lag_ms when it is a number (a fixed lag), None for "auto"."""
        return self.cfg.ecu.overrides.get("gnss_lag_ms")


class Journal:
    """The session log (None: nothing logged) and the operator's messages."""

    def __init__(
        self,
        session: SessionLog | None,
        clock: Callable[[], float],
        on_event: Callable[[Text], None] | None = None,
    ) -> None:
        self.session = session
        self.clock = clock
        self._on_event = on_event
        self.counters: Counter[str] = Counter()  # the loop's own anomalies, and "events"
        self.last_event: Text | None = None

    def log_event(self, t: float, kind: str, **detail: Any) -> None:
        """One event to the session log: `kind` of topdress.log.model.EVENT_KINDS, `detail`
        plain JSON values (docs/log.md lists each kind's)."""
        if self.session is not None:
            self.session.event(LogEvent(t, kind, detail))

    def event(self, message: Text) -> None:
        """Something the operator is told (the console, the display's last event)."""
        self.last_event = message
        self.counters["events"] += 1
        log.info("%s", message)  # English in the program log
        if self._on_event is not None:
            self._on_event(message)

    def raw(self, kind: str, t: float, payload: Any) -> None:
        """A line or frame as it came in or went out (topdress.log.session)."""
        if self.session is not None:
            self.session.raw(kind, t, payload)
