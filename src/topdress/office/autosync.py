"""The cab sending its sessions to the office by itself (`[office]` in its configuration).

A thread of its own wakes every `interval_s` and pushes every session of the log directory,
the one being recorded too (as far as it is committed): the control loop never waits for it,
and an office that is down, full or far away only delays the next try. The session files are
only read (`topdress.office.push`)."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from topdress.config import OfficeConfig
from topdress.errors import OfficeError
from topdress.office.push import session_files, sync
from topdress.office.schema import connect

_log = logging.getLogger(__name__)


@dataclass
class SyncState:
    """What the last round did, for the operator (read from any thread)."""

    rounds: int = 0
    sent_rows: int = 0  # state rows sent, all rounds
    last_error: str | None = None  # None: the last round sent everything


class OfficeSync:
    def __init__(
        self,
        cfg: OfficeConfig,
        sessions: str | Path,
        interval_s: float | None = None,
        on_message: Callable[[str], None] | None = None,
    ) -> None:
        self.cfg = cfg
        self.sessions = Path(sessions)
        self.interval_s = cfg.interval_s if interval_s is None else interval_s
        self.state = SyncState()
        self._say = on_message or (lambda m: None)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="office-sync", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout_s: float = 5.0) -> None:
        """Stop after the push under way (its batch commits or is sent again next time)."""
        self._stop.set()
        self._thread.join(timeout_s)

    def _run(self) -> None:
        while not self._stop.wait(self.interval_s):
            self.round()

    def round(self) -> None:
        """One sync of every session (never raises: the cab goes on without an office)."""
        try:
            out = sync(
                lambda: connect(self.cfg.url),
                session_files(self.sessions) if self.sessions.is_dir() else [],
                farm=self.cfg.farm,
                retries=0,
            )
        except OfficeError as exc:
            out = None
            error: str | None = str(exc)
        except Exception as exc:  # the cab must keep working whatever the office does
            _log.exception("office sync failed")
            out, error = None, f"office sync failed: {exc}"
        if out is not None:
            self.state.sent_rows += sum(r.state_sent for r in out.pushed)
            error = "; ".join(f"{p.name}: {e}" for p, e in out.failed) or None
        if error is not None and error != self.state.last_error:
            _log.warning("office sync: %s", error)
            self._say(f"office: {error}")
        self.state.last_error = error
        self.state.rounds += 1
