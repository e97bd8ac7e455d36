"""The display's processes keep off the first CPU, so the control loop finds it free."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

PROBE = """
import os, sys
from topdress.display.cpu import leave_first_cpu
os.sched_setaffinity(0, {int(c) for c in sys.argv[1].split(",")})
leave_first_cpu()
print(",".join(str(c) for c in sorted(os.sched_getaffinity(0))))
"""


def _after(cpus: set[int]) -> str:
    arg = ",".join(str(c) for c in sorted(cpus))
    out = subprocess.run([sys.executable, "-c", PROBE, arg], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def test_one_cpu_is_kept() -> None:
    only = min(os.sched_getaffinity(0))
    assert _after({only}) == str(only)


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="needs two CPUs")
def test_with_two_or_more_the_first_is_left_to_the_terminal() -> None:
    cpus = sorted(os.sched_getaffinity(0))
    assert _after(set(cpus)) == ",".join(str(c) for c in cpus[1:])
    assert _after({cpus[1]}) == str(cpus[1])  # a single CPU given: nowhere else to go


YIELD = """
import os
from topdress.display.cpu import yield_to_the_terminal
try:  # as the terminal under `chrt -r 10` would start it
    os.sched_setscheduler(0, os.SCHED_RR, os.sched_param(10))
except PermissionError:
    pass
before = os.sched_getscheduler(0)
nice = os.nice(0)
yield_to_the_terminal(10)
print(before, os.sched_getscheduler(0), os.nice(0) - nice, len(os.sched_getaffinity(0)))
"""


def test_the_display_drops_a_real_time_policy_it_inherited_and_its_priority() -> None:
    out = subprocess.run([sys.executable, "-c", YIELD], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    before, after, niced, cpus = (int(x) for x in out.stdout.split())
    # 10 lower, within the kernel's ceiling of 19 (a test run under `nice` starts at 10)
    assert after == os.SCHED_OTHER and niced == min(os.nice(0) + 10, 19) - os.nice(0)
    assert cpus == max(1, len(os.sched_getaffinity(0)) - 1)
    if before != os.SCHED_RR:
        pytest.skip("not allowed to set a real-time policy here: only the nice part checked")
