"""Where the display's processes run on the cab PC's CPUs."""

from __future__ import annotations

import os


def leave_first_cpu() -> None:
    """Keep this process (and what it starts) off the first CPU when there are two or more,
    so the terminal's control loop finds that one free when it wakes (docs/display.md)."""
    cpus = os.sched_getaffinity(0)
    if len(cpus) >= 2:
        os.sched_setaffinity(0, cpus - {min(cpus)})
