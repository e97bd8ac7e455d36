"""The simulated Task Controller (the farm terminal's twin, until the terminal has its own TC):
status every 2 s, answers the client's version, language and label requests, takes the pool
(the layer's C TP), accepts and activates it, then sets rates and sections as told; `silent`
is its fault knob (the TC gone)."""

from __future__ import annotations

import struct

from topdress.errors import ProtocolError
from topdress.isobus.node import Frame, TpEndpoint, split_id

TC = 0xF7


def _id(pgn: int, da: int, prio: int = 5) -> int:
    return prio << 26 | pgn << 8 | da << 8 | TC if pgn >> 8 < 240 else prio << 26 | pgn << 8 | TC


def pd(cmd: int, element: int, ddi: int, value: int) -> bytes:
    return bytes([cmd | (element & 0xF) << 4, element >> 4, ddi & 0xFF, ddi >> 8]) + struct.pack(
        "<i", value
    )


class MiniTc:
    def __init__(self) -> None:
        self.tp = TpEndpoint(TC, 4096)
        self.client: int | None = None
        self.silent = False
        self.pool: bytes | None = None
        self.activated = False
        self._out: list[Frame] = []
        self._next_status = 0
        self.pdacks: list[tuple[int, int, int]] = []  # (element, DDI, errors)

    def _to(self, da: int, data: bytes) -> None:
        self._out.append(Frame(_id(0xCB00, da), data))

    def command(self, element: int, ddi: int, value: int) -> None:
        """Set Value and Acknowledge to the client (ProtocolError before one connected)."""
        if self.client is None:
            raise ProtocolError("the simulated TC has no client yet")
        self._to(self.client, pd(10, element, ddi, value))

    def step(self, now_us: int, frames_in: list[Frame]) -> list[Frame]:
        for f in frames_in:
            _, pgn, sa, da = split_id(f.can_id)
            if self.silent:
                continue
            if pgn in (0xEC00, 0xEB00, 0xC800, 0xC700):
                self.tp.rx(f.can_id, f.data, now_us)
                if self.tp.received and self.pool is None:
                    self.pool = self.tp.received[-1][2]
                    self._to(
                        sa, bytes([0x71, 0]) + struct.pack("<I", len(self.pool) - 1) + b"\xff\xff"
                    )
            elif pgn == 0xEA00 and da == TC:
                self._out.append(Frame(_id(0xFE0F, 0xFF, 6), b"en\x50\x00\x00\x00\xff\xff"))
            elif pgn == 0xCB00 and da == TC:
                self.client = sa
                b0 = f.data[0]
                if b0 == 0x00:
                    self._to(sa, bytes([0x10, 4, 0xFF, 0x13, 0, 1, 16, 2]))
                elif b0 == 0x01:
                    self._to(sa, bytes([0x11]) + b"\xff" * 7)
                elif b0 == 0x41:
                    self._to(sa, bytes([0x51, 0]) + b"\xff" * 6)
                elif b0 == 0x81:
                    self.activated = True
                    self._to(sa, bytes([0x91, 0, 0xFF, 0xFF, 0xFF, 0xFF, 0, 0xFF]))
                elif b0 & 0x0F == 13:
                    e, ddi = (b0 >> 4) | f.data[1] << 4, f.data[2] | f.data[3] << 8
                    self.pdacks.append((e, ddi, f.data[4]))
        if not self.silent and now_us >= self._next_status:
            self._next_status = now_us + 2_000_000
            self._out.append(
                Frame(_id(0xCB00, 0xFF, 3), bytes([0xFE, 0xFF, 0xFF, 0xFF, 1, 0xFF, 0, 0xFF]))
            )
        self.tp.step(now_us)
        out = [] if self.silent else self._out + self.tp.tx()
        self._out = []
        return out
