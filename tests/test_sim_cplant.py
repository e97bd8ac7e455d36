"""The plant's C code (sim/csrc/plant.c) against plain Python: the normal draws of a random
stream, the field's NDVI formula, the air line's growing FIFO, the applied-fertilizer bins,
and fault knobs turned by replacing a device's parameters mid-run."""

from __future__ import annotations

import dataclasses
import math
import random
from collections import deque

import pytest

from topdress.sim.cplant import attach, ffi, lib, refill
from topdress.sim.field import Field, FieldParams
from topdress.sim.sil import Sil
from topdress.sim.tractor import Drive, Tractor, TractorParams
from topdress.sim.transport import AirLine, AirLineParams
from topdress.sim.wheel import GroundWheel, WheelParams
from topdress.sim.world import SimConfig, World

DT = 0.01


@pytest.mark.parametrize("before", [0, 1, 2, 7])
def test_gauss_stream_equals_random_gauss(before: int) -> None:
    """Draws made before the hand-over (an odd count leaves random.gauss a kept value) and
    refills at any fill level leave the stream exactly random.gauss's."""
    rng, twin = random.Random(before), random.Random(before)
    for _ in range(before):
        assert rng.gauss(0.0, 2.0) == twin.gauss(0.0, 2.0)
    block = ffi.new("tdsim_gauss_t *")
    attach(rng, block)
    pick = random.Random(99)
    for i in range(3000):
        if block.n - block.next < 2 or pick.random() < 0.02:
            refill(rng, block)
        assert lib.tdsim_gauss_draw(block) == twin.gauss(0.0, 1.0), i


def test_gauss_stream_run_dry_gives_nan() -> None:
    block = ffi.new("tdsim_gauss_t *")
    assert math.isnan(lib.tdsim_gauss_draw(block))


def plain_ndvi(f: Field, x: float, y: float) -> float:
    """The field's formula as Python wrote it (FieldParams)."""
    p = f.p
    k = 2 * math.pi / p.wavelength_m
    v = p.ndvi_mean + p.wave_amp * 0.5 * (
        math.sin(k * x + f._phase[0]) + math.sin(0.7 * k * y + f._phase[1])
    )
    two_r2 = 2 * (p.patch_radius_m * p.patch_radius_m)
    for px, py, amp in f._patches:
        v += amp * math.exp(-((x - px) ** 2 + (y - py) ** 2) / two_r2)
    return min(0.92, max(0.15, v))


@pytest.mark.parametrize("seed", range(3))
def test_field_ndvi_equals_the_plain_formula(seed: int) -> None:
    f = Field(FieldParams(patches=3 + 4 * seed, patch_amp=0.3, wave_amp=0.5), seed)
    rng = random.Random(seed)
    values = set()
    for _ in range(5000):
        x, y = rng.uniform(-20, 220), rng.uniform(-20, 220)
        got = f.ndvi(x, y)
        assert got == plain_ndvi(f, x, y), (x, y)
        values.add(got)
    assert {0.15, 0.92} <= values  # both clips reached
    f.p = dataclasses.replace(f.p, wavelength_m=20.0, ndvi_mean=0.5)
    assert f.ndvi(3.0, 4.0) == plain_ndvi(f, 3.0, 4.0)


def test_blocked_air_line_keeps_every_parcel_and_lets_them_land_when_cleared() -> None:
    """The FIFO grows past its first block and wraps; the result equals a deque's."""
    rng = random.Random(4)
    p = AirLineParams(blocked=True)
    line = AirLine(p)
    q: deque[tuple[float, float]] = deque()
    landed_total = in_flight = rev_in = 0.0
    most = 0
    for i in range(3000):
        t = (i + 1) * DT
        if i in (300, 2600):  # the line is cleared
            line.p = p = dataclasses.replace(p, blocked=False)
        if i == 400:  # and clogs again: the FIFO grows from the middle of its ring
            line.p = p = dataclasses.replace(p, blocked=True)
        d_rev = rng.uniform(0.0, 0.01)
        m = (rev_in + d_rev - max(rev_in, p.release_rev)) * 0.3
        rev_in += d_rev
        if m > 0.0:
            in_flight += m
            q.append((t + line.delay_s(3000.0), m))
        want = 0.0
        if q and q[0][0] <= t and not p.blocked:
            while q and q[0][0] <= t:
                want += q.popleft()[1]
        in_flight -= want
        got = line.step(t, d_rev, 0.3, 3000.0)
        assert got == want, i
        assert line.parcels == len(q) and line.in_flight_kg == in_flight
        landed_total += got
        most = max(most, line.parcels)
    assert most > 2000 and line.parcels < 30
    assert landed_total == line.landed_kg > 0.0


def test_applied_bins_do_not_depend_on_when_they_are_read() -> None:
    def run(read_every_step: bool) -> World:
        w = World(SimConfig(bin_m=0.05), seed=2, drive=Drive.paper_run(6.0, hold_m=10.0))
        with Sil(w) as sil:
            for _ in range(2500):
                sil.step()
                if read_every_step:
                    w.applied_by_bin  # noqa: B018 - reading brings the current bin up to date
        return w

    every, once = run(True), run(False)
    assert every.applied_by_bin == once.applied_by_bin
    bins = once.applied_by_bin[1]
    assert len(bins) > 100 and list(bins) == sorted(bins)
    assert sum(bins.values()) == pytest.approx(once.airlines[1].landed_kg, rel=1e-12)


def test_fault_knobs_act_when_the_parameters_are_replaced_mid_run() -> None:
    wheel = GroundWheel(WheelParams(), seed=1)
    for i in range(100):
        wheel.step(i * DT, DT, 2.0)
    wheel.p = dataclasses.replace(wheel.p, lifted_at_s=1.0)
    count, rev = wheel.count, wheel.revolutions
    for i in range(100, 200):
        assert wheel.step(i * DT, DT, 2.0) == count
    assert wheel.revolutions == rev

    tr = Tractor(TractorParams(), seed=1)
    for _ in range(1000):
        tr.step(DT, 2.0, 0.0)
    assert tr.v > 1.9
    tr.p = dataclasses.replace(tr.p, stall_at_s=tr.t)
    for _ in range(1000):
        tr.step(DT, 2.0, 0.0)
    assert tr.v == 0.0 and tr.a == 0.0
