"""The simulator's fast paths give bit for bit what the plain formulations give: the plant's
steps without min/max calls, the air line, the wheel's edge time, the loose-patch lookup,
the skipped GNSS calls, and the in-process CAN segment."""

from __future__ import annotations

import math
import random
from collections import deque

import can
import pytest

from topdress.sim.actuators import Fan, FanParams, MeterMotor, MeterParams
from topdress.sim.gnss import GnssParams, GnssReceiver
from topdress.sim.inproc import segment
from topdress.sim.tractor import Tractor, TractorParams
from topdress.sim.transport import AirLine, AirLineParams
from topdress.sim.wheel import GroundWheel, WheelParams
from topdress.sim.world import SimConfig, World

DT = 0.01


# -- the plain formulations (as the simulator wrote them before the fast paths) ----------


def ref_tractor_step(tr: Tractor, st: dict[str, float], rng: random.Random, v_t: float) -> None:
    """Tractor.step's speed, position and ripple update for a tractor already at v_t's gear."""
    p = tr.p
    st["t"] += DT
    if 0.0 <= p.stall_at_s <= st["t"]:
        v_t = 0.0
    a_des = (v_t - st["vb"]) / p.speed_tau_s
    a_des = min(st["limit"], max(-p.decel_ms2, a_des))
    if st["a"] >= st["limit"] - 1e-9 or a_des < st["a"]:
        st["jerk"] = p.jerk_ms3
    da = st["jerk"] * DT
    st["a"] += min(da, max(-da, a_des - st["a"]))
    st["vb"] += st["a"] * DT
    if v_t <= 0.0 and st["vb"] < 0.02:
        st["vb"], st["a"] = 0.0, 0.0
    if st["vb"] > 0.0 and p.ripple_sd > 0.0:
        k = DT / p.ripple_tau_s
        st["ripple"] += -k * st["ripple"] + p.ripple_sd * math.sqrt(2 * k) * rng.gauss(0.0, 1.0)
    st["v"] = max(0.0, st["vb"] * (1.0 + st["ripple"]))


def ref_wheel_step(
    p: WheelParams, st: dict[str, float], rng: random.Random, t: float, v: float, floor: float
) -> None:
    if v <= 0.0 or (0.0 <= p.lifted_at_s <= t):
        return
    k = DT / p.bounce_tau_s
    if p.bounce_sd > 0.0:
        st["bounce"] += -k * st["bounce"] + p.bounce_sd * math.sqrt(2 * k) * rng.gauss(0.0, 1.0)
    v_kmh = v * 3.6
    mean = max(0.0, p.slip_a * v_kmh * v_kmh + p.slip_b * v_kmh + p.slip_c + st["offset"])
    slip = max(mean, floor) * 0.01
    st["rev"] += v * DT * (1.0 - slip) * (1.0 + st["bounce"]) / (2.0 * math.pi * p.radius_m)


def ref_meter_step(p: MeterParams, st: dict[str, float], t: float, duty: float) -> None:
    duty = min(1.0, max(0.0, duty))
    if 0.0 <= p.jammed_at_s <= t:
        st["rpm"] = 0.0
        return
    if st["rpm"] <= 0.0 and duty <= p.breakaway_duty + p.load_duty:
        return
    load = p.load_duty
    if p.load_ripple:
        load *= 1.0 + p.load_ripple * math.sin(2.0 * math.pi * p.flutes * st["rev"])
    w_ss = p.max_rpm * (duty - p.friction_duty - load)
    w = max(0.0, w_ss + (st["rpm"] - w_ss) * math.exp(-DT / p.tau_s))
    st["rev"] += 0.5 * (st["rpm"] + w) * DT / 60.0
    st["rpm"] = w


def ref_airline_step(
    p: AirLineParams, st: dict[str, object], t: float, d_rev: float, fan_rpm: float
) -> float:
    q: deque[tuple[float, float]] = st["q"]  # type: ignore[assignment]
    if d_rev > 0.0:
        before = float(st["rev_in"])  # type: ignore[arg-type]
        st["rev_in"] = before + d_rev
        released = before + d_rev - max(before, p.release_rev)
        if released > 0.0:
            m = released * 0.3
            st["in_flight"] = float(st["in_flight"]) + m  # type: ignore[arg-type]
            if fan_rpm < p.min_fan_rpm:
                delay = float("inf")
            else:
                delay = p.drop_s + p.line_length_m / (p.air_speed_ms * fan_rpm / p.nominal_fan_rpm)
            q.append((t + delay, m))
    if not q or q[0][0] > t or p.blocked:
        return 0.0
    landed = 0.0
    while q and q[0][0] <= t:
        landed += q.popleft()[1]
    st["in_flight"] = float(st["in_flight"]) - landed  # type: ignore[arg-type]
    return landed


