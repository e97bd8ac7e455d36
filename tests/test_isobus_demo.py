"""`topdress demo --isobus`: the terminal as the Task Controller of the topdress ECU on ISOBUS.
The console says the TC's address, the implement's DDOP active, what the implement reports, and
at the end what it applied against what the terminal set. The implement alone with a scripted
TC (`run_isobus_demo`): the console says the address claimed, the DDOP accepted and the rate
the TC set. Either way the implement's session log records the ISOBUS traffic and the node's
events, read back by the log's own readers (export)."""

from __future__ import annotations

import io
import re
from pathlib import Path

import pytest

from topdress.cli.isobus_demo import (
    isobus_config_toml,
    run_isobus_demo,
    run_terminal_isobus_demo,
)
from topdress.config import default_config, loads_config
from topdress.isobus.node import split_id
from topdress.log.events import CanEvent
from topdress.log.export import session_events
from topdress.log.session import SessionReader

pytestmark = pytest.mark.wallclock  # paced to the wall clock: 9 s and 3 s
# The terminal demo's 40 s in virtual time, within 3 %: tests/test_terminal_isobus.py.


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


def test_demo_isobus_terminal_sets_the_rate_and_the_implement_applies_it(tmp_path: Path) -> None:
    out = io.StringIO()
    assert run_terminal_isobus_demo(default_config(), 9.0, tmp_path, 1, out) == 0
    text = out.getvalue()
    assert "ISOBUS: Task Controller at address 0xF7" in text
    assert "ISOBUS: implement topdress at 0x84: DDOP active, 2 products in kg/ha" in text
    # what the implement reports, as the terminal received it
    reports = re.findall(r"implement topdress 0x84: ([\d.]+) set / ([\d.]+) reported kg/ha", text)
    # the first line comes as the pool is activated: the topdress ECU's parameters are not
    # in yet, so the TC holds it at 0 (or it reports nothing yet); then the crop-sensor rate,
    # not a fixed one
    rates = [float(s) for s, _ in reports]
    assert rates and rates[-1] > 50.0
    assert all(r > 50.0 or (i == 0 and r == 0.0) for i, r in enumerate(rates)), rates
    # at the end: applied, at the terminal's rate, from the session log
    m = re.search(r"ISOBUS implement applied ([\d.]+) kg (at|OFF) the terminal's rate", text)
    assert m is not None, text
    assert float(m.group(1)) > 0.05  # 9 s from rest; 40 s within 3 %: test_terminal_isobus
    assert "nothing was metered" not in text
    # the implement's own session log: the TC's frames as it heard them, its own, its events
    (path,) = tmp_path.glob("isobus*.sqlite")
    with SessionReader(path) as reader:
        kinds = [e.kind for e in reader.events()]
        frames = [e for e in session_events(reader) if isinstance(e, CanEvent)]
    assert kinds[:2] == ["isobus.claimed", "isobus.ddop"], kinds
    assert "isobus.set" in kinds and "isobus.tc_lost" not in kinds
    by_dir = {d: {split_id(f.can_id)[1] for f in frames if f.dir == d} for d in ("rx", "tx")}
    assert {0xEE00, 0xCB00, 0xEC00, 0xEB00, 0xFE0D} <= by_dir["rx"]
    assert {0xEE00, 0xCB00, 0xEC00} <= by_dir["tx"]


def test_demo_configuration_puts_the_terminal_on_isobus() -> None:
    text = isobus_config_toml('[can]\ninterface = "virtual"\nchannel = "x"\n')
    assert loads_config(text).can.implement == "isobus"
