"""`topdress demo --isobus`: the terminal as the Task Controller of the topdress ECU on ISOBUS.
The console says the TC's address, the implement's DDOP active, what the implement reports, and
at the end what it applied against what the terminal set; the ISOBUS traffic is logged
(candump)."""

from __future__ import annotations

import io
import re
from pathlib import Path

import pytest

from topdress.cli.isobus_demo import isobus_config_toml, run_isobus_demo
from topdress.config import default_config, loads_config
from topdress.isobus.node import split_id

pytestmark = pytest.mark.wallclock  # paced to the wall clock: 9 s
# The demo's 40 s in virtual time, within 3 %: tests/test_terminal_isobus.py.


def test_demo_isobus_terminal_sets_the_rate_and_the_implement_applies_it(tmp_path: Path) -> None:
    out = io.StringIO()
    assert run_isobus_demo(default_config(), 9.0, tmp_path, 1, out) == 0
    text = out.getvalue()
    assert "ISOBUS: Task Controller at address 0xF7" in text
    assert "ISOBUS: implement topdress at 0x84: DDOP active, 2 products in kg/ha" in text
    # what the implement reports, as the terminal received it
    reports = re.findall(r"implement topdress 0x84: ([\d.]+) set / ([\d.]+) reported kg/ha", text)
    assert reports
    assert all(float(s) > 50.0 for s, _ in reports)  # the crop-sensor rate, not a fixed one
    # at the end: applied, at the terminal's rate, from the session log
    m = re.search(r"ISOBUS implement applied ([\d.]+) kg (at|OFF) the terminal's rate", text)
    assert m is not None, text
    assert float(m.group(1)) > 0.05  # 9 s from rest; 40 s within 3 %: test_terminal_isobus
    assert "nothing was metered" not in text
    (log,) = tmp_path.glob("isobus-*.log")
    ids = [int(line.split()[2].split("#")[0], 16) for line in log.read_text().splitlines()]
    pgns = {split_id(i)[1] for i in ids}
    assert {0xEE00, 0xCB00, 0xEC00, 0xEB00, 0xFE0D} <= pgns  # claim, PD, TP, working set


def test_demo_configuration_puts_the_terminal_on_isobus() -> None:
    text = isobus_config_toml('[can]\ninterface = "virtual"\nchannel = "x"\n')
    assert loads_config(text).can.implement == "isobus"
