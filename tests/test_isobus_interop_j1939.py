"""Interoperability of the ECU's ISOBUS layer (C, through cffi) with `can-j1939`, a J1939 stack
nobody here wrote, over python-can's udp_multicast on loopback: address-claim contests won and
lost by NAME, TP sessions both ways (CMDT and BAM) and aborts, the private frames on
Proprietary A/B."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import can
import j1939
import pytest

from isobus_rig import Wire, udp_bus, udp_group, udp_port
from topdress.isobus.node import ClaimNode, Frame, IsobusNode, TpEndpoint, split_id
from topdress.protocol.dbc import frame_ids

pytestmark = [pytest.mark.interop, pytest.mark.wallclock]

OURS = 0xA00A820000012345  # self-configurable, industry group 2
LOWER = OURS - 0x1000  # wins against ours
HIGHER = OURS + 0x1000  # loses against ours
PGN_PROPA = 0xEF00  # Proprietary A: destination specific


@pytest.fixture
def group() -> str:
    return udp_group()


@pytest.fixture
def peer(group: str) -> Iterator[j1939.ElectronicControlUnit]:
    ecu = j1939.ElectronicControlUnit()
    try:
        ecu.connect(interface="udp_multicast", channel=group, port=udp_port(group), fd=False)
    except OSError as exc:
        pytest.skip(f"udp_multicast CAN unavailable here: {exc}")
    yield ecu
    ecu.stop()  # its job thread first, so it sends nothing to a closed bus
    ecu.disconnect()


def _ca(ecu: j1939.ElectronicControlUnit, name: int, address: int) -> Any:
    """A peer controller application, started; returns once it holds its address."""
    ca = j1939.ControllerApplication(j1939.Name(value=name), address)
    ecu.add_ca(controller_application=ca)
    ca.start()
    return ca


def _settled(ca: Any, address: int) -> None:
    deadline = time.monotonic() + 3.0
    while ca.device_address != address and time.monotonic() < deadline:
        time.sleep(0.02)
    assert ca.device_address == address


def _peer_send(ca: Any, w: Wire, pdu_format: int, pdu_specific: int, payload: bytes) -> None:
    """The peer sends (it takes a list); it refuses while its last session to that address is
    still open, so try again as the bus runs on."""
    deadline = time.monotonic() + 3.0
    while not ca.send_pgn(0, pdu_format, pdu_specific, 6, list(payload)):
        assert time.monotonic() < deadline, "the peer's last session never closed"
        w.pump(0.05)


def _claim_wire(group: str, preferred: int) -> Wire:
    node = ClaimNode(OURS, preferred, (0x80, 0x87))
    return Wire(udp_bus(group), node, node.step)


def test_contest_won_by_our_lower_name(group: str, peer: Any) -> None:
    ca = _ca(peer, HIGHER, 0x84)
    _settled(ca, 0x84)  # the peer holds 0x84 first
    w = _claim_wire(group, 0x84)
    w.obj.start(w.now_us())
    w.pump(1.5, until=lambda: w.obj.address == 0x84 and ca.device_address not in (0x84, None))
    w.pump(0.6)
    assert w.obj.address == 0x84
    assert ca.device_address == 0x85  # the peer moved on, as J1939-81 says
    w.bus.shutdown()


def test_contest_lost_to_a_lower_name(group: str, peer: Any) -> None:
    w = _claim_wire(group, 0x84)
    w.obj.start(w.now_us())
    w.pump(0.4)
    assert w.obj.address == 0x84
    ca = _ca(peer, LOWER, 0x84)
    w.pump(1.5, until=lambda: w.obj.address == 0x85)
    w.pump(0.3)
    assert ca.device_address == 0x84
    assert w.obj.address == 0x85
    claims = [d for i, d in w.sent if split_id(i)[1] == 0xEE00]
    assert [split_id(i)[2] for i, _ in w.sent if split_id(i)[1] == 0xEE00] == [0x84, 0x85]
    assert all(int.from_bytes(d, "little") == OURS for d in claims)
    w.bus.shutdown()


def _tp_pair(group: str, peer: Any, capacity: int = 4096) -> tuple[Wire, Any, list[Any]]:
    got: list[Any] = []
    ca = _ca(peer, HIGHER, 0x90)
    ca.subscribe(lambda prio, pgn, sa, ts, data: got.append((pgn, sa, bytes(data))))
    _settled(ca, 0x90)
    ep = TpEndpoint(0x26, capacity)
    w = Wire(udp_bus(group), ep, ep.step)
    return w, ca, got


def test_cmdt_from_the_peer_to_us(group: str, peer: Any) -> None:
    w, ca, _ = _tp_pair(group, peer)
    payload = bytes((i * 7) & 0xFF for i in range(300))
    _peer_send(ca, w, PGN_PROPA >> 8, 0x26, payload)
    w.pump(5.0, until=lambda: bool(w.obj.received))
    assert w.obj.received == [(PGN_PROPA, 0x90, payload)]
    w.bus.shutdown()


def test_bam_from_the_peer(group: str, peer: Any) -> None:
    w, ca, _ = _tp_pair(group, peer)
    payload = bytes(range(40))
    _peer_send(ca, w, 0xFE, 0xCA, payload)  # a DM1-like broadcast
    w.pump(3.0, until=lambda: bool(w.obj.received))
    assert w.obj.received == [(0xFECA, 0x90, payload)]
    w.bus.shutdown()


def test_cmdt_from_us_to_the_peer(group: str, peer: Any) -> None:
    w, _, got = _tp_pair(group, peer)
    payload = bytes((i * 3 + 1) & 0xFF for i in range(1000))
    w.obj.send(PGN_PROPA, 0x90, payload, w.now_us())
    w.pump(10.0, until=lambda: w.obj.send_state != "busy" and bool(got))
    assert w.obj.send_state == "done"
    assert (PGN_PROPA, 0x26, payload) in got
    w.bus.shutdown()


def test_bam_from_us_to_the_peer(group: str, peer: Any) -> None:
    w, _, got = _tp_pair(group, peer)
    payload = bytes(range(100))
    w.obj.send(0xFECA, 0xFF, payload, w.now_us())
    w.pump(3.0, until=lambda: bool(got))
    assert (0xFECA, 0x26, payload) in got
    w.bus.shutdown()


def test_we_abort_a_message_too_long_and_the_peer_goes_on(group: str, peer: Any) -> None:
    w, ca, _ = _tp_pair(group, peer, capacity=50)
    _peer_send(ca, w, PGN_PROPA >> 8, 0x26, bytes(200))
    w.pump(1.0, until=lambda: any(d[0] == 255 for i, d in w.sent))
    aborts = [d for i, d in w.sent if split_id(i)[1] == 0xEC00 and d[0] == 255]
    assert aborts and aborts[0][1] == 2  # reason 2: resources
    assert w.obj.received == []
    _peer_send(ca, w, PGN_PROPA >> 8, 0x26, bytes(range(45)))  # fits: the peer recovered
    w.pump(5.0, until=lambda: bool(w.obj.received))
    assert w.obj.received == [(PGN_PROPA, 0x90, bytes(range(45)))]
    w.bus.shutdown()


def test_our_cancel_aborts_the_peers_receive(group: str, peer: Any) -> None:
    w, _, got = _tp_pair(group, peer)
    w.obj.send(PGN_PROPA, 0x90, bytes(1500), w.now_us())
    w.pump(2.0, until=lambda: sum(split_id(i)[1] == 0xEB00 for i, _ in w.sent) >= 3)
    w.obj.cancel()  # 3 of 215 packets sent
    w.pump(0.2)
    assert w.obj.send_state == "aborted"
    assert any(split_id(i)[1] == 0xEC00 and d[0] == 255 for i, d in w.sent)
    # can-j1939 2.0.12 ignores an Abort as receiver: its session ends by its own timeout
    # (T1 750 ms), so the next message waits that long
    w.pump(1.5)
    assert not any(pgn == PGN_PROPA for pgn, _, _ in got)  # the half message was dropped
    payload = bytes(range(20))
    w.obj.send(PGN_PROPA, 0x90, payload, w.now_us())
    w.pump(5.0, until=lambda: bool(got))
    assert (PGN_PROPA, 0x26, payload) in got
    w.bus.shutdown()


class _EcuWithCore:
    """The whole node on the bus, with the control core's frames going out on their ISOBUS
    PGNs (`queue`) and the terminal's frames it takes for the core kept in `taken`."""

    def __init__(self) -> None:
        self.node = IsobusNode(OURS, tc_timeout_ms=3500)
        self.queue: list[Frame] = []
        self.taken: list[Frame] = []

    def rx(self, can_id: int, data: bytes, now_us: int) -> None:
        self.node.rx(can_id, data, now_us)
        core = self.node.prop_rx(Frame(can_id, data))
        if core is not None:
            self.taken.append(core)

    def step(self, now_us: int) -> None:
        self.node.step(now_us, 0)

    def tx(self) -> list[Frame]:
        out = self.node.tx()
        for f in self.queue:
            bus = self.node.prop_tx(f)
            assert bus is not None, f"{f.can_id:#x} has no ISOBUS form now"
            out.append(bus)
        self.queue = []
        return out


