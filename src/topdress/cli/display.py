"""The display beside a running terminal: what `topdress run` and `topdress demo` call.

`DisplayLink` is the terminal's end of the display process (topdress.display.process): it
starts the process, feeds it and carries its commands to the terminal. `publish` only appends to
a bounded deque and sets an event (the control loop never waits on the display); a sender
thread pickles and writes. A display that dies, or hangs with the socket full, costs the
terminal nothing: snapshots are dropped (oldest first).

The link also keeps the display alive: the display process says every 0.5 s that it serves
and how many pages are connected; one that ended, stopped saying so, or never started serving
is started again (after 0.5 s, then with a doubling wait up to 30 s; counted, each start an
event in the session log), and the terminal's desk hears each change (`DisplayState`: the
display's alarms, and the meters paused when the operator has lost it, terminal/surface.py).
Everything the display process writes reaches the console escaped and prefixed `display: `.
"""

from __future__ import annotations

import contextlib
import json
import os
import secrets
import signal
import socket
import stat
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from topdress import i18n
from topdress.config import TerminalConfig
from topdress.display.guard import printable
from topdress.display.options import DisplayError, DisplayOptions, check_security, port_free
from topdress.display.peercred import kiosk_uid
from topdress.display.process import Hello
from topdress.terminal.app import Terminal
from topdress.view import commands as op
from topdress.view.commands import CommandResult, DisplayEvent, DisplayState
from topdress.view.snapshot import Snapshot

STOP_WAIT_S = 2.0  # for the display process to end with its socket before it is terminated
SNAPSHOT_BACKLOG = 600  # a minute of snapshots held while the display catches up
RESTART_BACKOFF_S = (0.5, 1.0, 2.0, 4.0, 8.0, 15.0, 30.0)  # waits before each next start
STABLE_S = 60.0  # a display that served this long starts its waits over
START_TIMEOUT_S = 30.0  # from its start to its first "alive" (importing NiceGUI takes seconds)
ALIVE_TIMEOUT_S = 3.0  # then: silent this long, it hangs; it is killed and started again
WATCH_PERIOD_S = 0.1
#: While the meters are on, a display that went down is tried again at least this often: the
#: back-off never leaves the driver without Stop on screen for long (display.lost_pause_s).
METERING_RETRY_S = 1.0
#: The watch waking this late was the terminal itself stalled (suspended, swapped out), not
#: the display: its silence meanwhile is not held against it.
STALL_S = 1.0
#: The events a display process may put into the session log.
DISPLAY_EVENTS = ("display.pin_failed", "display.pin_lockout")


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


def kiosk_token(path: str) -> str:
    """The cab's kiosk token from `path` ("" when none is configured); a missing file is
    created with a new random token, readable by its owner only. DisplayError when the file
    can be read by others or cannot be made."""
    if not path:
        return ""
    p = os.path.expanduser(path)
    try:
        fd = os.open(p, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        pass
    except OSError as exc:
        raise DisplayError(f"display.kiosk_token_file {path}: {exc.strerror}") from None
    else:
        with os.fdopen(fd, "w") as f:
            f.write(secrets.token_urlsafe(24) + "\n")
    try:
        mode = os.stat(p).st_mode
        token = open(p, encoding="utf-8").read().strip()  # noqa: SIM115 (closed at once)
    except (OSError, UnicodeDecodeError) as exc:
        raise DisplayError(f"display.kiosk_token_file {path}: {exc}") from None
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise DisplayError(f"display.kiosk_token_file {path} can be read by others: chmod 600 it")
    if len(token) < 16 or not token.isascii() or not token.isprintable() or " " in token:
        raise DisplayError(
            f"display.kiosk_token_file {path}: the token must be 16 or more printable "
            "characters without spaces (delete the file: a new one is made)"
        )
    return token


PREFS_FILE = "display-prefs.json"  # night mode and units, in log.dir
UNITS = ("metric", "imperial")


def load_prefs(path: Path) -> tuple[bool, str]:
    """(night, units) from `path`; the defaults when it is missing or not ours."""
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False, "metric"
    if not isinstance(doc, dict):
        return False, "metric"
    night, units = doc.get("night"), doc.get("units")
    return night is True, units if units in UNITS else "metric"


class _Child:
    """One display process and its socket."""

    def __init__(self, proc: subprocess.Popen[bytes], conn: Connection) -> None:
        self.proc = proc
        self.conn = conn
        self.started = time.monotonic()
        self.alive_at: float | None = None
        self.pages = 0
        self.error: str | None = None
        self.ended = threading.Event()

    def kill(self) -> None:
        if self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):  # its group: nothing of it lives on
                os.killpg(self.proc.pid, signal.SIGKILL)
        self.proc.wait()


