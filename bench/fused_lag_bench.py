"""The fused speed against the paper's rule on drives the project's simulator never made.

An independent model of a machine and its sensors writes raw-input events (the NDJSON of
`topdress replay`), and `topdress.log.replay` runs them through the C core as
`topdress replay EVENTS --speed-mode fused|paper` would:

- the drive: rest, launches, cruise, speed changes and braking at accelerations drawn per seed
  (0.2-0.9 m/s^2, smoothstep transitions, 3-12 km/h), then a stop;
- the ground wheel: the paper's slip curve (eq. 5 at the true speed) times an extra slip of
  the ground (2 % unless a case says otherwise), a bounce of 3 % correlated over 0.1 s,
  500 pulses of a 12.3 cm wheel, a count every 10 ms;
- the receiver: RMC sentences at 1-10 Hz whose speed is either Doppler (true speed + noise) or
  the difference of two positions (+ noise) over one fix period, through a first-order filter
  (tau) and a pure delay (the sentence arrives `delay` after its epoch); below 0.1 m/s it
  reports 0. Its lag behind the machine is delay + tau (+ half a fix period for the position
  difference).

Errors are taken at every speed update of the replay (500 ms) against the true speed then:
RMS over the rows while accelerating / braking (|a| > 0.05 m/s^2), and in cruise (3 s after a
change and later) the worst mean error of a cruise stretch, % of its speed. The lag the ECU
learned (no setting) is read at the end of the first cruise (the drive's events cut there: the
first start from rest is all it has seen) and at the end of the drive, against the receiver's
lag; the table gives the mean over the drives and the worst error.

    .venv/bin/python bench/fused_lag_bench.py            # the issue's three receivers
    .venv/bin/python bench/fused_lag_bench.py --matrix   # + receivers 0.2-2.0 s, 1-10 Hz, Doppler
                                                         #   and position difference, wrong lags
"""

from __future__ import annotations

import argparse
import math
import random
import statistics
from collections.abc import Sequence
from dataclasses import dataclass, replace

from topdress.config import EcuConfig, TerminalConfig, default_config
from topdress.gnss import sentences as nmea
from topdress.log.events import Event, NmeaEvent, WheelEvent
from topdress.log.replay import ReplayRow, ReplayStats, replay

DT = 0.001  # the model's own step, s
WHEEL_EVENT_S = 0.01
M_PER_PULSE = 2 * math.pi * 0.0615 / 500
A_PHASE = 0.05  # m/s^2: accelerating or braking beyond this
SETTLE_S = 3.0  # cruise counts from this long after a change


@dataclass(frozen=True)
class Receiver:
    delay_s: float
    tau_s: float
    rate_hz: float = 5.0
    posdiff: bool = False
    speed_sd_ms: float = 0.05  # Doppler noise per fix
    pos_sd_m: float = 0.005  # position noise per fix (position difference)

    @property
    def lag_s(self) -> float:
        return self.delay_s + self.tau_s + (0.5 / self.rate_hz if self.posdiff else 0.0)

    def label(self) -> str:
        kind = "pos-diff" if self.posdiff else "Doppler"
        return f"{self.lag_s:.2f} s ({self.delay_s:g}+{self.tau_s:g}, {self.rate_hz:g} Hz {kind})"


@dataclass(frozen=True)
class Drive:
    t: list[float]
    v: list[float]  # true speed, m/s, every DT
    a: list[float]
    cruise_since: list[float]  # time since the last speed change (inf: none yet), s


def _profile(seed: int) -> list[tuple[float, float]]:
    """(duration s, speed at its end m/s) pieces: a change is a smoothstep over its duration."""
    rng = random.Random(seed)
    pieces: list[tuple[float, float]] = [(4.0, 0.0)]
    v = 0.0
    for k in range(6):
        target = rng.uniform(3.0, 12.0) / 3.6 if k < 5 else 0.0
        a_peak = rng.uniform(0.2, 0.9)
        pieces.append((1.5 * abs(target - v) / a_peak, target))
        pieces.append((rng.uniform(12.0, 25.0) if k < 5 else 4.0, target))
        v = target
    return pieces


def first_cruise_end_s(seed: int) -> float:
    """When the first cruise ends (the second speed change begins), s."""
    pieces = _profile(seed)
    return sum(dur for dur, _ in pieces[:3])


