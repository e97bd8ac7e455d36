"""SIGKILL durability: a writer killed at random moments never corrupts its file and loses
at most the last second. Run as a script, this file is the writer."""

from __future__ import annotations

import os
import random
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from topdress.log.model import StateRow
from topdress.log.session import SessionLog

KILLS = 20
LOSS_BOUND_S = 1.0


def writer(directory: str) -> None:
    """Log ~1000 NMEA lines/s and 10 state rows/s; print `seq` after handing row `seq` over."""
    log = SessionLog.create(directory, "[log]\n")
    seq = 0
    while True:
        t = time.monotonic()
        log.raw("nmea", t, f"$GPTXT,{seq}")
        if seq % 100 == 0:
            log.state(StateRow(t, None, None, None, 0.0, 0.0, "wheel", None, None, *[0.0] * 8, seq))
        if seq % 50 == 0:
            print(seq, flush=True)
        seq += 1
        time.sleep(0.001)


def run_and_kill(directory: Path, after_s: float) -> tuple[list[tuple[float, int]], float]:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    proc = subprocess.Popen(
        [sys.executable, __file__, str(directory)], stdout=subprocess.PIPE, text=True, env=env
    )
    assert proc.stdout is not None
    markers: list[tuple[float, int]] = []
    first = threading.Event()

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            markers.append((time.monotonic(), int(line)))
            first.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    assert first.wait(30), "writer did not start"
    time.sleep(after_s)
    killed_at = time.monotonic()
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    reader.join(5)
    return markers, killed_at


@pytest.mark.wallclock
def test_sigkill_never_corrupts_and_loses_at_most_one_second(tmp_path: Path) -> None:
    rng = random.Random(20)
    checked = 0
    for kill in range(KILLS):
        directory = tmp_path / f"run{kill}"
        markers, killed_at = run_and_kill(directory, rng.uniform(0.0, 2.0))
        (path,) = directory.glob("*.sqlite")
        conn = sqlite3.connect(path)
        assert conn.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        lines = [r[0] for r in conn.execute("SELECT line FROM raw ORDER BY id")]
        seqs = [int(line.split(",")[1]) for line in lines]
        # Whole batches only: the rows present are exactly 0..n-1, no holes.
        assert seqs == list(range(len(seqs)))
        states = [r[0] for r in conn.execute("SELECT faults FROM state ORDER BY id")]
        assert states == list(range(0, 100 * len(states), 100))
        assert all(s < len(seqs) for s in states)
        conn.close()
        old = [seq for t, seq in markers if t <= killed_at - LOSS_BOUND_S]
        if old:
            assert len(seqs) > max(old), f"kill {kill}: row {max(old)} lost"
            checked += 1
    assert checked >= KILLS // 3  # enough kills came late enough to test the bound


if __name__ == "__main__":
    writer(sys.argv[1])
