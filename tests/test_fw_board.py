"""The STM32F4 board headers (ecu/ports/stm32f4/boards/*.h) and the firmware's build options:
the clock tree each board's crystal gives (board.h derives it and checks every PLL and bus limit
at compile time), the pin maps (no pin twice, none the board uses for something else, each pin
with an alternate function it has), and `FW_CFLAGS=-DBOARD_CAN_BITRATE=500000` reaching the
bit-timing register in the image."""

from __future__ import annotations

import re
import shutil
import struct
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PORT = REPO / "ecu" / "ports" / "stm32f4"
BOARDS = sorted(p.stem for p in (PORT / "boards").glob("*.h"))
CC = shutil.which("cc") or shutil.which("gcc")
ARM_CC = shutil.which("arm-none-eabi-gcc")
host_cc = pytest.mark.skipif(CC is None, reason="no host C compiler")
arm_cc = pytest.mark.skipif(
    ARM_CC is None, reason="arm-none-eabi-gcc missing (scripts/sysdeps.sh firmware)"
)

CLOCK = (
    *("BOARD_HSE_HZ", "BOARD_PLL_M", "BOARD_PLL_N", "BOARD_PLL_P", "BOARD_PLL_Q", "BOARD_VCO_HZ"),
    *("BOARD_CORE_HZ", "BOARD_APB1_HZ", "BOARD_APB2_HZ", "BOARD_FLASH_WS"),
)


def _board_values(tmp_path: Path, board: str, names: tuple[str, ...], *flags: str) -> list[int]:
    src = tmp_path / "board.c"
    body = "".join(f'    printf("%lu\\n", (unsigned long)({n}));\n' for n in names)
    src.write_text(
        f'#include <stdio.h>\n#include "board.h"\nint main(void) {{\n{body}    return 0;\n}}\n'
    )
    exe = tmp_path / "board"
    assert CC is not None
    cmd = [
        CC,
        "-std=c99",
        "-pedantic",
        "-Werror",
        "-I",
        str(PORT),
        f'-DBOARD_HEADER="boards/{board}.h"',
    ]
    subprocess.run(
        [*cmd, *flags, "-o", str(exe), str(src)], check=True, capture_output=True, text=True
    )
    return [
        int(v) for v in subprocess.run([str(exe)], capture_output=True, text=True).stdout.split()
    ]


def _compile_error(tmp_path: Path, board: str, *flags: str) -> str:
    src = tmp_path / "bad.c"
    src.write_text('#include "board.h"\nint main(void) { return 0; }\n')
    assert CC is not None
    # C11 on the host: glibc's headers replace C11's _Static_assert in C99 mode, losing its text
    cmd = [CC, "-std=c11", "-fsyntax-only", "-I", str(PORT), f'-DBOARD_HEADER="boards/{board}.h"']
    done = subprocess.run([*cmd, *flags, str(src)], capture_output=True, text=True)
    assert done.returncode != 0
    return done.stderr


@host_cc
@pytest.mark.parametrize(
    ("board", "want"),
    [
        # crystal, M, N, P, Q, VCO, SYSCLK, APB1, APB2, flash wait states (RM0090 6.3.2, 3.5.1)
        (
            "generic8",
            (8_000_000, 4, 160, 2, 7, 320_000_000, 160_000_000, 40_000_000, 80_000_000, 5),
        ),
        (
            "olimex_e407",
            (12_000_000, 6, 160, 2, 7, 320_000_000, 160_000_000, 40_000_000, 80_000_000, 5),
        ),
        (
            "olimex_p407",
            (25_000_000, 25, 320, 2, 7, 320_000_000, 160_000_000, 40_000_000, 80_000_000, 5),
        ),
    ],
)
def test_the_clock_tree_from_each_crystal(
    tmp_path: Path, board: str, want: tuple[int, ...]
) -> None:
    assert _board_values(tmp_path, board, CLOCK) == list(want)


@host_cc
def test_every_board_has_a_row_here() -> None:
    assert BOARDS == ["generic8", "olimex_e407", "olimex_p407"]


@host_cc
def test_the_limits_are_checked_at_compile_time(tmp_path: Path) -> None:
    # the 168 MHz tree: APB1 42 MHz, where 16 quanta per bit do not divide 250 kbit/s
    assert "must divide APB1 / 16" in _compile_error(
        tmp_path, "generic8", "-DBOARD_CORE_HZ=168000000u"
    )
    assert "SYSCLK at most 168 MHz" in _compile_error(
        tmp_path, "generic8", "-DBOARD_CORE_HZ=180000000u"
    )
    # 1 Mbit/s cannot be made from 40 MHz with 16 quanta per bit
    assert "must divide APB1 / 16" in _compile_error(
        tmp_path, "generic8", "-DBOARD_CAN_BITRATE=1000000"
    )
    # a crystal that is not one: the board header's own value is not guarded, so a test header
    bad = tmp_path / "boards"
    bad.mkdir()
    text = (PORT / "boards" / "generic8.h").read_text()
    (bad / "xtal3.h").write_text(text.replace("8000000u", "3000000u"))
    src = tmp_path / "x.c"
    src.write_text('#include "board.h"\nint main(void) { return 0; }\n')
    assert CC is not None
    inc = ["-I", str(PORT), "-I", str(tmp_path), '-DBOARD_HEADER="boards/xtal3.h"']
    done = subprocess.run(
        [CC, "-std=c11", "-fsyntax-only", *inc, str(src)],
        capture_output=True,
        text=True,
    )
    assert "HSE crystal 4-26 MHz" in done.stderr


