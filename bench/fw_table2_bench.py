"""Table 2's start delay with the ECU firmware in the loop (QEMU, lockstep) beside the
in-process core: the same runs (speeds, seeds, drives, cab PC) on both ECUs.

Prints, for each target speed, the distance from the clutch to the first fertilizer landing
(the World's truth, metres) in the dual mode, GNSS only and the fused mode, on the in-process
core and on the firmware, then:
    fw_table2_max_diff_m: X     the largest |firmware - core| over every cell (target <= 0.05)
    fw_table2_host_s: X         the host time the firmware's runs took
Usage: bench/fw_table2_bench.py [--reps N] (default 1). Needs qemu-system-arm and the image
(built by the rules of `make firmware` when missing).
"""

from __future__ import annotations

import argparse
import sys
import time

from topdress.sim import experiments as ex
from topdress.sim.qemu_ecu import (
    QemuSil,
    ensure_image,
    qemu_machine,
    qemu_missing,
)

COLUMNS = ("dual_delay_m", "gnss_delay_m", "fused_delay_m")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=1)
    args = ap.parse_args()
    if (why := qemu_missing()) is not None:
        print(f"fw_table2_bench: {why}", file=sys.stderr)
        return 1
    image = ensure_image()
    core = ex.table2(ex.Lab(), ex.TARGETS_KMH, args.reps, fused=ex.FUSED)
    t0 = time.perf_counter()
    fw = ex.table2(
        ex.Lab(machine=qemu_machine(image), sil=QemuSil), ex.TARGETS_KMH, args.reps, fused=ex.FUSED
    )
    host_s = time.perf_counter() - t0
    worst = 0.0
    print("km/h  " + "  ".join(f"{c:>13} core/fw" for c in COLUMNS))
    for a, b in zip(core, fw, strict=True):
        cells = []
        for c in COLUMNS:
            x, y = getattr(a, c), getattr(b, c)
            worst = max(worst, abs(x - y))
            cells.append(f"{x:9.3f}/{y:9.3f}")
        print(f"{a.target_kmh:4.1f}  " + "  ".join(cells))
    print(f"fw_table2_max_diff_m: {worst:.4f}")
    print(f"fw_table2_host_s: {host_s:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
