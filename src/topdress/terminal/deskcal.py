"""The calibration wizards on the operator's desk: the catch test, the wheel calibration, the
fan check and the look-ahead calibration (topdress.terminal.calibration, .leadcal). One runs at a
time, with the meters stopped and the ECU heard; its result is proposed, and applying it is a
settings change of its own.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future
from typing import Any

from topdress.ecu import EcuParams
from topdress.i18n import Text, text
from topdress.terminal.busswitch import BusSwitch
from topdress.terminal.calibration import (
    CalInputs,
    CatchTest,
    FanCheck,
    WheelCal,
    Wizard,
    isobus_refusal,
)
from topdress.terminal.journal import Journal, Settings
from topdress.terminal.leadcal import LeadCal
from topdress.view import commands as op
from topdress.view.links import link_state

Apply = Callable[
    [float, op.ApplySettings, "Future[op.CommandResult] | None"], "op.CommandResult | None"
]


class CalDesk:
    """The wizard running (None: none), started, fed every tick and closed."""

    def __init__(
        self,
        settings: Settings,
        journal: Journal,
        can: BusSwitch,
        operator: op.Operator,
        told: Callable[[Text], op.CommandResult],
        apply: Apply,
    ) -> None:
        """`told(message)`: the operator told a command is done, and its result; `apply`: a
        settings change (the result applied)."""
        self._settings = settings
        self._journal = journal
        self._can = can
        self._op = operator
        self._told = told
        self._apply = apply
        self.wizard: Wizard | LeadCal | None = None
        self._seq = 0

    def handle(self, now: float, c: Any, fut: Future[op.CommandResult]) -> op.CommandResult | None:
        if isinstance(c, op.StartCatchTest | op.StartWheelCal | op.StartFanCheck | op.StartLeadCal):
            return self._start(now, c)
        w = self.wizard
        if isinstance(c, op.LeadSeen):
            if not isinstance(w, LeadCal):
                return op.CommandResult(False, text("op.error.no_cal", cal=text("cal.lead")))
            before = w.step
            w.seen(now)
            if w.step == "done" and before != "done":
                self._result_event(now, w)
            return self._told(w.text)
        if isinstance(c, op.FinishCatchTest):
            if not isinstance(w, CatchTest):
                return op.CommandResult(False, text("op.error.no_cal", cal=text("cal.catch")))
            w.finish(c.weighed_kg)
            self._result_event(now, w)  # weighed again: the new result is logged too
            return self._told(w.text)
        if isinstance(c, op.FinishWheelCal):
            if not isinstance(w, WheelCal):
                return op.CommandResult(False, text("op.error.no_cal", cal=text("cal.wheel")))
            w.finish(c.distance_m)
            self._result_event(now, w)
            return self._told(w.text)
        if isinstance(c, op.CloseCalibration):
            if w is None:
                return op.CommandResult(False, text("cal.none"))
            value = w.value()
            self.end()
            if c.apply and isinstance(w, LeadCal) and w.values():
                return self._apply(now, op.ApplySettings("lookahead", w.values()), fut)
            if c.apply and value is not None and w.key:
                section, key = w.key.split(".")
                return self._apply(now, op.ApplySettings(section, {key: value}), fut)
            return op.CommandResult(True, text("op.done.cal_closed"))
        return op.CommandResult(False, f"unknown command {type(c).__name__}")

    def _start(self, now: float, c: Any) -> op.CommandResult:
        if self._op.state != op.STOPPED or self.wizard is not None:
            raise op.OperatorError(
                text("op.error.stop_first", state=text(f"op.state.{self._op.state}"))
            )
        link, cfg = self._can.link, self._settings.cfg
        if (prop := self._can.prop) is not None:  # an ISOBUS: only with a topdress ECU served
            fans = isinstance(c, op.StartFanCheck | op.StartLeadCal)
            why = None if prop.serving else prop.why or text("prop.why.none_served")
            if (refused := isobus_refusal(fans, why)) is not None:
                raise op.OperatorError(refused)
        if not (link.ready and link.ecu_alive):
            raise op.OperatorError(text("op.error.ecu_for_cal", state=link_state(link.state)))
        m = cfg.machine
        fan_min = float(cfg.ecu.overrides.get("fan_min_rpm", EcuParams.defaults().fan_min_rpm))
        if isinstance(c, op.StartCatchTest):
            self._seq = (self._seq + 1) % 256
            self.wizard = CatchTest(c.layer, c.revolutions, c.meter_rpm, self._seq, link.ids)
        elif isinstance(c, op.StartWheelCal):
            self.wizard = WheelCal(c.distance_m, m.wheel_radius_m, m.wheel_ppr)
        elif isinstance(c, op.StartLeadCal):
            self._seq = (self._seq + 1) % 256
            reaction = c.reaction_ms
            if reaction is None:
                reaction = cfg.operator.reaction_ms
            self.wizard = LeadCal(
                c.layer,
                c.meter_rpm,
                c.trials,
                reaction,
                c.run_s,
                m.fan_rpm,
                fan_min,
                self._seq,
                link.ids,
            )
        else:
            seconds = c.seconds if c.seconds is not None else cfg.operator.fan_check_s
            self.wizard = FanCheck(seconds, m.fan_rpm, fan_min)
        self._op.state = op.CALIBRATING
        return self._told(text("event.calibration", what=self.wizard.text))

    def end(self) -> None:
        w = self.wizard
        if w is None:
            return
        for msg in w.close():
            self._can.link.send(msg)
        self.wizard = None
        if self._op.state == op.CALIBRATING:
            self._op.state = op.STOPPED

    def tick(self, now: float, dt_s: float) -> None:
        w = self.wizard
        if w is None:
            return
        link = self._can.link
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
            self._journal.event(text("event.calibration", what=w.text))
            if w.step == "done":
                self._result_event(now, w)

    def _result_event(self, now: float, w: Wizard | LeadCal) -> None:
        """A wizard's result (as proposed; applying it is a setting change of its own)."""
        detail: dict[str, Any] = dict(w.result)
        if isinstance(w, CatchTest | LeadCal):
            detail["layer"] = w.layer
        if isinstance(w, WheelCal):
            detail["distance_m"] = w.distance_m  # as measured on the ground
        self._journal.log_event(now, f"calibration.{w.kind}", **detail)
