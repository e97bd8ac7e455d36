"""Serving the display: the address and PIN rules, and NiceGUI's server (in the display
process, see topdress.display.process)."""

from __future__ import annotations

import ipaddress
import logging
import socket
from dataclasses import dataclass

from topdress.display.hub import DisplayHub
from topdress.errors import TopdressError

log = logging.getLogger(__name__)


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


def run_server(hub: DisplayHub, opts: DisplayOptions) -> None:
    """Serve the pages on this thread until the server is stopped (the display process's
    main thread: uvicorn handles its signals there)."""
    from nicegui import ui

    from topdress.display.pages import register_pages  # NiceGUI only when serving

    register_pages(hub)
    ui.run(
        host=opts.host,
        port=opts.port,
        title="topdress",
        reload=False,
        show=False,
        show_welcome_message=False,
        uvicorn_logging_level="warning",
        favicon="🌽",
    )
