"""The CAN bus: any python-can interface (socketcan, slcan, pcan, kvaser, virtual,
udp_multicast, ...) opened from the `[can]` section (`open_bus`), and kept open (`CanPort`): read
in its own thread, given up when the adapter errors out or vanishes, and opened again there with
backoff, as the serial line sources are (devices/lines.py)."""

from __future__ import annotations

import errno
import logging
import threading
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

import can
import serial

from topdress.config import CanConfig
from topdress.errors import DeviceError

log = logging.getLogger(__name__)


def open_bus(cfg: CanConfig, **extra: Any) -> can.BusABC:
    """Open the python-can bus of the `[can]` section; DeviceError when it cannot be opened."""
    kwargs: dict[str, Any] = {"interface": cfg.interface, "channel": cfg.channel}
    if cfg.interface == "udp_multicast":
        kwargs["fd"] = False  # classic CAN frames, like the real bus
    elif cfg.interface != "virtual":
        kwargs["bitrate"] = cfg.bitrate
    kwargs.update(cfg.options)
    kwargs.update(extra)
    try:
        return can.Bus(**kwargs)
    except Exception as exc:
        # anything (kvaser without canlib: NameError); every failure to open is a DeviceError.
        if isinstance(exc, NameError | ImportError | AttributeError):
            raise DeviceError(
                f"cannot open CAN interface {cfg.interface!r}: its driver or the vendor library "
                f"it needs is not installed ({type(exc).__name__}: {exc})"
            ) from exc
        raise DeviceError(
            f"cannot open CAN interface {cfg.interface!r} channel {cfg.channel!r}: {exc}"
        ) from exc


#: Errors that say the adapter itself is gone (unplugged, its tty or network interface removed):
#: its bus is given up at once and opened again.
_GONE_ERRNOS = frozenset(
    {errno.EIO, errno.ENODEV, errno.ENXIO, errno.EBADF, errno.ENOENT, errno.ENETDOWN}
)
#: Conditions of the bus, not of the adapter (no ECU acknowledging: the transmit queue fills):
#: reopening cannot help, so they never make the bus be given up.
_BUS_ERRNOS = frozenset({errno.ENOBUFS, errno.EAGAIN})

Sink = Callable[[float, str, Any], None]
"""`sink(t, what, payload)`, from the port's thread: `frame` (a can.Message), `rx_error` (its
reason; the bus is kept), `lost` (the reason the bus was given up), `open` (the bus is open;
payload: seconds since it was lost or the port started), `open_failed` (the reason; said once
until it opens)."""


def _errnos(exc: BaseException) -> list[int]:
    """The error numbers along an exception's causes (python-can wraps pyserial's and the
    OS's errors in CanOperationError)."""
    found: list[int] = []
    seen: BaseException | None = exc
    while seen is not None and len(found) < 8:
        for attr in ("errno", "error_code"):
            value = getattr(seen, attr, None)
            if isinstance(value, int):
                found.append(value)
        seen = seen.__cause__ or seen.__context__
    return found


def reason(exc: BaseException) -> str:
    """An error in words, with its cause: python-can's own message ("Could not read from
    serial device") says what failed, the cause why."""
    cause = exc.__cause__
    return f"{exc}: {cause}" if cause is not None and str(cause) else str(exc)


def adapter_gone(exc: BaseException) -> bool:
    """The error says the adapter is gone: pyserial's errors but a write timeout (slcan and
    other serial adapters),
    or an OS error such as EIO, ENODEV, ENETDOWN, anywhere along its causes."""
    seen: BaseException | None = exc
    while seen is not None:
        # A write timeout is an adapter not draining, maybe for a moment: the dead_s rule
        if isinstance(seen, serial.SerialException) and not isinstance(
            seen, serial.SerialTimeoutException
        ):
            return True
        seen = seen.__cause__ or seen.__context__
    return any(n in _GONE_ERRNOS for n in _errnos(exc))


def bus_condition(exc: BaseException) -> bool:
    """The error is the bus's state, not the adapter's (a full transmit queue, a timeout)."""
    if isinstance(exc, can.CanTimeoutError) or "buffer full" in str(exc).lower():
        return True
    return any(n in _BUS_ERRNOS for n in _errnos(exc))


