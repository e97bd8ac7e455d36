"""The cab's browser recognised by the local user it runs as (`display.kiosk_user`): the owner of
the client end of a loopback connection, read from the kernel's socket table. No secret travels
on a command line or stays in a history, and no page or process of another user can pass for
the cab, whatever it guesses."""

from __future__ import annotations

import os
import pwd
import socket
from collections.abc import Iterator

import pytest

from test_display_security import Served, _serve
from topdress.display.guard import Guard
from topdress.display.options import DisplayError
from topdress.display.peercred import kiosk_uid, socket_owner

PIN = "4711"
OTHER = pwd.getpwnam("nobody").pw_uid


def test_the_owner_of_a_loopback_connection_is_read_from_the_kernel() -> None:
    with socket.create_server(("127.0.0.1", 0)) as server:
        port = server.getsockname()[1]
        with socket.create_connection(("127.0.0.1", port)) as client:
            peer_port = client.getsockname()[1]
            assert socket_owner("127.0.0.1", peer_port, "127.0.0.1", port) == os.getuid()
            assert socket_owner("127.0.0.1", 1, "127.0.0.1", port) is None


def test_a_dual_stack_server_sees_an_ipv4_client_too() -> None:
    with socket.create_server(("::", 0), family=socket.AF_INET6, dualstack_ipv6=True) as server:
        port = server.getsockname()[1]
        with socket.create_connection(("127.0.0.1", port)) as client:
            peer_port = client.getsockname()[1]
            assert socket_owner("127.0.0.1", peer_port, "127.0.0.1", port) == os.getuid()


def _guard(uid: int, owner: int | None) -> Guard:
    return Guard(kiosk_uid=uid, owner=lambda *_: owner)


@pytest.mark.parametrize(
    ("peer", "headers", "owner", "cab"),
    [
        ("127.0.0.1", {}, 1000, True),  # the kiosk user's browser
        ("127.0.0.1", {}, 1001, False),  # another local user's process
        ("127.0.0.1", {}, None, False),  # not in the table (not Linux, gone)
        ("127.0.0.1", {b"x-forwarded-for": "10.0.0.9"}, 1000, False),  # through a proxy
        ("10.0.0.9", {}, 1000, False),  # not loopback at all
    ],
)
def test_only_a_direct_loopback_connection_of_the_kiosk_user_is_the_cab(
    peer: str, headers: dict[bytes, str], owner: int | None, cab: bool
) -> None:
    info = _guard(1000, owner).client(peer, headers, "", ("127.0.0.1", 50000, 8080))
    assert info.cab is cab


def test_a_user_that_does_not_exist_names_the_key() -> None:
    with pytest.raises(DisplayError, match=r"display\.kiosk_user 'no-such-cab-user'"):
        kiosk_uid("no-such-cab-user")


@pytest.fixture(scope="module")
def mine() -> Iterator[Served]:
    """The kiosk user is the one these tests run as: a direct request is the cab's browser."""
    yield from _serve(f'[display]\npin = "{PIN}"\nkiosk_user = "{pwd.getpwuid(os.getuid())[0]}"\n')


@pytest.fixture(scope="module")
def theirs() -> Iterator[Served]:
    """The kiosk user is someone else: these tests' direct requests are a stranger's."""
    yield from _serve(f'[display]\npin = "{PIN}"\nkiosk_user = "nobody"\n')


def test_the_kiosk_users_browser_operates_without_the_pin(mine: Served) -> None:
    assert mine.operator() == "cab"


@pytest.mark.skipif(os.getuid() == OTHER, reason="the tests run as nobody")
def test_another_users_process_on_the_cab_pc_needs_the_pin(theirs: Served) -> None:
    assert theirs.operator() == "remote"
