"""Serving the display: NiceGUI (uvicorn) in its own thread, beside the terminal's loop.

The terminal keeps the main thread (Ctrl-C and SIGTERM stop it as before; uvicorn installs no
signal handler off the main thread) and the display runs its own asyncio loop in a daemon
thread. Nothing the display does can stop metering: the control loop only hands it a snapshot
reference; an exception in the display thread ends the display, not the terminal.
"""

from __future__ import annotations

import ipaddress
import logging
import socket
import sys
import threading
import time
from dataclasses import dataclass

from topdress.display.hub import DisplayHub
from topdress.errors import TopdressError

log = logging.getLogger(__name__)

START_TIMEOUT_S = 20.0  # importing NiceGUI and binding the port, on a busy 2-core machine
#: How long a thread holding the GIL runs before another may take it (CPython's default is
#: 5 ms). The display's Python work (building a page update) would otherwise hold up the
#: control loop and the reader threads by up to that much at each hand-over: the benchmark's
#: NMEA-to-command p99 went from 15 ms to 6 ms with 1 ms.
GIL_SWITCH_S = 0.001


class DisplayError(TopdressError):
    """The display cannot be served as configured (address, PIN)."""


@dataclass(frozen=True)
class DisplayOptions:
    host: str = "127.0.0.1"
    port: int = 8080
    pin: str = ""

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}"


def is_loopback(host: str) -> bool:
    """Whether `host` is reachable from this machine only."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_security(opts: DisplayOptions) -> None:
    """Any address but loopback serves the cab's controls to a network: a PIN is required."""
    if not is_loopback(opts.host) and not opts.pin:
        raise DisplayError(
            f"display.host = {opts.host!r} serves the display beyond this machine: "
            "set display.pin (start/stop, manual rate and settings then ask for it)"
        )


def port_free(host: str, port: int) -> bool:
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((host, port))
        except OSError:
            return False
    return True


class DisplayServer:
    """The NiceGUI app in a daemon thread; `start()` returns once it listens."""

    def __init__(self, hub: DisplayHub, opts: DisplayOptions) -> None:
        self.hub = hub
        self.opts = opts
        self.error: str | None = None
        self._thread: threading.Thread | None = None

    def start(self) -> str:
        """Serve; returns the address. DisplayError when it cannot (no PIN, port taken)."""
        check_security(self.opts)
        if not port_free(self.opts.host, self.opts.port):
            raise DisplayError(
                f"display: {self.opts.host}:{self.opts.port} is in use "
                "(another topdress? choose another with --port or display.port)"
            )
        from topdress.display.pages import register_pages  # NiceGUI only when serving

        register_pages(self.hub)
        sys.setswitchinterval(min(sys.getswitchinterval(), GIL_SWITCH_S))
        self._thread = threading.Thread(target=self._serve, name="display", daemon=True)
        self._thread.start()
        deadline = time.monotonic() + START_TIMEOUT_S
        while not self._listening():
            if not self._thread.is_alive() or time.monotonic() > deadline:
                raise DisplayError(f"display did not start: {self.error or 'timed out'}")
            time.sleep(0.05)
        return self.opts.url

    def _listening(self) -> bool:
        from nicegui.server import Server

        server = getattr(Server, "instance", None)
        return bool(server is not None and server.started)

    def _serve(self) -> None:
        from nicegui import ui

        try:
            ui.run(
                host=self.opts.host,
                port=self.opts.port,
                title="topdress",
                reload=False,
                show=False,
                show_welcome_message=False,
                uvicorn_logging_level="warning",
                favicon="🌽",
            )
        except BaseException as exc:  # SystemExit from uvicorn included: the terminal goes on
            self.error = f"{type(exc).__name__}: {exc}"
            log.error("display stopped: %s", self.error)

    def stop(self) -> None:
        """Ask uvicorn to finish; waits briefly (the thread is a daemon anyway)."""
        if self._thread is None:
            return
        from nicegui.server import Server

        server = getattr(Server, "instance", None)
        if server is not None:
            server.should_exit = True
        self._thread.join(timeout=3.0)
