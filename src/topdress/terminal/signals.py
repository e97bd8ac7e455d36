"""Stop signals: the first SIGINT/SIGTERM stops the terminal, the later ones cannot tear it.

A service stop (SIGTERM) or Ctrl-C (SIGINT) raises KeyboardInterrupt once, in the main thread,
so the loop ends through its normal close: stop command to the ECU, readers stopped, session log
closed (`closed_utc`, the last batch committed). An impatient second Ctrl-C, or systemd sending
SIGTERM to the whole process group, used to land inside that close and leave the log unclosed.
From the first signal on the process ignores them, and while the terminal closes (`deferred()`)
they are recorded, not raised; the close has its own timeouts (2 s per thread), so it ends.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopSignals:
    """Installed in the main thread for the duration of a run (`installed()`)."""

    def __init__(self) -> None:
        self.stopping = False
        self.ignored = 0

    def _on_signal(self, signum: int, frame: FrameType | None) -> None:
        if self.stopping:
            self.ignored += 1
            return
        self.stopping = True
        if signum == signal.SIGINT:
            raise KeyboardInterrupt  # Ctrl-C: "stopped by the operator"
        raise KeyboardInterrupt(signal.Signals(signum).name)

    @contextmanager
    def installed(self) -> Iterator[StopSignals]:
        if threading.current_thread() is not threading.main_thread():
            yield self
            return
        previous = {s: signal.signal(s, self._on_signal) for s in STOP_SIGNALS}
        try:
            yield self
        finally:
            # Once stopping, the process is on its way out (the report, the exit code): the
            # kernel drops further signals. A Python handler would be reset to the default
            # (terminate) while the interpreter exits, and a burst would kill it after all.
            for s, handler in previous.items():
                signal.signal(s, signal.SIG_IGN if self.stopping else handler)


@contextmanager
def deferred() -> Iterator[list[int]]:
    """Within the block, stop signals are recorded (the list), not raised: for closing the
    session log whole. Only the main thread can set handlers; elsewhere it does nothing."""
    got: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield got
        return

    def note(signum: int, frame: FrameType | None) -> None:
        got.append(signum)

    previous = {s: signal.signal(s, note) for s in STOP_SIGNALS}
    try:
        yield got
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