@host_cc
@pytest.mark.parametrize("bitrate", [500_000, 250_000, 125_000])
def test_bit_timing_sample_point_87_5(tmp_path: Path, bitrate: int) -> None:
    pll, hsi = _board_values(
        tmp_path,
        "generic8",
        ("BOARD_CAN_BTR_FOR(BOARD_APB1_HZ)", "BOARD_CAN_BTR_FOR(BOARD_HSI_HZ)"),
        f"-DBOARD_CAN_BITRATE={bitrate}",
    )
    for btr, pclk in ((pll, 40_000_000), (hsi, 16_000_000)):
        brp, ts1, ts2, sjw = (
            (btr & 0x3FF) + 1,
            ((btr >> 16) & 0xF) + 1,
            ((btr >> 20) & 7) + 1,
            ((btr >> 24) & 3) + 1,
        )
        quanta = 1 + ts1 + ts2
        assert pclk / (brp * quanta) == bitrate
        assert (1 + ts1) / quanta == 0.875
        assert sjw == 2


@host_cc
@pytest.mark.parametrize("bitrate", [500_000, 250_000, 125_000, 100_000])
def test_fixed_timing_is_what_the_host_tested_search_finds(tmp_path: Path, bitrate: int) -> None:
    # td_bxcan_timing() (ecu/ports/common, tested by make ctest) picks the same register value
    # from the board's 40 MHz APB1 at 87.5 %
    (fixed,) = _board_values(
        tmp_path,
        "generic8",
        ("BOARD_CAN_BTR_FOR(BOARD_APB1_HZ)",),
        f"-DBOARD_CAN_BITRATE={bitrate}",
    )
    src = tmp_path / "timing.c"
    src.write_text(
        '#include <stdio.h>\n#include "td_bxcan.h"\nint main(void) {\n'
        "    td_bxcan_timing_t t;\n"
        f"    if (td_bxcan_timing(40000000u, {bitrate}u, 875u, &t) != 0) return 1;\n"
        '    printf("%lu\\n", (unsigned long)t.btr);\n    return 0;\n}\n'
    )
    exe = tmp_path / "timing"
    assert CC is not None
    common = REPO / "ecu" / "ports" / "common"
    inc = [
        "-I",
        str(common),
        "-I",
        str(REPO / "ecu" / "include"),
        "-I",
        str(REPO / "ecu" / "src" / "gen"),
    ]
    subprocess.run([CC, *inc, "-o", str(exe), str(src), str(common / "td_bxcan.c")], check=True)
    searched = int(subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout)
    assert searched == fixed


# ---- pin maps ------------------------------------------------------------------------------

ROLES = {
    "PIN_CAN_RX": "CAN1_RX",
    "PIN_CAN_TX": "CAN1_TX",
    "PIN_WHEEL": "TIM2_CH1",
    "PIN_METER_UP_A": "TIM3_CH1",
    "PIN_METER_UP_B": "TIM3_CH2",
    "PIN_METER_LO_A": "TIM4_CH1",
    "PIN_METER_LO_B": "TIM4_CH2",
    "PIN_FAN_UP_TACH": "TIM9_CH1",
    "PIN_FAN_LO_TACH": "TIM{fan_lo}_CH1",
    "PIN_PWM_METER_UP": "TIM{pwm}_CH1",
    "PIN_PWM_METER_LO": "TIM{pwm}_CH2",
    "PIN_PWM_FAN_UP": "TIM{pwm}_CH3",
    "PIN_PWM_FAN_LO": "TIM{pwm}_CH4",
    "PIN_SERIAL_TX": "USART{usart}_TX",
    "PIN_SERIAL_RX": "USART{usart}_RX",
}


