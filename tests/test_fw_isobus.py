"""The ISOBUS firmware build (FW_ISOBUS=1): it builds with the strict flags within its budgets
(the worst-stack analysis passing), carries the node only when asked, and in the emulator claims
its address on the SLCAN link with a NAME from the chip's unique ID."""

from __future__ import annotations

import shutil
import subprocess
import time
from pathlib import Path

import can
import pytest

from topdress.sim.qemu_ecu import HilLink, QemuEcu, QemuOptions, qemu_missing

REPO = Path(__file__).resolve().parents[1]
ELF = "topdress-ecu-stm32f4.elf"
pytestmark = pytest.mark.skipif(
    shutil.which("arm-none-eabi-gcc") is None or shutil.which("arm-none-eabi-nm") is None,
    reason="no arm-none-eabi toolchain (scripts/sysdeps.sh firmware)",
)
FLASH_BUDGET, RAM_BUDGET = 128 * 1024, 32 * 1024
PGN_ADDRESS_CLAIMED = 0xEE00
MAKE = ("make", "--no-print-directory", "-s", "-j2", "-f", "ecu/ports/stm32f4/firmware.mk")


def _make(out: Path, *more: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*MAKE, f"OUT={out}", *more],
        cwd=REPO,
        capture_output=True,
        text=True,
    )


def _figures(stdout: str) -> dict[str, int]:
    pairs = (line.split(": ", 1) for line in stdout.splitlines() if "_bytes: " in line)
    return {key: int(value) for key, value in pairs}


def _symbols(elf: Path) -> set[str]:
    out = subprocess.run(["arm-none-eabi-nm", str(elf)], capture_output=True, text=True, check=True)
    return {ln.split()[-1] for ln in out.stdout.splitlines()}


@pytest.fixture(scope="module")
def isobus_build() -> tuple[Path, dict[str, int]]:
    out = REPO / "build" / "fw-isobus"
    done = _make(out, "FW_ISOBUS=1")
    assert done.returncode == 0, done.stderr
    return out / ELF, _figures(done.stdout)


def test_isobus_image_is_within_its_budgets(isobus_build: tuple[Path, dict[str, int]]) -> None:
    _, fig = isobus_build
    assert 0 < fig["flash_bytes"] <= FLASH_BUDGET
    assert 0 < fig["ram_bytes"] <= RAM_BUDGET  # static data and the stack reservation
    assert 0 < fig["stack_worst_bytes"] <= fig["stack_reserved_bytes"]


def test_the_node_is_linked_only_when_asked(isobus_build: tuple[Path, dict[str, int]]) -> None:
    elf, _ = isobus_build
    node = {"fw_isobus_init", "td_isob_rx", "td_isob_step", "td_tc_rate_mg_m2"}
    assert node <= _symbols(elf)
    done = _make(REPO / "build" / "fw")
    assert done.returncode == 0, done.stderr
    assert not node & _symbols(REPO / "build" / "fw" / ELF)


def test_a_bad_setting_is_a_clear_error(tmp_path: Path) -> None:
    done = _make(tmp_path / "fw", "FW_ISOBUS=yes")
    assert done.returncode != 0
    assert "FW_ISOBUS=yes: 0 or 1" in done.stderr


@pytest.mark.qemu
@pytest.mark.skipif(qemu_missing() is not None, reason=str(qemu_missing()))
def test_emulated_isobus_ecu_claims_its_address() -> None:
    out = REPO / "build" / "fw-qemu-isobus"
    done = _make(out, "FW_ISOBUS=1", "VARIANT=qemu")
    assert done.returncode == 0, done.stderr
    claims: list[tuple[int, bytes]] = []
    with QemuEcu(QemuOptions(image=out / ELF)) as ecu:
        HilLink(ecu.bus).send_clock(0, 0, free_run=True)  # its own tick: the node steps
        deadline = time.monotonic() + 20.0
        while not claims and time.monotonic() < deadline:
            msg = ecu.bus.recv(timeout=0.5)
            if msg is not None and (msg.arbitration_id >> 8) & 0x3FF00 == PGN_ADDRESS_CLAIMED:
                claims.append((msg.arbitration_id, bytes(msg.data)))
    assert claims, "no Address Claimed from the emulated ECU"
    can_id, data = claims[0]
    assert can_id & 0xFF == 0x84  # the preferred address, alone on the link
    assert (can_id >> 8) & 0xFF == 0xFF  # to all
    name = int.from_bytes(data, "little")  # ISO 11783-5 4.4.2: the NAME's fields
    assert (name >> 40) & 0xFF == 128  # function: Fertilize Rate Control (class 5)
    assert (name >> 49) & 0x7F == 5  # device class: fertilizers
    assert (name >> 60) & 0x7 == 2  # industry group: agriculture
    assert name & 0x1FFFFF != 0  # identity number from the unique ID


