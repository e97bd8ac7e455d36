"""The GNSS lag learned with each receiver, kept for the next session (terminal.gnsslag).

The last learned lag per receiver (topdress.terminal.receiver) in a small JSON file beside the
session logs, `STORE_FILE`, written atomically (in a background thread: the write ends in an
fsync). A file that cannot be read or parsed is an error told to the operator and logged, never
a crash: a damaged one is moved aside (`.damaged`) and the lags are learned anew.
"""

from __future__ import annotations

import datetime as dt
import json
import logging
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from topdress import protocol
from topdress.outpath import atomic_write
from topdress.terminal.receiver import ReceiverId

log = logging.getLogger(__name__)

STORE_FILE = "gnss-lag.json"
STORE_VERSION = 1
MAX_RECEIVERS = 32  # the file keeps the receivers used most recently
MAX_LAG_MS = round(protocol.param("GnssLag").maximum)  # GnssLag's range (DBC)


@dataclass(frozen=True)
class KeptLag:
    """The lag learned with one receiver, and when (local ISO time)."""

    receiver: ReceiverId
    lag_ms: int
    updated: str


def _now_iso() -> str:
    return dt.datetime.now().astimezone().isoformat(timespec="seconds")


def _strings(raw: Any, name: str) -> tuple[str, ...]:
    if not isinstance(raw, list) or not all(isinstance(x, str) for x in raw):
        raise ValueError(f"{name} is not a list of strings")
    return tuple(raw)


def _entry(raw: Any) -> KeptLag:
    if not isinstance(raw, dict):
        raise ValueError("a receiver is not an object")
    lag = raw.get("lag_ms")
    if type(lag) is not int or not 0 <= lag <= MAX_LAG_MS:
        raise ValueError(f"lag_ms {lag!r} is not a whole number of ms in 0..{MAX_LAG_MS}")
    where = raw.get("input")
    if not isinstance(where, str) or not where:
        raise ValueError("a receiver has no input")
    receiver = ReceiverId(
        where,
        tuple(sorted(_strings(raw.get("sentences", []), "sentences"))),
        _strings(raw.get("versions", []), "versions"),
    )
    return KeptLag(receiver, lag, str(raw.get("updated", "")))


def _as_json(k: KeptLag) -> dict[str, Any]:
    r = k.receiver
    return {
        "input": r.input,
        "sentences": list(r.sentences),
        "versions": list(r.versions),
        "lag_ms": k.lag_ms,
        "updated": k.updated,
    }


class LagStore:
    """The lags kept per receiver, in `path` (None: in memory only)."""

    def __init__(self, path: Path | None) -> None:
        self.path = path
        self.error: str | None = None  # the last load/save problem, for the operator
        self.kept: list[KeptLag] = []  # oldest first: the last is the most recent
        self._writer: ThreadPoolExecutor | None = None
        if path is not None:
            self._load(path)

    def _load(self, path: Path) -> None:
        try:
            raw = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return
        except (OSError, UnicodeDecodeError) as exc:
            self.error = f"cannot read {path}: {exc}"
            log.warning("%s", self.error)
            return
        try:
            doc = json.loads(raw)
            if not isinstance(doc, dict) or not isinstance(doc.get("receivers"), list):
                raise ValueError("not an object with a list of receivers")
            self.kept = [_entry(x) for x in doc["receivers"]]
        except (ValueError, RecursionError) as exc:
            aside = path.with_name(path.name + ".damaged")
            try:
                os.replace(path, aside)
                where = f"moved to {aside}"
            except OSError as err:
                where = f"not moved aside ({err})"
            self.kept = []
            self.error = f"{path} damaged ({exc}): {where}; the lag is learned anew"
            log.warning("%s", self.error)

    def for_input(self, where: str) -> KeptLag | None:
        """The lag kept most recently for a receiver on this input."""
        return next((k for k in reversed(self.kept) if k.receiver.input == where), None)

    def for_receiver(self, receiver: ReceiverId) -> KeptLag | None:
        """The lag kept for this receiver (topdress.terminal.receiver.ReceiverId.same)."""
        return next((k for k in reversed(self.kept) if k.receiver.same(receiver)), None)

    def keep(self, receiver: ReceiverId, lag_ms: int, wait: bool = True) -> None:
        """Keep `lag_ms` for `receiver` (it becomes the most recent) and write the file; with
        `wait` False in the background. The lag is bounded to GnssLag's 0..3000 ms."""
        lag = min(max(int(lag_ms), 0), MAX_LAG_MS)
        others = [k for k in self.kept if not k.receiver.same(receiver)]
        self.kept = [*others, KeptLag(receiver, lag, _now_iso())][-MAX_RECEIVERS:]
        if self.path is None:
            return
        doc = {"version": STORE_VERSION, "receivers": [_as_json(k) for k in self.kept]}
        body = json.dumps(doc, indent=2) + "\n"
        if wait:
            self.wait()
            self._write(body)
            return
        if self._writer is None:
            self._writer = ThreadPoolExecutor(max_workers=1, thread_name_prefix="gnss-lag")
        self._writer.submit(self._write, body)  # one worker: the newest text lands last

    def wait(self) -> None:
        """Until the background writes are done."""
        if self._writer is not None:
            self._writer.shutdown(wait=True)
            self._writer = None

    def _write(self, body: str) -> None:
        assert self.path is not None
        try:
            atomic_write(self.path, body)
        except OSError as exc:
            self.error = f"cannot save {self.path}: {exc}"
            log.warning("%s", self.error)