def make_drive(seed: int) -> Drive:
    t_list: list[float] = []
    v_list: list[float] = []
    a_list: list[float] = []
    since: list[float] = []
    t, v0, last_change = 0.0, 0.0, -math.inf
    for dur, v1 in _profile(seed):
        n = round(dur / DT)
        for i in range(n):
            x = (i + 0.5) / n
            if v1 == v0:
                v, a = v0, 0.0
            else:
                v = v0 + (v1 - v0) * x * x * (3 - 2 * x)
                a = (v1 - v0) * 6 * x * (1 - x) / dur
                last_change = t
            t_list.append(t)
            v_list.append(v)
            a_list.append(a)
            since.append(t - last_change)
            t += DT
        v0 = v1
    return Drive(t_list, v_list, a_list, since)


def wheel_events(drive: Drive, seed: int, ground_slip: float) -> list[Event]:
    rng = random.Random(1000 + seed)
    alpha = math.exp(-DT / 0.1)
    bounce, dist = 0.0, 0.0
    every = round(WHEEL_EVENT_S / DT)
    out: list[Event] = []
    for i, (t, v) in enumerate(zip(drive.t, drive.v, strict=True)):
        bounce = alpha * bounce + math.sqrt(1 - alpha * alpha) * rng.gauss(0.0, 0.03)
        kmh = v * 3.6
        slip = (0.167 * kmh * kmh - 0.296 * kmh + 0.773) / 100 + ground_slip
        if v > 0.0:
            dist += v * (1 - slip) * (1 + bounce) * DT
        if i % every == 0:
            out.append(WheelEvent(t, int(dist / M_PER_PULSE)))
    return out


def gnss_events(drive: Drive, rx: Receiver, seed: int) -> list[Event]:
    rng = random.Random(2000 + seed)
    period = 1.0 / rx.rate_hz
    k = period / (rx.tau_s + period)
    y, x, prev_pos = 0.0, 0.0, 0.0
    every = round(period / DT)
    out: list[Event] = []
    for i, (t, v) in enumerate(zip(drive.t, drive.v, strict=True)):
        x += v * DT
        if i == 0 or i % every:
            continue
        if rx.posdiff:
            pos = x + rng.gauss(0.0, rx.pos_sd_m)
            measured = (pos - prev_pos) / period
            prev_pos = pos
        else:
            measured = v + rng.gauss(0.0, rx.speed_sd_ms)
        y += k * (measured - y)
        speed = max(y, 0.0) if y >= 0.1 else 0.0
        line = nmea.rmc("GN", 7200.0 + t, True, 43.9 + x / 111_320.0, 125.3, speed, 0.0, "150626")
        out.append(NmeaEvent(t + rx.delay_s, line))
    return out


@dataclass(frozen=True)
class Score:
    accel_kmh: float
    decel_kmh: float
    cruise_pct: float  # worst |mean error| of a cruise stretch, % of its speed
    lag_ms: int | None  # the lag the ECU learned, at the end


def score(drive: Drive, rows: Sequence[ReplayRow], lag_ms: int | None) -> Score:
    acc: list[float] = []
    dec: list[float] = []
    stretches: dict[int, list[tuple[float, float]]] = {}
    for r in rows:
        i = min(max(round(r.t / DT), 0), len(drive.t) - 1)
        v, a = drive.v[i], drive.a[i]
        err = r.v_kmh - v * 3.6
        if a > A_PHASE:
            acc.append(err)
        elif a < -A_PHASE:
            dec.append(err)
        elif a == 0.0 and v > 0.5 and drive.cruise_since[i] >= SETTLE_S:
            key = round(drive.t[i] - drive.cruise_since[i], 3)
            stretches.setdefault(key, []).append((err, v * 3.6))
    worst = 0.0
    for pairs in stretches.values():
        mean_err = statistics.fmean(e for e, _ in pairs)
        worst = max(worst, abs(mean_err) / pairs[0][1] * 100)
    return Score(_rms(acc), _rms(dec), worst, lag_ms)


def _rms(xs: Sequence[float]) -> float:
    return math.sqrt(statistics.fmean(x * x for x in xs)) if xs else float("nan")


def with_lag(cfg: TerminalConfig, lag_ms: int | None) -> TerminalConfig:
    if lag_ms is None:
        return cfg
    return replace(cfg, ecu=EcuConfig(overrides={**cfg.ecu.overrides, "gnss_lag_ms": lag_ms}))


