"""Line sources: splitting, cutting, real pseudo-terminals (with a port that vanishes and comes
back), files, and the simulated twin's fault knobs."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from topdress.config import CropConfig, GnssConfig
from topdress.devices.lines import (
    FakeLineSource,
    FileLineSource,
    LineSplitter,
    SerialLineSource,
    StdinLineSource,
    open_line_source,
)
from topdress.errors import DeviceError
from topdress.gnss.nmea import NmeaDecoder, make_sentence

RMC = make_sentence("GPRMC,081836.00,A,4304.5678,N,12534.1234,E,3.24,87.5,210526,,,A")


class Collector:
    def __init__(self) -> None:
        self.lines: list[bytes] = []
        self.times: list[float] = []
        self.changed = threading.Condition()

    def __call__(self, t: float, line: bytes) -> None:
        with self.changed:
            self.times.append(t)
            self.lines.append(line)
            self.changed.notify_all()

    def wait_for(self, n: int, timeout: float = 5.0) -> None:
        with self.changed:
            assert self.changed.wait_for(lambda: len(self.lines) >= n, timeout), self.lines


def wait_until(cond: Callable[[], bool], timeout: float = 5.0) -> None:
    deadline = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < deadline, "condition not reached"
        time.sleep(0.01)


def test_splitter_handles_crlf_lf_and_cr_and_chunks() -> None:
    s = LineSplitter()
    assert s.feed(b"$GPA*00\r\n$GPB") == [b"$GPA*00"]
    assert s.feed(b"*11\n$GPC*22\r$GPD*33\r\n\r\n") == [b"$GPB*11", b"$GPC*22", b"$GPD*33"]
    assert s.counters["lines"] == 4
    assert s.flush() == []


def test_splitter_cuts_overlong_lines_and_counts_them() -> None:
    s = LineSplitter(max_line=10)
    lines = s.feed(b"0123456789ABCDEF\r\nshort\r\n")
    assert lines == [b"0123456789", b"short"]  # the rest of the long line is discarded
    assert s.counters["overlong"] == 1
    assert s.counters["lines"] == 1


def test_splitter_flushes_a_partial_line() -> None:
    s = LineSplitter()
    assert s.feed(b"$GPRMC,0818") == []
    assert s.flush() == [b"$GPRMC,0818"]
    assert s.counters["partial"] == 1


def test_serial_source_reads_a_pseudo_terminal() -> None:
    master, slave = os.openpty()
    got = Collector()
    src = SerialLineSource(os.ttyname(slave), 9600)
    src.start(got)
    try:
        wait_until(lambda: src.connected)
        os.write(master, RMC + b"garbage\xff\xfe\r\n" + RMC[:20])
        os.write(master, RMC[20:])
        got.wait_for(3)
        assert got.lines == [RMC.rstrip(), b"garbage\xff\xfe", RMC.rstrip()]
        assert got.times == sorted(got.times)
    finally:
        src.stop()
        os.close(master)
        os.close(slave)


def test_serial_port_that_vanishes_is_reopened_with_backoff(tmp_path: Path) -> None:
    link = tmp_path / "ttyGNSS"
    master, slave = os.openpty()
    link.symlink_to(os.ttyname(slave))
    got = Collector()
    src = SerialLineSource(str(link), 9600, backoff_s=0.02, backoff_max_s=0.1)
    src.start(got)
    try:
        wait_until(lambda: src.connected)
        os.write(master, RMC + RMC[:15])
        got.wait_for(1)
        # The device goes away: the port errors, the partial line is still delivered.
        os.close(master)
        os.close(slave)
        link.unlink()
        wait_until(lambda: not src.connected)
        got.wait_for(2)
        assert got.lines[1] == RMC[:15]
        assert src.counters["partial"] == 1
        wait_until(lambda: src.counters["open_failures"] >= 2)  # retrying while absent
        # It comes back under the same name.
        master, slave = os.openpty()
        link.symlink_to(os.ttyname(slave))
        wait_until(lambda: src.connected)
        os.write(master, RMC)
        got.wait_for(3)
        assert got.lines[2] == RMC.rstrip()
        assert src.counters["opens"] == 2
        assert src.counters["disconnects"] == 1
    finally:
        src.stop()
        os.close(master)
        os.close(slave)
    assert not src.connected


def test_missing_port_reports_not_connected() -> None:
    src = SerialLineSource("/dev/does-not-exist-topdress", 9600, backoff_s=0.01)
    src.start(Collector())
    try:
        wait_until(lambda: src.counters["open_failures"] >= 2)
        assert not src.connected
    finally:
        src.stop()


def test_file_source_delivers_every_line_then_ends(tmp_path: Path) -> None:
    path = tmp_path / "capture.nmea"
    path.write_bytes(RMC * 3 + b"x" * 300 + b"\r\n" + b"$GPGGA,tail")
    got = Collector()
    src = FileLineSource(path)
    src.start(got)
    assert src.finished.wait(5.0)
    src.stop()
    assert got.lines[:3] == [RMC.rstrip()] * 3
    assert got.lines[3] == b"x" * 256
    assert got.lines[4] == b"$GPGGA,tail"
    assert len(got.lines) == 5
    assert src.counters["overlong"] == 1
    assert src.counters["partial"] == 1
    assert not src.connected and src.last_error == "end of the input"  # why GNSS is "lost"


def test_missing_file_is_a_device_error(tmp_path: Path) -> None:
    with pytest.raises(DeviceError):
        FileLineSource(tmp_path / "absent.nmea")
    with pytest.raises(DeviceError):
        open_line_source(GnssConfig(source="file", path=str(tmp_path / "absent.nmea")))
    with pytest.raises(DeviceError):
        open_line_source(GnssConfig(source="tcp"))


def test_open_line_source_follows_the_config(tmp_path: Path) -> None:
    path = tmp_path / "crop.txt"
    path.write_bytes(b"1,0.0412,0.2104,0.4419,0.3541,0.8295\r\n")
    src = open_line_source(CropConfig(source="file", path=str(path), replay_interval_s=0.0))
    assert isinstance(src, FileLineSource)
    got = Collector()
    src.start(got)
    assert src.finished.wait(5.0)
    src.stop()
    assert got.lines == [b"1,0.0412,0.2104,0.4419,0.3541,0.8295"]
    serial_src = open_line_source(GnssConfig(port="/dev/ttyS9", baud=4800))
    assert isinstance(serial_src, SerialLineSource)
    assert (serial_src.port, serial_src.baud) == ("/dev/ttyS9", 4800)
    assert isinstance(open_line_source(GnssConfig(source="stdin")), StdinLineSource)


def test_fake_source_fault_knobs_and_decoder_counts() -> None:
    got = Collector()
    fake = FakeLineSource(drop=0.1, corrupt=0.2, seed=7)
    fake.start(got)
    fake.emit_all(0.0, 0.1, [RMC] * 1000)
    fake.disconnect()
    fake.emit(100.0, RMC)
    assert not fake.connected
    fake.reconnect()
    fake.emit(100.1, RMC)
    c = fake.counters
    assert c["dropped"] + c["lines"] + c["lost_disconnected"] == 1002
    assert 60 < c["dropped"] < 140
    assert 140 < c["corrupted"] < 260
    assert c["lost_disconnected"] == 1
    decoder = NmeaDecoder()
    fixes = [decoder.decode(line) for line in got.lines]
    # Every corrupted line is rejected, every clean one accepted.
    assert sum(not f.ok for f in fixes) == c["corrupted"]
    assert decoder.counters["ok"] == c["lines"] - c["corrupted"]
