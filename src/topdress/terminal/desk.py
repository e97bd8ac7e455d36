"""The operator's desk inside the terminal loop: commands in, run state, alarms, counters,
calibration wizards and settings; the fields it adds to every Snapshot.

`Terminal.post(command)` puts a command and its Future on the terminal's inbox; the loop
hands it to `OperatorDesk.handle`, which acts and completes the Future (at once, or once the
ECU acknowledged settings). Nothing here blocks: device reopening and parameter pushes go on
over the following ticks. The desk is handed the parts of the loop it works with (`DeskParts`),
and keeps its calibration wizards (terminal.deskcal), settings changes (terminal.desksettings)
and device test (terminal.devicetest) in parts of its own.
"""

from __future__ import annotations

import logging
from concurrent.futures import Future
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from topdress.crop.sensors import CompensatedNdvi
from topdress.errors import ConfigError, ProtocolError
from topdress.i18n import Text, text
from topdress.terminal.alarms import AlarmBook, AlarmInputs
from topdress.terminal.busswitch import BusSwitch
from topdress.terminal.calibration import CalCommand, CalibrationError, Wizard
from topdress.terminal.counters import WorkCounters
from topdress.terminal.deskcal import CalDesk
from topdress.terminal.desksettings import SettingsDesk
from topdress.terminal.deskview import DeskView, applied_kg_ha, speed_why
from topdress.terminal.devicetest import DeviceTest
from topdress.terminal.inbox import Inbox
from topdress.terminal.journal import Journal, Settings
from topdress.terminal.leadcal import LeadCal
from topdress.terminal.lines import Lines
from topdress.terminal.site import UNKNOWN, OffMap
from topdress.terminal.surface import DisplayWatch
from topdress.view import commands as op
from topdress.view.snapshot import (
    Snapshot,
    TankView,
)

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DeskParts:
    """The parts of the loop the desk works with."""

    settings: Settings
    journal: Journal
    inbox: Inbox
    lines: Lines
    can: BusSwitch
    ndvi: CompensatedNdvi


