"""Flash, RAM and worst-case stack of the ECU firmware image (`make firmware` runs it).

Usage: fw_report.py IMAGE.elf OBJ_DIR [--quiet]

Stack: every object's call graph with its functions' frame sizes (gcc -fcallgraph-info=su,
OBJ_DIR/**/*.ci) gives the deepest path from the reset handler and from each interrupt handler.
The worst case is the thread's deepest path plus one of each preemption level's deepest handler
(the clock security system's NMI, TIM2 capture at priority 1, CAN and USART at 2, SysTick at 4;
handlers of one level do not preempt each other), each entry with a full exception frame with FPU state (26 words + 1 for
alignment). Functions without a frame size (newlib's memcpy, memset, libgcc) count 64 bytes and
are listed. A recursive call or a call through a pointer makes the analysis fail.

Prints `flash_bytes`, `ram_bytes` (static data + the stack reservation), `stack_worst_bytes`,
`stack_reserved_bytes`, one per line, and exits 1 when a budget is exceeded (flash 64 KiB,
RAM 16 KiB, the worst stack over the reservation).
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

FLASH_BUDGET = 64 * 1024
RAM_BUDGET = 16 * 1024
RAM_ORIGIN = 0x20000000
UNKNOWN_FRAME = 64  # a library leaf without -fstack-usage (newlib-nano's are smaller)
EXCEPTION_FRAME = 27 * 4  # R0-R3, R12, LR, PC, xPSR, S0-S15, FPSCR, alignment word
THREAD_ROOTS = ("Reset_Handler",)
# preemption levels, highest priority first (fw_sys.c, fw_io.c, fw_can.c, fw_uart.c, fw_clock.c)
LEVELS = (
    ("NMI_Handler",),
    ("TIM2_IRQHandler",),
    ("CAN1_RX0_IRQHandler", "CAN1_TX_IRQHandler", "CAN1_SCE_IRQHandler", "USART1_IRQHandler"),
    ("SysTick_Handler",),
)

NODE = re.compile(r'node: \{ title: "([^"]+)" label: "([^"]*)"')
EDGE = re.compile(r'edge: \{ sourcename: "([^"]+)" targetname: "([^"]+)"')
SIZE = re.compile(r"\\n(\d+) bytes \(([a-z,]+)\)")


def load_graph(obj_dir: Path) -> tuple[dict[str, int], dict[str, set[str]], set[str]]:
    """Frame sizes by function, calls by function, and the indirect-call sites."""
    frames: dict[str, int] = {}
    calls: dict[str, set[str]] = {}
    indirect: set[str] = set()
    for ci in sorted(obj_dir.rglob("*.ci")):
        text = ci.read_text(encoding="utf-8", errors="replace")
        for title, label in NODE.findall(text):
            m = SIZE.search(label)
            if m is not None:
                if m[2] not in ("static", "dynamic,bounded"):
                    raise SystemExit(f"fw_report: {title} has a {m[2]} frame")
                frames[title] = int(m[1])
        for src, dst in EDGE.findall(text):
            if dst == "__indirect_call":
                indirect.add(src)
            calls.setdefault(src, set()).add(dst)
    return frames, calls, indirect


def deepest(
    root: str, frames: dict[str, int], calls: dict[str, set[str]], unknown: set[str]
) -> tuple[int, list[str]]:
    """The deepest stack from root (bytes) and its path; SystemExit on recursion."""
    memo: dict[str, tuple[int, list[str]]] = {}

    def walk(fn: str, on_path: tuple[str, ...]) -> tuple[int, list[str]]:
        if fn in on_path:
            raise SystemExit(f"fw_report: recursion {' -> '.join((*on_path, fn))}")
        if fn in memo:
            return memo[fn]
        own = frames.get(fn)
        if own is None:
            unknown.add(fn)
            own = UNKNOWN_FRAME
        best = (0, [])
        for callee in sorted(calls.get(fn, ())):
            best = max(best, walk(callee, (*on_path, fn)), key=lambda x: x[0])
        memo[fn] = (own + best[0], [fn, *best[1]])
        return memo[fn]

    return walk(root, ())


def symbol(elf: Path, name: str) -> int:
    out = subprocess.run(
        ["arm-none-eabi-nm", str(elf)], capture_output=True, text=True, check=True
    ).stdout
    m = re.search(rf"^([0-9a-f]+) \w {re.escape(name)}$", out, re.MULTILINE)
    if m is None:
        raise SystemExit(f"fw_report: no symbol {name} in {elf}")
    return int(m[1], 16)


def report(elf: Path, obj_dir: Path) -> tuple[dict[str, int], list[str]]:
    size = subprocess.run(
        ["arm-none-eabi-size", "-A", str(elf)], capture_output=True, text=True, check=True
    ).stdout
    rows = (ln.split() for ln in size.splitlines())
    sections = {p[0]: int(p[1]) for p in rows if len(p) >= 3 and p[1].isdigit()}
    flash = sum(sections.get(s, 0) for s in (".isr_vector", ".text", ".ARM.exidx", ".data"))
    ram = symbol(elf, "_end_of_ram_use") - RAM_ORIGIN
    reserved = symbol(elf, "_estack") - symbol(elf, "_sstack")
    frames, calls, indirect = load_graph(obj_dir)
    if indirect:
        raise SystemExit(f"fw_report: calls through pointers in {', '.join(sorted(indirect))}")
    unknown: set[str] = set()
    lines = []
    thread = max((deepest(r, frames, calls, unknown) for r in THREAD_ROOTS), key=lambda x: x[0])
    lines.append(f"thread {thread[0]} B: {' > '.join(thread[1])}")
    worst = thread[0]
    for level in LEVELS:
        top = max((deepest(h, frames, calls, unknown) for h in level), key=lambda x: x[0])
        lines.append(f"+ {top[0]} B + {EXCEPTION_FRAME} B exception frame: {' > '.join(top[1])}")
        worst += top[0] + EXCEPTION_FRAME
    fault = deepest("hard_fault_c", frames, calls, unknown)
    lines.append(f"hard fault (fresh stack) {fault[0] + EXCEPTION_FRAME} B")
    if unknown:
        lines.append(f"counted {UNKNOWN_FRAME} B each (no frame size): {', '.join(sorted(unknown))}")
    figures = {
        "flash_bytes": flash,
        "ram_bytes": ram,
        "stack_worst_bytes": worst,
        "stack_reserved_bytes": reserved,
    }
    return figures, lines


def main(argv: list[str]) -> int:
    if len(argv) < 3:
        print(__doc__, file=sys.stderr)
        return 2
    figures, lines = report(Path(argv[1]), Path(argv[2]))
    if "--quiet" not in argv:
        for line in lines:
            print(f"fw_report: {line}", file=sys.stderr)
    for key, value in figures.items():
        print(f"{key}: {value}")
    over = []
    if figures["flash_bytes"] > FLASH_BUDGET:
        over.append(f"flash {figures['flash_bytes']} > {FLASH_BUDGET}")
    if figures["ram_bytes"] > RAM_BUDGET:
        over.append(f"RAM {figures['ram_bytes']} > {RAM_BUDGET}")
    if figures["stack_worst_bytes"] > figures["stack_reserved_bytes"]:
        over.append(
            f"stack {figures['stack_worst_bytes']} > reserved {figures['stack_reserved_bytes']}"
        )
    if over:
        print(f"fw_report: over budget: {'; '.join(over)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