def run(rx: Receiver, seed: int, mode: str, lag_ms: int | None, ground_slip: float = 0.02) -> Score:
    drive = make_drive(seed)
    events = wheel_events(drive, seed, ground_slip) + gnss_events(drive, rx, seed)
    stats = ReplayStats()
    rows = replay(events, with_lag(default_config(), lag_ms), mode, stats)
    return score(drive, rows, stats.lag_learned_ms)


def first_start_lag(rx: Receiver, seed: int) -> int | None:
    """The lag learned with no setting after the first start: the drive's events cut at the end
    of the first cruise, ms (None: not learned)."""
    drive = make_drive(seed)
    cut = first_cruise_end_s(seed)
    events = wheel_events(drive, seed, 0.02) + gnss_events(drive, rx, seed)
    stats = ReplayStats()
    replay([e for e in events if e.t < cut], default_config(), "fused", stats)
    return stats.lag_learned_ms


def lag_cell(rx: Receiver, lags: Sequence[int | None]) -> str:
    """Mean learned lag, ms, and the worst error against the receiver's lag."""
    missing = sum(lag is None for lag in lags)
    if missing:
        return f"not learned in {missing} of {len(lags)}"
    ms = [float(lag) for lag in lags if lag is not None]
    worst = max((m - rx.lag_s * 1000 for m in ms), key=abs)
    return f"{statistics.fmean(ms):.0f} ({worst:+.0f})"


def mean_score(scores: Sequence[Score]) -> Score:
    lags = [s.lag_ms for s in scores if s.lag_ms is not None]
    return Score(
        statistics.fmean(s.accel_kmh for s in scores),
        statistics.fmean(s.decel_kmh for s in scores),
        max(s.cruise_pct for s in scores),
        round(statistics.fmean(lags)) if lags else None,
    )


def cell(s: Score) -> str:
    return f"{s.accel_kmh:.2f} / {s.decel_kmh:.2f} / {s.cruise_pct:.1f} %"


ISSUE_RECEIVERS = (Receiver(0.2, 0.3), Receiver(0.3, 0.75), Receiver(0.3, 1.5))
MATRIX_RECEIVERS = (
    Receiver(0.1, 0.1, 10.0),
    Receiver(0.1, 0.1, 10.0, posdiff=True),
    Receiver(0.2, 0.3, 1.0),
    Receiver(0.2, 0.3, 1.0, posdiff=True),
    Receiver(0.3, 1.0, 5.0),
    Receiver(0.3, 0.8, 2.0, posdiff=True),
    Receiver(0.5, 1.5, 10.0),
    Receiver(0.4, 1.1, 1.0, posdiff=True),
)


def table(receivers: Sequence[Receiver], seeds: Sequence[int]) -> None:
    print("| receiver lag | fused, no setting | paper rule | fused, lag set right |")
    print("|---|---|---|---|")
    lags: list[str] = []
    for rx in receivers:
        right = round(rx.lag_s * 1000)
        autos = [run(rx, s, "fused", None) for s in seeds]
        paper = mean_score([run(rx, s, "paper", None) for s in seeds])
        fixed = mean_score([run(rx, s, "fused", right) for s in seeds])
        print(f"| {rx.label()} | {cell(mean_score(autos))} | {cell(paper)} | {cell(fixed)} |")
        first = lag_cell(rx, [first_start_lag(rx, s) for s in seeds])
        lags.append(f"| {rx.label()} | {first} | {lag_cell(rx, [a.lag_ms for a in autos])} |")
    print()
    print("Learned lag (no setting), ms: mean over the drives (worst error against the receiver's)")
    print("| receiver lag | after the first start | at the end of the drive |")
    print("|---|---|---|")
    print("\n".join(lags))


def wrong_lags(seeds: Sequence[int]) -> None:
    print()
    print("| receiver lag | configured lag | fused: accel / decel km/h, worst cruise % |")
    print("|---|---|---|")
    for rx in ISSUE_RECEIVERS:
        for lag_ms in (0, 1800, 3000):
            s = mean_score([run(rx, seed, "fused", lag_ms) for seed in seeds])
            print(f"| {rx.label()} | {lag_ms} ms | {cell(s)} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, default=3, help="drives per receiver")
    ap.add_argument("--matrix", action="store_true", help="every receiver and wrong lags")
    args = ap.parse_args()
    seeds = range(args.seeds)
    print("RMS error accel / decel, km/h; worst cruise stretch, % (mean over drives, worst)")
    table(ISSUE_RECEIVERS, seeds)
    if args.matrix:
        print()
        table(MATRIX_RECEIVERS, seeds)
        wrong_lags(seeds)


if __name__ == "__main__":
    main()
