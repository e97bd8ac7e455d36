"""Line sources: where NMEA and crop sensor lines come from, behind one interface.

Every source delivers complete lines (terminator removed; CR, LF or CRLF) to a sink
`sink(t_monotonic, line)` from its own reader thread, so the control loop never blocks on I/O.
Nothing is dropped silently: an overlong line is cut at `max_line` bytes and delivered, a
partial line left when a port vanishes is delivered, and both are counted in `counters`.
"""

from __future__ import annotations

import contextlib
import random
import re
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import BinaryIO, Protocol

import serial

from topdress.config import CropConfig, GnssConfig
from topdress.errors import DeviceError

Sink = Callable[[float, bytes], None]
Clock = Callable[[], float]
MAX_LINE = 256
_EOL = re.compile(rb"[\r\n]+")  # CR, LF or CRLF; the empty lines between them are skipped


class LineSource(Protocol):
    """What the terminal needs of any line source."""

    counters: Counter[str]
    name: str  # for the operator: "serial:/dev/ttyUSB0", "file:...", "stdin"
    last_error: str | None  # why the device was last lost or could not be opened

    @property
    def connected(self) -> bool: ...

    def start(self, sink: Sink) -> None: ...

    def stop(self) -> None: ...


class LineSplitter:
    """Splits a byte stream into lines; counts 'lines', 'overlong' (cut) and 'partial'."""

    def __init__(self, max_line: int = MAX_LINE) -> None:
        self.max_line = max_line
        self.counters: Counter[str] = Counter()
        self._buf = bytearray()
        self._cutting = False  # inside the remainder of a line already cut

    def feed(self, data: bytes) -> list[bytes]:
        lines: list[bytes] = []
        # Runs between terminators, not bytes: a Python step per byte was most of a reader
        # thread's time. Only the last piece is unterminated.
        pieces = _EOL.split(data)
        last = len(pieces) - 1
        for i, piece in enumerate(pieces):
            if piece and not self._cutting:
                room = self.max_line - len(self._buf)
                if len(piece) < room:
                    self._buf += piece
                else:
                    self._buf += piece[:room]
                    lines.append(self._take("overlong"))
                    self._cutting = True
            if i < last:
                if self._buf:
                    lines.append(self._take("lines"))
                self._cutting = False
        return lines

    def flush(self) -> list[bytes]:
        """The partial line held, if any (end of stream or a vanished port)."""
        self._cutting = False
        return [self._take("partial")] if self._buf else []

    def _take(self, counter: str) -> bytes:
        self.counters[counter] += 1
        line = bytes(self._buf)
        self._buf.clear()
        return line


class _ThreadedSource:
    """Common reader-thread plumbing of the real sources."""

    def __init__(self, name: str, max_line: int, clock: Clock) -> None:
        self.name = name
        self.clock = clock
        self.splitter = LineSplitter(max_line)
        self.counters = self.splitter.counters
        self.last_error: str | None = None
        self._connected = False
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._sink: Sink | None = None

    @property
    def connected(self) -> bool:
        return self._connected

    def start(self, sink: Sink) -> None:
        if self._thread is not None:
            raise DeviceError(f"{self.name}: already started")
        self._sink = sink
        self._thread = threading.Thread(target=self._run, name=self.name, daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)

    def _deliver(self, lines: list[bytes]) -> None:
        assert self._sink is not None
        for line in lines:
            self._sink(self.clock(), line)

    def _run(self) -> None:
        raise NotImplementedError


class SerialLineSource(_ThreadedSource):
    """A serial port (pyserial). A port that cannot be opened or vanishes is reopened with
    exponential backoff (`backoff_s` doubling up to `backoff_max_s`) while `connected` is False,
    so the controller treats the device as lost meanwhile."""

    def __init__(
        self,
        port: str,
        baud: int,
        max_line: int = MAX_LINE,
        backoff_s: float = 0.1,
        backoff_max_s: float = 5.0,
        clock: Clock = time.monotonic,
    ) -> None:
        super().__init__(f"serial:{port}", max_line, clock)
        self.port = port
        self.baud = baud
        self.backoff_s = backoff_s
        self.backoff_max_s = backoff_max_s
        self._port: serial.Serial | None = None  # while the reader reads it
        self._port_lock = threading.Lock()

    def stop(self) -> None:
        self._stop.set()
        # The reader blocks in read() with no timeout (no wake-ups while the line is quiet):
        # this wakes it; a cancel that comes before the read makes that read return. Under the
        # lock, so the port is not closed meanwhile.
        with self._port_lock:
            if self._port is not None:
                with contextlib.suppress(OSError):
                    self._port.cancel_read()
        super().stop()

    def _run(self) -> None:
        delay = self.backoff_s
        while not self._stop.is_set():
            try:
                with serial.Serial(self.port, self.baud, timeout=None) as port:
                    self._connected = True
                    self.counters["opens"] += 1
                    delay = self.backoff_s
                    self._read(port)
            except (serial.SerialException, OSError) as exc:
                self.counters["open_failures" if not self._connected else "disconnects"] += 1
                self.last_error = str(exc)
            self._connected = False
            self._deliver(self.splitter.flush())
            if self._stop.wait(delay):
                break
            delay = min(delay * 2.0, self.backoff_max_s)

    def _read(self, port: serial.Serial) -> None:
        with self._port_lock:
            self._port = port
        try:
            while not self._stop.is_set():
                data = port.read(max(1, port.in_waiting))
                if data:
                    self._deliver(self.splitter.feed(data))
        finally:
            with self._port_lock:
                self._port = None