class OperatorDesk:
    def __init__(self, parts: DeskParts, autostart: bool, config_path: Path | None) -> None:
        self._parts = parts
        self._settings = parts.settings
        self._journal = parts.journal
        cfg = parts.settings.cfg
        self.op = op.Operator(autostart)
        self.alarms = AlarmBook(cfg.operator.off_rate_pct, cfg.operator.off_rate_s)
        self.display = DisplayWatch(cfg.display.lost_pause_s)
        # Beside the session logs; a terminal without a session log (tests, a log that could
        # not be created) keeps them in memory only.
        session = parts.journal.session
        where = session.path.parent if session is not None else None
        self.counters = WorkCounters(where / cfg.operator.counters_file if where else None)
        if self.counters.error:
            parts.journal.event(text("event.counters_error", error=self.counters.error))
        self.settings = SettingsDesk(
            parts.settings,
            parts.journal,
            parts.lines,
            parts.can,
            self.op,
            self.alarms,
            self._done,
            config_path,
        )
        self.cal = CalDesk(
            parts.settings, parts.journal, parts.can, self.op, self._done, self.settings.apply
        )
        self.devices = DeviceTest(parts.settings, parts.lines, parts.can)
        self._t0: float | None = None  # when the loop opened
        self._last_t: float | None = None
        self._model_rates = (0.0, 0.0)
        self.tank = self.counters.tank  # as the last run left it (none: no fill entered yet)

    @property
    def wizard(self) -> Wizard | LeadCal | None:
        """The calibration wizard running (None: none)."""
        return self.cal.wizard

    def open(self, now: float) -> None:
        """The loop opened: headless, the meters start without an operator."""
        self._t0 = now
        if self.op.state == op.RUNNING:
            self._journal.log_event(now, "operator.start", was="stopped", auto=True)

    # ---- posting (any thread) ----------------------------------------------------------------
    def post(self, command: Any) -> Future[op.CommandResult]:
        fut: Future[op.CommandResult] = Future()
        self._parts.inbox.put(("op", self._journal.clock(), (command, fut)))
        return fut

    # ---- the loop ----------------------------------------------------------------------------
    def record(self, kind: str, t: float, payload: Any) -> None:
        """Keep the last inputs of each device for the device test."""
        self.devices.record(kind, t, payload)

    def handle(self, now: float, item: tuple[Any, Future[op.CommandResult]]) -> None:
        command, fut = item
        try:
            result = self._dispatch(now, command, fut)
        except (op.OperatorError, CalibrationError) as exc:
            result = op.CommandResult(False, exc.text)
        except ProtocolError as exc:
            result = op.CommandResult(False, str(exc))
        except ConfigError as exc:
            result = op.CommandResult(False, str(exc), {exc.key: _reason(exc)})
        if result is not None and not fut.done():
            fut.set_result(result)

    def _dispatch(
        self, now: float, c: Any, fut: Future[op.CommandResult]
    ) -> op.CommandResult | None:
        if isinstance(c, op.Start):
            was = self.op.state
            msg = self.op.start()
            self._journal.log_event(now, "operator.start", was=was)
            return self._done(msg)
        if isinstance(c, op.Stop):
            was = self.op.state
            self.cal.end()
            msg = self.op.stop()
            self._send_command_now()
            self._journal.log_event(now, "operator.stop", was=was)
            return self._done(msg)
        if isinstance(c, op.Pause):
            msg = self.op.pause()
            self._journal.log_event(now, "operator.pause", was=op.RUNNING)
            return self._done(msg)
        if isinstance(c, op.SetManual):
            msg = self.op.set_manual(c)
            self._manual_event(now)
            return self._done(msg)
        if isinstance(c, op.AckAlarm):
            if c.name is not None and not self.alarms.known(c.name):
                return op.CommandResult(False, text("op.error.no_alarm", name=c.name))
            acked = self.alarms.ack(c.name)
            for name in acked:
                self._journal.log_event(now, "alarm.acked", name=name)
            return op.CommandResult(True, text("op.done.acked", n=len(acked)))
        if isinstance(c, op.ResetCounter):
            try:
                self.counters.reset(c.which)
            except ValueError as exc:
                return op.CommandResult(False, str(exc))
            self.counters.save(wait=False)  # the loop does not wait on the disk
            self._journal.log_event(now, "counter.reset", which=c.which)
            return self._done(text("op.done.reset", which=text(f"count.{c.which}")))
        if isinstance(c, op.UndoReset):
            try:
                self.counters.undo(c.which)
            except ValueError:
                return op.CommandResult(False, text("op.error.no_undo", which=c.which))
            self.counters.save(wait=False)
            self._journal.log_event(now, "counter.undo", which=c.which)
            return self._done(text("op.done.undo", which=text(f"count.{c.which}")))
        if isinstance(c, op.FillTank):
            if not (0.0 < c.fill_kg < 1e6 and 0.0 <= c.alarm_kg < c.fill_kg):
                return op.CommandResult(
                    False, text("op.error.tank", fill=c.fill_kg, alarm=c.alarm_kg)
                )
            self.tank = TankView(c.fill_kg, c.fill_kg, c.alarm_kg)
            self.counters.set_tank(self.tank)
            self._journal.log_event(now, "tank.filled", fill_kg=c.fill_kg, alarm_kg=c.alarm_kg)
            return self._done(text("op.done.tank", kg=c.fill_kg, alarm=c.alarm_kg))
        if isinstance(c, op.Help):
            return op.CommandResult(False, c.text)
        if isinstance(c, op.DisplayState | op.DisplayEvent):
            return self._display_report(now, c)
        if isinstance(c, op.TestDevice):
            return self.devices.test(c.device, self._t0 or 0.0)
        if isinstance(c, op.ApplySettings):
            return self.settings.apply(now, c, fut)
        return self.cal.handle(now, c, fut)

    # ---- the operator's display (terminal/surface.py) -------------------------------------------
    def _display_report(self, now: float, c: op.DisplayState | op.DisplayEvent) -> op.CommandResult:
        if isinstance(c, op.DisplayState):
            self.display.take(c, now)
        else:
            self._journal.log_event(now, c.kind, **c.detail)
            if c.kind == "display.pin_lockout":
                self._journal.event(text("event.pin_lockout", **c.detail))
        return op.CommandResult(True)

    def _display_tick(self, now: float) -> None:
        change = self.display.tick(now)
        if change.back:
            self._journal.log_event(now, "display.back", lost_s=round(change.lost_s, 1))
            return
        if not change.lost:
            return
        paused = self.op.state == op.RUNNING and self.display.pauses
        if paused:
            self.op.pause()
            self._journal.log_event(now, "operator.pause", was=op.RUNNING, auto=True)
        state = self.display.state
        why = state.why if state is not None and state.state == "down" else "no page"
        self._journal.log_event(
            now, "display.lost", lost_s=round(change.lost_s, 1), why=why, paused=paused
        )
        self._journal.event(
            text("event.display_lost_paused" if paused else "event.display_lost", s=change.lost_s)
        )

    def _manual_event(self, now: float) -> None:
        m = self.op.manual
        if m.mode == "fixed":
            self._journal.log_event(
                now, "manual.set", mode=m.mode, upper_kg_ha=m.upper_kg_ha, lower_kg_ha=m.lower_kg_ha
            )
        elif m.mode == "percent":
            self._journal.log_event(now, "manual.set", mode=m.mode, percent=m.percent)
        else:
            self._journal.log_event(now, "manual.off")

    def _done(self, message: Text) -> op.CommandResult:
        self._journal.event(text("event.operator", what=message))
        return op.CommandResult(True, message)

    def _send_command_now(self) -> None:
        can = self._parts.can
        cmd = self.command()
        if can.tc is not None:  # an ISOBUS implement: its setpoints and work state now
            can.tc.poll(self._journal.clock(), cmd)
            return
        if not can.link.set_command(cmd[0], cmd[1], cmd[2], cmd[3]):
            can.link.send_now()

    # ---- the command and the tick ------------------------------------------------------------
    def command(self) -> tuple[bool, float, float, float]:
        """(start, fan rpm, upper kg/ha, lower kg/ha) for PcCommand now."""
        fan = float(self._settings.cfg.machine.fan_rpm)
        if self.cal.wizard is not None:
            c: CalCommand = self.cal.wizard.command
            return (c.start, c.fan_rpm, 0.0, 0.0)
        upper, lower = self.op.rates(self._model_rates)
        return (self.op.start_bit, fan, upper, lower)

    def rates(self, model: tuple[float, float]) -> tuple[bool, float, float, float]:
        self._model_rates = model
        return self.command()

    def _log_health(self) -> dict[str, Any]:
        log = self._journal.session
        if log is None:
            return {}
        return {
            "log_health": str(log.health),
            "log_free_mb": (log.free_bytes or 0) / 1e6,
            "log_min_free_mb": log.min_free_bytes / 1e6,
            "log_error": log.last_error or "",
        }

    def after_tick(self, now: float, snap: Snapshot, off_map: tuple[OffMap, ...] = ()) -> DeskView:
        """`off_map`: the maps the outlet is too far outside of (the wrong-field alarm)."""
        dt_s = 0.0 if self._last_t is None else max(0.0, now - self._last_t)
        self._last_t = now
        self.cal.tick(now, dt_s)
        self._display_tick(now)
        self._count(snap, dt_s)
        self.counters.maybe_save(now)
        metering = self.op.state == op.RUNNING and snap.ecu_live and snap.running
        tank = self.tank
        low = tank.remaining_kg is not None and tank.remaining_kg <= tank.alarm_kg
        inputs = AlarmInputs(
            metering=metering,
            target_rpm=snap.target_rpm,
            meter_rpm=snap.meter_rpm,
            faults=snap.faults if snap.ecu_live else 0,
            gnss_link=snap.gnss_link,
            crop_link=snap.crop_link,
            ecu_link=snap.ecu_link,
            off_map=off_map,
            ecu_protocol=snap.ecu_protocol,
            **self._log_health(),
            display_down=self.display.down,
            display_lost=self.display.lost,
            operating=self.op.state in (op.RUNNING, op.PAUSED),
            position_lost=snap.zone == UNKNOWN,
            isobus=(
                None
                if snap.isobus is None
                else (snap.isobus.state, snap.isobus.implement, snap.isobus.problem)
            ),
            ecu_refused=self._parts.can.refused,
            tank_low=(
                text("alarm.text.tank_low", kg=max(0.0, tank.remaining_kg or 0.0)) if low else None
            ),
        )
        for name, alarm in self.alarms.update(snap.t_s, inputs):
            figures = {k: v for k, v in alarm.values if isinstance(v, int | float)}
            self._journal.log_event(now, "alarm.raised", name=name, **figures)
            self._journal.event(text("event.alarm", alarm=alarm))
        cfg = self._settings.cfg
        fresh = {r.sensor_id: r.ndvi for r in self._parts.ndvi.sensors.fresh(now)}
        return DeskView(
            operator=self.op.state,
            manual=self.op.manual,
            rate_model_kg_ha=self._model_rates,
            speed_why=speed_why(snap, self._settings.cfg),
            alarms=self.alarms.views(),
            count_field=self.counters.view("field"),
            count_season=self.counters.view("season"),
            count_undo=self.counters.undoable(),
            tank=self.tank,
            calibration=self.cal.wizard.view() if self.cal.wizard is not None else None,
            settings_pending=self.settings.pending is not None,
            settings_state=dict(self.settings.state),
            ndvi_per_sensor=tuple(fresh.get(i) for i in range(1, cfg.crop.sensors + 1)),
            cv_threshold_pct=cfg.speed.cv_threshold_pct,
            switch_speed_kmh=cfg.speed.switch_speed_kmh,
            applied_kg_ha=applied_kg_ha(snap, cfg),
        )

    def _count(self, snap: Snapshot, dt_s: float) -> None:
        if not (snap.ecu_live and snap.running) or dt_s <= 0.0 or dt_s > 1.0:
            return
        m = self._settings.cfg.machine
        kg = (
            snap.meter_rpm[0] / 60.0 * dt_s * m.kg_per_rev_upper,
            snap.meter_rpm[1] / 60.0 * dt_s * m.kg_per_rev_lower,
        )
        if max(snap.meter_rpm) < 0.1:  # fans only (paused, headland): no work done
            return
        d_m = snap.v_kmh / 3.6 * dt_s
        self.counters.add(d_m * m.width_m / 10_000.0, kg, dt_s, d_m)
        left = self.tank.remaining_kg
        if left is not None:
            self.tank = replace(self.tank, remaining_kg=left - kg[0] - kg[1])
            self.counters.set_tank(self.tank)

    def close(self) -> None:
        self.counters.save()
        self.cal.end()


def _reason(exc: ConfigError) -> str:
    text = str(exc)
    prefix = f"{exc.key}: "
    return text[len(prefix) :] if text.startswith(prefix) else text