def test_private_frames_on_proprietary_pgns_with_the_peer(group: str, peer: Any) -> None:
    """The peer plays the terminal (a TC status from its address): its Proprietary A frame to
    us reaches the core as PcParamSet; our EcuStatus reaches it on Proprietary B from our
    claimed address and our EcuParamAck on Proprietary A to it; the same Proprietary A frame
    from another address is ignored and counted."""
    got: list[tuple[int, int, bytes]] = []
    ca = _ca(peer, HIGHER, 0x90)
    ca.subscribe(lambda prio, pgn, sa, ts, data: got.append((pgn, sa, bytes(data))))
    _settled(ca, 0x90)
    ecu = _EcuWithCore()
    w = Wire(udp_bus(group), ecu, ecu.step)
    ecu.node.start(w.now_us())
    w.pump(0.5, until=lambda: ecu.node.address == 0x84)
    assert ecu.node.address == 0x84
    status = bytes([0xFE, 0xFF, 0xFF, 0xFF, 0x00, 0xFF, 0x00, 0xFF])  # TC status, to all
    assert ca.send_pgn(0, 0xCB, 0xFF, 3, list(status))
    w.pump(0.5, until=lambda: ecu.node.tc_address == 0x90)
    assert ecu.node.tc_address == 0x90
    ids = frame_ids()
    param = bytes([37, 0, 0, 0, 0x2C, 0x01, 0, 0])  # MeterTau = 300 ms
    _peer_send_prio(ca, w, 0xEF, 0x84, 2, param)
    w.pump(1.0, until=lambda: bool(ecu.taken))
    assert ecu.taken == [Frame(ids["PcParamSet"], param)]
    ecu.queue = [Frame(ids["EcuStatus"], bytes(range(8))),
                 Frame(ids["EcuParamAck"], bytes([37, 0, 0, 0, 0x2C, 0x01, 0, 0]))]  # fmt: skip

    def mine() -> list[tuple[int, bytes]]:
        return [(pgn & 0x3FF00 if pgn & 0xFF00 < 0xF000 else pgn, data)
                for pgn, sa, data in got if sa == 0x84]  # fmt: skip

    status_b = (0xFF5C, bytes(range(8)))
    ack_a = (0xEF00, bytes([37, 0, 0, 0, 0x2C, 0x01, 0, 0]))
    w.pump(1.0, until=lambda: status_b in mine() and ack_a in mine())
    assert status_b in mine()
    assert ack_a in mine()
    # the same frame from 0x91, a node that is not the TC (sent raw on the bus)
    stranger = (2 << 26) | (0xEF84 << 8) | 0x91
    w.bus.send(can.Message(arbitration_id=stranger, data=param, is_extended_id=True))
    w.pump(1.0, until=lambda: ecu.node.counters["prop_wrong_source"] >= 1)
    assert ecu.node.counters["prop_wrong_source"] == 1
    assert len(ecu.taken) == 1
    w.bus.shutdown()


def _peer_send_prio(ca: Any, w: Wire, pf: int, ps: int, prio: int, payload: bytes) -> None:
    deadline = time.monotonic() + 3.0
    while not ca.send_pgn(0, pf, ps, prio, list(payload)):
        assert time.monotonic() < deadline, "the peer refused to send"
        w.pump(0.05)