class StreamLineSource(_ThreadedSource):
    """Lines from a binary stream, optionally paced `interval_s` apart (replay of a capture).
    At the end of the stream `connected` turns False and `finished` is set."""

    def __init__(
        self,
        stream: BinaryIO,
        name: str,
        interval_s: float = 0.0,
        max_line: int = MAX_LINE,
        clock: Clock = time.monotonic,
    ) -> None:
        super().__init__(name, max_line, clock)
        self.stream = stream
        self.interval_s = interval_s
        self.finished = threading.Event()
        self._connected = True

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                data = self.stream.readline(self.splitter.max_line)
                if not data:
                    break
                for line in self.splitter.feed(data):
                    self._deliver([line])
                    if self.interval_s and self._stop.wait(self.interval_s):
                        return
            self._deliver(self.splitter.flush())
        except OSError as exc:
            self.counters["read_errors"] += 1
            self.last_error = str(exc)
        finally:
            self.last_error = self.last_error or "end of the input"
            self._connected = False
            self.finished.set()


class FileLineSource(StreamLineSource):
    def __init__(self, path: str | Path, interval_s: float = 0.0, max_line: int = MAX_LINE) -> None:
        try:
            stream = open(path, "rb")  # noqa: SIM115 - closed by stop()
        except OSError as exc:
            raise DeviceError(f"cannot open {path}: {exc}") from exc
        super().__init__(stream, f"file:{path}", interval_s, max_line)

    def stop(self) -> None:
        super().stop()
        self.stream.close()


class StdinLineSource(StreamLineSource):
    def __init__(self, max_line: int = MAX_LINE) -> None:
        super().__init__(sys.stdin.buffer, "stdin", 0.0, max_line)


class FakeLineSource:
    """Simulated twin of a line source, driven by the caller in virtual time.

    `emit(t, line)` delivers at once unless a fault knob says otherwise: `drop` (probability a
    line is lost on the wire), `corrupt` (probability one byte is altered), and `disconnect()` /
    `reconnect()`; lines emitted while disconnected are lost like on a pulled cable. The faults
    are counted in `counters` ('dropped', 'corrupted', 'lost_disconnected') for the test to check.
    """

    def __init__(self, drop: float = 0.0, corrupt: float = 0.0, seed: int = 0) -> None:
        self.name = "fake"
        self.last_error: str | None = None
        self.drop = drop
        self.corrupt = corrupt
        self.counters: Counter[str] = Counter()
        self._rng = random.Random(seed)
        self._sink: Sink | None = None
        self._connected = True

    @property
    def connected(self) -> bool:
        return self._connected

    def start(self, sink: Sink) -> None:
        self._sink = sink

    def stop(self) -> None:
        self._sink = None

    def disconnect(self) -> None:
        self._connected = False
        self.last_error = "disconnected"

    def reconnect(self) -> None:
        self._connected = True

    def emit(self, t: float, line: bytes) -> None:
        if self._sink is None:
            return
        if not self._connected:
            self.counters["lost_disconnected"] += 1
            return
        if self.drop and self._rng.random() < self.drop:
            self.counters["dropped"] += 1
            return
        if self.corrupt and line and self._rng.random() < self.corrupt:
            line = self._alter(line)
            self.counters["corrupted"] += 1
        self.counters["lines"] += 1
        self._sink(t, line.rstrip(b"\r\n"))

    def emit_all(self, t0: float, interval_s: float, lines: Iterable[bytes]) -> None:
        for i, line in enumerate(lines):
            self.emit(t0 + i * interval_s, line)

    def _alter(self, line: bytes) -> bytes:
        line = line.rstrip(b"\r\n") or b" "
        i = self._rng.randrange(len(line))
        # Any bit but 0x20, whose flip only changes the case of a letter; keep it one line.
        bits = [1 << b for b in (0, 1, 2, 3, 4, 6) if line[i] ^ (1 << b) not in (0x0A, 0x0D)]
        flipped = line[i] ^ self._rng.choice(bits)
        return line[:i] + bytes([flipped]) + line[i + 1 :]


def open_line_source(cfg: GnssConfig | CropConfig) -> LineSource:
    """The source a [gnss] or [crop] section asks for."""
    if cfg.source == "serial":
        return SerialLineSource(cfg.port, cfg.baud)
    if cfg.source == "file":
        return FileLineSource(cfg.path, cfg.replay_interval_s)
    if cfg.source == "stdin":
        return StdinLineSource()
    raise DeviceError(f"unknown line source {cfg.source!r}")
