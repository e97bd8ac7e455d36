"""The field experiment: passes over a field with NDVI variation, speed changes inside the
passes, headland stops and turns and loose patches, run in the loop with the C ECU core in
each speed mode; the applied rate per metre against the prescription at that spot.

The simulated PC runs the terminal's crop path (sensors -> distance queue -> linear model,
with the look-ahead) and pauses the metering in the headland turns, so every pass starts from
rest and ends at rest. The field crew's measure is the fertilizer that landed on each 5 cm of
track (`World.applied_by_bin`) beside the true NDVI under the outlets there.
"""

from __future__ import annotations

import dataclasses
import json
import math
import random
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from topdress.protocol import SpeedMode
from topdress.sim.experiments import FUSED
from topdress.sim.sil import NdviRate, PcParams, Sil
from topdress.sim.tractor import Drive, Segment
from topdress.sim.world import SimConfig, World

EcuSettings = tuple[tuple[str, float], ...]
WINDOW_M = 10.0  # the start and stop windows
AFTER_M = 2.0  # after a stop: whatever lands before the machine has moved this far counts
FINE_BIN_M = 0.05

# the fused mode with the parameters tuned on the simulator (experiments.FUSED)
FUSED_SETTINGS: EcuSettings = (("SpeedMode", float(SpeedMode.FUSED.code)), *FUSED)
# The metering loop of the paper's ECU (the plain PID, before the learned drive slope).
PAPER_DRIVE: EcuSettings = (("DriveAdapt", 0.0), ("MeterTau", 0.0))
MODES: dict[str, EcuSettings] = {
    SpeedMode.PAPER: (),
    SpeedMode.GNSS_ONLY: (("SpeedMode", float(SpeedMode.GNSS_ONLY.code)),),
    SpeedMode.WHEEL_ONLY: (("SpeedMode", float(SpeedMode.WHEEL_ONLY.code)),),
    SpeedMode.FUSED: FUSED_SETTINGS,
}
# the terminal's look-ahead for the rate: half the 323 ms program cycle + half the 500 ms
# command period + the ECU's lead (meter + air line)
LOOKAHEAD_S = 0.41 + 0.6


@dataclass(frozen=True)
class FieldPlan:
    """The field: `passes` passes of `length_m`, each split into `changes` stretches at speeds
    drawn from speed_kmh; one loose patch of `loose_radius_m` per pass (0: none)."""

    passes: int = 10
    length_m: float = 150.0
    speed_kmh: tuple[float, float] = (4.0, 10.0)
    changes: int = 3
    loose_radius_m: float = 8.0
    headland_stop_s: float = 2.0
    width_m: float = 3.6

    def drive(self, seed: int) -> Drive:
        rng = random.Random(seed * 31 + 7)
        segs: list[Segment] = [Segment("stop", duration_s=3.0 + rng.random())]
        part = self.length_m / self.changes
        for i in range(self.passes):
            for _ in range(self.changes):
                v = round(rng.uniform(*self.speed_kmh), 1)
                segs.append(Segment("straight", speed_kmh=v, length_m=part))
            segs.append(Segment("stop", duration_s=self.headland_stop_s))
            if i == self.passes - 1:
                break
            sign = 1.0 if i % 2 == 0 else -1.0
            segs.append(
                Segment("turn", speed_kmh=3.0, angle_deg=180.0 * sign, radius_m=self.width_m / 2)
            )
            segs.append(Segment("stop", duration_s=self.headland_stop_s + rng.random()))
        return Drive(segs)

    def loose_patches(self, seed: int) -> tuple[tuple[float, float, float], ...]:
        """One patch on each pass (passes run north-south at x = i * width)."""
        if self.loose_radius_m <= 0.0:
            return ()
        rng = random.Random(seed * 17 + 3)
        r = self.loose_radius_m
        return tuple(
            (i * self.width_m, rng.uniform(r, self.length_m - r), r) for i in range(self.passes)
        )


@dataclass
class FieldRun:
    """One field run: per-bin landings and truth, pass limits, the speed error trace."""

    bin_m: float
    applied: dict[int, float]
    ndvi: dict[int, float]
    passes: list[tuple[float, float]]  # (start odometer, stop odometer) of each pass
    speed_err_kmh: np.ndarray


