"""Losing the operator display: what the terminal does with the meters (virtual time, the
simulated machine), and the display process started again when it dies (a real process)."""

from __future__ import annotations

import os
import signal
import socket
import time
import urllib.request
from collections.abc import Callable, Iterator
from concurrent.futures import Future
from pathlib import Path
from typing import Any

import pytest

from test_operator import drive, make_rig, post, stand, straight
from topdress.cli.display import DisplayLink
from topdress.config import TerminalConfig, default_config
from topdress.display.options import DisplayOptions
from topdress.log.session import SessionLog, SessionReader
from topdress.terminal.surface import ALARM_ONLY_AFTER_S, DisplayWatch
from topdress.view import commands as op
from topdress.view.commands import CommandResult, DisplayEvent, DisplayState


def _alarms(rig: Any) -> dict[str, str]:
    return {a.name: a.state for a in rig.term.snapshot.alarms}


def test_the_meters_pause_when_the_operator_has_lost_the_display(tmp_path: Path) -> None:
    """A page was open; the display process dies while metering: `display_down` at once, and
    after display.lost_pause_s (10 s) the meters pause (fans on) with `display_lost`; a page
    back clears it, and only the operator's Start resumes."""
    session = SessionLog.create(tmp_path, "")
    rig = make_rig(drive(straight(8.0, 400.0)), autostart=True, session=session)
    try:
        rig.run(6.0)
        assert post(rig, DisplayState("ok", pages=1)).ok
        rig.run(8.0)
        t_lost = rig.world.t_s
        assert post(rig, DisplayState("down", 0, "killed by signal 9")).ok
        rig.run(t_lost + 9.8)
        s = rig.term.snapshot
        assert s.operator == "running" and s.meter_rpm[0] > 10.0  # within the grace time
        assert _alarms(rig) == {"display_down": "active"}
        rig.run(t_lost + 10.3)
        s = rig.term.snapshot
        assert s.operator == "paused" and s.rate_kg_ha == (0.0, 0.0)
        assert _alarms(rig) == {"display_down": "active", "display_lost": "active"}
        rig.run(t_lost + 13.0)
        assert rig.term.snapshot.meter_rpm[0] < 0.5 and min(rig.term.snapshot.fan_rpm) > 2500
        assert post(rig, DisplayState("starting", 0, "", 1)).ok
        assert post(rig, DisplayState("ok", 1, "", 1)).ok  # the page reconnected
        rig.run(t_lost + 14.0)
        assert rig.term.snapshot.operator == "paused"  # no restart of the meters by itself
        assert _alarms(rig) == {"display_down": "cleared", "display_lost": "cleared"}
        assert post(rig, op.Start()).ok
        rig.run(t_lost + 20.0)
        assert rig.term.snapshot.meter_rpm[0] > 10.0
    finally:
        rig.close()
    assert any(e.startswith("no operator display for 10 s: meters paused") for _, e in rig.events)
    with SessionReader(session.path) as reader:
        events = [(e.kind, dict(e.detail)) for e in reader.events()]
    lost = next(d for k, d in events if k == "display.lost")
    assert lost["paused"] is True and lost["why"] == "killed by signal 9"
    assert lost["lost_s"] == pytest.approx(10.0, abs=0.15)
    assert ("operator.pause", {"was": "running", "auto": True}) in events
    back = next(d for k, d in events if k == "display.back")
    assert back["lost_s"] == pytest.approx(13.0, abs=0.3)


def test_a_display_nobody_opened_is_an_alarm_when_down_and_never_pauses() -> None:
    """Headless with the display served (the console is the operator's surface): a display
    process that cannot start raises `display_down`, the meters go on."""
    rig = make_rig(drive(straight(8.0, 400.0)), autostart=True)
    try:
        rig.run(4.0)
        post(rig, DisplayState("starting"))
        post(rig, DisplayState("down", 0, "127.0.0.1:8080 is in use"))
        rig.run(30.0)
        assert rig.term.snapshot.operator == "running"
        assert _alarms(rig) == {"display_down": "active"}
    finally:
        rig.close()
    assert any(e == "alarm: operator display down: restarting it" for _, e in rig.events)


