"""The display beside a running terminal: what `topdress run` and `topdress demo` call.

`DisplayLink` is the terminal's end of the display process (topdress.display.process): it
starts the process, feeds it and carries its commands to the terminal. `publish` only appends to
a bounded deque and sets an event (the control loop never waits on the display); a sender
thread pickles and writes. A display that dies, or hangs with the socket full, costs the
terminal nothing: snapshots are dropped (oldest first) and the terminal says once that the
display stopped.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import threading
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future
from multiprocessing.connection import Connection
from typing import Any

from topdress import i18n
from topdress.config import TerminalConfig
from topdress.display.options import DisplayError, DisplayOptions, check_security, port_free
from topdress.display.process import Hello
from topdress.terminal.app import Terminal
from topdress.view.commands import CommandResult
from topdress.view.snapshot import Snapshot

STOP_WAIT_S = 2.0  # for the display process to end with its socket before it is terminated
SNAPSHOT_BACKLOG = 600  # a minute of snapshots held while the display catches up


def display_options(
    cfg: TerminalConfig, enabled: bool | None, host: str | None, port: int | None
) -> DisplayOptions | None:
    """The `[display]` settings with the command line's over them; None when off.
    DisplayError when the address needs a PIN that is not set."""
    dc = cfg.display
    if not (dc.enabled if enabled is None else enabled):
        return None
    opts = DisplayOptions(host=host or dc.host, port=port or dc.port, pin=dc.pin)
    check_security(opts)
    return opts


class AttachedDisplay:
    """What the control loop publishes into; None inside when the display could not start."""

    def __init__(self, link: DisplayLink | None) -> None:
        self.link = link

    def publish(self, snapshot: Snapshot) -> None:
        if self.link is not None:
            self.link.publish(snapshot)

    def stop(self) -> None:
        if self.link is not None:
            self.link.stop()


def serve_display(
    term: Terminal, opts: DisplayOptions, message: Callable[[str], None]
) -> AttachedDisplay:
    """Serve the display for `term` from its own process; a display that cannot start is
    said and left out (the terminal works without it)."""
    i18n.set_language(term.cfg.display.language)
    link = DisplayLink(term, opts, message)
    try:
        url = link.start()
    except DisplayError as exc:
        message(f"display not served: {exc}")
        return AttachedDisplay(None)
    message(f"display: {url}")
    return AttachedDisplay(link)


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
