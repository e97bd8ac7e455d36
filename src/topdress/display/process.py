"""The display process: NiceGUI on its main thread, fed by the terminal over a socket pair.

The terminal's control loop and its reader threads share one interpreter lock; a web server in
the same process would hold them up for milliseconds at a time. So the display is a child
process (`python -m topdress.display`), started and fed by the terminal's end,
topdress.cli.display.DisplayLink:

    terminal                                         display process
    control loop ─publish()─► DisplayLink ──snapshots, config──► reader ─► DisplayHub ─► pages
    Terminal.post ◄── receiver ◄──────────commands, language──── RemoteTerminal ◄─ buttons
                      sender ───────────────────results─────────► futures

The process imports the Snapshot contract (topdress.view), the configuration and the catalogue:
never the terminal, python-can or the ECU binding. It ends when the socket closes (the terminal
gone).
"""

from __future__ import annotations

import argparse
import itertools
import logging
import os
import threading
from concurrent.futures import Future
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any

from topdress import i18n
from topdress.config import TerminalConfig
from topdress.display.cpu import yield_to_the_terminal
from topdress.display.guard import printable
from topdress.display.options import DisplayOptions
from topdress.display.peercred import kiosk_uid
from topdress.view.commands import CommandResult

log = logging.getLogger(__name__)

DISPLAY_NICENESS = 5  # the display yields the CPU to the terminal


@dataclass(frozen=True)
class Hello:
    """The first message to the display: how to serve and what to show."""

    opts: DisplayOptions
    cfg: TerminalConfig
    language: str
    kiosk_token: str = ""  # the cab's browser's (display.kiosk_token_file); never on a command line
    night: bool = False  # the view's night mode and units as the operator last chose them
    units: str = "metric"


# ---- the display process ---------------------------------------------------------------------
class RemoteTerminal:
    """The display's end: the terminal's `post` over the socket, results back as futures."""

    def __init__(self, conn: Connection) -> None:
        self.conn = conn
        self.cfg: TerminalConfig | None = None
        self._lock = threading.Lock()
        self._ids = itertools.count(1)
        self._pending: dict[int, Future[CommandResult]] = {}

    def send(self, *msg: Any) -> None:
        with self._lock:
            self.conn.send(msg)

    def post(self, command: Any) -> Future[CommandResult]:
        fut: Future[CommandResult] = Future()
        cid = next(self._ids)
        self._pending[cid] = fut
        self.send("cmd", cid, command)
        return fut

    def report(self, kind: str, detail: dict[str, Any]) -> None:
        """An event for the terminal's session log (a wrong PIN, a lockout)."""
        self.send("event", kind, detail)

    def config(self) -> TerminalConfig:
        assert self.cfg is not None
        return self.cfg

    def resolve(self, cid: int, result: CommandResult) -> None:
        fut = self._pending.pop(cid, None)
        if fut is not None:
            fut.set_result(result)


def _serve(conn: Connection) -> int:

    from topdress.display.guard import Guard
    from topdress.display.hub import DisplayHub
    from topdress.display.server import run_server

    try:
        hello = conn.recv()
    except EOFError:  # the terminal ended before the display started
        return 0
    assert isinstance(hello, Hello)
    remote = RemoteTerminal(conn)
    remote.cfg = hello.cfg
    i18n.set_language(hello.language)
    hub = DisplayHub(
        remote.config,
        remote.post,
        on_language=lambda code: remote.send("lang", code),
        report=remote.report,
    )
    hub.set_prefs(hello.night, hello.units)
    # The terminal keeps them (and a file beside the session logs): a display started again,
    # or a terminal started again, shows what the operator chose.
    hub.on_prefs = lambda p: remote.send("prefs", p.night, p.units)
    dc = hello.cfg.display
    guard = Guard.of(
        dc.allowed_hosts,
        dc.trusted_proxies,
        hello.kiosk_token,
        kiosk_uid(dc.kiosk_user) if dc.kiosk_user else None,
    )

    def read() -> None:
        try:
            while True:
                msg = conn.recv()
                if msg[0] == "snap":
                    hub.publish(msg[1])
                elif msg[0] == "cfg":
                    remote.cfg = msg[1]
                elif msg[0] == "result":
                    remote.resolve(msg[1], msg[2])
        except (EOFError, OSError):
            pass  # the terminal is gone: so is the display
        os._exit(0)

    threading.Thread(target=read, name="display-rx", daemon=True).start()
    try:
        run_server(hub, hello.opts, guard, lambda pages: remote.send("alive", pages))
    except BaseException as exc:  # uvicorn's SystemExit on a port it cannot bind, too
        remote.send("error", f"{type(exc).__name__}: {exc}")
        return 1
    return 0


class _SafeFormatter(logging.Formatter):
    """A request's path or header in a log message (NiceGUI's "... not found") is written with
    its control characters escaped: no escape sequence or line of its own on the console."""

    def formatMessage(self, record: logging.LogRecord) -> str:
        return printable(super().formatMessage(record), limit=2000)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="topdress display process (started by the terminal)")
    ap.add_argument("--fd", type=int, required=True, help="the socket to the terminal")
    args = ap.parse_args(argv)
    yield_to_the_terminal(DISPLAY_NICENESS)
    handler = logging.StreamHandler()
    handler.setFormatter(_SafeFormatter("%(levelname)s %(name)s: %(message)s"))
    logging.basicConfig(level=logging.WARNING, handlers=[handler])
    return _serve(Connection(args.fd))