def test_no_page_for_the_grace_time_pauses_and_zero_means_the_alarm_only() -> None:
    """The display process fine, but the only page closed (the cab's browser crashed)."""
    rig = make_rig(drive(stand(1.0), straight(8.0, 400.0)), autostart=True)
    try:
        post(rig, DisplayState("ok", pages=1))
        post(rig, DisplayState("ok", pages=0))
        rig.run(12.0)
        assert rig.term.snapshot.operator == "paused"
        assert _alarms(rig) == {"display_lost": "active"}
    finally:
        rig.close()
    watch = DisplayWatch(lost_pause_s=0.0)  # [display] lost_pause_s = 0: never pause
    watch.take(DisplayState("ok", pages=1), 0.0)
    watch.take(DisplayState("ok", pages=0), 1.0)
    assert not watch.tick(1.0 + ALARM_ONLY_AFTER_S - 0.01).lost
    assert watch.tick(1.0 + ALARM_ONLY_AFTER_S).lost and not watch.pauses


# ---- the display process, started again --------------------------------------------------------
class RecordingTerminal:
    """The terminal as DisplayLink sees it: its configuration and `post` (answered at once)."""

    def __init__(self, cfg: TerminalConfig) -> None:
        self.cfg = cfg
        self.posted: list[Any] = []

    def post(self, command: Any) -> Future[CommandResult]:
        self.posted.append(command)
        fut: Future[CommandResult] = Future()
        fut.set_result(CommandResult(True))
        return fut

    def states(self) -> list[str]:
        return [c.state for c in self.posted if isinstance(c, DisplayState)]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def until(what: str, check: Callable[[], Any], timeout_s: float = 60.0) -> Any:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if result := check():
            return result
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


def answers(url: str) -> bool:
    try:
        with urllib.request.urlopen(url, timeout=2) as response:
            return bool(response.status == 200)
    except OSError:
        return False


@pytest.fixture
def served() -> Iterator[tuple[DisplayLink, RecordingTerminal, list[str]]]:
    term = RecordingTerminal(default_config())
    messages: list[str] = []
    link = DisplayLink(term, DisplayOptions("127.0.0.1", free_port()), messages.append)  # type: ignore[arg-type]
    link.start()
    try:
        until("the display serving", lambda: answers(link.opts.url))
        yield link, term, messages
    finally:
        link.stop()


def test_a_killed_display_is_started_again_counted_and_logged(
    served: tuple[DisplayLink, RecordingTerminal, list[str]],
) -> None:
    link, term, messages = served
    until("the display alive", lambda: term.states()[-1:] == ["ok"])
    first = link.pid
    assert first is not None
    os.kill(first, signal.SIGKILL)
    until("a new display process", lambda: link.pid not in (None, first))
    until("the new one serving", lambda: answers(link.opts.url))
    until("the desk told it is back", lambda: term.states()[-1:] == ["ok"])
    assert term.states() == ["starting", "ok", "down", "starting", "ok"]
    down = next(c for c in term.posted if isinstance(c, DisplayState) and c.state == "down")
    assert down.why == "killed by signal 9"
    (restarted,) = [c for c in term.posted if isinstance(c, DisplayEvent)]
    assert restarted.kind == "display.restarted" and restarted.detail["n"] == 1
    assert link.restarts == 1
    assert "display down (killed by signal 9); starting it again in 0.5 s" in messages


@pytest.mark.wallclock
def test_a_display_that_cannot_start_is_said_and_tried_again(
    served: tuple[DisplayLink, RecordingTerminal, list[str]],
) -> None:
    """Its port taken by another program while it was down: `down` with the reason, tried
    again with a growing wait, served once the port is free."""
    link, term, messages = served
    until("the display alive", lambda: term.states()[-1:] == ["ok"])
    pid = link.pid
    assert pid is not None
    os.kill(pid, signal.SIGKILL)
    until("the display down", lambda: link.pid is None)
    squatter = socket.socket()
    squatter.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    squatter.bind(("127.0.0.1", link.opts.port))
    squatter.listen()
    try:
        busy = f"127.0.0.1:{link.opts.port} is in use"
        until("the port refused", lambda: any(busy in m for m in messages))
        until("a second try", lambda: sum(busy in m for m in messages) >= 2)
        waits = [m.rsplit(" in ", 1)[1] for m in messages if busy in m]
        assert waits[:2] == ["1 s", "2 s"]  # after the first 0.5 s: doubling
        assert any(isinstance(c, DisplayState) and c.why == busy for c in term.posted)
    finally:
        squatter.close()
    until("served again", lambda: answers(link.opts.url), timeout_s=60.0)
    assert link.restarts == 1
