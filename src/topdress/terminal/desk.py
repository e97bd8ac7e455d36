"""The operator's desk inside the terminal loop: commands in, run state, alarms, counters,
calibration wizards and settings; the fields it adds to every Snapshot.

`Terminal.post(command)` puts a command and its Future on the terminal's inbox; the loop
hands it to `OperatorDesk.handle`, which acts and completes the Future (at once, or once the
ECU acknowledged settings). Nothing here blocks: device reopening and parameter pushes go on
over the following ticks.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable, Iterable
from concurrent.futures import Future
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Protocol

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
from topdress.crop.sensors import CompensatedNdvi, parse_crop_line
from topdress.devices.lines import LineSource
from topdress.ecu import EcuParams, meter_rate_kg_ha
from topdress.errors import ConfigError, DeviceError, ProtocolError, SensorError
from topdress.gnss.nmea import NmeaDecoder
from topdress.i18n import Text, text
from topdress.log.session import SessionLog
from topdress.protocol import Fault, Source
from topdress.terminal.alarms import AlarmBook, AlarmInputs
from topdress.terminal.calibration import (
    CalCommand,
    CalibrationError,
    CalInputs,
    CatchTest,
    FanCheck,
    WheelCal,
    Wizard,
)
from topdress.terminal.canlink import CanLink
from topdress.terminal.counters import WorkCounters
from topdress.terminal.inbox import Inbox
from topdress.terminal.leadcal import LeadCal
from topdress.terminal.site import OffMap
from topdress.terminal.surface import DisplayWatch
from topdress.view import commands as op
from topdress.view.links import link_state
from topdress.view.snapshot import (
    AlarmView,
    CalibrationView,
    CounterView,
    DeviceLine,
    Snapshot,
    TankView,
)

log = logging.getLogger(__name__)

DEVICE_LINES = 20  # lines or frames kept per device for the "test" view


@dataclass(frozen=True)
class DeskView:
    """The Snapshot fields the desk fills."""

    operator: str
    manual: op.ManualView
    rate_model_kg_ha: tuple[float, float]
    speed_why: Text | None
    alarms: tuple[AlarmView, ...]
    count_field: CounterView
    count_season: CounterView
    count_undo: tuple[str, ...]
    tank: TankView
    calibration: CalibrationView | None
    settings_pending: bool
    settings_state: dict[str, str]
    ndvi_per_sensor: tuple[float | None, ...]
    cv_threshold_pct: float
    switch_speed_kmh: float
    applied_kg_ha: tuple[float, float]


class Loop(Protocol):
    """What the desk asks of the control loop it sits in (topdress.terminal.app.Terminal):
    its state to read, its log, and the two ways a changed setting reaches the loop's parts."""

    cfg: TerminalConfig
    session: SessionLog | None
    clock: Callable[[], float]
    inbox: Inbox
    link: CanLink
    ndvi: CompensatedNdvi
    gnss: LineSource
    crop: LineSource

    @property
    def started_at(self) -> float | None: ...

    def log_event(self, t: float, kind: str, **detail: Any) -> None: ...

    def event(self, message: Text) -> None: ...

    def reopen(self, section: str, new: TerminalConfig, now: float) -> None: ...

    def open_can(self, new: TerminalConfig, done: Callable[[str | None], None]) -> None: ...

    def take(self, section: str, new: TerminalConfig) -> None: ...


