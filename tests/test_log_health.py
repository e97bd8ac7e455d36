"""The session log on a full disk: its health for the control loop, a clean close with the
reserve, the failure recorded in the file for `log summary`, nothing left behind."""

from __future__ import annotations

import errno
import os
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from session_rig import CONFIG, fill
from topdress.cli.main import main
from topdress.log.session import RESERVE_BYTES, LogHealth, SessionLog, SessionReader
from topdress.terminal.counters import atomic_write

RMC = "$GPRMC,123519,A,4807.038,N,01131.000,E,3.78,084.4,230394,003.1,W*6E" + "," * 200


@pytest.fixture
def small_disk(tmp_path: Path) -> Iterator[Path]:
    """A 1 MiB filesystem (tmpfs, mounted for the test; needs root)."""
    where = tmp_path / "disk"
    where.mkdir()
    mount = ["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(where)]
    if os.geteuid() != 0 or subprocess.run(mount, capture_output=True).returncode != 0:
        pytest.skip("mounting a small tmpfs needs root")
    try:
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], check=False)


def _until(cond: object, timeout_s: float = 5.0) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if cond():  # type: ignore[operator]
            return True
        time.sleep(0.01)
    return False


def test_a_full_disk_is_reported_closed_cleanly_and_told_from_a_power_cut(
    small_disk: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = SessionLog.create(small_disk, CONFIG, commit_period_s=0.05, min_free_bytes=200_000)
    assert log.health == LogHealth.OK and (small_disk / f".{log.path.name}.reserve").exists()
    filler = small_disk / "other-program.bin"
    with filler.open("wb") as f, pytest.raises(OSError):  # another program fills the disk
        while True:
            f.write(b"\0" * 65536)
            f.flush()
    for i in range(2000):
        log.raw("nmea", float(i), RMC)
        if i % 100 == 0:
            log.sync()
    assert _until(lambda: log.health == LogHealth.DISK_FULL)
    assert log.lost > 0 and "full" in (log.last_error or "")
    log.close()
    with SessionReader(log.path) as reader:
        assert "closed_utc" in reader.meta  # the close found room: the reserve
        assert '"kind":"disk_full"' in reader.meta["write_failed"]
        assert int(reader.meta["lost"]) == log.lost
    assert main(["log", "summary", str(log.path)]) == 0
    text = capsys.readouterr().out
    assert "disk full" in text and "power cut" not in text
    # nothing left behind but the session (and the filler): no reserve, no temporary file;
    # the checkpoint found no room, so the closed session's -wal (and -shm) stay beside it
    left = {p.name for p in small_disk.iterdir()} - {filler.name}
    assert left <= {log.path.name + c for c in ("", "-wal", "-shm")}


def test_low_free_space_is_reported_and_freeing_space_resumes_writing(small_disk: Path) -> None:
    log = SessionLog.create(small_disk, CONFIG, commit_period_s=0.05, min_free_bytes=300_000)
    filler = small_disk / "filler.bin"
    filler.write_bytes(b"\0" * 600_000)
    log.raw("nmea", 0.0, RMC)
    log.sync()
    assert log.health == LogHealth.LOW_SPACE and log.ok  # still writing: a warning
    assert log.free_bytes is not None and log.free_bytes < 300_000
    filler.unlink()
    log.raw("nmea", 1.0, RMC)
    log.sync()
    assert log.health == LogHealth.OK
    log.close()


def test_a_capped_log_closes_cleanly_and_records_the_failure(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Before: the counters could not be written at close, and the summary blamed a power cut.
    log = SessionLog.create(tmp_path, CONFIG, max_bytes=96 * 1024, commit_period_s=0.05)
    fill(log, seconds=60.0)
    log.sync()
    assert log.health == LogHealth.DISK_FULL and log.lost > 0
    log.close()
    assert main(["log", "summary", str(log.path)]) == 0
    text = capsys.readouterr().out
    assert "disk full" in text and "power cut" not in text
    assert f"lost {log.lost}" in text


def test_a_row_that_squeezes_into_a_full_log_does_not_end_the_alarm(tmp_path: Path) -> None:
    # Before: one small batch fitting into the rolled-back pages set the health back to OK,
    # so the disk-full alarm blinked off while the log was still at its cap.
    log = SessionLog.create(tmp_path, CONFIG, max_bytes=96 * 1024, commit_period_s=0.05)
    line = RMC + "," * 300
    i = 0
    while not log.lost:
        for _ in range(200):
            log.raw("nmea", float(i), line)
            i += 1
        log.sync()
    assert log.health == LogHealth.DISK_FULL and not log.ok
    with SessionReader(log.path) as reader:
        before = reader.count("raw")
    log.raw("nmea", float(i), RMC)  # one short row: it fits
    log.sync()
    with SessionReader(log.path) as reader:
        assert reader.count("raw") == before + 1
    assert log.health == LogHealth.DISK_FULL and not log.ok
    assert log.free_bytes is not None and log.free_bytes < log.min_free_bytes
    log.close()


def test_a_write_error_that_is_not_a_full_disk_is_write_failing(tmp_path: Path) -> None:
    log = SessionLog.create(tmp_path, CONFIG, commit_period_s=0.05)
    log.raw("nmea", 0.0, RMC)
    log.sync()
    assert log.health == LogHealth.OK
    assert log._conn is not None
    log._conn.execute("PRAGMA query_only = ON")  # every write now fails, not for space
    log.raw("nmea", 1.0, RMC)
    log.sync()
    assert log.health == LogHealth.WRITE_FAILING and not log.ok
    log._conn.execute("PRAGMA query_only = OFF")
    log.raw("nmea", 2.0, RMC)
    log.sync()
    assert log.health == LogHealth.OK and log.ok
    log.close()


def test_a_reserve_left_by_a_killed_session_is_removed_a_running_ones_kept(
    tmp_path: Path,
) -> None:
    stale = tmp_path / ".session-20260101T000000Z.sqlite.reserve"
    stale.write_bytes(b"\0" * RESERVE_BYTES)
    running = SessionLog.create(tmp_path, CONFIG, name="running")
    other = SessionLog.create(tmp_path, CONFIG, name="other")
    assert not stale.exists()
    assert (tmp_path / ".running.sqlite.reserve").exists()  # its lock is held
    running.close()
    other.close()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["other.sqlite", "running.sqlite"]


def test_counters_that_cannot_be_written_leave_no_temporary_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A full disk left a 0-byte .counters.json.tmp beside the sessions.
    def full(fd: int) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(OSError):
        atomic_write(tmp_path / "counters.json", "{}\n")
    assert list(tmp_path.iterdir()) == []
