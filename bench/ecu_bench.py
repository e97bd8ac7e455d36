"""ECU core benchmark (`make bench`): instructions per control step, and the Cortex-M4 footprint.

Prints exactly:
    instructions_per_step: N   callgrind, collecting only inside td_app_step, td_app_rx and
                               td_app_tx_pop, over 20,000 steps of bench/ecu_bench_main.c
                               (both motors running, command and GNSS time in every 500 ms, wheel
                               edge times, status drained), default speed mode
    instructions_per_step_fused: N   the same in the fused speed mode
    cortex_m4_text_bytes: N    text of a linked Cortex-M4 image (bench/ecu_cm4_main.c + the core +
    cortex_m4_ram_bytes: N     what it needs of newlib-nano/libgcc; --gc-sections, nosys specs),
                               data + bss including the one static td_app_t a port owns
Details go to stderr. Missing tools are installed with apt-get (as root).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
BUILD = REPO / "build" / "bench"
STEPS = 20_000
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


def instructions_per_step(speed_mode: int) -> int:
    exe = BUILD / "ecu_bench"
    src = [str(p) for p in [*CORE, REPO / "bench" / "ecu_bench_main.c"]]
    run(["gcc", *WARN, "-O2", *INCLUDES, *src, "-lm", "-o", str(exe)])
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


def cortex_m4_sizes() -> tuple[int, int]:
    elf = BUILD / "ecu_cm4.elf"
    src = [str(p) for p in [*CORE, REPO / "bench" / "ecu_cm4_main.c"]]
    link = ["-Wl,--gc-sections", "--specs=nosys.specs", "--specs=nano.specs", "-lm"]
    run(["arm-none-eabi-gcc", *CM4, *WARN, *INCLUDES, *src, *link, "-o", str(elf)])
    lines = run(["arm-none-eabi-size", str(elf)]).splitlines()
    text, data, bss = (int(x) for x in lines[1].split()[:3])
    symbols = run(["arm-none-eabi-nm", "-S", "--size-sort", str(elf)]).splitlines()
    app = next((int(s.split()[1], 16) for s in symbols if s.endswith(" app")), 0)
    log(f"cortex-m4 image: text {text}, data {data}, bss {bss} (td_app_t {app} bytes)")
    return text, data + bss


def main() -> int:
    ensure_tools()
    BUILD.mkdir(parents=True, exist_ok=True)
    ips = instructions_per_step(0)
    ips_fused = instructions_per_step(3)
    text, ram = cortex_m4_sizes()
    print(f"instructions_per_step: {ips}")
    print(f"instructions_per_step_fused: {ips_fused}")
    print(f"cortex_m4_text_bytes: {text}")
    print(f"cortex_m4_ram_bytes: {ram}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
