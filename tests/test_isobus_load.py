"""A bus at 100 % load (virtual time): a babbling node fills every slot of a 250 kbit/s bus
with high-priority frames (among them proprietary frames to the ECU from its address), so
neither the Task Controller's frames nor the ECU's get through. The ECU's node takes every
frame without error or restart; the TC is lost, the meters stop (the fail-safe), and the log
says so (isobus.bus_load, isobus.tc_lost); when the flood ends the TC connects again and the
meters run at its rate."""

from __future__ import annotations

from topdress.isobus.node import Frame, IsobusNode, split_id, topdress_name
from topdress.log.isobus import BUS_FRAMES_PER_S, IsobusWatch
from topdress.log.model import LogEvent
from topdress.sim.isobus import IsobusMachine, tc_timeout_ms
from topdress.sim.tc import MiniTc
from topdress.sim.tractor import Drive
from topdress.sim.world import World

ALL_ON = -4096 + 0x555
BABBLER = 0x20
PER_STEP = 19  # 1852 frames/s at 250 kbit/s: 18.5 each 10 ms, every slot taken


def _flood(step: int) -> list[Frame]:
    """A step's frames of the babbling node: priority-0 broadcasts and, every third, a
    Proprietary A frame to the ECU (ours only from the TC: counted, never acted on)."""
    out = []
    for i in range(PER_STEP):
        pgn_ps = 0xEF84 if i % 3 == 0 else 0xFF10  # Proprietary A to 0x84, or a broadcast
        can_id = (pgn_ps << 8) | BABBLER  # priority 0
        out.append(Frame(can_id, bytes([step & 0xFF, i, 0, 0, 0, 0, 0, 0])))
    return out


def test_full_bus_load_is_safe_reported_and_recovered() -> None:
    world = World(seed=3, drive=Drive.paper_run(7.0, hold_m=600.0, wait_s=2.0))
    node = IsobusNode(topdress_name(1407, bytes(range(12))), tc_timeout_ms=tc_timeout_ms(1500))
    m, tc, watch = IsobusMachine(world, node, 3.6, 6), MiniTc(), IsobusWatch(node)
    events: list[LogEvent] = []
    pending: list[Frame] = []
    flooding = False
    running: list[tuple[float, bool]] = []

    def run(seconds: float) -> None:
        nonlocal pending
        for n in range(round(seconds / world.dt)):
            into_ecu = _flood(n) if flooding else pending
            out = m.step(into_ecu)
            events.extend(watch.events(world.t_s))
            # at 100 % load nothing of the ECU's reaches the TC, nothing of the TC's the ECU
            pending = tc.step(world.now_us, _flood(n) if flooding else out)
            running.append((world.t_s, m.running))

    run(3.0)
    for element, ddi, value in ((2, 160, 1), (2, 289, 1), (3, 6, 15000), (2, 290, ALL_ON)):
        tc.command(element, ddi, value)
    run(5.0)
    assert m.running and node.rate_kg_ha(0) == 150.0
    before = node.counters
    flooding = True
    t_flood = world.t_s
    run(5.0)
    flooding = False
    during = node.counters
    heard = during["rx_frames"] - before["rx_frames"]
    assert heard == 500 * PER_STEP  # every frame taken, none refused as malformed
    assert during["rx_errors"] == before["rx_errors"]
    assert during["prop_wrong_source"] - before["prop_wrong_source"] == 500 * 7  # 7 in 19
    assert during["prop_rx"] == before["prop_rx"]
    # the fail-safe: TC lost within its status period plus the timeout, the meters stopped
    lost = [e for e in events if e.kind == "isobus.tc_lost"]
    assert len(lost) == 1 and t_flood < lost[0].t <= t_flood + 3.5 + 0.01
    stopped = [t for t, r in running if t > t_flood and not r]
    # the command to the core stops at the next control period
    assert stopped and 0.0 < stopped[0] - lost[0].t < 0.0101
    assert not any(r for t, r in running if stopped[0] <= t <= t_flood + 5.0)
    load = [e for e in events if e.kind == "isobus.bus_load"]
    assert load[0].detail["overloaded"] is True
    assert load[0].detail["load_pct"] >= 100.0
    assert t_flood < load[0].t <= t_flood + 2.0
    # the flood over: the same node (no restart) connects again and meters the TC's rate
    run(8.0)
    assert [e.detail["overloaded"] for e in events if e.kind == "isobus.bus_load"] == [True, False]
    assert node.tc_state == "connected" and node.counters["connects"] == 2
    assert m.running and node.rate_kg_ha(0) == 150.0
    assert node.claim_state == "claimed" and node.address == 0x84
    assert split_id(_flood(0)[0].can_id)[1:3] == (0xEF00, BABBLER)
    print(f"bus load reported {load[0].detail['load_pct']} % ({BUS_FRAMES_PER_S:.0f} frames/s)")