def ref_edge(pos: float, prev: float, count: int, now_us: int, last: int) -> int:
    """The capture timer pulse by pulse: the time of every encoder edge crossed in the step,
    by linear interpolation; the last one is captured if it made the count what it is."""
    edge = last
    for k in range(math.floor(prev) + 1, math.floor(pos) + 1):
        if pos > prev and count == int(pos):
            edge = (now_us - int((pos - k) / (pos - prev) * DT * 1e6)) & 0xFFFFFFFF
    return edge


# -- the tests --------------------------------------------------------------------------


def skip_draw(tr: Tractor, ref_rng: random.Random) -> None:
    """Keep the reference's stream with the tractor's over a step it did not model: the
    ripple draws once in a step that ends with speed."""
    if tr._vb > 0.0 and tr.p.ripple_sd > 0.0:
        ref_rng.gauss(0.0, 1.0)


@pytest.mark.parametrize("seed", range(4))
def test_tractor_speed_equals_the_plain_formulation(seed: int) -> None:
    rng = random.Random(seed)
    p = TractorParams(ripple_sd=0.004 * (1 + seed), stall_at_s=30.0 if seed == 3 else -1.0)
    tr = Tractor(p, seed=seed)
    ref_rng = random.Random(seed)
    tr.step(DT, 2.0, 0.0)  # the first step picks the gear: the reference starts after it
    st = {"t": tr.t, "vb": tr._vb, "a": tr.a, "limit": tr._accel_limit, "jerk": tr._jerk}
    st |= {"ripple": tr._ripple, "v": tr.v}
    skip_draw(tr, ref_rng)
    v_t = 2.0
    for i in range(4000):
        if i % 500 == 499:  # the driver changes speed: the gear is picked again in both
            v_t = rng.choice([0.0, 1.0, 2.5, 0.3])
            tr.step(DT, v_t, rng.uniform(-0.3, 0.3))
            st = {"t": tr.t, "vb": tr._vb, "a": tr.a, "limit": tr._accel_limit}
            st |= {"jerk": tr._jerk, "ripple": tr._ripple, "v": tr.v}
            skip_draw(tr, ref_rng)
            continue
        h, x, y, odo = tr.heading, tr.x, tr.y, tr.odometer
        k = rng.uniform(-0.3, 0.3) if i % 7 == 0 else 0.0
        tr.step(DT, v_t, k)
        ref_tractor_step(tr, st, ref_rng, v_t)
        assert (tr.v, tr.a, tr._vb, tr._ripple) == (st["v"], st["a"], st["vb"], st["ripple"])
        ds = st["v"] * DT
        assert tr.odometer == odo + ds
        assert tr.heading == h + ds * k
        assert (tr.x, tr.y) == (x + ds * math.sin(tr.heading), y + ds * math.cos(tr.heading))


@pytest.mark.parametrize("seed", range(4))
def test_wheel_equals_the_plain_formulation(seed: int) -> None:
    rng = random.Random(seed)
    p = WheelParams(
        bounce_sd=(0.036, 0.1, 0.0, 0.036)[seed], lifted_at_s=20.0 if seed == 3 else -1.0
    )
    wheel = GroundWheel(p, seed)
    ref_rng = random.Random(seed)
    st = {"offset": ref_rng.gauss(0.0, p.slip_sd_pct), "bounce": 0.0, "rev": 0.0}
    for i in range(3000):
        t = (i + 1) * DT
        v = max(0.0, rng.uniform(-0.5, 7.5))
        floor = rng.choice([0.0, 0.0, 15.0, 0.5])
        count = wheel.step(t, DT, v, floor)
        ref_wheel_step(p, st, ref_rng, t, v, floor)
        assert wheel.revolutions == st["rev"]
        if not 0.0 <= p.lifted_at_s <= t:
            assert count == int(st["rev"] * p.ppr)


def test_meter_and_fan_equal_the_plain_formulation() -> None:
    rng = random.Random(5)
    for mp in (MeterParams(), MeterParams(load_ripple=0.0), MeterParams(jammed_at_s=12.0)):
        motor = MeterMotor(mp, DT)
        st = {"rpm": 0.0, "rev": 0.0}
        for i in range(2500):
            t = (i + 1) * DT
            duty = rng.uniform(-0.2, 1.2) if i % 50 == 0 else rng.uniform(0.0, 0.6)
            count = motor.step(t, DT, duty)
            ref_meter_step(mp, st, t, duty)
            assert (motor.rpm, motor.revolutions) == (st["rpm"], st["rev"])
            assert count == int(st["rev"] * mp.counts_per_rev)
    fp = FanParams(belt_slip=0.1, failed_at_s=15.0)
    fan = Fan(fp, DT)
    rpm = rev = 0.0
    for i in range(2500):
        t = (i + 1) * DT
        duty = rng.uniform(-0.2, 1.2)
        count = fan.step(t, DT, duty)
        d = 0.0 if 0.0 <= fp.failed_at_s <= t else min(1.0, max(0.0, duty))
        w_ss = fp.max_rpm * d * (1.0 - fp.belt_slip)
        rpm = w_ss + (rpm - w_ss) * math.exp(-DT / fp.tau_s)
        rev += rpm * DT / 60.0
        assert (fan.rpm, fan.revolutions, count) == (rpm, rev, int(rev * fp.ppr))


