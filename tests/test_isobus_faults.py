"""Bad input and faults on the ISOBUS (issue: "Bad input and faults"), the simulated machine
with its C node and the terminal's Task Controller in virtual time. Each gives the console's
line (topdress.cli.isobus_demo.console_line) and the log's event (IsobusWatch), the meters in a
safe state, and no restart of the node: a TC that refuses the DDOP, a higher-priority NAME that
takes our address, values out of range or for unknown elements, a DDOP transfer aborted
halfway. (A bus at 100 % load: tests/test_isobus_load.py.)"""

from __future__ import annotations

import io
from collections.abc import Callable
from pathlib import Path

import pytest

from topdress.cli.isobus_demo import console_line, run_isobus_demo
from topdress.config import default_config
from topdress.isobus import tcserver
from topdress.isobus.node import ClaimNode, Frame, IsobusNode, split_id, topdress_name
from topdress.log.isobus import IsobusWatch
from topdress.log.model import LogEvent
from topdress.log.session import SessionReader
from topdress.sim.isobus import IsobusMachine, tc_timeout_ms
from topdress.sim.tc import MiniTc
from topdress.sim.tractor import Drive
from topdress.sim.world import World

ALL_ON = -4096 + 0x555
ECU, TC = 0x84, 0xF7
TP_CM = 0xEC00


def _unchanged(frames: list[Frame]) -> list[Frame]:
    return frames


class Rig:
    """The machine, the TC and the watch; `run()` steps them, `inject` adds frames to the ECU,
    `intercept` may rewrite the TC's frames to the ECU."""

    def __init__(self) -> None:
        world = World(seed=3, drive=Drive.paper_run(7.0, hold_m=600.0, wait_s=2.0))
        node = IsobusNode(topdress_name(1407, bytes(range(12))), tc_timeout_ms=tc_timeout_ms(1500))
        self.m, self.tc, self.watch = (
            IsobusMachine(world, node, 3.6, 6),
            MiniTc(),
            IsobusWatch(node),
        )
        self.node, self.world = node, world
        self.events: list[LogEvent] = []
        self.lines: list[str] = []
        self.pending: list[Frame] = []
        self.peers: list[ClaimNode] = []
        self.intercept: Callable[[list[Frame]], list[Frame]] = _unchanged

    def run(self, seconds: float, inject: list[Frame] | None = None) -> list[Frame]:
        heard: list[Frame] = []
        extra = list(inject or [])
        for _ in range(round(seconds / self.world.dt)):
            now = self.world.now_us
            for p in self.peers:
                p.step(now)
                extra += p.tx()
            out = self.m.step(self.intercept(self.pending) + extra)
            for p in self.peers:
                for f in out:
                    p.rx(f.can_id, f.data, now)
            heard += out
            for ev in self.watch.events(self.world.t_s):
                self.events.append(ev)
                line = console_line(ev)
                if line is not None:
                    self.lines.append(line)
            self.pending = self.tc.step(now, out + extra)
            extra = []
        return heard

    def connect_and_apply(self) -> None:
        self.run(3.0)
        assert self.tc.activated
        for element, ddi, value in ((2, 160, 1), (2, 289, 1), (3, 6, 15000), (2, 290, ALL_ON)):
            self.tc.command(element, ddi, value)
        self.run(3.0)
        assert self.m.running and self.node.rate_kg_ha(0) == 150.0

    def kinds(self) -> list[str]:
        return [e.kind for e in self.events]


def _set_value(element: int, ddi: int, value: int) -> Frame:
    """Set Value and Acknowledge from the TC to the ECU, raw (the TC server checks what it
    sends; a foreign TC need not)."""
    data = bytes([0x0A | (element & 0xF) << 4, element >> 4]) + ddi.to_bytes(2, "little")
    return Frame((3 << 26) | (0xCB << 16) | (ECU << 8) | TC, data + value.to_bytes(4, "little"))


def test_values_out_of_range_or_for_unknown_elements_are_refused() -> None:
    r = Rig()
    r.connect_and_apply()
    bad = [
        _set_value(3, 6, 70_000),  # 700 kg/ha: above the DDOP's maximum 600
        _set_value(99, 6, 10_000),  # no element 99
        _set_value(3, 999, 1),  # no DDI 999 on the bin
        _set_value(3, 7, 10_000),  # the actual rate: not settable
    ]
    r.run(0.5, bad)
    pdacks = {(e, d): err for e, d, err in r.tc.pdacks if err != 0}
    assert pdacks == {(3, 6): 0x80, (99, 6): 0x02, (3, 999): 0x04, (3, 7): 0x10}
    (ev,) = [e for e in r.events if e.kind == "isobus.value_refused"]
    assert ev.detail == {"refused": 4, "total": 4}
    assert any("TC values refused: 4 (4 so far)" in line for line in r.lines), r.lines
    # the rate in force is kept, the meters run at it: never at 700 kg/ha
    r.run(1.0)
    assert r.node.rate_kg_ha(0) == 150.0 and r.m.running
    assert r.node.counters["connects"] == 1


