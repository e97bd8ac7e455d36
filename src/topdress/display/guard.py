"""Who may reach the operating surface, and as whom: Host and Origin, the client's address, the
cab's own browser, PIN failures, and text from a request made safe for a console.

Pure Python (no NiceGUI, no Starlette): the display process wraps its web app in
`GuardMiddleware`; the terminal's end uses `printable` on everything the display process says.

- **Host**: an IP literal, `localhost`, or a name in `display.allowed_hosts`. A DNS-rebinding
  page (a name of the attacker's, resolved to 127.0.0.1 later) sends its own name as Host, so
  it is refused before anything is served.
- **Origin** (sent by browsers on socket.io's polling and websocket requests and on any
  cross-site request): the same host and port as Host, so a page of another site or port opened
  in the cab's browser cannot connect.
- **The client's address**: the peer's, unless the peer is one of `display.trusted_proxies`;
  only then is `X-Forwarded-For` read (its rightmost address that is not a trusted proxy).
- **The cab's own browser** (no PIN): with `display.kiosk_user`, a direct loopback connection
  whose socket belongs to that local user (the kernel's socket table, `peercred`): no secret on
  the browser's command line or in its history, nothing a page or another user can guess;
  with `display.kiosk_token_file`, the browser that opened
  `/?kiosk=TOKEN` once (kept as an HttpOnly, SameSite=Strict cookie) and no other; without it, a
  direct loopback connection that carries no forwarding header (a proxy on the cab PC would make
  every client loopback: it must be declared, and the kiosk token used).
"""

from __future__ import annotations

import hmac
import ipaddress
import unicodedata
from collections.abc import Awaitable, Callable, Iterable, MutableMapping
from dataclasses import dataclass, field
from typing import Any, Protocol
from urllib.parse import parse_qsl, urlencode, urlsplit

from topdress.display.peercred import socket_owner

Address = ipaddress.IPv4Address | ipaddress.IPv6Address
Network = ipaddress.IPv4Network | ipaddress.IPv6Network

KIOSK_COOKIE = "topdress_kiosk"
KIOSK_PARAM = "kiosk"
SCOPE_KEY = "topdress.client"  # where the middleware leaves a request's ClientInfo
FORWARDING_HEADERS = (b"x-forwarded-for", b"forwarded", b"x-real-ip", b"x-forwarded-host")


def printable(text: str, limit: int = 500) -> str:
    """`text` as one safe console line: control and format characters (escape sequences, line
    breaks, bidi overrides) written as `\\x1b`, `\\u202e`; cut at `limit` characters."""
    out = []
    for ch in text[:limit]:
        if unicodedata.category(ch) in ("Cc", "Cf", "Zl", "Zp"):
            code = ord(ch)
            out.append(f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}")
        else:
            out.append(ch)
    return "".join(out) + ("…" if len(text) > limit else "")


def _ip(text: str) -> Address | None:
    try:
        return ipaddress.ip_address(text.strip().strip("[]"))
    except ValueError:
        return None


def split_host(value: str) -> tuple[str, str]:
    """A Host header (or an Origin's netloc) as (name, port); the name lower-case, without a
    trailing dot or an IPv6 literal's brackets; the port "" when none is given."""
    value = value.strip().lower()
    if value.startswith("["):
        name, _, rest = value[1:].partition("]")
        return name, rest.removeprefix(":")
    name, _, port = value.partition(":") if value.count(":") == 1 else (value, "", "")
    return name.rstrip("."), port


@dataclass(frozen=True)
class ClientInfo:
    """A request's client as the display judges it."""

    address: str  # the peer's, or the forwarded one behind a trusted proxy
    cab: bool  # the cab's own browser: operating needs no PIN


