"""ISOBUS layer benchmark (`make bench`): its footprint on a Cortex-M4 and its time per 10 ms
period on the host under 30 % bus load.

Prints:
    isobus_cm4_text_bytes: N     arm-none-eabi-gcc -Os -mcpu=cortex-m4 of ecu/isobus/src + DDOP
    isobus_cm4_ddop_bytes: N     of which the generated DDOP
    isobus_cm4_state_bytes: N    sizeof(td_isob_t) on the Cortex-M4 (static RAM of the node)
    isobus_host_state_bytes: N
    isobus_host_period_mean_us / _p99_us / _max_us: X   receive + step + drain per 10 ms period
The node is not in the firmware image yet, so there is no flash/RAM/stack figure of the image.
"""

from __future__ import annotations

import re
import shutil
import subprocess
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


def main() -> None:
    with tempfile.TemporaryDirectory() as d:
        cm4(Path(d))
        host(Path(d))


if __name__ == "__main__":
    main()