@pytest.mark.qemu
@pytest.mark.skipif(qemu_missing() is not None, reason=str(qemu_missing()))
def test_emulated_isobus_ecu_activates_its_pool_with_a_tc() -> None:
    """A whole TC session with the firmware on its own tick: claim, pool by TP, activated; then
    the ECU says who it is (EcuIdent on Proprietary B from its claimed address)."""
    from topdress.isobus.node import Frame, from_bus
    from topdress.isobus.tcserver import TcServer, tc_name
    from topdress.protocol import EcuIdent, decode

    out = REPO / "build" / "fw-qemu-isobus"
    done = _make(out, "FW_ISOBUS=1", "VARIANT=qemu")
    assert done.returncode == 0, done.stderr
    tc = TcServer(tc_name(7))
    idents: list[EcuIdent] = []
    with QemuEcu(QemuOptions(image=out / ELF)) as ecu:
        HilLink(ecu.bus).send_clock(0, 0, free_run=True)
        t0 = time.monotonic()
        tc.start(0)
        while time.monotonic() - t0 < 30.0:
            heard: list[Frame] = []
            msg = ecu.bus.recv(timeout=0.005)
            while msg is not None:
                heard.append(Frame(msg.arbitration_id, bytes(msg.data)))
                msg = ecu.bus.recv(timeout=0.0)
            now_us = int((time.monotonic() - t0) * 1e6)
            for f in tc.step(now_us, heard):
                ecu.bus.send(can.Message(arbitration_id=f.can_id, data=f.data, is_extended_id=True))
            for f in heard:
                core = from_bus(f, by_ecu=True, peer=0x84, my_address=0xF7)
                if core is not None and isinstance(d := decode((core.can_id, core.data)), EcuIdent):
                    idents.append(d)
            if tc.client is not None and tc.client.active and idents:
                break
    assert tc.client is not None, tc.errors
    assert tc.client.address == 0x84
    assert tc.client.active, tc.errors
    assert idents and idents[0].target == "stm32f4" and idents[0].on_defaults, idents


@pytest.mark.qemu
@pytest.mark.skipif(qemu_missing() is not None, reason=str(qemu_missing()))
def test_emulated_isobus_ecu_meters_the_tcs_rate() -> None:
    """The FW_ISOBUS image in lockstep with the simulated machine and the terminal's TC: the
    rate the TC sets reaches the meters (metered on the simulated ground), sections off stop
    them. The terminal's GNSS speed goes as PcGnssTime on Proprietary B from the TC's address
    (the firmware's core would otherwise run on its slipping wheel alone). Then 100 % bus load
    on the link for 6 s: no step late or missed (no reset), the rate held."""
    from topdress.isobus.node import Frame, to_bus
    from topdress.protocol.frames import encode_gnss_time
    from topdress.sim.qemu_ecu import QemuWorld
    from topdress.sim.tc import MiniTc
    from topdress.sim.tractor import Drive

    out = REPO / "build" / "fw-qemu-isobus"
    done = _make(out, "FW_ISOBUS=1", "VARIANT=qemu")
    assert done.returncode == 0, done.stderr
    tc = MiniTc()
    with QemuEcu(QemuOptions(image=out / ELF)) as ecu:
        world = QemuWorld(ecu, seed=3, drive=Drive.paper_run(7.0, hold_m=400.0, wait_s=3.0))
        pending: list[Frame] = []
        steps = 0

        def run(
            seconds: float, dist: list[float] | None = None, extra: tuple[Frame, ...] = ()
        ) -> None:
            nonlocal pending, steps
            for _ in range(round(seconds / world.dt)):
                steps += 1
                if steps % 10 == 0 and tc.server.address is not None:  # a fix every 100 ms
                    g = encode_gnss_time(world.truth.v_kmh, 0, steps // 10)
                    bus = to_bus(Frame(g.arbitration_id, bytes(g.data)), False, tc.server.address)
                    assert bus is not None
                    pending.append(bus)
                for f in [*pending, *extra]:
                    world.link.send((f.can_id, f.data))
                frames = [Frame(i, d) for i, d in world.step().can]
                pending = tc.step(world.now_us, frames)
                if dist is not None:
                    dist[0] += world.truth.v_kmh / 3.6 * world.dt

        run(4.0)
        assert tc.activated, tc.server.errors
        for element, ddi, value in ((2, 160, 1), (2, 289, 1), (3, 6, 15000), (4, 6, 10000),
                                    (2, 290, -4096 + 0x555)):  # fmt: skip
            tc.command(element, ddi, value)
        run(10.0)
        kg0, dist = (world.metered_kg(0), world.metered_kg(1)), [0.0]
        run(6.0, dist)
        area_ha = dist[0] * 3.6 / 10_000
        rates = [(world.metered_kg(i) - kg0[i]) / area_ha for i in (0, 1)]
        print(f"emulated ISOBUS ECU metered {rates[0]:.1f} / {rates[1]:.1f} kg/ha (TC 150 / 100)")
        assert rates[0] == pytest.approx(150.0, rel=0.03)
        assert rates[1] == pytest.approx(100.0, rel=0.03)
        # 100 % bus load on the link: a babbling node's 19 frames a step (priority 0, a third of
        # them Proprietary A to the ECU from the wrong address) beside the TC's; every step
        # still comes at its time (no reset: lockstep would stall) and the rate holds
        flood = [Frame((0xEF84 if i % 3 == 0 else 0xFF10) << 8 | 0x20, bytes([i] * 8))
                 for i in range(19)]  # fmt: skip
        late = world.timing.late_inputs
        kg0, dist = (world.metered_kg(0), world.metered_kg(1)), [0.0]
        run(2.0, dist, tuple(flood))
        area_ha = dist[0] * 3.6 / 10_000
        loaded = [(world.metered_kg(i) - kg0[i]) / area_ha for i in (0, 1)]
        print(f"at 100 % load: {loaded[0]:.1f} / {loaded[1]:.1f} kg/ha")
        assert loaded[0] == pytest.approx(150.0, rel=0.03)
        assert world.timing.late_inputs == late
        assert set(world.timing.intervals_us) == {10_000}
        rpm_on = world.truth.meter_rpm[0]
        tc.command(2, 290, -4096)  # every section off
        run(0.5)
        assert world.truth.meter_rpm[0] < 0.3 * rpm_on
