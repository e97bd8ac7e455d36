"""The operating surface against an attacker: Host and Origin (DNS rebinding), forwarded
addresses, the cab's own browser behind a proxy (the kiosk token), PIN guessing, and request
text on the console. Real HTTP requests (http.client) against real display processes started
by the terminal's end (DisplayLink), and the PIN dialog in NiceGUI's simulated browser."""

from __future__ import annotations

import asyncio
import http.client
import os
import re
import socket
from collections.abc import Iterator
from pathlib import Path

import pytest
from nicegui.testing import User

from test_display import Terminal, pinned, working
from test_display_liveness import RecordingTerminal, answers, free_port, until
from topdress.cli.display import DisplayLink, kiosk_token
from topdress.config import loads_config
from topdress.display import pages
from topdress.display.guard import Guard, PinGate, printable
from topdress.display.hub import DisplayHub
from topdress.display.options import DisplayError, DisplayOptions
from topdress.display.pages import register_pages
from topdress.view.commands import DisplayEvent

PIN = "4711"


class Served:
    def __init__(self, link: DisplayLink, term: RecordingTerminal, messages: list[str]) -> None:
        self.link, self.term, self.messages = link, term, messages
        self.port = link.opts.port

    def get(
        self, path: str, headers: dict[str, str] | None = None
    ) -> tuple[int, dict[str, str], str]:
        """GET `path` as written (no quoting), Host 127.0.0.1:port unless given."""
        conn = http.client.HTTPConnection("127.0.0.1", self.port, timeout=10)
        try:
            conn.putrequest("GET", path, skip_host=True, skip_accept_encoding=True)
            hdrs = {"Host": f"127.0.0.1:{self.port}", **(headers or {})}
            for k, v in hdrs.items():
                conn.putheader(k, v)
            conn.endheaders()
            r = conn.getresponse()
            headers_ = {k.lower(): v for k, v in r.getheaders()}
            if r.status == 101:  # switched to a websocket: no HTTP body follows
                return r.status, headers_, ""
            return r.status, headers_, r.read().decode()
        finally:
            conn.close()

    def operator(self, headers: dict[str, str] | None = None) -> str:
        """Whom the page takes the client for: cab (no PIN) or remote."""
        status, _, body = self.get("/", headers)
        assert status == 200, body[:200]
        found = re.search(r'"data-operator":"(\w+)"', body)
        assert found, "no data-operator on the page"
        return found.group(1)

    def events(self) -> list[DisplayEvent]:
        return [c for c in self.term.posted if isinstance(c, DisplayEvent)]


def _serve(config: str) -> Iterator[Served]:
    term = RecordingTerminal(loads_config(config))
    messages: list[str] = []
    opts = DisplayOptions("127.0.0.1", free_port(), PIN)
    link = DisplayLink(term, opts, messages.append)  # type: ignore[arg-type]
    link.start()
    try:
        until("the display serving", lambda: answers(opts.url))
        yield Served(link, term, messages)
    finally:
        link.stop()


@pytest.fixture(scope="module")
def kiosk(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Served]:
    """The cab PC with a TLS proxy in front (every client arrives from loopback): the kiosk
    token recognises the cab's browser."""
    token_file = tmp_path_factory.mktemp("kiosk") / "token"
    yield from _serve(
        f'[display]\npin = "{PIN}"\nallowed_hosts = ["cab.example"]\n'
        f'kiosk_token_file = "{token_file}"\n'
    )


@pytest.fixture(scope="module")
def plain() -> Iterator[Served]:
    """No proxy declared, no kiosk token: the cab's browser is a direct loopback client."""
    yield from _serve(f'[display]\npin = "{PIN}"\n')


# ---- Host and Origin ------------------------------------------------------------------------
def test_a_foreign_host_is_refused_before_anything_is_served(kiosk: Served) -> None:
    """DNS rebinding: the attacker's name resolves to 127.0.0.1, the browser sends it as Host."""
    assert kiosk.get("/", {"Host": f"rebind.attacker.example:{kiosk.port}"})[0] == 421
    assert kiosk.get("/_nicegui_ws/socket.io/?EIO=4&transport=polling",
                     {"Host": "rebind.attacker.example"})[0] == 421  # fmt: skip
    for host in (f"127.0.0.1:{kiosk.port}", f"localhost:{kiosk.port}", "cab.example",
                 f"[::1]:{kiosk.port}", "CAB.EXAMPLE."):  # fmt: skip
        assert kiosk.get("/", {"Host": host})[0] == 200, host


