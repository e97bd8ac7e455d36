"""The terminal's Task Controller in virtual time: against the topdress ECU's C TC client
(`Bus`, frames passed both ways each 10 ms) and against the client's side of a session recorded
with AgIsoStack++'s TaskControllerClient (`replay_agiso`)."""

from __future__ import annotations

import re
from pathlib import Path

from topdress.isobus.node import Frame, IsobusNode, split_id, topdress_name
from topdress.isobus.poolstore import PoolStore
from topdress.isobus.tcserver import TcServer, tc_name

DATA = Path(__file__).parent / "data"
TRACE = DATA / "agiso_tc_session_agiso_client.log"
DDOP = DATA / "agiso_spreader_ddop_2bins_6sections.bin"
CLIENT, TC = 0x80, 0xF7
AGISO_NAME = 0xA00A8000AFE01092  # the AgIsoStack++ spreader client of the recordings
LINE = re.compile(r"\((\d+\.\d+)\) \S+ ([0-9A-F]{8})#([0-9A-F]*)")


def client_frames(
    trace: Path = TRACE, sources: tuple[int, ...] = (CLIENT,)
) -> list[tuple[int, Frame]]:
    """The frames the clients at `sources` sent in a candump trace, with their time (us)."""
    out = []
    t0 = None
    for line in trace.read_text(encoding="ascii").splitlines():
        m = LINE.match(line)
        if not m:
            continue
        t = float(m[1])
        t0 = t if t0 is None else t0
        can_id = int(m[2], 16)
        if split_id(can_id)[2] in sources:
            out.append((int((t - t0) * 1e6), Frame(can_id, bytes.fromhex(m[3]))))
    return out


def replay_agiso(
    trace: Path = TRACE, store: PoolStore | None = None, sources: tuple[int, ...] = (CLIENT,)
) -> tuple[TcServer, list[Frame]]:
    """The client's side of a recorded session against a fresh server, 10 ms steps between."""
    tc = TcServer(tc_name(7), store=store)
    tc.start(0)
    sent: list[Frame] = []
    now = 0
    for t, f in client_frames(trace, sources):
        while now + 10_000 <= t:
            now += 10_000
            sent += tc.step(now, [])
        sent += tc.step(t, [f])
    return tc, sent


ECU_NAME = topdress_name(1407, bytes(range(12)))
STEP_US = 10_000


class Bus:
    """The C client and the terminal's TC in virtual time, frames passed both ways each 10 ms;
    `mm_per_step` is the distance the client is told it drove."""

    def __init__(self, tc: TcServer, mm_per_step: int = 28) -> None:
        self.node = IsobusNode(ECU_NAME, tc_timeout_ms=6000)
        self.tc = tc
        self.now = 0
        self.mm = 0
        self.mm_per_step = mm_per_step
        self.from_node: list[Frame] = []
        self.from_tc: list[Frame] = []
        self._pending: list[Frame] = []
        self.node.start(0)
        tc.start(0)

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds * 1e6 / STEP_US)):
            self.now += STEP_US
            self.mm += self.mm_per_step
            for f in self._pending:
                self.node.rx(f.can_id, f.data, self.now)
            self.node.step(self.now, self.mm)
            out = self.node.tx()
            self.from_node += out
            self._pending = self.tc.step(self.now, out)
            self.from_tc += self._pending

    def uploads(self) -> int:
        """Pool transfers the client started (its TP/ETP request to send)."""
        return sum(
            1
            for f in self.from_node
            if split_id(f.can_id)[1] in (0xEC00, 0xC800) and f.data[0] in (16, 20)
        )


def connected(tc: TcServer) -> Bus:
    bus = Bus(tc)
    bus.run(4.0)
    c = tc.client
    assert c is not None and c.active and bus.node.tc_state == "connected", tc.errors
    return bus
