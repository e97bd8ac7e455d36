"""Where the display is served: the address, the port, and the PIN rule for any address but
loopback."""

from __future__ import annotations

import ipaddress
import socket
from dataclasses import dataclass

from topdress.errors import TopdressError


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
