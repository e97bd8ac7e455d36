"""UTC for every record: the time of the last GNSS fix carried forward on the monotonic clock.

Never the system clock: a tractor PC's clock is set by hand or by a network it seldom has, and
one set back while a session ran made the as-applied times run backwards. Through a GNSS gap
the receiver's last UTC is carried forward on the monotonic clock (which drifts by parts per
million: a few ms an hour); before the first fix with a date there is no UTC (None)."""

from __future__ import annotations

from datetime import datetime


def parse_fix_utc(text: str | None) -> float | None:
    """POSIX seconds of a fix's ISO time (RMC gives date and time); None without a date."""
    if text is None or "T" not in text:
        return None
    try:
        return datetime.fromisoformat(text.replace("Z", "+00:00")).timestamp()
    except ValueError:
        return None


class UtcClock:
    """`on_fix(t, utc_text)` with each fix's arrival time; `now(t)` gives (POSIX s, "gnss"),
    or None before the first fix with a date.

    The fix's time is when the receiver measured, the arrival a few hundred ms later: the
    receiver's latency is not known here, so the arrival is taken as the fix time (the rows
    are at most that latency late in UTC; the monotonic `t` keeps the exact order)."""

    def __init__(self) -> None:
        self._anchor: tuple[float, float] | None = None  # (monotonic t, UTC s) of the last fix

    def on_fix(self, t: float, utc_text: str | None) -> None:
        utc = parse_fix_utc(utc_text)
        if utc is not None:
            self._anchor = (t, utc)

    def now(self, t: float) -> tuple[float, str] | None:
        if self._anchor is None:
            return None
        return self._anchor[1] + (t - self._anchor[0]), "gnss"
