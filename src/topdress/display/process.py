"""The display in its own process, beside the terminal's.

The terminal's control loop and its reader threads share one interpreter lock; a web server in
the same process (building page updates, charts, websocket frames) would hold them up for
milliseconds at a time. So the display is a child process (`python -m
topdress.display.process`, NiceGUI on its main thread), joined to the terminal by a socket pair:

    terminal                                         display process
    control loop ─publish()─► DisplayLink ──snapshots, config──► reader ─► DisplayHub ─► pages
    Terminal.post ◄── receiver ◄──────────commands, language──── RemoteTerminal ◄─ buttons
                      sender ───────────────────results─────────► futures

`publish` only appends to a bounded deque and sets an event (the control loop never waits on
the display); a sender thread pickles and writes. A display that dies, or hangs with the socket
full, costs the terminal nothing: snapshots are dropped (oldest first) and the terminal says
once that the display stopped. The child ends when the socket closes (the terminal gone).
"""

from __future__ import annotations

import argparse
import itertools
import logging
import os
import socket
import subprocess
import sys
import threading
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any

from topdress import i18n
from topdress.config import TerminalConfig
from topdress.display.cpu import yield_to_the_terminal
from topdress.display.server import DisplayError, DisplayOptions, check_security, port_free
from topdress.terminal.app import Snapshot, Terminal
from topdress.view.commands import CommandResult

log = logging.getLogger(__name__)

STOP_WAIT_S = 2.0  # for the display process to end with its socket before it is terminated
SNAPSHOT_BACKLOG = 600  # a minute of snapshots held while the display catches up
DISPLAY_NICENESS = 5  # the display yields the CPU to the terminal


@dataclass(frozen=True)
class Hello:
    """The first message to the display: how to serve and what to show."""

    opts: DisplayOptions
    cfg: TerminalConfig
    language: str


class DisplayLink:
    """The terminal's end: starts the display process, feeds it, carries its commands."""

    def __init__(
        self, term: Terminal, opts: DisplayOptions, message: Callable[[str], None]
    ) -> None:
        self.term = term
        self.opts = opts
        self.message = message
        self._snaps: deque[Snapshot] = deque(maxlen=SNAPSHOT_BACKLOG)
        self._out: deque[tuple[Any, ...]] = deque()  # results, config: never dropped
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._cfg: TerminalConfig | None = None
        self._proc: subprocess.Popen[bytes] | None = None
        self._conn: Connection | None = None
        self._error: str | None = None
        self._gone_told = False

    # ---- life cycle ----------------------------------------------------------------------
    def start(self) -> str:
        """Start the display process and return its address at once: the terminal does not
        wait for it (it listens within seconds; one that cannot is said on the console)."""
        check_security(self.opts)
        if not port_free(self.opts.host, self.opts.port):
            raise DisplayError(
                f"{self.opts.host}:{self.opts.port} is in use "
                "(another topdress? choose another with --port or display.port)"
            )
        ours, theirs = socket.socketpair()
        env = dict(os.environ)
        env.pop("PYTEST_CURRENT_TEST", None)  # NiceGUI would take a test port
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "topdress.display", "--fd", str(theirs.fileno())],
            pass_fds=(theirs.fileno(),),
            stdin=subprocess.DEVNULL,
            env=env,
            # Its own process group: Ctrl-C on the terminal's console stops the terminal, which
            # then closes the socket, and the display ends with it.
            start_new_session=True,
        )
        theirs.close()
        self._conn = Connection(ours.detach())
        # The options (the PIN with them) go over the socket, never on a command line.
        self._conn.send(Hello(self.opts, self.term.cfg, i18n.language()))
        self._cfg = self.term.cfg
        for target, name in ((self._receive, "display-rx"), (self._send, "display-tx")):
            threading.Thread(target=target, name=name, daemon=True).start()
        return self.opts.url

    def stop(self) -> None:
        """Close the socket (the display process ends with it) and wait for the process."""
        self._stop.set()
        self._wake.set()
        if self._conn is not None:
            self._conn.close()
        if self._proc is not None:
            try:
                self._proc.wait(timeout=STOP_WAIT_S)
            except subprocess.TimeoutExpired:  # still importing NiceGUI, say
                self._proc.terminate()
                self._proc.wait()

    @property
    def pid(self) -> int | None:
        return self._proc.pid if self._proc is not None else None

    # ---- the control loop's side -----------------------------------------------------------
    def publish(self, snapshot: Snapshot) -> None:
        """Hand the tick's snapshot over (constant time; never waits on the display)."""
        if self.term.cfg is not self._cfg:  # settings applied: the display shows the new ones
            self._cfg = self.term.cfg
            self._out.append(("cfg", self._cfg))
        self._snaps.append(snapshot)
        self._wake.set()

    # ---- threads -----------------------------------------------------------------------------
    def _send(self) -> None:
        assert self._conn is not None
        while not self._stop.is_set():
            self._wake.wait()
            self._wake.clear()
            try:
                while self._out:
                    self._conn.send(self._out.popleft())
                while self._snaps:
                    self._conn.send(("snap", self._snaps.popleft()))
            except (OSError, ValueError):  # the display process is gone
                self._gone("the display process closed its end")
                return

    def _receive(self) -> None:
        assert self._conn is not None
        while not self._stop.is_set():
            try:
                msg = self._conn.recv()
            except (EOFError, OSError, ValueError):
                self._gone("the display process ended")
                return
            kind = msg[0]
            if kind == "error":
                self._error = str(msg[1])
                self.message(f"display not served: {self._error}")
            elif kind == "cmd":
                self._command(int(msg[1]), msg[2])
            elif kind == "lang":
                i18n.set_language(str(msg[1]))  # the console follows

    def _command(self, cid: int, command: Any) -> None:
        def done(fut: Future[CommandResult]) -> None:
            # In the control loop's thread: only queue the answer, the sender writes it.
            self._out.append(("result", cid, fut.result()))
            self._wake.set()

        self.term.post(command).add_done_callback(done)

    def _gone(self, why: str) -> None:
        if not self._stop.is_set() and not self._gone_told and self._error is None:
            self._gone_told = True
            self.message(f"display stopped ({why}); the terminal works on")


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

    def config(self) -> TerminalConfig:
        assert self.cfg is not None
        return self.cfg

    def resolve(self, cid: int, result: CommandResult) -> None:
        fut = self._pending.pop(cid, None)
        if fut is not None:
            fut.set_result(result)


def _serve(conn: Connection) -> int:

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
    hub = DisplayHub(remote.config, remote.post, on_language=lambda code: remote.send("lang", code))

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
        run_server(hub, hello.opts)
    except BaseException as exc:  # uvicorn's SystemExit on a port it cannot bind, too
        remote.send("error", f"{type(exc).__name__}: {exc}")
        return 1
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="topdress display process (started by the terminal)")
    ap.add_argument("--fd", type=int, required=True, help="the socket to the terminal")
    args = ap.parse_args(argv)
    yield_to_the_terminal(DISPLAY_NICENESS)
    logging.basicConfig(level=logging.WARNING, format="display %(levelname)s %(name)s: %(message)s")
    return _serve(Connection(args.fd))
