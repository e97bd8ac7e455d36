"""Replays the Task Controller's side of a session recorded between AgIsoStack++'s
TaskControllerServer (the referee, commit in docs/isobus.md) and the topdress ECU's ISOBUS
layer, against the layer now, and compares its answers: address claimed, DDOP transferred,
accepted and activated, set values for rate and sections acknowledged, measurements at the
cadence the TC asked for."""

from __future__ import annotations

import re
import struct
from pathlib import Path

import pytest

from topdress.isobus.node import Frame, IsobusNode, split_id, topdress_name

pytestmark = pytest.mark.interop

TRACE = Path(__file__).parent / "data" / "agiso_tc_session_topdress_ecu.log"
ECU, TC = 0x84, 0xF7
LINE = re.compile(r"\((\d+\.\d+)\) \S+ ([0-9A-F]{8})#([0-9A-F]*)")


def _trace() -> list[tuple[float, int, bytes]]:
    out = []
    for line in TRACE.read_text(encoding="ascii").splitlines():
        m = LINE.match(line)
        if m:
            out.append((float(m[1]), int(m[2], 16), bytes.fromhex(m[3])))
    return out


def _pd(data: bytes) -> tuple[int, int, int, int]:
    """(command, element, DDI, value) of a process-data message."""
    cmd, element = data[0] & 0x0F, (data[0] >> 4) | (data[1] << 4)
    ddi = data[2] | data[3] << 8
    return cmd, element, ddi, struct.unpack_from("<i", data, 4)[0]


def _replay() -> tuple[IsobusNode, list[tuple[float, Frame]], list[tuple[float, int, bytes]]]:
    frames = _trace()
    t0 = frames[0][0]
    node = IsobusNode(topdress_name(1407, bytes(range(12))), tc_timeout_ms=6000)
    node.start(1000)
    sent: list[tuple[float, Frame]] = []
    theirs = [f for f in frames if split_id(f[1])[2] != ECU]
    t_step = 0.0
    for ts, can_id, data in theirs:
        t = ts - t0
        while t_step + 0.01 <= t:
            t_step += 0.01
            node.step(int(t_step * 1e6) + 1000, int(t_step * 2780))
            sent += [(t_step, f) for f in node.tx()]
        node.rx(can_id, data, int(t * 1e6) + 1000)
        sent += [(t, f) for f in node.tx()]
    return node, sent, frames


def test_referee_session_replays() -> None:
    node, sent, frames = _replay()
    t0 = frames[0][0]
    assert node.address == ECU and node.tc_address == TC
    assert node.tc_state == "connected" and node.counters["connects"] == 1 and not node.alarm
    # the pool went out by TP (RTS of 1 + 1515 bytes) and the TC answered transfer and activation OK
    rts = [f for _, f in sent if split_id(f.can_id)[1] == 0xEC00 and f.data[0] == 16]
    assert rts and rts[0].data[1] | rts[0].data[2] << 8 == 1516
    from_tc = [
        (ts - t0, d) for ts, i, d in frames if split_id(i)[1] == 0xCB00 and split_id(i)[2] == TC
    ]
    assert any(d[0] == 0x71 and d[1] == 0 for _, d in from_tc)
    assert any(d[0] == 0x91 and d[1] == 0 for _, d in from_tc)
    # the rates the TC set last (DDI 6 per bin) are the node's
    last: dict[int, int] = {}
    for _, d in from_tc:
        cmd, element, ddi, value = _pd(d)
        if cmd in (3, 10) and ddi == 6:
            last[element] = value
    assert (node.rate_kg_ha(0), node.rate_kg_ha(1)) == (last[3] / 100, last[4] / 100)
    assert (node.rate_kg_ha(0), node.rate_kg_ha(1)) == (180.0, 120.0)
    # set values with acknowledge: PDACK 0 for 289, 6, 290; 0x04 for DDI 160 on element 4,
    # where the pool has none (the referee's runner addressed it there)
    errors = {(e, ddi): f.data[4] for _, f in sent for c, e, ddi, _v in [_pd(f.data)]
              if split_id(f.can_id)[1] == 0xCB00 and c == 13}  # fmt: skip
    assert errors[(2, 289)] == 0 and errors[(3, 6)] == 0 and errors[(2, 290)] == 0
    assert errors[(4, 160)] == 0x04
    # actual rate of the upper bin every 1000 ms after the TC asked (and on change, distance):
    # the replayed node answers as often as the recorded one did, within one
    asked = next(t for t, d in from_tc if _pd(d)[0] == 4 and _pd(d)[1:3] == (3, 7))
    ours = [t for t, f in sent if split_id(f.can_id)[1] == 0xCB00 and _pd(f.data)[:3] == (3, 3, 7)
            and t >= asked]  # fmt: skip
    recorded = [ts - t0 for ts, i, d in frames if split_id(i)[2] == ECU and split_id(i)[1] == 0xCB00
                and _pd(d)[:3] == (3, 3, 7) and ts - t0 >= asked]  # fmt: skip
    span = frames[-1][0] - t0 - asked
    assert len(ours) >= span - 1  # at least one a second
    assert abs(len(ours) - len(recorded)) <= 1
