"""ECU firmware benchmark (`make bench`): the STM32F4 image's footprint and its 10 ms step in QEMU.

Prints exactly:
    fw_flash_bytes: N          text + data of build/fw/topdress-ecu-stm32f4.elf (budget 65536)
    fw_ram_bytes: N            data + bss + the stack reservation (budget 16384)
    fw_stack_worst_bytes: N    deepest thread path + one handler per preemption level with
                               exception frames (scripts/fw_report.py)
  the same three for every board header (ecu/ports/stm32f4/boards/BOARD.h), the emulator
  build (BOARD = qemu) and the ISOBUS builds (FW_ISOBUS=1: BOARD = isobus on the generic
  board, qemu_isobus in the emulator):
    fw_BOARD_flash_bytes: N
    fw_BOARD_ram_bytes: N
    fw_BOARD_stack_worst_bytes: N
  free-running (the firmware on its own SysTick, the guest on the host clock, the plant
  answering each step), QEMU netduinoplus2 with the simulated machine in the loop
  (sim.qemu_ecu), 10 s of a 6.5 km/h pass:
    fw_qemu_step_mean_us: X    the firmware's step interval on its own clock
    fw_qemu_step_sd_us: X
    fw_qemu_step_p99_us: X
    fw_qemu_step_max_us: N
    fw_qemu_late_share: X      share of steps that found no fresh counters
    fw_qemu_step_cost_max_us: N  longest step (receive + core) on the emulated chip
  lockstep (the simulator drives each step at its own time; the step interval on the
  firmware's clock is the simulator's 10 ms exactly, so the jitter left is the host's time
  per World step, which sets only how fast the run goes):
    fw_lockstep_interval_sd_us: X   0 by construction (checked)
    fw_lockstep_host_mean_us: X     host time per World step (plant + round trip to QEMU)
    fw_lockstep_host_p99_us: X
    fw_lockstep_host_max_us: X
    fw_lockstep_realtime_x: X       simulated seconds per host second
    fw_lockstep_step_cost_max_us: N longest step on the emulated chip: the core and the time its
                                    received frames took (host time in QEMU)
Details go to stderr. Without qemu-system-arm the qemu figures are left out (said on stderr).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SECONDS = 10.0


def log(msg: str) -> None:
    print(f"fw_bench: {msg}", file=sys.stderr)


def footprint(*args: str) -> dict[str, int]:
    done = subprocess.run(
        ["make", "--no-print-directory", "-s", "-f", "ecu/ports/stm32f4/firmware.mk", *args],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        sys.exit(f"fw_bench: make firmware failed:\n{done.stderr}")
    log(done.stderr.strip())
    figures = dict(line.split(": ") for line in done.stdout.splitlines() if ": " in line)
    return {k: int(v) for k, v in figures.items()}


def qemu_timing(lockstep: bool) -> dict[str, float] | None:
    from topdress.sim.qemu_ecu import QemuEcu, QemuSil, QemuWorld, qemu_missing
    from topdress.sim.sil import PcParams
    from topdress.sim.tractor import Drive, Segment

    why = qemu_missing()
    if why is not None:
        log(f"no qemu figures: {why}")
        return None
    drive = Drive([Segment("stop", duration_s=1.0), Segment("straight", 6.5, length_m=1000.0)])
    with QemuEcu() as ecu:
        world = QemuWorld(ecu, drive=drive, lockstep=lockstep)
        with QemuSil(world, PcParams(), record=False) as sil:
            while world.t_s < SECONDS:
                sil.step()
        return world.timing.summary()


def main() -> int:
    f = footprint()
    print(f"fw_flash_bytes: {f['flash_bytes']}")
    print(f"fw_ram_bytes: {f['ram_bytes']}")
    print(f"fw_stack_worst_bytes: {f['stack_worst_bytes']}")
    boards = sorted(p.stem for p in (REPO / "ecu" / "ports" / "stm32f4" / "boards").glob("*.h"))
    for name, args in [(b, (f"BOARD={b}",)) for b in boards] + [
        ("qemu", ("VARIANT=qemu",)),
        ("isobus", ("FW_ISOBUS=1",)),
        ("qemu_isobus", ("FW_ISOBUS=1", "VARIANT=qemu")),
    ]:
        f = footprint(*args)
        for key in ("flash_bytes", "ram_bytes", "stack_worst_bytes"):
            print(f"fw_{name}_{key}: {f[key]}")
    t = qemu_timing(lockstep=False)
    if t is not None:
        print(f"fw_qemu_step_mean_us: {t['mean_us']:.1f}")
        print(f"fw_qemu_step_sd_us: {t['sd_us']:.1f}")
        print(f"fw_qemu_step_p99_us: {t['p99_us']:.0f}")
        print(f"fw_qemu_step_max_us: {t['max_us']:.0f}")
        print(f"fw_qemu_late_share: {t['late_inputs'] / t['steps']:.4f}")
        print(f"fw_qemu_step_cost_max_us: {t['max_cost_us']:.0f}")
    t = qemu_timing(lockstep=True)
    if t is not None:
        print(f"fw_lockstep_interval_sd_us: {t['sd_us']:.1f}")
        print(f"fw_lockstep_host_mean_us: {t['host_mean_us']:.0f}")
        print(f"fw_lockstep_host_p99_us: {t['host_p99_us']:.0f}")
        print(f"fw_lockstep_host_max_us: {t['host_max_us']:.0f}")
        print(f"fw_lockstep_realtime_x: {t['steps'] * 0.01 / t['host_total_s']:.2f}")
        print(f"fw_lockstep_step_cost_max_us: {t['max_cost_us']:.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
