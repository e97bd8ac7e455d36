"""The ISOBUS node's events in the session log (topdress.log.isobus), in virtual time: a TC
that connects, sets rates and falls silent; a TC that refuses the DDOP. Written to a session
file and read back by the log's export, with the meters' state at each."""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import pytest

from topdress.isobus import tcserver
from topdress.isobus.node import Frame, IsobusNode, topdress_name
from topdress.log.export import write_log_events
from topdress.log.isobus import IsobusWatch
from topdress.log.session import SessionLog, SessionReader
from topdress.sim.isobus import IsobusMachine, tc_timeout_ms
from topdress.sim.tc import MiniTc
from topdress.sim.tractor import Drive
from topdress.sim.world import World

ALL_ON = -4096 + 0x555


def _run(m: IsobusMachine, tc: MiniTc, watch: IsobusWatch, log: SessionLog, seconds: float) -> None:
    pending: list[Frame] = []
    for _ in range(round(seconds / m.world.dt)):
        out = m.step(pending)
        for ev in watch.events(m.world.t_s):
            log.event(ev)
        pending = tc.step(m.world.now_us, out)


def _rig() -> tuple[IsobusMachine, MiniTc, IsobusWatch]:
    world = World(seed=3, drive=Drive.paper_run(7.0, hold_m=400.0, wait_s=2.0))
    node = IsobusNode(topdress_name(1407, bytes(range(12))), tc_timeout_ms=tc_timeout_ms(1500))
    return IsobusMachine(world, node, 3.6, 6), MiniTc(), IsobusWatch(node)


def _logged(path: Path) -> list[dict[str, Any]]:
    text = io.StringIO()
    with SessionReader(path) as reader:
        write_log_events(reader, text)
    return [json.loads(line) for line in text.getvalue().splitlines()]


def test_claim_ddop_set_and_lost_tc_are_logged(tmp_path: Path) -> None:
    m, tc, watch = _rig()
    with SessionLog.create(tmp_path, "", name="s") as log:
        _run(m, tc, watch, log, 3.0)
        for element, ddi, value in ((2, 160, 1), (2, 289, 1), (3, 6, 15000), (2, 290, ALL_ON)):
            tc.command(element, ddi, value)
        _run(m, tc, watch, log, 3.0)
        assert m.running
        tc.silent = True
        _run(m, tc, watch, log, 4.0)
        assert not m.running  # the meters' command stopped with the alarm
        path = log.path
    events = _logged(path)
    kinds = [e["kind"] for e in events]
    assert kinds[0] == "isobus.claimed" and "isobus.ddop" in kinds and "isobus.tc_lost" in kinds
    sets = [e for e in events if e["kind"] == "isobus.set"]
    last_on = [s for s in sets if s["detail"]["upper_kg_ha"] == 150.0]
    assert last_on and last_on[-1]["detail"]["sections"] == 0b111111
    lost = next(e for e in events if e["kind"] == "isobus.tc_lost")
    # the TC's last status at most 2 s before it fell silent at 6 s, then the 1.5 s timeout
    assert 6.0 < float(lost["t"]) <= 9.6
    # with the TC lost the rates read 0: the ECU logs that it applies nothing
    assert sets[-1]["detail"] == {"upper_kg_ha": 0.0, "lower_kg_ha": 0.0, "sections": 0}
    assert float(sets[-1]["t"]) == pytest.approx(float(lost["t"]))


def test_refused_ddop_is_logged_with_its_code(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(tcserver, "MAX_POOL_BYTES", 1000)  # a TC without room for our pool
    m, tc, watch = _rig()
    with SessionLog.create(tmp_path, "", name="s") as log:
        _run(m, tc, watch, log, 5.0)
        path = log.path
    assert m.node.tc_state == "refused" and m.node.alarm and not m.running
    events = _logged(path)
    (ddop,) = [e for e in events if e["kind"] == "isobus.ddop"]
    assert ddop["detail"]["accepted"] is False
    assert ddop["detail"]["code"] == m.node.refuse_code != 0
    assert "isobus.tc_lost" not in [e["kind"] for e in events]  # a refusal, not a loss
