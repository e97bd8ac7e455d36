"""Where and how the display's processes run on the cab PC's CPUs: below the terminal.

The terminal's control loop must win the CPU whenever it wakes (docs/display.md): it may run
with a real-time policy (`chrt -r 10`, or systemd's `CPUSchedulingPolicy=rr`), which the
processes it starts would inherit, so the display and the kiosk browser drop back to the
normal policy, a lower priority (nice) and the CPUs other than the first.
"""

from __future__ import annotations

import os


def leave_first_cpu() -> None:
    """Keep this process (and what it starts) off the first CPU when there are two or more,
    so the terminal's control loop finds that one free when it wakes."""
    cpus = os.sched_getaffinity(0)
    if len(cpus) >= 2:
        os.sched_setaffinity(0, cpus - {min(cpus)})


def yield_to_the_terminal(niceness: int) -> None:
    """This process (and what it starts) below the terminal: the normal scheduling policy
    (not a real-time one inherited from the terminal), `niceness` more, off the first CPU."""
    if os.sched_getscheduler(0) != os.SCHED_OTHER:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    os.nice(niceness)
    leave_first_cpu()
