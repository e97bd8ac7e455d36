"""The terminal of the virtual-time rigs (tests/test_terminal.py's VirtualRig, the ISOBUS rigs):
the real Terminal with fake GNSS and crop lines and its CAN port on a virtual bus of its own,
the machine's end of that bus beside it, every event it says kept with the world's time."""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterable
from dataclasses import replace

import can

from topdress.config import TerminalConfig
from topdress.devices.can import open_bus
from topdress.devices.lines import FakeLineSource
from topdress.log.session import SessionLog
from topdress.terminal.app import Terminal

_channels = itertools.count()


class TerminalParts:
    """`cfg` on a channel of its own (`channel_cfg`), the terminal opened on it."""

    def __init__(
        self,
        cfg: TerminalConfig,
        clock: Callable[[], float],
        session: SessionLog | None,
        implement: str | None = None,
    ) -> None:
        channel = f"test-rig-{next(_channels)}"
        can_cfg = replace(cfg.can, channel=channel)
        if implement is not None:
            can_cfg = replace(can_cfg, implement=implement)
        self.cfg = replace(cfg, can=can_cfg)
        self.gnss = FakeLineSource()
        self.crop = FakeLineSource()
        self.pc_bus: can.BusABC = open_bus(self.cfg.can)
        self.ecu_bus: can.BusABC = open_bus(self.cfg.can)  # the machine's end
        self.events: list[tuple[float, str]] = []
        self.term = Terminal(
            self.cfg,
            self.gnss,
            self.crop,
            self.pc_bus,
            session,
            clock=clock,
            on_event=lambda e: self.events.append((clock(), str(e))),
        )
        self.term.open()

    def deliver(
        self, t: float, nmea: Iterable[str], crop: Iterable[str], frames: Iterable[can.Message]
    ) -> None:
        """One step of the machine at `t`: its NMEA and crop lines to the terminal's sources, its
        frames to the terminal's inbox (as its CAN reader puts them)."""
        for line in nmea:
            self.gnss.emit(t, line.encode())
        for line in crop:
            self.crop.emit(t, line.encode())
        for msg in frames:
            self.term.inbox.put(("can", t, msg))

    def close(self) -> None:
        self.term.close()
        self.pc_bus.shutdown()
        self.ecu_bus.shutdown()
