"""The simulated machine with its ECU on ISOBUS, commanded by the terminal's Task Controller
(tcserver) in virtual time: the TC's kg/ha metered within 3 % in steady state, sections
switched within 0.2 s, a lost TC stops the meters."""

from __future__ import annotations

from topdress.isobus.node import Frame, IsobusNode, topdress_name
from topdress.sim.isobus import IsobusMachine, tc_timeout_ms
from topdress.sim.tc import MiniTc
from topdress.sim.tractor import Drive
from topdress.sim.world import World

WIDTH_M, SECTIONS = 3.6, 6
ALL_ON = -4096 + 0x555  # sections 1-6 on (01), 7-16 not installed (11)


def _rig() -> tuple[IsobusMachine, MiniTc]:
    world = World(seed=3, drive=Drive.paper_run(7.0, hold_m=400.0, wait_s=4.0))
    node = IsobusNode(topdress_name(1407, bytes(range(12))), tc_timeout_ms=tc_timeout_ms(1500))
    return IsobusMachine(world, node, WIDTH_M, SECTIONS), MiniTc()


def _run(
    m: IsobusMachine,
    tc: MiniTc,
    seconds: float,
    pending: list[Frame],
    dist: list[float] | None = None,
) -> list[Frame]:
    for _ in range(round(seconds / m.world.dt)):
        out = m.step(pending)
        pending = tc.step(m.world.now_us, out)
        if dist is not None:
            dist[0] += m.world.truth.v_kmh / 3.6 * m.world.dt  # over the ground, not the wheel's
    return pending


def test_tc_rate_metered_sections_and_lost_tc() -> None:
    m, tc = _rig()
    pending = _run(m, tc, 4.0, [])
    assert tc.activated and m.node.tc_state == "connected"
    assert tc.pool is not None and tc.pool[:3] == b"DVC"
    for element, ddi, value in (
        (2, 160, 1),
        (2, 289, 1),
        (3, 6, 15000),
        (4, 6, 10000),
        (2, 290, ALL_ON),
    ):
        tc.command(element, ddi, value)
    pending = _run(m, tc, 20.0, pending)  # reach steady state
    assert sorted((e, d) for e, d, err in tc.pdacks if err == 0) == [
        (2, 160),
        (2, 289),
        (2, 290),
        (3, 6),
        (4, 6),
    ]
    w = m.world
    kg0, dist = (w.metered_kg(0), w.metered_kg(1)), [0.0]
    pending = _run(m, tc, 10.0, pending, dist)
    area_ha = dist[0] * WIDTH_M / 10_000
    rates = [(w.metered_kg(i) - kg0[i]) / area_ha for i in (0, 1)]
    print(f"metered over 10 s at 7 km/h: {rates[0]:.1f} / {rates[1]:.1f} kg/ha (TC: 150 / 100)")
    assert abs(rates[0] - 150.0) <= 0.03 * 150.0, rates
    assert abs(rates[1] - 100.0) <= 0.03 * 100.0, rates
    # all sections off: the meters stop within 0.2 s
    rpm_on = w.truth.meter_rpm[0]
    tc.command(2, 290, -4096)
    pending = _run(m, tc, 0.2, pending)
    assert not m.running and w.truth.meter_rpm[0] < 0.3 * rpm_on
    tc.command(2, 290, ALL_ON)
    pending = _run(m, tc, 3.0, pending)
    assert m.running and w.truth.meter_rpm[0] > 0.9 * rpm_on
    # the TC falls silent: its last status was at most 2 s ago, so 1.4 s on the meters still
    # run; 3.6 s on the 1.5 s command timeout after the first missed status is over
    tc.silent = True
    pending = _run(m, tc, 1.4, pending)
    assert m.running
    pending = _run(m, tc, 2.2, pending)
    assert not m.running and m.node.alarm and m.node.rate_kg_ha(0) == 0.0
    _run(m, tc, 0.5, pending)
    assert w.truth.meter_rpm[0] < 0.1 * rpm_on
