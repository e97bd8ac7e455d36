"""A C ISOBUS object (claim, TP endpoint or the whole node) on a python-can bus in real time:
the test drives it by polling, steps it every 10 ms on the monotonic clock and drops the
frames udp_multicast echoes back to their sender."""

from __future__ import annotations

import random
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import can
import pytest


def udp_group() -> str:
    return f"239.74.{random.randrange(1, 250)}.{random.randrange(1, 250)}"


def udp_port(group: str) -> int:
    """A port of the group's own: a socket on python-can's default port hears every group
    joined on this host (Linux), so two runs at once (two pytest workers) would talk to each
    other's nodes."""
    a, b = (int(x) for x in group.split(".")[2:])
    return 20000 + (a * 250 + b) % 40000


def udp_bus(group: str) -> can.BusABC:
    try:
        return can.Bus(interface="udp_multicast", channel=group, port=udp_port(group), fd=False)
    except OSError as exc:
        pytest.skip(f"udp_multicast CAN unavailable here: {exc}")


class Wire:
    """One C object on the bus; `rx(id, data, now_us)`, `tx()` and `step(now_us)` of it."""

    def __init__(self, bus: can.BusABC, obj: Any, step: Callable[[int], None]) -> None:
        self.bus = bus
        self.obj = obj
        self._step = step
        self._echo: deque[tuple[int, bytes]] = deque(maxlen=256)
        self._t0 = time.monotonic()
        self._last_step = -1
        self.sent: list[tuple[int, bytes]] = []
        self.heard: list[tuple[int, bytes]] = []

    def now_us(self) -> int:
        return int((time.monotonic() - self._t0) * 1e6) + 1000

    def pump(self, seconds: float, until: Callable[[], bool] | None = None) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            msg = self.bus.recv(timeout=0.002)
            now = self.now_us()
            if msg is not None and msg.is_extended_id:
                key = (msg.arbitration_id, bytes(msg.data))
                if key in self._echo:
                    self._echo.remove(key)  # our own frame looped back
                else:
                    self.heard.append(key)
                    self.obj.rx(msg.arbitration_id, bytes(msg.data), now)
            if now - self._last_step >= 10_000:
                self._last_step = now
                self._step(now)
            for f in self.obj.tx():
                self._echo.append((f.can_id, f.data))
                self.sent.append((f.can_id, f.data))
                self.bus.send(
                    can.Message(arbitration_id=f.can_id, data=f.data, is_extended_id=True)
                )
            if until is not None and until():
                return