class OperatorDesk:
    def __init__(self, loop: Loop, autostart: bool, config_path: Path | None) -> None:
        self.loop = loop
        self.config_path = config_path
        cfg = loop.cfg
        self.op = op.Operator(autostart)
        self.alarms = AlarmBook(cfg.operator.off_rate_pct, cfg.operator.off_rate_s)
        self.display = DisplayWatch(cfg.display.lost_pause_s)
        # Beside the session logs; a terminal without a session log (tests, a log that could
        # not be created) keeps them in memory only.
        session = loop.session
        where = session.path.parent if session is not None else None
        self.counters = WorkCounters(where / cfg.operator.counters_file if where else None)
        if self.counters.error:
            loop.event(text("event.counters_error", error=self.counters.error))
        self.wizard: Wizard | LeadCal | None = None
        self._cal_seq = 0
        self._pending: Future[op.CommandResult] | None = None  # settings awaiting the ECU
        # The last settings change: dotted key -> pending, ok, refused: <reason>, put back.
        self._settings_state: dict[str, str] = {}
        self._last_t: float | None = None
        self._model_rates = (0.0, 0.0)
        self._lines: dict[str, deque[tuple[float, Any]]] = {
            k: deque(maxlen=DEVICE_LINES) for k in ("gnss", "crop", "can")
        }
        self.tank = TankView()  # no fill entered yet

    # ---- posting (any thread) ----------------------------------------------------------------
    def post(self, command: Any) -> Future[op.CommandResult]:
        fut: Future[op.CommandResult] = Future()
        self.loop.inbox.put(("op", self.loop.clock(), (command, fut)))
        return fut

    # ---- the loop ----------------------------------------------------------------------------
    def record(self, kind: str, t: float, payload: Any) -> None:
        """Keep the last inputs of each device for the device test."""
        key = {"nmea": "gnss", "crop": "crop", "can": "can"}.get(kind)
        if key is not None:
            self._lines[key].append((t, payload))

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
        loop = self.loop
        if isinstance(c, op.Start):
            was = self.op.state
            msg = self.op.start()
            loop.log_event(now, "operator.start", was=was)
            return self._done(msg)
        if isinstance(c, op.Stop):
            was = self.op.state
            self._end_wizard()
            msg = self.op.stop()
            self._send_command_now()
            loop.log_event(now, "operator.stop", was=was)
            return self._done(msg)
        if isinstance(c, op.Pause):
            msg = self.op.pause()
            loop.log_event(now, "operator.pause", was=op.RUNNING)
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
                loop.log_event(now, "alarm.acked", name=name)
            return op.CommandResult(True, text("op.done.acked", n=len(acked)))
        if isinstance(c, op.ResetCounter):
            try:
                self.counters.reset(c.which)
            except ValueError as exc:
                return op.CommandResult(False, str(exc))
            self.counters.save(wait=False)  # the loop does not wait on the disk
            loop.log_event(now, "counter.reset", which=c.which)
            return self._done(text("op.done.reset", which=text(f"count.{c.which}")))
        if isinstance(c, op.UndoReset):
            try:
                self.counters.undo(c.which)
            except ValueError:
                return op.CommandResult(False, text("op.error.no_undo", which=c.which))
            self.counters.save(wait=False)
            loop.log_event(now, "counter.undo", which=c.which)
            return self._done(text("op.done.undo", which=text(f"count.{c.which}")))
        if isinstance(c, op.FillTank):
            if not (0.0 < c.fill_kg < 1e6 and 0.0 <= c.alarm_kg < c.fill_kg):
                return op.CommandResult(
                    False, text("op.error.tank", fill=c.fill_kg, alarm=c.alarm_kg)
                )
            self.tank = TankView(c.fill_kg, c.fill_kg, c.alarm_kg)
            loop.log_event(now, "tank.filled", fill_kg=c.fill_kg, alarm_kg=c.alarm_kg)
            return self._done(text("op.done.tank", kg=c.fill_kg, alarm=c.alarm_kg))
        if isinstance(c, op.Help):
            return op.CommandResult(False, c.text)
        if isinstance(c, op.DisplayState | op.DisplayEvent):
            return self._display_report(now, c)
        if isinstance(c, op.TestDevice):
            return self._device_test(c.device)
        if isinstance(c, op.ApplySettings):
            return self._apply(now, c, fut)
        return self._calibration(now, c, fut)

    # ---- the operator's display (terminal/surface.py) -------------------------------------------
    def _display_report(self, now: float, c: op.DisplayState | op.DisplayEvent) -> op.CommandResult:
        if isinstance(c, op.DisplayState):
            self.display.take(c, now)
        else:
            self.loop.log_event(now, c.kind, **c.detail)
            if c.kind == "display.pin_lockout":
                self.loop.event(text("event.pin_lockout", **c.detail))
        return op.CommandResult(True)

    def _display_tick(self, now: float) -> None:
        change = self.display.tick(now)
        if change.back:
            self.loop.log_event(now, "display.back", lost_s=round(change.lost_s, 1))
            return
        if not change.lost:
            return
        paused = self.op.state == op.RUNNING and self.display.pauses
        if paused:
            self.op.pause()
            self.loop.log_event(now, "operator.pause", was=op.RUNNING, auto=True)
        state = self.display.state
        why = state.why if state is not None and state.state == "down" else "no page"
        self.loop.log_event(
            now, "display.lost", lost_s=round(change.lost_s, 1), why=why, paused=paused
        )
        self.loop.event(
            text("event.display_lost_paused" if paused else "event.display_lost", s=change.lost_s)
        )

    def _manual_event(self, now: float) -> None:
        m = self.op.manual
        if m.mode == "fixed":
            self.loop.log_event(
                now, "manual.set", mode=m.mode, upper_kg_ha=m.upper_kg_ha, lower_kg_ha=m.lower_kg_ha
            )
        elif m.mode == "percent":
            self.loop.log_event(now, "manual.set", mode=m.mode, percent=m.percent)
        else:
            self.loop.log_event(now, "manual.off")

    def _done(self, message: Text) -> op.CommandResult:
        self.loop.event(text("event.operator", what=message))
        return op.CommandResult(True, message)

    def _send_command_now(self) -> None:
        link = self.loop.link
        cmd = self.command()
        if not link.set_command(cmd[0], cmd[1], cmd[2], cmd[3]):
            link.send_now()

    # ---- calibration -------------------------------------------------------------------------
    def _calibration(
        self, now: float, c: Any, fut: Future[op.CommandResult]
    ) -> op.CommandResult | None:
        if isinstance(c, op.StartCatchTest | op.StartWheelCal | op.StartFanCheck | op.StartLeadCal):
            return self._start_wizard(now, c)
        w = self.wizard
        if isinstance(c, op.LeadSeen):
            if not isinstance(w, LeadCal):
                return op.CommandResult(False, text("op.error.no_cal", cal=text("cal.lead")))
            before = w.step
            w.seen(now)
            if w.step == "done" and before != "done":
                self._result_event(now, w)
            return self._done(w.text)
        if isinstance(c, op.FinishCatchTest):
            if not isinstance(w, CatchTest):
                return op.CommandResult(False, text("op.error.no_cal", cal=text("cal.catch")))
            w.finish(c.weighed_kg)
            self._result_event(now, w)  # weighed again: the new result is logged too
            return self._done(w.text)
        if isinstance(c, op.FinishWheelCal):
            if not isinstance(w, WheelCal):
                return op.CommandResult(False, text("op.error.no_cal", cal=text("cal.wheel")))
            w.finish(c.distance_m)
            self._result_event(now, w)
            return self._done(w.text)
        if isinstance(c, op.CloseCalibration):
            if w is None:
                return op.CommandResult(False, text("cal.none"))
            value = w.value()
            self._end_wizard()
            if c.apply and isinstance(w, LeadCal) and w.values():
                return self._apply(now, op.ApplySettings("lookahead", w.values()), fut)
            if c.apply and value is not None and w.key:
                section, key = w.key.split(".")
                return self._apply(now, op.ApplySettings(section, {key: value}), fut)
            return op.CommandResult(True, text("op.done.cal_closed"))
        return op.CommandResult(False, f"unknown command {type(c).__name__}")

    def _start_wizard(self, now: float, c: Any) -> op.CommandResult:
        if self.op.state != op.STOPPED or self.wizard is not None:
            raise op.OperatorError(
                text("op.error.stop_first", state=text(f"op.state.{self.op.state}"))
            )
        loop = self.loop
        if not (loop.link.ready and loop.link.ecu_alive):
            raise op.OperatorError(text("op.error.ecu_for_cal", state=link_state(loop.link.state)))
        m = loop.cfg.machine
        if isinstance(c, op.StartCatchTest):
            self._cal_seq = (self._cal_seq + 1) % 256
            ids = loop.link.ids
            self.wizard = CatchTest(c.layer, c.revolutions, c.meter_rpm, self._cal_seq, ids)
        elif isinstance(c, op.StartWheelCal):
            self.wizard = WheelCal(c.distance_m, m.wheel_radius_m, m.wheel_ppr)
        elif isinstance(c, op.StartLeadCal):
            self._cal_seq = (self._cal_seq + 1) % 256
            reaction = c.reaction_ms
            if reaction is None:
                reaction = loop.cfg.operator.reaction_ms
            fan_min = loop.cfg.ecu.overrides.get("fan_min_rpm", EcuParams.defaults().fan_min_rpm)
            self.wizard = LeadCal(
                c.layer,
                c.meter_rpm,
                c.trials,
                reaction,
                c.run_s,
                m.fan_rpm,
                float(fan_min),
                self._cal_seq,
                loop.link.ids,
            )
        else:
            seconds = c.seconds if c.seconds is not None else loop.cfg.operator.fan_check_s
            fan_min = loop.cfg.ecu.overrides.get("fan_min_rpm", EcuParams.defaults().fan_min_rpm)
            self.wizard = FanCheck(seconds, m.fan_rpm, float(fan_min))
        self.op.state = op.CALIBRATING
        return self._done(text("event.calibration", what=self.wizard.text))

    def _end_wizard(self) -> None:
        w = self.wizard
        if w is None:
            return
        for msg in w.close():
            self.loop.link.send(msg)
        self.wizard = None
        if self.op.state == op.CALIBRATING:
            self.op.state = op.STOPPED

    def _wizard_tick(self, now: float, dt_s: float) -> None:
        w = self.wizard
        if w is None:
            return
        link = self.loop.link
        ecu = link.ecu if link.ecu_alive else None
        diag = ecu.diag if ecu else None
        status = ecu.status if ecu else None
        x = CalInputs(
            ecu_live=link.ecu_alive,
            cal_status=ecu.cal if ecu else None,
            cal_t=ecu.cal_t if ecu else None,
            wheel_pulses=diag.wheel_pulses if diag else None,
            v_wheel_kmh=status.wheel_kmh if status else 0.0,
            gnss_kmh=link.command.gnss_kmh,
            fan_rpm=(status.fan_rpm_upper, status.fan_rpm_lower) if status else (0.0, 0.0),
            dt_s=dt_s,
        )
        before = w.step
        for msg in w.tick(now, x):
            link.send(msg)
        if w.step != before and w.step in ("weigh", "aborted", "done"):
            self.loop.event(text("event.calibration", what=w.text))
            if w.step == "done":
                self._result_event(now, w)

    def _result_event(self, now: float, w: Wizard | LeadCal) -> None:
        """A wizard's result (as proposed; applying it is a setting change of its own)."""
        detail: dict[str, Any] = dict(w.result)
        if isinstance(w, CatchTest | LeadCal):
            detail["layer"] = w.layer
        if isinstance(w, WheelCal):
            detail["distance_m"] = w.distance_m  # as measured on the ground
        self.loop.log_event(now, f"calibration.{w.kind}", **detail)

    # ---- the command and the tick ------------------------------------------------------------
    def command(self) -> tuple[bool, float, float, float]:
        """(start, fan rpm, upper kg/ha, lower kg/ha) for PcCommand now."""
        fan = float(self.loop.cfg.machine.fan_rpm)
        if self.wizard is not None:
            c: CalCommand = self.wizard.command
            return (c.start, c.fan_rpm, 0.0, 0.0)
        upper, lower = self.op.rates(self._model_rates)
        return (self.op.start_bit, fan, upper, lower)

    def rates(self, model: tuple[float, float]) -> tuple[bool, float, float, float]:
        self._model_rates = model
        return self.command()

    def _log_health(self) -> dict[str, Any]:
        log = self.loop.session
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
        self._wizard_tick(now, dt_s)
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
            tank_low=(
                text("alarm.text.tank_low", kg=max(0.0, tank.remaining_kg or 0.0)) if low else None
            ),
        )
        for name, alarm in self.alarms.update(snap.t_s, inputs):
            figures = {k: v for k, v in alarm.values if isinstance(v, int | float)}
            self.loop.log_event(now, "alarm.raised", name=name, **figures)
            self.loop.event(text("event.alarm", alarm=alarm))
        cfg = self.loop.cfg
        fresh = {r.sensor_id: r.ndvi for r in self.loop.ndvi.sensors.fresh(now)}
        return DeskView(
            operator=self.op.state,
            manual=self.op.manual,
            rate_model_kg_ha=self._model_rates,
            speed_why=speed_why(snap, self.loop.cfg),
            alarms=self.alarms.views(),
            count_field=self.counters.view("field"),
            count_season=self.counters.view("season"),
            count_undo=self.counters.undoable(),
            tank=self.tank,
            calibration=self.wizard.view() if self.wizard is not None else None,
            settings_pending=self._pending is not None,
            settings_state=dict(self._settings_state),
            ndvi_per_sensor=tuple(fresh.get(i) for i in range(1, cfg.crop.sensors + 1)),
            cv_threshold_pct=cfg.speed.cv_threshold_pct,
            switch_speed_kmh=cfg.speed.switch_speed_kmh,
            applied_kg_ha=applied_kg_ha(snap, cfg),
        )

    def _count(self, snap: Snapshot, dt_s: float) -> None:
        if not (snap.ecu_live and snap.running) or dt_s <= 0.0 or dt_s > 1.0:
            return
        m = self.loop.cfg.machine
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

    def close(self) -> None:
        self.counters.save()
        self._end_wizard()

    # ---- device test -------------------------------------------------------------------------
    def _device_test(self, device: str) -> op.CommandResult:
        if device not in self._lines:
            return op.CommandResult(False, text("op.error.no_device", device=device))
        t0 = self.loop.started_at or 0.0
        decode: Callable[[Any], tuple[str, str]] = {
            "gnss": _decode_nmea(NmeaDecoder()),
            "crop": _decode_crop(self.loop.cfg),
            "can": _decode_can(self.loop.link.ids),
        }[device]
        lines = [DeviceLine(t - t0, *decode(p)) for t, p in self._lines[device]]
        where = {
            "gnss": self.loop.gnss.name,
            "crop": self.loop.crop.name,
            "can": self.loop.link.where,
        }[device]
        return op.CommandResult(
            True, text("op.done.test", device=device, where=where, n=len(lines)), data=lines
        )

    # ---- settings ----------------------------------------------------------------------------
    def _apply(
        self, now: float, c: op.ApplySettings, fut: Future[op.CommandResult] | None
    ) -> op.CommandResult | None:
        loop = self.loop
        if self._pending is not None:
            raise op.OperatorError(text("op.error.settings_busy"))
        if c.base is not None and c.base != section_version(loop.cfg, c.section):
            # Applied from another screen since this one was filled: its values would undo it.
            return op.CommandResult(
                False, text("op.error.stale", section=c.section), {c.section: "stale"}, "stale"
            )
        new = validate_section(loop.cfg, c.section, c.values)
        if c.section in ECU_SECTIONS:
            changed = changed_ecu_params(loop.cfg, new)
            if changed:
                return self._push(now, c, new, changed, fut)
        elif c.section in DEVICE_KEYS:
            keys = changed_device_keys(loop.cfg, new, c.section)
            if c.section == "can":  # the CAN link starts over on any change of [can]
                self._open_can(c, new, keys, fut)
                return None  # answered once the new bus is open
            try:
                # A line source is opened again only when the keys it is opened with changed.
                if keys:
                    loop.reopen(c.section, new, now)
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
        self._pending = pending

        def done(error: str | None) -> None:
            self._pending = None
            if error is None:
                pending.set_result(self._commit_later(c, new))
            else:  # the keys that made it fail said
                errors = dict.fromkeys(keys or [c.section], error)
                pending.set_result(op.CommandResult(False, error, errors))

        self.loop.open_can(new, done)

    def _commit_later(self, c: op.ApplySettings, new: TerminalConfig) -> op.CommandResult:
        """`_commit` once a device or the ECU has taken the change; a failure is the answer."""
        try:
            return self._commit(self.loop.clock(), c, new)
        except (op.OperatorError, ConfigError) as exc:
            why = exc.text if isinstance(exc, op.OperatorError) else str(exc)
            return op.CommandResult(False, text("op.error.not_saved", error=why))

    def _commit(self, now: float, c: op.ApplySettings, new: TerminalConfig) -> op.CommandResult:
        """Save the section to the file, then take the new configuration."""
        loop = self.loop
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
            new = _with_section(loop.cfg, new_file, c.section)
            saved = text("op.done.saved", path=str(self.config_path))
        else:
            saved = text("op.done.not_saved")
        for key, old_value, new_value in changed_keys(loop.cfg, new, c.section):
            loop.log_event(now, "setting.changed", key=key, old=old_value, new=new_value)
        loop.take(c.section, new)
        if c.section == "operator":
            self.alarms.retune(new.operator.off_rate_pct, new.operator.off_rate_s)
        later = text("op.done.later") if c.section in RESTART_SECTIONS else ""
        done = self._done(text("op.done.settings", section=c.section, saved=saved, later=later))
        return replace(done, data=section_version(loop.cfg, c.section))

    def _push(
        self,
        now: float,
        c: op.ApplySettings,
        new: TerminalConfig,
        changed: dict[int, float],
        fut: Future[op.CommandResult] | None,
    ) -> op.CommandResult | None:
        loop = self.loop
        link = loop.link
        if self.op.state != op.STOPPED:
            raise op.OperatorError(
                text(
                    "op.error.ecu_stopped",
                    section=c.section,
                    state=text(f"op.state.{self.op.state}"),
                )
            )
        if not (link.ready and link.params_done and link.ecu_alive):
            raise op.OperatorError(text("op.error.ecu_params", state=link_state(link.state)))
        old = loop.cfg.ecu_params()
        pending: Future[op.CommandResult] = fut if fut is not None else Future()
        self._pending = pending
        keys = {pid: protocol.param(pid).config_key for pid in changed}
        self._settings_state = dict.fromkeys(keys.values(), "pending")

        def done(error: str | None, accepted: list[int]) -> None:
            self._pending = None
            if error is None:
                self._settings_state = dict.fromkeys(keys.values(), "ok")
                pending.set_result(self._commit_later(c, new))
                return
            # Nothing half-applied: what the ECU took of this change goes back.
            back = {pid: old[pid] for pid in accepted if pid in old}
            if back:
                loop.link.push_params(back, loop.clock(), _log_rollback)
            key = refused_key(error, changed, c.section)
            self._settings_state = {keys[pid]: "put back" for pid in accepted if pid in keys}
            self._settings_state[key] = f"refused: {error}"
            loop.event(text("event.settings_refused", section=c.section, error=error))
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


