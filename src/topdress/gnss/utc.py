"""UTC for every record: the time of the last GNSS fix carried forward on the monotonic clock,
else the system clock, and which of the two it is."""

from __future__ import annotations

import time
from collections.abc import Callable
from datetime import datetime
from typing import Final

# A fix's time is carried forward this long at most; after that the system clock is used.
MAX_CARRY_S: Final = 10.0


def parse_fix_utc(text: str | None) -> float | None:
    """POSIX seconds of a fix's ISO time (RMC gives date and time); None without a date."""
    if text is None or "T" not in text:
        return None
    try:
        return datetime.fromisoformat(text.replace("Z", "+00:00")).timestamp()
    except ValueError:
        return None


class UtcClock:
    """`on_fix(t, utc_text)` with each fix's arrival time; `now(t)` gives (POSIX s, source).

    The fix's time is when the receiver measured, the arrival a few hundred ms later: the
    receiver's latency is not known here, so the arrival is taken as the fix time (the rows
    are at most that latency late in UTC; the monotonic `t` keeps the exact order)."""

    def __init__(self, system: Callable[[], float] = time.time) -> None:
        self._system = system
        self._anchor: tuple[float, float] | None = None  # (monotonic t, UTC s) of the last fix

    def on_fix(self, t: float, utc_text: str | None) -> None:
        utc = parse_fix_utc(utc_text)
        if utc is not None:
            self._anchor = (t, utc)

    def now(self, t: float) -> tuple[float, str]:
        if self._anchor is not None and 0.0 <= t - self._anchor[0] <= MAX_CARRY_S:
            return self._anchor[1] + (t - self._anchor[0]), "gnss"
        return self._system(), "system"