def test_socketio_refuses_another_origin(kiosk: Served) -> None:
    """A page of another site (or port) in the cab's browser cannot open the page's socket."""
    poll = "/_nicegui_ws/socket.io/?EIO=4&transport=polling"
    own = f"http://127.0.0.1:{kiosk.port}"
    assert kiosk.get(poll, {"Origin": own})[0] == 200
    for origin in ("http://attacker.example", f"http://127.0.0.1:{kiosk.port + 1}", "null",
                   f"http://localhost:{kiosk.port}"):  # fmt: skip
        assert kiosk.get(poll, {"Origin": origin})[0] == 403, origin
    # the websocket upgrade itself, as a browser sends it
    key = "dGhlIHNhbXBsZSBub25jZQ=="
    upgrade = {"Upgrade": "websocket", "Connection": "Upgrade", "Sec-WebSocket-Version": "13",
               "Sec-WebSocket-Key": key}  # fmt: skip
    ws = "/_nicegui_ws/socket.io/?EIO=4&transport=websocket"
    assert kiosk.get(ws, {**upgrade, "Origin": "http://attacker.example"})[0] == 403
    assert kiosk.get(ws, {**upgrade, "Origin": own})[0] == 101


# ---- who is the cab ---------------------------------------------------------------------------
def test_behind_a_local_proxy_only_the_kiosk_token_makes_the_cab(kiosk: Served) -> None:
    assert kiosk.operator() == "remote"  # loopback alone: a proxy makes everyone loopback
    token = kiosk_token(kiosk.term.cfg.display.kiosk_token_file)
    status, headers, _ = kiosk.get(f"/calibration?kiosk={token}&x=1")
    assert status == 303 and headers["location"] == "/calibration?x=1"  # the token leaves the URL
    cookie = headers["set-cookie"]
    assert "HttpOnly" in cookie and "SameSite=Strict" in cookie
    assert kiosk.operator({"Cookie": cookie.split(";")[0]}) == "cab"
    # (a wrong cookie: remote, and counted as a guess, in the next test)


def test_guessing_the_kiosk_token_is_locked_out_and_logged(kiosk: Served) -> None:
    address = "127.0.0.1"
    for _ in range(5):
        assert kiosk.get("/?kiosk=guess")[0] == 403
    status, _, page = kiosk.get("/?kiosk=guess")
    assert status == 429  # a page that tries again by itself and says where Stop is
    assert 'http-equiv="refresh" content="5;url=/"' in page and "stop switch" in page
    token = kiosk_token(kiosk.term.cfg.display.kiosk_token_file)
    # The cab's kiosk coming back with its token is never locked out by others' guesses.
    assert kiosk.get(f"/?kiosk={token}")[0] == 303
    until("the events", lambda: any(e.kind == "display.pin_lockout" for e in kiosk.events()))
    failed = [e.detail for e in kiosk.events() if e.kind == "display.pin_failed"]
    assert [d["failures"] for d in failed] == [1, 2, 3, 4, 5, 1]  # a guess while locked counts
    # A wrong kiosk cookie is a guess too: counted and logged (the page is served as remote).
    assert kiosk.operator({"Cookie": "topdress_kiosk=" + "y" * len(token)}) == "remote"
    until("the cookie guess", lambda: any(e.detail.get("what") == "kiosk_cookie"
                                          for e in kiosk.events()))  # fmt: skip
    assert {(d["address"], d["what"]) for d in failed} == {(address, "kiosk")}
    (lockout,) = [e.detail for e in kiosk.events() if e.kind == "display.pin_lockout"]
    assert lockout == {"address": address, "failures": 5, "lockout_s": 60.0}


def test_x_forwarded_for_from_loopback_is_not_believed(plain: Served) -> None:
    assert plain.operator() == "cab"  # the cab PC's own browser, nothing in between
    for header in ("X-Forwarded-For", "X-Real-IP", "Forwarded"):
        # Something forwarded this: a proxy nobody declared. Never the cab, whatever it says.
        assert plain.operator({header: "127.0.0.1"}) == "remote", header


# ---- the console --------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("path", "shown"),
    [
        ("/%1b%5b2J%1b%5b31mFAKE-ALARM", "/\\x1b[2J\\x1b[31mFAKE-ALARM"),
        ("/%0aoperator:%20stopped", "/\\x0aoperator: stopped"),
    ],
)
def test_a_request_path_reaches_the_console_escaped(plain: Served, path: str, shown: str) -> None:
    assert plain.get(path)[0] == 404
    line = until("the display's log line", lambda: [m for m in plain.messages if shown in m])[0]
    assert line.startswith("display: WARNING nicegui: http://")
    for m in plain.messages:
        assert "\x1b" not in m and "\n" not in m and "\r" not in m
        assert not m.startswith("operator:")