@dataclass(frozen=True)
class Guard:
    allowed_hosts: frozenset[str] = frozenset()
    trusted_proxies: tuple[Network, ...] = ()
    kiosk_token: str = ""  # "": the cab's browser is a direct loopback connection
    kiosk_uid: int | None = None  # the cab's browser runs as this local user (display.kiosk_user)
    owner: Callable[[str, int, str, int], int | None] = socket_owner

    @classmethod
    def of(
        cls,
        allowed_hosts: Iterable[str],
        proxies: Iterable[str],
        kiosk: str,
        kiosk_uid: int | None = None,
    ) -> Guard:
        return cls(
            frozenset(split_host(h)[0] for h in allowed_hosts),
            tuple(ipaddress.ip_network(p, strict=False) for p in proxies),
            kiosk,
            kiosk_uid,
        )

    # ---- Host and Origin --------------------------------------------------------------------
    def host_ok(self, host: str) -> bool:
        """One Host (two are joined with ", " by the middleware: refused), its port digits."""
        if "," in host:
            return False
        name, port = split_host(host)
        if port and not (port.isascii() and port.isdigit() and int(port) <= 65535):
            return False
        return bool(name) and (
            _ip(name) is not None or name == "localhost" or name in self.allowed_hosts
        )

    def origin_ok(self, origin: str | None, host: str) -> bool:
        """No Origin (not a cross-site browser request), or the page's own: same host and
        port as the Host the request was sent to."""
        if origin is None:
            return True
        parts = urlsplit(origin)
        if parts.scheme not in ("http", "https") or not parts.netloc:
            return False  # "null" (a sandboxed frame, a file), anything else
        o_name, o_port = split_host(parts.netloc)
        h_name, h_port = split_host(host)
        default = "443" if parts.scheme == "https" else "80"
        # Behind a TLS proxy that passes the Host through, Host carries no port at all.
        return o_name == h_name and (o_port or default) == (h_port or default)

    # ---- the client ---------------------------------------------------------------------------
    def trusted(self, address: str) -> bool:
        ip = _ip(address)
        return ip is not None and any(ip in net for net in self.trusted_proxies)

    def client(
        self,
        peer: str,
        headers: dict[bytes, str],
        cookie_token: str,
        ports: tuple[str, int, int] = ("", 0, 0),
    ) -> ClientInfo:
        """Who sent a request: `peer` the socket's address, `headers` lower-case names,
        `cookie_token` the kiosk cookie's value ("" when none), `ports` the connection's
        (server address, peer port, server port) for `kiosk_uid`."""
        forwarded = any(h in headers for h in FORWARDING_HEADERS)
        address = peer
        if self.trusted(peer):
            hops = [h.strip() for h in headers.get(b"x-forwarded-for", "").split(",") if h.strip()]
            for hop in reversed(hops):
                address = hop
                if not self.trusted(hop):
                    break
        ip = _ip(peer)
        direct = ip is not None and ip.is_loopback and not forwarded and not self.trusted(peer)
        if self.kiosk_token or self.kiosk_uid is not None:
            cab = bool(self.kiosk_token and cookie_token) and hmac.compare_digest(
                cookie_token.encode(), self.kiosk_token.encode()
            )
            if not cab and direct and self.kiosk_uid is not None and ports[1]:
                server, peer_port, server_port = ports
                cab = self.owner(peer, peer_port, server, server_port) == self.kiosk_uid
        else:
            cab = direct
        return ClientInfo(printable(address, 64), cab)

    def kiosk_ok(self, given: str) -> bool:
        return bool(self.kiosk_token) and hmac.compare_digest(
            given.encode("utf-8", "replace"), self.kiosk_token.encode()
        )


# ---- PIN failures ----------------------------------------------------------------------------
PIN_MAX_FAILURES = 5  # wrong PINs from one address before it is locked out
PIN_WINDOW_S = 600.0  # failures older than this are forgotten
PIN_LOCKOUT_S = 60.0  # the first lockout; each next one doubles...
PIN_LOCKOUT_MAX_S = 900.0  # ...up to this
PIN_GLOBAL_MAX_FAILURES = 20  # from all addresses together (an attacker changing address)
GLOBAL = "*"


@dataclass
class _Record:
    failures: list[float] = field(default_factory=list)
    locked_until: float = 0.0
    lockouts: int = 0


@dataclass
class PinGate:
    """Counts wrong PINs per client address and in total; locks an address (or everyone, past
    the total) out for a time that doubles at each lockout. Time is passed in."""

    max_failures: int = PIN_MAX_FAILURES
    global_max_failures: int = PIN_GLOBAL_MAX_FAILURES
    window_s: float = PIN_WINDOW_S
    lockout_s: float = PIN_LOCKOUT_S
    lockout_max_s: float = PIN_LOCKOUT_MAX_S
    _records: dict[str, _Record] = field(default_factory=dict)

    def locked_for(self, address: str, now: float) -> float:
        """Seconds until `address` may try again (0: now)."""
        waits = [r.locked_until - now for k in (address, GLOBAL) if (r := self._records.get(k))]
        return max([0.0, *waits])

    def failed(self, address: str, now: float) -> tuple[int, float]:
        """A wrong PIN: (failures of this address in the window, the lockout it started in
        seconds, 0 when none)."""
        started = 0.0
        count = 0
        for key, limit in ((address, self.max_failures), (GLOBAL, self.global_max_failures)):
            r = self._records.setdefault(key, _Record())
            r.failures = [t for t in r.failures if now - t < self.window_s] + [now]
            if key == address:
                count = len(r.failures)
            if len(r.failures) >= limit:
                length = min(self.lockout_s * 2**r.lockouts, self.lockout_max_s)
                r.lockouts += 1
                r.failures.clear()
                r.locked_until = now + length
                started = max(started, length)
        if len(self._records) > 10_000:  # addresses never seen again: forget the oldest
            del self._records[next(k for k in self._records if k != GLOBAL)]
        return count, started

    def succeeded(self, address: str) -> None:
        self._records.pop(address, None)


# ---- the middleware ----------------------------------------------------------------------------
Scope = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[MutableMapping[str, Any]]]
Send = Callable[[MutableMapping[str, Any]], Awaitable[None]]
App = Callable[[Scope, Receive, Send], Awaitable[None]]


def _cookie(header: str, name: str) -> str:
    for part in header.split(";"):
        key, _, value = part.strip().partition("=")
        if key == name:
            return value
    return ""


