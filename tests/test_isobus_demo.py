"""`topdress demo --isobus`: the console says the address claimed, the DDOP accepted and the
rate the TC set, and the session log records the ISOBUS traffic and the node's events, read
back by the log's own readers (export)."""

from __future__ import annotations

import io
from pathlib import Path

import pytest

from topdress.cli.isobus_demo import run_isobus_demo
from topdress.config import default_config
from topdress.isobus.node import split_id
from topdress.log.events import CanEvent
from topdress.log.export import session_events
from topdress.log.session import SessionReader

pytestmark = pytest.mark.wallclock  # paced to the wall clock: 3 s


def test_demo_isobus_claims_connects_and_applies(tmp_path: Path) -> None:
    out = io.StringIO()
    assert run_isobus_demo(default_config(), 3.0, tmp_path, 1, out) == 0
    text = out.getvalue()
    assert "address 0x84 claimed" in text
    assert "TC 0xF7: DDOP accepted and activated" in text
    assert "TC set upper 150 kg/ha, lower 100 kg/ha, sections 111111" in text
    (path,) = tmp_path.glob("isobus*.sqlite")
    with SessionReader(path) as reader:
        events = list(reader.events())
        frames = [e for e in session_events(reader) if isinstance(e, CanEvent)]
    kinds = [e.kind for e in events]
    assert kinds[:3] == ["isobus.claimed", "isobus.ddop", "isobus.set"], kinds
    claimed, ddop, setting = events[:3]
    assert claimed.detail["address"] == 0x84 and claimed.detail["state"] == "claimed"
    assert ddop.detail == {"accepted": True, "tc": 0xF7, "code": 0}
    assert 0.2 < claimed.t < ddop.t < setting.t < 3.0
    final = [e for e in events if e.kind == "isobus.set"][-1].detail
    assert final == {"upper_kg_ha": 150.0, "lower_kg_ha": 100.0, "sections": 0b111111}
    assert "isobus.tc_lost" not in kinds
    by_dir = {d: {split_id(f.can_id)[1] for f in frames if f.dir == d} for d in ("rx", "tx")}
    # the ECU's: claim, process data, TP of its pool, working set master, its status (Prop. B)
    assert {0xEE00, 0xCB00, 0xEC00, 0xEB00, 0xFE0D, 0xFF5C} <= by_dir["rx"]
    # the TC's: its claim, process data, TP flow control
    assert {0xEE00, 0xCB00, 0xEC00} <= by_dir["tx"]