def test_printable_escapes_what_a_console_would_act_on() -> None:
    assert printable("a\x1b[2Jb\n\rc\x9b\u202etxt\u2028") == (
        "a\\x1b[2Jb\\x0a\\x0dc\\x9b\\u202etxt\\u2028"
    )
    assert printable("红色 ok") == "红色 ok"
    assert printable("x" * 600).endswith("x…") and len(printable("x" * 600)) == 501


# ---- the rules alone --------------------------------------------------------------------------
def test_the_client_behind_a_trusted_proxy_is_the_forwarded_one() -> None:
    g = Guard.of([], ["127.0.0.1", "10.0.0.0/8"], "")
    xff = {b"x-forwarded-for": "203.0.113.7, 10.1.1.1"}
    info = g.client("127.0.0.1", xff, "")
    assert info.address == "203.0.113.7"  # the rightmost hop that is not a trusted proxy
    assert not info.cab  # from the proxy: never the cab without the kiosk token
    spoofed = g.client("198.51.100.2", {b"x-forwarded-for": "127.0.0.1"}, "")
    assert spoofed.address == "198.51.100.2" and not spoofed.cab  # not a proxy: the peer
    assert g.client("127.0.0.1", {}, "").cab is False  # the proxy's own address
    assert Guard.of([], [], "").client("::1", {}, "").cab
    assert not Guard.of([], [], "").client("192.168.1.20", {}, "").cab


def test_pin_failures_lock_an_address_out_for_a_doubling_time() -> None:
    gate = PinGate()
    for i in range(1, 5):
        assert gate.failed("10.0.0.9", float(i)) == (i, 0.0)
    assert gate.failed("10.0.0.9", 5.0) == (5, 60.0)
    assert gate.locked_for("10.0.0.9", 5.0) == 60.0 and gate.locked_for("10.0.0.8", 5.0) == 0.0
    for i in range(5):
        gate.failed("10.0.0.9", 70.0 + i)
    assert gate.locked_for("10.0.0.9", 74.0) == 120.0  # the second lockout: twice as long
    spread = PinGate()
    for i in range(20):  # an attacker changing address every try
        spread.failed(f"10.0.1.{i}", float(i))
    assert spread.locked_for("10.0.2.1", 19.0) == 60.0  # everyone but the cab waits
    gate.succeeded("10.0.0.9")
    assert gate.locked_for("10.0.0.9", 75.0) == 0.0


def test_the_kiosk_token_file_is_made_private_and_a_readable_one_refused(tmp_path: Path) -> None:
    path = tmp_path / "state" / "token"
    path.parent.mkdir()
    token = kiosk_token(str(path))
    assert len(token) >= 32 and (path.stat().st_mode & 0o777) == 0o600
    assert kiosk_token(str(path)) == token  # kept across starts: the kiosk's URL stays
    os.chmod(path, 0o644)
    with pytest.raises(DisplayError, match="can be read by others"):
        kiosk_token(str(path))


def test_the_new_display_keys_are_checked() -> None:
    cfg = loads_config(
        '[display]\nallowed_hosts = ["cab.local"]\ntrusted_proxies = ["127.0.0.1", "fd00::/8"]\n'
        "lost_pause_s = 0\n"
    )
    assert cfg.display.allowed_hosts == ("cab.local",) and cfg.display.lost_pause_s == 0.0
    for bad, key in (('allowed_hosts = ["http://cab"]', "allowed_hosts"),
                     ('trusted_proxies = ["proxy"]', "trusted_proxies"),
                     ('trusted_proxies = "127.0.0.1"', "trusted_proxies"),
                     ("lost_pause_s = -1", "lost_pause_s")):  # fmt: skip
        with pytest.raises(Exception, match=f"display.{key}"):
            loads_config(f"[display]\n{bad}\n")


