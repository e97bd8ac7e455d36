"""The firmware's diagnostic frames (protocol/topdress.dbc: EcuCanHealth, EcuFaultRecord):
decoded from the bytes the DBC packs, taken by the terminal's CAN link, shown and logged as
events (terminal/ecuhealth.py)."""

from __future__ import annotations

import can
import pytest

from topdress import protocol
from topdress.config import CanConfig
from topdress.errors import ProtocolError
from topdress.terminal.canlink import CanLink
from topdress.terminal.ecuhealth import health_text


def _health(**kw: int) -> can.Message:
    sig = {"TxErrors": 0, "RxErrors": 0, "BusState": 0, "ErrorPassiveCount": 0}
    sig |= {"BusOffCount": 0, "RxOverruns": 0} | kw
    data = protocol.database().get_message_by_name("EcuCanHealth").encode(sig)
    return can.Message(arbitration_id=0x186A6465, data=data, is_extended_id=True)


def _fault(reg: int, kind: int, value: int) -> can.Message:
    msg = protocol.database().get_message_by_name("EcuFaultRecord")
    data = msg.encode({"RegisterId": reg, "Kind": kind, "Value": value})
    return can.Message(arbitration_id=0x186B6465, data=data, is_extended_id=True)


def test_decode_the_dbc_bytes() -> None:
    # byte layout as the firmware's generated codec packs it (little-endian, DBC order)
    msg = _health(TxErrors=136, RxErrors=3, BusState=1, ErrorPassiveCount=2, BusOffCount=1)
    assert bytes(msg.data) == bytes([136, 3, 1, 2, 0, 1, 0, 0])
    h = protocol.decode(msg)
    assert h == protocol.EcuCanHealth(136, 3, "error-passive", 2, 1, 0)
    assert (
        str(health_text(h)) == "CAN error-passive, errors tx 136 rx 3, error-passive 2x, bus-off 1x"
    )
    rec = protocol.decode(_fault(4, 1, 0x08001234))
    assert rec == protocol.EcuFaultRecord("PC", "hard fault", 0x08001234)
    assert protocol.is_known_id(0x186A6465) and protocol.is_known_id(0x186B6465)


def test_bad_values_are_protocol_errors() -> None:
    data = bytearray(_health().data)
    data[2] = 3  # BusState 3 is not a state
    with pytest.raises(ProtocolError):
        protocol.decode(can.Message(arbitration_id=0x186A6465, data=data, is_extended_id=True))
    bad = bytearray(_fault(0, 1, 0).data)
    bad[0] = 6  # no register 6
    with pytest.raises(ProtocolError):
        protocol.decode(can.Message(arbitration_id=0x186B6465, data=bad, is_extended_id=True))


def test_the_link_keeps_health_and_says_state_changes_and_the_fault_record() -> None:
    bus = can.Bus(interface="virtual", channel="test-ecu-health")
    events: list[str] = []
    try:
        link = CanLink(bus, CanConfig(), fan_rpm=3000, on_event=lambda e: events.append(str(e)))
        link.on_frame(_health(), 1.0)
        assert link.ecu.can_health is not None and events == []  # error-active: nothing to say
        link.on_frame(_health(TxErrors=40), 2.0)
        assert events == []  # counters move, the state does not
        link.on_frame(_health(TxErrors=255, BusState=2, ErrorPassiveCount=1, BusOffCount=1), 3.0)
        assert events == [
            "ECU CAN controller: CAN bus-off, errors tx 255 rx 0, error-passive 1x, bus-off 1x"
        ]
        # the fault record: said once, when all six registers are in; a malformed one counted
        regs = [0x00008200, 0x40000000, 0xE000ED34, 0x20020000, 0x0800_1C3A, 0x0800_1B01]
        for i, v in enumerate(regs):
            link.on_frame(_fault(i, 1, v), 4.0 + i)
        for i, v in enumerate(regs):  # the next round: the same record, not said again
            link.on_frame(_fault(i, 1, v), 10.0 + i)
        said = [e for e in events if "reset after" in e]
        assert said == [
            "ECU reset after a hard fault; it kept CFSR 0x00008200 HFSR 0x40000000 "
            "MMFAR 0xE000ED34 BFAR 0x20020000 PC 0x08001C3A LR 0x08001B01 "
            "(find the PC in the firmware's map file)"
        ]
        # a crystal failure (kind 2) has no registers to wait for: said at its first frame
        link.on_frame(_fault(0, 2, 0), 15.0)
        link.on_frame(_fault(1, 2, 0), 16.0)
        assert [e for e in events if "crystal" in e] == [
            "ECU crystal failure before this start: it ran on its internal oscillator, off the bus "
            "with its outputs off (check the crystal and its load capacitors)"
        ]
        before = link.counters.rx_malformed
        link.on_frame(can.Message(arbitration_id=0x186B6465, data=b"\x09" * 8), 20.0)
        assert link.counters.rx_malformed == before + 1
    finally:
        bus.shutdown()