class Attempts(Protocol):
    """Where guesses of a secret (the PIN, the kiosk token) are counted (the display's hub)."""

    def locked_for(self, address: str) -> float: ...

    def failed(self, address: str, what: str) -> None: ...


class GuardMiddleware:
    """ASGI middleware in front of the whole display (pages, static files, socket.io):
    refuses a foreign Host (421) or Origin (403), takes the kiosk token, and leaves the
    request's `ClientInfo` in its scope under SCOPE_KEY. A wrong kiosk token counts as a
    failed guess in `attempts`, as a wrong PIN does."""

    def __init__(self, app: App, guard: Guard, attempts: Attempts | None = None) -> None:
        self.app = app
        self.guard = guard
        self.attempts = attempts

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        headers: dict[bytes, str] = {}
        for key, value in scope.get("headers", ()):
            name = bytes(key).lower()
            text = bytes(value).decode("latin-1")
            headers[name] = f"{headers[name]}, {text}" if name in headers else text
        host = headers.get(b"host", "")
        target = bytes(scope.get("raw_path") or b"/")
        if scope["type"] == "http" and not target.startswith(b"/"):
            # absolute-form ("GET http://other.example/"): its host, not Host, is the one
            # asked for (RFC 9112 3.2.2); a browser sends it only to a proxy
            await _refuse(scope, send, 421, "this display is not a proxy\n")
            return
        if not self.guard.host_ok(host):
            await _refuse(scope, send, 421, "this display is not served under that name\n")
            return
        if not self.guard.origin_ok(headers.get(b"origin"), host):
            await _refuse(scope, send, 403, "cross-origin request refused\n")
            return
        peer = scope.get("client")
        server = scope.get("server") or ("", 0)
        cookie = _cookie(headers.get(b"cookie", ""), KIOSK_COOKIE)
        ports = (str(server[0]), int(peer[1]), int(server[1] or 0)) if peer else ("", 0, 0)
        info = self.guard.client(str(peer[0]) if peer else "", headers, cookie, ports)
        scope[SCOPE_KEY] = info
        if cookie and self.guard.kiosk_token and not info.cab and self.attempts is not None:
            self.attempts.failed(info.address, "kiosk_cookie")  # a guess too: counted, logged
        if scope["type"] == "http" and self.guard.kiosk_token:
            query = dict(parse_qsl(bytes(scope.get("query_string", b"")).decode("latin-1")))
            if KIOSK_PARAM in query:
                await self._kiosk(scope, send, info, query)
                return
        await self.app(scope, receive, send)

    async def _kiosk(
        self, scope: Scope, send: Send, info: ClientInfo, query: dict[str, str]
    ) -> None:
        given = query.pop(KIOSK_PARAM)
        # The right token passes even during a lockout: guesses of other sources (a page's
        # <img>, any local process) must not lock the cab out of its own display, and a
        # token of 256 random bits needs no lockout to stay unguessed. Wrong ones are counted.
        if not self.guard.kiosk_ok(given):
            locked = self.attempts is not None and self.attempts.locked_for(info.address) > 0
            if self.attempts is not None:
                self.attempts.failed(info.address, "kiosk")
            if locked:
                await _refuse(scope, send, 429, LOCKED_PAGE, "text/html")
            else:
                await _refuse(scope, send, 403, "wrong kiosk token\n")
            return
        # The token leaves the address bar: the cookie carries it from now on.
        location = str(scope.get("path", "/")) + (f"?{urlencode(query)}" if query else "")
        cookie = (
            f"{KIOSK_COOKIE}={self.guard.kiosk_token}; Path=/; HttpOnly; SameSite=Strict; "
            "Max-Age=315360000"
        )
        await send(
            {
                "type": "http.response.start",
                "status": 303,
                "headers": [
                    (b"location", location.encode("latin-1", "replace")),
                    (b"set-cookie", cookie.encode()),
                    (b"content-length", b"0"),
                ],
            }
        )
        await send({"type": "http.response.body", "body": b""})


#: A locked-out page: says where Stop is meanwhile and tries again by itself.
LOCKED_PAGE = """<!doctype html><html><head><meta charset="utf-8">
<meta http-equiv="refresh" content="5;url=/"><title>topdress</title></head>
<body style="font:24px sans-serif;background:#1b4332;color:#fff;padding:16px">
<p>Too many wrong attempts from this address: trying again in 5 s.</p>
<p><b>Stop</b>: the terminal's console (type <code>stop</code>) or the machine's stop switch.</p>
</body></html>
"""


async def _refuse(
    scope: Scope, send: Send, status: int, body: str, kind: str = "text/plain"
) -> None:
    if scope["type"] == "websocket":  # closed before acceptance: the server answers 403
        await send({"type": "websocket.close", "code": 1008})
        return
    data = body.encode()
    await send(
        {
            "type": "http.response.start",
            "status": status,
            "headers": [
                (b"content-type", f"{kind}; charset=utf-8".encode()),
                (b"content-length", str(len(data)).encode()),
            ],
        }
    )
    await send({"type": "http.response.body", "body": data})
