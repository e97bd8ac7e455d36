"""Work counters for the field and for the season: area, kg per layer, working time, distance.

Two counters run side by side and are reset apart (a new field; a new season). They count
only what was applied: while the ECU reports a meter turning, from the speed it meters with
(its selected speed), the working width and the measured metering speed times kg/rev. They
live in a small JSON file beside the session logs, written atomically (a temporary file, then
rename) every `SAVE_PERIOD_S` and at the end, so a power cut loses at most that much work and
never leaves a half-written file. The periodic saves are written by a thread of their own: the
write ends in an fsync, which takes tens of milliseconds on a cab PC's flash (more on an SD
card), and the control loop must not wait for it.
"""

from __future__ import annotations

import datetime as dt
import json
import logging
import os
import threading
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any

from topdress.outpath import atomic_write
from topdress.view.snapshot import CounterView, TankView

log = logging.getLogger(__name__)

SAVE_PERIOD_S = 10.0
COUNTERS = ("field", "season")


def _now_iso() -> str:
    return dt.datetime.now().astimezone().isoformat(timespec="seconds")


def _from_json(raw: Any) -> CounterView:
    if not isinstance(raw, dict):
        raise ValueError("not an object")
    kg = raw.get("kg", [0.0, 0.0])
    return CounterView(
        area_ha=float(raw.get("area_ha", 0.0)),
        kg=(float(kg[0]), float(kg[1])),
        work_s=float(raw.get("work_s", 0.0)),
        distance_m=float(raw.get("distance_m", 0.0)),
        since=str(raw.get("since", "")),
    )


class _Saver:
    """Writes the newest text it is given, in a thread of its own (started at the first)."""

    def __init__(self, write: Callable[[str], None]) -> None:
        self._write = write
        self._cond = threading.Condition()
        self._text: str | None = None
        self._busy = False
        self._thread: threading.Thread | None = None

    def submit(self, text: str) -> None:
        with self._cond:
            self._text = text  # a newer text replaces one not yet written
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="counters", daemon=True)
                self._thread.start()
            self._cond.notify()

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._text is not None)
                text, self._text, self._busy = self._text, None, True
            try:
                assert text is not None
                self._write(text)
            finally:
                with self._cond:
                    self._busy = False
                    self._cond.notify_all()

    def wait(self, timeout_s: float = 10.0) -> bool:
        """Until nothing is left to write; False if the disk took longer than `timeout_s`."""
        with self._cond:
            return self._cond.wait_for(lambda: self._text is None and not self._busy, timeout_s)


class WorkCounters:
    """The field and season counters, persisted in `path` (None: in memory only)."""

    def __init__(self, path: Path | None) -> None:
        self.path = path
        self.error: str | None = None  # the last load/save problem, for the operator
        self.counters = {name: CounterView(since=_now_iso()) for name in COUNTERS}
        self.tank = TankView()  # the tank's fill and what is left: kept with the counters
        self._last_save_t: float | None = None
        self._dirty = False
        # Each counter as it was before its last reset, while the terminal runs: the reset can
        # be undone (a tap on the wrong counter) without losing what was counted since.
        self._before: dict[str, CounterView] = {}
        self._saver = _Saver(self._write)
        if path is not None:
            self._load(path)

    def _load(self, path: Path) -> None:
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return
        except OSError as exc:
            self.error = f"cannot read {path}: {exc}"
            log.warning("%s", self.error)
            return
        try:
            doc = json.loads(text)
            self.counters = {name: _from_json(doc[name]) for name in COUNTERS}
            self.tank = _tank(doc.get("tank"))
        except (ValueError, KeyError, IndexError, TypeError) as exc:
            # Kept aside, not overwritten: the season's figures may be recoverable by hand.
            aside = path.with_name(path.name + ".damaged")
            os.replace(path, aside)
            self.error = f"counters file {path} damaged ({exc}): moved to {aside}, counting anew"
            log.warning("%s", self.error)

    def add(self, area_ha: float, kg: tuple[float, float], dt_s: float, d_m: float) -> None:
        for name in COUNTERS:
            self.counters[name] = self.counters[name].add(area_ha, kg, dt_s, d_m)
        self._dirty = True

    def set_tank(self, tank: TankView) -> None:
        self.tank = tank
        self._dirty = True

    def reset(self, which: str) -> None:
        if which not in COUNTERS:
            raise ValueError(f"no counter {which!r} (known: {', '.join(COUNTERS)})")
        self._before[which] = self.counters[which]
        self.counters[which] = CounterView(since=_now_iso())
        self._dirty = True

    def undo(self, which: str) -> None:
        """The counter as before its last reset, plus what was counted since."""
        before = self._before.pop(which, None)
        if before is None:
            raise ValueError(f"no reset of {which!r} to undo")
        now = self.counters[which]
        self.counters[which] = before.add(now.area_ha, now.kg, now.work_s, now.distance_m)
        self._dirty = True

    def undoable(self) -> tuple[str, ...]:
        return tuple(name for name in COUNTERS if name in self._before)

    def view(self, which: str) -> CounterView:
        return self.counters[which]

    def maybe_save(self, now: float) -> None:
        """Save when something changed and SAVE_PERIOD_S has passed since the last save; the
        file is written in the background (the caller, the control loop, does not wait)."""
        if self._last_save_t is None:
            self._last_save_t = now
        if self._dirty and now - self._last_save_t >= SAVE_PERIOD_S:
            self._last_save_t = now
            self.save(wait=False)

    def save(self, wait: bool = True) -> None:
        """Write the counters as they are now; `wait` False: in the background."""
        if self.path is None:
            return
        doc: dict[str, Any] = {name: asdict(v) for name, v in self.counters.items()}
        doc["tank"] = asdict(self.tank)
        text = json.dumps(doc, indent=2)
        self._dirty = False
        if wait:
            self._saver.wait()  # an older text must not land after this one
            self._write(text + "\n")
        else:
            self._saver.submit(text + "\n")

    def _write(self, text: str) -> None:
        assert self.path is not None
        try:
            atomic_write(self.path, text)
        except OSError as exc:
            self.error = f"cannot save the counters to {self.path}: {exc}"
            log.warning("%s", self.error)
            self._dirty = True  # tried again at the next period


def _tank(raw: Any) -> TankView:
    """The tank as saved (absent in files of older versions: no fill entered)."""
    if raw is None:
        return TankView()
    fill, left, alarm = raw["fill_kg"], raw["remaining_kg"], raw["alarm_kg"]
    for v in (fill, left):
        if v is not None and not isinstance(v, int | float):
            raise TypeError(f"tank: {v!r} is not a number")
    if not isinstance(alarm, int | float):
        raise TypeError(f"tank: {alarm!r} is not a number")
    return TankView(
        None if fill is None else float(fill), None if left is None else float(left), float(alarm)
    )
