"""The operator's display as the control loop sees it (the desk keeps one `DisplayWatch`).

The terminal's end of the display (topdress.cli.display) posts a `DisplayState` at each change:
its process starting, serving (with how many browser pages are connected), or down. The watch
turns that into two alarms and one decision:

- `display_down`: the display process is not serving (it crashed, hangs, or cannot start); the
  terminal restarts it.
- `display_lost`: the operator had a page open and has had none (or no display process) for
  `display.lost_pause_s`; while metering, the meters are paused then (fans on, rates 0), so the
  machine never meters on with no Stop in front of the operator for longer than that. They stay
  paused until the operator's Start, once a display (or the console) is back.

A terminal whose display nobody ever opened (headless, `run --start` with the console only) is
not paused: the console is its operator's surface.
"""

from __future__ import annotations

from dataclasses import dataclass

from topdress.view.commands import DisplayState

#: With `lost_pause_s = 0` (never pause), the alarm still comes after this long.
ALARM_ONLY_AFTER_S = 3.0


@dataclass(frozen=True)
class DisplayChange:
    """What a tick found: the display just lost for longer than allowed, or back."""

    lost: bool = False
    back: bool = False
    lost_s: float = 0.0  # how long the operator has been without a display


class DisplayWatch:
    def __init__(self, lost_pause_s: float) -> None:
        self.lost_pause_s = lost_pause_s
        self.state: DisplayState | None = None  # None: no display served
        self._had_page = False
        self._without_since: float | None = None
        self._was_without_s = 0.0
        self.lost = False

    @property
    def down(self) -> bool:
        return self.state is not None and self.state.state == "down"

    @property
    def pauses(self) -> bool:
        """Whether losing the display pauses the meters (else: the alarm only)."""
        return self.lost_pause_s > 0.0

    def take(self, state: DisplayState, now: float) -> None:
        self.state = state
        if state.state == "ok" and state.pages > 0:
            self._had_page = True
            if self._without_since is not None:
                self._was_without_s = now - self._without_since
            self._without_since = None
        elif self._had_page and self._without_since is None:
            self._without_since = now

    def tick(self, now: float) -> DisplayChange:
        since = self._without_since
        if since is None:
            if self.lost:
                self.lost = False
                return DisplayChange(back=True, lost_s=self._was_without_s)
            return DisplayChange()
        limit = self.lost_pause_s if self.pauses else ALARM_ONLY_AFTER_S
        if not self.lost and now - since >= limit:
            self.lost = True
            return DisplayChange(lost=True, lost_s=now - since)
        return DisplayChange()
