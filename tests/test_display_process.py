"""The display process draws a page from the Snapshot contract alone: it never loads the
terminal, python-can, cantools or the ECU binding (the C extension)."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from multiprocessing.connection import Connection
from pathlib import Path

from topdress import i18n
from topdress.config import default_config
from topdress.display.options import DisplayOptions
from topdress.display.process import Hello
from topdress.view.snapshot import Snapshot

#: What the display process must not load (module names as Python's -X importtime prints them).
FORBIDDEN = ("topdress.terminal", "topdress.ecu", "topdress.sim", "topdress.cli", "can", "cantools")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _serving(port: int, timeout_s: float) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return True
        time.sleep(0.1)
    return False


def _loaded(names: str) -> set[str]:
    """The modules a Python process imported, from its -X importtime report."""
    out = set()
    for line in names.splitlines():
        if line.startswith("import time:") and "|" in line:
            out.add(line.rsplit("|", 1)[1].strip())
    return out


def test_the_display_process_loads_no_terminal_no_python_can_no_c_extension(tmp_path: Path) -> None:
    port = _free_port()
    ours, theirs = socket.socketpair()
    env = dict(os.environ, PYTHONPROFILEIMPORTTIME="1")
    env.pop("PYTEST_CURRENT_TEST", None)  # NiceGUI would take a test port
    report = open(tmp_path / "imports.txt", "w+", encoding="utf-8")  # noqa: SIM115
    proc = subprocess.Popen(
        [sys.executable, "-m", "topdress.display", "--fd", str(theirs.fileno())],
        pass_fds=(theirs.fileno(),),
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=report,  # a pipe would fill up and stop the child
        env=env,
    )
    theirs.close()
    conn = Connection(ours.detach())
    try:
        conn.send(Hello(DisplayOptions("127.0.0.1", port), default_config(), i18n.language()))
        conn.send(("snap", Snapshot(t_s=1.0, running=True, v_kmh=8.0, faults=0b101)))
        assert _serving(port, 60.0), "the display never served its page"
        # A page drawn: the main screen renders the snapshot it was sent.
        with socket.create_connection(("127.0.0.1", port)) as s:
            s.sendall(b"GET / HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n")
            assert s.recv(64).startswith(b"HTTP/1.1 200")
    finally:
        conn.close()  # the display ends with its socket
        proc.wait(timeout=30)
        report.seek(0)
        loaded = _loaded(report.read())
        report.close()
    assert "topdress.display.pages" in loaded and "topdress.view.snapshot" in loaded
    bad = sorted(m for m in loaded if any(m == f or m.startswith(f + ".") for f in FORBIDDEN))
    assert bad == []