def _reason(exc: ConfigError) -> str:
    text = str(exc)
    prefix = f"{exc.key}: "
    return text[len(prefix) :] if text.startswith(prefix) else text


def _decode_nmea(dec: NmeaDecoder) -> Callable[[Any], tuple[str, str]]:
    def f(line: Any) -> tuple[str, str]:
        fix = dec.decode(line)
        raw = bytes(line).decode("latin-1").rstrip()
        if not fix.ok:
            return raw, f"not usable: {fix.error}"
        parts = [f"{fix.talker}{fix.type}", "fix" if fix.fix_valid else "no fix"]
        if fix.speed_kmh is not None:
            parts.append(f"{fix.speed_kmh:.2f} km/h")
        if fix.lat is not None and fix.lon is not None:
            parts.append(f"{fix.lat:.6f},{fix.lon:.6f}")
        return raw, " ".join(parts)

    return f


def _decode_crop(cfg: TerminalConfig) -> Callable[[Any], tuple[str, str]]:
    def f(line: Any) -> tuple[str, str]:
        raw = bytes(line).decode("latin-1").rstrip()
        try:
            r = parse_crop_line(0.0, line, cfg.crop.columns, cfg.crop.sensors)
        except SensorError as exc:
            return raw, f"not usable: {exc}"
        return raw, f"sensor {r.sensor_id} NDVI {r.ndvi:.3f}"

    return f


