"""A USB-CAN adapter speaking SLCAN on a pseudo-terminal, for tests: python-can's real `slcan`
interface opens its tty with pyserial exactly as it opens a real adapter's. Test code, no part of
the package.

The adapter's tty is reached through a symbolic link (`path`), as udev's /dev/serial/by-id link
reaches a real one. `pull()` removes the link and closes the pty (the adapter is unplugged);
`plug()` makes a new pty and points the link at it (plugged back: a new /dev/pts number, the
same by-id path). On the CAN side the adapter is a python-can `virtual` bus on `channel`, where
the ECU's twin (`EcuOnChannel`) or a terminal's own virtual bus sits.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import select
import threading
import time
import tty
from pathlib import Path

import can

from ecu_twin import SimulatedEcu
from topdress import protocol
from topdress.config import TerminalConfig
from topdress.devices.can import open_bus
from topdress.devices.lines import FakeLineSource
from topdress.log.model import LogEvent
from topdress.log.session import SessionLog, SessionReader
from topdress.protocol import Fault
from topdress.terminal.app import Terminal


class SlcanAdapter:
    """An SLCAN adapter: answers python-can's commands (C, O, L, Sn, ...) with CR, forwards the
    frames it is given (T/t) to the CAN side while its channel is open, and writes the frames
    it hears there to the tty. `frames` holds what it put on the CAN side, with the monotonic
    time it did so."""

    def __init__(self, path: Path, channel: str) -> None:
        self.path = path
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.frames: list[tuple[float, can.Message]] = []
        self.commands: list[str] = []
        self.plugged_at: float | None = None
        self._lock = threading.Lock()
        self._fds: tuple[int, int] | None = None  # (master, slave) while plugged
        self._open = False  # the CAN channel, opened by "O"
        self._stop = threading.Event()
        self.plug()
        self._threads = [
            threading.Thread(target=self._from_tty, name="slcan-tty", daemon=True),
            threading.Thread(target=self._from_can, name="slcan-can", daemon=True),
        ]
        for thread in self._threads:
            thread.start()

    def plug(self) -> None:
        """A new pty, the link pointed at it."""
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no CR/LF translation
        # The slave stays open here too: a master whose slave was never opened reads EIO.
        link = self.path.with_name(self.path.name + ".new")
        os.symlink(os.ttyname(slave), link)
        with self._lock:
            self._fds = (master, slave)
            self._open = False
        os.replace(link, self.path)
        self.plugged_at = time.monotonic()

    def pull(self) -> None:
        """The adapter unplugged: the link removed (as udev does) and the pty closed. A link
        left dangling could soon name another program's pty: /dev/pts numbers are reused."""
        self.path.unlink(missing_ok=True)
        with self._lock:
            fds, self._fds = self._fds, None
            self._open = False
        if fds is not None:
            for fd in fds:
                os.close(fd)

    def close(self) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join(timeout=2.0)
        self.pull()
        self.path.unlink(missing_ok=True)
        self.bus.shutdown()

    def _from_tty(self) -> None:
        buf = b""
        master = None
        while not self._stop.is_set():
            with self._lock:
                fds = self._fds
            if fds is None or fds[0] != master:
                buf = b""  # a new adapter starts with nothing half-received
                master = None if fds is None else fds[0]
            if master is None:
                time.sleep(0.005)
                continue
            try:
                ready, _, _ = select.select([master], [], [], 0.02)
                data = os.read(master, 4096) if ready else b""
            except OSError:  # pulled meanwhile
                time.sleep(0.005)
                continue
            buf += data
            while b"\r" in buf:
                line, buf = buf.split(b"\r", 1)
                self._command(master, line.decode("ascii", "replace"))

    def _command(self, master: int, cmd: str) -> None:
        reply = b"\r"
        if cmd[:1] in ("T", "t"):
            extended = cmd[0] == "T"
            n = 8 if extended else 3
            try:
                can_id, dlc = int(cmd[1 : 1 + n], 16), int(cmd[1 + n])
                data = bytes.fromhex(cmd[2 + n : 2 + n + 2 * dlc])
            except ValueError:
                reply = b"\a"
            else:
                msg = can.Message(arbitration_id=can_id, data=data, is_extended_id=extended)
                with self._lock:
                    is_open = self._open
                if is_open:
                    self.bus.send(msg)
                    self.frames.append((time.monotonic(), msg))
                reply = b"Z\r" if extended else b"z\r"
        else:
            self.commands.append(cmd)
            with self._lock:
                if cmd in ("O", "L"):
                    self._open = True
                elif cmd == "C":
                    self._open = False
        with contextlib.suppress(OSError):  # pulled meanwhile
            os.write(master, reply)

    def _from_can(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(timeout=0.02)
            if msg is None:
                continue
            with self._lock:
                fds, is_open = self._fds, self._open
            if fds is None or not is_open:
                continue  # nobody listening: the frame is gone, as on a real bus
            if msg.is_extended_id:
                line = f"T{msg.arbitration_id:08X}{msg.dlc}{bytes(msg.data).hex().upper()}\r"
            else:
                line = f"t{msg.arbitration_id:03X}{msg.dlc}{bytes(msg.data).hex().upper()}\r"
            with contextlib.suppress(OSError):  # pulled meanwhile
                os.write(fds[0], line.encode())


class EcuOnChannel:
    """The ECU's twin on a python-can virtual channel, stepped on the wall clock (10 ms) in its
    own thread, since the adapter and the terminal on the other side run in real time.
    `timeouts` counts the steps on which the core had stopped the meters for want of a command
    (TD_FAULT_CMD_TIMEOUT) after it had run."""

    def __init__(self, channel: str) -> None:
        self.bus = can.Bus(interface="virtual", channel=channel)
        self._t0 = time.monotonic()
        self.twin = SimulatedEcu(self.bus)
        self.ran = False
        self.timeouts = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="ecu-twin", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(SimulatedEcu.STEP_S):
            self.twin.pump(time.monotonic() - self._t0)
            state = self.twin.ecu.state
            self.ran |= state.running
            if self.ran and Fault.CMD_TIMEOUT in state.faults:
                self.timeouts += 1

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.bus.shutdown()


class _Enough(Exception):
    """Ends a LiveTerminal's run from its tick."""


class LiveTerminal:
    """The terminal's own loop (`Terminal.run`) in a thread, on the wall clock, logging to a
    session, until `join()`; the GNSS and crop inputs stay quiet (the CAN link is under test).

    A watch thread records when this process could not run for a while (`stalls`: a shared
    machine under load): a command period is the loop's fault only beyond such a stall."""

    WATCH_S = 0.005
    STALL_S = 0.05

    def __init__(self, cfg: TerminalConfig, log_dir: Path) -> None:
        self.events: list[tuple[float, str]] = []
        self.stalls: list[tuple[float, float]] = []
        self.session = SessionLog.create(log_dir, "")
        self.term = Terminal(
            cfg,
            FakeLineSource(),
            FakeLineSource(),
            open_bus(cfg.can),
            self.session,
            start=True,
            on_event=lambda e: self.events.append((time.monotonic(), str(e))),
        )
        self._stop = threading.Event()
        self._threads = [
            threading.Thread(target=self._run, name="live-terminal", daemon=True),
            threading.Thread(target=self._watch, name="stall-watch", daemon=True),
        ]
        for thread in self._threads:
            thread.start()

    def _run(self) -> None:
        def on_tick(snapshot: object, now: float) -> None:
            if self._stop.is_set():
                raise _Enough

        with contextlib.suppress(_Enough):
            self.term.run(on_tick=on_tick)

    def _watch(self) -> None:
        while not self._stop.is_set():
            t = time.monotonic()
            time.sleep(self.WATCH_S)
            if time.monotonic() - t > self.STALL_S:
                self.stalls.append((t, time.monotonic()))

    def join(self) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join(timeout=30.0)
            assert not thread.is_alive()

    def long_periods(self, times: list[float], bound_s: float) -> list[tuple[float, float]]:
        """The periods between `times` longer than `bound_s` once the process's own stalls
        within them are taken off: (start, length)."""
        out = []
        for a, b in itertools.pairwise(times):
            stalled = sum(max(0.0, min(b, s1) - max(a, s0)) for s0, s1 in self.stalls)
            if b - a - stalled > bound_s:
                out.append((a, b - a))
        return out

    def commands(self) -> list[float]:
        """When each PcCommand went out (the loop's clock), from the session's tx log."""
        with SessionReader(self.session.path) as reader:
            ids = protocol.DEFAULT_IDS.command
            return [r.t for r in reader.raw() if r.kind == "can_tx" and r.can_id == ids]

    def state_times(self) -> list[float]:
        """When each state row was written: the loop's ticks."""
        with SessionReader(self.session.path) as reader:
            return [row.t for row in reader.states()]

    def log_events(self) -> list[LogEvent]:
        with SessionReader(self.session.path) as reader:
            return list(reader.events())
