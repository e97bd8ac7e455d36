"""The terminal's inbox: what the reader threads hand to the control loop.

Two kinds of input, two disciplines:

- control items (CAN frames, CAN errors, operator commands) go to one FIFO that is served first;
  a CAN bus at 1 Mbit/s carries at most ~8,000 frames/s, so its bound is only a safety net;
- lines (NMEA, crop) go to one bounded deque per source. A source that floods (a file replayed as
  fast as it is read, a receiver at the wrong rate, a pty spammed) loses its *oldest* lines,
  counted per source in `dropped`; the newest line is the one worth acting on, and a flood can
  neither grow memory nor delay a CAN frame or the 10 Hz tick.

`get()` returns the oldest control item if there is one, else a line from the sources in turn,
else waits (up to `timeout`) for the next put.
"""

from __future__ import annotations

import threading
import time
from collections import Counter, deque
from typing import Any

Item = tuple[str, float, Any]

LINE_KINDS = ("nmea", "crop")
LINE_LIMIT = 256  # per source: 25 s of a 10 Hz receiver, 6 s of 4 sensors at 10 Hz
CONTROL_LIMIT = 20_000  # CAN frames and commands: over 2 s of a fully loaded bus


class Inbox:
    """Thread-safe: any thread puts, the control loop gets."""

    def __init__(self, line_limit: int = LINE_LIMIT, control_limit: int = CONTROL_LIMIT) -> None:
        self._lock = threading.Lock()
        # A bell, not a threading.Condition: waiting is one lock acquire in C (a Condition's
        # wait and notify run in Python, ~100 times a second each). Held = not rung; the puts
        # ring it (under `_lock`, so one at a time), the loop takes the ring by acquiring it.
        self._bell = threading.Lock()
        self._bell.acquire()
        self._control: deque[Item] = deque()
        self._control_limit = control_limit
        self._lines: dict[str, deque[Item]] = {k: deque(maxlen=line_limit) for k in LINE_KINDS}
        self._turn = 0
        self.dropped: Counter[str] = Counter()
        self.high_water: Counter[str] = Counter()

    def put(self, item: Item) -> None:
        """Queue one item; lines of a full source push out that source's oldest line."""
        kind = item[0]
        with self._lock:
            lines = self._lines.get(kind)
            if lines is not None:
                if len(lines) == lines.maxlen:
                    self.dropped[kind] += 1
                lines.append(item)
                depth = len(lines)
            else:
                if len(self._control) >= self._control_limit:
                    self._control.popleft()
                    self.dropped[kind] += 1
                self._control.append(item)
                depth = len(self._control)
            if depth > self.high_water[kind]:
                self.high_water[kind] = depth
            if self._bell.locked():
                self._bell.release()

    def get(self, timeout: float | None = None) -> Item | None:
        """The next item, control first; None when nothing came within `timeout` seconds."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            with self._lock:
                item = self._take()
            if item is not None:
                return item
            wait = -1.0 if deadline is None else deadline - time.monotonic()
            if deadline is not None and wait <= 0:
                return None
            rung = self._bell.acquire(timeout=wait)
            with self._lock:
                item = self._take()
            if item is not None or not rung:
                return item
            # rung for an item taken meanwhile without waiting: wait on

    def empty(self) -> bool:
        with self._lock:
            return not self._control and not any(self._lines.values())

    def depth(self) -> int:
        with self._lock:
            return len(self._control) + sum(len(q) for q in self._lines.values())

    def _take(self) -> Item | None:
        if self._control:
            return self._control.popleft()
        # Round robin over the line sources, so a flooding GNSS does not starve the crop line.
        for i in range(len(LINE_KINDS)):
            kind = LINE_KINDS[(self._turn + i) % len(LINE_KINDS)]
            if self._lines[kind]:
                self._turn = (self._turn + i + 1) % len(LINE_KINDS)
                return self._lines[kind].popleft()
        return None
