"""The terminal's Task Controller against `can-j1939` (a J1939 stack nobody here wrote) over
python-can's udp_multicast on loopback, in real time: the TC's address contested by a NAME that
wins (the TC moves on, and names the other TC) and by one that loses (the TC keeps 0xF7), and a
can-j1939 node as a TC client that uploads a 1750-byte pool to the TC over TP (CMDT) and gets
it activated."""

from __future__ import annotations

import random
import time
from collections.abc import Iterator
from typing import Any

import can
import j1939
import pytest
from can import BusABC as Bus

from isobus_rig import Wire, udp_group
from tc_rig import DDOP
from topdress.isobus.node import Frame, split_id
from topdress.isobus.tcserver import TcServer, tc_name

pytestmark = [pytest.mark.interop, pytest.mark.wallclock]

TC = 0xF7
OURS = tc_name(0x1234)
CLIENT_NAME = 0xA00A8000AFE01092  # a spreader's NAME (device class 5): no TC


class TcOnWire:
    """The TC server as the rig's C objects are driven: frames heard are kept for its step."""

    def __init__(self, tc: TcServer) -> None:
        self.tc = tc
        self._heard: list[Frame] = []
        self._out: list[Frame] = []

    def rx(self, can_id: int, data: bytes, now_us: int) -> None:
        self._heard.append(Frame(can_id, data))

    def step(self, now_us: int) -> None:
        heard, self._heard = self._heard, []
        self._out += self.tc.step(now_us, heard)

    def tx(self) -> list[Frame]:
        out, self._out = self._out, []
        return out


@pytest.fixture
def peer() -> Iterator[tuple[Bus, Any]]:
    """A can-j1939 ECU and a python-can bus on one multicast group and a port of their own: the
    interface binds its port for every group, so a shared port would hear other tests' buses."""
    group, port = udp_group(), random.randrange(20_000, 60_000)
    ecu = j1939.ElectronicControlUnit()
    try:
        ecu.connect(interface="udp_multicast", channel=group, port=port, fd=False)
        bus = can.Bus(interface="udp_multicast", channel=group, port=port, fd=False)
    except OSError as exc:
        pytest.skip(f"udp_multicast CAN unavailable here: {exc}")
    yield bus, ecu
    ecu.stop()
    ecu.disconnect()


def _ca(ecu: Any, name: int, address: int) -> Any:
    ca = j1939.ControllerApplication(j1939.Name(value=name), address)
    ecu.add_ca(controller_application=ca)
    ca.start()
    return ca


def _tc_on_bus(bus: Bus) -> tuple[Wire, TcServer]:
    """The TC on the bus, once it holds 0xF7."""
    w = TcOnWire(TcServer(OURS))
    wire = Wire(bus, w, w.step)
    w.tc.start(wire.now_us())
    wire.pump(0.5, until=lambda: w.tc.address == TC)
    assert w.tc.address == TC
    return wire, w.tc


def _wait(what: Any, seconds: float = 3.0) -> None:
    end = time.monotonic() + seconds
    while not what() and time.monotonic() < end:
        time.sleep(0.02)
    assert what()


def test_tc_address_won_by_a_lower_tc_name(peer: tuple[Bus, Any]) -> None:
    bus, ecu = peer
    w, tc = _tc_on_bus(bus)
    rival = _ca(ecu, OURS - 0x100, TC)  # another TC number 1, with a lower NAME
    w.pump(2.0, until=lambda: tc.address not in (TC, None))
    w.pump(0.3)
    assert rival.device_address == TC
    moved = tc.address
    assert moved is not None and 128 <= moved <= 247 and moved != TC
    claims = [split_id(i)[2] for i, _ in w.sent if split_id(i)[1] == 0xEE00]
    assert claims[0] == TC and claims[-1] == moved
    assert tc.other_tcs == {TC: OURS - 0x100}
    assert tc.alarms == [f"another Task Controller number 1 at {TC:#x}"]
    w.bus.shutdown()


def test_tc_address_defended_against_a_higher_name(peer: tuple[Bus, Any]) -> None:
    bus, ecu = peer
    w, tc = _tc_on_bus(bus)
    intruder = _ca(ecu, CLIENT_NAME, TC)  # an implement that wants 0xF7
    w.pump(2.0, until=lambda: intruder.device_address not in (TC, None))
    w.pump(0.3)
    assert tc.address == TC and intruder.device_address not in (TC, None)
    assert tc.other_tcs == {} and tc.alarms == []
    w.bus.shutdown()


def test_j1939_client_uploads_its_pool_over_tp_and_is_activated(peer: tuple[Bus, Any]) -> None:
    bus, ecu = peer
    w, tc = _tc_on_bus(bus)
    ca = _ca(ecu, CLIENT_NAME, 0x80)
    got: list[bytes] = []
    ca.subscribe(lambda prio, pgn, sa, ts, data: got.append(bytes(data)) if pgn == 0xCB00 else None)
    _wait(lambda: ca.device_address == 0x80)

    def task_message(cookie: Any) -> bool:
        """The client's task message every 2 s (ISO 11783-10): a client that keeps it is not
        dropped however slowly this run goes."""
        ca.send_pgn(0, 0xCB, TC, 6, [0xFF, 0xFF, 0xFF, 0xFF, 0, 0, 0, 0])
        return True

    ca.add_timer(2.0, task_message)
    w.pump(0.4)

    def send(pf: int, ps: int, data: bytes, answer: int | None, seconds: float = 2.0) -> None:
        deadline = time.monotonic() + 3.0
        while not ca.send_pgn(0, pf, ps, 6, list(data)):  # its last session still open
            assert time.monotonic() < deadline
            w.pump(0.05)
        if answer is not None:
            w.pump(seconds, until=lambda: any(g[0] == answer for g in got))
            assert any(g[0] == answer for g in got), (hex(answer), got, tc.errors)

    pool = DDOP.read_bytes()
    send(0xFE, 0x0D, bytes([1]) + b"\xff" * 7, 0x00)  # working-set master: version asked
    send(0xCB, TC, bytes([0x10, 4, 0xFF, 0x15, 0, 1, 6, 2]), None)  # its version
    send(0xCB, TC, bytes([0x01]) + b"\xff" * 7, 0x11)  # structure label: none kept
    send(0xCB, TC, bytes([0x41]) + len(pool).to_bytes(4, "little") + b"\xff" * 3, 0x51)
    send(0xCB, TC, bytes([0x61]) + pool, 0x71, seconds=20.0)  # 1751 bytes: TP CMDT
    send(0xCB, TC, bytes([0x81]) + b"\xff" * 7, 0x91)
    c = tc.client
    assert c is not None and c.address == 0x80 and c.name == CLIENT_NAME
    assert c.pool == pool and c.active and c.geo and tc.errors == []
    assert bytes([0x91, 0, 0xFF, 0xFF, 0xFF, 0xFF, 0, 0xFF]) in got
    # the TC sent CTS windows and the end-of-message acknowledge of a 1751-byte message
    eoma = [d for i, d in w.sent if split_id(i)[1] == 0xEC00 and d[0] == 19]
    assert eoma and int.from_bytes(eoma[0][1:3], "little") == 1751
    w.bus.shutdown()
