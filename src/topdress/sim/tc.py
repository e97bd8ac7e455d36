"""The farm terminal's Task Controller on the simulated bus: the terminal's own TC server
(topdress.isobus.tcserver) with the fault knob `silent` (the TC gone: hears and sends nothing)."""

from __future__ import annotations

from topdress.isobus.node import Frame
from topdress.isobus.tcserver import TcServer, tc_name

TC_IDENTITY = 0x7C  # the simulated terminal's NAME identity number


class MiniTc:
    def __init__(self) -> None:
        self.server = TcServer(tc_name(TC_IDENTITY))
        self.silent = False
        self._started = False

    @property
    def pool(self) -> bytes | None:
        c = self.server.client
        return None if c is None else c.pool

    @property
    def activated(self) -> bool:
        c = self.server.client
        return c is not None and c.active

    @property
    def pdacks(self) -> list[tuple[int, int, int]]:
        c = self.server.client
        return [] if c is None else c.pdacks

    def command(self, element: int, ddi: int, value: int) -> None:
        """Set Value and Acknowledge to the client (ProtocolError before a pool is active)."""
        self.server.set_value(element, ddi, value)

    def step(self, now_us: int, frames_in: list[Frame]) -> list[Frame]:
        if not self._started:
            self._started = True
            self.server.start(now_us)
        if self.silent:
            return []
        return self.server.step(now_us, frames_in)
