"""`topdress demo --isobus`: the console says the address claimed, the DDOP accepted and the
rate the TC set, and the ISOBUS traffic is logged (candump)."""

from __future__ import annotations

import io
from pathlib import Path

import pytest

from topdress.cli.isobus_demo import run_isobus_demo
from topdress.config import default_config
from topdress.isobus.node import split_id

pytestmark = pytest.mark.wallclock  # paced to the wall clock: 3 s


def test_demo_isobus_claims_connects_and_applies(tmp_path: Path) -> None:
    out = io.StringIO()
    assert run_isobus_demo(default_config(), 3.0, tmp_path, 1, out) == 0
    text = out.getvalue()
    assert "address 0x84 claimed" in text
    assert "TC 0xF7: DDOP accepted and activated" in text
    assert "TC set upper 150 kg/ha, lower 100 kg/ha, sections 111111" in text
    (log,) = tmp_path.glob("isobus-*.log")
    ids = [int(line.split()[2].split("#")[0], 16) for line in log.read_text().splitlines()]
    pgns = {split_id(i)[1] for i in ids}
    assert {0xEE00, 0xCB00, 0xEC00, 0xEB00, 0xFE0D} <= pgns  # claim, PD, TP, working set
