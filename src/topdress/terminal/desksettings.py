"""The operator's settings changed while running: checked, pushed to the ECU or a device
opened anew, saved to the configuration file, then taken by the loop's parts.

A section of ECU parameters is pushed while the meters are stopped, and committed once the ECU
took every value; a refusal puts back what it took of the change. A topdress ECU on an ISOBUS
held after it refused a parameter of its first push takes the change saved at once and the
whole push again (terminal.busswitch). A changed [gnss] or [crop] section opens its line
source anew (only when a key it is opened with changed); a changed [can] section opens its bus
in its own thread and is answered once the link is on it.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from concurrent.futures import Future
from dataclasses import replace
from pathlib import Path
from typing import Any

from topdress import protocol
from topdress.config import TerminalConfig
from topdress.config_edit import (
    DEVICE_KEYS,
    ECU_SECTIONS,
    RESTART_SECTIONS,
    changed_device_keys,
    changed_ecu_params,
    changed_keys,
    save_section,
    section_version,
    validate_section,
)
from topdress.errors import ConfigError, DeviceError
from topdress.i18n import Text, text
from topdress.terminal.alarms import AlarmBook
from topdress.terminal.busswitch import BusSwitch
from topdress.terminal.journal import Journal, Settings
from topdress.terminal.lines import Lines
from topdress.view import commands as op
from topdress.view.links import link_state

log = logging.getLogger(__name__)


class SettingsDesk:
    """A settings change from the operator (`apply`), one at a time; `state` says, per dotted
    key of the last change, pending, ok, refused: <reason> or put back."""

    def __init__(
        self,
        settings: Settings,
        journal: Journal,
        lines: Lines,
        can: BusSwitch,
        operator: op.Operator,
        alarms: AlarmBook,
        told: Callable[[Text], op.CommandResult],
        config_path: Path | None,
    ) -> None:
        """`told(message)`: the operator told a command is done, and its result."""
        self._settings = settings
        self._journal = journal
        self._lines = lines
        self._can = can
        self._op = operator
        self._alarms = alarms
        self._told = told
        self.config_path = config_path
        self.pending: Future[op.CommandResult] | None = None  # settings awaiting the ECU
        self.state: dict[str, str] = {}

    def apply(
        self, now: float, c: op.ApplySettings, fut: Future[op.CommandResult] | None
    ) -> op.CommandResult | None:
        if self.pending is not None:
            raise op.OperatorError(text("op.error.settings_busy"))
        if c.base is not None and c.base != section_version(self._settings.cfg, c.section):
            # Applied from another screen since this one was filled: its values would undo it.
            return op.CommandResult(
                False, text("op.error.stale", section=c.section), {c.section: "stale"}, "stale"
            )
        new = validate_section(self._settings.cfg, c.section, c.values)
        if c.section in ECU_SECTIONS:
            changed = changed_ecu_params(self._settings.cfg, new)
            if changed and self._can.refused is not None:
                # The ECU on an ISOBUS refused one at start and is held: the change may mend
                # it, and is pushed with all the others from the top (refused: the alarm again).
                done = self._commit(now, c, new)
                self._can.push_again(now)
                return done
            if changed and self._can.pushes_params:
                return self._push(now, c, new, changed, fut)
            # An ISOBUS implement that is not a topdress ECU has none: taken as it is, and
            # pushed to a topdress ECU served again in place of the values it had.
            self._can.link.renew(changed)
        elif c.section in DEVICE_KEYS:
            keys = changed_device_keys(self._settings.cfg, new, c.section)
            if c.section == "can":  # the CAN link starts over on any change of [can]
                self._open_can(c, new, keys, fut)
                return None  # answered once the new bus is open
            try:
                # A line source is opened again only when the keys it is opened with changed.
                if keys:
                    self._lines.reopen(c.section, new)
            except DeviceError as exc:  # the old device stays; the keys that made it fail said
                return op.CommandResult(
                    False, str(exc), dict.fromkeys(keys or [c.section], str(exc))
                )
        return self._commit(now, c, new)

    def _open_can(
        self,
        c: op.ApplySettings,
        new: TerminalConfig,
        keys: list[str],
        fut: Future[op.CommandResult] | None,
    ) -> None:
        """The new bus opens in its own thread (the loop goes on, on the old one); the answer
        comes once it is open, or names why it cannot be (the old one stays)."""
        pending: Future[op.CommandResult] = fut if fut is not None else Future()
        self.pending = pending

        def done(error: str | None) -> None:
            self.pending = None
            if error is None:
                pending.set_result(self._commit_later(c, new))
            else:  # the keys that made it fail said
                errors = dict.fromkeys(keys or [c.section], error)
                pending.set_result(op.CommandResult(False, error, errors))

        self._can.open_can(new, done)

    def _commit_later(self, c: op.ApplySettings, new: TerminalConfig) -> op.CommandResult:
        """`_commit` once a device or the ECU has taken the change; a failure is the answer."""
        try:
            return self._commit(self._journal.clock(), c, new)
        except (op.OperatorError, ConfigError) as exc:
            why = exc.text if isinstance(exc, op.OperatorError) else str(exc)
            return op.CommandResult(False, text("op.error.not_saved", error=why))

    def _commit(self, now: float, c: op.ApplySettings, new: TerminalConfig) -> op.CommandResult:
        """Save the section to the file, then take the new configuration."""
        saved: Text
        if self.config_path is not None:
            try:
                new_file = save_section(self.config_path, c.section, c.values)
            except OSError as exc:
                raise op.OperatorError(
                    text("op.error.save", path=str(self.config_path), error=str(exc))
                ) from exc
            # The file may hold other sections than the running ones (edited meanwhile):
            # the running configuration takes only this section from it.
            new = _with_section(self._settings.cfg, new_file, c.section)
            saved = text("op.done.saved", path=str(self.config_path))
        else:
            saved = text("op.done.not_saved")
        for key, old_value, new_value in changed_keys(self._settings.cfg, new, c.section):
            self._journal.log_event(now, "setting.changed", key=key, old=old_value, new=new_value)
        self._settings.take(c.section, new)
        if c.section == "operator":
            self._alarms.retune(new.operator.off_rate_pct, new.operator.off_rate_s)
        later = text("op.done.later") if c.section in RESTART_SECTIONS else ""
        done = self._told(text("op.done.settings", section=c.section, saved=saved, later=later))
        return replace(done, data=section_version(self._settings.cfg, c.section))

    def _push(
        self,
        now: float,
        c: op.ApplySettings,
        new: TerminalConfig,
        changed: dict[int, float],
        fut: Future[op.CommandResult] | None,
    ) -> op.CommandResult | None:
        link = self._can.link
        if self._op.state != op.STOPPED:
            raise op.OperatorError(
                text(
                    "op.error.ecu_stopped",
                    section=c.section,
                    state=text(f"op.state.{self._op.state}"),
                )
            )
        if not (link.ready and link.params_done and link.ecu_alive):
            raise op.OperatorError(text("op.error.ecu_params", state=link_state(link.state)))
        old = self._settings.cfg.ecu_params()
        pending: Future[op.CommandResult] = fut if fut is not None else Future()
        self.pending = pending
        keys = {pid: protocol.param(pid).config_key for pid in changed}
        self.state = dict.fromkeys(keys.values(), "pending")

        def done(error: str | None, accepted: list[int]) -> None:
            self.pending = None
            if error is None:
                self.state = dict.fromkeys(keys.values(), "ok")
                pending.set_result(self._commit_later(c, new))
                return
            # Nothing half-applied: what the ECU took of this change goes back.
            back = {pid: old[pid] for pid in accepted if pid in old}
            if back:
                link.push_params(back, self._journal.clock(), _log_rollback)
            key = refused_key(error, changed, c.section)
            self.state = {keys[pid]: "put back" for pid in accepted if pid in keys}
            self.state[key] = f"refused: {error}"
            self._journal.event(text("event.settings_refused", section=c.section, error=error))
            pending.set_result(op.CommandResult(False, error, {key: error}))

        link.push_params(changed, now, done)
        return None if fut is not None else op.CommandResult(True, text("op.done.pushing"))


def _log_rollback(error: str | None, accepted: list[int]) -> None:
    if error is not None:
        log.warning("putting back the previous ECU parameters failed: %s", error)


def refused_key(error: str, changed: Iterable[int], section: str) -> str:
    """The configuration key (the display's field) an ECU's refusal is shown at: the key of the
    parameter the refusal names (`SwitchSpeed = 7: ...`), else the whole section."""
    name = error.split(" = ", 1)[0]
    for pid in changed:
        spec = protocol.param(pid)
        if spec.signal == name:
            return spec.config_key
    return section


def _with_section(running: TerminalConfig, from_file: TerminalConfig, section: str) -> Any:
    return replace(running, **{section: getattr(from_file, section)})
