"""The STM32F4 images as built (arm-none-eabi-objdump / nm on the ELF): what only the shipped
code can show. The outputs are made safe before anything else runs, the step's wait cannot
sleep through its tick, the board image carries no emulator path, the clock security system and
the CAN error interrupt have their handlers in the vector table."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
OBJDUMP = shutil.which("arm-none-eabi-objdump")
pytestmark = pytest.mark.skipif(
    OBJDUMP is None or shutil.which("arm-none-eabi-gcc") is None,
    reason="no arm-none-eabi toolchain (scripts/sysdeps.sh firmware)",
)
ELF = "topdress-ecu-stm32f4.elf"


def _build(out: Path, *more: str) -> Path:
    args = (f"OUT={out}", *more)
    done = subprocess.run(
        ["make", "--no-print-directory", "-s", "-j2", "-f", "ecu/ports/stm32f4/firmware.mk", *args],
        cwd=REPO,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    return out / ELF


# the repository's own outputs (make rebuilds what changed, usually nothing: `make firmware` and
# the QEMU tests build the same)
@pytest.fixture(scope="module")
def board() -> Path:
    return _build(REPO / "build" / "fw")


@pytest.fixture(scope="module")
def emulator() -> Path:
    return _build(REPO / "build" / "fw-qemu", "VARIANT=qemu")


def _function(elf: Path, name: str) -> list[str]:
    assert OBJDUMP is not None
    out = subprocess.run(
        [OBJDUMP, "-d", "--no-show-raw-insn", str(elf)], capture_output=True, text=True, check=True
    ).stdout
    body = out.split(f"<{name}>:\n", 1)[1].split("\n\n", 1)[0]
    return [line.split("\t", 1)[1].strip() for line in body.splitlines() if "\t" in line]


def _symbols(elf: Path) -> dict[str, int]:
    nm = shutil.which("arm-none-eabi-nm")
    assert nm is not None
    out = subprocess.run([nm, str(elf)], capture_output=True, text=True, check=True).stdout
    return {p[2]: int(p[0], 16) for p in (ln.split() for ln in out.splitlines()) if len(p) == 3}


def test_outputs_off_is_the_first_call_of_main(board: Path) -> None:
    calls = [
        re.sub(r".*<(\w+)>.*", r"\1", i) for i in _function(board, "main") if i.startswith("bl")
    ]
    assert calls[:3] == ["fw_io_outputs_off", "fw_reset_cause", "fw_clock_init"]


def test_outputs_off_freezes_the_pwm_timer_under_a_debugger(board: Path) -> None:
    # DBGMCU (0xE0042000) + APB2_FZ (0x0C) |= DBG_TIM8_STOP (bit 1); TIM8 (0x40010400) BDTR
    # (0x44) = OSSI | LOCK level 2 (0x600), MOE off
    code = _function(board, "fw_io_outputs_off")
    assert ".word\t0xe0042000" in code and ".word\t0x40010400" in code
    assert any(re.fullmatch(r"orr(\.w)?\s+r(\d), r\2, #2", i) for i in code)
    assert any(re.fullmatch(r"str\s+r\d, \[r\d, #12\]", i) for i in code)
    assert "mov.w\tr2, #1536\t@ 0x600" in code


def test_the_wait_checks_and_sleeps_with_interrupts_masked(board: Path) -> None:
    code = [
        " ".join(i.split()[:2]) if i.startswith("cps") else i.split()[0]
        for i in _function(board, "fw_wait_step")
    ]
    assert code[0] == "cpsid i"  # masked before the tick is read
    wfi = code.index("wfi")
    # WFI entered masked (a tick pending since the check ends it at once), the tick taken right
    # after it, masked again for the next check; the only other unmasking is on the way out
    assert code[wfi + 1 : wfi + 3] == ["cpsie i", "cpsid i"]
    for at, ins in enumerate(code):
        if ins == "cpsie i" and at != wfi + 1:
            assert code[at + 1] == "bx"


def test_the_board_image_has_no_emulator_path(board: Path, emulator: Path) -> None:
    on_board, in_qemu = _symbols(board), _symbols(emulator)
    for hil in ("td_hil_rx", "td_slcan_feed", "fw_uart_init"):
        assert hil not in on_board and hil in in_qemu
    # the board sets its clock up from the reset state; the emulator build has no clock set-up
    assert "clock_reset_state" in on_board or "fw_clock_init" in on_board
    assert "fw_can_init" in on_board and "fw_can_init" not in in_qemu


def test_vector_table_has_the_new_handlers(board: Path) -> None:
    sym = _symbols(board)
    vectors = sym["vectors"]
    data = subprocess.run(
        ["arm-none-eabi-objcopy", "-O", "binary", "-j", ".isr_vector", str(board), "/dev/stdout"],
        capture_output=True,
        check=True,
    ).stdout
    assert vectors == sym.get("_sisr_vector", vectors)
    words = [int.from_bytes(data[i : i + 4], "little") & ~1 for i in range(0, len(data), 4)]
    assert words[2] == sym["NMI_Handler"] & ~1  # the clock security system
    assert words[16 + 22] == sym["CAN1_SCE_IRQHandler"] & ~1  # bxCAN status change / error
    assert words[16 + 37] == 0  # USART1: only the emulator build has a serial link