@dataclass(frozen=True)
class FieldMetrics:
    rate_rms_pct: float
    rate_p95_pct: float
    total_kg_err_pct: float
    start_m: float
    stop_m: float
    speed_rms_kmh: float
    starts: int
    metres: int
    rate_rms_mid_pct: float = math.nan  # the metres outside the start and stop windows

    def as_dict(self) -> dict[str, float]:
        return {k: round(float(v), 4) for k, v in dataclasses.asdict(self).items()}


def _bins(b: dict[int, float], lo: int, hi: int) -> np.ndarray:
    return np.array([b.get(i, 0.0) for i in range(lo, hi)])


def pass_errors(
    run: FieldRun, kg_ha: Callable[[float], float], width_m: float
) -> tuple[list[float], float, float, list[float], list[float], list[float]]:
    """(per-metre rate errors %, applied kg, prescribed kg, start deficits m, stop excesses m,
    per-metre errors outside the start and stop windows).

    Per metre: the kg landed on each whole metre of a pass against the prescription of its
    bins. Start: the metres of rate missing over the first WINDOW_M of a pass. Stop: the
    metres of rate in excess over the last WINDOW_M, plus what landed up to AFTER_M beyond
    the stop point, counted at the rate prescribed there. Applied kg counts every landing
    (turns included), prescribed kg the passes only."""
    bm = run.bin_m
    per_bin = 1e-4 * width_m * bm  # kg per bin per kg/ha

    def presc(lo: int, hi: int) -> np.ndarray:
        return np.array([kg_ha(run.ndvi.get(i, math.nan)) * per_bin for i in range(lo, hi)])

    errs: list[float] = []
    mid: list[float] = []
    starts: list[float] = []
    stops: list[float] = []
    total_p = 0.0
    per_m = round(1.0 / bm)
    win = round(WINDOW_M / bm)
    for a_m, b_m in run.passes:
        a, b = math.ceil(a_m / bm), math.floor(b_m / bm)
        if b - a < 2 * win:
            continue
        p = presc(a, b)
        x = _bins(run.applied, a, b)
        total_p += float(p.sum())
        n = (b - a) // per_m
        pm = p[: n * per_m].reshape(n, per_m).sum(axis=1)
        xm = x[: n * per_m].reshape(n, per_m).sum(axis=1)
        e = (100.0 * (xm / pm - 1.0)).tolist()
        errs.extend(e)
        w_m = round(WINDOW_M)
        mid.extend(e[w_m : n - w_m])
        starts.append(float(np.sum((1.0 - x[:win] / p[:win]) * bm)))
        after = float(_bins(run.applied, b, b + round(AFTER_M / bm)).sum())
        stop = float(np.sum((x[-win:] / p[-win:] - 1.0) * bm)) + after / p[-1] * bm
        stops.append(stop)
    total_x = float(sum(run.applied.values()))
    return errs, total_x, total_p, starts, stops, mid


def field_metrics(
    runs: Iterable[FieldRun], kg_ha: Callable[[float], float], width_m: float
) -> FieldMetrics:
    """The field's figures over several runs (seeds)."""
    errs: list[float] = []
    mids: list[float] = []
    starts: list[float] = []
    stops: list[float] = []
    tx = tp = 0.0
    sq: list[np.ndarray] = []
    for run in runs:
        e, x, p, s0, s1, mid = pass_errors(run, kg_ha, width_m)
        errs += e
        mids += mid
        starts += s0
        stops += s1
        tx += x
        tp += p
        sq.append(run.speed_err_kmh)
    err = np.array(errs)
    sp = np.concatenate(sq) if sq else np.array([])
    return FieldMetrics(
        rate_rms_pct=float(np.sqrt(np.mean(err**2))) if err.size else math.nan,
        rate_p95_pct=float(np.percentile(np.abs(err), 95)) if err.size else math.nan,
        total_kg_err_pct=100.0 * (tx / tp - 1.0) if tp > 0 else math.nan,
        start_m=float(np.mean(starts)) if starts else math.nan,
        stop_m=float(np.mean(stops)) if stops else math.nan,
        speed_rms_kmh=float(np.sqrt(np.mean(sp**2))) if sp.size else math.nan,
        starts=len(starts),
        metres=int(err.size),
        rate_rms_mid_pct=float(np.sqrt(np.mean(np.square(mids)))) if mids else math.nan,
    )


