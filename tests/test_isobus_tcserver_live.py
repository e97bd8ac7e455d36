"""The topdress ECU's ISOBUS node (the C TC client) on the simulated machine, served by the
terminal's Task Controller in virtual time, one process: the pool taken and activated, 150 kg/ha
and the sections set by the server, the actual rate read back by time-interval measurement."""

from __future__ import annotations

from topdress.isobus.node import Frame, IsobusNode, topdress_name
from topdress.isobus.tcserver import TcServer, tc_name
from topdress.sim.isobus import IsobusMachine, tc_timeout_ms
from topdress.sim.tractor import Drive
from topdress.sim.world import World

ALL_ON = -4096 + 0x555  # sections 1-6 on (01), 7-16 not installed (11)


def _run(m: IsobusMachine, tc: TcServer, seconds: float, pending: list[Frame]) -> list[Frame]:
    for _ in range(round(seconds / m.world.dt)):
        out = m.step(pending)
        pending = tc.step(m.world.now_us, out)
    return pending


def test_ecu_node_served_by_the_terminal_tc() -> None:
    world = World(seed=3, drive=Drive.paper_run(7.0, hold_m=400.0, wait_s=4.0))
    node = IsobusNode(topdress_name(1407, bytes(range(12))), tc_timeout_ms=tc_timeout_ms(1500))
    m = IsobusMachine(world, node, 3.6, 6)
    tc = TcServer(tc_name(7))
    tc.start(0)
    pending = _run(m, tc, 4.0, [])
    c = tc.client
    assert c is not None and c.active and c.device is not None and tc.errors == []
    assert node.tc_state == "connected" and node.tc_address == tc.address
    assert sorted(c.device.bins) == [3, 4]
    tc.set_value(2, 160, 1)  # section control state: automatic
    tc.set_value(2, 289, 1)  # setpoint work state: on
    tc.set_value(3, 6, 15000)  # 150 kg/ha (mg/m^2)
    tc.set_value(4, 6, 10000)
    tc.set_value(2, 290, ALL_ON)
    tc.measure_every(3, 7, 1000)
    pending = _run(m, tc, 20.0, pending)
    acked = {(e, d) for e, d, err in c.pdacks if err == 0}
    assert acked >= {(2, 160), (2, 289), (3, 6), (4, 6), (2, 290)}
    assert node.rate_kg_ha(0) == 150.0 and node.rate_kg_ha(1) == 100.0
    assert m.running
    actual = c.values[(3, 7)] / 100  # kg/ha
    print(f"actual rate read back by the TC: {actual:.1f} kg/ha (set 150)")
    assert abs(actual - 150.0) <= 0.05 * 150.0
    print(f"measurements of the actual rate in 20 s: {c.heard[(3, 7)]}")
    assert 20 <= c.heard[(3, 7)] <= 22  # one at once, then every 1000 ms over 20 s
    tc.set_value(2, 290, -4096)  # all sections off
    _run(m, tc, 0.5, pending)
    assert not m.running
