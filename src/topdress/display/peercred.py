"""Whose process is at the other end of a loopback TCP connection, from the kernel's socket
table (/proc/net/tcp and tcp6): the cab's kiosk browser is recognised by the local user it runs
as (`display.kiosk_user`), with no secret on its command line or in its history. Linux only;
elsewhere (or when the table cannot be read) the owner is unknown and the cab is not assumed."""

from __future__ import annotations

import ipaddress
import pwd
from pathlib import Path

from topdress.display.options import DisplayError

TABLES = (Path("/proc/net/tcp"), Path("/proc/net/tcp6"))


def _hex_address(ip: str, port: int) -> str:
    """An address as the kernel's table writes it: the address's 32-bit words in host (little-
    endian) byte order, the port in hex."""
    packed = ipaddress.ip_address(ip).packed
    words = [packed[i : i + 4][::-1].hex().upper() for i in range(0, len(packed), 4)]
    return f"{''.join(words)}:{port:04X}"


def _mapped(ip: str) -> str:
    """127.0.0.1 as an IPv6 socket sees it (::ffff:127.0.0.1)."""
    return str(ipaddress.IPv6Address(f"::ffff:{ip}"))


def socket_owner(peer_ip: str, peer_port: int, server_ip: str, server_port: int) -> int | None:
    """The uid owning the client end (peer_ip:peer_port -> server_ip:server_port) of a local
    TCP connection, or None when it is not in the tables."""
    wanted = {(_hex_address(peer_ip, peer_port), _hex_address(server_ip, server_port))}
    if ipaddress.ip_address(peer_ip).version == 4:
        wanted.add(
            (
                _hex_address(_mapped(peer_ip), peer_port),
                _hex_address(_mapped(server_ip), server_port),
            )
        )
    for table in TABLES:
        try:
            lines = table.read_text(encoding="ascii").splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            cols = line.split()
            if len(cols) > 7 and (cols[1], cols[2]) in wanted:
                return int(cols[7])
    return None


def kiosk_uid(name: str) -> int:
    """The uid of `display.kiosk_user`; DisplayError naming the key when there is no such user."""
    try:
        return pwd.getpwnam(name).pw_uid
    except KeyError:
        raise DisplayError(f"display.kiosk_user {name!r}: no such local user") from None
