"""ECU core benchmark (`make bench`): instructions per control step, and the Cortex-M4 footprint.

Prints exactly:
    instructions_per_step: N   callgrind, collecting only inside td_app_step, td_app_rx and
                               td_app_tx_pop, over 20,000 steps of bench/ecu_bench_main.c
                               (both motors running, command and GNSS time in every 500 ms, wheel
                               edge times, status drained), default speed mode
    instructions_per_step_fused: N   the same in the fused speed mode
    instructions_per_fix_step_mean: N   the same collection per control period that takes a GNSS
    instructions_per_fix_step_max: N    fix while the speed changes (a launch 0 -> 8 km/h in 4 s, a
                               brake 8 -> 0 in 3 s, three times; fixes at 10 Hz through PcGnssTime
                               as the terminal sends them, a receiver 1.3 s behind): the mean and
                               the worst, fused mode (the GNSS lag learner works then)
    instructions_per_step_launch_brake: N   every step of that drive, averaged
    cortex_m4_text_bytes: N    text of a linked Cortex-M4 image (bench/ecu_cm4_main.c + the core +
    cortex_m4_ram_bytes: N     what it needs of newlib-nano/libgcc; --gc-sections, nosys specs),
                               data + bss including the one static td_app_t a port owns
    budget NAME: N of LIMIT (within|OVER)   the four budgeted figures against the core's budget:
                               mean step <= 3,000 and worst step <= 6,000 instructions, text
                               <= 20 KiB, RAM <= 2.5 KiB; exit status 1 when one is over
Details go to stderr. Missing tools are installed with apt-get (as root).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
BUILD = REPO / "build" / "bench"
STEPS = 20_000
DRIVE_STEPS = 6_000  # drive 1 of the driver: three 20 s cycles of launch, cruise, brake, stand
# The driver's wrappers of the periods that take a fix: names that share no prefix, as
# callgrind 3.19 honoured only one of --dump-before/--dump-after for one of two that did.
FIX_CHANGE, FIX_STEADY = "change_fix_period", "steady_fix_period"
CORE = [*sorted((REPO / "ecu" / "src").glob("*.c")), REPO / "ecu" / "src" / "gen" / "td_can.c"]
INCLUDES = ["-I", str(REPO / "ecu" / "include"), "-I", str(REPO / "ecu" / "src" / "gen")]
WARN = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]
CM4 = [
    "-mcpu=cortex-m4",
    "-mthumb",
    "-mfloat-abi=hard",
    "-mfpu=fpv4-sp-d16",
    "-Os",
    # link-time optimisation: the core's small functions are inlined across files and what a
    # port never calls is dropped (16,296 -> ~12,400 bytes before the learned GNSS lag)
    "-flto",
    # the core never reads errno: sqrtf becomes the FPU's VSQRT instead of newlib's wrapper
    "-fno-math-errno",
    "-ffunction-sections",
    "-fdata-sections",
]
COLLECT = ("td_app_step", "td_app_rx", "td_app_tx_pop")
# The core's budget: the mean step (the launch-and-brake drive, every step) and the worst step (a
# period that takes a fix while the speed changes), Cortex-M4 text and RAM.
BUDGET = {
    "instructions_per_step_launch_brake": 3_000,
    "instructions_per_fix_step_max": 6_000,
    "cortex_m4_text_bytes": 20 * 1024,
    "cortex_m4_ram_bytes": 2_560,
}


def log(msg: str) -> None:
    print(f"ecu_bench: {msg}", file=sys.stderr)


def run(cmd: list[str], env: dict[str, str] | None = None) -> str:
    done = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    if done.returncode != 0:
        sys.exit(f"ecu_bench: {' '.join(cmd[:2])} failed:\n{done.stderr}")
    return done.stdout


def newlib_present() -> bool:
    if shutil.which("arm-none-eabi-gcc") is None:
        return False
    found = run(["arm-none-eabi-gcc", "-print-file-name=nosys.specs"]).strip()
    return os.path.isabs(found)


def ensure_tools() -> None:
    missing = []
    if shutil.which("valgrind") is None:
        missing.append("valgrind")
    if shutil.which("arm-none-eabi-gcc") is None:
        missing.append("gcc-arm-none-eabi")
    if not newlib_present():
        missing.append("libnewlib-arm-none-eabi")
    if not missing:
        return
    if os.geteuid() != 0:
        sys.exit(
            f"ecu_bench: missing {' '.join(missing)} (sudo apt-get install {' '.join(missing)})"
        )
    log(f"installing {' '.join(missing)}")
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    run(["apt-get", "update", "-qq"], env=env)
    run(["apt-get", "install", "-y", "-qq", "--no-install-recommends", *missing], env=env)


def build_driver() -> Path:
    exe = BUILD / "ecu_bench"
    src = [str(p) for p in [*CORE, REPO / "bench" / "ecu_bench_main.c"]]
    run(["gcc", *WARN, "-O2", *INCLUDES, *src, "-lm", "-o", str(exe)])
    return exe


def instructions_per_step(exe: Path, speed_mode: int) -> int:
    out_file = BUILD / "callgrind.out"
    toggles = [f"--toggle-collect={f}" for f in COLLECT]
    cmd = ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out_file}", *toggles]
    printed = run([*cmd, str(exe), str(STEPS), str(speed_mode)])
    m = re.match(r"steps (\d+) frames (\d+) meter_rpm ([\d.]+) ([\d.]+)", printed)
    if m is None or int(m[1]) != STEPS:
        sys.exit(f"ecu_bench: unexpected driver output {printed!r}")
    if not (float(m[3]) > 1.0 and float(m[4]) > 1.0 and int(m[2]) > 0):
        sys.exit(f"ecu_bench: the motors did not run or no frames went out: {printed!r}")
    totals = re.search(r"^totals:\s+(\d+)", out_file.read_text(), re.MULTILINE)
    if totals is None:
        sys.exit("ecu_bench: no totals in the callgrind output")
    log(
        f"host gcc -O2, speed mode {speed_mode}: {totals[1]} instructions in {STEPS} steps; "
        f"driver: {printed.strip()}"
    )
    return round(int(totals[1]) / STEPS)


@dataclass(frozen=True)
class Part:
    """One callgrind dump: what triggered it, its instructions, those in the GNSS lag learner
    (inclusive: the calls into td_lag_* from outside it)."""

    trigger: str
    total: int
    learner: int


def parts(text: str) -> list[Part]:
    """The dumps of a callgrind file written with --combine-dumps, --compress-strings=no."""
    out = []
    for body in re.split(r"^part: \d+$", text, flags=re.MULTILINE)[1:]:
        trigger = re.search(r"^desc: Trigger: (.*)$", body, re.MULTILINE)
        totals = re.search(r"^totals: (\d+)", body, re.MULTILINE)
        if trigger is None or totals is None:
            sys.exit("ecu_bench: a callgrind dump without its trigger or totals")
        out.append(Part(trigger[1], int(totals[1]), learner_cost(body.splitlines())))
    return out


def learner_cost(lines: list[str]) -> int:
    fn = callee = ""
    cost, after_calls = 0, False
    for line in lines:
        if after_calls:  # the line after calls=: position, inclusive cost of the call
            after_calls = False
            if callee.startswith("td_lag_") and not fn.startswith("td_lag_"):
                cost += int(line.split()[-1])
        elif line.startswith("fn="):
            fn = line[3:]
        elif line.startswith("cfn="):
            callee = line[4:]
        elif line.startswith("calls="):
            after_calls = True
    return cost


def fix_steps(exe: Path) -> tuple[list[Part], list[Part], int]:
    """Drive 1 under callgrind, each period that takes a fix dumped apart: the fix periods while
    the speed changes, those while it does not, the instructions over all steps."""
    out_file = BUILD / "callgrind.fix.out"
    toggles = [f"--toggle-collect={f}" for f in COLLECT]
    dumps = [
        f"--dump-{when}={fn}" for fn in (FIX_CHANGE, FIX_STEADY) for when in ("before", "after")
    ]
    plain = ["--combine-dumps=yes", "--compress-strings=no", "--compress-pos=no", "--dump-line=no"]
    cmd = ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out_file}", *plain]
    printed = run([*cmd, *toggles, *dumps, str(exe), str(DRIVE_STEPS), "3", "1"])
    m = re.match(r"steps (\d+) frames (\d+) fixes_change (\d+) lag_learned_ms (\d+)", printed)
    if m is None or int(m[1]) != DRIVE_STEPS:
        sys.exit(f"ecu_bench: unexpected driver output {printed!r}")
    # the learner must have worked: the receiver's 1.3 s, learned as ~1.2 s (docs/speed.md)
    if not 900 <= int(m[4]) <= 1600:
        sys.exit(
            f"ecu_bench: the GNSS lag was not learned in the launch-and-brake drive: {printed!r}"
        )
    dumped = parts(out_file.read_text())
    change = [p for p in dumped if p.trigger == f"--dump-after={FIX_CHANGE}"]
    steady = [p for p in dumped if p.trigger == f"--dump-after={FIX_STEADY}"]
    if len(change) != int(m[3]) or not steady:
        sys.exit(f"ecu_bench: {len(change)} fix periods dumped, the driver took {m[3]}")
    log(f"launch and brake, fused mode: {printed.strip()}")
    log(f"cruise at 8 km/h, a fix every 10 steps: {cruise_per_step(dumped)} instructions per step")
    between = sum(p.total for p in dumped if not p.trigger.startswith("--dump-after"))
    periods = DRIVE_STEPS - len(change) - len(steady)
    log(f"{periods} periods without a fix: {round(between / periods)} instructions on the mean")
    return change, steady, sum(p.total for p in dumped)


def cruise_per_step(dumped: list[Part]) -> int:
    """Every step in the cruises of drive 1 (6.1..11.9 s of each 20 s cycle), averaged: the steps
    up to and including the k-th fix (step 10 k) are the dumps before and after it."""
    fixes = [p for p in dumped if p.trigger.startswith("--dump-")]
    blocks = [a.total + b.total for a, b in zip(fixes[0::2], fixes[1::2], strict=True)]
    cruise = [c for k, c in enumerate(blocks) if 61 < k % 200 < 120]
    return round(sum(cruise) / (10 * len(cruise)))


def stats(name: str, fixes: list[Part]) -> tuple[int, int]:
    mean = round(sum(p.total for p in fixes) / len(fixes))
    worst = max(fixes, key=lambda p: p.total)
    learner = [p.learner for p in fixes]
    log(
        f"{len(fixes)} fix periods {name}: mean {mean}, max {worst.total} instructions "
        f"(the lag learner: mean {round(sum(learner) / len(learner))}, max {max(learner)}; "
        f"{worst.learner} in the worst period)"
    )
    return mean, worst.total


def cortex_m4_sizes() -> tuple[int, int, int]:
    elf = BUILD / "ecu_cm4.elf"
    src = [str(p) for p in [*CORE, REPO / "bench" / "ecu_cm4_main.c"]]
    link = ["-Wl,--gc-sections", "--specs=nosys.specs", "--specs=nano.specs", "-lm"]
    run(["arm-none-eabi-gcc", *CM4, *WARN, *INCLUDES, *src, *link, "-o", str(elf)])
    lines = run(["arm-none-eabi-size", str(elf)]).splitlines()
    text, data, bss = (int(x) for x in lines[1].split()[:3])
    symbols = run(["arm-none-eabi-nm", "-S", "--size-sort", str(elf)]).splitlines()
    app = next((int(s.split()[1], 16) for s in symbols if s.endswith(" app")), 0)
    log(f"cortex-m4 image: text {text}, data {data}, bss {bss} (td_app_t {app} bytes)")
    return text, data + bss, app


def main() -> int:
    ensure_tools()
    BUILD.mkdir(parents=True, exist_ok=True)
    exe = build_driver()
    ips = instructions_per_step(exe, 0)
    ips_fused = instructions_per_step(exe, 3)
    change, steady, drive_total = fix_steps(exe)
    fix_mean, fix_max = stats("while the speed changes", change)
    stats("otherwise (cruise, standing)", steady)
    text, ram, app = cortex_m4_sizes()
    print(f"instructions_per_step: {ips}")
    print(f"instructions_per_step_fused: {ips_fused}")
    figures = {
        "instructions_per_fix_step_mean": fix_mean,
        "instructions_per_fix_step_max": fix_max,
        "instructions_per_step_launch_brake": round(drive_total / DRIVE_STEPS),
        "cortex_m4_text_bytes": text,
        "cortex_m4_ram_bytes": ram,
        "td_app_t_bytes": app,
    }
    for name, value in figures.items():
        print(f"{name}: {value}")
    over = 0
    for name, limit in BUDGET.items():
        within = figures[name] <= limit
        over += not within
        print(f"budget {name}: {figures[name]} of {limit} ({'within' if within else 'OVER'})")
    return 1 if over else 0


if __name__ == "__main__":
    sys.exit(main())
