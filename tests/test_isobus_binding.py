"""The ECU's ISOBUS C layer through cffi: NAME fields, claim contests, TP/ETP between two
endpoints, and the node's connection to a Task Controller driven from Python."""

from __future__ import annotations

import pytest

from topdress.errors import ProtocolError
from topdress.isobus.node import (
    ClaimNode,
    Frame,
    IsobusNode,
    TpEndpoint,
    name_fields,
    split_id,
    topdress_name,
)

UID = bytes(range(12))


def test_name_of_the_implement() -> None:
    name = topdress_name(1407, UID)
    f = name_fields(name)
    assert (f["industry_group"], f["device_class"], f["function"]) == (2, 5, 128)
    assert (f["manufacturer_code"], f["self_configurable"]) == (1407, 1)
    assert f["identity_number"] == name & 0x1FFFFF
    assert topdress_name(1407, UID[:-1] + b"\x0c") != name
    with pytest.raises(ProtocolError, match="manufacturer code 2048"):
        topdress_name(2048, UID)


def _exchange(a: object, b: object, now: int) -> None:
    for src, dst in ((a, b), (b, a)):
        for f in src.tx():  # type: ignore[attr-defined]
            dst.rx(f.can_id, f.data, now)  # type: ignore[attr-defined]


def test_claim_contest_between_two_c_nodes() -> None:
    low, high = (
        ClaimNode(0x100, 0x80, (0x80, 0x87)),
        ClaimNode(0x8000000000000200, 0x80, (0x80, 0x87)),
    )
    low.start(0)
    high.start(0)
    for t in range(0, 400_000, 10_000):
        _exchange(low, high, t)
        low.step(t)
        high.step(t)
    assert (low.address, high.address) == (0x80, 0x81)


@pytest.mark.parametrize("size", [9, 1785, 1786, 3000])
def test_tp_and_etp_between_two_endpoints(size: int) -> None:
    a, b = TpEndpoint(0x84), TpEndpoint(0x26)
    payload = bytes((i * 13) & 0xFF for i in range(size))
    a.send(0xCB00, 0x26, payload, 0)
    for t in range(0, 5_000_000, 10_000):
        _exchange(a, b, t)
        a.step(t)
        b.step(t)
    assert a.send_state == "done"
    assert b.received == [(0xCB00, 0x84, payload)]


def _pd(b0: int, *rest: int) -> bytes:
    return bytes([b0, *rest] + [0xFF] * (7 - len(rest)))


def test_node_connects_to_a_tc_holding_its_pool() -> None:
    node = IsobusNode(topdress_name(1407, UID))
    node.start(0)
    tc, now = 0xF7, 0
    answers = {0x00: _pd(0x10, 4, 0xFF, 0x13, 0, 1, 16, 2)}
    seen: list[Frame] = []
    for _ in range(400):
        now += 10_000
        node.step(now, 0)
        if now % 1_000_000 == 0:
            node.rx(0x0CCBFFF7, _pd(0xFE, 0xFF, 0xFF, 0xFF, 0, 0xFF, 0, 0xFF), now)
        for f in node.tx():
            seen.append(f)
            _, pgn, _, da = split_id(f.can_id)
            if pgn == 0xCB00 and da == tc and f.data[0] in answers:
                node.rx(0x14CB00F7 | (node.address or 0) << 8, answers[f.data[0]], now)
            if pgn == 0xCB00 and f.data[0] == 0x01:  # structure label: none stored
                node.rx(0x14CB00F7 | (node.address or 0) << 8, _pd(0x11, *[0xFF] * 7), now)
            if pgn == 0xCB00 and f.data[0] == 0x41:  # pool size: refuse, not enough memory
                node.rx(0x14CB00F7 | (node.address or 0) << 8, _pd(0x51, 1), now)
    assert node.address == 0x84 and node.claim_state == "claimed"
    assert node.tc_address == tc
    assert node.tc_state == "refused" and node.alarm and node.refuse_code == 1
    assert node.rate_kg_ha(0) == 0.0 and node.sections_on == 0
    assert any(split_id(f.can_id)[1] == 0xFE0D for f in seen)  # the working set was announced
    with pytest.raises(ProtocolError, match="at most 8 bytes"):
        node.rx(0x18EEFF26, bytes(9), now)
    with pytest.raises(ProtocolError, match="no measured DDI 6"):
        node.set_actual(3, 6, 1)