class CanPort:
    """The `[can]` interface, kept open: read in its own thread, and when it errors out or
    vanishes, given up and opened again there with backoff (`backoff_s` doubling up to
    `backoff_max_s`), so neither opening (slcan's open sleeps) nor a dead adapter ever holds
    the control loop. `send` is called from the loop.

    A bus is given up when an error says the adapter is gone (`adapter_gone`), or when its
    sends or receives have failed for `dead_s` without one working (an error of python-can's
    that names no cause), but never for a condition of the bus itself (`bus_condition`: with
    the ECU's cable pulled, the adapter is fine and reopening it cannot help).

    `bus`: an interface already open (`topdress run` opens it before anything starts, so a
    wrong `[can]` section is an error at once); without it the port's thread opens it.
    `wait(seconds)` is the pause between tries (True: stop); tests pass one on virtual time.
    """

    def __init__(
        self,
        cfg: CanConfig,
        bus: can.BusABC | None = None,
        *,
        opener: Callable[[CanConfig], can.BusABC] = open_bus,
        backoff_s: float = 0.1,
        backoff_max_s: float = 1.0,
        dead_s: float = 0.3,
        recv_timeout_s: float = 0.1,
        clock: Callable[[], float] = time.monotonic,
        wait: Callable[[float], bool] | None = None,
    ) -> None:
        self.cfg = cfg
        self.name = f"{cfg.interface}:{cfg.channel}"
        self.counters: Counter[str] = Counter()
        self.last_error: str | None = None
        self.backoff_s = backoff_s
        self.backoff_max_s = backoff_max_s
        self.dead_s = dead_s
        self.recv_timeout_s = recv_timeout_s
        self.clock = clock
        self._opener = opener
        self._stop = threading.Event()
        self._wait = wait if wait is not None else self._stop.wait
        self._lock = threading.Lock()  # a send and the bus being given up: one at a time
        self._bus = bus
        self._gone: str | None = None  # why the bus in use is to be given up (a send said so)
        self._tx_failing_since: float | None = None
        self._failing = False  # tries to open have failed since the last open
        self._thread: threading.Thread | None = None
        self._sink: Sink | None = None

    @property
    def connected(self) -> bool:
        """A bus is open and not being given up."""
        return self._bus is not None and self._gone is None

    @property
    def bus(self) -> can.BusABC | None:
        """The python-can bus in use (None while there is none)."""
        return self._bus

    def start(self, sink: Sink) -> None:
        if self._thread is not None:
            raise DeviceError(f"CAN {self.name}: already started")
        self._sink = sink
        self._thread = threading.Thread(target=self._run, name=f"can:{self.name}", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the thread, then shut the bus down. A thread still inside a slow open leaves
        by itself and shuts down what it opened."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self._thread is None or not self._thread.is_alive():
            self._give_up()

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Send on the bus in use: DeviceError while there is none; python-can's or the OS's
        error as it is when the send fails (and the bus is marked to be given up when that
        error says the adapter is gone, or sends have failed for `dead_s`)."""
        with self._lock:
            bus = self._bus
            if bus is None or self._gone is not None:
                raise DeviceError(f"CAN {self.name} is not open: {self.last_error or 'closed'}")
            try:
                bus.send(msg, timeout=timeout)
            except (can.CanError, OSError) as exc:
                now = self.clock()
                self.counters["tx_errors"] += 1
                if self._tx_failing_since is None:
                    self._tx_failing_since = now
                if self._dead(exc, self._tx_failing_since, now):
                    self._gone = reason(exc)
                raise
        self._tx_failing_since = None

    def _dead(self, exc: BaseException, since: float, now: float) -> bool:
        if adapter_gone(exc):
            return True
        return not bus_condition(exc) and now - since >= self.dead_s

    def _tell(self, what: str, payload: Any) -> None:
        if self._sink is not None:
            self._sink(self.clock(), what, payload)

    def _run(self) -> None:
        delay = self.backoff_s
        down_since = self.clock()
        while not self._stop.is_set():
            if self._bus is None:
                if not self._open(down_since):
                    if self._wait(delay):
                        break
                    delay = min(delay * 2.0, self.backoff_max_s)
                    continue
                delay = self.backoff_s
            why = self._read()
            if why is None:
                break
            down_since = self.clock()
            self._give_up()
            self.counters["lost"] += 1
            self.last_error = why
            self._tell("lost", why)
            if self._wait(delay):
                break
        self._give_up()

    def _open(self, down_since: float) -> bool:
        try:
            bus = self._opener(self.cfg)
        except DeviceError as exc:
            self.counters["open_failures"] += 1
            self.last_error = str(exc)
            if not self._failing:  # once until it opens, not at every try
                self._failing = True
                self._tell("open_failed", str(exc))
            return False
        if self._stop.is_set():  # stopped while opening: nobody will use it
            _shutdown(bus, self.name)
            return False
        with self._lock:
            self._bus, self._gone, self._tx_failing_since = bus, None, None
        self._failing = False
        self.counters["opens"] += 1
        self._tell("open", self.clock() - down_since)
        return True

    def _read(self) -> str | None:
        """Read until stopped (None) or the bus is to be given up (why)."""
        bus = self._bus
        assert bus is not None
        failing_since: float | None = None
        while not self._stop.is_set():
            if self._gone is not None:
                return self._gone
            try:
                msg = bus.recv(timeout=self.recv_timeout_s)
            except (can.CanError, OSError) as exc:
                now = self.clock()
                self.counters["rx_errors"] += 1
                failing_since = now if failing_since is None else failing_since
                if self._dead(exc, failing_since, now):
                    return reason(exc)
                self._tell("rx_error", reason(exc))
                if self._wait(min(self.recv_timeout_s, self.dead_s / 2)):
                    return None
                continue
            failing_since = None
            if msg is not None:
                self._tell("frame", msg)
        return None

    def _give_up(self) -> None:
        with self._lock:
            bus, self._bus = self._bus, None
            self._gone = None
        if bus is not None:
            _shutdown(bus, self.name)


def _shutdown(bus: can.BusABC, name: str) -> None:
    try:
        bus.shutdown()
    except (can.CanError, OSError) as exc:  # the adapter is gone already
        log.info("CAN %s did not shut down cleanly: %s", name, exc)