def test_a_higher_priority_name_takes_our_address() -> None:
    r = Rig()
    r.connect_and_apply()
    rival = ClaimNode(0x0000_0000_0000_0001, ECU, (ECU, ECU))  # the lowest NAME wins
    rival.start(r.world.now_us)
    r.peers.append(rival)
    stopped_with_alarm = False
    for _ in range(10):
        r.run(0.05)
        stopped_with_alarm |= not r.m.running and r.node.alarm
    assert rival.address == ECU
    new = r.node.address
    assert new is not None and new != ECU and 0x80 <= new <= 0x87
    assert r.node.counters["contests_lost"] == 1
    moved = [e for e in r.events if e.kind == "isobus.claimed" and "moved" in e.detail]
    assert moved and moved[0].detail["moved"] == ECU and moved[0].detail["address"] == new
    assert any(f"address 0x84 taken by a higher-priority NAME: now 0x{new:02X}" in line
               for line in r.lines), r.lines  # fmt: skip
    # the connection starts again from the new address: no rate meanwhile, the meters stop
    assert stopped_with_alarm
    assert "isobus.tc_lost" in r.kinds()
    assert any("ALARM: Task Controller lost, meters stopped" in line for line in r.lines)
    # the TC lets the old client go (its NAME claimed another address) and takes the same ECU
    # at its new address
    assert r.tc.server.counters["clients_displaced"] == 1
    r.run(15.0)
    assert r.node.tc_state == "connected" and r.node.counters["connects"] == 2
    assert r.tc.server.client is not None and r.tc.server.client.address == new
    for element, ddi, value in ((2, 160, 1), (2, 289, 1), (3, 6, 15000), (2, 290, ALL_ON)):
        r.tc.command(element, ddi, value)
    r.run(1.0)
    assert r.m.running and r.node.claim_state == "claimed"


def test_ddop_transfer_aborted_halfway_is_sent_again() -> None:
    r = Rig()
    seen_cts = [0]

    def abort_second_cts(frames: list[Frame]) -> list[Frame]:
        out = []
        for f in frames:
            _, pgn, _, da = split_id(f.can_id)
            if pgn == TP_CM and da == ECU and f.data[0] == 17:  # CTS to the ECU
                seen_cts[0] += 1
                if seen_cts[0] == 2:  # the pool half sent: the TC aborts (reason 2: resources)
                    data = bytes([255, 2, 0xFF, 0xFF, 0xFF, 0x00, 0xCB, 0x00])
                    f = Frame(f.can_id, data)
            out.append(f)
        return out

    r.intercept = abort_second_cts
    r.run(2.5)
    assert seen_cts[0] >= 2
    (ev,) = [e for e in r.events if e.kind == "isobus.tp_aborted"]
    assert ev.detail == {"state": "aborted", "reason": 2, "tc_state": "pool transfer"}
    assert any("DDOP transfer aborted (reason 2), sent again in 2 s" in line for line in r.lines)
    assert not r.m.running  # no rate without an active pool
    r.intercept = _unchanged
    r.run(6.0)
    assert r.tc.activated and r.node.tc_state == "connected"
    assert r.node.counters["connects"] == 1 and not r.node.alarm


def test_a_tc_that_refuses_the_ddop(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(tcserver, "MAX_POOL_BYTES", 1000)  # a TC without room for our pool
    out = io.StringIO()
    assert run_isobus_demo(default_config(), 5.0, tmp_path, 1, out, pace=False) == 0
    text = out.getvalue()
    assert "refused the DDOP (code 0x" in text and "meters stopped" in text, text
    assert "DDOP accepted" not in text and "TC set upper" not in text
    (path,) = tmp_path.glob("isobus*.sqlite")
    with SessionReader(path) as reader:
        events = list(reader.events())
    (ddop,) = [e for e in events if e.kind == "isobus.ddop"]
    assert ddop.detail["accepted"] is False and ddop.detail["code"] != 0
    assert not [e for e in events if e.kind == "isobus.set"]  # nothing applied
