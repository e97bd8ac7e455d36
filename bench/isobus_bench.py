"""ISOBUS layer benchmark (`make bench`): its footprint on a Cortex-M4 and its time per 10 ms
period on the host under 30 % bus load.

Prints:
    isobus_cm4_text_bytes: N     arm-none-eabi-gcc -Os -mcpu=cortex-m4 of ecu/isobus/src + DDOP
    isobus_cm4_ddop_bytes: N     of which the generated DDOP
    isobus_cm4_state_bytes: N    sizeof(td_isob_t) on the Cortex-M4 (static RAM of the node)
    isobus_host_state_bytes: N
    isobus_host_period_mean_us / _p99_us / _max_us: X   receive + step + drain per 10 ms period
    isobus_step_host_{idle,load30}_{mean,sd,p99,max}_us: X   the control step with the node
        beside it (bench/isobus_step_main.c: receive, the TC's command, td_app_step, the core's
        frames on Proprietary A/B, the node's step), without traffic and at 30 % bus load
    isobus_step_qemu_{idle,load30}_{mean,sd,p99,max}_us: X   the same step of the FW_ISOBUS
        emulator image in lockstep with the simulated machine and the terminal's TC
        (HilStepCost on the emulated chip's clock, QEMU -icount shift=3: 8 ns an instruction;
        the step and the time its received frames took, not the wait for the link's bytes),
        without extra traffic and with the link at 30 % of a 250 kbit/s bus
    isobus_step_qemu_load30_frames_per_s: X   the frames both ways on the link in that run
The step interval in lockstep is the simulator's 10 ms by construction (fw_bench.py); the
image's flash, RAM and worst stack are fw_bench.py's fw_isobus_* and fw_qemu_isobus_*.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SRC = [*sorted((REPO / "ecu/isobus/src").glob("*.c")), REPO / "ecu/isobus/src/gen/td_ddop_gen.c"]
INC = ["-I", str(REPO / "ecu/isobus/include"), "-I", str(REPO / "ecu/isobus/src/gen"),
       "-I", str(REPO / "ecu/include")]  # fmt: skip
CM4 = ["-std=c99", "-Os", "-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16"]


def cm4(tmp: Path) -> None:
    gcc = shutil.which("arm-none-eabi-gcc")
    if gcc is None:
        print("isobus_cm4: arm-none-eabi-gcc missing (make firmware installs it)")
        return
    objs = []
    for c in SRC:
        o = tmp / (c.stem + ".o")
        subprocess.run([gcc, *CM4, *INC, "-c", str(c), "-o", str(o)], check=True)
        objs.append(o)
    sizes = subprocess.run(["arm-none-eabi-size", *map(str, objs)], check=True,
                           capture_output=True, text=True).stdout.splitlines()[1:]  # fmt: skip
    text = {Path(line.split()[-1]).stem: int(line.split()[0]) for line in sizes}
    probe = tmp / "sz.c"
    probe.write_text('#include "td_isob.h"\nunsigned long s = sizeof(td_isob_t);\n')
    asm = subprocess.run([gcc, *CM4, *INC, "-S", str(probe), "-o", "-"], check=True,
                         capture_output=True, text=True).stdout  # fmt: skip
    state = re.search(r"^s:\s*\n\s*\.word\s+(\d+)", asm, re.M)
    print(f"isobus_cm4_text_bytes: {sum(text.values())}")
    print(f"isobus_cm4_ddop_bytes: {text['td_ddop_gen']}")
    print(f"isobus_cm4_state_bytes: {state.group(1) if state else '?'}")


def host(tmp: Path) -> None:
    exe = tmp / "isobus_bench"
    subprocess.run(["cc", "-std=c99", "-O2", *INC, str(REPO / "bench/isobus_main.c"),
                    *map(str, SRC), "-o", str(exe)], check=True)  # fmt: skip
    print(subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout, end="")


def host_step(tmp: Path) -> None:
    exe = tmp / "isobus_step_bench"
    core = [*sorted((REPO / "ecu/src").glob("*.c")), REPO / "ecu/src/gen/td_can.c"]
    subprocess.run(["cc", "-std=c99", "-O2", *INC, "-I", str(REPO / "ecu/src/gen"),
                    str(REPO / "bench/isobus_step_main.c"), *map(str, SRC), *map(str, core),
                    "-lm", "-o", str(exe)], check=True)  # fmt: skip
    print(subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout, end="")


BUS_FRAMES_PER_S = 250_000 / 135  # 29-bit identifier, 8 bytes, stuffing: ~135 bits a frame


def qemu_step(load: bool, seconds: float = 20.0) -> dict[str, float] | None:
    """The FW_ISOBUS emulator image in lockstep with the machine and the terminal's TC; with
    `load`, other nodes' broadcasts and the TC's set values fill the link to 30 % of a bus."""
    from topdress.isobus.node import Frame, to_bus
    from topdress.protocol.frames import encode_gnss_time
    from topdress.sim.qemu_ecu import QemuEcu, QemuOptions, QemuWorld, qemu_missing
    from topdress.sim.tc import MiniTc
    from topdress.sim.tractor import Drive

    why = qemu_missing()
    if why is not None:
        print(f"isobus_bench: no qemu figures: {why}", file=sys.stderr)
        return None
    out = REPO / "build" / "fw-qemu-isobus"
    subprocess.run(["make", "--no-print-directory", "-s", "-f", "ecu/ports/stm32f4/firmware.mk",
                    "FW_ISOBUS=1", "VARIANT=qemu", f"OUT={out}"], cwd=REPO, check=True,
                   capture_output=True)  # fmt: skip
    tc = MiniTc()
    frames_seen, steps, acc = 0, 0, 0.0
    target = 0.30 * BUS_FRAMES_PER_S * 0.01  # frames a 10 ms step at 30 % load
    with QemuEcu(QemuOptions(image=out / "topdress-ecu-stm32f4.elf", icount_shift=3)) as ecu:
        world = QemuWorld(ecu, seed=3, drive=Drive.paper_run(7.0, hold_m=400.0, wait_s=3.0))
        pending: list[Frame] = []
        set_at = None
        while world.t_s < seconds:
            steps += 1
            sa = tc.server.address
            if steps % 10 == 0 and sa is not None:
                g = encode_gnss_time(world.truth.v_kmh, 0, steps // 10)
                bus = to_bus(Frame(g.arbitration_id, bytes(g.data)), False, sa)
                pending.append(bus) if bus is not None else None
            if tc.activated and set_at is None:
                set_at = world.t_s
                for element, ddi, value in ((2, 160, 1), (2, 289, 1), (3, 6, 15000),
                                            (4, 6, 10000), (2, 290, -4096 + 0x555)):  # fmt: skip
                    tc.command(element, ddi, value)
            if load and set_at is not None:
                acc += target
                while acc >= len(pending) + 1.0:  # other nodes' broadcasts up to 30 %
                    pending.append(Frame(0x18FEF120 + steps % 4, bytes(8)))
                acc -= len(pending)
            for f in pending:
                world.link.send((f.can_id, f.data))
            heard = [Frame(i, d) for i, d in world.step().can]
            if set_at is not None:
                frames_seen += len(heard) + len(pending)
            pending = tc.step(world.now_us, heard)
        costs = world.timing.costs_us[-round((seconds - (set_at or 0.0)) / 0.01) + 50 :]
        rate = (world.metered_kg(0), world.truth.meter_rpm[0])
    print(
        f"isobus_bench: qemu {'load' if load else 'idle'}: TC set at {set_at} s, meter "
        f"{rate[1]:.1f} rpm, {len(costs)} steps measured",
        file=sys.stderr,
    )
    if not costs:
        return None
    mean = sum(costs) / len(costs)
    s = sorted(costs)
    return {
        "mean_us": mean,
        "sd_us": (sum((c - mean) ** 2 for c in costs) / len(costs)) ** 0.5,
        "p99_us": float(s[min(len(s) - 1, round(0.99 * len(s)))]),
        "max_us": float(s[-1]),
        "frames_per_s": frames_seen / max(0.01, seconds - (set_at or 0.0)),
    }


def main() -> None:
    with tempfile.TemporaryDirectory() as d:
        cm4(Path(d))
        host(Path(d))
        host_step(Path(d))
    for load, name in ((False, "idle"), (True, "load30")):
        q = qemu_step(load)
        if q is None:
            continue
        for key in ("mean", "sd", "p99", "max"):
            print(f"isobus_step_qemu_{name}_{key}_us: {q[key + '_us']:.1f}")
        if load:
            print(f"isobus_step_qemu_load30_frames_per_s: {q['frames_per_s']:.0f}")


if __name__ == "__main__":
    main()