@dataclass(frozen=True)
class FieldSetup:
    """What differs between the field experiment and the baseline reproduction."""

    plan: FieldPlan = field(default_factory=FieldPlan)
    cfg: SimConfig = field(default_factory=lambda: SimConfig(bin_m=FINE_BIN_M))
    lookahead_s: float = LOOKAHEAD_S
    gnss_time: bool = True
    ecu_params: EcuSettings = ()  # on top of the mode's settings
    pc_cycle_s: float = 0.323  # the PC's program cycle (the paper's; the terminal ticks 0.1 s)
    send_on_rate: bool = False  # the PC sends a changed rate at once (can.send_on_rate)

    def ndvi_rate(self, lookahead: bool) -> NdviRate:
        return NdviRate(lookahead_s=self.lookahead_s if lookahead else 0.0)


# The code before issue 11's changes, as the issue measured it: sensors at the outlets, a
# counts-only wheel port, no PcGnssTime, no look-ahead, the plain PID; 10 passes of 150 m at
# one speed of 5-9 km/h each, no loose patches.
BASELINE = FieldSetup(
    plan=FieldPlan(speed_kmh=(5.0, 9.0), changes=1, loose_radius_m=0.0),
    cfg=SimConfig(bin_m=FINE_BIN_M, crop_ahead_m=0.0, wheel_edges=False),
    lookahead_s=0.0,
    gnss_time=False,
    ecu_params=PAPER_DRIVE,
)


def robustness_variants() -> dict[str, Callable[[SimConfig], SimConfig]]:
    """Name -> a change of the simulated machine (the ECU and terminal settings unchanged)."""

    def gnss(**kw: float | tuple[tuple[float, float], ...]) -> Callable[[SimConfig], SimConfig]:
        return lambda c: dataclasses.replace(c, gnss=dataclasses.replace(c.gnss, **kw))  # type: ignore[arg-type]

    def wheel(**kw: float) -> Callable[[SimConfig], SimConfig]:
        return lambda c: dataclasses.replace(c, wheel=dataclasses.replace(c.wheel, **kw))  # type: ignore[arg-type]

    return {
        "latency 0.2 s": gnss(latency_s=0.2),
        "latency 1.0 s": gnss(latency_s=1.0),
        "receiver 1 Hz": gnss(rate_hz=1.0),
        "receiver 10 Hz": gnss(rate_hz=10.0),
        "10 s outage": gnss(outages=((60.0, 70.0),)),
        "bouncing wheel": wheel(bounce_sd=0.10),
        # diagnostic, not a fault: how much of the rate error is the crop sensors' noise
        "crop sensors without noise": lambda c: dataclasses.replace(
            c, crop=dataclasses.replace(c.crop, refl_sd=0.0)
        ),
    }


def field_run(setup: FieldSetup, mode: str, seed: int, lookahead: bool = True) -> FieldRun:
    """One run of the field in `mode` (a MODES key)."""
    plan = setup.plan
    cfg = dataclasses.replace(setup.cfg, loose_patches=plan.loose_patches(seed))
    drive = plan.drive(seed)
    world = World(cfg, seed=seed, drive=drive)
    pc = PcParams(
        ecu_params=(*setup.ecu_params, *MODES[mode]),
        gnss_time=setup.gnss_time,
        ndvi_rate=setup.ndvi_rate(lookahead and mode == "fused"),
        cycle_s=setup.pc_cycle_s,
        send_on_rate=setup.send_on_rate,
    )
    passes: list[tuple[float, float]] = []
    start: float | None = None
    index = -1
    with Sil(world, pc) as sil:
        while not drive.finished and world.t_s < 3600.0:
            if drive.index != index:
                prev = drive.segments[index] if index >= 0 else None
                index = drive.index
                seg = drive.segment
                odo = world.tractor.odometer
                if prev is not None and prev.kind == "stop" and seg and seg.kind == "straight":
                    start = odo
                ended = prev is not None and prev.kind == "stop" and start is not None
                if ended and drive.segments[index - 2].kind == "straight":
                    assert start is not None
                    passes.append((start, odo))
                    start = None
                # the operator pauses the metering for the headland turn
                sil.pc.paused = seg is not None and seg.kind == "turn"
            sil.step()
        if start is not None:
            passes.append((start, world.tractor.odometer))
        assert sil.record is not None
        tr = sil.record.arrays()
    moving = (tr["v_true_kmh"] > 0.0) | (tr["selected_kmh"] > 0.0)
    err = (tr["selected_kmh"] - tr["v_true_kmh"])[moving]
    return FieldRun(cfg.bin_m, dict(world.applied_by_bin[0]), world.ndvi_by_bin, passes, err)


