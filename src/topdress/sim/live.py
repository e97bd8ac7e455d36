"""The simulated machine, live: the World paced to the wall clock and wired like the real one.

Its GNSS receiver writes NMEA to one pseudo-terminal and the crop sensors' data logger writes
its lines to another (`os.openpty`); a terminal opens the slave side with pyserial exactly like
a real serial port. The ECU core exchanges CAN frames on a python-can bus (`virtual` within one
process, `udp_multicast` across processes). Everything runs in one thread that steps the World
every 10 ms of wall time.

Like a real serial line, a pty whose reader has stopped reading fills up; the bytes that no
longer fit are dropped and counted (`counters["serial_dropped_bytes"]`), never blocking the plant.
"""

from __future__ import annotations

import logging
import os
import threading
import time
import tty
from collections import Counter
from collections.abc import Callable

import can

from topdress.sim.world import World

log = logging.getLogger(__name__)

_RESYNC_S = 1.0  # further behind the wall clock than this: skip ahead instead of racing


class PtyPort:
    """One pseudo-terminal: the machine writes to the master, a terminal opens `path`."""

    def __init__(self) -> None:
        self.master, self._slave = os.openpty()
        # Raw: no echo, no CR/LF translation. The slave stays open here so the line never
        # hangs up while the reader closes and reopens it.
        tty.setraw(self._slave)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self._slave)

    def write(self, data: bytes) -> int:
        """Write what fits; returns the number of bytes dropped."""
        try:
            n = os.write(self.master, data)
        except BlockingIOError:
            n = 0
        return len(data) - n

    def close(self) -> None:
        os.close(self.master)
        os.close(self._slave)


class LiveMachine:
    """A World stepping in real time in its own thread, on two ptys and a CAN bus."""

    def __init__(
        self,
        world: World,
        bus: can.BusABC,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.world = world
        self.bus = bus
        self.clock = clock
        self.gnss_port = PtyPort()
        self.crop_port = PtyPort()
        self.counters: Counter[str] = Counter()
        self.error: BaseException | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="live-machine", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        """Stop the thread, then close the ptys."""
        self._stop.set()
        if self._thread.ident is not None:  # started: stop() also runs after a failed start
            self._thread.join(timeout=5.0)
        self.gnss_port.close()
        self.crop_port.close()

    def _run(self) -> None:
        try:
            self._loop()
        except Exception as exc:  # reported to the caller, who owns the process
            self.error = exc
            log.exception("simulated machine stopped")

    def _loop(self) -> None:
        w = self.world
        t0 = self.clock() - w.t_s
        while not self._stop.is_set():
            self.step_once()
            lag = self.clock() - (t0 + w.t_s)
            if lag > _RESYNC_S:
                self.counters["resyncs"] += 1
                t0 += lag
            elif lag < 0:
                self._stop.wait(-lag)

    def step_once(self) -> None:
        """Deliver the PC's frames, advance the World one step, put out what it produced."""
        w = self.world
        while (msg := self.bus.recv(timeout=0)) is not None:
            if w.deliver_can(msg) != 0:
                self.counters["can_rejected"] += 1
        out = w.step()
        dropped = 0
        if out.nmea:
            dropped += self.gnss_port.write("".join(out.nmea).encode("ascii"))
        if out.crop:
            dropped += self.crop_port.write("".join(out.crop).encode("ascii"))
        self.counters["serial_dropped_bytes"] += dropped
        for frame_id, data in out.can:
            try:
                self.bus.send(can.Message(arbitration_id=frame_id, data=data, is_extended_id=True))
            except can.CanError:
                self.counters["can_tx_errors"] += 1
