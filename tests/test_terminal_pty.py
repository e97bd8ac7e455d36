"""The terminal on a real pseudo-terminal read with pyserial: a GNSS port that vanishes."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

import pytest

from topdress.config import default_config
from topdress.devices.can import open_bus
from topdress.devices.lines import FakeLineSource, SerialLineSource
from topdress.gnss import sentences as nmea
from topdress.sim.live import PtyPort
from topdress.terminal.app import Terminal


def _wait_for(cond: Callable[[], bool], timeout_s: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.01)
    return cond()


def test_vanished_gnss_port_forwards_not_available_at_once() -> None:
    cfg = default_config()
    cfg = replace(cfg, can=replace(cfg.can, channel="test-terminal-pty"))
    port = PtyPort()
    gnss = SerialLineSource(port.path, 115200)
    bus = open_bus(cfg.can)
    events: list[str] = []
    term = Terminal(cfg, gnss, FakeLineSource(), bus, on_event=lambda e: events.append(str(e)))
    term.open()
    try:
        assert _wait_for(lambda: gnss.connected)
        line = nmea.rmc("BD", 3600.0, True, 43.9, 125.3, 7.2 / 3.6, 90.0, "210526")
        port.write(line.encode())
        assert _wait_for(lambda: not term.inbox.empty())
        kind, t, payload = term.inbox.get()
        assert (kind, payload) == ("nmea", line.rstrip("\r\n").encode())
        term.handle(kind, t, payload)
        term.tick(time.monotonic())
        assert term.link.command.gnss_kmh == pytest.approx(7.2, abs=0.001)  # via knots
        assert term.snapshot.gnss_link == "ok"
        port.close()  # the USB adapter is pulled: the device node goes away
        assert _wait_for(lambda: not gnss.connected)
        term.tick(time.monotonic())
        assert term.link.command.gnss_kmh is None
        assert term.snapshot.gnss_link == "lost"
        assert events[-2].startswith(f"GNSS lost (serial:{port.path}: ")  # names the port
        assert events[-1] == "alarm: GNSS lost: metering on the ground wheel"  # to acknowledge
        assert gnss.counters["disconnects"] + gnss.counters["open_failures"] >= 1
    finally:
        term.close()
        bus.shutdown()
