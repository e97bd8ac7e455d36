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
    assert (name >> 40) & 0xFF == 130  # function: rate control
    assert (name >> 49) & 0x7F == 5  # device class: fertilizers
    assert (name >> 60) & 0x7 == 2  # industry group: agriculture
    assert name & 0x1FFFFF != 0  # identity number from the unique ID


@pytest.mark.qemu
@pytest.mark.skipif(qemu_missing() is not None, reason=str(qemu_missing()))
def test_emulated_isobus_ecu_activates_its_pool_with_a_tc() -> None:
    """A whole TC session with the firmware on its own tick: claim, pool by TP, activated."""
    from topdress.isobus.node import Frame
    from topdress.isobus.tcserver import TcServer, tc_name

    out = REPO / "build" / "fw-qemu-isobus"
    done = _make(out, "FW_ISOBUS=1", "VARIANT=qemu")
    assert done.returncode == 0, done.stderr
    tc = TcServer(tc_name(7))
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
            if tc.client is not None and tc.client.active:
                break
    assert tc.client is not None, tc.errors
    assert tc.client.address == 0x84
    assert tc.client.active, tc.errors