class DisplayLink:
    """The terminal's end: starts the display process, feeds it, carries its commands, and
    starts it again when it ends or hangs."""

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
        self._lock = threading.Lock()
        self._cfg: TerminalConfig | None = None
        self._child: _Child | None = None
        self._kiosk = ""
        self.restarts = 0  # starts after the first
        self._failures = 0  # in a row: the index into RESTART_BACKOFF_S
        self._next_start = 0.0
        self._down_since: float | None = None
        self._told: DisplayState | None = None
        self._why_restarted = ""
        self.metering = False  # the operator has the meters on (the last snapshot's state)
        self.prefs_path: Path | None = None  # where they are kept (start: in log.dir)
        self.prefs = (False, "metric")  # (night, units)

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
        self._kiosk = kiosk_token(self.term.cfg.display.kiosk_token_file)
        if self.term.cfg.display.kiosk_user:
            kiosk_uid(self.term.cfg.display.kiosk_user)  # a wrong name is said now, not served
        self.keep_prefs_in(Path(self.term.cfg.log.dir) / PREFS_FILE)
        self._cfg = self.term.cfg
        self._spawn()
        for target, name in ((self._send, "display-tx"), (self._watch, "display-watch")):
            threading.Thread(target=target, name=name, daemon=True).start()
        return self.opts.url

    def _spawn(self) -> None:
        ours, theirs = socket.socketpair()
        env = dict(os.environ)
        env.pop("PYTEST_CURRENT_TEST", None)  # NiceGUI would take a test port
        proc = subprocess.Popen(
            [sys.executable, "-m", "topdress.display", "--fd", str(theirs.fileno())],
            pass_fds=(theirs.fileno(),),
            stdin=subprocess.DEVNULL,
            stderr=subprocess.PIPE,  # read, escaped, by the terminal (_relay)
            env=env,
            # Its own process group: Ctrl-C on the terminal's console stops the terminal, which
            # then closes the socket, and the display ends with it.
            start_new_session=True,
        )
        theirs.close()
        child = _Child(proc, Connection(ours.detach()))
        # The options (the PIN and the kiosk token with them) go over the socket, never on a
        # command line. A started-again display takes the configuration in force now.
        cfg = self.term.cfg
        night, units = self.prefs
        child.conn.send(Hello(self.opts, cfg, i18n.language(), self._kiosk, night, units))
        with self._lock:
            self._cfg = cfg
            self._child = child
        for target, name in ((self._receive, "display-rx"), (self._relay, "display-err")):
            threading.Thread(target=target, args=(child,), name=name, daemon=True).start()
        self._tell(DisplayState("starting", 0, "", self.restarts))

    def stop(self) -> None:
        """Close the socket (the display process ends with it) and wait for the process."""
        self._stop.set()
        self._wake.set()
        with self._lock:
            child = self._child
        if child is None:
            return
        child.conn.close()
        try:
            child.proc.wait(timeout=STOP_WAIT_S)
        except subprocess.TimeoutExpired:  # still importing NiceGUI, say
            child.kill()

    @property
    def pid(self) -> int | None:
        with self._lock:
            return self._child.proc.pid if self._child is not None else None

    # ---- the control loop's side -----------------------------------------------------------
    def publish(self, snapshot: Snapshot) -> None:
        """Hand the tick's snapshot over (constant time; never waits on the display)."""
        if self.term.cfg is not self._cfg:  # settings applied: the display shows the new ones
            self._cfg = self.term.cfg
            self._out.append(("cfg", self._cfg))
        self.metering = snapshot.operator != op.STOPPED
        self._snaps.append(snapshot)
        self._wake.set()

    # ---- threads -----------------------------------------------------------------------------
    def _send(self) -> None:
        while not self._stop.is_set():
            self._wake.wait()
            self._wake.clear()
            with self._lock:
                child = self._child
            if child is None:  # down: the newest snapshots wait (bounded) for the next one
                continue
            try:
                while self._out:
                    child.conn.send(self._out.popleft())
                while self._snaps:
                    child.conn.send(("snap", self._snaps.popleft()))
            except (OSError, ValueError, TypeError):  # gone: the watch starts another
                child.ended.set()

    def _receive(self, child: _Child) -> None:
        while not self._stop.is_set():
            try:
                msg = child.conn.recv()
            except (EOFError, OSError, ValueError, TypeError):  # TypeError: closed under it
                child.ended.set()
                return
            kind = msg[0]
            if kind == "alive":
                child.alive_at = time.monotonic()
                child.pages = int(msg[1])
            elif kind == "error":
                child.error = printable(str(msg[1]))
            elif kind == "cmd":
                self._command(int(msg[1]), msg[2])
            elif kind == "prefs":
                self.take_prefs(bool(msg[1]), str(msg[2]))
            elif kind == "lang":
                i18n.set_language(str(msg[1]))  # the console follows
            elif kind == "event" and msg[1] in DISPLAY_EVENTS:
                detail = {
                    str(k): printable(v, 64) if isinstance(v, str) else v
                    for k, v in dict(msg[2]).items()
                    if isinstance(v, str | int | float)
                }
                self.term.post(DisplayEvent(str(msg[1]), detail))

    def keep_prefs_in(self, path: Path) -> None:
        """Night mode and units from `path` (a terminal started again), kept there."""
        self.prefs_path = path
        self.prefs = load_prefs(path)

    def take_prefs(self, night: bool, units: str) -> None:
        """The operator's night mode and units: kept for the next display process and in
        `prefs_path` for the next terminal (a file that cannot be written is said)."""
        if units not in UNITS:
            return
        self.prefs = (night, units)
        if self.prefs_path is None:
            return
        try:
            self.prefs_path.parent.mkdir(parents=True, exist_ok=True)
            self.prefs_path.write_text(json.dumps({"night": night, "units": units}) + "\n")
        except OSError as exc:
            self.message(f"display: view preferences not saved ({exc.strerror})")

    def _relay(self, child: _Child) -> None:
        """What the display process writes (its log, a traceback): to the console, each line
        escaped (a request's path may hold escape codes or line breaks) and marked as its."""
        assert child.proc.stderr is not None
        for raw in child.proc.stderr:
            line = raw.decode("utf-8", "replace").rstrip("\r\n")
            if line and not self._stop.is_set():
                self.message(f"display: {printable(line)}")

    def _command(self, cid: int, command: Any) -> None:
        def done(fut: Future[CommandResult]) -> None:
            # In the control loop's thread: only queue the answer, the sender writes it.
            self._out.append(("result", cid, fut.result()))
            self._wake.set()

        self.term.post(command).add_done_callback(done)

    # ---- keeping it alive ------------------------------------------------------------------
    def _watch(self) -> None:
        last = time.monotonic()
        while not self._stop.wait(WATCH_PERIOD_S):
            with self._lock:
                child = self._child
            now = time.monotonic()
            if now - last > STALL_S and child is not None:
                self.after_stall(child, now - last - WATCH_PERIOD_S)
            last = now
            if child is None:
                if now >= self._next_start:
                    self._start_again()
                continue
            why = self._why_down(child, now)
            if why is not None:
                self._down(child, why, now)
            elif child.alive_at is not None:
                if self._down_since is not None:
                    self._back(now)
                if now - child.started >= STABLE_S:
                    self._failures = 0
                self._tell(DisplayState("ok", child.pages, "", self.restarts))

    @staticmethod
    def after_stall(child: _Child, stall_s: float) -> None:
        """The terminal did not run for `stall_s`: neither did its reading of the display's
        "alive" messages, which may still wait in the socket. The display's times move on by
        the stall, so a healthy one is not killed for the terminal's own pause."""
        child.started += stall_s
        if child.alive_at is not None:
            child.alive_at += stall_s

    def _back(self, now: float) -> None:
        """The display serving again: the outage the driver had, from down to serving."""
        assert self._down_since is not None
        down_s = now - self._down_since
        self._down_since = None
        self.term.post(
            DisplayEvent(
                "display.restarted",
                {"n": self.restarts, "why": self._why_restarted, "down_s": round(down_s, 2)},
            )
        )

    def _wait_s(self) -> float:
        """The wait before the next start: growing, unless the meters are on."""
        wait_s = RESTART_BACKOFF_S[min(self._failures, len(RESTART_BACKOFF_S) - 1)]
        self._failures += 1
        return min(wait_s, METERING_RETRY_S) if self.metering else wait_s

    def _why_down(self, child: _Child, now: float) -> str | None:
        code = child.proc.poll()
        if code is not None or child.ended.is_set():
            if code is None:
                try:
                    code = child.proc.wait(timeout=0.5)
                except subprocess.TimeoutExpired:
                    return "its socket closed"
            if child.error is not None:
                return child.error
            return f"killed by signal {-code}" if code < 0 else f"exit code {code}"
        if child.alive_at is None and now - child.started > START_TIMEOUT_S:
            return f"not serving {START_TIMEOUT_S:g} s after its start"
        if child.alive_at is not None and now - child.alive_at > ALIVE_TIMEOUT_S:
            return f"no answer for {ALIVE_TIMEOUT_S:g} s"
        return None

    def _down(self, child: _Child, why: str, now: float) -> None:
        with self._lock:
            self._child = None
        child.conn.close()
        child.kill()
        if child.alive_at is not None and now - child.started >= STABLE_S:
            self._failures = 0
        wait_s = self._wait_s()
        self._next_start = now + wait_s
        if self._down_since is None:
            self._down_since = now
        self._tell(DisplayState("down", 0, why, self.restarts))
        self.message(f"display down ({why}); starting it again in {wait_s:g} s")

    def _start_again(self) -> None:
        why = self._told.why if self._told is not None else ""
        if not port_free(self.opts.host, self.opts.port):
            self._down_since = self._down_since or time.monotonic()
            wait_s = self._wait_s()
            self._next_start = time.monotonic() + wait_s
            busy = f"{self.opts.host}:{self.opts.port} is in use"
            self._tell(DisplayState("down", 0, busy, self.restarts))
            self.message(f"display down ({busy}); trying again in {wait_s:g} s")
            return
        self.restarts += 1
        self._why_restarted = why  # told with the outage once the new one serves (_back)
        try:
            self._spawn()
        except OSError as exc:  # no process could be made (memory, file descriptors)
            self._next_start = time.monotonic() + RESTART_BACKOFF_S[-1]
            self._tell(DisplayState("down", 0, f"cannot start: {exc}", self.restarts))
            return
        self.message(f"display started again ({self.restarts} restarts)")

    def _tell(self, state: DisplayState) -> None:
        """The terminal's desk hears each change of the display's state (alarms, pause)."""
        if state != self._told:
            self._told = state
            self.term.post(state)