# ---- the PIN dialog -----------------------------------------------------------------------
async def test_pin_guessing_is_slowed_locked_out_and_logged(
    user: User, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(pages, "client_is_remote", lambda: True)
    monkeypatch.setattr("topdress.display.actions.WRONG_PIN_DELAY_S", 0.01)
    reports: list[tuple[str, dict[str, object]]] = []
    term = Terminal()
    hub = DisplayHub(pinned, term.post, report=lambda k, d: reports.append((k, d)))
    hub.publish(working(operator="stopped"))
    register_pages(hub)
    await user.open("/")
    user.find(marker="start").click()
    await user.should_see(marker="pin")
    for i in range(1, 6):
        user.find(marker="pin").type("0000")
        user.find(marker="pin_ok").click()
        for _ in range(100):  # each wrong PIN answered before the next is typed
            if len(reports) >= i:
                break
            await asyncio.sleep(0.02)
    await user.should_see("wrong PIN")
    user.find(marker="pin").type(PIN)  # the right one, but locked out now
    user.find(marker="pin_ok").click()
    await user.should_see("too many wrong PINs: try again in 60 s")
    assert term.sent == []
    kinds = [k for k, _ in reports]
    assert kinds == ["display.pin_failed"] * 5 + ["display.pin_lockout"]
    assert all(PIN not in str(d) and "0000" not in str(d) for _, d in reports)  # never logged


def test_every_route_is_behind_the_guard(plain: Served) -> None:
    """The static files too, and a request written by hand."""
    status, _, _ = plain.get("/_nicegui/static/nicegui.css", {"Host": "attacker.example"})
    assert status == 421
    with socket.create_connection(("127.0.0.1", plain.port)) as s:
        s.sendall(b"GET / HTTP/1.1\r\nHost: attacker.example\r\n\r\n")
        assert s.recv(64).startswith(b"HTTP/1.1 421")


def _raw(port: int, request: bytes) -> bytes:
    """The status of a request written by hand ("400", "421", ...)."""
    with socket.create_connection(("127.0.0.1", port)) as s:
        s.sendall(request)
        return s.recv(64)[9:12]


def test_a_request_line_naming_another_host_is_refused(plain: Served) -> None:
    """Host is ours, an absolute-form target names a host: refused, whichever host it is."""
    ours = f"Host: 127.0.0.1:{plain.port}\r\n".encode()
    for target in (b"http://rebind.attacker.example/", f"http://127.0.0.1:{plain.port}/".encode()):
        assert _raw(plain.port, b"GET " + target + b" HTTP/1.1\r\n" + ours + b"\r\n") == b"421"
    two = b"GET / HTTP/1.1\r\n" + ours + b"Host: rebind.attacker.example\r\n\r\n"
    assert _raw(plain.port, two) in (b"400", b"421")  # two Host headers
    assert _raw(plain.port, b"GET / HTTP/1.1\r\nHost: 127.0.0.1:abc\r\n\r\n") == b"421"
    assert _raw(plain.port, b"GET / HTTP/1.1\r\n" + ours + b"\r\n") == b"200"


def test_one_host_with_a_numeric_port_is_all_that_is_taken() -> None:
    from topdress.display.guard import Guard

    guard = Guard.of(["cab.example"], [], "")
    assert guard.host_ok("127.0.0.1:8080") and guard.host_ok("[::1]:80")
    assert guard.host_ok("cab.example") and guard.host_ok("localhost:65535")
    assert not guard.host_ok("127.0.0.1:abc")  # not a port
    assert not guard.host_ok("127.0.0.1:99999")
    assert not guard.host_ok("127.0.0.1:١٢٣")  # digits, but not ASCII ones
    # two Host headers, joined by the middleware: which one a proxy believed is unknown
    assert not guard.host_ok("127.0.0.1:8080, rebind.attacker.example")


def test_the_lockout_of_everyone_is_logged_as_everyone() -> None:
    from topdress.display.hub import DisplayHub

    def lockouts(addresses: list[str]) -> list[dict[str, object]]:
        reports: list[tuple[str, dict[str, object]]] = []
        hub = DisplayHub(
            lambda: loads_config("[display]\n"),
            report=lambda k, d: reports.append((k, d)),
            clock=lambda: 100.0,
        )
        for address in addresses:
            hub.failed(address, "pin")
        return [d for k, d in reports if k == "display.pin_lockout"]

    # an attacker changing address, 1 guess each: everyone locked out, logged so
    (everyone,) = lockouts([f"10.0.1.{i}" for i in range(20)])
    assert everyone["address"] == "*" and everyone["lockout_s"] == 60.0
    (one,) = lockouts(["10.0.0.9"] * 5)
    assert one["address"] == "10.0.0.9"


async def test_one_pin_try_a_second_per_tab_not_per_dialog(
    user: User, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A wrong PIN, the dialog cancelled and opened again: the next try still waits its turn
    (the tab's, WRONG_PIN_DELAY_S set long here), so new dialogs give no faster guessing."""
    monkeypatch.setattr(pages, "client_is_remote", lambda: True)
    from topdress.display import actions

    monkeypatch.setattr(actions, "WRONG_PIN_DELAY_S", 30.0)
    reports: list[tuple[str, dict[str, object]]] = []
    term = Terminal()
    hub = DisplayHub(pinned, term.post, report=lambda k, d: reports.append((k, d)))
    hub.publish(working(operator="stopped"))
    register_pages(hub)
    await user.open("/")
    for _ in range(3):
        user.find(marker="start").click()
        await user.should_see(marker="pin")
        user.find(marker="pin").type("0000")
        user.find(marker="pin_ok").click()
        await asyncio.sleep(0.2)
        user.find("Cancel").click()
        await asyncio.sleep(0.1)
    assert [k for k, _ in reports] == ["display.pin_failed"]  # the 2nd and 3rd still wait