def test_air_line_equals_the_plain_formulation() -> None:
    rng = random.Random(7)
    p = AirLineParams()
    line = AirLine(p)
    st: dict[str, object] = {"q": deque(), "rev_in": 0.0, "in_flight": 0.0}
    landed_total = 0.0
    for i in range(5000):
        t = (i + 1) * DT
        d_rev = rng.choice([0.0, rng.uniform(0.0, 0.01), rng.uniform(0.0, 0.002)])
        fan = rng.choice([3000.0, 2900.0, 1000.0, rng.uniform(1100.0, 4000.0)])
        got = line.step(t, d_rev, 0.3, fan)
        assert got == ref_airline_step(p, st, t, d_rev, fan)
        assert line.in_flight_kg == st["in_flight"]
        landed_total += got
    assert landed_total > 0.0 and line.landed_kg == landed_total


@pytest.mark.parametrize("seed", range(6))
def test_wheel_edge_time_equals_the_pulse_by_pulse_capture(seed: int) -> None:
    rng = random.Random(seed)
    world = World(seed=seed)
    ppr = world.wheel.p.ppr
    last = world._edge_us
    prev = world._wheel_pos
    pos = prev
    captured = 0
    for n in range(1, 4000):
        # standing, creeping (no whole pulse), one pulse, several pulses per step
        pos += rng.choice(
            [0.0, rng.uniform(0.0, 0.3), rng.uniform(0.5, 1.5), rng.uniform(1.0, 9.0)]
        )
        world.wheel.revolutions = pos / ppr
        pos_seen = world.wheel.revolutions * ppr
        # an encoder that has stopped counting: the count lags the wheel
        count = int(pos_seen) if rng.random() > 0.05 else int(pos_seen) - 1
        now = (n * 10_000 + 2**32 - 50_000) & 0xFFFFFFFF  # wraps
        got = world._wheel_edge(now, count)
        want = ref_edge(pos_seen, prev, count, now, last)
        assert got == want, (n, pos_seen, prev)
        captured += got != last
        last, prev = got, pos_seen
    assert captured > 1000


def test_loose_patch_lookup_equals_the_plain_membership() -> None:
    rng = random.Random(11)
    patches = tuple(
        (rng.uniform(0, 60), rng.uniform(0, 60), rng.uniform(0.5, 8.0)) for _ in range(12)
    )
    world = World(SimConfig(loose_patches=patches, loose_slip_pct=15.0))
    x, y = 30.0, 30.0
    h = 0.3
    inside = 0
    for i in range(20000):
        if i % 3000 == 0:
            x, y = rng.uniform(-5, 65), rng.uniform(-5, 65)  # jumps: the answer must not stick
        elif i % 1000 == 500:
            px, py, r = rng.choice(patches)
            x, y = px + r, py  # on a patch edge (inside: d2 <= r * r)
        else:
            h = rng.uniform(0, 2 * math.pi) if i % 200 == 0 else h
            step = rng.choice([0.0, 0.02, 0.05, 0.3])
            # drive about the patches, turning back at the border of the 70 m square
            x, y = x + step * math.sin(h), y + step * math.cos(h)
            if not (-5 < x < 65 and -5 < y < 65):
                h += math.pi
        want = 15.0 if any((x - px) ** 2 + (y - py) ** 2 <= r * r for px, py, r in patches) else 0.0
        assert world._loose(x, y) == want, (i, x, y)
        inside += want > 0.0
    assert 1000 < inside < 19000, inside


def test_skipping_the_gnss_until_it_is_due_changes_nothing() -> None:
    p = GnssParams(outages=((3.0, 4.0),), latency_s=0.37, rate_hz=7.0)
    every, skipping = GnssReceiver(p, 3), GnssReceiver(p, 3)
    rng = random.Random(3)
    for n in range(1, 3000):
        t = n * DT
        state = (rng.uniform(0, 50), rng.uniform(0, 50), rng.uniform(0, 3), rng.uniform(0, 6.3))
        a = every.step(t, *state)
        b = skipping.step(t, *state) if t + 1e-9 >= skipping.next_due_s else []
        assert a == b, t


def test_in_process_segment_hands_frames_over_in_order_without_copies() -> None:
    a, b, c = segment("test-seg", 3)
    msgs = [
        can.Message(arbitration_id=0x18000000 + i, data=bytes([i]), is_extended_id=True)
        for i in range(5)
    ]
    for m in msgs:
        a.send(m)
    assert a.recv(0) is None  # not its own frames
    assert [b.recv(0) for _ in range(5)] == msgs
    assert all(x is y for x, y in zip([c.recv(0.01) for _ in range(5)], msgs, strict=True))
    assert b.recv(0) is None and c.recv(0.5) is None
    with pytest.raises(can.CanOperationError, match="nothing to receive"):
        b.recv()
    c.shutdown()
    a.send(msgs[0])
    assert b.recv(0) is msgs[0]
    a.shutdown()
    b.shutdown()