def _decode_can(ids: protocol.FrameIds) -> Callable[[Any], tuple[str, str]]:
    def f(msg: Any) -> tuple[str, str]:
        raw = f"{msg.arbitration_id:08X} {bytes(msg.data).hex(' ')}"
        try:
            return raw, repr(protocol.decode(msg, ids))
        except ProtocolError as exc:
            return raw, f"not ours or malformed: {exc}"

    return f


def applied_kg_ha(snap: Snapshot, cfg: TerminalConfig) -> tuple[float, float]:
    """The rate each layer applies now, from its measured metering speed and the ECU's
    selected speed (eq. 4 inverted, in the C core); 0 standing or while the ECU is not heard."""
    if not snap.ecu_live:
        return (0.0, 0.0)
    m = cfg.machine
    lo = cfg.speed.min_work_speed_kmh
    return (
        meter_rate_kg_ha(m.width_m, snap.meter_rpm[0], snap.v_kmh, m.kg_per_rev_upper, lo),
        meter_rate_kg_ha(m.width_m, snap.meter_rpm[1], snap.v_kmh, m.kg_per_rev_lower, lo),
    )


def speed_why(snap: Snapshot, cfg: TerminalConfig) -> Text | None:
    """Why the ECU meters on the speed it does, in the terms of the paper's rule (None while
    the ECU is not heard)."""
    if not snap.ecu_live:
        return None
    s = cfg.speed
    src = text(f"source.{snap.source}")
    if s.mode != "paper":
        return text("why.mode", source=src, mode=s.mode)
    faults = Fault(snap.faults)
    if snap.source == Source.NONE:
        return text("why.none")
    if snap.source == Source.GNSS and Fault.WHEEL_ENCODER in faults:
        return text("why.encoder_fault")
    if Fault.GNSS_FROZEN in faults:
        return text("why.gnss_frozen")
    if snap.gnss_kmh is None or Fault.GNSS_LOST in faults:
        return text("why.no_gnss", source=src)
    cmp_v = snap.gnss_kmh if s.switch_compare == "gnss" else snap.v_wheel_kmh
    cv = text("why.cv_none") if snap.cv_pct is None else text("why.cv", cv=snap.cv_pct)
    rule = dict(
        cv=cv,
        threshold=s.cv_threshold_pct,
        compare=text(f"source.{s.switch_compare}"),
        speed=cmp_v,
        switch=s.switch_speed_kmh,
    )
    if snap.source == Source.GNSS:
        return text("why.gnss", **rule)
    if not snap.uniform:
        return text("why.not_uniform", **rule)
    return text("why.slow", **rule)
