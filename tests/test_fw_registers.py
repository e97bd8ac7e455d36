"""The register check: every register address, bit and field of the STM32F4 port
(ecu/ports/stm32f4/stm32f4_regs.h) against the table ecu/ports/stm32f4/registers.tsv, which gives
each its RM0090 section. A host program prints what the header defines; a wrong address, a
shifted bit or a definition without a row fails."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PORT = REPO / "ecu" / "ports" / "stm32f4"
CC = shutil.which("cc") or shutil.which("gcc")

pytestmark = pytest.mark.skipif(CC is None, reason="no host C compiler")


def _rows() -> list[tuple[str, str, int, str]]:
    rows = []
    for line in (PORT / "registers.tsv").read_text(encoding="utf-8").splitlines():
        if line.startswith("#") or not line.strip():
            continue
        name, expr, value, section = line.split("\t")
        rows.append((name, expr, int(value, 16), section))
    return rows


def _defined(tmp_path: Path, exprs: list[str]) -> list[int]:
    prog = [
        "#include <stdint.h>",
        "#include <stdio.h>",
        '#include "stm32f4_regs.h"',
        "int main(void) {",
    ]
    prog += [f'    printf("%lu\\n", (unsigned long)({e}));' for e in exprs]
    prog.append("    return 0;\n}\n")
    src = tmp_path / "regs.c"
    src.write_text("\n".join(prog), encoding="utf-8")
    exe = tmp_path / "regs"
    assert CC is not None
    subprocess.run([CC, "-std=c99", "-I", str(PORT), "-o", str(exe), str(src)], check=True)
    out = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout
    return [int(v) for v in out.split()]


def test_every_row_matches_the_header(tmp_path: Path) -> None:
    rows = _rows()
    assert len(rows) > 200
    got = _defined(tmp_path, [expr for _, expr, _, _ in rows])
    wrong = [
        f"{name}: header {g:#010x}, table {want:#010x} ({section})"
        for (name, _, want, section), g in zip(rows, got, strict=True)
        if g != want
    ]
    assert wrong == []


def test_every_definition_has_a_row_with_its_section() -> None:
    header = (PORT / "stm32f4_regs.h").read_text(encoding="utf-8")
    defined = set(re.findall(r"^#define ([A-Z0-9_]+) ", header, re.M)) - {"REG"}
    rows = _rows()
    assert defined - {name for name, _, _, _ in rows} == set()
    assert all(re.match(r"(RM0090|PM0214) \d", section) for _, _, _, section in rows)


def test_known_values_from_the_manual(tmp_path: Path) -> None:
    # a few read off RM0090 by hand, independent of the table: a table rewritten from a broken
    # header would still fail here
    got = _defined(
        tmp_path,
        [
            "(uintptr_t)&RCC->PLLCFGR",
            "RCC_CR_CSSON",
            "(uintptr_t)&CAN1->BTR",
            "(uintptr_t)&CAN1->ESR",
            "CAN_BTR_SILM",
            "(uintptr_t)&DBGMCU_APB2_FZ",
            "DBGMCU_APB2_FZ_TIM8",
            "(uintptr_t)&TIM8->BDTR",
            "IRQ_CAN1_SCE",
        ],
    )
    assert got == [
        0x40023804,
        1 << 19,
        0x4000641C,
        0x40006418,
        1 << 31,
        0xE004200C,
        2,
        0x40010444,
        22,
    ]


def test_a_changed_bit_is_caught(tmp_path: Path) -> None:
    # the check itself: a header with one bit moved disagrees with the table
    bad = tmp_path / "port"
    bad.mkdir()
    text = (PORT / "stm32f4_regs.h").read_text(encoding="utf-8")
    (bad / "stm32f4_regs.h").write_text(
        text.replace("#define CAN_ESR_BOFF (1u << 2)", "#define CAN_ESR_BOFF (1u << 3)"),
        encoding="utf-8",
    )
    src = tmp_path / "one.c"
    src.write_text(
        '#include <stdio.h>\n#include "stm32f4_regs.h"\n'
        'int main(void) { printf("%u\\n", CAN_ESR_BOFF); return 0; }\n',
        encoding="utf-8",
    )
    assert CC is not None
    subprocess.run([CC, "-I", str(bad), "-o", str(tmp_path / "one"), str(src)], check=True)
    out = subprocess.run([str(tmp_path / "one")], capture_output=True, text=True, check=True).stdout
    want = {name: value for name, _, value, _ in _rows()}["CAN_ESR_BOFF"]
    assert int(out) == 8 != want
