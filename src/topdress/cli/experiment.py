"""`topdress experiment NAME --out DIR`: the paper's experiments in the loop with the ECU core."""

from __future__ import annotations

import argparse
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, TypeVar

from tqdm import tqdm

from topdress.errors import ConfigError, DeviceError
from topdress.sim import experiments as ex
from topdress.sim import fieldexp as fx
from topdress.sim import report
from topdress.sim.qemu_ecu import (
    QemuSil,
    ensure_image,
    qemu_machine,
    qemu_missing,
)

NAMES = ("cv", "slip", "table2", "table34", "table5", "fig10", "field", "all")
T = TypeVar("T")


def register(sub: Any) -> None:
    """Add `experiment` to the top-level parser."""
    p = sub.add_parser(
        "experiment",
        help="reproduce one of the paper's experiments in simulation",
        description="Run the paper's experiments with the ECU core in the loop and write "
        "Markdown reports and PNG figures, our numbers beside the paper's.",
    )
    p.add_argument("name", choices=NAMES, help="which experiment (all = every one + index)")
    p.add_argument("--out", required=True, type=Path, help="output directory")
    p.add_argument("--reps", type=int, default=5, help="repetitions per speed (default 5)")
    p.add_argument("--seed", type=int, default=0, help="base seed of the runs")
    p.add_argument("--quick", action="store_true", help="reduced run: fewer reps and speeds")
    p.add_argument("--passes", type=int, default=10, help="field: passes of 150 m (default 10)")
    p.add_argument(
        "--ecu",
        choices=("host", "qemu"),
        default="host",
        help="the ECU in the loop: host = the C core in-process (default); qemu = the STM32F4 "
        "firmware image in QEMU, in lockstep (table2 only)",
    )
    p.set_defaults(func=run)


def _progress(items: Iterable[T], what: str) -> Iterable[T]:
    bar: Iterable[T] = tqdm(list(items), desc=what, unit="run", leave=False)
    return bar


def _table2(out: Path, lab: ex.Lab, reps: int) -> Path:
    rows = ex.table2(lab, ex.TARGETS_KMH, reps, ex.FASTER, ex.FUSED)
    return report.write_table2(out, rows, ex.faster_check(lab, ex.TARGETS_KMH, reps))


def _field(out: Path, args: argparse.Namespace) -> Path:
    """Seeds seed..seed+reps-1; --quick: 2 passes of 60 m, one seed, no robustness runs."""
    if args.quick:
        plan = fx.FieldPlan(passes=2, length_m=60.0)
        return fx.write_field(out, [args.seed], plan, robustness=False, baseline=False)
    if args.passes < 1:
        raise ConfigError("--passes", f"must be at least 1, got {args.passes}")
    seeds = list(range(args.seed, args.seed + args.reps))
    return fx.write_field(out, seeds, fx.FieldPlan(passes=args.passes))


def _lab(args: argparse.Namespace) -> ex.Lab:
    if args.ecu == "host":
        return ex.Lab(base_seed=args.seed, progress=_progress)
    if args.name != "table2":
        raise ConfigError("--ecu", "qemu runs table2 only (the firmware's start delay)")
    if (why := qemu_missing()) is not None:
        raise DeviceError(f"--ecu qemu: {why}")
    machine = qemu_machine(ensure_image())
    return ex.Lab(base_seed=args.seed, progress=_progress, machine=machine, sil=QemuSil)


def run(args: argparse.Namespace) -> int:
    if args.reps < 1:
        raise ConfigError("--reps", f"must be at least 1, got {args.reps}")
    out: Path = args.out
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError("--out", f"cannot create {out}: {exc.strerror}") from None
    reps = min(args.reps, 2) if args.quick else args.reps
    slip_speeds = ex.SLIP_SPEEDS_KMH[::2] if args.quick else ex.SLIP_SPEEDS_KMH
    jumps = ex.TABLE5_JUMPS_RPM[:2] if args.quick else ex.TABLE5_JUMPS_RPM
    lab = _lab(args)
    targets = ex.TARGETS_KMH
    jobs: dict[str, Callable[[], Path]] = {
        "cv": lambda: report.write_cv(out, ex.cv_experiment(lab, targets, reps)),
        "slip": lambda: report.write_slip(out, ex.slip_experiment(lab, slip_speeds, reps)),
        "table2": lambda: _table2(out, lab, reps),
        "table34": lambda: report.write_table34(out, ex.table34(lab, targets, reps)),
        "table5": lambda: report.write_table5(
            out, ex.table5(lab, jumps), ex.table5(lab, jumps, ex.MATCHED_FF)
        ),
        "fig10": lambda: report.write_fig10(out, lab, targets),
        "field": lambda: _field(out, args),
    }
    names = list(jobs) if args.name == "all" else [args.name]
    written = []
    for name in tqdm(names, desc="experiments", unit="exp", disable=len(names) == 1):
        written.append(jobs[name]())
    if args.name == "all":
        written.append(report.write_index(out, written, reps, args.seed))
    for path in written:
        print(path)
    return 0