def field_experiment(
    setup: FieldSetup,
    seeds: Iterable[int],
    modes: Iterable[str] = tuple(MODES),
    cfg_change: Callable[[SimConfig], SimConfig] | None = None,
) -> dict[str, FieldMetrics]:
    """Mode -> the field's figures over the seeds."""
    if cfg_change is not None:
        setup = dataclasses.replace(setup, cfg=cfg_change(setup.cfg))
    kg_ha = setup.ndvi_rate(False).kg_ha
    out = {}
    for mode in modes:
        runs = [field_run(setup, mode, s) for s in seeds]
        out[mode] = field_metrics(runs, kg_ha, setup.plan.width_m)
    return out


def metrics_json(result: Mapping[str, FieldMetrics]) -> dict[str, dict[str, float]]:
    return {mode: m.as_dict() for mode, m in result.items()}


ROBUST_MODES = ("paper", "fused")


def write_field(
    out: Path,
    seeds: list[int],
    plan: FieldPlan,
    robustness: bool = True,
    baseline: bool = True,
) -> Path:
    """Run the field experiment (and the baseline reproduction and robustness runs) and write
    field.md and field.json."""
    setup = dataclasses.replace(FieldSetup(), plan=plan)
    res = field_experiment(setup, seeds)
    doc: dict[str, object] = {"modes": metrics_json(res), "seeds": seeds}
    md = "# Field experiment\n\n"
    md += (
        f"{plan.passes} passes of {plan.length_m:g} m, {plan.changes} speeds per pass drawn from "
        f"{plan.speed_kmh[0]:g}-{plan.speed_kmh[1]:g} km/h, headland stop, turn (metering "
        f"paused), stop; one loose patch (radius {plan.loose_radius_m:g} m, wheel slip 15 %) per "
        f"pass; seeds {seeds}. Rate error per metre of pass: landed vs prescribed at that spot. "
        "Start: metres of rate missing over the first 10 m of a pass; stop: metres of rate in "
        "excess over the last 10 m (plus what lands after). Speed error: ECU speed - true, "
        "100 ms samples while moving. rate_rms_mid_pct: the per-metre RMS outside the start "
        "and stop windows.\n\n"
    )
    md += _table_md(res)
    if baseline:
        bplan = dataclasses.replace(BASELINE.plan, passes=plan.passes, length_m=plan.length_m)
        base = field_experiment(
            dataclasses.replace(BASELINE, plan=bplan),
            seeds,
            (SpeedMode.PAPER, SpeedMode.GNSS_ONLY, SpeedMode.WHEEL_ONLY),
        )
        doc["baseline"] = metrics_json(base)
        md += (
            "\n## Baseline (the code before the fused mode)\n\n"
            "Sensors at the outlets, counts-only wheel port, no PcGnssTime, no look-ahead, "
            "the plain PID; one speed of 5-9 km/h per pass, no loose patches.\n\n"
        )
        md += _table_md(base)
    if robustness:
        rob: dict[str, dict[str, dict[str, float]]] = {}
        md += f"\n## Robustness (seed {seeds[0]}; ECU and terminal settings unchanged)\n\n"
        for name, change in robustness_variants().items():
            r = field_experiment(setup, seeds[:1], ROBUST_MODES, change)
            rob[name] = metrics_json(r)
            md += f"\n### {name}\n\n" + _table_md(r)
        doc["robustness"] = rob
    (out / "field.json").write_text(json.dumps(doc, indent=2) + "\n")
    path = out / "field.md"
    path.write_text(md)
    return path


def _table_md(res: Mapping[str, FieldMetrics]) -> str:
    keys = ("rate_rms_pct", "rate_p95_pct", "total_kg_err_pct", "start_m", "stop_m")
    more = ("speed_rms_kmh", "rate_rms_mid_pct")
    lines = ["| mode | " + " | ".join((*keys, *more)) + " |", "|---" * 8 + "|"]
    for mode, m in res.items():
        vals = [f"{getattr(m, k):.2f}" for k in (*keys, *more)]
        lines.append(f"| {mode} | " + " | ".join(vals) + " |")
    return "\n".join(lines) + "\n"