def _macros(board: str) -> dict[str, str]:
    assert CC is not None
    out = subprocess.run(
        [CC, "-E", "-dM", "-x", "c", str(PORT / "boards" / f"{board}.h")],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    found = (re.match(r"#define (\w+) (.*)", line) for line in out.splitlines())
    return {m[1]: m[2] for m in found if m}


def _pin_table() -> dict[tuple[str, str], int]:
    rows = (
        ln.split("\t") for ln in (PORT / "pins.tsv").read_text().splitlines() if ln and ln[0] != "#"
    )
    return {(pin, fn): int(af) for pin, fn, af in rows}


def _pins(macros: dict[str, str]) -> dict[str, tuple[str, int]]:
    pins = {}
    for name, value in macros.items():
        if name.startswith("PIN_"):
            port, pin, af = (int(v.strip().rstrip("u")) for v in value.split(","))
            pins[name] = (f"P{'ABCDE'[port]}{pin}", af)
    return pins


def check_pin_map(macros: dict[str, str]) -> list[str]:
    """The pin map's errors: a role missing, a pin used twice or reserved, a wrong function."""
    pins = _pins(macros)
    table = _pin_table()
    errors = [f"{role} missing" for role in ROLES if role not in pins]
    seen: dict[str, str] = {}
    reserved = set(macros.get("BOARD_RESERVED_PINS", '""').replace('"', " ").split())
    usart = "1" if pins.get("PIN_SERIAL_TX", ("", 0))[0] == "PA9" else "3"
    for role, (pin, af) in pins.items():
        if pin in seen:
            errors.append(f"{pin} is {seen[pin]} and {role}")
        seen[pin] = role
        if pin in reserved:
            errors.append(f"{role} on {pin}, which the board uses for something else")
        fn = ROLES.get(role, "?").format(
            pwm=macros["BOARD_PWM_TIM"].rstrip("u"),
            fan_lo=macros["BOARD_FAN_LO_TIM"].rstrip("u"),
            usart=usart,
        )
        if table.get((pin, fn)) != af:
            errors.append(f"{role}: {pin} AF{af} is not {fn} (pins.tsv)")
    return errors


@host_cc
@pytest.mark.parametrize("board", BOARDS)
def test_pin_map_has_no_conflict(board: str) -> None:
    assert check_pin_map(_macros(board)) == []


@host_cc
def test_pin_map_check_catches_conflicts() -> None:
    m = _macros("olimex_e407")
    assert check_pin_map({**m, "PIN_PWM_FAN_LO": "2u, 9u, 3u"}) == [
        "PIN_PWM_FAN_LO on PC9, which the board uses for something else",
        "PIN_PWM_FAN_LO: PC9 AF3 is not TIM1_CH4 (pins.tsv)",
    ]
    assert check_pin_map({**m, "PIN_WHEEL": "1u, 8u, 1u"})[0] == "PB8 is PIN_CAN_RX and PIN_WHEEL"
    # the generic map on the E407 runs into its Ethernet, microSD and USB pins
    generic = _macros("generic8")
    errors = check_pin_map({**generic, "BOARD_RESERVED_PINS": m["BOARD_RESERVED_PINS"]})
    assert {e.split()[2] for e in errors} == {
        "PA7,",
        "PA2,",
        "PB14,",
        "PC8,",
        "PC9,",
        "PA9,",
        "PA10,",
    }


# ---- the build option reaches the image ----------------------------------------------------


def _symbol_words(elf: Path, name: str, count: int) -> list[int]:
    """`count` 32-bit words of a symbol's initial value, read from the ELF's sections."""
    data = elf.read_bytes()
    assert data[:4] == b"\x7fELF" and data[4] == 1  # 32-bit
    (shoff,) = struct.unpack_from("<I", data, 0x20)
    shentsize, shnum, _ = struct.unpack_from("<HHH", data, 0x2E)
    sections = [
        struct.unpack_from("<IIIIIIIIII", data, shoff + i * shentsize) for i in range(shnum)
    ]
    symtab = next(s for s in sections if s[1] == 2)
    strtab = sections[symtab[6]]
    for off in range(symtab[4], symtab[4] + symtab[5], 16):
        st_name, value, _size, _info, _other, shndx = struct.unpack_from("<IIIBBH", data, off)
        end = data.index(b"\0", strtab[4] + st_name)
        if data[strtab[4] + st_name : end].decode() == name:
            sec = sections[shndx]
            at = sec[4] + value - sec[3]
            return list(struct.unpack_from(f"<{count}I", data, at))
    raise AssertionError(f"{name} not in {elf}")


def _make(out: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [
            "make",
            "--no-print-directory",
            "-s",
            "-j2",
            "-f",
            "ecu/ports/stm32f4/firmware.mk",
            f"OUT={out}",
            *args,
        ],
        cwd=REPO,
        capture_output=True,
        text=True,
    )


@arm_cc
def test_bitrate_option_reaches_the_image_and_rebuilds(tmp_path: Path) -> None:
    out = tmp_path / "fw"
    done = _make(out, "FW_CFLAGS=-DBOARD_CAN_BITRATE=500000")
    assert done.returncode == 0, done.stderr
    # 500 kbit/s from 40 MHz: BRP 5, TS1 13, TS2 2, SJW 2; on the 16 MHz fallback BRP 2
    assert _symbol_words(out / "topdress-ecu-stm32f4.elf", "fw_can_btr", 2) == [
        0x011C0004,
        0x011C0001,
    ]
    # the same flags: nothing to do; other flags: every object again (the flags stamp)
    elf = str(out / "topdress-ecu-stm32f4.elf")
    assert _make(out, "-q", elf, "FW_CFLAGS=-DBOARD_CAN_BITRATE=500000").returncode == 0
    plan = _make(out, "-n").stdout
    assert plan.count(" -c ") > 20 and "fw_can.c" in plan
